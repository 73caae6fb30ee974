"""`companion fly --mission autopilot` on a real PX4 SITL (SIH quadrotor): the mission a ground station uploaded
(PX4 keeps no home item: seq 0 is flown) is planned at PX4's MPC_XY_CRUISE and flown without an upload of the
companion's; a change in flight is found by MISSION_CURRENT's mission_id and re-planned. Judged from PX4's GCS
port. The ArduCopter counterpart: test_real_autopilot_mission.py."""
from __future__ import annotations

import time
from pathlib import Path

import pytest

pytest.register_assert_rewrite("px4_sitl")
from helpers import read_decision_log  # noqa: E402
from px4_sitl import mavlink  # noqa: E402
from test_px4_flight import NOMINAL, commanded, companion_bin, finish, fly, landed_and_disarmed  # noqa: E402

pytest_plugins = ["px4_sitl"]

HOME = (47.397742, 8.545594)          # PX4 SIH's default home
REL = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
M_PER_DEG_LAT, M_PER_DEG_LON = 111_320.0, 111_320.0 * 0.6757   # cos(47.4 deg)


def mission(last_east_m: float) -> list:
    def at(n: float, e: float) -> tuple:
        return HOME[0] + n / M_PER_DEG_LAT, HOME[1] + e / M_PER_DEG_LON
    return [(REL, mavlink.MAV_CMD_NAV_TAKEOFF, 0, *HOME, 15.0),
            (REL, mavlink.MAV_CMD_NAV_WAYPOINT, 0, *at(40.0, 0.0), 15.0),
            (REL, mavlink.MAV_CMD_NAV_WAYPOINT, 0, *at(40.0, last_east_m), 15.0),
            # PX4 takes the RTL item only in MAV_FRAME_MISSION
            (mavlink.MAV_FRAME_MISSION, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0.0, 0.0, 0.0)]


def test_px4_the_uploaded_mission_is_planned_flown_and_a_change_re_planned(px4_vehicle, tmp_path):
    exe = companion_bin()
    v = px4_vehicle(NOMINAL)
    o = v.observer
    assert o.upload_mission(mission(40.0)) == mavlink.MAV_MISSION_ACCEPTED
    proc, out = fly(exe, v.onboard_port, Path("autopilot"), tmp_path / "runs")
    try:
        o.wait("the companion's STATUSTEXT that the mission is planned",
               lambda o: any("mission planned" in t or "re-planned at the autopilot's" in t for t in o.texts), 60)
        o.wait("the first waypoint reached in MISSION", lambda o: o.mode == "MISSION" and 1 in o.reached, 150)
        assert o.upload_mission(mission(80.0)) == mavlink.MAV_MISSION_ACCEPTED
        o.wait("the companion's STATUSTEXT that the mission changed, within 5 s",
               lambda o: any("mission changed" in t for t in o.texts), 5.0)
        o.wait("landed and disarmed", landed_and_disarmed, 240)
    finally:
        rc = finish(proc, out, 30)
    assert rc == 0, f"companion fly exited {rc}; {o.summary()}"
    records = read_decision_log(tmp_path / "runs")
    said = [str(e) for r in records for e in r.get("events", [])]
    assert any(("mission planned" in e or "re-planned at the autopilot's speeds" in e)
               and "params speeds" not in e for e in said), said[-20:]
    assert any("mission changed, re-planned" in e for e in said), said[-20:]
    uploads = [c for c in commanded(records, {"follow_trajectory"}) if c[1] == "MISSION_UPLOAD"]
    assert uploads and all(str(c[2]).startswith("SKIPPED") for c in uploads), uploads
    cruise = [r["observations"]["cruise_speed_mps"] for r in records if "cruise_speed_mps" in r.get("observations", {})]
    assert cruise and cruise[-1] > 0, "MPC_XY_CRUISE not read"
