"""`companion signing-setup` against a real ArduCopter SITL (issue 26): a fresh vehicle without a key gets one
from the companion's own command, which exits 0 only once the vehicle has proven it holds the key; then a
signed `companion fly` flies the mission. Judged from the vehicle: the ground station on SERIAL0 sees it arm,
fly and land disarmed; an observer with the key on SERIAL2 sees the autopilot's frames signed with it; the
relay in front of SERIAL1 sees every frame the companion sent signed.
"""
from __future__ import annotations

import os
import stat
import subprocess
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from standin import mavlink
from test_real_ardupilot import SPEEDUP, assert_flew_and_landed, fly_real

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

# signing-setup gives the key only to the autopilot named: system and component (issue 40).
PIN = ("--autopilot-sysid", "1", "--autopilot-compid", "1")


def signing_setup(url: str, key: Path, *extra: str, timeout: float = 90.0) -> subprocess.CompletedProcess:
    return subprocess.run([os.environ["COMPANION_BIN"], "signing-setup", "--connect", url, "--key", str(key),
                           *extra], capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)


def signed_heartbeats(url: str, key: bytes, timeout: float = 15.0) -> tuple:
    """(heartbeats from 1/1 that verified with `key`, unsigned or unverified ones) on a fresh connection."""
    conn = mavutil.mavlink_connection(url, source_system=1, source_component=mavlink.MAV_COMP_ID_ONBOARD_COMPUTER + 1,
                                      dialect="ardupilotmega", retries=30)
    # With a key set, pymavlink checks every signature; an unsigned frame then fails (allow_unsigned is None).
    conn.setup_signing(key, sign_outgoing=True)
    good = bad = 0
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline and good < 3:
            m = conn.recv_match(blocking=True, timeout=1.0)
            if m is None:
                continue
            if m.get_type() == "BAD_DATA":
                bad += 1
            elif m.get_type() == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == (1, 1):
                if m._header.incompat_flags & mavlink.MAVLINK_IFLAG_SIGNED:
                    good += 1
                else:
                    bad += 1
    finally:
        conn.close()
    return good, bad


def test_real_signing_setup_provisions_the_key_and_a_signed_flight_flies(arducopter, fly, monitors_factory, relay,
                                                                         tmp_path):
    veh = arducopter(speedup=SPEEDUP)
    key_file = tmp_path / "signing.key"
    r = signing_setup(veh.autopilot.url, key_file, *PIN)
    assert r.returncode == 0, f"signing-setup exit {r.returncode}\n{r.stdout}\n{r.stderr}"
    assert "verified" in r.stdout, r.stdout
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    key = bytes.fromhex(key_file.read_text().strip())
    assert len(key) == 32

    # A second run does not overwrite the key the autopilot now holds.
    again = signing_setup(veh.autopilot.url, key_file, *PIN)
    assert again.returncode != 0 and "refusing to overwrite" in again.stderr, again.stderr
    assert bytes.fromhex(key_file.read_text().strip()) == key

    # The autopilot itself signs with the key (an observer with the key on SERIAL2).
    good, bad = signed_heartbeats(veh.autopilot.monitor_url, key)
    assert good >= 3, f"{good} signed heartbeats verified with the key, {bad} not"
    # The ground-station observer on SERIAL0 signs from now on too (no second SETUP_SIGNING sent).
    veh.gcs.signing_key = key
    veh.gcs.conn.setup_signing(key, sign_outgoing=True)

    f = fly_real(veh, fly, monitors_factory, relay, signing_key=key)
    sent = [m for (_, m, _) in f.ctx.relay.sent]
    assert sent and all(m._header.incompat_flags & mavlink.MAVLINK_IFLAG_SIGNED for m in sent), \
        "the companion sent unsigned frames"
    assert_flew_and_landed(f)
    err = f.run.stderr_path.read_text()
    assert "without MAVLink signing" not in err, err[-2000:]


def test_real_require_signing_refuses_an_autopilot_without_the_key(arducopter, fly, tmp_path):
    """--require-signing with a key the autopilot does not hold: nothing is commanded, and stderr says why."""
    veh = arducopter(speedup=SPEEDUP)
    key = os.urandom(32)
    veh.autopilot.signing_key = key
    run = fly(veh.autopilot, extra=("--require-signing", "--duration", "25s"))
    rc = run.wait_exit(60)
    assert rc == 0, run.output()
    assert not veh.gcs.ever_armed(), "the vehicle armed" + run.output()
    err = run.stderr_path.read_text()
    assert "refused" in err and "--require-signing" in err, err[-2000:]
