"""`companion signing-setup` gives the key only to the autopilot the operator names (issue 40, item 5), against the
stand-in autopilot (1/1) behind a relay that records every frame signing-setup sends.

* no pin (or half a pin): refused before anything is written or sent;
* pinned 1/1 with an impostor 7/1 heard first (the relay holds the stand-in back): refused, and the relay shows no
  SETUP_SIGNING at all;
* pinned 1/1 with an impostor 7/1 speaking beside it: refused, no SETUP_SIGNING sent.
"""
from __future__ import annotations

import dataclasses
import os
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from standin import mavlink

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]


def signing_setup(url: str, key: Path, *extra: str, timeout: float = 60.0) -> subprocess.Popen:
    return subprocess.Popen([os.environ["COMPANION_BIN"], "signing-setup", "--connect", url, "--key", str(key),
                             "--timeout", "20s", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)


def autopilot_heartbeat() -> Any:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                             mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0,
                                             mavlink.MAV_STATE_STANDBY, 3)


def setups_sent(rl: Any) -> list:
    with rl._lock:
        return [(m.target_system, m.target_component) for (_, m, _) in rl.sent if m.get_type() == "SETUP_SIGNING"]


def impostor_until(rl: Any, done: threading.Event, srcsys: int = 7, srccomp: int = 1) -> threading.Thread:
    """An impostor autopilot sending heartbeats through the relay (to signing-setup) every 0.25 s until `done`."""
    def run() -> None:
        while not done.is_set():
            rl.inject_unsigned(autopilot_heartbeat(), srcsys=srcsys, srccomp=srccomp)
            time.sleep(0.25)
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


@pytest.mark.parametrize("pin", [(), ("--autopilot-sysid", "1"), ("--autopilot-compid", "1")],
                         ids=["unpinned", "sysid-only", "compid-only"])
def test_signing_setup_without_the_full_pin_is_refused_and_writes_nothing(autopilot_factory, relay, tmp_path, pin):
    ap = autopilot_factory()
    rl = relay(int(ap.standin.url.rsplit(":", 1)[1]))
    key = tmp_path / "signing.key"
    p = signing_setup(rl.url, key, *pin)
    out, err = p.communicate(timeout=30)
    assert p.returncode not in (None, 0), out + err
    assert "needs the autopilot named" in err and "--autopilot-compid" in err, err
    assert not key.exists(), "a key file was written"
    assert setups_sent(rl) == [] and rl.accepts == 0, "signing-setup connected or sent"


def test_signing_setup_pinned_with_an_impostor_heard_first_is_refused_and_sends_no_key(autopilot_factory, relay,
                                                                                       tmp_path):
    ap = autopilot_factory()
    rl = relay(int(ap.standin.url.rsplit(":", 1)[1]))
    rl.blackout(8.0)                                     # the real 1/1 held back: the impostor is heard first
    key = tmp_path / "signing.key"
    p = signing_setup(rl.url, key, "--autopilot-sysid", "1", "--autopilot-compid", "1")
    deadline = time.monotonic() + 10
    while rl._pair is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert rl._pair is not None, "signing-setup never connected to the relay"
    done = threading.Event()
    impostor_until(rl, done)
    try:
        out, err = p.communicate(timeout=40)
    finally:
        done.set()
    assert p.returncode not in (None, 0), out + err
    assert "another autopilot, 7/1" in err and "the key was not sent" in err, err
    assert "verified:" not in out, out
    assert setups_sent(rl) == [], f"SETUP_SIGNING sent to {setups_sent(rl)}"


def test_signing_setup_pinned_with_an_impostor_beside_the_autopilot_is_refused(autopilot_factory, relay, tmp_path):
    ap = autopilot_factory()
    rl = relay(int(ap.standin.url.rsplit(":", 1)[1]))
    key = tmp_path / "signing.key"
    done = threading.Event()
    p = signing_setup(rl.url, key, "--autopilot-sysid", "1", "--autopilot-compid", "1")
    deadline = time.monotonic() + 10
    while rl._pair is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert rl._pair is not None, "signing-setup never connected to the relay"
    # The stand-in's heartbeats reach signing-setup; an impostor 7/1 speaks too.
    impostor_until(rl, done)
    try:
        out, err = p.communicate(timeout=40)
    finally:
        done.set()
    assert p.returncode not in (None, 0), out + err
    assert "another autopilot, 7/1" in err, err
    assert setups_sent(rl) == [], f"SETUP_SIGNING sent to {setups_sent(rl)}"


def test_signing_setup_pinned_alone_sends_the_key_only_to_the_pinned_autopilot(autopilot_factory, relay, tmp_path):
    """The stand-in has no MAVLink signing, so the set-up ends unverified; what matters here is where the key went:
    every SETUP_SIGNING the relay saw was addressed to the pinned 1/1."""
    ap = autopilot_factory()
    rl = relay(int(ap.standin.url.rsplit(":", 1)[1]))
    key = tmp_path / "signing.key"
    p = signing_setup(rl.url, key, "--autopilot-sysid", "1", "--autopilot-compid", "1")
    out, err = p.communicate(timeout=60)
    assert p.returncode not in (None, 0), out + err
    assert "its frames stay unsigned" in err, err
    assert setups_sent(rl) and set(setups_sent(rl)) == {(1, 1)}, setups_sent(rl)
