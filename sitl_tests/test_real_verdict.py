"""The verdict in the operator's terms (issue 36 item 4) on a real ArduCopter SITL with its own default pack
(3300 mAh, ../shared/sitl/README.md: a mission should be judged on that pack) and the shipped profile
(`--vehicle arducopter-sitl`): the operator's MISSION_START is refused with two STATUSTEXTs, planned against available
energy (the autopilot's BATT_CAPACITY, computed here from its parameter and cell count) and what would fit, and the
refused cycle's record holds the same numbers, typed (`guarantee.verdict`).
"""
from __future__ import annotations

import math
from pathlib import Path
import re
import time
from typing import Any

import pytest

from standin import mavlink
from test_real_ardupilot import SPEEDUP
from test_real_launch import COMPANION, texts_since, wait_waiting

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

SITL_DEFAULT_PACK_MAH = 3300      # ArduCopter SITL's own BATT_CAPACITY


def test_real_default_pack_refusal_names_planned_available_and_what_fits(arducopter, fly):
    veh = arducopter(speedup=SPEEDUP, extra_defaults={"BATT_CAPACITY": SITL_DEFAULT_PACK_MAH})
    gcs = veh.gcs
    run = fly(veh.autopilot, auto_start=False, extra=("--vehicle", "arducopter-sitl"))
    wait_waiting(gcs, run)

    def judged() -> bool:
        return any(((r.get("guarantee") or {}).get("pack") or {}).get("capacity_mah") == SITL_DEFAULT_PACK_MAH
                   and r["guarantee"].get("verdict") for r in run.records())
    deadline = time.monotonic() + 60
    while not judged():
        assert time.monotonic() < deadline, "no record judged on the autopilot's pack" + run.output()
        time.sleep(0.5)
    t0 = time.monotonic()
    result = gcs.command_long(mavlink.MAV_CMD_MISSION_START, component=COMPANION, timeout=10.0)
    assert result == mavlink.MAV_RESULT_DENIED, f"ACK {result}" + gcs.summary() + run.output()
    # (gcs.wait holds the observer's lock while it asks: read its list directly, as test_real_launch does)
    gcs.wait(lambda: any(s.startswith("Start refused") for t, s in gcs.statustext if t >= t0), 10,
             "the refusal's STATUSTEXT")
    time.sleep(2.0)
    with gcs._lock:       # the companion's own texts, in order (the autopilot's interleave with them)
        texts = [s for t, _, c, s in gcs.statustext_from if t >= t0 and c == COMPANION]
    run.proc.terminate()
    run.proc.wait(timeout=20)
    assert not gcs.ever_armed(), "the vehicle armed after a refused start" + gcs.summary()

    i = next(k for k, s in enumerate(texts) if s.startswith("Start refused"))
    # One text (its chunks joined by the observer): the verdict, then the time and what fits.
    head, _, fit = texts[i].partition(". ")
    m = re.fullmatch(r"Start refused: plan (\d+(?:\.\d)?) kJ, have (\d+(?:\.\d)?) kJ at (\d+)%", head)
    assert m, texts
    planned_kj, have_kj, pct = float(m[1]), float(m[2]), int(m[3])
    # The pack: 3300 mAh at 3.7 V a cell, cells counted from SITL's 12.6 V; a quarter kept back (params' [battery]).
    cells = math.ceil(12.6 / 4.25)
    spendable = pct / 100.0 * SITL_DEFAULT_PACK_MAH * 3.6 * cells * 3.7 - 0.25 * SITL_DEFAULT_PACK_MAH * 3.6 * cells * 3.7
    assert have_kj == pytest.approx(spendable / 1000.0, abs=0.051 if have_kj < 100 else 0.51), (head, spendable)
    assert planned_kj > have_kj, head
    assert re.search(r"(fits: (search|tracking) \d+ s|nothing fits: route alone)", fit, re.I), texts
    # The refused cycle's record: the same numbers, typed.
    verdicts = [r["guarantee"]["verdict"] for r in run.records() if (r.get("guarantee") or {}).get("verdict")]
    assert any(round(v["planned_energy_j"] / 1000.0, 1 if v["planned_energy_j"] < 1e5 else 0) == planned_kj and
               round(v["available_energy_j"] / 1000.0, 1 if v["available_energy_j"] < 1e5 else 0) == have_kj
               for v in verdicts), (head, verdicts[-1])
    named = re.search(r"(search|tracking) (\d+) s", fit)
    if named:
        assert any(v.get(f"longest_{named[1]}_s") == float(named[2]) for v in verdicts), (fit, verdicts[-1])


def test_real_the_search_the_refusal_names_is_flown_and_lands_above_the_reserve(arducopter, fly, tmp_path):
    """Issue 36, Done-when 1: the default route on SITL's own 3300 mAh pack with the shipped profile is refused,
    naming the longest search the pack holds; the same route with that search limit (and the shipped zones) is
    started by the operator, searches (no target in SITL) to that limit without the in-flight guarantee cutting it, lands, and ends with the pack above what
    params' [battery] keeps back (never-drawn share + reserve: a quarter), judged from the ground station."""
    veh = arducopter(speedup=SPEEDUP, extra_defaults={"BATT_CAPACITY": SITL_DEFAULT_PACK_MAH})
    gcs = veh.gcs
    first = fly(veh.autopilot, auto_start=False, once=True, extra=("--vehicle", "arducopter-sitl"))
    wait_waiting(gcs, first)
    deadline = time.monotonic() + 60
    longest = None
    while longest is None:
        assert time.monotonic() < deadline, "no verdict on the autopilot's pack" + first.output()
        for r in first.records():
            v = (r.get("guarantee") or {}).get("verdict") or {}
            if ((r["guarantee"].get("pack") or {}).get("capacity_mah") == SITL_DEFAULT_PACK_MAH
                    and v.get("longest_search_s") is not None):
                longest = v["longest_search_s"]
        time.sleep(0.5)
    first.proc.terminate()
    first.proc.wait(timeout=20)
    assert 10.0 <= longest < 300.0, f"the refusal names a search of {longest} s"
    route_text = (Path(__file__).parent.parent / "params" / "missions" / "tracking_route.toml").read_text()
    fitted, n = re.subn(r"(?m)^search_time_limit_s = .*$", f"search_time_limit_s = {longest}", route_text)
    assert n == 1, "the shipped route's search_time_limit_s line"
    route = tmp_path / "route_fit.toml"
    route.write_text(fitted)
    zones = Path(__file__).parent.parent / "params" / "missions" / "tracking_zones.geojson"
    run = fly(veh.autopilot, mission=route, auto_start=False, once=True,
              extra=("--vehicle", "arducopter-sitl", "--zones", str(zones)))
    wait_waiting(gcs, run)
    time.sleep(3.0)                       # a cycle judged on the autopilot's pack
    t_start = time.monotonic()
    result = gcs.command_long(mavlink.MAV_CMD_MISSION_START, component=COMPANION, timeout=10.0)
    assert result == mavlink.MAV_RESULT_ACCEPTED, f"ACK {result} for the search the refusal named ({longest} s)" \
        + gcs.summary() + run.output()
    gcs.wait(lambda: gcs.armed and gcs.alt > 2.0, 120, "take-off")
    rc = run.wait_exit(1200)
    assert rc == 0, f"exit {rc}" + run.output()
    gcs.wait(lambda: not gcs.armed and gcs.landed, 60, "landed and disarmed")
    pct = gcs.battery_pct
    assert pct is not None and pct > 25, f"the flight ended at {pct} %, at or below the quarter kept back" \
        + gcs.summary()
    # The search ran to the limit named (the shell's search clock runs from the arrival at the last waypoint, where
    # the plan holds the route's search_time_limit_s), not cut short by the in-flight guarantee.
    with gcs._lock:
        said = [s for t, _, c, s in gcs.statustext_from if c == COMPANION and t >= t_start]
    assert any(s.startswith("Search time over") for s in said), " | ".join(said)
    assert not any(s.startswith("Cannot meet goals") for s in said), " | ".join(said)
    print(f"named search {longest:.0f} s; flown to its limit; landed at {pct} %")
