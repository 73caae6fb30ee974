"""A companion that dies in the air, on a real ArduCopter SITL (issue 40, "safe without the companion").

SIGKILL in AUTO after waypoint 2 (no stop path runs: no hand-off, no words), then either
* restarted 3 s later with the same command line and --log-dir, as systemd's Restart= does: the restarted
  companion never says it waits for the operator; within 10 s the ground station has its STATUSTEXT saying a
  flight is in progress and the hand-off, the vehicle is in the hand-off mode (params/link.toml [flight]
  handoff = rtl), and it ends landed and disarmed; or
* not restarted: the vehicle flies the rest of the uploaded route, its search loiter at the last waypoint and
  the mission's own RTL, and ends landed and disarmed with nobody commanding it.

The flight starts like the other real tests (conftest.py `fly`, --auto-start, the fixture's pack). The route
is the default one with a 20 s search limit (the mission's loiter at wpf), so the flight stays short.
"""
from __future__ import annotations

import os
import shutil
import signal
import time
from pathlib import Path
from typing import Any, Tuple

import pytest

from helpers import read_decision_log
from standin import mavlink

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

SPEEDUP = float(os.environ.get("REAL_SITL_SPEEDUP", "3"))
REPO = Path(__file__).resolve().parent.parent
SEARCH_LIMIT_S = 20.0
COMPANION = 191


def short_search_route(tmp_path: Path) -> Path:
    text = (REPO / "params/missions/tracking_route.toml").read_text()
    assert "search_time_limit_s = 300.0" in text, "the default route changed: update this test"
    p = tmp_path / "route_short_search.toml"
    p.write_text(text.replace("search_time_limit_s = 300.0", f"search_time_limit_s = {SEARCH_LIMIT_S}"))
    return p


def fly_until_waypoint_2(arducopter: Any, fly: Any, relay: Any, tmp_path: Path,
                         extra: Tuple[str, ...] = ()) -> Tuple[Any, Any, Any, Path]:
    """A fresh vehicle, the companion flying its route in AUTO through a relay, up to MISSION_ITEM_REACHED 2."""
    veh = arducopter(speedup=SPEEDUP)
    rl = relay(int(veh.autopilot.url.rsplit(":", 1)[1]))
    via = type(veh.autopilot)(url=rl.url, monitor_url=veh.autopilot.monitor_url)
    route = short_search_route(tmp_path)
    run = fly(via, mission=route, extra=extra)
    gcs = veh.gcs
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and run.proc.poll() is None:
        if 2 in gcs.reached_seqs() and gcs.mode == "AUTO" and gcs.armed:
            break
        time.sleep(0.1)
    assert 2 in gcs.reached_seqs() and gcs.mode == "AUTO", \
        "the companion did not fly the route to waypoint 2 in AUTO" + run.output() + gcs.summary()
    run.proc.send_signal(signal.SIGKILL)
    run.proc.wait(timeout=10)
    return veh, rl, via, route


def wait_landed_disarmed(gcs: Any, timeout: float, what: str) -> None:
    gcs.wait(lambda: not gcs.armed and gcs.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND, timeout, what)


def test_real_killed_in_auto_and_restarted_hands_off_and_says_a_flight_is_in_progress(arducopter, fly, relay, tmp_path):
    veh, rl, via, route = fly_until_waypoint_2(arducopter, fly, relay, tmp_path)
    gcs = veh.gcs
    time.sleep(3.0)
    assert gcs.armed and gcs.alt > 5.0, "the vehicle is no longer flying at the restart" + gcs.summary()
    restarted_at = time.monotonic()
    log_dir = next(tmp_path.glob("companion-log-*"))
    run = fly(via, mission=route, log_dir=log_dir)
    # Within 10 s: the words from component 191 and the hand-off mode.
    gcs.wait(lambda: any("flight in progress" in t and "RTL" in t
                         for t in [s for tt, _, c, s in gcs.statustext_from if c == COMPANION and tt >= restarted_at]),
             10.0, "no STATUSTEXT from the restarted companion saying a flight is in progress and the hand-off")
    gcs.wait(lambda: gcs.mode == "RTL", max(0.5, restarted_at + 10.0 - time.monotonic()),
             "the vehicle is not in the hand-off mode (RTL) within 10 s of the restart")
    said = gcs.texts_from(COMPANION, since=restarted_at)
    assert not [t for t in said if "waiting for the operator" in t and "landed" not in t], said
    wait_landed_disarmed(gcs, 240, "the vehicle did not end landed and disarmed after the hand-off")
    assert run.wait_exit(30) == 0, "the restarted companion did not end its run (--once)" + run.output()
    records = run.records()
    events = [e if isinstance(e, str) else str(e) for r in records for e in r.get("events", [])]
    assert any("started in flight" in e and "hand-off RTL" in e and "not resumed" in e for e in events), events[-20:]
    assert any(r.get("vehicle", {}).get("operator") == "flight_in_progress" for r in records)


def test_real_killed_in_auto_and_not_restarted_the_mission_brings_it_home(arducopter, fly, relay, tmp_path):
    veh, rl, via, route = fly_until_waypoint_2(arducopter, fly, relay, tmp_path)
    gcs = veh.gcs
    killed_at = time.monotonic()
    # Nobody commands it now: the uploaded mission alone flies wp3..wpf, loiters, returns and lands.
    wait_landed_disarmed(gcs, 300, "with the companion dead the vehicle did not end landed and disarmed")
    reached = gcs.reached_seqs()
    assert {3, 4, 5} <= set(reached), f"the route's last waypoints were not flown: {reached}" + gcs.summary()
    assert 6 in reached, f"the search loiter at wpf did not complete: {reached}" + gcs.summary()
    assert gcs.modes_since(killed_at) == ["AUTO"], \
        f"the mission itself returned (AUTO throughout), no failsafe mode: {gcs.modes_since(killed_at)}"
    assert gcs.max_alt > 15.0
    with rl._lock:
        after = [m for (t, m, _) in rl.sent if t > killed_at]
    assert not after, f"something spoke for the dead companion: {after[:5]}"


def test_real_killed_in_auto_restarted_resumes_its_own_flight_on_consent_and_lands(arducopter, fly, relay, tmp_path):
    """[flight] restart_in_air = "resume_with_consent": the restarted companion proves the flight its own (its run
    log, the mission on the autopilot, the guarantee with the battery now), offers to resume, the operator's
    MISSION_START resumes it without arming, taking off or uploading, and the flight ends landed and disarmed."""
    params = tmp_path / "params-resume"
    shutil.copytree(REPO / "params", params)
    link = params / "link.toml"
    text = link.read_text()
    assert 'restart_in_air = "handoff"' in text
    link.write_text(text.replace('restart_in_air = "handoff"', 'restart_in_air = "resume_with_consent"'))
    veh, rl, via, route = fly_until_waypoint_2(arducopter, fly, relay, tmp_path, extra=("--params", str(params)))
    gcs = veh.gcs
    time.sleep(3.0)
    assert gcs.armed and gcs.alt > 5.0, "the vehicle is no longer flying at the restart" + gcs.summary()
    restarted_at = time.monotonic()
    log_dir = next(tmp_path.glob("companion-log-*"))
    run = fly(via, mission=route, log_dir=log_dir, extra=("--params", str(params)))
    # (gcs.wait holds the observer's lock: the condition reads its lists directly.)
    said_since = lambda: [s for tt, _, c, s in gcs.statustext_from if c == COMPANION and tt >= restarted_at]
    gcs.wait(lambda: any("MISSION_START in 20s resumes" in t for t in said_since()), 20.0,
             "no offer to resume from the restarted companion")
    assert gcs.mode == "AUTO", "handed off before the operator answered" + gcs.summary()
    result = gcs.command_long(mavlink.MAV_CMD_MISSION_START, component=COMPANION, timeout=10.0)
    assert result == mavlink.MAV_RESULT_ACCEPTED, result
    gcs.wait(lambda: any("resumed its own flight" in t for t in said_since()), 10.0,
             "no 'resumed' from the restarted companion")
    wait_landed_disarmed(gcs, 300, "the resumed flight did not end landed and disarmed")
    assert run.wait_exit(60) == 0, "the restarted companion did not end its run (--once)" + run.output()
    newest = max((d for d in log_dir.iterdir() if (d / "decisions.jsonl").is_file()), key=lambda d: d.name)
    records = read_decision_log(newest)
    events = [e if isinstance(e, str) else str(e) for r in records for e in r.get("events", [])]
    assert any(e.startswith("started in flight: resumed on the operator's consent") for e in events), events[-20:]
    commands = [c["command"] for r in records for c in r.get("commands", [])]
    assert not {"MAV_CMD_COMPONENT_ARM_DISARM", "MAV_CMD_NAV_TAKEOFF", "MISSION_UPLOAD"} & set(commands), commands
    assert gcs.arm_count(since=restarted_at) == 0
    said = gcs.texts_from(COMPANION, since=restarted_at)
    assert not [t for t in said if "hand-off" in t and "MISSION_START" not in t], said
