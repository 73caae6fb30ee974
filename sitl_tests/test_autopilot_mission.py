"""`companion fly --mission autopilot` on the stand-in autopilot (its mission protocol is ArduPilot's: item 0 home,
MissionItemProtocol's download; sitl_tests/standin/mission.py): the mission a ground station uploaded is planned
before any start and flown without an upload of the companion's; a changed mission is re-planned within 5 s
(said to the ground station and recorded); an item the companion cannot plan refuses the start, naming it.
The same on real ArduCopter: test_real_autopilot_mission.py."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, List

import pytest

from helpers import joined_statustexts, offset, wp
from standin import mavlink
from standin.vocabulary import HOME_ALT_AMSL, HOME_LAT, HOME_LON
from test_operator_and_landing import COMPANION, events, wait

pytestmark = [pytest.mark.companion_fly]

REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT


def mission(last_east_m: float, loiter_unlim: bool = False) -> List[dict]:
    home = wp(HOME_LAT, HOME_LON, HOME_ALT_AMSL, frame=mavlink.MAV_FRAME_GLOBAL)
    nav = mavlink.MAV_CMD_NAV_LOITER_UNLIM if loiter_unlim else mavlink.MAV_CMD_NAV_WAYPOINT
    return [home,
            wp(0, 0, 20.0, command=mavlink.MAV_CMD_NAV_TAKEOFF, frame=REL),
            wp(*offset(HOME_LAT, HOME_LON, 150.0, 0.0), 20.0, command=nav, frame=REL),
            wp(*offset(HOME_LAT, HOME_LON, 150.0, last_east_m), 20.0, frame=REL),
            wp(0, 0, 0, command=mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=REL)]


def texts(gcs: Any, since: float = 0.0) -> List[str]:
    """The companion's STATUSTEXTs, chunks joined."""
    return joined_statustexts(gcs.since(since, "STATUSTEXT"), COMPANION)


def companion_uploads(sa: Any) -> List[Any]:
    return [e for e in sa.received("MISSION_COUNT", include_dropped=True) if e.data["src"][1] == COMPANION]


def test_the_uploaded_mission_is_planned_flown_as_is_and_a_change_re_planned(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    assert gcs.upload_mission(mission(150.0)).type == mavlink.MAV_MISSION_ACCEPTED
    run = fly(ap, mission=Path("autopilot"))            # --auto-start --once
    wait(lambda: any("mission planned" in t or "mission re-planned at the autopilot's speeds" in t
                     for t in texts(gcs)), 30, "the STATUSTEXT that the uploaded mission is planned", run)
    # A ground station changes the cruise speed (the stand-in's WPNAV_SPEED is 500 cm/s): re-planned at it.
    t_set = time.monotonic()
    gcs.param_set("WPNAV_SPEED", 700)
    wait(lambda: any("re-planned at the autopilot's speeds" in t for t in texts(gcs, since=t_set)), 5.0,
         "the STATUSTEXT that the mission was re-planned at the new WPNAV_SPEED", run)
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["mission_current"] >= 2, 120,
         "the uploaded mission flown in AUTO", run)
    t_up = time.monotonic()
    assert gcs.upload_mission(mission(250.0)).type == mavlink.MAV_MISSION_ACCEPTED
    wait(lambda: any("mission changed, re-planned from the point reached" in t for t in texts(gcs, since=t_up)), 5.0,
         "the STATUSTEXT that the mission changed and was re-planned from the point reached, within 5 s", run)
    wait(lambda: run.proc.poll() is not None, 180, "the flight to end (--once)")
    assert run.proc.returncode == 0, run.output()
    assert not companion_uploads(sa), "the companion uploaded a mission of its own"
    said = [str(e) for e in events(run.records())]
    assert any("mission planned" in e for e in said), said[-20:]
    assert any("mission changed, re-planned from the point reached" in e for e in said), said[-20:]
    # Followed on the new plan: the activity flown comes from the re-derived mission (the leg from the point
    # reached, `leghere-N`), after the ones flown before the change; the guarantee re-allocated from there.
    walked = []
    for r in run.records():
        name = (r.get("guarantee") or {}).get("activity_name")
        if name and (not walked or walked[-1] != name):
            walked.append(name)
    assert walked[0] == "take_off" and any(a.startswith("leghere-") for a in walked), walked
    # Before it, only the first plan's activities (the climb is named take_off until the take-off item is done, so
    # a change uploaded just after it may come before the first leg is named).
    first = walked.index(next(a for a in walked if a.startswith("leghere-")))
    assert all(a == "take_off" or a.startswith("leghome-") for a in walked[:first]), walked
    cruise = [r["observations"]["cruise_speed_mps"] for r in run.records()
              if "cruise_speed_mps" in r.get("observations", {})]
    assert cruise and cruise[-1] == 7.0, cruise[-3:]


def test_speeds_the_autopilot_reports_after_the_plan_re_plan_it_even_when_equal_to_the_params(
        autopilot_factory, fly, client):
    """The autopilot's speeds answered after the mission was planned at the params' fallback (CI stop 43, ArduCopter
    SITL): re-planned and said at the autopilot's speeds, also when they equal [derive]'s (ArduCopter's defaults)."""
    ap = autopilot_factory()
    sa = ap.standin
    speeds = {"WPNAV_SPEED": 1000, "WPNAV_SPEED_UP": 250, "WPNAV_SPEED_DN": 150}   # = params [derive] in cm/s
    for name, v in speeds.items():
        sa.set_param(name, v)
    sa.hold_param_reads(list(speeds))
    gcs = client(sa.url)
    assert gcs.upload_mission(mission(150.0)).type == mavlink.MAV_MISSION_ACCEPTED
    run = fly(ap, mission=Path("autopilot"), auto_start=False)
    wait(lambda: any("mission planned" in t and "params speeds" in t for t in texts(gcs)), 30,
         "the STATUSTEXT that the mission is planned at the params' speeds (the autopilot's not answered)", run)
    t_release = time.monotonic()
    sa.release_param_reads()
    wait(lambda: any("re-planned at the autopilot's speeds" in t and "params speeds" not in t
                     for t in texts(gcs, since=t_release)), 5.0,
         "the STATUSTEXT that the mission was re-planned at the autopilot's speeds (PARAM_REQUEST_READ retried)", run)
    # The record holding the re-plan is written with the cycle's record (at most one decision period later).
    wait(lambda: any("re-planned at the autopilot's speeds" in e and "params speeds" not in e
                     for e in map(str, events(run.records()))), 5.0,
         "the re-plan at the autopilot's speeds in the decision record", run)


def test_an_item_the_companion_cannot_plan_refuses_the_start_naming_it(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    assert gcs.upload_mission(mission(150.0, loiter_unlim=True)).type == mavlink.MAV_MISSION_ACCEPTED
    run = fly(ap, mission=Path("autopilot"))
    wait(lambda: any("mission refused: autopilot mission: item 2: LOITER_UNLIM" in t for t in texts(gcs)), 30,
         "the STATUSTEXT naming the refused item", run)
    wait(lambda: sa.state()["position_ok"], 30, "the stand-in ready to arm", run)
    time.sleep(3.0)
    assert not sa.rec.of("arm"), "armed on a mission it could not plan"
    assert not companion_uploads(sa)
    run.proc.terminate()
    run.proc.wait(timeout=15)
    said = [str(e) for e in events(run.records())]
    assert any("autopilot mission: item 2: LOITER_UNLIM" in e for e in said), said[-20:]
    assert any("the mission is not planned" in e for e in said), said[-20:]
