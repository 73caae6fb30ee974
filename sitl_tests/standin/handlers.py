"""MAVLink message and command handlers (named ``_h_<TYPE>``), message intervals and parameters."""
from __future__ import annotations

import math
from typing import Any, List, Optional

from .link import Link
from .recording import jsonable
from .vocabulary import DEFAULT_INTERVALS_MS, KNOWN_NOT_GENERATED, MODES, mavlink


class MessageHandlers:
    """What StandinAutopilot (mixed into it) does with each message and command it is sent."""

    # ----- message handlers (named _h_<TYPE>) --------------------------------------------------------

    def _h_HEARTBEAT(self, link: Link, m: Any) -> None:
        pass

    def _h_COMMAND_LONG(self, link: Link, m: Any) -> None:
        params = [m.param1, m.param2, m.param3, m.param4, m.param5, m.param6, m.param7]
        self._command(link, m, m.command, params, frame=None, is_int=False, confirmation=m.confirmation)

    def _h_COMMAND_INT(self, link: Link, m: Any) -> None:
        params = [m.param1, m.param2, m.param3, m.param4, m.x, m.y, m.z]
        self._command(link, m, m.command, params, frame=m.frame, is_int=True, confirmation=0)

    def _h_SET_MODE(self, link: Link, m: Any) -> None:
        ok = self._change_mode(m.custom_mode, reason="SET_MODE")
        result = mavlink.MAV_RESULT_ACCEPTED if ok else mavlink.MAV_RESULT_FAILED
        # Quirk: ArduPilot acks the SET_MODE *message* with a COMMAND_ACK whose command is the message id 11
        # (GCS_MAVLINK::handle_set_mode, GCS_Common.cpp: "this is extraordinarily improper").
        hdr = m.get_header()
        link.send(mavlink.MAVLink_command_ack_message(mavlink.MAVLINK_MSG_ID_SET_MODE, result, 0, 0, hdr.srcSystem, hdr.srcComponent))
        self.rec.add(self.wall(), self._sim, "command", command=mavlink.MAVLINK_MSG_ID_SET_MODE, name="SET_MODE",
                     params=[m.base_mode, m.custom_mode], result=result, src=[hdr.srcSystem, hdr.srcComponent])

    def _h_PARAM_SET(self, link: Link, m: Any) -> None:
        name = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
        name = name.rstrip("\x00")
        known = self._set_param(name, float(m.param_value), source=f"link{link.ident}")
        if known:
            # GCS_Param.cpp handle_param_set -> gcs().send_parameter_value(): the new value goes out on every
            # channel, so a companion on another port hears a ground station's change (seen on ArduCopter 4.7 SITL)
            for each in list(self.links):
                self._send_param(each, name)
        # unknown names get no PARAM_VALUE back, as in GCS_MAVLINK::handle_param_set (GCS_Param.cpp)

    def _h_PARAM_REQUEST_READ(self, link: Link, m: Any) -> None:
        names = list(self.params)
        pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
        name = pid.rstrip("\x00") if m.param_index < 0 else (names[m.param_index] if 0 <= m.param_index < len(names) else None)
        if name in self.params and name not in self.held_param_reads:
            self._send_param(link, name)

    def _h_PARAM_REQUEST_LIST(self, link: Link, m: Any) -> None:
        for name in self.params:
            self._send_param(link, name)

    def _h_SET_POSITION_TARGET_GLOBAL_INT(self, link: Link, m: Any) -> None:
        self.rec.add(self.wall(), self._sim, "position_target", frame=m.coordinate_frame, type_mask=m.type_mask,
                     lat=m.lat_int / 1e7, lon=m.lon_int / 1e7, alt=m.alt, vx=m.vx, vy=m.vy, vz=m.vz)
        if self.v.mode != MODES["GUIDED"]:
            return   # ignored outside GUIDED (GCS_MAVLINK_Copter::handle_message, ArduCopter/GCS_Mavlink.cpp)
        pos_ignored = (m.type_mask & 0b111) == 0b111
        vel_ignored = (m.type_mask & 0b111000) == 0b111000
        if not pos_ignored:
            n, e = self._ne_of(m.lat_int / 1e7, m.lon_int / 1e7)
            self._guided_goto(n, e, self._alt_of_frame(m.alt, m.coordinate_frame))
        elif not vel_ignored:
            self._guided_velocity(m.vx, m.vy, m.vz)

    def _h_SET_POSITION_TARGET_LOCAL_NED(self, link: Link, m: Any) -> None:
        self.rec.add(self.wall(), self._sim, "position_target", frame=m.coordinate_frame, type_mask=m.type_mask,
                     x=m.x, y=m.y, z=m.z, vx=m.vx, vy=m.vy, vz=m.vz)
        if self.v.mode != MODES["GUIDED"]:
            return
        pos_ignored = (m.type_mask & 0b111) == 0b111
        vel_ignored = (m.type_mask & 0b111000) == 0b111000
        if not pos_ignored:
            if m.coordinate_frame in (mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED):
                n, e, alt = self.v.north + m.x, self.v.east + m.y, self.v.alt - m.z
            else:
                n, e, alt = m.x, m.y, -m.z
            self._guided_goto(n, e, alt)
        elif not vel_ignored:
            self._guided_velocity(m.vx, m.vy, m.vz)

    def _h_REQUEST_DATA_STREAM(self, link: Link, m: Any) -> None:
        pass   # legacy stream-rate request: accepted, rates unchanged (stand-in)

    # mission protocol (libraries/GCS_MAVLink/MissionItemProtocol.cpp)

    # ----- commands --------------------------------------------------------------------------------

    def _command(self, link: Link, m: Any, cmd: int, p: List[float], frame: Optional[int], is_int: bool, confirmation: int) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        result = self._do_command(link, cmd, p, frame, is_int)
        if result is not None:
            link.send(mavlink.MAVLink_command_ack_message(cmd, result, 0, 0, src[0], src[1]))
        name = mavlink.enums["MAV_CMD"][cmd].name if cmd in mavlink.enums["MAV_CMD"] else str(cmd)
        self.rec.add(self.wall(), self._sim, "command", command=cmd, name=name, params=[jsonable(x) for x in p],
                     frame=frame, is_int=is_int, confirmation=confirmation, result=result, src=list(src),
                     signed=bool(getattr(m, "_signed", False)))

    def _do_command(self, link: Link, cmd: int, p: List[float], frame: Optional[int], is_int: bool) -> Optional[int]:
        R = mavlink
        v = self.v
        if cmd == R.MAV_CMD_COMPONENT_ARM_DISARM:
            force = int(round(p[1])) == 21196
            if p[0] == 1.0:
                return R.MAV_RESULT_ACCEPTED if self._arm(force) else R.MAV_RESULT_FAILED
            if p[0] == 0.0:
                # AP_Arming_Copter::disarm: a MAVLink disarm in flight is refused unless forced
                if not v.armed:
                    return R.MAV_RESULT_ACCEPTED
                if not v.landed and not force:
                    return R.MAV_RESULT_FAILED
                self._disarm("mavlink")
                return R.MAV_RESULT_ACCEPTED
            return R.MAV_RESULT_UNSUPPORTED
        if cmd == R.MAV_CMD_DO_SET_MODE:
            return R.MAV_RESULT_ACCEPTED if self._change_mode(int(p[1]), reason="DO_SET_MODE") else R.MAV_RESULT_FAILED
        if cmd == R.MAV_CMD_NAV_TAKEOFF:
            # GCS_MAVLINK_Copter::handle_MAV_CMD_NAV_TAKEOFF (ArduCopter/GCS_Mavlink.cpp): COMMAND_INT must use
            # MAV_FRAME_GLOBAL_RELATIVE_ALT (else DENIED; COMMAND_LONG is given that frame); then
            # Mode::do_user_takeoff (ArduCopter/takeoff.cpp) fails unless armed, landed, and the mode has a user
            # takeoff: GUIDED and LOITER always, ALT_HOLD only when param3 (pilot may navigate) is non-zero.
            if is_int and frame != R.MAV_FRAME_GLOBAL_RELATIVE_ALT:
                return R.MAV_RESULT_DENIED
            user_takeoff = v.mode in (MODES["GUIDED"], MODES["LOITER"]) or (v.mode == MODES["ALT_HOLD"] and p[2] != 0)
            if not v.armed or not v.landed or not user_takeoff:
                return R.MAV_RESULT_FAILED
            alt = p[6]
            if alt <= 0:
                return R.MAV_RESULT_FAILED
            v.takeoff_alt = alt
            v.auto_armed = True
            v.landed = False
            v.landed_since = None
            v.target = (v.north, v.east, alt)
            self.rec.add(self.wall(), self._sim, "takeoff", alt=alt)
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_NAV_LAND:
            return R.MAV_RESULT_ACCEPTED if self._change_mode(MODES["LAND"], reason="NAV_LAND") else R.MAV_RESULT_FAILED
        if cmd == R.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return R.MAV_RESULT_ACCEPTED if self._change_mode(MODES["RTL"], reason="NAV_RTL") else R.MAV_RESULT_FAILED
        if cmd == R.MAV_CMD_MISSION_START:
            # GCS_MAVLINK_Copter: MISSION_START switches to AUTO and sets auto_armed so a landed copter starts
            if len(self.mission) <= 1:
                return R.MAV_RESULT_FAILED
            if not self._change_mode(MODES["AUTO"], reason="MISSION_START"):
                return R.MAV_RESULT_FAILED
            v.auto_armed = True
            if self.mission_current == 0:
                self._set_mission_current(1)
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_DO_SET_MISSION_CURRENT:
            return R.MAV_RESULT_ACCEPTED if self._set_mission_current(int(p[0])) else R.MAV_RESULT_FAILED
        if cmd == R.MAV_CMD_DO_REPOSITION:
            # handle_command_int_do_reposition (ArduCopter/GCS_Mavlink.cpp): GUIDED only unless
            # MAV_DO_REPOSITION_FLAGS_CHANGE_MODE is set; then switches to GUIDED.
            if v.mode != MODES["GUIDED"]:
                if not (int(p[1]) & R.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE):
                    return R.MAV_RESULT_DENIED
                if not self._change_mode(MODES["GUIDED"], reason="DO_REPOSITION"):
                    return R.MAV_RESULT_FAILED
            if not v.armed or v.landed:
                return R.MAV_RESULT_FAILED
            lat, lon = (p[4] / 1e7, p[5] / 1e7) if is_int else (p[4], p[5])
            if lat == 0 and lon == 0:
                n, e = v.north, v.east
            else:
                n, e = self._ne_of(lat, lon)
            alt = v.alt if math.isnan(p[6]) else self._alt_of_frame(p[6], frame if frame is not None else R.MAV_FRAME_GLOBAL_RELATIVE_ALT)
            if p[0] > 0:
                v.speed_override = p[0]
            self._guided_goto(n, e, alt)
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_DO_CHANGE_SPEED:
            if p[1] > 0:
                v.speed_override = p[1]
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_CONDITION_YAW:
            v.heading_deg = p[0] % 360
            return R.MAV_RESULT_ACCEPTED
        if cmd in (R.MAV_CMD_DO_SET_ROI, R.MAV_CMD_DO_SET_ROI_LOCATION, R.MAV_CMD_DO_SET_ROI_NONE,
                   R.MAV_CMD_DO_MOUNT_CONTROL, R.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW):
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_DO_SET_HOME:
            if p[0] == 1:
                lat, lon = self._latlon()
                self.home = (lat, lon, self.home[2] + v.alt)
            else:
                lat, lon = (p[4] / 1e7, p[5] / 1e7) if is_int else (p[4], p[5])
                self.home = (lat, lon, p[6])
            self.mission[0] = self._home_item()
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_interval(int(p[0]), p[1])
        if cmd == R.MAV_CMD_GET_MESSAGE_INTERVAL:
            mid = int(p[0])
            if mid not in self.intervals_ms:
                return R.MAV_RESULT_FAILED
            ms = self.intervals_ms[mid]
            link.send(mavlink.MAVLink_message_interval_message(mid, -1 if ms < 0 else ms * 1000))
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_REQUEST_MESSAGE:
            mid = int(p[0])
            if mid == R.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
                link.send(self._autopilot_version())
                return R.MAV_RESULT_ACCEPTED
            if mid == R.MAVLINK_MSG_ID_HEARTBEAT:
                link.send(self._heartbeat_msg())
                return R.MAV_RESULT_ACCEPTED
            if mid not in self.intervals_ms:
                return R.MAV_RESULT_FAILED
            self._send_msg(mid, link, force=True)
            return R.MAV_RESULT_ACCEPTED
        if cmd == R.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            link.send(self._autopilot_version())
            return R.MAV_RESULT_ACCEPTED
        return R.MAV_RESULT_UNSUPPORTED

    def _set_interval(self, mid: int, interval_us: float) -> int:
        # GCS_MAVLINK::set_message_interval (GCS_Common.cpp): -1 disables, 0 restores the default,
        # otherwise interval in us; an id with no ap_message fails with a STATUSTEXT.
        if mid not in DEFAULT_INTERVALS_MS and mid != mavlink.MAVLINK_MSG_ID_HEARTBEAT and mid not in KNOWN_NOT_GENERATED:
            self._statustext(f"No ap_message for mavlink id ({mid})", mavlink.MAV_SEVERITY_INFO)
            return mavlink.MAV_RESULT_FAILED
        if mid == mavlink.MAVLINK_MSG_ID_HEARTBEAT or mid in KNOWN_NOT_GENERATED:
            self.rec.add(self.wall(), self._sim, "interval", msgid=mid, ms=None)
            return mavlink.MAV_RESULT_ACCEPTED   # stand-in: heartbeat stays 1 Hz; the others are never generated
        if interval_us < 0:
            self.intervals_ms[mid] = -1
        elif interval_us == 0:
            self.intervals_ms[mid] = DEFAULT_INTERVALS_MS[mid]
        else:
            self.intervals_ms[mid] = max(1, min(60000, int(interval_us / 1000)))
        self._next_due.pop(mid, None)
        self.rec.add(self.wall(), self._sim, "interval", msgid=mid, ms=self.intervals_ms[mid])
        return mavlink.MAV_RESULT_ACCEPTED

    # ----- params ------------------------------------------------------------------------------------

    def _set_param(self, name: str, value: float, source: str) -> bool:
        if name not in self.params:
            self.rec.add(self.wall(), self._sim, "param", name=name, value=value, known=False, source=source)
            return False
        self.params[name] = value
        self.rec.add(self.wall(), self._sim, "param", name=name, value=value, known=True, source=source)
        v = self.v
        if name == "SIM_GPS_DISABLE":
            if value >= 1 and v.gps_lost_since is None:
                v.gps_lost_since = self._sim
            elif value < 1:
                v.gps_lost_since = None
        elif name == "SIM_BATT_PCT" and value >= 0:
            v.consumed_ah = self._capacity_ah() * (1.0 - min(100.0, value) / 100.0)
            # as AP_BattMonitor_Backend::reset_remaining: the energy at the present voltage
            v.consumed_j = v.consumed_ah * 3600.0 * self._battery_voltage()
        elif name == "SIM_OBST_DIST":
            if value > 0:
                self._place_obstacle(value)
            else:
                self.obstacle = None
        elif name == "DISARM_DELAY":
            self.cfg.disarm_delay_s = value
        elif name == "SIM_SPEEDUP" and value > 0:
            self.cfg.speedup = value
        return True

    def _send_param(self, link: Link, name: str) -> None:
        names = list(self.params)
        link.send(mavlink.MAVLink_param_value_message(name.encode(), self.params[name], mavlink.MAV_PARAM_TYPE_REAL32,
                                                      len(names), names.index(name)))
