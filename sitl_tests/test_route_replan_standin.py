"""The companion's own route planned at the autopilot's cruise speed (issue 36: the plan is what is flown; fly/
route_replan.rs): `fly` derives the default route's plan before any socket at params' [derive] cruise speed (10 m/s,
ArduCopter's default WPNAV_SPEED); the stand-in reports WPNAV_SPEED 500 cm/s, so on the ground the route is derived
again at 5 m/s and re-planned, said to the ground station and recorded. The legs take twice as long: the re-planned
duration is the header's plus sum(leg lengths) x (1/5 - 1/10) s (the shipped params have no leg overhead)."""
from __future__ import annotations

import json
import re

import pytest

from test_autopilot_mission import texts
from test_operator_and_landing import events, wait

pytestmark = [pytest.mark.companion_fly]


def test_the_default_route_is_re_planned_at_the_autopilots_cruise_speed(autopilot_factory, fly, client):
    ap = autopilot_factory()
    gcs = client(ap.standin.url)
    run = fly(ap, auto_start=False)
    said = "route re-planned at the autopilot's cruise 5 m/s (params 10)"
    wait(lambda: any(said in t for t in texts(gcs)), 30, "the STATUSTEXT of the re-plan at WPNAV_SPEED", run)
    wait(lambda: any(said in str(e) for e in events(run.records())), 30, "the record's event of the re-plan", run)
    run.proc.terminate()
    run.proc.wait(timeout=15)
    header = json.loads(next(run.log_dir.rglob("decisions.jsonl")).read_text().splitlines()[0])
    plan = header["plan"]
    moving = sum(a["length_m"] for a in plan["derived"] if a["kind"] in ("leg", "return"))
    assert moving > 100.0, plan["derived"]
    ev = [str(e) for e in events(run.records()) if said in str(e)]
    assert ev, [str(e) for e in events(run.records())][-20:]
    m = re.search(r": ([0-9.]+) kJ ([0-9]+) s$", ev[0])
    assert m, ev[0]
    want = plan["planned_duration_s"] + moving * (1 / 5.0 - 1 / 10.0)
    assert abs(float(m[2]) - want) <= 1.0, (ev[0], want)
    assert float(m[1]) * 1000.0 > plan["planned_energy_j"], (ev[0], plan["planned_energy_j"])
