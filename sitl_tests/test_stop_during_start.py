"""A stop at each step of the start never leaves a vehicle the companion armed (issue 40, item 1), on the stand-in.

`fly --auto-start` sets GUIDED, arms once the autopilot reports ready, and takes off to 10 m. SIGINT or SIGTERM (once,
or twice within 100 ms) arrives:

* while the ARM waits for the autopilot to be ready (WAITING_READY): nothing was armed, nothing is armed later;
* while the ARM is on its way (sent, its answer and the armed heartbeats not yet heard: a slow link towards the
  companion, the relay's `delay_down`);
* right after the ARM was accepted;
* while climbing through 1, 3 and 6 m.

Then the vehicle, as the stand-in (the autopilot) has it once the companion is gone, is disarmed on the ground or in
the hand-off mode (params/link.toml [flight] handoff = "rtl"), never armed in GUIDED; the ground station heard the
companion say so, and the last record says what it did.
"""
from __future__ import annotations

import signal
import time
from typing import Any, List

import pytest

from helpers import GcsClient

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

COMPANION = 191
HANDOFF_MODE = "RTL"                   # params/link.toml [flight] handoff = "rtl"
ARM = 400                              # MAV_CMD_COMPONENT_ARM_DISARM
SLOW_LINK_S = 0.8                      # the autopilot's answers and heartbeats reach the companion this much later


def wait(pred, timeout: float, what: str, run: Any, poll: float = 0.005) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        if run.proc.poll() is not None:
            raise AssertionError(f"companion exited ({run.proc.returncode}) while waiting for {what}\n{run.output()}")
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout}s waiting for {what}\n{run.output()}")


def logged(run: Any, text: str) -> bool:
    return text in run.stderr_path.read_text()


def arm_commands(sa: Any) -> List[Any]:
    return [e for e in sa.commands(ARM) if e.data["src"][1] == COMPANION and e.data["params"][0] == 1.0]


def start(step: str, autopilot_factory: Any, fly: Any, relay: Any, client: Any):
    """The stand-in, a ground station on it, and `fly --auto-start` at `step` of the start."""
    # WAITING_READY: the position estimate is ready only after 24 s simulated (6 s wall at the default speedup), long
    # after the companion asked to arm, even on a busy machine.
    ap = autopilot_factory(ekf_ready_s=24.0 if step == "arm_waiting_ready" else 8.0)
    sa = ap.standin
    gcs = client(sa.url)
    if step == "arm_pending":
        r = relay(int(sa.url.rsplit(":", 1)[1]))
        r.delay_down(SLOW_LINK_S)
        ap.url = r.url
    run = fly(ap)
    if step == "arm_waiting_ready":
        wait(lambda: logged(run, "ARM: WAITING_READY"), 30, "the ARM waiting for the autopilot", run)
    elif step == "arm_pending":
        # The stand-in armed and answered; the answer is still on its way to the companion.
        wait(lambda: arm_commands(sa), 30, "the companion's ARM at the autopilot", run)
        assert not logged(run, "ARM: ACCEPTED"), "the slow link did not hold the answer back"
    elif step == "arm_accepted":
        wait(lambda: logged(run, "ARM: ACCEPTED"), 30, "the ARM accepted", run)
    else:
        alt = float(step.removeprefix("climb_").removesuffix("m"))
        wait(lambda: sa.state()["alt"] >= alt, 30, f"the climb through {alt} m", run)
    return sa, gcs, run


def stop_with(run: Any, signals: List[int]) -> float:
    t0 = time.monotonic()
    for i, sig in enumerate(signals):
        if i:
            time.sleep(0.05)          # the second signal within 100 ms of the first
        run.proc.send_signal(sig)
    return t0


def left_safe(sa: Any, run: Any) -> dict:
    """The companion exits 0; from then on the vehicle is never armed in GUIDED, and it ends disarmed on the ground
    or in the hand-off mode. Returns the stand-in's state at the end."""
    rc = run.wait_exit(20)
    assert rc == 0, f"exit {rc}\n{run.output()}"
    gone = time.monotonic()
    state = sa.state()
    while True:
        assert not (state["armed"] and state["mode"] == "GUIDED"), \
            f"armed in GUIDED {time.monotonic() - gone:.1f} s after the companion exited: {state}\n{run.output()}"
        down = not state["armed"] and state["landed"]
        if down or (state["mode"] == HANDOFF_MODE and time.monotonic() - gone > 2.0):
            return state
        assert time.monotonic() - gone < 60, f"neither down nor in {HANDOFF_MODE}: {state}"
        time.sleep(0.02)
        state = sa.state()


def companion_texts(gcs: GcsClient, since: float) -> List[str]:
    return [m.text for m in gcs.since(since, "STATUSTEXT") if m.get_srcComponent() == COMPANION]


def last_events(run: Any) -> List[str]:
    records = run.records()
    assert records, run.output()
    return [e for r in records[-3:] for e in r.get("events", [])]


def check_words(step: str, gcs: GcsClient, run: Any, t_signal: float) -> None:
    events = last_events(run)
    if step == "arm_waiting_ready":
        assert any("the vehicle is disarmed" in e for e in events), events
        return
    assert any(f"hand-off {HANDOFF_MODE}" in e for e in events), events
    deadline = time.monotonic() + 5
    while not any(t.startswith(f"Companion stopping: {HANDOFF_MODE}") for t in companion_texts(gcs, t_signal)):
        assert time.monotonic() < deadline, companion_texts(gcs, 0.0)
        time.sleep(0.05)


STEPS = ["arm_waiting_ready", "arm_pending", "arm_accepted", "climb_1m", "climb_3m", "climb_6m"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("step", STEPS)
def test_a_stop_at_each_step_of_the_start_leaves_the_vehicle_down_or_handed_off(
        step, sig, autopilot_factory, fly, relay, client):
    sa, gcs, run = start(step, autopilot_factory, fly, relay, client)
    t_signal = stop_with(run, [sig])
    left_safe(sa, run)
    check_words(step, gcs, run, t_signal)
    if step == "arm_waiting_ready":
        # The autopilot becomes ready after the stop: the companion armed nothing, before or after.
        sa.wait_for(lambda: sa.state()["position_ok"], timeout=30, what="the position estimate")
        time.sleep(0.5)
        assert not arm_commands(sa), [e.data for e in arm_commands(sa)]
        assert not sa.rec.of("arm") and not sa.state()["armed"], sa.state()
    else:
        assert arm_commands(sa), "the step was not reached"


@pytest.mark.parametrize("signals", [(signal.SIGINT, signal.SIGINT), (signal.SIGTERM, signal.SIGINT)],
                         ids=["SIGINT+SIGINT", "SIGTERM+SIGINT"])
@pytest.mark.parametrize("step", ["arm_pending", "climb_3m"])
def test_two_signals_within_100_ms_still_hand_off(step, signals, autopilot_factory, fly, relay, client):
    sa, gcs, run = start(step, autopilot_factory, fly, relay, client)
    t_signal = stop_with(run, list(signals))
    left_safe(sa, run)
    check_words(step, gcs, run, t_signal)
