"""A small TCP relay between the companion and a real autopilot, which a test can black out, cut and fill with
garbage, and which keeps a timestamped list of every MAVLink message the companion sent.

    companion --tcp--> Relay(listen 127.0.0.1:<free>) --tcp--> autopilot (SITL SERIAL1)

* `blackout(seconds)`: radio silence. The TCP connections stay open, but every byte either way is dropped
  (what a companion sees when a telemetry radio fades: nothing arrives, what it sends is lost).
* `cut()`: both TCP connections closed; the companion must reconnect (the relay accepts again).
* `inject_garbage(n)` / `garbage_every(period)`: random bytes, and a frame with a broken CRC, to the companion.
* `inject_unsigned(msg)`: a well-formed unsigned frame to the companion, impersonating the autopilot.
* `sent`: (monotonic time, message, delivered) of everything the companion sent, parsed with pymavlink.
* `delay_down(seconds)`: a slow link towards the companion: every byte from the autopilot arrives this much later
  (in order); what the companion sends goes through at once. A busy radio, where the autopilot's answers and its
  heartbeats are still on their way while the companion acts.
"""
from __future__ import annotations

import os
import random
import select
import socket
import threading
import time
from typing import Any, List, Optional, Tuple

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402


class Relay:
    def __init__(self, upstream_port: int, upstream_host: str = "127.0.0.1", seed: int = 1) -> None:
        self.upstream = (upstream_host, upstream_port)
        self._srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._srv.bind(("127.0.0.1", 0))
        self._srv.listen(4)
        self.port = self._srv.getsockname()[1]
        self.url = f"tcp:127.0.0.1:{self.port}"
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._blackout_until = 0.0
        self.blackouts: List[Tuple[float, float]] = []         # (start, end) monotonic
        self.cuts: List[float] = []
        self.accepts = 0
        self.garbage_bytes = 0
        self.malformed_frames = 0
        self._garbage_period: Optional[float] = None
        self._next_garbage = 0.0
        self._rng = random.Random(seed)
        self._pair: Optional[Tuple[socket.socket, socket.socket]] = None
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self.sent: List[Tuple[float, Any, bool]] = []
        self._down_delay = 0.0
        self._down_queue: List[Tuple[float, bytes]] = []      # (deliver at, bytes) towards the companion
        self._t = threading.Thread(target=self._run, daemon=True, name="relay")

    def start(self) -> "Relay":
        self._t.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._t.join(timeout=3)
        self._drop_pair()
        self._srv.close()

    # ---- controls ----
    def blackout(self, seconds: float) -> Tuple[float, float]:
        start = time.monotonic()
        with self._lock:
            self._blackout_until = start + seconds
            self.blackouts.append((start, start + seconds))
        return start, start + seconds

    def delay_down(self, seconds: float) -> None:
        with self._lock:
            self._down_delay = max(0.0, seconds)

    def in_blackout(self) -> bool:
        return time.monotonic() < self._blackout_until

    def cut(self) -> None:
        with self._lock:
            self.cuts.append(time.monotonic())
        self._drop_pair()

    def garbage_every(self, period: Optional[float]) -> None:
        self._garbage_period = period

    def inject_garbage(self, n: int = 64) -> None:
        pair = self._pair
        if pair is None:
            return
        junk = bytes(self._rng.randrange(256) for _ in range(n))
        # and a well-framed MAVLink 2 HEARTBEAT whose CRC is wrong
        hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)
        frame = bytearray(hb.pack(mavlink.MAVLink(None, srcSystem=1, srcComponent=1)))
        frame[-1] ^= 0xA5
        try:
            pair[0].sendall(junk + bytes(frame))
            self.garbage_bytes += n
            self.malformed_frames += 1
        except OSError:
            pass

    def inject_unsigned(self, msg: Any, srcsys: int = 1, srccomp: int = 1) -> bool:
        """An unsigned frame towards the companion, as if from (srcsys, srccomp): an attacker on the link."""
        pair = self._pair
        if pair is None:
            return False
        frame = msg.pack(mavlink.MAVLink(None, srcSystem=srcsys, srcComponent=srccomp))
        try:
            pair[0].sendall(bytes(frame))
            return True
        except OSError:
            return False

    # ---- queries ----
    def sent_between(self, t0: float, t1: float, types: Optional[set] = None) -> List[Any]:
        with self._lock:
            return [m for (t, m, _) in self.sent if t0 <= t < t1 and (types is None or m.get_type() in types)]

    def sent_types(self) -> List[str]:
        with self._lock:
            return [m.get_type() for (_, m, _) in self.sent]

    # ---- the loop ----
    def _drop_pair(self) -> None:
        with self._lock:
            pair, self._pair = self._pair, None
            self._down_queue.clear()
        if pair:
            for s in pair:
                try:
                    s.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
                s.close()

    def _flush_down(self, to: socket.socket, now: float) -> bool:
        """Deliver the delayed bytes now due, in order; False when the companion's socket failed."""
        while True:
            with self._lock:
                if not self._down_queue or self._down_queue[0][0] > now:
                    return True
                _, data = self._down_queue.pop(0)
            try:
                to.sendall(data)
            except OSError:
                return False

    def _record(self, data: bytes, delivered: bool) -> None:
        now = time.monotonic()
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception:
            msgs = []
        with self._lock:
            for m in msgs:
                if m.get_type() != "BAD_DATA":
                    self.sent.append((now, m, delivered))

    def _run(self) -> None:
        while not self._stop.is_set():
            socks: List[socket.socket] = [self._srv]
            pair = self._pair
            if pair:
                socks += list(pair)
            try:
                r, _, _ = select.select(socks, [], [], 0.05)
            except (OSError, ValueError):
                continue
            now = time.monotonic()
            if pair and not self._flush_down(pair[0], now):
                self._drop_pair()
                continue
            if pair and self._garbage_period and now >= self._next_garbage and not self.in_blackout():
                self._next_garbage = now + self._garbage_period
                self.inject_garbage(self._rng.randrange(8, 80))
            for s in r:
                if s is self._srv:
                    client, _ = self._srv.accept()
                    try:
                        up = socket.create_connection(self.upstream, timeout=5)
                    except OSError:
                        client.close()
                        continue
                    up.settimeout(None)
                    self._drop_pair()
                    for x in (client, up):
                        x.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    with self._lock:
                        self._pair = (client, up)
                        self.accepts += 1
                    continue
                if not pair or s not in pair:
                    continue
                try:
                    data = s.recv(65536)
                except OSError:
                    data = b""
                if not data:
                    self._drop_pair()
                    break
                other = pair[1] if s is pair[0] else pair[0]
                deliver = not self.in_blackout()
                if s is pair[0]:
                    self._record(data, deliver)
                if deliver and s is pair[1] and (self._down_delay > 0 or self._down_queue):
                    with self._lock:
                        self._down_queue.append((now + self._down_delay, data))
                elif deliver:
                    try:
                        other.sendall(data)
                    except OSError:
                        self._drop_pair()
                        break

