"""A stop during the take-off, against a fresh real ArduCopter SITL (skipped without the binary; issue 40, item 1).

`fly --auto-start` arms and takes off in GUIDED; SIGINT arrives while the vehicle climbs through 1-3 m. The ground
station (GcsObserver on SERIAL0) hears `Companion stopping: RTL, take over` from the companion and sees the vehicle in
RTL (params/link.toml [flight] handoff = "rtl"); once the companion is gone the vehicle is never in GUIDED again, and
it ends landed and disarmed by the autopilot's own RTL. The stand-in cases (every step of the start, both signals,
two signals within 100 ms) are in test_stop_during_start.py; this is the one real flight, kept short.
"""
from __future__ import annotations

import signal
import time

import pytest

from test_real_ardupilot import SPEEDUP

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]


def test_real_sigint_while_climbing_hands_off_to_rtl_and_the_vehicle_lands(arducopter, fly):
    veh = arducopter(speedup=SPEEDUP)
    gcs = veh.gcs
    run = fly(veh.autopilot)                              # --auto-start --once
    gcs.wait(lambda: gcs.armed and gcs.mode == "GUIDED" and gcs.alt >= 1.0, 240, "the climb through 1 m in GUIDED")
    assert run.proc.poll() is None, run.output()
    t0 = time.monotonic()
    at_m = gcs.alt
    run.proc.send_signal(signal.SIGINT)
    gcs.wait(lambda: gcs.mode == "RTL", 10.0, f"RTL after SIGINT at {at_m:.1f} m")
    gcs.wait(lambda: any(s.startswith("Companion stopping: RTL") for t, s in gcs.statustext if t >= t0), 5.0,
             "the stop's STATUSTEXT")
    rc = run.wait_exit(20)
    assert rc == 0, f"exit {rc}\n" + run.output()
    gone = time.monotonic()
    gcs.wait(lambda: not gcs.armed and gcs.landed, 180, "landed and disarmed by the autopilot's RTL")
    with gcs._lock:
        after = [m for t, m in gcs.modes if t >= gone]
    assert "GUIDED" not in after, f"GUIDED after the companion exited: {after}" + gcs.summary()
    events = [e for r in run.records()[-3:] for e in r.get("events", [])]
    assert any("hand-off RTL" in e for e in events), events
    print(f"SIGINT at {at_m:.1f} m: RTL, landed and disarmed; modes after exit {after}")
