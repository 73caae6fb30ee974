"""PX4 SITL (built-in SIH quadrotor) as a pytest fixture: a fresh vehicle per test.

Where PX4 comes from: env `PX4_SITL_DIR` (a directory with `bin/px4` and `etc/`: PX4's own
`build/px4_sitl_default` or the prebuilt tree in `../shared/sitl/px4`), else `../shared/sitl/px4`
beside the checkout. Without one the PX4 tests are skipped with how to get one (docs/sitl.md).

Each test gets:
* its own network namespace when the process may make one (root: `unshare(CLONE_NEWNET)` on the
  test's thread, loopback up), so nothing listens beyond it and ports never meet another test's;
* its own `PX4_INSTANCE` (0-9; PX4 keeps a lock file and a socket per instance under /tmp, shared
  by every namespace) reserved with a lock file of ours;
* its own working directory with clean parameters (`PX4_PARAM_<NAME>=value` set at boot);
* a ground-station observer on PX4's GCS port (udp 18570+N), which judges the flight as a ground
  station sees it.
PX4's log and working directory are kept (and named) when the test fails.

Ports for instance N (PX4's etc/init.d-posix/px4-rc.mavlink): PX4 sends the onboard link to
udp 14540+N and listens for it on 14580+N; the GCS link listens on 18570+N.
"""
from __future__ import annotations

import ctypes
import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Dict, List, Optional

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
HOW_TO_GET_PX4 = ("no PX4 SITL: set PX4_SITL_DIR to a directory with bin/px4 and etc/ (PX4-Autopilot's "
                  "build/px4_sitl_default after `make px4_sitl_default`, or ../shared/sitl/px4); see docs/sitl.md")

# PX4's custom_mode: main mode in bits 16..24, sub mode in bits 24..32 (px4_custom_mode.h).
PX4_MODES = {(4, 2): "TAKEOFF", (4, 3): "LOITER", (4, 4): "MISSION", (4, 5): "RTL", (4, 6): "LAND"}


def px4_mode_name(custom_mode: int) -> str:
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    return PX4_MODES.get((main, sub), f"PX4_{main}_{sub}")


def find_px4_dir() -> Optional[Path]:
    env = os.environ.get("PX4_SITL_DIR")
    cands = [Path(env)] if env else [ROOT.parent / "shared" / "sitl" / "px4"]
    for c in cands:
        if (c / "bin" / "px4").is_file() and (c / "etc").is_dir():
            return c.resolve()
    return None


def runnable_tree(px4_dir: Path) -> Path:
    """A tree whose `bin/px4-<module>` command links work. PX4's build makes them symlinks to
    `px4`; a copy that lost the links has 3-byte files reading "px4" (not executable). Then a
    shadow tree of symlinks is made once under the temp directory and reused."""
    probe = px4_dir / "bin" / "px4-param"
    if not probe.exists() or probe.is_symlink() or os.access(probe, os.X_OK):
        return px4_dir
    tag = hashlib.sha256(str(px4_dir).encode()).hexdigest()[:12]
    shadow = Path(tempfile.gettempdir()) / f"companion-px4-tree-{tag}"
    if (shadow / "ready").exists():
        return shadow
    tmp = Path(tempfile.mkdtemp(prefix=shadow.name + ".", dir=shadow.parent))
    (tmp / "bin").mkdir()
    os.symlink(px4_dir / "etc", tmp / "etc")
    os.symlink(px4_dir / "bin" / "px4", tmp / "bin" / "px4")
    for f in (px4_dir / "bin").iterdir():
        if f.name == "px4":
            continue
        if f.stat().st_size < 16 and f.read_text(errors="replace").strip() == "px4":
            os.symlink("px4", tmp / "bin" / f.name)
        else:
            shutil.copy2(f, tmp / "bin" / f.name)
    (tmp / "ready").write_text("")
    try:
        os.rename(tmp, shadow)
    except OSError:            # another worker made it first
        shutil.rmtree(tmp, ignore_errors=True)
    return shadow


_CLONE_NEWNET = 0x40000000


def private_network() -> bool:
    """Move this thread (and every process and thread it starts from now on) into a new network
    namespace with loopback up. False when not allowed (then ports are shared with the host)."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        return False
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.unshare(_CLONE_NEWNET) != 0:
        return False
    return subprocess.run(["ip", "link", "set", "lo", "up"], capture_output=True).returncode == 0


class InstanceLock:
    """Reserve a PX4 instance number (0-9) machine-wide for this test."""

    def __init__(self) -> None:
        self.fd: Optional[int] = None
        self.n = -1

    def acquire(self, timeout: float = 600.0) -> int:
        deadline = time.time() + timeout
        while time.time() < deadline:
            for n in range(10):
                fd = os.open(f"/tmp/companion-px4-instance-{n}.lock", os.O_CREAT | os.O_RDWR, 0o666)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError:
                    os.close(fd)
                    continue
                if self._px4_running(n):
                    fcntl.flock(fd, fcntl.LOCK_UN)
                    os.close(fd)
                    continue
                self.fd, self.n = fd, n
                return n
            time.sleep(1.0)
        raise RuntimeError("no free PX4 instance in 0-9")

    def _free(self) -> int:
        """The first instance neither reserved by a test nor used by a running PX4 (not held)."""
        for n in range(10):
            fd = os.open(f"/tmp/companion-px4-instance-{n}.lock", os.O_CREAT | os.O_RDWR, 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fd, fcntl.LOCK_UN)
            except OSError:
                continue
            finally:
                os.close(fd)
            if not self._px4_running(n):
                return n
        raise RuntimeError("no free PX4 instance in 0-9")

    @staticmethod
    def _px4_running(n: int) -> bool:
        # PX4's server socket for instance n; a stale file without a listener does not count.
        sock = Path(f"/tmp/px4-sock-{n}")
        if not sock.exists():
            return False
        import socket
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            s.connect(str(sock))
            return True
        except OSError:
            return False
        finally:
            s.close()

    def release(self) -> None:
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = None


class GcsObserver:
    """A quiet ground station on PX4's GCS link: what the vehicle reports, kept for judging."""

    def __init__(self, instance: int) -> None:
        self.instance = instance
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{18570 + instance}",
                                               source_system=255, source_component=190)
        self.lock = threading.Lock()
        self.sysid = instance + 1
        self.armed_seen = False
        self.armed = False
        self.modes: List[str] = []
        self.mode = ""
        self.system_status = -1
        self.max_alt_m = 0.0
        self.alt_m = 0.0
        self.reached: List[int] = []
        self.landed_state = 0
        self.texts: List[str] = []
        self.battery_pct: Optional[int] = None
        self.battery_currents_ca: set = set()
        self.heartbeats = 0
        # (time, source component, command, result) of every COMMAND_ACK from the vehicle's system
        self.acks: List[tuple] = []
        # (time, lat_e7, lon_e7, relative alt m, mode) of every GLOBAL_POSITION_INT while armed
        self.track: List[tuple] = []
        self._mission_msgs: List[Any] = []     # MISSION_REQUEST(_INT)/MISSION_ACK addressed to this GCS
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        last_hb = 0.0
        while not self._stop:
            now = time.time()
            if now - last_hb > 0.5:
                try:
                    self.conn.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                except OSError:
                    pass
                last_hb = now
            try:
                m = self.conn.recv_match(blocking=True, timeout=0.2)
            except Exception:       # a malformed datagram: ignore it, keep observing
                continue
            if m is None or m.get_srcSystem() != self.sysid:
                continue
            t = m.get_type()
            with self.lock:
                if t == "HEARTBEAT" and m.get_srcComponent() == 1:
                    self.heartbeats += 1
                    self.armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                    self.armed_seen |= self.armed
                    self.system_status = m.system_status
                    self.mode = px4_mode_name(m.custom_mode)
                    if not self.modes or self.modes[-1] != self.mode:
                        self.modes.append(self.mode)
                elif t == "GLOBAL_POSITION_INT":
                    self.alt_m = m.relative_alt / 1000.0
                    if self.armed:
                        self.max_alt_m = max(self.max_alt_m, self.alt_m)
                        self.track.append((time.time(), m.lat, m.lon, self.alt_m, self.mode))
                elif t == "MISSION_ITEM_REACHED":
                    if not self.reached or self.reached[-1] != m.seq:
                        self.reached.append(m.seq)
                elif t == "EXTENDED_SYS_STATE":
                    self.landed_state = m.landed_state
                elif t == "STATUSTEXT":
                    self.texts.append(m.text)
                elif t == "SYS_STATUS":
                    self.battery_pct = m.battery_remaining
                    self.battery_currents_ca.add(m.current_battery)     # -1: not measured
                elif t == "COMMAND_ACK":
                    self.acks.append((time.time(), m.get_srcComponent(), m.command, m.result))
                elif t in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK") and m.target_system == 255:
                    self._mission_msgs.append(m)

    def upload_mission(self, items: List[tuple], timeout: float = 15.0) -> int:
        """Upload a mission as a ground station does: MISSION_COUNT, then each item PX4 asks for as
        MISSION_ITEM_INT; `items` are (frame, command, param1, lat, lon, alt), seq 0 the first item flown
        (PX4 keeps no home item). Returns PX4's MISSION_ACK result."""
        with self.lock:
            self._mission_msgs.clear()
        self.conn.mav.mission_count_send(self.sysid, 1, len(items), 0)
        deadline = time.time() + timeout
        while time.time() < deadline:
            with self.lock:
                msgs, self._mission_msgs = self._mission_msgs, []
            for m in msgs:
                if m.get_type() == "MISSION_ACK":
                    return m.type
                frame, cmd, p1, lat, lon, alt = items[m.seq]
                self.conn.mav.mission_item_int_send(self.sysid, 1, m.seq, frame, cmd, 0, 1, p1, 0, 0, 0,
                                                    int(lat * 1e7), int(lon * 1e7), alt, 0)
            time.sleep(0.02)
        raise AssertionError(f"PX4 instance {self.instance}: no MISSION_ACK to the upload; {self.summary()}")

    def wait(self, what: str, cond, timeout: float) -> None:
        deadline = time.time() + timeout
        while time.time() < deadline:
            with self.lock:
                if cond(self):
                    return
            time.sleep(0.2)
        raise AssertionError(f"PX4 instance {self.instance}: {what} not seen within {timeout:.0f} s; "
                             f"{self.summary()}")

    def summary(self) -> str:
        with self.lock:
            return (f"modes {self.modes}, armed now {self.armed} (ever {self.armed_seen}), max alt "
                    f"{self.max_alt_m:.1f} m, reached {self.reached}, landed_state {self.landed_state}, "
                    f"battery {self.battery_pct} %, texts {self.texts[-8:]}")

    def close(self) -> None:
        self._stop = True
        self._thread.join(timeout=2)
        self.conn.close()


class Px4Sitl:
    """One PX4 SIH vehicle in its own working directory."""

    def __init__(self, tree: Path, instance: int, workdir: Path, params: Dict[str, float]) -> None:
        self.tree, self.instance, self.workdir = tree, instance, workdir
        self.params = params
        self.log_path = workdir / "px4.log"
        self.proc: Optional[subprocess.Popen] = None
        self.observer: Optional[GcsObserver] = None

    @property
    def onboard_port(self) -> int:
        """Where PX4 sends the onboard link (the companion listens here)."""
        return 14540 + self.instance

    def start(self, ready_timeout: float = 60.0) -> None:
        self.workdir.mkdir(parents=True, exist_ok=True)
        env = dict(os.environ)
        env.update(PX4_SIMULATOR="sihsim", PX4_SYS_AUTOSTART="10040", PX4_SIM_MODEL="sihsim_quadx",
                   HEADLESS="1", PATH=f"{self.tree / 'bin'}:{env.get('PATH', '')}")
        for k, v in self.params.items():
            env[f"PX4_PARAM_{k}"] = str(v)
        self._log = open(self.log_path, "w")
        self.proc = subprocess.Popen([str(self.tree / "bin" / "px4"), "-d", "-i", str(self.instance),
                                      str(self.tree / "etc")], cwd=self.workdir, env=env,
                                     stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT)
        self.observer = GcsObserver(self.instance)
        try:
            self.observer.wait("a STANDBY heartbeat", lambda o: o.system_status == mavlink.MAV_STATE_STANDBY,
                               ready_timeout)
        except AssertionError as e:
            raise AssertionError(f"{e}; PX4 log {self.log_path}: {self.log_tail()}") from None

    def log_tail(self, n: int = 15) -> str:
        try:
            return " | ".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no log)"

    def stop(self) -> None:
        if self.observer:
            self.observer.close()
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if getattr(self, "_log", None):
            self._log.close()


def companion_help(exe: str) -> str:
    try:
        return subprocess.run([exe, "fly", "--help"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired):
        return ""


@pytest.fixture
def px4_vehicle(request, tmp_path):
    """Factory: `px4_vehicle(params={...})` starts a fresh PX4 SIH vehicle (up and in STANDBY)
    and returns it; it is stopped after the test, its working directory kept on failure."""
    if not os.environ.get("PX4_SITL_DIR") and "px4" not in (request.config.option.markexpr or ""):
        # A whole-suite run (e.g. the ArduPilot one) would fly them a second time beside
        # scripts/sitl_px4.sh, which exports PX4_SITL_DIR.
        pytest.skip("PX4 tests run with PX4_SITL_DIR set (scripts/sitl_px4.sh) or with -m px4")
    px4_dir = find_px4_dir()
    if px4_dir is None:
        pytest.skip(HOW_TO_GET_PX4)
    tree = runnable_tree(px4_dir)
    private_network()
    lock = InstanceLock()
    started: List[Px4Sitl] = []

    def make(params: Optional[Dict[str, float]] = None) -> Px4Sitl:
        n = lock.acquire()
        v = Px4Sitl(tree, n, tmp_path / f"px4-{n}", dict(params or {}))
        started.append(v)
        v.start()
        return v

    yield make
    failed = getattr(request.node, "rep_call", None) is not None and request.node.rep_call.failed
    for v in started:
        v.stop()
        if failed:
            print(f"\nPX4 instance {v.instance} kept: {v.workdir} (log {v.log_path})")
    lock.release()
    # PX4_KEEP_PASSED=1 keeps a passed test's folder too (a flaky flight's good runs, to compare)
    if not failed and not os.environ.get("PX4_KEEP_PASSED"):
        shutil.rmtree(tmp_path, ignore_errors=True)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    rep = outcome.get_result()
    setattr(item, "rep_" + rep.when, rep)


def pytest_configure(config: Any) -> None:
    config.addinivalue_line("markers", "px4: flies the companion against a real PX4 SITL (SIH)")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: Any, items: List[Any]) -> None:
    # Before `-m` selects: every test using a PX4 vehicle carries the `px4` marker.
    for item in items:
        if "px4_vehicle" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.px4)


class UdpRelay:
    """A UDP relay between PX4's onboard link and the companion that a test can pause (a link cut):
    PX4 -> relay (udp 14540+N) -> companion (udp `companion_port`); replies go back to PX4's
    14580+N. Frames from the companion are decoded and kept with their time, paused or not."""

    def __init__(self, instance: int, companion_port: int) -> None:
        import socket
        self.px4_in = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.px4_in.bind(("127.0.0.1", 14540 + instance))
        self.px4_addr = ("127.0.0.1", 14580 + instance)
        self.companion_addr = ("127.0.0.1", companion_port)
        self.paused = False
        self.lock = threading.Lock()
        self.from_companion: List[tuple] = []      # (time, message type, message)
        self._parser = mavlink.MAVLink(None)
        self._parser.robust_parsing = True
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import select
        while not self._stop:
            r, _, _ = select.select([self.px4_in], [], [], 0.2)
            if not r:
                continue
            data, addr = self.px4_in.recvfrom(65536)
            if addr[1] == self.companion_addr[1]:
                try:
                    msgs = self._parser.parse_buffer(data) or []
                except Exception:
                    msgs = []
                now = time.time()
                with self.lock:
                    for m in msgs:
                        self.from_companion.append((now, m.get_type(), m))
                if not self.paused:
                    self.px4_in.sendto(data, self.px4_addr)
            elif not self.paused:
                self.px4_in.sendto(data, self.companion_addr)

    def sent_between(self, t0: float, t1: float, types: tuple) -> List[Any]:
        with self.lock:
            return [m for (t, ty, m) in self.from_companion if t0 <= t <= t1 and ty in types]

    def close(self) -> None:
        self._stop = True
        self._thread.join(timeout=2)
        self.px4_in.close()
