"""The ArduCopter SITL vehicle profile (issue 23 item 5), on a real ArduCopter SITL flying the default mission with
`--vehicle arducopter-sitl` (params/vehicles/arducopter-sitl.toml, made by `companion calibrate` from the flights
docs/sitl.md gives):

* the guarantee's pre-flight estimate of each activity flown is within 10 % of the energy the autopilot reports
  drawn over it (BATTERY_STATUS.energy_consumed), in total and for the long search, and the record holds both;
* `companion calibrate` on this flight gives the profile's power curve back within the fit error it states.

No speed-up: the search's time limit is the companion's wall clock, so a faster SITL would fly it longer.
"""
from __future__ import annotations

import pytest

from profile_check import compare, polynomial, power_at, profile, recalibrate, stated_rms_w

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

# The pack: with the profile's ~355 W the whole default mission (10 min of tracking included) needs ~380 kJ, more than
# the 12 Ah fixture pack's usable 360 kJ, so the guarantee would rightly refuse the start; 16 Ah holds it.
PACK = {"BATT_CAPACITY": 16000}


def test_real_profile_predicts_the_energy_flown_within_10_percent(arducopter, fly, tmp_path):
    import os
    veh = arducopter(speedup=1.0, extra_defaults=PACK)
    # the profile was fitted on the typed activities: this test judges that legacy plan explicitly
    run = fly(veh.autopilot, extra=("--vehicle", "arducopter-sitl", "--legacy-plan"))
    rc = run.wait_exit(900)
    assert rc == 0, f"companion fly exited {rc}\n" + run.output()
    # what the autopilot itself says, over the ground-station link
    assert veh.gcs.ever_armed() and not veh.gcs.armed, veh.gcs.summary()
    records = run.records()
    # no re-allocation for a margin or a failure (the plan following the versions that run is one by design:
    # docs/guarantee.md, "One configuration"), so the estimates in force are the pre-flight plan's
    realloc = [g["reallocation"] for g in (r.get("guarantee") or {} for r in records) if g.get("reallocation")]
    assert not [x for x in realloc if x.get("trigger") not in ("follows_versions", "follows_placement")], \
        realloc

    def drawn(r):
        return r.get("observations", {}).get("energy_consumed_j")

    rows = compare(records, drawn)
    names = [n for n, _, _ in rows]
    assert names[:4] == ["take_off", "transit", "transit_gps_degraded", "obstacle_dense"], rows
    # the records copy the autopilot's count: the last one within 2 kJ of what the ground station heard last
    last = drawn(records[-1])
    assert veh.gcs.battery_energy_j is not None and abs(last - veh.gcs.battery_energy_j) <= 2000.0, \
        (last, veh.gcs.battery_energy_j)
    planned = sum(p for _, p, _ in rows)
    flown = sum(d for _, _, d in rows)
    assert flown > 50_000.0, rows
    assert abs(planned - flown) <= 0.10 * flown, rows
    search = next(r for r in rows if r[0] == "obstacle_dense")
    assert abs(search[1] - search[2]) <= 0.10 * search[2], search

    # calibrate on this flight: the profile's curve back within its stated error over the speeds flown
    shipped = profile("arducopter-sitl")
    refit = recalibrate(os.environ["COMPANION_BIN"], run.log_dir, tmp_path / "refit.toml")
    (c_ship, b_ship), (c_new, b_new) = polynomial(shipped), polynomial(refit)
    tol = stated_rms_w(shipped)
    for v in [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]:
        assert abs(power_at(c_ship, b_ship, v) - power_at(c_new, b_new, v)) <= tol, (v, c_ship, c_new, tol)
    # the ground power apart from the air's: a disarmed sample counted in the air (or the reverse) moves power
    # between the base and c0 while their sum still fits
    assert abs(b_new - b_ship) <= tol, (b_ship, b_new, tol)
