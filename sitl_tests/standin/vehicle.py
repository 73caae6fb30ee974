"""The vehicle: its state, arming, and flight-mode changes."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

from .vocabulary import MODE_NAMES, MODES, NOT_ARMABLE, POSITION_MODES, PREARM_DISPLAY_PERIOD_S, mavlink


@dataclass
class Vehicle:
    north: float = 0.0
    east: float = 0.0
    alt: float = 0.0                 # m above home
    vn: float = 0.0
    ve: float = 0.0
    vd: float = 0.0                  # NED, down positive
    heading_deg: float = 0.0
    armed: bool = False
    landed: bool = True
    mode: int = MODES["STABILIZE"]
    auto_armed: bool = False         # Copter ap.auto_armed: set by takeoff / MISSION_START
    takeoff_alt: Optional[float] = None
    target: Optional[Tuple[float, float, float]] = None      # GUIDED position target (n, e, alt)
    vel_target: Optional[Tuple[float, float, float]] = None  # GUIDED velocity target (vn, ve, vd)
    vel_target_until: float = 0.0
    speed_override: Optional[float] = None                   # DO_CHANGE_SPEED
    consumed_ah: float = 0.0
    consumed_j: float = 0.0     # energy drawn (BATTERY_STATUS.energy_consumed, hJ on the wire)
    rtl_stage: str = ""
    rtl_loiter_until: float = 0.0
    land_target: Optional[Tuple[float, float]] = None
    landed_since: Optional[float] = None
    disarm_timer_start: Optional[float] = None
    gps_lost_since: Optional[float] = None
    ekf_failsafe: bool = False
    max_alt: float = 0.0
    max_dist: float = 0.0
    clipping: int = 0
    collided: bool = False


class ArmingAndModes:
    """Pre-arm checks, arming, disarming and mode changes of StandinAutopilot (mixed into it), as ArduCopter
    does them."""

    def _position_ok(self) -> bool:
        v = self.v
        if self._sim < self.cfg.ekf_ready_s:
            return False
        if v.gps_lost_since is not None and self._sim - v.gps_lost_since >= self.cfg.gps_loss_ekf_s:
            return False
        return True

    def _prearm_failure(self) -> Optional[str]:
        """The first failing pre-arm check as ArduPilot words it, or None when they pass. Pre-arm checks
        depend on the current mode (AP_Arming_Copter::mandatory_gps_checks asks Mode::requires_GPS)."""
        v = self.v
        # AP_Arming_Copter::mandatory_gps_checks: a position mode needs a position estimate;
        # reported as "PreArm: Need Position Estimate" (ArduCopter/AP_Arming_Copter.cpp)
        if v.mode in POSITION_MODES and not self._position_ok():
            return "PreArm: Need Position Estimate"
        if self.params.get("SIM_GPS_DISABLE", 0) >= 1 and v.mode in POSITION_MODES:
            return "PreArm: GPS 1: Bad fix"
        if self._sim < self.cfg.ekf_ready_s:
            # stand-in simplification: before the EKF has aligned, non-position modes fail the AHRS
            # pre-arm check (AP_Arming::ins_checks/ahrs "AHRS: waiting for home") rather than passing
            return "PreArm: AHRS: waiting for home"
        return None

    def _prearm_display(self) -> None:
        """AP_Arming_Copter::update runs the pre-arm checks at 1 Hz and, while disarmed, displays the failure
        every PREARM_DISPLAY_PERIOD (30 s; the counter starts at half, so the first one comes after 15 s)."""
        if self._sim < self._prearm_next_display:
            return
        self._prearm_next_display += PREARM_DISPLAY_PERIOD_S
        if self.v.armed or not self.params.get("ARMING_CHECK", 1):
            return
        why = self._prearm_failure()
        if why is not None:
            self._statustext(why, mavlink.MAV_SEVERITY_CRITICAL)

    def _arm(self, force: bool) -> bool:
        v = self.v
        if v.armed:
            return True
        if not force:
            # AP_Arming_Copter::arm_checks: check_failed(true, "%s mode not armable", flightmode->name())
            if v.mode in NOT_ARMABLE:
                self._statustext(f"Arm: {MODE_NAMES[v.mode]} mode not armable", mavlink.MAV_SEVERITY_CRITICAL)
                return False
            why = self._prearm_failure()
            if why is not None:
                self._statustext(why, mavlink.MAV_SEVERITY_CRITICAL)
                return False
        v.armed = True
        v.landed = True
        v.auto_armed = False
        v.takeoff_alt = None
        v.disarm_timer_start = self._sim
        # home is set to the current location on arming (AP_Arming::arm -> set_home_to_current_location)
        lat, lon = self._latlon()
        self.home = (lat, lon, self.home[2])
        v.north = v.east = 0.0
        if self.obstacle is not None:
            self.obstacle = None
        self.mission[0] = self._home_item()
        self.rec.add(self.wall(), self._sim, "arm", force=force, mode=MODE_NAMES.get(v.mode))
        return True

    def _disarm(self, reason: str) -> None:
        v = self.v
        if not v.armed:
            return
        v.armed = False
        v.auto_armed = False
        v.takeoff_alt = None
        v.target = None
        v.vel_target = None
        v.vn = v.ve = v.vd = 0.0
        self.rec.add(self.wall(), self._sim, "disarm", reason=reason, alt=v.alt)
        if reason == "disarm_delay":
            self._statustext("Disarming motors", mavlink.MAV_SEVERITY_INFO)

    def _change_mode(self, mode: int, reason: str) -> bool:
        v = self.v
        if mode not in MODE_NAMES:
            self._statustext(f"Mode change to {mode} failed: unsupported", mavlink.MAV_SEVERITY_WARNING)
            return False
        if mode in POSITION_MODES and not self._position_ok() and v.armed:
            # Copter::set_mode (ArduCopter/mode.cpp): "ignore_checks = !motors->armed(); allow switching to any
            # mode if disarmed. We rely on the arming check"; armed: mode_change_failed(.., "requires position")
            self._statustext(f"Mode change to {MODE_NAMES[mode]} failed: requires position", mavlink.MAV_SEVERITY_WARNING)
            return False
        if mode == MODES["AUTO"] and v.armed and v.landed:
            # ModeAuto::init: on the ground armed, the mission must start with a takeoff (mode_auto.cpp)
            first = self.mission[1]["command"] if len(self.mission) > 1 else None
            if first != mavlink.MAV_CMD_NAV_TAKEOFF:
                self._statustext("Auto: Missing Takeoff Cmd", mavlink.MAV_SEVERITY_CRITICAL)
                return False
        old = v.mode
        v.mode = mode
        v.target = None
        v.vel_target = None
        v.rtl_stage = ""
        v.land_target = None
        if mode in (MODES["LOITER"], MODES["BRAKE"], MODES["GUIDED"], MODES["ALT_HOLD"]) and not v.landed:
            v.target = (v.north, v.east, v.alt)
        if mode == MODES["AUTO"]:
            if self.mission_current == 0 and len(self.mission) > 1:
                self._set_mission_current(1)
            else:
                self.mission_item_started = self._sim
                self.mission_delay_until = None
        if mode == MODES["RTL"]:
            v.rtl_stage = "climb"
        if mode == MODES["LAND"]:
            v.land_target = (v.north, v.east)
        self.rec.add(self.wall(), self._sim, "mode", old=MODE_NAMES.get(old), new=MODE_NAMES[mode], reason=reason)
        return True

    def _guided_goto(self, n: float, e: float, alt: float) -> None:
        v = self.v
        v.target = (n, e, alt)
        v.vel_target = None

    def _guided_velocity(self, vn: float, ve: float, vd: float) -> None:
        v = self.v
        v.vel_target = (vn, ve, vd)
        v.target = None
        # GUIDED velocity commands time out after 3 s (GUIDED_POSVEL_TIMEOUT_MS, mode_guided.cpp)
        v.vel_target_until = self._sim + 3.0 * 1.0
