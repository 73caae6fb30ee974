"""Onboard monitors: the camera/tracking application, as another component of the same system."""
from __future__ import annotations

import threading
import time
from typing import Any, Dict, Optional, Tuple

from .link import accept_unsigned
from .vocabulary import MODE_NAMES, mavlink

MONITOR_NAMES = ("tgt_det", "tgt_spd", "trk_conf", "lum", "cpu_load")
# Sensor drivers' failure reports (1 = failed): sent only once a scenario sets them, as a driver
# reports a failure, so a flight without one carries no failure observation at all.
REPORT_NAMES = ("lidar_fail", "cam_fail", "gps_fail")


class OnboardMonitors:
    """Sends NAMED_VALUE_FLOAT `tgt_det` (0/1), `tgt_spd` (m/s, target speed relative to the drone),
    `trk_conf` (0..1), `lum` (lux) and `cpu_load` (0..1) from compid 100 (MAV_COMP_ID_CAMERA) of the
    vehicle's system, through the autopilot, which routes broadcasts to the companion's link
    (MAVLink_routing.cpp). It also keeps a view of the vehicle from the telemetry it hears, so scenario
    scripts work the same against the stand-in and a real SITL."""

    def __init__(self, url: str, sysid: int = 1, compid: int = mavlink.MAV_COMP_ID_CAMERA,
                 signing_key: Optional[bytes] = None, rate_hz: float = 2.0, request_streams: bool = False) -> None:
        from pymavlink import mavutil
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid, dialect="ardupilotmega",
                                               autoreconnect=True)
        self.conn.mav.robust_parsing = True
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=accept_unsigned)
        self.values: Dict[str, float] = {"tgt_det": 0.0, "tgt_spd": 0.0, "trk_conf": 0.0, "lum": 600.0, "cpu_load": 0.3}
        self.view: Dict[str, Any] = {"armed": False, "mode": None, "alt": 0.0, "mission_seq": 0, "landed_state": 0,
                                     "heartbeats": 0, "airborne_since": None, "battery_consumed_mah": None,
                                     "battery_pct": None, "modes": []}
        # On a real SITL the monitors' port (SERIAL2) streams at its SR2_* rates, which may be 0: ask for what the
        # view needs with SET_MESSAGE_INTERVAL. Off for the stand-in, whose intervals are vehicle-wide.
        self.request_streams = request_streams
        self._streams_requested = False
        self.sysid = sysid
        self._param_values: Dict[str, Tuple[float, float]] = {}    # name -> (value, time received)
        self.sent = 0
        self.rate_hz = rate_hz
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, name="onboard-monitors", daemon=True)
        self._t0 = time.monotonic()

    def start(self) -> "OnboardMonitors":
        self._t.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._t.join(timeout=5)
        try:
            self.conn.close()
        except Exception:
            pass

    def set(self, **values: float) -> None:
        with self._lock:
            for k, val in values.items():
                if k not in MONITOR_NAMES + REPORT_NAMES:
                    raise KeyError(f"unknown monitor value {k!r}; known: {MONITOR_NAMES + REPORT_NAMES}")
                self.values[k] = float(val)

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            v = dict(self.view)
            v["modes"] = list(self.view["modes"])
            return v

    def param_set(self, name: str, value: float) -> None:
        """PARAM_SET to the autopilot over this link: how a test sets SITL's SIM_* (or vehicle) parameters on a
        real SITL. ArduPilot takes PARAM_SET from any component (GCS_MAVLINK::handle_param_set, GCS_Param.cpp)."""
        self.conn.mav.param_set_send(self.sysid, mavlink.MAV_COMP_ID_AUTOPILOT1, name.encode(), float(value),
                                     mavlink.MAV_PARAM_TYPE_REAL32)

    def param_get(self, name: str, timeout: float = 5.0) -> Optional[float]:
        """PARAM_REQUEST_READ, then the PARAM_VALUE answer (None on timeout)."""
        t0 = time.monotonic()
        self.conn.mav.param_request_read_send(self.sysid, mavlink.MAV_COMP_ID_AUTOPILOT1, name.encode(), -1)
        while time.monotonic() < t0 + timeout:
            with self._lock:
                got = self._param_values.get(name)
            if got is not None and got[1] >= t0:
                return got[0]
            time.sleep(0.02)
        return None

    def _request_streams(self) -> None:
        for mid in (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, mavlink.MAVLINK_MSG_ID_BATTERY_STATUS):
            self.conn.mav.command_long_send(self.sysid, mavlink.MAV_COMP_ID_AUTOPILOT1,
                                            mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, mid, 500_000, 0, 0, 0, 0, 0)

    def _run(self) -> None:
        next_send = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_send:
                next_send = now + 1.0 / self.rate_hz
                with self._lock:
                    vals = dict(self.values)
                tboot = int((now - self._t0) * 1000)
                try:
                    for name, val in vals.items():
                        self.conn.mav.named_value_float_send(tboot, name.encode(), val)
                        self.sent += 1
                    # a component heartbeat so routers learn where compid 100 lives
                    self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_CAMERA, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
                except Exception:
                    pass
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.05)
            except Exception:
                m = None
            if m is None:
                continue
            t = m.get_type()
            with self._lock:
                v = self.view
                if t == "HEARTBEAT" and m.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1:
                    v["heartbeats"] += 1
                    v["armed"] = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    mode = MODE_NAMES.get(m.custom_mode, str(m.custom_mode))
                    if mode != v["mode"]:
                        v["modes"].append((time.monotonic(), mode))
                    v["mode"] = mode
                    if self.request_streams and not self._streams_requested:
                        self._streams_requested = True
                        try:
                            self._request_streams()
                        except Exception:
                            self._streams_requested = False
                elif t == "PARAM_VALUE":
                    pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
                    self._param_values[pid.rstrip("\x00")] = (m.param_value, time.monotonic())
                elif t == "BATTERY_STATUS":
                    v["battery_consumed_mah"] = m.current_consumed if m.current_consumed >= 0 else None
                    v["battery_pct"] = m.battery_remaining if m.battery_remaining >= 0 else None
                elif t == "GLOBAL_POSITION_INT":
                    v["alt"] = m.relative_alt / 1000.0
                    if v["alt"] > 2.0 and v["airborne_since"] is None:
                        v["airborne_since"] = time.monotonic()
                elif t == "MISSION_CURRENT":
                    v["mission_seq"] = m.seq
                elif t == "EXTENDED_SYS_STATE":
                    v["landed_state"] = m.landed_state
