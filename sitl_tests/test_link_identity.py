"""Who the companion takes for the autopilot, and what it says about an untrusted link (issue 26, items 3-4),
against the stand-in autopilot (1/1) behind a relay that lets an impostor speak first.

The relay holds the stand-in's frames back (a blackout) while the impostor, component 2 of the same system,
sends autopilot HEARTBEATs to the companion; then the real autopilot is heard. Judged by what the stand-in
did (armed or not) and by what the companion sent (targets, STATUSTEXT).
"""
from __future__ import annotations

import time
from typing import Any

import pytest

from standin import mavlink

pytestmark = [pytest.mark.companion_fly]


def impostor_heartbeat() -> Any:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                             mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0,
                                             mavlink.MAV_STATE_STANDBY, 3)


def impostor_first(rl: Any) -> None:
    """While the relay holds the real autopilot back (a blackout set before the companion connected), an
    impostor 1/2 sends autopilot heartbeats: it is heard first."""
    deadline = time.monotonic() + 10
    while rl._pair is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert rl._pair is not None, "the companion never connected to the relay"
    while rl.in_blackout():
        rl.inject_unsigned(impostor_heartbeat(), srcsys=1, srccomp=2)
        time.sleep(0.25)


def wait_for(cond: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.1)
    return False


def test_the_pin_is_system_and_component_an_impostor_1_2_heard_first_is_never_obeyed(autopilot_factory, fly,
                                                                                        relay):
    ap = autopilot_factory()
    sa = ap.standin
    rl = relay(int(ap.url.rsplit(":", 1)[1]))
    via = type(ap)(url=rl.url, monitor_url=ap.monitor_url)
    rl.blackout(6.0)
    run = fly(via, extra=("--autopilot-sysid", "1", "--duration", "60s"))
    impostor_first(rl)
    armed = wait_for(lambda: bool(sa.rec.of("arm")) or run.proc.poll() is not None, 50)
    assert armed and sa.rec.of("arm"), "the real autopilot 1/1 was never armed\n" + run.output()
    with rl._lock:
        sent = [m for (_, m, _) in rl.sent]
    targets = {(m.target_system, m.target_component) for m in sent if m.get_type() in ("COMMAND_LONG", "COMMAND_INT")}
    assert targets == {(1, 1)}, f"commands went to {targets}"
    err = run.stderr_path.read_text()
    assert "first autopilot heard" not in err, err[-2000:]


def test_without_a_pin_the_choice_and_the_unsigned_link_are_said(autopilot_factory, fly, relay):
    ap = autopilot_factory()
    rl = relay(int(ap.url.rsplit(":", 1)[1]))
    via = type(ap)(url=rl.url, monitor_url=ap.monitor_url)
    run = fly(via, extra=("--duration", "60s"))

    def texts() -> list:
        with rl._lock:
            return [m.text for (_, m, _) in rl.sent if m.get_type() == "STATUSTEXT"]

    said = wait_for(lambda: any("not pinned" in t for t in texts()) and any("UNSIGNED" in t for t in texts()), 30)
    assert said, f"STATUSTEXT sent: {texts()}\n" + run.output()
    err = run.stderr_path.read_text()
    assert "autopilot 1/1 chosen: the first autopilot heard" in err and "--autopilot-sysid 1" in err, err[-2000:]
    assert "without MAVLink signing" in err, err[-2000:]
    assert sum("UNSIGNED" in t for t in texts()) == 1, texts()


def test_require_signing_without_a_key_refuses_to_start(autopilot_factory, fly):
    ap = autopilot_factory()
    run = fly(ap, extra=("--require-signing",))
    rc = run.wait_exit(30)
    assert rc not in (None, 0), run.output()
    err = run.stderr_path.read_text()
    assert "--require-signing: no --signing-key given" in err, err[-2000:]
    assert not ap.standin.rec.of("arm")
