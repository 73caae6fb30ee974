"""Shared helpers for sitl_tests: a small pymavlink ground-station client, the decision-log reader and the
single place where the `companion fly` command line is built."""
from __future__ import annotations

import glob
import json
import os
import threading
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

# ------------------------------------------------------------------------------------------------
# `companion fly` command line: THE one place the flags live (the Rust CLI is still being finalised).
# ------------------------------------------------------------------------------------------------

def companion_fly_cmd(exe: str, connect_url: str, log_dir: Path, mission: Optional[Path] = None,
                      signing_key_file: Optional[Path] = None, extra: Iterable[str] = (),
                      auto_start: bool = True, once: bool = True) -> List[str]:
    # --auto-start: the tests fly without an operator (the operator-start tests pass auto_start=False).
    # --once: exit after one flight (landed and disarmed) instead of waiting for the operator again.
    cmd = [exe, "fly", "--connect", connect_url, "--log-dir", str(log_dir)]
    if auto_start:
        cmd.append("--auto-start")
    if once:
        cmd.append("--once")
    if mission is not None:
        cmd += ["--mission", str(mission)]
    if signing_key_file is not None:
        # a file holding the 32-byte MAVLink 2 secret key as 64 hex digits
        cmd += ["--signing-key", str(signing_key_file)]
    return cmd + list(extra)


# Seconds of silence after which the companion counts the autopilot as lost (`fly --link-timeout`, default 3s).
COMPANION_LINK_TIMEOUT_S = 3.0


# ------------------------------------------------------------------------------------------------
# Decision log (JSON Lines of DecisionRecord, companion-core/src/record.rs); a header line without `cycle` is skipped.
# ------------------------------------------------------------------------------------------------

def said(value: Any) -> Any:
    """The sentence of a typed event, link event or command outcome (schema 2 writes each as an object
    with `kind`, its fields and `text`, the sentence for people); a sentence (schema 1) as it is."""
    return value.get("text", "") if isinstance(value, dict) else value


def sentences(record: Dict[str, Any]) -> Dict[str, Any]:
    """The record with its events, link events and command results as the sentences the tests assert on."""
    for key in ("events", "link_events"):
        if isinstance(record.get(key), list):
            record[key] = [said(e) for e in record[key]]
    for c in record.get("commands") or []:
        if isinstance(c, dict) and "result" in c:
            c["result"] = said(c["result"])
    return record


def read_decision_log(log_dir: Path, fallback: Optional[Path] = None, typed: bool = False) -> List[Dict[str, Any]]:
    """Records from every *.jsonl under `log_dir`; when there is none, from `fallback` (the run's stdout,
    where `fly` writes JSON lines when no log dir is given). Events, link events and command results are
    given as their sentences (`sentences`), or as written (`typed`: schema 2's objects with `kind` and fields)."""
    records: List[Dict[str, Any]] = []
    files = sorted(glob.glob(str(Path(log_dir) / "**" / "*.jsonl"), recursive=True))
    if not files and fallback is not None and Path(fallback).exists():
        files = [str(fallback)]
    for f in files:
        with open(f) as fh:
            for n, raw in enumerate(fh, 1):
                line = raw.strip()
                if not line:
                    continue
                if f == str(fallback) and not line.startswith("{"):
                    continue                      # human output mixed into stdout
                try:
                    obj = json.loads(line)
                except json.JSONDecodeError as e:
                    if not raw.endswith("\n"):
                        break                     # the last line, still being written by a running companion
                    raise AssertionError(f"{f}:{n}: decision log line is not JSON: {e}: {line[:200]}")
                if isinstance(obj, dict) and "cycle" in obj:
                    records.append(obj if typed else sentences(obj))
    return records


def all_actions(records: List[Dict[str, Any]]) -> List[str]:
    # what ran: the MDPs' actions and the shell's own safety actions (the flight's end, a landing kept up)
    return [a for r in records for a in r.get("actions", []) + r.get("shell_actions", [])]


def tracking_versions(records: List[Dict[str, Any]]) -> set:
    """Tracking versions seen: from `track_vN` primitive actions and from resource placements of app `tracking`."""
    seen = set()
    for r in records:
        for a in r.get("actions", []):
            if a.startswith("track_v"):
                seen.add("V" + a[len("track_v"):])
        res = r.get("resources") or {}
        for p in res.get("placements", []) or []:
            if p.get("app") == "tracking":
                seen.add(p.get("version"))
    return seen


# ------------------------------------------------------------------------------------------------
# A ground-station-like pymavlink client with a background reader that keeps every message.
# ------------------------------------------------------------------------------------------------

class GcsClient:
    def __init__(self, url: str, sysid: int = 255, compid: int = 190, signing_key: Optional[bytes] = None,
                 target: tuple = (1, 1)) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid, dialect="ardupilotmega")
        self.conn.mav.robust_parsing = True
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True)
        self.target = target
        self.msgs: List[tuple] = []      # (monotonic, msg)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True, name="gcs-client")
        self._t.start()

    @property
    def mav(self) -> Any:
        return self.conn.mav

    def close(self) -> None:
        self._stop.set()
        self._t.join(timeout=3)
        try:
            self.conn.close()
        except Exception:
            pass

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.05)
            except Exception:
                time.sleep(0.01)
                continue
            if m is None or m.get_type() == "BAD_DATA":
                continue
            with self._lock:
                self.msgs.append((time.monotonic(), m))

    # ---- queries ----
    def since(self, t0: float, mtype: Optional[str] = None) -> List[Any]:
        with self._lock:
            return [m for (t, m) in self.msgs if t >= t0 and (mtype is None or m.get_type() == mtype)]

    def wait(self, mtype: str, cond: Callable[[Any], bool] = lambda m: True, timeout: float = 10.0,
             since: Optional[float] = None) -> Any:
        t0 = since if since is not None else time.monotonic()
        deadline = time.monotonic() + timeout
        idx = 0
        while time.monotonic() < deadline:
            with self._lock:
                items = [(t, m) for (t, m) in self.msgs if t >= t0]
            for t, m in items[idx:]:
                if m.get_type() == mtype and cond(m):
                    return m
            idx = len(items)
            time.sleep(0.01)
        raise AssertionError(f"no {mtype} matching the condition within {timeout}s")

    def none_within(self, mtype: str, seconds: float, cond: Callable[[Any], bool] = lambda m: True) -> bool:
        t0 = time.monotonic()
        time.sleep(seconds)
        return not any(cond(m) for m in self.since(t0, mtype))

    # ---- actions ----
    def command_long(self, cmd: int, *params: float, wait_ack: bool = True, timeout: float = 5.0) -> Optional[Any]:
        p = list(params) + [0.0] * (7 - len(params))
        t0 = time.monotonic()
        self.mav.command_long_send(self.target[0], self.target[1], cmd, 0, *p)
        if not wait_ack:
            return None
        return self.wait("COMMAND_ACK", lambda m: m.command == cmd, timeout=timeout, since=t0)

    def command_int(self, cmd: int, frame: int, p1: float = 0, p2: float = 0, p3: float = 0, p4: float = 0,
                    x: int = 0, y: int = 0, z: float = 0, timeout: float = 5.0) -> Any:
        t0 = time.monotonic()
        self.mav.command_int_send(self.target[0], self.target[1], frame, cmd, 0, 0, p1, p2, p3, p4, x, y, z)
        return self.wait("COMMAND_ACK", lambda m: m.command == cmd, timeout=timeout, since=t0)

    def gcs_heartbeat(self) -> None:
        """One HEARTBEAT as a ground station (QGroundControl, Mission Planner and MAVProxy send one a second): the
        companion takes MAV_CMD_MISSION_START only from a system it heard do this (or --gcs-sysid)."""
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)

    def start_mission(self, companion: int = 191, system: int = 1, timeout: float = 5.0) -> Any:
        """The operator's start: a GCS heartbeat, then MAV_CMD_MISSION_START to the companion; the COMMAND_ACK."""
        self.gcs_heartbeat()
        time.sleep(0.3)
        self.target = (system, companion)
        return self.command_long(mavlink.MAV_CMD_MISSION_START, timeout=timeout)

    def set_mode(self, name: str) -> Any:
        modes = {"STABILIZE": 0, "ALT_HOLD": 2, "AUTO": 3, "GUIDED": 4, "LOITER": 5, "RTL": 6, "LAND": 9, "BRAKE": 17}
        return self.command_long(mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, modes[name])

    def arm(self, force: bool = False) -> Any:
        return self.command_long(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196 if force else 0)

    def param_set(self, name: str, value: float, timeout: float = 5.0) -> Any:
        t0 = time.monotonic()
        self.mav.param_set_send(self.target[0], self.target[1], name.encode(), float(value), mavlink.MAV_PARAM_TYPE_REAL32)
        return self.wait("PARAM_VALUE", lambda m: m.param_id == name, timeout=timeout, since=t0)

    def upload_mission(self, items: List[Dict[str, Any]], use_int: bool = True, timeout: float = 20.0) -> Any:
        """Upload `items` (seq 0 = home placeholder included), answering whichever request kind arrives."""
        t0 = time.monotonic()
        self.mav.mission_count_send(self.target[0], self.target[1], len(items), 0)
        deadline = time.monotonic() + timeout
        idx = 0
        while time.monotonic() < deadline:
            new = self.since(t0)
            for m in new[idx:]:
                t = m.get_type()
                if t in ("MISSION_REQUEST", "MISSION_REQUEST_INT"):
                    it = items[m.seq]
                    if use_int:
                        self.mav.mission_item_int_send(self.target[0], self.target[1], m.seq, it["frame"], it["command"],
                                                       0, 1, it.get("param1", 0), it.get("param2", 0), it.get("param3", 0),
                                                       it.get("param4", 0), int(it["lat"] * 1e7), int(it["lon"] * 1e7), it["alt"], 0)
                    else:
                        self.mav.mission_item_send(self.target[0], self.target[1], m.seq, it["frame"], it["command"],
                                                   0, 1, it.get("param1", 0), it.get("param2", 0), it.get("param3", 0),
                                                   it.get("param4", 0), it["lat"], it["lon"], it["alt"], 0)
                elif t == "MISSION_ACK":
                    return m
            idx = len(new)
            time.sleep(0.01)
        raise AssertionError("mission upload: no MISSION_ACK")



def joined_statustexts(msgs: Iterable[Any], compid: int) -> List[str]:
    """The STATUSTEXTs from component `compid` as a ground station shows them: the MAVLink 2 chunks of one text (one
    non-zero `id`, `chunk_seq` 0, 1, ...) joined, each text once."""
    out: List[str] = []
    open_id = None
    for m in msgs:
        if m.get_srcComponent() != compid:
            continue
        if m.id != 0 and m.id == open_id and m.chunk_seq > 0:
            out[-1] += m.text
        else:
            out.append(m.text)
        open_id = m.id if m.id != 0 else None
    return out

def wp(lat: float, lon: float, alt: float, command: int = mavlink.MAV_CMD_NAV_WAYPOINT,
       frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, **params: float) -> Dict[str, Any]:
    d = {"lat": lat, "lon": lon, "alt": alt, "command": command, "frame": frame}
    d.update(params)
    return d


def offset(lat: float, lon: float, north_m: float, east_m: float) -> tuple:
    import math
    return (lat + math.degrees(north_m / 6378137.0),
            lon + math.degrees(east_m / (6378137.0 * math.cos(math.radians(lat)))))
