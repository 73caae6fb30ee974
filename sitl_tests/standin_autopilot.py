#!/usr/bin/env python3
"""A stand-in ArduPilot Copter: a TEST FIXTURE, not an autopilot.

It speaks MAVLink 2 over loopback TCP/UDP and behaves, for everything a companion computer uses, the
way ArduCopter does, so the `companion fly` shell can be tested without building ArduPilot. Where a
behaviour is an ArduPilot quirk, the comment names the ArduPilot source file it comes from (paths in
the ArduPilot/ardupilot repository). Where the stand-in simplifies, the comment says "stand-in".
docs/sitl.md describes it; `SITL_URL` points the tests at a real SITL instead.

Use it three ways:
  * imported: ``StandinAutopilot(StandinConfig(...)).start()`` (what sitl_tests/conftest.py does),
  * as a script: ``python sitl_tests/standin_autopilot.py --listen tcp:127.0.0.1:5760``,
  * as a module from sitl_tests/: ``python -m standin_autopilot --listen udp:127.0.0.1:14550``.

Time: vehicle dynamics and vehicle timers (EKF convergence, DISARM_DELAY, battery drain, GPS-loss
failsafe) run on *simulated* time = wall time x ``speedup`` (like SITL's SIM_SPEEDUP). Link timing
(stream intervals, mission protocol re-requests and timeouts, link outages) stays on wall time,
because the companion's own link timers are wall-clock.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import selectors
import socket
import sys
import threading
import time
from dataclasses import dataclass, field, asdict
from typing import Any, Callable, Dict, List, Optional, Tuple

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

# ---------------------------------------------------------------------------------------------
# ArduCopter vocabulary
# ---------------------------------------------------------------------------------------------

# Copter custom modes (ArduCopter/mode.h `enum class Number`; also the COPTER_MODE enum in
# ardupilotmega.xml). Only the ones a companion uses are simulated.
MODES = {
    "STABILIZE": 0,
    "ALT_HOLD": 2,
    "AUTO": 3,
    "GUIDED": 4,
    "LOITER": 5,
    "RTL": 6,
    "LAND": 9,
    "BRAKE": 17,
}
MODE_NAMES = {v: k for k, v in MODES.items()}
# Modes that need a position estimate (Mode::requires_GPS() is true for these in ArduCopter/mode_*.cpp).
POSITION_MODES = {MODES[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "BRAKE")}
# Modes that refuse arming: ModeAuto::allows_arming() is false unless AUTO_OPTIONS allows it
# (ArduCopter/mode_auto.cpp); RTL and LAND return false too (ArduCopter/mode.h).
NOT_ARMABLE = {MODES["AUTO"], MODES["RTL"], MODES["LAND"]}
# Modes reported with MAV_MODE_FLAG_GUIDED_ENABLED (GCS_MAVLINK_Copter::base_mode(),
# ArduCopter/GCS_Mavlink.cpp).
GUIDED_FLAG_MODES = {MODES[m] for m in ("AUTO", "GUIDED", "LOITER", "RTL", "BRAKE")}

# AP_Arming.cpp: PREARM_DISPLAY_PERIOD 30 (s between repeats of a failing pre-arm check while disarmed).
PREARM_DISPLAY_PERIOD_S = 30.0

# Default home: SITL's CMAC location (Tools/autotest/locations.txt "CMAC").
HOME_LAT, HOME_LON, HOME_ALT_AMSL = -35.363261, 149.165230, 584.0
EARTH_R = 6378137.0

# EKF_STATUS_REPORT flags (EKF_STATUS_FLAGS in common.xml).
EKF_OK_FLAGS = (
    mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_HORIZ | mavlink.EKF_VELOCITY_VERT
    | mavlink.EKF_POS_HORIZ_REL | mavlink.EKF_POS_HORIZ_ABS | mavlink.EKF_POS_VERT_ABS
    | mavlink.EKF_PRED_POS_HORIZ_REL | mavlink.EKF_PRED_POS_HORIZ_ABS
)
EKF_ALIGNING_FLAGS = mavlink.EKF_ATTITUDE | mavlink.EKF_VELOCITY_VERT | mavlink.EKF_POS_VERT_ABS | mavlink.EKF_CONST_POS_MODE

# Parameters: ArduPilot names where ArduPilot has one (units as ArduPilot: cm, cm/s, mAh, s).
# SIM_* names are SITL's (libraries/SITL/SITL.cpp, ardupilot.org/dev/docs/SITL_simulation_parameters.html);
# names marked stand-in exist only here.
DEFAULT_PARAMS: Dict[str, float] = {
    "SYSID_THISMAV": 1,
    "DISARM_DELAY": 10,        # s; ArduCopter/Parameters.cpp default 10, used by Copter::auto_disarm_check (motors.cpp)
    "RTL_ALT": 1500,           # cm; default 15 m
    "RTL_LOIT_TIME": 5000,     # ms; default 5 s loiter above home before descending
    "WPNAV_SPEED": 500,        # cm/s horizontal (AC_WPNav default 5 m/s)
    "WPNAV_SPEED_UP": 250,     # cm/s climb (default 2.5 m/s)
    "WPNAV_SPEED_DN": 150,     # cm/s descent (default 1.5 m/s)
    "WPNAV_RADIUS": 200,       # cm waypoint acceptance radius (default 2 m)
    "LAND_SPEED": 50,          # cm/s final descent (default 0.5 m/s)
    "LAND_ALT_LOW": 1000,      # cm; below it LAND descends at LAND_SPEED (default 10 m)
    "BATT_CAPACITY": 3300,     # mAh (SITL default)
    "FS_EKF_ACTION": 1,        # 1 = LAND on EKF failsafe (ArduCopter default)
    "ARMING_CHECK": 1,
    "SIM_SPEEDUP": 1,
    "SIM_WIND_SPD": 0,         # m/s
    "SIM_WIND_DIR": 180,       # deg, direction the wind comes from
    "SIM_VIB_MOT_MAX": 0,      # Hz; >0 adds motor vibration (libraries/SITL/SITL.cpp VIB_MOT_MAX)
    "SIM_VIB_MOT_MULT": 1,     # amplitude scale of motor noise (VIB_MOT_MULT)
    "SIM_BATT_VOLTAGE": 12.6,  # V full pack (SITL default)
    "SIM_BATT_CAP_AH": 0,      # Ah; 0 = use BATT_CAPACITY
    "SIM_GPS_DISABLE": 0,      # 1 = GPS 1 off (libraries/SITL/SITL.cpp GPS_DISABLE)
    "SIM_BATT_PCT": -1,        # stand-in: write 0..100 to set the state of charge now
    "SIM_OBST_DIST": 0,        # stand-in: write d>0 to place an obstacle d m ahead; 0 removes it
    "SIM_OBST_ORIENT": 0,      # stand-in: DISTANCE_SENSOR orientation (MAV_SENSOR_ORIENTATION, 0 = forward)
}

# Stream messages: default interval (ms) standing in for the SRx_* stream rates. ArduPilot maps each
# MAVLink id to an ap_message (GCS_MAVLINK::mavlink_id_to_ap_message_id, GCS_Common.cpp); ids with no
# mapping are refused by MAV_CMD_SET_MESSAGE_INTERVAL with "No ap_message for mavlink id (%u)".
DEFAULT_INTERVALS_MS: Dict[int, int] = {
    mavlink.MAVLINK_MSG_ID_SYS_STATUS: 500,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: 500,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 250,
    mavlink.MAVLINK_MSG_ID_ATTITUDE: 250,
    mavlink.MAVLINK_MSG_ID_VFR_HUD: 500,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS: 1000,
    mavlink.MAVLINK_MSG_ID_VIBRATION: 1000,
    mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 1000,
    mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1000,
    mavlink.MAVLINK_MSG_ID_MISSION_CURRENT: 1000,
    mavlink.MAVLINK_MSG_ID_WIND: 1000,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: 200,
    mavlink.MAVLINK_MSG_ID_HOME_POSITION: 5000,
    mavlink.MAVLINK_MSG_ID_SYSTEM_TIME: 5000,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: -1,   # off by default, as with SR*_POSITION on most links
}
# Ids ArduPilot maps to an ap_message that the stand-in accepts interval requests for but never generates.
KNOWN_NOT_GENERATED = {
    mavlink.MAVLINK_MSG_ID_RAW_IMU, mavlink.MAVLINK_MSG_ID_SCALED_IMU, mavlink.MAVLINK_MSG_ID_SCALED_PRESSURE,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, mavlink.MAVLINK_MSG_ID_RC_CHANNELS, mavlink.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT,
    mavlink.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT, mavlink.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
    mavlink.MAVLINK_MSG_ID_TERRAIN_REPORT, mavlink.MAVLINK_MSG_ID_AHRS, mavlink.MAVLINK_MSG_ID_POWER_STATUS,
    mavlink.MAVLINK_MSG_ID_MEMINFO, mavlink.MAVLINK_MSG_ID_RANGEFINDER, mavlink.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS,
}
HEARTBEAT_INTERVAL_S = 1.0

# Mission protocol timings (libraries/GCS_MAVLink/MissionItemProtocol.h/.cpp).
MISSION_UPLOAD_TIMEOUT_S = 8.0      # upload_timeout_ms = 8000
MISSION_REREQUEST_S = 1.0           # wp_recv_timeout_ms = 1000 + stream slowdown
MISSION_MAX_ITEMS = 700             # stand-in storage limit (AP_Mission::num_commands_max on SITL is larger)
STREAM_SLOWDOWN_DURING_TRANSFER = 4  # GCS_MAVLINK::get_reschedule_interval_ms: interval *= 4 while requesting items

SUPPORTED_FRAMES = {
    mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_INT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, mavlink.MAV_FRAME_MISSION,
}
NAV_COMMANDS = {
    mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_TAKEOFF, mavlink.MAV_CMD_NAV_LAND,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_LOITER_UNLIM,
    mavlink.MAV_CMD_NAV_SPLINE_WAYPOINT, mavlink.MAV_CMD_NAV_DELAY,
}
DO_COMMANDS = {
    mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_DO_SET_ROI, mavlink.MAV_CMD_DO_SET_ROI_LOCATION,
    mavlink.MAV_CMD_DO_SET_ROI_NONE, mavlink.MAV_CMD_CONDITION_YAW, mavlink.MAV_CMD_CONDITION_DELAY,
    mavlink.MAV_CMD_DO_JUMP, mavlink.MAV_CMD_DO_SET_SERVO, mavlink.MAV_CMD_DO_DIGICAM_CONTROL,
    mavlink.MAV_CMD_DO_MOUNT_CONTROL, mavlink.MAV_CMD_IMAGE_START_CAPTURE, mavlink.MAV_CMD_IMAGE_STOP_CAPTURE,
    mavlink.MAV_CMD_VIDEO_START_CAPTURE, mavlink.MAV_CMD_VIDEO_STOP_CAPTURE, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
}


def _signing_timestamp() -> int:
    # MAVLink 2 signing timestamps count 10 us units since 2015-01-01 (mavlink.io/en/guide/message_signing.html).
    return int((time.time() - 1420070400) * 100000)


def _accept_unsigned(_mav: Any, msg_id: int) -> bool:
    # With signing on, ArduPilot accepts only RADIO_STATUS unsigned (GCS_Signing.cpp accept_unsigned_callback:
    # "we accept RADIO_STATUS messages unsigned as the radio doesn't know the key").
    return msg_id == mavlink.MAVLINK_MSG_ID_RADIO_STATUS


@dataclass
class StandinConfig:
    """Everything a test may want to change. Times are in simulated seconds unless named *_wall."""

    listen: str = "tcp:127.0.0.1:0"     # tcp:HOST:PORT (server), udp:HOST:PORT (bind, reply to last sender), udpout:HOST:PORT
    sysid: int = 1
    compid: int = 1                     # MAV_COMP_ID_AUTOPILOT1
    speedup: float = 1.0
    ekf_ready_s: float = 30.0           # SITL typically needs tens of seconds before "Need Position Estimate" clears
    disarm_delay_s: float = 10.0        # DISARM_DELAY
    gps_loss_ekf_s: float = 3.0         # stand-in: dead-reckoning time before POS_HORIZ_ABS drops after GPS loss
    home: Tuple[float, float, float] = (HOME_LAT, HOME_LON, HOME_ALT_AMSL)
    signing_key: Optional[bytes] = None  # 32 bytes; sign everything sent, reject unsigned received
    mission_request_int: bool = False   # False: request items with legacy MISSION_REQUEST as MissionItemProtocol::queued_request_send does
    physics_hz: float = 50.0
    garbage_period_wall: float = 0.0    # >0: inject a burst of garbage + malformed frames this often (wall s)
    capture_wire: bool = False          # keep every byte sent and received per link (Link.wire_out / wire_in)
    seed: int = 1

    def __post_init__(self) -> None:
        if self.speedup <= 0:
            raise ValueError("speedup must be > 0")


# ---------------------------------------------------------------------------------------------
# Recording: everything the autopilot received and did, for assertions.
# ---------------------------------------------------------------------------------------------

@dataclass
class Event:
    wall: float      # seconds since stand-in start (wall clock)
    sim: float       # simulated seconds since start
    kind: str        # received | command | mode | arm | disarm | mission_upload | mission_clear | param | statustext | ...
    data: Dict[str, Any] = field(default_factory=dict)


class Recorder:
    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.events: List[Event] = []

    def add(self, wall: float, sim: float, kind: str, **data: Any) -> None:
        with self._lock:
            self.events.append(Event(wall, sim, kind, data))

    def of(self, kind: str) -> List[Event]:
        with self._lock:
            return [e for e in self.events if e.kind == kind]

    def snapshot(self) -> List[Event]:
        with self._lock:
            return list(self.events)

    def to_json(self) -> str:
        return json.dumps([asdict(e) for e in self.snapshot()], default=str)


# ---------------------------------------------------------------------------------------------
# Links
# ---------------------------------------------------------------------------------------------

class _Writer:
    """File-like sink pymavlink's MAVLink.send() writes into."""

    def __init__(self, link: "Link") -> None:
        self.link = link

    def write(self, buf: bytes) -> None:
        self.link.send_raw(bytes(buf))


class Link:
    """One peer: a TCP client connection or a UDP peer. Own parser, own sequence numbers (ArduPilot keeps
    per-channel state), own signing streams."""

    def __init__(self, owner: "StandinAutopilot", ident: int, sock: socket.socket, addr: Any, udp: bool) -> None:
        self.owner = owner
        self.ident = ident
        self.sock = sock
        self.addr = addr
        self.udp = udp
        self.mav = mavlink.MAVLink(_Writer(self), owner.cfg.sysid, owner.cfg.compid)
        self.mav.robust_parsing = True
        key = owner.cfg.signing_key
        if key is not None:
            self.mav.signing.secret_key = key
            self.mav.signing.sign_outgoing = True
            self.mav.signing.link_id = ident & 0xFF
            self.mav.signing.timestamp = _signing_timestamp()
            self.mav.signing.allow_unsigned_callback = _accept_unsigned
        self.seen: set = set()          # (sysid, compid) heard on this link, for routing
        self.closed = False
        self.bytes_in = 0
        self.bytes_out = 0
        # The raw byte streams, when cfg.capture_wire: lets a test compare a peer's .tlog with the wire.
        self.wire_out: Optional[bytearray] = bytearray() if owner.cfg.capture_wire else None
        self.wire_in: Optional[bytearray] = bytearray() if owner.cfg.capture_wire else None
        if owner.cfg.capture_wire:
            owner.wire_links.append(self)

    def send_raw(self, buf: bytes) -> None:
        if self.closed or self.owner.in_outage():
            return
        try:
            if self.udp:
                if self.addr is not None:
                    self.sock.sendto(buf, self.addr)
            else:
                self.sock.sendall(buf)
            self.bytes_out += len(buf)
            if self.wire_out is not None:
                self.wire_out += buf
        except OSError:
            self.closed = True

    def send(self, msg: Any) -> None:
        self.mav.send(msg)


# ---------------------------------------------------------------------------------------------
# The vehicle
# ---------------------------------------------------------------------------------------------

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


class StandinAutopilot:
    """See the module docstring. Thread-safe public methods; one background thread does all I/O."""

    def __init__(self, cfg: Optional[StandinConfig] = None, **overrides: Any) -> None:
        if cfg is None:
            cfg = StandinConfig(**overrides)
        elif overrides:
            cfg = StandinConfig(**{**asdict(cfg), **overrides})
        self.cfg = cfg
        self.rec = Recorder()
        self.params: Dict[str, float] = dict(DEFAULT_PARAMS)
        self.params["SYSID_THISMAV"] = cfg.sysid
        self.params["DISARM_DELAY"] = cfg.disarm_delay_s
        self.params["SIM_SPEEDUP"] = cfg.speedup
        self._prearm_next_display = PREARM_DISPLAY_PERIOD_S / 2
        self.v = Vehicle()
        self.home = cfg.home
        self.lock = threading.RLock()
        self.rng = random.Random(cfg.seed)
        self.links: List[Link] = []
        self.wire_links: List[Link] = []    # every link ever made, closed ones too (cfg.capture_wire only)
        self._next_link = 1
        self._sel = selectors.DefaultSelector()
        self._server: Optional[socket.socket] = None
        self._udp: Optional[socket.socket] = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        self._sim = 0.0
        self._last_step = self._t0
        self.port = 0
        # telemetry scheduling (wall clock)
        self.intervals_ms: Dict[int, int] = dict(DEFAULT_INTERVALS_MS)
        self._next_due: Dict[int, float] = {}
        self._next_hb = 0.0
        # mission (item 0 is home: AP_Mission stores home as command 0; MissionItemProtocol_Waypoints::get_item
        # "always allow HOME to be read")
        self.mission: List[Dict[str, Any]] = [self._home_item()]
        self.mission_current = 0
        self.mission_item_started: float = 0.0
        self.mission_delay_until: Optional[float] = None
        self.upload: Optional[Dict[str, Any]] = None
        self._request_warning_sent = False
        self._item_warning_sent = False
        # link faults
        self._outages: List[Tuple[float, float]] = []
        self._next_garbage = 0.0
        # counters (read by tests)
        self.counters: Dict[str, int] = {
            "rx_messages": 0, "rx_garbage_bytes": 0, "rx_bad_frames": 0, "rx_bad_signature": 0,
            "rx_unsigned_rejected": 0, "rx_dropped_in_outage": 0, "tx_garbage_bytes": 0,
            "tx_malformed_frames": 0, "forwarded": 0,
        }
        self.obstacle: Optional[Tuple[float, float]] = None   # world (n, e)

    # ----- lifecycle -----------------------------------------------------------------------------

    def start(self) -> "StandinAutopilot":
        kind, host, port = _parse_url(self.cfg.listen)
        if kind == "tcp":
            srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            srv.bind((host, port))
            srv.listen(8)
            srv.setblocking(False)
            self._server = srv
            self.port = srv.getsockname()[1]
            self._sel.register(srv, selectors.EVENT_READ, "accept")
        elif kind in ("udp", "udpout"):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            if kind == "udp":
                s.bind((host, port))
                addr = None
            else:
                s.bind(("127.0.0.1", 0))
                addr = (host, port)
            s.setblocking(False)
            self._udp = s
            self.port = s.getsockname()[1] if kind == "udp" else port
            link = Link(self, self._new_ident(), s, addr, udp=True)
            self.links.append(link)
            self._sel.register(s, selectors.EVENT_READ, link)
        else:
            raise ValueError(f"unsupported listen URL {self.cfg.listen!r}")
        self._t0 = time.monotonic()
        self._last_step = self._t0
        self._thread = threading.Thread(target=self._run, name="standin-autopilot", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for link in self.links:
            try:
                if not link.udp:
                    link.sock.close()
            except OSError:
                pass
        for s in (self._server, self._udp):
            if s is not None:
                s.close()
        self._sel.close()

    def __enter__(self) -> "StandinAutopilot":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    @property
    def url(self) -> str:
        kind, host, _ = _parse_url(self.cfg.listen)
        return f"{'tcp' if kind == 'tcp' else 'udpout'}:{host}:{self.port}"

    # ----- clocks ------------------------------------------------------------------------------

    def wall(self) -> float:
        return time.monotonic() - self._t0

    def sim_time(self) -> float:
        with self.lock:
            return self._sim

    def wait_sim(self, seconds: float, timeout: float = 120.0) -> None:
        """Block until `seconds` of simulated time have passed."""
        target = self.sim_time() + seconds
        self.wait_for(lambda: self._sim >= target, timeout=timeout, what=f"sim time +{seconds}s")

    def wait_for(self, pred: Callable[[], bool], timeout: float = 60.0, what: str = "condition", poll: float = 0.02) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self.lock:
                if pred():
                    return
            time.sleep(poll)
        raise TimeoutError(f"stand-in: timed out after {timeout}s waiting for {what}")

    # ----- test controls (the same effects as PARAM_SET of the SIM_* parameters) ------------------

    def set_param(self, name: str, value: float) -> bool:
        with self.lock:
            return self._set_param(name, float(value), source="api")

    def link_outage(self, seconds: float) -> None:
        """Cut the link both ways for `seconds` of wall time: nothing is sent; what arrives is recorded
        (kind ``received`` with dropped=True) but not acted on, as if lost on the radio."""
        with self.lock:
            start = self.wall()
            self._outages.append((start, start + seconds))
            self.rec.add(start, self._sim, "link_outage", start=start, end=start + seconds)

    def in_outage(self) -> bool:
        now = self.wall()
        return any(a <= now < b for a, b in self._outages)

    def place_obstacle(self, distance_m: float) -> None:
        with self.lock:
            self._place_obstacle(distance_m)

    def inject_garbage(self, nbytes: int = 64) -> None:
        """Send random non-MAVLink bytes (no 0xFD/0xFE start markers) on every link."""
        with self.lock:
            junk = bytes(self.rng.choice([b for b in range(256) if b not in (0xFD, 0xFE)]) for _ in range(nbytes))
            for link in self.links:
                link.send_raw(junk)
            self.counters["tx_garbage_bytes"] += nbytes

    def inject_malformed(self) -> None:
        """Send one of each malformed frame kind: bad CRC, truncated, bad incompat flags, unknown id."""
        with self.lock:
            for link in self.links:
                enc = mavlink.MAVLink(None, self.cfg.sysid, self.cfg.compid)
                good = bytearray(self._heartbeat_msg().pack(enc))
                bad_crc = bytearray(good)
                bad_crc[-1] ^= 0xFF
                truncated = bytes(good[: len(good) // 2])
                bad_flags = bytearray(good)
                bad_flags[2] = 0x80                      # unknown incompat flag
                unknown = bytearray(b"\xfd\x04\x00\x00\x07\x01\x01\x39\x30\x00\x01\x02\x03\x04\xaa\xbb")  # id 12345
                for frame in (bytes(bad_crc), truncated, bytes(bad_flags), bytes(unknown)):
                    link.send_raw(frame)
                self.counters["tx_malformed_frames"] += 4

    def inject_unsigned(self, msg: Any, srcsys: Optional[int] = None, srccomp: Optional[int] = None) -> None:
        """Send `msg` unsigned (an attacker's injection) on every link, impersonating the autopilot by default."""
        with self.lock:
            enc = mavlink.MAVLink(None, srcsys if srcsys is not None else self.cfg.sysid,
                                  srccomp if srccomp is not None else self.cfg.compid)
            buf = bytes(msg.pack(enc))
            for link in self.links:
                link.send_raw(buf)
            self.rec.add(self.wall(), self._sim, "inject_unsigned", type=msg.get_type())

    def send_statustext(self, text: str, severity: int = mavlink.MAV_SEVERITY_INFO) -> None:
        with self.lock:
            self._statustext(text, severity)

    # ----- read-only views for tests --------------------------------------------------------------

    def state(self) -> Dict[str, Any]:
        with self.lock:
            v = self.v
            return {
                "sim": self._sim, "wall": self.wall(), "armed": v.armed, "landed": v.landed,
                "mode": MODE_NAMES.get(v.mode, str(v.mode)), "alt": v.alt, "north": v.north, "east": v.east,
                "max_alt": v.max_alt, "max_dist": v.max_dist, "battery_pct": self._battery_pct(),
                "position_ok": self._position_ok(), "mission_current": self.mission_current,
                "mission_count": len(self.mission), "collided": v.collided, "ekf_failsafe": v.ekf_failsafe,
            }

    def received(self, msg_type: Optional[str] = None, include_dropped: bool = False) -> List[Event]:
        out = []
        for e in self.rec.of("received"):
            if msg_type is not None and e.data["type"] != msg_type:
                continue
            if e.data.get("dropped") and not include_dropped:
                continue
            out.append(e)
        return out

    def commands(self, command: Optional[int] = None) -> List[Event]:
        return [e for e in self.rec.of("command") if command is None or e.data["command"] == command]

    def mode_changes(self) -> List[Event]:
        return self.rec.of("mode")

    def mission_uploads(self) -> List[Event]:
        return self.rec.of("mission_upload")

    # ----- main loop -----------------------------------------------------------------------------

    def _new_ident(self) -> int:
        i = self._next_link
        self._next_link += 1
        return i

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                events = self._sel.select(timeout=0.005)
            except (OSError, ValueError):
                break
            for key, _ in events:
                if key.data == "accept":
                    self._accept()
                else:
                    self._read(key.data)
            with self.lock:
                now = time.monotonic()
                dt_wall = now - self._last_step
                if dt_wall >= 1.0 / self.cfg.physics_hz:
                    self._last_step = now
                    dt = min(dt_wall, 0.25) * self.cfg.speedup
                    # integrate in small steps so high speedups keep the kinematics stable
                    steps = max(1, int(math.ceil(dt / 0.05)))
                    for _ in range(steps):
                        self._sim += dt / steps
                        self._physics(dt / steps)
                self._prearm_display()
                self._telemetry()
                self._mission_protocol_update()
                self._garbage_update()
                self.links = [l for l in self.links if not l.closed]

    def _accept(self) -> None:
        assert self._server is not None
        try:
            conn, addr = self._server.accept()
        except OSError:
            return
        conn.setblocking(True)
        conn.settimeout(2.0)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        link = Link(self, self._new_ident(), conn, addr, udp=False)
        with self.lock:
            self.links.append(link)
            self.rec.add(self.wall(), self._sim, "connect", link=link.ident, addr=str(addr))
        self._sel.register(conn, selectors.EVENT_READ, link)

    def _read(self, link: Link) -> None:
        try:
            if link.udp:
                data, addr = link.sock.recvfrom(65536)
                link.addr = addr
            else:
                data = link.sock.recv(65536)
        except (BlockingIOError, socket.timeout):
            return
        except OSError:
            data = b""
        if not data:
            if not link.udp:
                with self.lock:
                    link.closed = True
                    self.rec.add(self.wall(), self._sim, "disconnect", link=link.ident)
                try:
                    self._sel.unregister(link.sock)
                    link.sock.close()
                except (OSError, KeyError, ValueError):
                    pass
            return
        link.bytes_in += len(data)
        if link.wire_in is not None:
            link.wire_in += data
        msgs = link.mav.parse_buffer(data) or []
        with self.lock:
            for m in msgs:
                self._on_message(link, m)

    # ----- receive path ---------------------------------------------------------------------------

    def _on_message(self, link: Link, m: Any) -> None:
        t = m.get_type()
        if t == "BAD_DATA":
            reason = getattr(m, "reason", "")
            if "signature" in reason:
                # pymavlink raises "Invalid signature" for unsigned or badly signed frames when a key is set
                if _is_signed_frame(m.data):
                    self.counters["rx_bad_signature"] += 1
                else:
                    self.counters["rx_unsigned_rejected"] += 1
                self.rec.add(self.wall(), self._sim, "rejected", link=link.ident, reason=reason,
                             signed=_is_signed_frame(m.data), msgid=_frame_msgid(m.data))
            elif reason.startswith("Bad prefix"):
                self.counters["rx_garbage_bytes"] += len(m.data)
            else:
                self.counters["rx_bad_frames"] += 1
                self.counters["rx_garbage_bytes"] += len(m.data)
            return
        if t == "UNKNOWN" or t.startswith("UNKNOWN"):
            self.counters["rx_bad_frames"] += 1
            return
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        dropped = self.in_outage()
        data = {k: _jsonable(v) for k, v in m.to_dict().items() if k != "mavpackettype"}
        self.rec.add(self.wall(), self._sim, "received", link=link.ident, type=t, src=list(src),
                     signed=bool(getattr(m, "_signed", False)), dropped=dropped, fields=data)
        if dropped:
            self.counters["rx_dropped_in_outage"] += 1
            return
        self.counters["rx_messages"] += 1
        link.seen.add(src)
        # routing (libraries/GCS_MAVLink/MAVLink_routing.cpp): broadcasts go to every other link;
        # messages for another component go where that component was heard.
        tsys = getattr(m, "target_system", 0)
        tcomp = getattr(m, "target_component", 0)
        self._route(link, m, tsys, tcomp)
        if tsys not in (0, self.cfg.sysid) or tcomp not in (0, self.cfg.compid):
            return
        handler = getattr(self, "_h_" + t, None)
        if handler is not None:
            try:
                handler(link, m)
            except Exception as e:  # a fixture bug must show up in the recording, not kill the link thread
                self.counters["handler_errors"] = self.counters.get("handler_errors", 0) + 1
                self.rec.add(self.wall(), self._sim, "handler_error", type=t, error=repr(e))

    def _route(self, src_link: Link, m: Any, tsys: int, tcomp: int) -> None:
        if len(self.links) < 2:
            return
        buf = bytes(m.get_msgbuf())
        for link in self.links:
            if link is src_link:
                continue
            broadcast = tsys == 0
            for_link = any(s == tsys and (tcomp == 0 or c == tcomp) for s, c in link.seen)
            if broadcast or (for_link and (tsys, tcomp) != (self.cfg.sysid, self.cfg.compid)):
                link.send_raw(buf)
                self.counters["forwarded"] += 1

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
            self._send_param(link, name)
        # unknown names get no PARAM_VALUE back, as in GCS_MAVLINK::handle_param_set (GCS_Param.cpp)

    def _h_PARAM_REQUEST_READ(self, link: Link, m: Any) -> None:
        names = list(self.params)
        pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
        name = pid.rstrip("\x00") if m.param_index < 0 else (names[m.param_index] if 0 <= m.param_index < len(names) else None)
        if name in self.params:
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

    # ----- commands --------------------------------------------------------------------------------

    def _command(self, link: Link, m: Any, cmd: int, p: List[float], frame: Optional[int], is_int: bool, confirmation: int) -> None:
        hdr = m.get_header()
        src = (hdr.srcSystem, hdr.srcComponent)
        result = self._do_command(link, cmd, p, frame, is_int)
        if result is not None:
            link.send(mavlink.MAVLink_command_ack_message(cmd, result, 0, 0, src[0], src[1]))
        name = mavlink.enums["MAV_CMD"][cmd].name if cmd in mavlink.enums["MAV_CMD"] else str(cmd)
        self.rec.add(self.wall(), self._sim, "command", command=cmd, name=name, params=[_jsonable(x) for x in p],
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

    # ----- arming, modes ---------------------------------------------------------------------------

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

    def mission_done(self) -> bool:
        return self.mission_current >= len(self.mission)

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

    def _item_ne(self, item: Dict[str, Any]) -> Tuple[float, float]:
        if item["x"] == 0 and item["y"] == 0:
            return self.v.north, self.v.east    # lat/lon 0: "use current location" (AP_Mission)
        return self._ne_of(item["x"] / 1e7, item["y"] / 1e7)

    def _item_alt(self, item: Dict[str, Any]) -> float:
        return self._alt_of_frame(item["z"], item["frame"])

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
                                                    int(getattr(self, "_current_a", 0.0) * 100), int(v.consumed_ah * 1000), -1, pct,
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

    def _garbage_update(self) -> None:
        p = self.cfg.garbage_period_wall
        if p <= 0 or not self.links:
            return
        now = self.wall()
        if now >= self._next_garbage:
            self._next_garbage = now + p
            self.inject_garbage(self.rng.randint(8, 96))
            self.inject_malformed()


# ---------------------------------------------------------------------------------------------
# Onboard monitors: the camera/tracking application, as another component of the same system.
# ---------------------------------------------------------------------------------------------

MONITOR_NAMES = ("tgt_det", "tgt_spd", "trk_conf", "lum", "cpu_load")


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
            self.conn.setup_signing(signing_key, sign_outgoing=True, allow_unsigned_callback=_accept_unsigned)
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
                if k not in MONITOR_NAMES:
                    raise KeyError(f"unknown monitor value {k!r}; known: {MONITOR_NAMES}")
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


# ---------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------

def _parse_url(url: str) -> Tuple[str, str, int]:
    parts = url.split(":")
    if len(parts) != 3 or parts[0] not in ("tcp", "udp", "udpout"):
        raise ValueError(f"listen URL must be tcp:HOST:PORT, udp:HOST:PORT or udpout:HOST:PORT, got {url!r}")
    host = parts[1]
    if host not in ("127.0.0.1", "localhost") and not host.startswith("127."):
        raise ValueError("the stand-in listens on loopback only")
    return parts[0], "127.0.0.1" if host == "localhost" else host, int(parts[2])


def _is_signed_frame(buf: bytes) -> bool:
    return len(buf) > 2 and buf[0] == 0xFD and bool(buf[2] & 0x01)


def _frame_msgid(buf: bytes) -> Optional[int]:
    if len(buf) >= 10 and buf[0] == 0xFD:
        return buf[7] | (buf[8] << 8) | (buf[9] << 16)
    if len(buf) >= 6 and buf[0] == 0xFE:
        return buf[5]
    return None


def _jsonable(x: Any) -> Any:
    if isinstance(x, float) and (math.isnan(x) or math.isinf(x)):
        return str(x)
    if isinstance(x, (bytes, bytearray)):
        return x.decode(errors="replace")
    if isinstance(x, (list, tuple)):
        return [_jsonable(i) for i in x]
    return x


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description="Stand-in ArduPilot Copter (test fixture; loopback only)")
    ap.add_argument("--listen", default="tcp:127.0.0.1:5760", help="tcp:HOST:PORT | udp:HOST:PORT | udpout:HOST:PORT")
    ap.add_argument("--sysid", type=int, default=1)
    ap.add_argument("--speedup", type=float, default=1.0, help="simulated seconds per wall second (like SIM_SPEEDUP)")
    ap.add_argument("--ekf-ready-s", type=float, default=30.0, help="simulated seconds until the position estimate is ready")
    ap.add_argument("--disarm-delay-s", type=float, default=10.0)
    ap.add_argument("--signing-key", help="hex of a 32-byte MAVLink 2 signing key")
    ap.add_argument("--mission-request-int", action="store_true", help="request upload items with MISSION_REQUEST_INT")
    ap.add_argument("--garbage-period", type=float, default=0.0, help="inject garbage and malformed frames every N wall s")
    ap.add_argument("--record", help="write the recording (JSON) here on exit")
    ap.add_argument("--duration", type=float, default=0.0, help="exit after N wall seconds (0 = until Ctrl-C)")
    a = ap.parse_args(argv)
    cfg = StandinConfig(listen=a.listen, sysid=a.sysid, speedup=a.speedup, ekf_ready_s=a.ekf_ready_s,
                        disarm_delay_s=a.disarm_delay_s, mission_request_int=a.mission_request_int,
                        signing_key=bytes.fromhex(a.signing_key) if a.signing_key else None,
                        garbage_period_wall=a.garbage_period)
    ap_ = StandinAutopilot(cfg).start()
    print(f"stand-in ArduCopter listening on {ap_.url} (speedup {cfg.speedup})", flush=True)
    try:
        t0 = time.monotonic()
        while a.duration <= 0 or time.monotonic() - t0 < a.duration:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        ap_.stop()
        if a.record:
            with open(a.record, "w") as f:
                f.write(ap_.rec.to_json())
        print(json.dumps(ap_.counters), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
