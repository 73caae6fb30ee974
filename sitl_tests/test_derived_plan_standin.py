"""The derived plan is the plan in `fly` (issue 36): against the stand-in, the guarantee judges the activities derived
from the route flown (params/missions/tracking_route.toml) and the shipped zones (tracking_zones.geojson), and the
record walks them in flight order as the route progresses (route_activity: the mission item, the position, the
phase), not the typed activities of params/missions/tracking.toml.
"""
from __future__ import annotations

import json
from typing import Any, Dict, List

import pytest

from test_companion_fly import assert_mission_completed, fly_mission

pytestmark = pytest.mark.companion_fly


def header(run: Any) -> Dict[str, Any]:
    logs = sorted(run.log_dir.rglob("decisions.jsonl"))
    assert logs, "no decision log\n" + run.output()
    return json.loads(logs[0].read_text().splitlines()[0])


def walked(records: List[Dict[str, Any]]) -> List[str]:
    """The guarantee's activities in the order the records name them, repeats collapsed."""
    out: List[str] = []
    for r in records:
        name = (r.get("guarantee") or {}).get("activity_name")
        if name and (not out or out[-1] != name):
            out.append(name)
    return out


def test_the_guarantee_walks_the_derived_activities_in_flight_order(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()
    if ap.standin is None:
        pytest.skip("stand-in only")
    f = fly_mission(ap, fly, monitors_factory)
    assert_mission_completed(f)
    plan = header(f.run).get("plan")
    assert plan, "the log header names no plan\n" + f.why()
    assert plan["route_file"].endswith("tracking_route.toml") and plan["zones_file"].endswith("tracking_zones.geojson")
    derived = [a["name"] for a in plan["derived"]]
    assert plan["activities"] == len(derived)
    assert "plan: %d activities derived from" % len(derived) in f.run.output()
    seen = walked(f.records)
    # every activity named is a derived one, and they come in flight order (never back)
    assert set(seen) <= set(derived), (seen, derived)
    order = [derived.index(a) for a in seen]
    assert order == sorted(order), seen
    assert seen[0] == "take_off", seen
    assert seen[-1] == "land", seen
    legs = [a for a in seen if a.startswith("leg")]
    assert len(legs) >= 3, seen
    assert "tracking" in seen, seen
    # the leg pieces in the shipped GPS-degraded zone are judged as such (the position picks the piece)
    degraded = [a["name"] for a in plan["derived"] if "gps_degraded" in a["constraints"]]
    assert degraded and set(degraded) & set(seen), (degraded, seen)
    # the typed plan's names never appear
    assert not set(seen) & {"transit", "transit_gps_degraded", "obstacle_dense", "tracking_area", "landing_area"}
