"""Sending: STATUSTEXT, HEARTBEAT and the telemetry streams at their message intervals."""
from __future__ import annotations

import math
import time
from typing import Any, Optional

from .link import Link
from .vocabulary import (EKF_ALIGNING_FLAGS, EKF_OK_FLAGS, GUIDED_FLAG_MODES, HEARTBEAT_INTERVAL_S, MODES,
                         STREAM_SLOWDOWN_DURING_TRANSFER, mavlink)


class Telemetry:
    """The messages StandinAutopilot (mixed into it) builds from its state and sends."""

    # ----- sending ---------------------------------------------------------------------------------------

    def _statustext(self, text: str, severity: int) -> None:
        self.rec.add(self.wall(), self._sim, "statustext", text=text, severity=severity)
        msg = mavlink.MAVLink_statustext_message(severity, text.encode()[:50], 0, 0)
        for link in self.links:
            link.send(msg)

    def _heartbeat_msg(self) -> Any:
        v = self.v
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED | mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if v.mode in GUIDED_FLAG_MODES:
            base |= mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        if v.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink.MAV_STATE_ACTIVE if v.armed else mavlink.MAV_STATE_STANDBY
        if v.ekf_failsafe or self._battery_pct() < 10:
            status = mavlink.MAV_STATE_CRITICAL
        return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, base, v.mode, status, 3)

    def _autopilot_version(self) -> Any:
        caps = (mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2)
        if self.cfg.signing_key is not None:
            caps |= mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        return mavlink.MAVLink_autopilot_version_message(caps, 0x04050000, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0, [0] * 18)

    def _build(self, mid: int) -> Optional[Any]:
        v = self.v
        M = mavlink
        tboot = int(self._sim * 1000) & 0xFFFFFFFF
        lat, lon = self._latlon()
        gps_ok = self.params["SIM_GPS_DISABLE"] < 1
        if mid == M.MAVLINK_MSG_ID_SYS_STATUS:
            sensors = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_3D_MAG \
                | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE | M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_SENSOR_BATTERY \
                | M.MAV_SYS_STATUS_AHRS
            health = sensors
            if not gps_ok:
                health &= ~M.MAV_SYS_STATUS_SENSOR_GPS
            if not self._position_ok():
                health &= ~M.MAV_SYS_STATUS_AHRS
            if self._battery_pct() < 20:
                health &= ~M.MAV_SYS_STATUS_SENSOR_BATTERY
            # GCS::update_sensor_status_flags (libraries/GCS_MAVLink/GCS.cpp): the pre-arm bit is always present,
            # enabled when any arming check is (ARMING_CHECK != 0), healthy when armed or the checks pass.
            present, enabled = sensors | M.MAV_SYS_STATUS_PREARM_CHECK, sensors
            if self.params.get("ARMING_CHECK", 1):
                enabled |= M.MAV_SYS_STATUS_PREARM_CHECK
                if v.armed or self._prearm_failure() is None:
                    health |= M.MAV_SYS_STATUS_PREARM_CHECK
            return M.MAVLink_sys_status_message(present, enabled, health, 350, int(self._battery_voltage() * 1000),
                                                int(getattr(self, "_current_a", 0.0) * 100), self._battery_pct(), 0, 0, 0, 0, 0, 0, 0, 0, 0)
        if mid == M.MAVLINK_MSG_ID_GPS_RAW_INT:
            if gps_ok:
                fix, sats, eph = (3 if self._sim >= min(5.0, self.cfg.ekf_ready_s) else 1), 12, 70
            else:
                fix, sats, eph = 0, 0, 65535   # SIM_GPS_DISABLE: the GPS stops reporting a fix
            return M.MAVLink_gps_raw_int_message(int(self._sim * 1e6), fix, int(lat * 1e7) if gps_ok else 0,
                                                 int(lon * 1e7) if gps_ok else 0, int((self.home[2] + v.alt) * 1000),
                                                 eph, 100, int(math.hypot(v.vn, v.ve) * 100), int(v.heading_deg * 100) % 36000, sats)
        if mid == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            return M.MAVLink_global_position_int_message(tboot, int(lat * 1e7), int(lon * 1e7), int((self.home[2] + v.alt) * 1000),
                                                         int(v.alt * 1000), int(v.vn * 100), int(v.ve * 100), int(v.vd * 100),
                                                         int(v.heading_deg * 100) % 36000)
        if mid == M.MAVLINK_MSG_ID_ATTITUDE:
            return M.MAVLink_attitude_message(tboot, 0.0, 0.0, math.radians(v.heading_deg if v.heading_deg <= 180 else v.heading_deg - 360), 0.0, 0.0, 0.0)
        if mid == M.MAVLINK_MSG_ID_VFR_HUD:
            return M.MAVLink_vfr_hud_message(math.hypot(v.vn, v.ve), math.hypot(v.vn, v.ve), int(v.heading_deg) % 360,
                                             0 if not v.armed else (10 if v.landed else 45), self.home[2] + v.alt, -v.vd)
        if mid == M.MAVLINK_MSG_ID_BATTERY_STATUS:
            volt = self._battery_voltage()
            cells = [int(volt * 1000 / 3)] * 3 + [65535] * 7
            pct = self._battery_pct()
            charge = M.MAV_BATTERY_CHARGE_STATE_OK if pct > 20 else (M.MAV_BATTERY_CHARGE_STATE_LOW if pct > 10 else M.MAV_BATTERY_CHARGE_STATE_CRITICAL)
            return M.MAVLink_battery_status_message(0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 3000, cells,
                                                    int(getattr(self, "_current_a", 0.0) * 100), int(v.consumed_ah * 1000), int(v.consumed_j / 100), pct,
                                                    0, charge, [0, 0, 0, 0], 0, 0)
        if mid == M.MAVLINK_MSG_ID_VIBRATION:
            vib = self._vibration_level()
            if vib > 30.0:
                v.clipping += 1     # IMU clipping counters grow once vibration saturates the accelerometers
            return M.MAVLink_vibration_message(int(self._sim * 1e6), vib, vib * 0.9, vib * 1.2, v.clipping, 0, 0)
        if mid == M.MAVLINK_MSG_ID_EKF_STATUS_REPORT:
            if self._sim < self.cfg.ekf_ready_s:
                flags = EKF_ALIGNING_FLAGS
                var = 1.0
            elif not self._position_ok():
                flags = (EKF_OK_FLAGS & ~(M.EKF_POS_HORIZ_ABS | M.EKF_PRED_POS_HORIZ_ABS)) | M.EKF_CONST_POS_MODE
                var = 1.2
            else:
                flags = EKF_OK_FLAGS
                var = 0.05 if gps_ok else 0.6
            return M.MAVLink_ekf_status_report_message(flags, var, var, 0.05, 0.03, 0.0, 0.0)
        if mid == M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            if not v.armed or v.landed:
                landed = M.MAV_LANDED_STATE_ON_GROUND
            elif v.mode in (MODES["LAND"],) or (v.mode == MODES["RTL"] and v.rtl_stage == "land") or v.vd > 0.3:
                landed = M.MAV_LANDED_STATE_LANDING
            elif v.takeoff_alt is not None:
                landed = M.MAV_LANDED_STATE_TAKEOFF
            else:
                landed = M.MAV_LANDED_STATE_IN_AIR
            return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_MC, landed)
        if mid == M.MAVLINK_MSG_ID_MISSION_CURRENT:
            total = len(self.mission) - 1
            if len(self.mission) <= 1:
                state = M.MISSION_STATE_NO_MISSION
            elif self.mission_done():
                state = M.MISSION_STATE_COMPLETE
            elif v.mode == MODES["AUTO"] and v.armed:
                state = M.MISSION_STATE_ACTIVE
            else:
                state = M.MISSION_STATE_NOT_STARTED if self.mission_current <= 1 else M.MISSION_STATE_PAUSED
            seq = min(self.mission_current, max(0, len(self.mission) - 1))
            return M.MAVLink_mission_current_message(seq, total, state, 0)
        if mid == M.MAVLINK_MSG_ID_WIND:
            if not v.armed or v.landed:
                return None   # stand-in: the EKF only estimates wind in flight (EKF3 inhibits wind states on the ground)
            return M.MAVLink_wind_message(self.params["SIM_WIND_DIR"], self.params["SIM_WIND_SPD"], 0.0)
        if mid == M.MAVLINK_MSG_ID_DISTANCE_SENSOR:
            d = self._obstacle_distance()
            cm = 4001 if d is None else max(20, int(d * 100))   # out of range reads above max_distance
            return M.MAVLink_distance_sensor_message(tboot, 20, 4000, cm, M.MAV_DISTANCE_SENSOR_LASER, 0,
                                                     int(self.params["SIM_OBST_ORIENT"]), 0, 0.35, 0.35, [1, 0, 0, 0], 100)
        if mid == M.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return M.MAVLink_local_position_ned_message(tboot, v.north, v.east, -v.alt, v.vn, v.ve, v.vd)
        if mid == M.MAVLINK_MSG_ID_HOME_POSITION:
            hl, hn, ha = self.home
            return M.MAVLink_home_position_message(int(hl * 1e7), int(hn * 1e7), int(ha * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0)
        if mid == M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return M.MAVLink_system_time_message(int(time.time() * 1e6), tboot)
        return None

    def _vibration_level(self) -> float:
        v = self.v
        if not v.armed:
            return 0.0
        base = 1.0 if v.landed else 4.0
        mot = self.params["SIM_VIB_MOT_MAX"] * self.params["SIM_VIB_MOT_MULT"]
        # stand-in mapping: motor-noise frequency x scale -> m/s/s; VIB_MOT_MAX=250 gives ~ 30 (ArduPilot's "bad")
        return base + 0.105 * mot * (0.3 if v.landed else 1.0)

    def _send_msg(self, mid: int, link: Optional[Link] = None, force: bool = False) -> None:
        msg = self._build(mid)
        if msg is None:
            return
        for l in ([link] if link is not None else self.links):
            l.send(msg)

    def _telemetry(self) -> None:
        if not self.links:
            return
        now = self.wall()
        if now >= self._next_hb:
            self._next_hb = now + HEARTBEAT_INTERVAL_S
            hb = self._heartbeat_msg()
            for link in self.links:
                link.send(hb)
        slow = STREAM_SLOWDOWN_DURING_TRANSFER if self.upload is not None else 1
        for mid, ms in self.intervals_ms.items():
            if ms < 0:
                continue
            due = self._next_due.get(mid, 0.0)
            if now >= due:
                self._next_due[mid] = now + ms * slow / 1000.0
                self._send_msg(mid)
