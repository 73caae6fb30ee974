"""A real ArduCopter SITL per test, and a ground station that watches it.

`ArduCopterSitl` starts one `arducopter` SITL process in its own working directory (`-w`: stored parameters
wiped, so each vehicle starts full, disarmed, with no mission) on its own instance number (`-I N`: SERIAL0 tcp
5760+10N, SERIAL1 tcp 5762+10N, SERIAL2 tcp 5763+10N), and stops it (its whole process group) afterwards.
SITL holds its start-up on SERIAL0 until a first client connects there: `GcsObserver` is that client.

`GcsObserver` is the ground station on SERIAL0: it keeps a record of what the vehicle did as a ground station
sees it (armed, altitude, modes flown, MISSION_ITEM_REACHED, EXTENDED_SYS_STATE landed state, STATUSTEXT) and
it injects hazards the SITL way (PARAM_SET of SIM_*/BATT_* parameters), reboots the autopilot
(MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN) and sets up MAVLink 2 signing (SETUP_SIGNING).

Where the binary is: `ARDUCOPTER_BIN` and `SITL_DEFAULTS`, else `../shared/sitl/ardupilot/` beside the
repository (docs/sitl.md says how to build one).
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
SHARED_ARDUPILOT = REPO.parent / "shared" / "sitl" / "ardupilot"
CMAC_HOME = "-35.363261,149.165230,584,353"
ARTIFACTS = Path(__file__).resolve().parent / "artifacts"

# ArduCopter custom_mode numbers (ArduCopter/mode.h)
COPTER_MODES = {0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 9: "LAND",
                16: "POSHOLD", 17: "BRAKE", 20: "GUIDED_NOGPS", 21: "SMART_RTL"}

HOW_TO_GET_ONE = ("no ArduCopter SITL: set ARDUCOPTER_BIN to an arducopter SITL binary and SITL_DEFAULTS to "
                  "ArduPilot's Tools/autotest/default_params/copter.parm, or put them in ../shared/sitl/ardupilot/ "
                  "(build: ./waf configure --board sitl && ./waf copter; docs/sitl.md)")


def find_arducopter() -> Tuple[Optional[Path], Optional[Path], str]:
    """(binary, defaults, why-not): the binary and defaults file, or Nones and the reason to skip."""
    env_bin, env_def = os.environ.get("ARDUCOPTER_BIN"), os.environ.get("SITL_DEFAULTS")
    binary = Path(env_bin) if env_bin else SHARED_ARDUPILOT / "arducopter"
    defaults = Path(env_def) if env_def else (binary.parent / "copter.parm")
    if not binary.is_file():
        return None, None, f"{HOW_TO_GET_ONE} (looked for {binary})"
    if not os.access(binary, os.X_OK):
        return None, None, f"{binary} is not executable"
    if not defaults.is_file():
        return None, None, f"no SITL defaults file at {defaults}: set SITL_DEFAULTS ({HOW_TO_GET_ONE})"
    return binary, defaults, ""


def port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


_instance_lock = threading.Lock()
_instance_counter = 0


def next_instance() -> int:
    """An instance number no other test of this session uses: xdist worker gwK takes 1+20K .. 20+20K,
    in turn, skipping any whose ports are taken (ports 5760+10N .. 5763+10N)."""
    global _instance_counter
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    k = int(worker[2:]) if worker.startswith("gw") and worker[2:].isdigit() else 0
    with _instance_lock:
        for _ in range(20):
            n = 1 + 20 * k + (_instance_counter % 20)
            _instance_counter += 1
            if all(port_free(5760 + 10 * n + d) for d in (0, 2, 3)):
                return n
    raise RuntimeError(f"no free SITL instance for worker {worker}")


@dataclass
class SitlPorts:
    instance: int

    @property
    def serial0(self) -> int:
        return 5760 + 10 * self.instance

    @property
    def serial1(self) -> int:
        return 5762 + 10 * self.instance

    @property
    def serial2(self) -> int:
        return 5763 + 10 * self.instance


class ArduCopterSitl:
    """One ArduCopter SITL process in its own working directory."""

    def __init__(self, binary: Path, defaults: Path, instance: int, workdir: Path, speedup: float = 1.0,
                 home: str = CMAC_HOME, extra_defaults: Optional[Dict[str, float]] = None) -> None:
        self.binary, self.defaults, self.workdir = binary, defaults, workdir
        self.ports = SitlPorts(instance)
        self.speedup = speedup
        self.home = home
        self.extra_defaults = extra_defaults or {}
        self.proc: Optional[subprocess.Popen] = None
        self.log_path = workdir / "arducopter.log"

    def start(self) -> "ArduCopterSitl":
        self.workdir.mkdir(parents=True, exist_ok=True)
        defaults = str(self.defaults)
        if self.extra_defaults:
            # a second defaults file, loaded after copter.parm (SITL takes a comma-separated list)
            extra = self.workdir / "test.parm"
            extra.write_text("".join(f"{k} {v}\n" for k, v in self.extra_defaults.items()))
            defaults += "," + str(extra)
        cmd = [str(self.binary), "--model", "+", "--speedup", str(self.speedup), "-I", str(self.ports.instance),
               "-w", "--defaults", defaults, "--home", self.home]
        (self.workdir / "cmdline").write_text(" ".join(cmd) + "\n")
        self.proc = subprocess.Popen(cmd, cwd=self.workdir, stdout=open(self.log_path, "w"), stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        self.wait_listening(self.ports.serial0, 30.0)
        return self

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def wait_listening(self, port: int, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not self.alive():
                raise RuntimeError(f"arducopter exited ({self.proc.returncode}); log: {self.log_tail()}")
            with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
                s.settimeout(0.5)
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    return
            time.sleep(0.1)
        raise RuntimeError(f"nothing listens on tcp {port} after {timeout}s; log: {self.log_tail()}")

    def log_tail(self, n: int = 2000) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-n:]
        except OSError:
            return "(no log)"

    def stop(self) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.proc.wait(timeout=5)

    def keep_artifacts(self, dest: Path) -> None:
        """Copy the SITL's stdout log, command line and logs/ (dataflash) to `dest`."""
        dest.mkdir(parents=True, exist_ok=True)
        for name in ("arducopter.log", "cmdline", "test.parm"):
            if (self.workdir / name).exists():
                shutil.copy2(self.workdir / name, dest / name)
        if (self.workdir / "logs").is_dir():
            shutil.copytree(self.workdir / "logs", dest / "logs", dirs_exist_ok=True)


# ------------------------------------------------------------------------------------------------
# The ground station on SERIAL0
# ------------------------------------------------------------------------------------------------

class GcsObserver:
    """Ground station on the autopilot's SERIAL0: heartbeats at 1 Hz (sysid 255), asks for the telemetry a
    ground station shows, records what the vehicle did, and sends hazards, reboots and signing set-up.
    Reconnects when the autopilot goes away (a reboot re-executes SITL, which closes its sockets)."""

    def __init__(self, url: str, alive: Callable[[], bool] = lambda: True, sysid: int = 255, compid: int = 190) -> None:
        self.url, self.sysid, self.compid = url, sysid, compid
        self._alive = alive
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self.conn: Any = None
        self.t0 = time.monotonic()
        self.heartbeats = 0
        self.armed = False
        self.armed_times: List[Tuple[float, bool]] = []         # (t, armed) at each change
        self.mode: Optional[str] = None
        self.modes: List[Tuple[float, str]] = []                # (t, mode) at each change
        self.alt = 0.0
        self.max_alt = 0.0
        self.landed_state = 0
        self.landed_states: List[Tuple[float, int]] = []
        self.reached: List[Tuple[float, int]] = []              # (t, seq) of MISSION_ITEM_REACHED
        self.statustext: List[Tuple[float, str]] = []
        self.statustext_from: List[Tuple[float, int, int, str]] = []  # (t, system, component, text)
        self._open_chunks: Dict[Any, Any] = {}
        self.battery_pct: Optional[int] = None
        self.battery_consumed_mah: Optional[int] = None
        self.battery_energy_j: Optional[float] = None            # BATTERY_STATUS.energy_consumed (hJ) in J
        self.battery_power_w: List[Tuple[float, float]] = []    # (t, V x I) of each BATTERY_STATUS with both
        # (t, the autopilot's time since boot in s) of each GLOBAL_POSITION_INT: maps the observer's wall clock to the
        # vehicle's, which runs SITL_SPEEDUP times faster (energy and durations are the vehicle's)
        self.boot_at: List[Tuple[float, float]] = []
        self.ekf_flags = 0
        self.gps_fix: Optional[int] = None
        self.params: Dict[str, Tuple[float, float]] = {}
        self.acks: List[Tuple[float, int, int]] = []            # (t, command, result)
        self.acks_by: List[Tuple[float, int, int, int]] = []    # (t, source component, command, result)
        # (t, system, component, name, value, time_boot_ms) of each NAMED_VALUE_FLOAT / NAMED_VALUE_INT
        self.named_values: List[Tuple[float, int, int, str, float, int]] = []
        self.connects = 0
        self.signing_key: Optional[bytes] = None
        self._mission_msgs: List[Any] = []                      # MISSION_REQUEST(_INT)/ACK addressed to us
        self._t = threading.Thread(target=self._run, daemon=True, name="gcs-observer")

    # ---- life ----
    def start(self, timeout: float = 60.0) -> "GcsObserver":
        self._connect()
        self._t.start()
        self.wait(lambda: self.heartbeats > 0, timeout, "no HEARTBEAT from the autopilot on SERIAL0")
        return self

    def stop(self) -> None:
        self._stop.set()
        self._t.join(timeout=5)
        self._close()

    def _connect(self) -> None:
        self.conn = mavutil.mavlink_connection(self.url, source_system=self.sysid, source_component=self.compid,
                                               dialect="ardupilotmega", retries=60)
        self.conn.mav.robust_parsing = True
        if self.signing_key is not None:
            self.conn.setup_signing(self.signing_key, sign_outgoing=True)
        self.connects += 1
        self._streams_asked = False

    def _close(self) -> None:
        try:
            self.conn.close()
        except Exception:
            pass

    def _request_streams(self) -> None:
        # every ArduPilot stream group at 4 Hz, plus the messages the record needs at a known rate
        self.conn.mav.request_data_stream_send(1, 1, mavlink.MAV_DATA_STREAM_ALL, 4, 1)
        for mid in (mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS, mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT):
            self.conn.mav.command_long_send(1, 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0, mid, 250_000, 0, 0, 0, 0, 0)

    def _run(self) -> None:
        next_hb = 0.0
        while not self._stop.is_set():
            if not self._alive():
                time.sleep(0.2)
                continue
            now = time.monotonic()
            try:
                if now >= next_hb:
                    next_hb = now + 1.0
                    self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                m = self.conn.recv_match(blocking=True, timeout=0.1)
            except (OSError, ConnectionError):
                m = None
                self._reconnect()
                continue
            if m is None:
                # pymavlink reports a closed TCP peer only by printing; notice it by the socket
                if self._peer_closed():
                    self._reconnect()
                continue
            self._record(m)

    def _peer_closed(self) -> bool:
        sock = getattr(self.conn, "port", None)
        if sock is None or not hasattr(sock, "recv"):
            return False
        try:
            sock.setblocking(False)
            data = sock.recv(1, socket.MSG_PEEK)
            return data == b""
        except BlockingIOError:
            return False
        except OSError:
            return True

    def _reconnect(self) -> None:
        self._close()
        deadline = time.monotonic() + 60
        while not self._stop.is_set() and time.monotonic() < deadline:
            if not self._alive():
                return
            try:
                self._connect()
                return
            except Exception:
                time.sleep(0.2)

    def _record(self, m: Any) -> None:
        t = m.get_type()
        now = time.monotonic()
        with self._lock:
            if t == "HEARTBEAT" and m.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1 and m.type != mavlink.MAV_TYPE_GCS:
                self.heartbeats += 1
                armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if armed != self.armed or not self.armed_times:
                    self.armed_times.append((now, armed))
                self.armed = armed
                mode = COPTER_MODES.get(m.custom_mode, str(m.custom_mode))
                if mode != self.mode:
                    self.modes.append((now, mode))
                self.mode = mode
                if not self._streams_asked:
                    self._streams_asked = True
                    self._request_streams()
            elif t == "GLOBAL_POSITION_INT":
                if m.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1:
                    self.boot_at.append((now, m.time_boot_ms / 1000.0))
                self.alt = m.relative_alt / 1000.0
                self.max_alt = max(self.max_alt, self.alt)
            elif t == "EXTENDED_SYS_STATE":
                if m.landed_state != self.landed_state or not self.landed_states:
                    self.landed_states.append((now, m.landed_state))
                self.landed_state = m.landed_state
            elif t == "MISSION_ITEM_REACHED":
                self.reached.append((now, m.seq))
            elif t == "STATUSTEXT":
                # A long text comes in MAVLink 2 chunks (one non-zero `id`, `chunk_seq` 1, 2, ... after the
                # first): joined into one text, as QGroundControl shows it.
                src = (m.get_srcSystem(), m.get_srcComponent())
                cid, seq = getattr(m, "id", 0), getattr(m, "chunk_seq", 0)
                open_at = self._open_chunks.get(src)
                if cid and seq > 0 and open_at is not None and open_at[0] == cid:
                    _, k, j = open_at
                    self.statustext[k] = (self.statustext[k][0], self.statustext[k][1] + m.text)
                    e = self.statustext_from[j]
                    self.statustext_from[j] = (e[0], e[1], e[2], e[3] + m.text)
                else:
                    self.statustext.append((now, m.text))
                    self.statustext_from.append((now, src[0], src[1], m.text))
                    self._open_chunks[src] = (cid, len(self.statustext) - 1, len(self.statustext_from) - 1) \
                        if cid else None
            elif t == "BATTERY_STATUS":
                self.battery_pct = m.battery_remaining if m.battery_remaining >= 0 else None
                self.battery_consumed_mah = m.current_consumed if m.current_consumed >= 0 else None
                self.battery_energy_j = 100.0 * m.energy_consumed if m.energy_consumed >= 0 else None
                mv = sum(v for v in m.voltages if v != 65535)
                if mv > 0 and m.current_battery >= 0:
                    self.battery_power_w.append((now, mv / 1000.0 * m.current_battery / 100.0))
            elif t == "EKF_STATUS_REPORT":
                self.ekf_flags = m.flags
            elif t == "GPS_RAW_INT":
                self.gps_fix = m.fix_type
            elif t == "PARAM_VALUE":
                pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
                self.params[pid.rstrip("\x00")] = (m.param_value, now)
            elif t in ("NAMED_VALUE_FLOAT", "NAMED_VALUE_INT"):
                name = m.name if isinstance(m.name, str) else m.name.decode(errors="replace")
                self.named_values.append((now, m.get_srcSystem(), m.get_srcComponent(), name.rstrip("\x00"),
                                          m.value, m.time_boot_ms))
            elif t in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK") and m.target_system == self.sysid:
                self._mission_msgs.append(m)
            elif t == "COMMAND_ACK":
                self.acks.append((now, m.command, m.result))
                self.acks_by.append((now, m.get_srcComponent(), m.command, m.result))

    # ---- queries ----
    def wait(self, cond: Callable[[], bool], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if cond():
                    return
            time.sleep(0.05)
        raise AssertionError(f"{what} (within {timeout:.0f}s){self.summary()}")

    @property
    def landed(self) -> bool:
        return self.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND

    def modes_since(self, t0: float) -> List[str]:
        with self._lock:
            before = [m for t, m in self.modes if t < t0][-1:]
            return before + [m for t, m in self.modes if t >= t0]

    def modes_flown(self) -> List[str]:
        with self._lock:
            return [m for _, m in self.modes]

    def vehicle_time(self, t: float) -> Optional[float]:
        """The autopilot's time since boot (s) at the observer's wall time `t`, interpolated between the
        GLOBAL_POSITION_INTs around it (None before the first or after the last)."""
        with self._lock:
            pts = list(self.boot_at)
        for (t0, b0), (t1, b1) in zip(pts, pts[1:]):
            if t0 <= t <= t1:
                return b0 if t1 == t0 else b0 + (b1 - b0) * (t - t0) / (t1 - t0)
        return None

    def ever_armed(self) -> bool:
        with self._lock:
            return any(a for _, a in self.armed_times)

    def arm_count(self, since: float = 0.0) -> int:
        """How many times the vehicle went from disarmed to armed (after `since`)."""
        with self._lock:
            return sum(1 for t, a in self.armed_times if a and t >= since)

    def reached_seqs(self) -> List[int]:
        with self._lock:
            return [s for _, s in self.reached]

    def texts_from(self, component: int, since: float = 0.0) -> List[str]:
        """STATUSTEXTs a component sent (routed here by the autopilot), after `since`."""
        with self._lock:
            return [s for t, _, c, s in self.statustext_from if c == component and t >= since]

    def texts(self) -> List[str]:
        with self._lock:
            return [s for _, s in self.statustext]

    def summary(self) -> str:
        with self._lock:
            return (f"\n[gcs observer] armed={self.armed} mode={self.mode} modes={[m for _, m in self.modes]} "
                    f"alt={self.alt:.1f} max_alt={self.max_alt:.1f} landed_state={self.landed_state} "
                    f"reached={[s for _, s in self.reached]} battery={self.battery_pct}% connects={self.connects} "
                    f"statustext(last 15)={[s for _, s in self.statustext][-15:]}")

    # ---- actions (each answered by the autopilot) ----
    def param_set(self, name: str, value: float, timeout: float = 10.0) -> float:
        """PARAM_SET on the ground-station port, then the autopilot's PARAM_VALUE echo (its new value)."""
        t0 = time.monotonic()
        for _ in range(3):
            self.conn.mav.param_set_send(1, 1, name.encode(), float(value), mavlink.MAV_PARAM_TYPE_REAL32)
            end = time.monotonic() + timeout / 3
            while time.monotonic() < end:
                with self._lock:
                    got = self.params.get(name)
                if got is not None and got[1] >= t0:
                    return got[0]
                time.sleep(0.05)
        raise AssertionError(f"PARAM_SET {name}={value}: no PARAM_VALUE{self.summary()}")

    def param_get(self, name: str, timeout: float = 10.0) -> float:
        t0 = time.monotonic()
        for _ in range(3):
            self.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
            end = time.monotonic() + timeout / 3
            while time.monotonic() < end:
                with self._lock:
                    got = self.params.get(name)
                if got is not None and got[1] >= t0:
                    return got[0]
                time.sleep(0.05)
        raise AssertionError(f"PARAM_REQUEST_READ {name}: no PARAM_VALUE{self.summary()}")

    def command_long(self, cmd: int, *params: float, timeout: float = 5.0, component: int = 1) -> Optional[int]:
        """COMMAND_LONG to `component` of the vehicle (the autopilot by default; 191 is the companion); the
        COMMAND_ACK result from that component, or None when none came."""
        p = list(params) + [0.0] * (7 - len(params))
        t0 = time.monotonic()
        self.conn.mav.command_long_send(1, component, cmd, 0, *p)
        end = t0 + timeout
        while time.monotonic() < end:
            with self._lock:
                got = [r for (t, src, c, r) in self.acks_by if t >= t0 and c == cmd and src == component]
            if got:
                return got[0]
            time.sleep(0.05)
        return None

    def upload_mission(self, items: List[Tuple[int, int, float, float, float, float]], timeout: float = 15.0) -> int:
        """Upload a mission as a ground station does (MISSION_COUNT, then each item the autopilot asks for with
        MISSION_REQUEST(_INT), as MISSION_ITEM_INT); `items` are (frame, command, param1, lat, lon, alt), item 0
        ArduPilot's home placeholder. Returns the autopilot's MISSION_ACK result."""
        with self._lock:
            self._mission_msgs.clear()
        self.conn.mav.mission_count_send(1, 1, len(items), mavlink.MAV_MISSION_TYPE_MISSION)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                msgs, self._mission_msgs = self._mission_msgs, []
            for m in msgs:
                if m.get_type() == "MISSION_ACK":
                    return m.type
                frame, cmd, p1, lat, lon, alt = items[m.seq]
                self.conn.mav.mission_item_int_send(1, 1, m.seq, frame, cmd, 0, 1, p1, 0, 0, 0, int(lat * 1e7),
                                                    int(lon * 1e7), alt, mavlink.MAV_MISSION_TYPE_MISSION)
            time.sleep(0.02)
        raise AssertionError(f"mission upload: no MISSION_ACK within {timeout}s{self.summary()}")

    def setup_signing(self, key: bytes) -> None:
        """SETUP_SIGNING on the ground-station port (ArduPilot stores the key and then requires signed frames on
        every port, GCS_Signing.cpp); this link signs from now on."""
        assert len(key) == 32
        self.conn.mav.setup_signing_send(1, 1, key, 0)
        time.sleep(0.5)
        self.signing_key = key
        self.conn.setup_signing(key, sign_outgoing=True)
