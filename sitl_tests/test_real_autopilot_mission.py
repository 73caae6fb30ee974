"""`companion fly --mission autopilot` against a real ArduCopter SITL (a fresh vehicle per test): the mission a
ground station uploaded is the one planned and flown (the companion uploads nothing), and a mission the ground
station changes in flight is downloaded again and re-planned, said in a STATUSTEXT from component 191 and in the
decision record. Judged from the ground station on SERIAL0, which also does the uploads (as QGroundControl or
Mission Planner would)."""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Dict, List, Tuple

import pytest

from standin import mavlink

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

SPEEDUP = float(os.environ.get("REAL_SITL_SPEEDUP", "3"))
HOME = (-35.363261, 149.165230)          # real_autopilot.CMAC_HOME
M_PER_DEG_LAT = 111_320.0
M_PER_DEG_LON = 111_320.0 * 0.8155        # cos(35.36 deg)
REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
COMPANION = 191


def at(north_m: float, east_m: float) -> Tuple[float, float]:
    return HOME[0] + north_m / M_PER_DEG_LAT, HOME[1] + east_m / M_PER_DEG_LON


def mission(last: Tuple[float, float]) -> List[Tuple[int, int, float, float, float, float]]:
    """Home placeholder, take-off to 20 m, three waypoints (the last at `last` north/east m), RTL."""
    wps = [(60.0, 0.0), (60.0, 60.0), last]
    return ([(mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_CMD_NAV_WAYPOINT, 0, HOME[0], HOME[1], 0.0),
             (REL, mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0.0, 0.0, 20.0)]
            + [(REL, mavlink.MAV_CMD_NAV_WAYPOINT, 0, *at(n, e), 20.0) for n, e in wps]
            + [(REL, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0.0, 0.0, 0.0)])


def upload_when_ready(gcs: Any, items: List[Tuple[int, int, float, float, float, float]]) -> None:
    """ArduCopter answers MAV_MISSION_NO_SPACE to an upload in its first seconds (its mission storage is not
    sized yet, seen on this SITL): a ground station tries again."""
    deadline = time.monotonic() + 60
    result = None
    while time.monotonic() < deadline:
        result = gcs.upload_mission(items)
        if result != mavlink.MAV_MISSION_NO_SPACE:
            break
        time.sleep(1.0)
    assert result == mavlink.MAV_MISSION_ACCEPTED, f"MISSION_ACK {result}" + gcs.summary()


# GcsObserver.wait calls its condition holding the observer's lock (not re-entrant): conditions read its
# lists directly, never through the query methods that take the lock again.
def said_by_companion(gcs: Any, what: str, since: float = 0.0) -> bool:
    """A text longer than one STATUSTEXT (50 characters) comes in chunks: searched joined too."""
    said = [s for t, _, c, s in gcs.statustext_from if c == COMPANION and t >= since]
    return any(what in s for s in said) or what in "".join(said)


def reached(gcs: Any) -> set:
    return {s for _, s in gcs.reached}


def events(records: List[Dict[str, Any]]) -> List[str]:
    return [e for r in records for e in r.get("events", [])]


def test_real_the_uploaded_mission_is_planned_flown_and_a_change_in_flight_re_planned(arducopter, fly):
    veh = arducopter(speedup=SPEEDUP)
    gcs = veh.gcs
    wpnav = gcs.param_get("WPNAV_SPEED")
    upload_when_ready(gcs, mission((0.0, 60.0)))
    run = fly(veh.autopilot, mission=Path("autopilot"))   # --auto-start --once
    # Its first plan, or the re-plan at the autopilot's speeds that replaced it before the STATUSTEXT rate cap let
    # the first one out (the pilot hears the plan in force; the record keeps both).
    gcs.wait(lambda: said_by_companion(gcs, "mission planned")
             or said_by_companion(gcs, "mission re-planned at the autopilot's speeds"), 60,
             "the companion's STATUSTEXT that it planned the uploaded mission")
    # Planned at the autopilot's own speeds (re-planned at them if its PARAM_VALUEs came after the download).
    gcs.wait(lambda: any(("mission planned" in s or "re-planned at the autopilot's speeds" in s)
                         and "params speeds" not in s for t, _, c, s in gcs.statustext_from if c == COMPANION),
             10, "a plan at WPNAV_SPEED, WPNAV_SPEED_UP and WPNAV_SPEED_DN (no params speeds)")
    gcs.wait(lambda: gcs.mode == "AUTO" and 2 in reached(gcs), 240, "the first waypoint reached in AUTO")
    # A ground station uploads a new mission of the same length in flight: the last waypoint moved.
    upload_when_ready(gcs, mission((0.0, 120.0)))
    t_up = time.monotonic()
    gcs.wait(lambda: said_by_companion(gcs, "mission changed, re-planned from the point reached", since=t_up), 5.0,
             "the companion's STATUSTEXT that the mission changed and was re-planned from the point reached, "
             "within 5 s of the upload")
    gcs.wait(lambda: {3, 4} <= reached(gcs), 240, "the waypoints of the new mission reached")
    gcs.wait(lambda: not gcs.armed and gcs.landed, 240, "the mission's RTL landed the vehicle")
    rc = run.wait_exit(60)
    assert rc == 0, f"exit {rc}\n" + run.output()
    records = run.records()
    said = [str(e) for e in events(records)]
    assert any("mission planned" in e for e in said), said[-20:]
    assert any("mission changed, re-planned from the point reached" in e for e in said), said[-20:]
    # The route progress follows the autopilot's mission, then the re-plan from the point reached (`leghere-N`).
    walked: List[str] = []
    for r in records:
        name = (r.get("guarantee") or {}).get("activity_name")
        if name and (not walked or walked[-1] != name):
            walked.append(name)
    # (a short first leg at SITL's speed-up may fall between two records: any leg of the first plan)
    here = [i for i, a in enumerate(walked) if a.startswith("leghere-")]
    assert walked[0] == "take_off" and here, walked
    assert any(a.startswith("leg") for a in walked[1:here[0]]), walked
    # forward only: nothing after the re-plan goes back to an activity flown before it
    assert not set(walked[here[0]:]) & set(walked[:here[0]]), walked
    # Nothing uploaded by the companion: the route step kept the autopilot's mission.
    cmds = [c for r in records for c in r.get("commands", [])]
    uploads = [c for c in cmds if c.get("command") == "MISSION_UPLOAD"]
    assert uploads and all(str(c.get("result", "")).startswith("SKIPPED") for c in uploads), uploads
    # The cruise speed the plan used is the autopilot's WPNAV_SPEED (cm/s), as its ground station reads it.
    cruise = [r["observations"]["cruise_speed_mps"] for r in records
              if "cruise_speed_mps" in r.get("observations", {})]
    assert cruise and abs(cruise[-1] - wpnav / 100.0) < 1e-6, (cruise[-1:], wpnav)
