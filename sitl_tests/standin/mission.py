"""The mission protocol (upload, download, clear, set current) and flying the mission in AUTO."""
from __future__ import annotations

import math
from typing import Any, Dict, Tuple

from .link import Link
from .vocabulary import (DO_COMMANDS, MISSION_MAX_ITEMS, MISSION_REREQUEST_S, MISSION_UPLOAD_TIMEOUT_S, MODES,
                         NAV_COMMANDS, SUPPORTED_FRAMES, mavlink)


class MissionProtocol:
    """Mission items of StandinAutopilot (mixed into it): item 0 is home, uploads follow
    MissionItemProtocol, AUTO flies the items in order."""

    # ----- mission protocol messages (libraries/GCS_MAVLink/MissionItemProtocol.cpp) --------------

    def _h_MISSION_COUNT(self, link: Link, m: Any) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        if m.mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, src, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)   # stand-in: no fence/rally
            return
        if self.upload is not None:
            if self.upload["src"] != src:
                # "someone is already uploading a mission ... otherwise we deny"
                self._mission_ack(link, src, mavlink.MAV_MISSION_DENIED)
                return
        if m.count > MISSION_MAX_ITEMS:
            self._mission_ack(link, src, mavlink.MAV_MISSION_NO_SPACE)
            self._statustext(f"Only {MISSION_MAX_ITEMS} items are supported", mavlink.MAV_SEVERITY_WARNING)
            return
        # truncate(): the stored mission is cut to the announced length before items arrive
        self.mission = self.mission[: max(1, m.count)]
        self.rec.add(self.wall(), self._sim, "mission_count", count=m.count, src=list(src), link=link.ident)
        if m.count == 0:
            self._mission_ack(link, src, mavlink.MAV_MISSION_ACCEPTED)
            self.rec.add(self.wall(), self._sim, "mission_upload", items=[], src=list(src), link=link.ident)
            return
        now = self.wall()
        self.upload = {"src": src, "link": link, "next": 0, "last": m.count - 1, "items": [],
                       "last_rx": now, "last_req": now}
        self._request_warning_sent = False
        self._item_warning_sent = False
        self._send_mission_request()

    def _h_MISSION_ITEM_INT(self, link: Link, m: Any) -> None:
        self._mission_item(link, m, is_int=True)

    def _h_MISSION_ITEM(self, link: Link, m: Any) -> None:
        if not self._item_warning_sent:
            # GCS_MAVLINK::handle_mission_item: MISSION_ITEM is converted, with a once-per-transfer warning
            self._statustext("got MISSION_ITEM; GCS should send MISSION_ITEM_INT", mavlink.MAV_SEVERITY_WARNING)
            self._item_warning_sent = True
        self._mission_item(link, m, is_int=False)

    def _h_MISSION_REQUEST_LIST(self, link: Link, m: Any) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        if self.upload is not None:
            self._mission_ack(link, src, mavlink.MAV_MISSION_DENIED)   # "reject fetching of points until done"
            return
        count = len(self.mission) if m.mission_type == mavlink.MAV_MISSION_TYPE_MISSION else 0
        self._request_warning_sent = False
        link.send(mavlink.MAVLink_mission_count_message(src[0], src[1], count, m.mission_type))

    def _h_MISSION_REQUEST_INT(self, link: Link, m: Any) -> None:
        self._mission_request(link, m, want_int=True)

    def _h_MISSION_REQUEST(self, link: Link, m: Any) -> None:
        if not self._request_warning_sent:
            # GCS_MAVLINK::handle_mission_request warns once per transfer (mission_request_warning_sent)
            self._statustext("got MISSION_REQUEST; use MISSION_REQUEST_INT!", mavlink.MAV_SEVERITY_WARNING)
            self._request_warning_sent = True
        self._mission_request(link, m, want_int=False)

    def _h_MISSION_CLEAR_ALL(self, link: Link, m: Any) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        running = self.v.mode == MODES["AUTO"] and self.v.armed and not self.v.landed
        ok = self.upload is None and not running   # AP_Mission::clear() refuses while the mission runs
        if ok:
            self.mission = [self._home_item()]
            self.mission_current = 0
        self.rec.add(self.wall(), self._sim, "mission_clear", ok=ok, src=list(src))
        self._mission_ack(link, src, mavlink.MAV_MISSION_ACCEPTED if ok else mavlink.MAV_MISSION_ERROR)

    def _h_MISSION_SET_CURRENT(self, link: Link, m: Any) -> None:
        ok = self._set_mission_current(m.seq)
        self.rec.add(self.wall(), self._sim, "mission_set_current", seq=m.seq, ok=ok)
        self._send_msg(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, link)

    def _h_MISSION_ACK(self, link: Link, m: Any) -> None:
        self.rec.add(self.wall(), self._sim, "mission_ack_rx", result=m.type)

    # ----- mission protocol helpers ----------------------------------------------------------------

    def _home_item(self) -> Dict[str, Any]:
        lat, lon, alt = self.home
        # home is item 0, absolute frame (AP_Mission::mission_cmd_to_mavlink_int for the stored home)
        return {"seq": 0, "frame": mavlink.MAV_FRAME_GLOBAL, "command": mavlink.MAV_CMD_NAV_WAYPOINT, "current": 0,
                "autocontinue": 1, "param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": 0.0,
                "x": int(round(lat * 1e7)), "y": int(round(lon * 1e7)), "z": float(alt), "mission_type": 0}

    def _mission_ack(self, link: Link, dest: Tuple[int, int], result: int, mission_type: int = 0) -> None:
        link.send(mavlink.MAVLink_mission_ack_message(dest[0], dest[1], result, mission_type))
        self.rec.add(self.wall(), self._sim, "mission_ack_tx", result=result, dest=list(dest))

    def _send_mission_request(self) -> None:
        up = self.upload
        if up is None:
            return
        dest = up["src"]
        if self.cfg.mission_request_int:
            msg = mavlink.MAVLink_mission_request_int_message(dest[0], dest[1], up["next"], 0)
        else:
            # MissionItemProtocol::queued_request_send sends the legacy MISSION_REQUEST
            msg = mavlink.MAVLink_mission_request_message(dest[0], dest[1], up["next"], 0)
        up["link"].send(msg)
        up["last_req"] = self.wall()

    def _mission_item(self, link: Link, m: Any, is_int: bool) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        up = self.upload
        if m.mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, src, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)
            return
        if up is None:
            # an item with no upload in progress: ArduPilot answers MAV_MISSION_ERROR via the routing of
            # handle_mission_item (no link); the stand-in answers so the sender learns
            self._mission_ack(link, src, mavlink.MAV_MISSION_ERROR)
            return
        if m.seq != up["next"]:
            self._mission_ack(link, src, mavlink.MAV_MISSION_INVALID_SEQUENCE)   # upload continues
            return
        if src != up["src"]:
            self._mission_ack(link, src, mavlink.MAV_MISSION_DENIED)
            return
        x, y = (m.x, m.y) if is_int else (int(round(m.x * 1e7)), int(round(m.y * 1e7)))
        item = {"seq": m.seq, "frame": m.frame, "command": m.command, "current": m.current, "autocontinue": m.autocontinue,
                "param1": m.param1, "param2": m.param2, "param3": m.param3, "param4": m.param4, "x": x, "y": y,
                "z": m.z, "mission_type": 0}
        result = self._check_item(item)
        if result != mavlink.MAV_MISSION_ACCEPTED:
            self._mission_ack(link, src, result)
            self.upload = None     # an item error ends the transfer ("receiving = false")
            self.rec.add(self.wall(), self._sim, "mission_upload_failed", seq=m.seq, result=result)
            return
        up["items"].append(item)
        up["last_rx"] = self.wall()
        up["next"] += 1
        if up["next"] > up["last"]:
            items = up["items"]
            self.mission = items if items else [self._home_item()]
            if self.v.armed:
                self.mission[0] = self._home_item()    # home is owned by the vehicle once set
            self.mission_current = min(self.mission_current, len(self.mission) - 1)
            self.upload = None
            self._statustext("Flight plan received", mavlink.MAV_SEVERITY_INFO)   # MissionItemProtocol_Waypoints::complete
            self._mission_ack(link, src, mavlink.MAV_MISSION_ACCEPTED)
            self.rec.add(self.wall(), self._sim, "mission_upload", items=items, src=list(src), link=link.ident,
                         int_items=is_int)
            return
        self._send_mission_request()

    def _check_item(self, item: Dict[str, Any]) -> int:
        # AP_Mission::mavlink_int_to_mission_cmd rejections
        if item["seq"] == 0:
            return mavlink.MAV_MISSION_ACCEPTED   # home slot: stored, replaced by the vehicle's home on arming
        if item["frame"] not in SUPPORTED_FRAMES:
            return mavlink.MAV_MISSION_UNSUPPORTED_FRAME
        cmd = item["command"]
        if cmd not in NAV_COMMANDS and cmd not in DO_COMMANDS:
            return mavlink.MAV_MISSION_UNSUPPORTED
        if cmd in NAV_COMMANDS and cmd not in (mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_DELAY):
            if abs(item["x"]) > 900000000:
                return mavlink.MAV_MISSION_INVALID_PARAM5_X
            if abs(item["y"]) > 1800000000:
                return mavlink.MAV_MISSION_INVALID_PARAM6_Y
        return mavlink.MAV_MISSION_ACCEPTED

    def _mission_request(self, link: Link, m: Any, want_int: bool) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        if self.upload is not None:
            self._mission_ack(link, src, mavlink.MAV_MISSION_DENIED)
            return
        if m.mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
            self._mission_ack(link, src, mavlink.MAV_MISSION_UNSUPPORTED, m.mission_type)
            return
        if m.seq != 0 and m.seq >= len(self.mission):
            # "try to educate the GCS on the actual size of the mission" (MissionItemProtocol_Waypoints::get_item)
            link.send(mavlink.MAVLink_mission_count_message(src[0], src[1], len(self.mission), 0))
            self._mission_ack(link, src, mavlink.MAV_MISSION_ERROR)
            return
        # seq 0 always reads back the vehicle's current home (AP_Mission::read_cmd_from_storage:
        # "special handling for command #0 which is home"), whatever was uploaded there
        it = self._home_item() if m.seq == 0 else dict(self.mission[m.seq])
        current = 1 if (m.seq == self.mission_current and m.seq != 0) else 0
        args = (src[0], src[1], m.seq, it["frame"], it["command"], current, 1, it["param1"], it["param2"], it["param3"], it["param4"])
        if want_int:
            link.send(mavlink.MAVLink_mission_item_int_message(*args, it["x"], it["y"], it["z"], 0))
        else:
            link.send(mavlink.MAVLink_mission_item_message(*args, it["x"] / 1e7, it["y"] / 1e7, it["z"], 0))

    def _mission_protocol_update(self) -> None:
        up = self.upload
        if up is None:
            return
        now = self.wall()
        if self.in_outage():
            return
        if now - up["last_rx"] > MISSION_UPLOAD_TIMEOUT_S:
            # MissionItemProtocol::update: timeout -> MAV_MISSION_OPERATION_CANCELLED + "Mission upload timeout"
            self.upload = None
            self._mission_ack(up["link"], up["src"], mavlink.MAV_MISSION_OPERATION_CANCELLED)
            self._statustext("Mission upload timeout", mavlink.MAV_SEVERITY_WARNING)
            self.rec.add(self.wall(), self._sim, "mission_upload_timeout", next=up["next"])
            return
        if now - up["last_req"] > MISSION_REREQUEST_S:
            self._send_mission_request()

    def _set_mission_current(self, seq: int) -> bool:
        if seq < 0 or seq >= len(self.mission) or (seq == 0 and len(self.mission) > 1):
            return False
        self.mission_current = seq
        self.mission_item_started = self._sim
        self.mission_delay_until = None
        return True

    # ----- AUTO mission flight ---------------------------------------------------------------------

    def mission_done(self) -> bool:
        return self.mission_current >= len(self.mission)

    def _auto_step(self, dt: float) -> None:
        v = self.v
        if self.mission_done() or len(self.mission) <= 1:
            # mission complete: hold position (ModeAuto::exit_mission -> loiter)
            if v.target is None:
                v.target = (v.north, v.east, v.alt)
            self._move_towards(*v.target, dt)
            return
        item = self.mission[self.mission_current]
        cmd = item["command"]
        done = False
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            alt = self._item_alt(item)
            self._move_towards(v.north, v.east, alt, dt)
            done = v.alt >= alt - 0.1
        elif cmd in (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_SPLINE_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM):
            n, e = self._item_ne(item)
            left = self._move_towards(n, e, self._item_alt(item), dt)
            if left <= self.params["WPNAV_RADIUS"] / 100.0:
                hold = item["param1"] if cmd in (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME) else float("inf")
                if self.mission_delay_until is None:
                    self.mission_delay_until = self._sim + max(0.0, hold)
                done = self._sim >= self.mission_delay_until
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            if item["x"] != 0 or item["y"] != 0:
                n, e = self._item_ne(item)
                if math.hypot(n - v.north, e - v.east) > 1.0:
                    self._move_towards(n, e, v.alt, dt)
                    return
                self._descend(dt, n, e)
            else:
                self._descend(dt)
            if v.landed:
                self._mission_item_reached()
                self.mission_current = len(self.mission)
            return
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._rtl_step(dt)
            return
        elif cmd == mavlink.MAV_CMD_DO_CHANGE_SPEED:
            if item["param2"] > 0:
                v.speed_override = item["param2"]
            done = True
        else:
            done = True      # DO_/CONDITION_ items: accepted, no effect on kinematics (stand-in)
        if done:
            if cmd in NAV_COMMANDS:
                self._mission_item_reached()
            self.mission_current += 1
            self.mission_item_started = self._sim
            self.mission_delay_until = None
            v.target = (v.north, v.east, v.alt)

    def _mission_item_reached(self) -> None:
        for link in self.links:
            link.send(mavlink.MAVLink_mission_item_reached_message(self.mission_current))
        self.rec.add(self.wall(), self._sim, "mission_item_reached", seq=self.mission_current)

    def _item_ne(self, item: Dict[str, Any]) -> Tuple[float, float]:
        if item["x"] == 0 and item["y"] == 0:
            return self.v.north, self.v.east    # lat/lon 0: "use current location" (AP_Mission)
        return self._ne_of(item["x"] / 1e7, item["y"] / 1e7)

    def _item_alt(self, item: Dict[str, Any]) -> float:
        return self._alt_of_frame(item["z"], item["frame"])
