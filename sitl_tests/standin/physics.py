"""Vehicle motion: kinematics per mode, landing, battery drain, the obstacle sensor, geometry."""
from __future__ import annotations

import math
from typing import Optional, Tuple

from .vocabulary import EARTH_R, MODE_NAMES, MODES, POSITION_MODES, mavlink


class Physics:
    """How StandinAutopilot's vehicle (mixed into it) moves on simulated time."""

    # ----- physics ------------------------------------------------------------------------------------

    def _speed_xy(self) -> float:
        return self.v.speed_override or self.params["WPNAV_SPEED"] / 100.0

    def _move_towards(self, n: float, e: float, alt: float, dt: float, speed: Optional[float] = None) -> float:
        """Straight-line kinematics: horizontal at WPNAV_SPEED, vertical at WPNAV_SPEED_UP/DN. Returns the 3-D distance left."""
        v = self.v
        speed = speed if speed is not None else self._speed_xy()
        dn, de = n - v.north, e - v.east
        dxy = math.hypot(dn, de)
        step = min(dxy, speed * dt)
        if dxy > 1e-6:
            v.vn, v.ve = dn / dxy * step / dt, de / dxy * step / dt
            v.north += dn / dxy * step
            v.east += de / dxy * step
            if step / dt > 0.5:
                v.heading_deg = math.degrees(math.atan2(de, dn)) % 360
        else:
            v.vn = v.ve = 0.0
        dz = alt - v.alt
        vz = self.params["WPNAV_SPEED_UP"] / 100.0 if dz > 0 else self.params["WPNAV_SPEED_DN"] / 100.0
        zstep = max(-vz * dt, min(vz * dt, dz))
        v.alt += zstep
        v.vd = -zstep / dt
        return math.sqrt((n - v.north) ** 2 + (e - v.east) ** 2 + (alt - v.alt) ** 2)

    def _descend(self, dt: float, n: Optional[float] = None, e: Optional[float] = None) -> None:
        v = self.v
        rate = self.params["WPNAV_SPEED_DN"] / 100.0 if v.alt > self.params["LAND_ALT_LOW"] / 100.0 else self.params["LAND_SPEED"] / 100.0
        if n is not None and e is not None:
            self._move_towards(n, e, v.alt, dt)
        else:
            v.vn = v.ve = 0.0
        v.alt -= rate * dt
        v.vd = rate
        if v.alt <= 0.0:
            self._touchdown()

    def _touchdown(self) -> None:
        v = self.v
        v.alt = 0.0
        v.vn = v.ve = v.vd = 0.0
        if not v.landed:
            v.landed = True
            v.landed_since = self._sim
            self.rec.add(self.wall(), self._sim, "landed", north=v.north, east=v.east, mode=MODE_NAMES.get(v.mode))

    def _physics(self, dt: float) -> None:
        v = self.v
        # battery
        self._battery_step(dt)
        # GPS loss -> EKF failsafe (ArduCopter/ekf_check.cpp: failsafe_ekf_event, FS_EKF_ACTION 1 = LAND)
        if v.armed and not v.landed and v.mode in POSITION_MODES and not self._position_ok() and not v.ekf_failsafe:
            v.ekf_failsafe = True
            self._statustext("EKF Failsafe: changed to LAND Mode", mavlink.MAV_SEVERITY_CRITICAL)
            v.mode = MODES["LAND"]
            v.land_target = None
            self.rec.add(self.wall(), self._sim, "mode", old=None, new="LAND", reason="ekf_failsafe")
        if v.ekf_failsafe and self._position_ok():
            v.ekf_failsafe = False
        if not v.armed:
            v.vn = v.ve = v.vd = 0.0
            return
        mode = v.mode
        if v.landed:
            v.vn = v.ve = v.vd = 0.0
            if self._wants_liftoff():
                v.landed = False
                v.landed_since = None
            else:
                if v.disarm_timer_start is None:
                    v.disarm_timer_start = self._sim
                # landing modes disarm once down (mode_land.cpp / mode_rtl.cpp / AUTO NAV_LAND: disarm when landed)
                landing_mode = mode in (MODES["LAND"], MODES["RTL"]) or (mode == MODES["AUTO"] and self.mission_done())
                if landing_mode and v.landed_since is not None and self._sim - v.landed_since >= 1.0:
                    self._disarm("landed")
                    return
                # Copter::auto_disarm_check (ArduCopter/motors.cpp): armed, landed, throttle at idle for DISARM_DELAY s
                delay = self.params["DISARM_DELAY"]
                if delay > 0 and self._sim - v.disarm_timer_start >= delay:
                    self._disarm("disarm_delay")
                return
        v.disarm_timer_start = None
        if mode == MODES["GUIDED"]:
            self._guided_step(dt)
        elif mode == MODES["AUTO"]:
            self._auto_step(dt)
        elif mode == MODES["RTL"]:
            self._rtl_step(dt)
        elif mode == MODES["LAND"]:
            lt = v.land_target
            self._descend(dt, *(lt if lt else (None, None)))
        else:  # LOITER, BRAKE, ALT_HOLD, STABILIZE: hold (stand-in: no RC input, so hold position/altitude)
            if v.target is None:
                v.target = (v.north, v.east, v.alt)
            self._move_towards(*v.target, dt)
        v.max_alt = max(v.max_alt, v.alt)
        v.max_dist = max(v.max_dist, math.hypot(v.north, v.east))
        self._obstacle_step()

    def _wants_liftoff(self) -> bool:
        v = self.v
        if v.takeoff_alt is not None and v.mode in (MODES["GUIDED"], MODES["LOITER"], MODES["ALT_HOLD"]):
            return True
        if v.mode == MODES["AUTO"] and v.auto_armed and not self.mission_done() and 0 < self.mission_current < len(self.mission):
            return self.mission[self.mission_current]["command"] == mavlink.MAV_CMD_NAV_TAKEOFF
        return False

    def _guided_step(self, dt: float) -> None:
        v = self.v
        if v.vel_target is not None:
            if self._sim > v.vel_target_until:
                v.vel_target = None
                v.target = (v.north, v.east, v.alt)
            else:
                vn, ve, vd = v.vel_target
                v.north += vn * dt
                v.east += ve * dt
                v.alt = max(0.0, v.alt - vd * dt)
                v.vn, v.ve, v.vd = vn, ve, vd
                if math.hypot(vn, ve) > 0.5:
                    v.heading_deg = math.degrees(math.atan2(ve, vn)) % 360
                return
        if v.target is None:
            v.target = (v.north, v.east, v.alt)
        left = self._move_towards(*v.target, dt)
        if v.takeoff_alt is not None and v.alt >= v.takeoff_alt - 0.1:
            self.rec.add(self.wall(), self._sim, "takeoff_complete", alt=v.alt)
            v.takeoff_alt = None
        if left < 0.01 and v.target[2] <= 0.0 and v.alt <= 0.0:
            self._touchdown()

    def _rtl_step(self, dt: float) -> None:
        # ModeRTL stages (ArduCopter/mode_rtl.cpp): climb to RTL_ALT, return, loiter RTL_LOIT_TIME, descend, land
        v = self.v
        rtl_alt = max(self.params["RTL_ALT"] / 100.0, 0.0)
        if not v.rtl_stage:
            v.rtl_stage = "climb"
        if v.rtl_stage == "climb":
            target_alt = max(rtl_alt, v.alt)
            self._move_towards(v.north, v.east, target_alt, dt)
            if v.alt >= target_alt - 0.1:
                v.rtl_stage = "return"
                v.target = (0.0, 0.0, v.alt)
        elif v.rtl_stage == "return":
            if v.target is None:
                v.target = (0.0, 0.0, v.alt)
            left = self._move_towards(*v.target, dt)
            if left <= self.params["WPNAV_RADIUS"] / 100.0:
                v.rtl_stage = "loiter"
                v.rtl_loiter_until = self._sim + self.params["RTL_LOIT_TIME"] / 1000.0
        elif v.rtl_stage == "loiter":
            self._move_towards(0.0, 0.0, v.alt, dt)
            if self._sim >= v.rtl_loiter_until:
                v.rtl_stage = "land"
        else:
            self._descend(dt, 0.0, 0.0)

    def _battery_step(self, dt: float) -> None:
        v = self.v
        if not v.armed:
            current = 0.5
        elif v.landed:
            current = 3.0
        else:
            # stand-in hover current plus wind and climb load
            current = 14.0 + 0.6 * self.params["SIM_WIND_SPD"] + 4.0 * max(0.0, -v.vd)
        self._current_a = current
        v.consumed_ah += current * dt / 3600.0
        v.consumed_j += self._battery_voltage() * current * dt     # as AP_BattMonitor integrates V x I

    def _capacity_ah(self) -> float:
        cap = self.params["SIM_BATT_CAP_AH"]
        return cap if cap > 0 else self.params["BATT_CAPACITY"] / 1000.0

    def _battery_pct(self) -> int:
        cap = self._capacity_ah()
        return int(max(0.0, min(100.0, 100.0 * (1.0 - self.v.consumed_ah / cap))))

    def _battery_voltage(self) -> float:
        pct = self._battery_pct() / 100.0
        cells_full = self.params["SIM_BATT_VOLTAGE"]
        # stand-in discharge curve: 4.2 V/cell full, ~3.5 V/cell empty, sag under load
        return max(0.0, cells_full * (0.83 + 0.17 * pct) - 0.01 * getattr(self, "_current_a", 0.0))

    def _place_obstacle(self, distance_m: float) -> None:
        v = self.v
        h = math.radians(v.heading_deg)
        self.obstacle = (v.north + distance_m * math.cos(h), v.east + distance_m * math.sin(h))
        self.rec.add(self.wall(), self._sim, "obstacle", distance=distance_m, north=self.obstacle[0], east=self.obstacle[1])

    def _obstacle_distance(self) -> Optional[float]:
        """Distance to the obstacle if it lies in the forward sensor's +-20 deg cone and 40 m range."""
        if self.obstacle is None:
            return None
        v = self.v
        dn, de = self.obstacle[0] - v.north, self.obstacle[1] - v.east
        d = math.hypot(dn, de)
        if d < 0.05:
            return 0.0
        bearing = math.degrees(math.atan2(de, dn)) % 360
        off = abs((bearing - v.heading_deg + 180) % 360 - 180)
        if off > 20 or d > 40.0:
            return None
        return d

    def _obstacle_step(self) -> None:
        d = self._obstacle_distance()
        if d is not None and d < 1.0 and not self.v.collided:
            self.v.collided = True
            self.rec.add(self.wall(), self._sim, "collision", distance=d)

    # ----- geometry ------------------------------------------------------------------------------------

    def _latlon(self) -> Tuple[float, float]:
        lat0, lon0, _ = self.home
        lat = lat0 + math.degrees(self.v.north / EARTH_R)
        lon = lon0 + math.degrees(self.v.east / (EARTH_R * math.cos(math.radians(lat0))))
        return lat, lon

    def _ne_of(self, lat: float, lon: float) -> Tuple[float, float]:
        lat0, lon0, _ = self.home
        n = math.radians(lat - lat0) * EARTH_R
        e = math.radians(lon - lon0) * EARTH_R * math.cos(math.radians(lat0))
        return n, e

    def _alt_of_frame(self, alt: float, frame: int) -> float:
        if frame in (mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT):
            return alt - self.home[2]
        return alt
