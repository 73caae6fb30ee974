"""`fly --learn-cpt` learns only from sources that can be trusted (issue 40, item 6), against the stand-in ArduCopter.

* without signing and without a dedicated onboard link: refused at start, with the reason, nothing commanded;
* with a dedicated onboard link (`--onboard udpin:127.0.0.1:PORT`, the tracker on it) on an unsigned autopilot link,
  and with signing: a spoofer sending the tracker's `tgt_det` unsigned as 1/100 on the autopilot link moves no
  learned row (without these rules the rows moved up to 0.36 from their prior; the real tracker alone moves them
  about 0.02).
"""
from __future__ import annotations

import dataclasses
import os
import socket
import threading
import time
from typing import Any, List

import pytest

from standin import mavlink
from test_companion_fly import assert_mission_completed, fly_mission

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

# The most a learned row may move from its prior here: the real tracker alone moves it about 0.02.
MAX_SHIFT = 0.1


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def spoof_tracker(sa: Any, done: threading.Event) -> threading.Thread:
    """Unsigned `tgt_det` from 1/100 (the tracker's ids) on the autopilot link, flipping 0/1 at 10 Hz."""
    def run() -> None:
        k = 0
        while not done.is_set():
            msg = mavlink.MAVLink_named_value_float_message(k * 100, b"tgt_det", float(k % 2))
            sa.inject_unsigned(msg, srcsys=1, srccomp=mavlink.MAV_COMP_ID_CAMERA)
            k += 1
            time.sleep(0.1)
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def learned_shifts(records: List[dict]) -> List[float]:
    return [abs(u["new"] - u["prior"]) for r in records if "kind" not in r for u in r.get("cpt_learned", [])]


def test_learn_cpt_on_an_unsigned_link_without_an_onboard_link_is_refused(autopilot_factory, fly):
    ap = autopilot_factory()
    run = fly(ap, extra=("--learn-cpt",))
    rc = run.wait_exit(60)
    assert rc not in (None, 0), run.output()
    err = run.stderr_path.read_text()
    assert "--learn-cpt: the autopilot link is unsigned" in err and "--onboard" in err, err[-2000:]
    assert not ap.standin.rec.of("arm")


def test_learn_cpt_with_a_network_onboard_link_is_refused(autopilot_factory, fly):
    ap = autopilot_factory()
    run = fly(ap, extra=("--learn-cpt", "--onboard", f"udpin:0.0.0.0:{free_udp_port()}"))
    rc = run.wait_exit(60)
    assert rc not in (None, 0), run.output()
    assert "is reachable from a network" in run.stderr_path.read_text(), run.output()
    assert not ap.standin.rec.of("arm")


@pytest.mark.parametrize("trust", ["onboard", "signed"])
def test_a_spoofed_unsigned_tracker_moves_no_learned_row(autopilot_factory, fly, monitors_factory, trust):
    if trust == "signed":
        ap = autopilot_factory(signing_key=os.urandom(32))
        extra: tuple = ("--learn-cpt",)
    else:
        port = free_udp_port()
        # The tracker speaks on the companion's own onboard link; the autopilot link stays unsigned.
        ap = dataclasses.replace(autopilot_factory(), monitor_url=f"udpout:127.0.0.1:{port}")
        extra = ("--learn-cpt", "--onboard", f"udpin:127.0.0.1:{port}")
    done = threading.Event()
    spoof_tracker(ap.standin, done)
    try:
        f = fly_mission(ap, fly, monitors_factory, extra=extra)
    finally:
        done.set()
    assert_mission_completed(f)
    shifts = learned_shifts(f.records)
    assert shifts, "no CPT row learned in a flight that tracked\n" + f.why()
    assert max(shifts) <= MAX_SHIFT, f"a learned row moved {max(shifts):.3f} from its prior"
