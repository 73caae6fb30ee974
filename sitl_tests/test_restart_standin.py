"""A companion restarted while the vehicle flies, against the stand-in ArduCopter (the real-SITL version, with
the route's own end, is test_real_restart.py): killed (SIGKILL, no stop path) while flying its route in AUTO and
started again with the same command line and --log-dir, it never says it waits for the operator; the ground
station hears `flight in progress` with the hand-off from component 191, the vehicle is put in RTL
(params/link.toml [flight] handoff), a MISSION_START is refused while the flight goes on, and the record says it
was not resumed."""
from __future__ import annotations

import time
from typing import Any, Callable, List

import pytest

from standin import mavlink

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

COMPANION = 191


def wait(pred: Callable[[], bool], timeout: float, what: str, run: Any = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        if run is not None and run.proc.poll() is not None:
            raise AssertionError(f"companion exited ({run.proc.returncode}) while waiting for {what}\n{run.output()}")
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout}s waiting for {what}" + (f"\n{run.output()}" if run else ""))


def texts_from_companion(gcs: Any, since: float) -> List[str]:
    return [m.text for m in gcs.since(since, "STATUSTEXT") if m.get_srcComponent() == COMPANION]


def test_restarted_in_the_air_says_a_flight_is_in_progress_and_hands_off(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    first = fly(ap)                                        # --auto-start, as the real tests fly
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["alt"] > 10.0, 90, "the route in AUTO", first)
    first.proc.kill()
    first.proc.wait(timeout=10)
    time.sleep(1.0)
    assert sa.state()["armed"] and sa.state()["mode"] == "AUTO"
    t0 = time.monotonic()
    again = fly(ap, log_dir=first.log_dir)                 # systemd's restart: same command line, same --log-dir
    wait(lambda: any("flight in progress" in t and "hand-off RTL" in t for t in texts_from_companion(gcs, t0)), 10,
         "STATUSTEXT 'flight in progress, hand-off RTL' from 191", again)
    wait(lambda: sa.state()["mode"] == "RTL", 10, "the hand-off mode RTL", again)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_DENIED, "a start was taken while the found flight goes on"
    time.sleep(2.0)
    said = texts_from_companion(gcs, t0)
    assert not [t for t in said if "waiting for the operator" in t], said
    again.proc.terminate()
    again.proc.wait(timeout=15)
    recs = again.records()
    evs = [e for r in recs for e in r.get("events", [])]
    assert any(e.startswith("started in flight") and "mode AUTO" in e and "hand-off RTL" in e and "not resumed" in e
               for e in evs), evs[:20]
    assert any(r.get("vehicle", {}).get("operator") == "flight_in_progress" for r in recs)
