"""The stand-in autopilot: its state, lifecycle, clocks, test controls, views and main loop."""
from __future__ import annotations

import math
import random
import selectors
import socket
import threading
import time
from dataclasses import asdict
from typing import Any, Callable, Dict, List, Optional, Tuple

from .config import StandinConfig
from .handlers import MessageHandlers
from .link import Link, LinkIO, parse_url
from .mission import MissionProtocol
from .physics import Physics
from .recording import Event, Recorder
from .telemetry import Telemetry
from .vehicle import ArmingAndModes, Vehicle
from .vocabulary import DEFAULT_INTERVALS_MS, DEFAULT_PARAMS, MODE_NAMES, PREARM_DISPLAY_PERIOD_S, mavlink


class StandinAutopilot(LinkIO, MessageHandlers, MissionProtocol, ArmingAndModes, Physics, Telemetry):
    """The stand-in ArduCopter (see the package docstring). Thread-safe public methods; one background thread
    does all I/O. The mixins hold what it does, by subject; this class holds its state and its public API."""

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
        self.held_param_reads: set = set()     # PARAM_REQUEST_READ of these names is not answered yet
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
        kind, host, port = parse_url(self.cfg.listen)
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
        kind, host, _ = parse_url(self.cfg.listen)
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

    def hold_param_reads(self, names: List[str]) -> None:
        """Leave PARAM_REQUEST_READ of `names` unanswered until released, as ArduCopter SITL did in its first
        seconds (its PARAM_VALUEs came after the mission download, CI stop 43)."""
        with self.lock:
            self.held_param_reads = set(names)

    def release_param_reads(self) -> None:
        with self.lock:
            self.held_param_reads = set()

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

    def inject_unsigned_burst(self, msgs: List[Any], srcsys: Optional[int] = None,
                              srccomp: Optional[int] = None) -> None:
        """Several unsigned frames in one write (back to back, one TCP segment), as the attacker's two armed
        heartbeats were: nothing of the autopilot's own can arrive in between."""
        with self.lock:
            enc = mavlink.MAVLink(None, srcsys if srcsys is not None else self.cfg.sysid,
                                  srccomp if srccomp is not None else self.cfg.compid)
            buf = b"".join(bytes(m.pack(enc)) for m in msgs)
            for link in self.links:
                link.send_raw(buf)
            self.rec.add(self.wall(), self._sim, "inject_unsigned", type="+".join(m.get_type() for m in msgs))

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

    def _garbage_update(self) -> None:
        p = self.cfg.garbage_period_wall
        if p <= 0 or not self.links:
            return
        now = self.wall()
        if now >= self._next_garbage:
            self._next_garbage = now + p
            self.inject_garbage(self.rng.randint(8, 96))
            self.inject_malformed()
