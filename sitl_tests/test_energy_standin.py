"""Energy from the autopilot and power measured (issue 23, items 1-2), against the stand-in: the companion reads the
stand-in's BATT_CAPACITY, reckons the guarantee's pack from it, and records the power the stand-in's battery model
draws (its hover current is 14 A, sitl_tests/standin/physics.py) against the activity's predicted power.
"""
from __future__ import annotations

import math
import time
from typing import Any, Dict, List

import pytest

pytestmark = [pytest.mark.companion_fly]

CELL_NOMINAL_V = 3.7      # the companion's stated assumption (docs/guarantee.md)
CELL_MAX_V = 4.25         # cells counted from the first pack voltage: ceil(V / 4.25)


def guarantee(r: Dict[str, Any]) -> Dict[str, Any]:
    return r.get("guarantee") or {}


def test_standin_pack_capacity_and_measured_power_reach_the_record(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()
    if ap.standin is None:
        pytest.skip("stand-in only (test_real_energy.py is the real SITL's)")
    sa = ap.standin
    monitors_factory(ap)
    cap_mah = float(sa.params["BATT_CAPACITY"])
    cells = math.ceil(sa.params["SIM_BATT_VOLTAGE"] / CELL_MAX_V)   # the full pack the stand-in starts with
    run = fly(ap)
    airborne: List[Dict[str, Any]] = []
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and len(airborne) < 15:
        assert run.proc.poll() is None, "companion exited\n" + run.output()
        s = sa.state()
        if s["armed"] and not s["landed"] and s["alt"] > 5.0:
            airborne = [r for r in run.records()
                        if (guarantee(r).get("power") or {}).get("measured_w") is not None
                        and r.get("observations", {}).get("altitude_m", 0.0) > 5.0]
        time.sleep(0.5)
    run.proc.terminate()
    run.wait_exit(30)
    records = run.records()
    assert len(airborne) >= 15, "no airborne records with a measured power\n" + run.output()

    packed = [r for r in records if guarantee(r).get("pack")]
    assert packed, "no record holds the pack"
    # until the autopilot answers PARAM_REQUEST_READ the params' pack is used, and said; from its answer on, its own
    first = next((i for i, r in enumerate(packed) if "capacity_mah" in guarantee(r)["pack"]), len(packed))
    assert all(guarantee(r)["pack"]["capacity_source"] == "params" for r in packed[:first])
    with_pack = packed[first:]
    assert with_pack, "no record holds the autopilot's capacity"
    c_j = cap_mah * 3.6 * cells * CELL_NOMINAL_V
    for r in with_pack:
        p, o = guarantee(r)["pack"], r["observations"]
        assert p["capacity_source"] == "autopilot" and p["capacity_mah"] == cap_mah
        assert p["cells"] == cells and p["cells_source"] == "first_voltage"
        assert p["capacity_j"] == pytest.approx(c_j, rel=1e-9)
        # the energy left: the percentage of the pack, or the charge not yet consumed, whichever is smaller
        left = o["battery_pct"] / 100.0 * c_j
        if "consumed_mah" in o:
            left = min(left, max(0.0, cap_mah - o["consumed_mah"]) * 3.6 * cells * CELL_NOMINAL_V)
        assert p["left_j"] == pytest.approx(left, rel=1e-9)

    for r in airborne:
        pw, o = guarantee(r)["power"], r["observations"]
        assert pw["measured_w"] == pytest.approx(o["battery_v"] * o["battery_current_a"], rel=1e-9)
        assert pw["predicted_w"] > 0.0
    # the stand-in's hover draws 14 A, plus 4 A per m/s of climb: in the air the measured current is that
    hovering = [r["observations"]["battery_current_a"] for r in airborne]
    assert max(hovering) >= 14.0 - 0.01, hovering
    # the activity's measured energy grows from the autopilot's consumed energy (BATTERY_STATUS.energy_consumed)
    assert max(guarantee(r)["power"].get("measured_j", 0.0) for r in airborne) > 0.0
