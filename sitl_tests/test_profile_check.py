"""The vehicle-profile checks' statistics (profile_check.py) against published tables, with no autopilot."""
from __future__ import annotations

import pytest

from profile_check import MISSION, check_vehicle_numbers, t975


@pytest.mark.parametrize("df,table", [(1, 12.706), (2, 4.303), (7, 2.365), (11, 2.201), (30, 2.042)])
def test_t975_equals_the_tables(df, table):
    # Student's t two-sided 95 % critical values (NIST/SEMATECH e-Handbook, table 1.3.6.7.2)
    assert abs(t975(df) - table) < 0.002, (df, t975(df))


def overlay(climb_mps: float, climbs: int, rms_s: float, overhead_s: float = 3.5, legs: int = 12):
    src = f"{MISSION}:derive."
    return {
        MISSION: {"derive": {"climb_speed_mps": climb_mps, "descent_speed_mps": 1.0, "waypoint_overhead_s": overhead_s}},
        "calibration": {"sources": {
            src + "climb_speed_mps": f"companion calibrate: {climbs} climb(s) in {climbs} run(s), 20.2 m on average; "
                                     f"rate = height / time over them all; RMS of each one's time against it {rms_s} s",
            src + "descent_speed_mps": f"companion calibrate: {climbs} descent(s) in {climbs} run(s), 20.0 m on "
                                       "average; rate = height / time over them all; RMS of each one's time against "
                                       "it 0.00 s",
            src + "waypoint_overhead_s": f"companion calibrate: {legs} legs in 3 run(s), 48..150 m, commanded 5.0..5.0 "
                                         "m/s (x); model t = L / v_cmd + c, fit RMS 1.02 s; without it RMS 3.66 s",
        }},
    }


def test_a_climb_two_of_its_sds_off_a_three_flight_profile_is_within_its_prediction_band():
    # stop 48's CI: 20.2 m flown in 19.97 s, the profile (3 climbs, RMS 0.79 s) predicting 18.01 s; band 4.8 s
    shipped = overlay(20.2 / 18.01, 3, 0.79)
    check_vehicle_numbers(shipped, overlay(20.2 / 19.97, 1, 0.0))
    # a climb 5 s longer is outside it; so is 2.5 s longer off a ten-flight profile (band 1.96 s)
    with pytest.raises(AssertionError, match="climb_speed_mps"):
        check_vehicle_numbers(shipped, overlay(20.2 / 23.01, 1, 0.0))
    check_vehicle_numbers(overlay(20.2 / 18.01, 10, 0.79), overlay(20.2 / 19.9, 1, 0.0))
    with pytest.raises(AssertionError, match="climb_speed_mps"):
        check_vehicle_numbers(overlay(20.2 / 18.01, 10, 0.79), overlay(20.2 / 20.5, 1, 0.0))


def test_a_new_flights_waypoint_overhead_is_judged_against_both_estimates_spreads():
    # 12 legs, RMS 1.02 s, against 4 legs: band t(11) * 1.02 * sqrt(12/11) * sqrt(1/12 + 1/4) = 1.37 s
    check_vehicle_numbers(overlay(1.0, 3, 0.5), overlay(1.0, 1, 0.0, overhead_s=3.5 + 1.3, legs=4))
    with pytest.raises(AssertionError, match="waypoint_overhead_s"):
        check_vehicle_numbers(overlay(1.0, 3, 0.5), overlay(1.0, 1, 0.0, overhead_s=3.5 + 1.45, legs=4))
