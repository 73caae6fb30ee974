"""Home before plan (issue 36): `companion fly` with the shipped route (relative to home) and zones given as
absolute longitude/latitude polygons, and no `--home`, cannot place the route among the zones until it knows the
vehicle's home. It waits for the autopilot's HOME_POSITION, plans then (said to the ground station and recorded),
and grants no start before: the first command follows the plan. The same canyon as the shipped home-relative zones,
written absolute at the stand-in's home: the legs through it are judged GPS-degraded."""
from __future__ import annotations

import json

import pytest

from helpers import offset
from standin.vocabulary import HOME_LAT, HOME_LON
from test_autopilot_mission import texts
from test_derived_plan_standin import walked
from test_operator_and_landing import wait

pytestmark = [pytest.mark.companion_fly]


def absolute_canyon() -> str:
    corners = [offset(HOME_LAT, HOME_LON, n, e) for n, e in [(100, -40), (100, 140), (160, 140), (160, -40), (100, -40)]]
    return json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "properties": {"name": "canyon", "constraints": ["gps_degraded"]},
        "geometry": {"type": "Polygon", "coordinates": [[[lon, lat] for lat, lon in corners]]}}]})


def test_a_relative_route_among_absolute_zones_is_planned_from_the_autopilots_home(autopilot_factory, fly, client,
                                                                                     tmp_path):
    ap = autopilot_factory()
    sa = ap.standin
    if sa is None:
        pytest.skip("stand-in only")
    zones = tmp_path / "canyon.geojson"
    zones.write_text(absolute_canyon())
    gcs = client(sa.url)
    run = fly(ap, extra=("--zones", str(zones)))          # --auto-start --once, no --home
    wait(lambda: any("mission planned from the autopilot's home (" in t for t in texts(gcs)), 30,
         "the STATUSTEXT that the plan was made from the autopilot's home", run)
    wait(lambda: run.proc.poll() is not None, 240, "the flight to end (--once)")
    assert run.proc.returncode == 0, run.output()
    assert "waiting for the autopilot's home" in run.output()
    recs = run.records()
    planned_at = next(i for i, r in enumerate(recs)
                      if any("from the autopilot's home" in str(e) for e in r.get("events", [])))
    first_cmd = next(i for i, r in enumerate(recs) if r.get("commands"))
    assert first_cmd >= planned_at, "a command before the plan existed"
    seen = walked(recs)
    assert {"leg1-2.2", "leg3-4.2"} & set(seen), seen       # the canyon's pieces, placed from home
    assert seen[0] == "take_off" and seen[-1] == "land", seen
