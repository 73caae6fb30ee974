"""The plan against the flight (issue 36, Done-when 2), shared by the ArduCopter and PX4 tests: the pre-flight plan
from the decision log's header (`plan.planned`: per activity the pre-flight allocation's energy and duration), the
flight from the ground station's own link (GcsObserver: BATTERY_STATUS voltage x current integrated over the vehicle's
clock, arm to disarm). Each activity's time window is where the companion's records name it (`guarantee.activity_name`,
at the record's `vehicle_time_s`); its energy and duration are the ground station's over that window.

Times are the autopilot's (time_boot_ms): SITL runs SITL_SPEEDUP times faster than the wall clock, and the plan is in
the vehicle's seconds.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Tuple

TOLERANCE = 0.15
# Only activities longer than this (s, flown) are compared one by one (issue 36).
LONG_ACTIVITY_S = 30.0


def header(log_dir: Path) -> Dict[str, Any]:
    logs = sorted(Path(log_dir).rglob("decisions.jsonl"))
    assert logs, f"no decision log under {log_dir}"
    return json.loads(logs[0].read_text().splitlines()[0])


@dataclass
class Flight:
    """What the ground station saw, on the vehicle's clock."""
    armed_at: float
    disarmed_at: float
    power: List[Tuple[float, float]]          # (vehicle s, V x I W), arm to disarm

    def energy(self, t0: float, t1: float) -> float:
        """V x I integrated over [t0, t1] (each sample holds until the next)."""
        e = 0.0
        for (ta, p), (tb, _) in zip(self.power, self.power[1:]):
            lo, hi = max(ta, t0), min(tb, t1)
            if hi > lo:
                e += p * (hi - lo)
        return e


def ground_flight(gcs: Any, since: float) -> Flight:
    """The flight after wall time `since`: the arming and the disarming after it, and the pack's V x I between them,
    all mapped onto the vehicle's clock."""
    with gcs._lock:
        changes = [(t, a) for t, a in gcs.armed_times if t >= since]
        power = list(gcs.battery_power_w)
    arm = next(t for t, a in changes if a)
    disarm = next(t for t, a in changes if not a and t > arm)
    v_arm, v_disarm = gcs.vehicle_time(arm), gcs.vehicle_time(disarm)
    assert v_arm is not None and v_disarm is not None, (arm, disarm)
    samples = [(gcs.vehicle_time(t), p) for t, p in power if arm <= t <= disarm]
    samples = [(v, p) for v, p in samples if v is not None]
    assert len(samples) > 20, f"{len(samples)} BATTERY_STATUS samples with V and I in the flight"
    return Flight(v_arm, v_disarm, samples)


def activity_windows(records: List[Dict[str, Any]], flight: Flight) -> List[Tuple[str, float, float]]:
    """(activity, start, end) on the vehicle's clock: each activity from the first armed record naming it to the
    next one's start; the first starts at arming, the last ends at disarming."""
    starts: List[Tuple[str, float]] = []
    for r in records:
        name = (r.get("guarantee") or {}).get("activity_name")
        vt = (r.get("observations") or {}).get("vehicle_time_s")
        if not name or vt is None or not (r.get("vehicle") or {}).get("armed"):
            continue
        if not flight.armed_at <= vt <= flight.disarmed_at:
            continue
        if not starts or starts[-1][0] != name:
            starts.append((name, vt))
    assert starts, "no armed record names an activity"
    starts[0] = (starts[0][0], flight.armed_at)
    ends = [t for _, t in starts[1:]] + [flight.disarmed_at]
    return [(n, t0, t1) for (n, t0), t1 in zip(starts, ends)]


@dataclass
class Row:
    what: str
    planned_j: float
    flown_j: float
    planned_s: float
    flown_s: float

    @property
    def energy_ratio(self) -> float:
        return self.planned_j / self.flown_j

    @property
    def duration_ratio(self) -> float:
        return self.planned_s / self.flown_s

    def within(self) -> bool:
        return abs(self.planned_j - self.flown_j) <= TOLERANCE * self.flown_j and \
            abs(self.planned_s - self.flown_s) <= TOLERANCE * self.flown_s


def compare(plan: Dict[str, Any], records: List[Dict[str, Any]], flight: Flight,
            not_flown: Dict[str, str]) -> Tuple[Row, List[Row], List[str]]:
    """The whole mission and each activity flown longer than LONG_ACTIVITY_S: planned against flown. `not_flown`:
    the planned activities the flight cannot fly and why (tracking with no target in SITL); they are left out of the
    mission's planned total, said in the table. Returns (mission, activities, the table's lines)."""
    cells = {c["name"]: c for c in plan["planned"]}
    windows = activity_windows(records, flight)
    flown_names = [n for n, _, _ in windows]
    assert len(set(flown_names)) == len(flown_names), f"an activity flown twice: {flown_names}"
    for n in flown_names:
        assert n in cells, (n, list(cells))
    missing = [n for n in cells if n not in flown_names and n not in not_flown]
    rows = []
    for n, t0, t1 in windows:
        rows.append(Row(n, cells[n]["energy_j"], flight.energy(t0, t1), cells[n]["duration_s"], t1 - t0))
    kept = [c for n, c in cells.items() if n not in not_flown]
    mission = Row("mission (arm to disarm)", sum(c["energy_j"] for c in kept), flight.energy(flight.armed_at,
                  flight.disarmed_at), sum(c["duration_s"] for c in kept), flight.disarmed_at - flight.armed_at)
    lines = [f"{'activity':<26} {'plan kJ':>8} {'flown kJ':>8} {'ratio':>6} {'plan s':>7} {'flown s':>7} {'ratio':>6}"]
    for r in [mission] + rows:
        mark = "" if r is mission or r.flown_s > LONG_ACTIVITY_S else "  (<= 30 s: not compared)"
        lines.append(f"{r.what:<26} {r.planned_j / 1000:8.1f} {r.flown_j / 1000:8.1f} {r.energy_ratio:6.2f} "
                     f"{r.planned_s:7.1f} {r.flown_s:7.1f} {r.duration_ratio:6.2f}{mark}")
    for n, why in not_flown.items():
        if n in cells:
            lines.append(f"{n:<26} {cells[n]['energy_j'] / 1000:8.1f} {'-':>8} {'':>6} "
                         f"{cells[n]['duration_s']:7.1f}   not flown: {why}")
    for n in missing:
        lines.append(f"{n:<26} {cells[n]['energy_j'] / 1000:8.1f} {'-':>8} {'':>6} "
                     f"{cells[n]['duration_s']:7.1f}   NEVER FLOWN")
    print("\n".join(lines))
    assert not missing, f"planned activities never flown: {missing} (flown: {flown_names})"
    return mission, [r for r in rows if r.flown_s > LONG_ACTIVITY_S], lines


def assert_within(mission: Row, long_rows: List[Row], lines: List[str]) -> None:
    table = "\n".join(lines)
    bad = [r.what for r in [mission] + long_rows if not r.within()]
    assert not bad, f"planned more than {TOLERANCE:.0%} off the flight for {bad}:\n{table}"
