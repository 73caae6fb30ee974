"""Fixtures for the SITL tests.

* `standin`: a factory that starts the stand-in ArduCopter (the `standin` package, a test fixture) on a free
  loopback port and stops it afterwards.
* `autopilot`: what the companion flies against: the stand-in, or the real SITL named by env `SITL_URL`
  (then tests marked `standin_only` are skipped, since a real SITL has no hazard hooks or recording).
* `fly`: starts the real companion (`$COMPANION_BIN fly ...`, command line built by helpers.companion_fly_cmd)
  with its own log dir, and collects its decision log.

* `arducopter`: a factory that starts a fresh real ArduCopter SITL for the test (real_autopilot.py: own working
  directory, own instance number, `-w`), with `gcs_observer` on its SERIAL0; tests using it are marked
  `real_autopilot` and are skipped, saying how to get one, when no ArduCopter SITL binary is found.
* `relay`: a factory for a TCP relay (relay.py) between the companion and an autopilot port.

Tests marked `companion_fly` always run (CI included): `$COMPANION_BIN` must be a companion binary with `fly`.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from helpers import GcsClient, companion_fly_cmd, read_decision_log  # noqa: E402
from standin import OnboardMonitors, StandinAutopilot, StandinConfig  # noqa: E402
from real_autopilot import ARTIFACTS, ArduCopterSitl, GcsObserver, find_arducopter, next_instance  # noqa: E402
from relay import Relay  # noqa: E402

SITL_URL = os.environ.get("SITL_URL")                                   # e.g. tcp:127.0.0.1:5762 (ArduPilot SERIAL1)
SITL_MONITOR_URL = os.environ.get("SITL_MONITOR_URL", "tcp:127.0.0.1:5763")   # a second SITL port for the monitors
STANDIN_SPEEDUP = float(os.environ.get("STANDIN_SPEEDUP", "4"))
FLY_TIMEOUT_S = float(os.environ.get("SITL_FLY_TIMEOUT", "240"))


def pytest_configure(config: Any) -> None:
    config.addinivalue_line("markers", "companion_fly: flies `$COMPANION_BIN fly` end to end")
    config.addinivalue_line("markers", "standin_only: needs the stand-in's own controls (link cut, garbage/unsigned "
                            "injection, obstacle placement) or its recording (skipped with SITL_URL)")
    config.addinivalue_line("markers", "real_autopilot: flies a fresh real ArduCopter SITL per test (skipped, saying "
                            "how to get one, without an arducopter binary)")
    config.addinivalue_line("markers", "sitl_hazard: injects a hazard with PARAM_SET (SIM_*/BATT_*), which a real "
                            "ArduPilot SITL accepts too; runs against SITL_URL")


def pytest_collection_modifyitems(config: Any, items: List[Any]) -> None:
    _, _, why_no_sitl = find_arducopter()
    for item in items:
        only = item.get_closest_marker("standin_only")
        if SITL_URL and only:
            why = only.kwargs.get("reason", "this test needs the stand-in's hazard injection/recording")
            item.add_marker(pytest.mark.skip(reason=f"SITL_URL={SITL_URL}: {why}"))
        if why_no_sitl and item.get_closest_marker("real_autopilot"):
            item.add_marker(pytest.mark.skip(reason=why_no_sitl))


@pytest.hookimpl(tryfirst=True, hookwrapper=True)
def pytest_runtest_makereport(item: Any, call: Any):
    # fixtures read item.rep_call at teardown to keep a failed test's logs
    outcome = yield
    rep = outcome.get_result()
    setattr(item, "rep_" + rep.when, rep)


# ------------------------------------------------------------------------------------------------
# stand-in
# ------------------------------------------------------------------------------------------------

@pytest.fixture
def standin():
    """Factory: standin(**StandinConfig fields) -> started StandinAutopilot on 127.0.0.1:<free port>."""
    started: List[StandinAutopilot] = []

    def make(**overrides: Any) -> StandinAutopilot:
        overrides.setdefault("listen", "tcp:127.0.0.1:0")
        sa = StandinAutopilot(StandinConfig(**overrides)).start()
        started.append(sa)
        return sa

    yield make
    errors = []
    for sa in started:
        sa.stop()
        errors += [e.data for e in sa.rec.of("handler_error")]
    if errors:
        pytest.fail(f"stand-in handler errors (a fixture bug): {errors[:5]}")


@pytest.fixture
def client():
    """Factory: client(url, **kw) -> GcsClient, closed afterwards."""
    made: List[GcsClient] = []

    def make(url: str, **kw: Any) -> GcsClient:
        c = GcsClient(url, **kw)
        made.append(c)
        return c

    yield make
    for c in made:
        c.close()


# ------------------------------------------------------------------------------------------------
# companion runs
# ------------------------------------------------------------------------------------------------

@dataclass
class Autopilot:
    url: str                                   # what the companion connects to
    monitor_url: str                           # where the onboard monitors connect
    standin: Optional[StandinAutopilot] = None  # None against a real SITL
    signing_key: Optional[bytes] = None


@pytest.fixture
def autopilot_factory(standin):
    def make(**overrides: Any) -> Autopilot:
        if SITL_URL:
            return Autopilot(url=SITL_URL, monitor_url=SITL_MONITOR_URL, signing_key=overrides.get("signing_key"))
        overrides.setdefault("speedup", STANDIN_SPEEDUP)
        overrides.setdefault("ekf_ready_s", 8.0)
        sa = standin(**overrides)
        return Autopilot(url=sa.url, monitor_url=sa.url, standin=sa, signing_key=overrides.get("signing_key"))

    return make


@dataclass
class FlightRun:
    proc: subprocess.Popen
    log_dir: Path
    stdout_path: Path
    stderr_path: Path
    cmd: List[str]
    started: float = field(default_factory=time.monotonic)

    def records(self) -> List[Dict[str, Any]]:
        return read_decision_log(self.log_dir, fallback=self.stdout_path)

    def output(self) -> str:
        return f"cmd: {' '.join(self.cmd)}\n--- stdout\n{self.stdout_path.read_text()[-3000:]}\n--- stderr\n{self.stderr_path.read_text()[-3000:]}"

    def wait_exit(self, timeout: float) -> Optional[int]:
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            return None


@pytest.fixture
def fly(tmp_path):
    """Factory: fly(autopilot, mission=None, extra=(), auto_start=True, once=True, log_dir=None) -> FlightRun of
    `companion fly` (killed at teardown)."""
    runs: List[FlightRun] = []

    def start(ap: Autopilot, mission: Optional[Path] = None, extra: tuple = (), auto_start: bool = True,
              once: bool = True, log_dir: Optional[Path] = None) -> FlightRun:
        exe = os.environ["COMPANION_BIN"]
        n = len(runs)
        if log_dir is None:      # a restart passes the earlier run's, as systemd's unit does
            log_dir = tmp_path / f"companion-log-{n}"
            log_dir.mkdir()
        key_file = None
        if ap.signing_key is not None:
            key_file = tmp_path / f"signing-{n}.key"
            key_file.write_text(ap.signing_key.hex())
        cmd = companion_fly_cmd(exe, ap.url, log_dir, mission=mission, signing_key_file=key_file, extra=extra,
                                auto_start=auto_start, once=once)
        out, err = tmp_path / f"companion-{n}.out", tmp_path / f"companion-{n}.err"
        proc = subprocess.Popen(cmd, stdout=open(out, "w"), stderr=open(err, "w"), stdin=subprocess.DEVNULL,
                                env={**os.environ, "RUST_BACKTRACE": "1"})
        run = FlightRun(proc, log_dir, out, err, cmd)
        runs.append(run)
        return run

    yield start
    for r in runs:
        if r.proc.poll() is None:
            r.proc.terminate()
            try:
                r.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                r.proc.kill()
                r.proc.wait(timeout=10)


@pytest.fixture
def monitors_factory():
    made: List[OnboardMonitors] = []

    def make(ap: Autopilot, **kw: Any) -> OnboardMonitors:
        kw.setdefault("request_streams", ap.standin is None)
        m = OnboardMonitors(ap.monitor_url, signing_key=ap.signing_key, **kw).start()
        made.append(m)
        return m

    yield make
    for m in made:
        m.stop()


# ------------------------------------------------------------------------------------------------
# a real ArduCopter SITL per test
# ------------------------------------------------------------------------------------------------

@dataclass
class RealVehicle:
    sitl: ArduCopterSitl
    gcs: GcsObserver
    autopilot: Autopilot          # url: SERIAL1 (the companion's port), monitor_url: SERIAL2


def _failed(request: Any) -> bool:
    rep = getattr(request.node, "rep_call", None)
    return rep is None or rep.failed


# The pack the real ArduCopter SITL flies unless a test says otherwise: the mission's 74 Wh (params/missions/
# tracking.toml [battery]) as a 3S pack, 74 Wh / 11.1 V = 6667 mAh. The companion reckons its energy goal from the
# autopilot's BATT_CAPACITY (docs/guarantee.md); SITL's default 3300 mAh does not hold the default mission under the
# params' power model, so every default-mission flight would be refused at launch.
ARDUCOPTER_PACK: Dict[str, float] = {"BATT_CAPACITY": 12000}


@pytest.fixture
def arducopter(request, tmp_path):
    """Factory: arducopter(speedup=1.0, extra_defaults=None) -> RealVehicle: a fresh ArduCopter SITL in its own
    working directory and instance, up and streaming to its ground-station observer on SERIAL0. Stopped at
    teardown (process group killed); its log, command line and logs/ kept under sitl_tests/artifacts/<test>/
    when the test failed, with the companion's output."""
    binary, defaults, why = find_arducopter()
    if binary is None:
        pytest.skip(why)
    vehicles: List[RealVehicle] = []

    def make(speedup: float = 1.0, extra_defaults: Optional[Dict[str, float]] = None) -> RealVehicle:
        n = len(vehicles)
        sitl = ArduCopterSitl(binary, defaults, next_instance(), tmp_path / f"arducopter-{n}", speedup=speedup,
                              extra_defaults={**ARDUCOPTER_PACK, **(extra_defaults or {})})
        vehicles.append(RealVehicle(sitl, None, None))  # type: ignore[arg-type]
        sitl.start()
        gcs = GcsObserver(f"tcp:127.0.0.1:{sitl.ports.serial0}", alive=sitl.alive).start()
        vehicles[-1].gcs = gcs
        sitl.wait_listening(sitl.ports.serial1, 30.0)
        sitl.wait_listening(sitl.ports.serial2, 30.0)
        ap = Autopilot(url=f"tcp:127.0.0.1:{sitl.ports.serial1}", monitor_url=f"tcp:127.0.0.1:{sitl.ports.serial2}")
        vehicles[-1].autopilot = ap
        return vehicles[-1]

    yield make
    failed = _failed(request)
    for v in vehicles:
        if v.gcs is not None:
            v.gcs.stop()
        v.sitl.stop()
        if failed:
            dest = ARTIFACTS / request.node.name / v.sitl.workdir.name
            v.sitl.keep_artifacts(dest)
            if v.gcs is not None:
                (dest / "gcs_observer.txt").write_text(v.gcs.summary() + "\n" + "\n".join(v.gcs.texts()) + "\n")
    if failed:
        dest = ARTIFACTS / request.node.name
        dest.mkdir(parents=True, exist_ok=True)
        for f in tmp_path.glob("companion-*"):
            if f.is_file():
                shutil.copy2(f, dest / f.name)
            else:
                shutil.copytree(f, dest / f.name, dirs_exist_ok=True)


@pytest.fixture
def gcs_observer(arducopter):
    """A fresh vehicle's ground-station observer (for tests that need only the one vehicle)."""
    return arducopter().gcs


@pytest.fixture
def relay():
    """Factory: relay(upstream_port) -> started Relay on 127.0.0.1:<free port>; stopped at teardown."""
    made: List[Relay] = []

    def make(upstream_port: int, **kw: Any) -> Relay:
        r = Relay(upstream_port, **kw).start()
        made.append(r)
        return r

    yield make
    for r in made:
        r.stop()
