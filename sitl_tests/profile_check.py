"""What the vehicle-profile tests (issue 23 item 5) compare, shared by the ArduCopter and PX4 ones: per activity of
a flown default mission, the guarantee's estimate in force when the activity began (`guarantee.planned_j`,
the pre-flight plan's cell while nothing was re-allocated) against the energy the autopilot reports drawn over it
(`energy_of`, from the observations the companion copied off the autopilot's BATTERY_STATUS), and the profile's
power curve and its leg, climb and descent numbers (`[derive]`) against the ones `companion calibrate` fits to the new
flight, and that the refit overlay holds only the vehicle (no route length, activity hold or machine path)."""
from __future__ import annotations

import math
import re
import subprocess
import tomllib
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Tuple

ROOT = Path(__file__).resolve().parent.parent
VEHICLES = ROOT / "params" / "vehicles"
MISSION = "missions/tracking.toml"


def activity_spans(records: List[Dict[str, Any]]) -> List[Tuple[str, Dict[str, Any], Dict[str, Any]]]:
    """(activity, its first armed record, the first record of the next activity) for every activity completed
    while armed: the wait on the ground before arming is not part of an activity flown."""
    spans = []
    cur: Optional[Tuple[str, Dict[str, Any]]] = None
    for r in records:
        g = r.get("guarantee") or {}
        name = g.get("activity_name")
        if not name or not r.get("vehicle", {}).get("armed"):
            continue
        if cur is None:
            cur = (name, r)
        elif cur[0] != name:
            spans.append((cur[0], cur[1], r))
            cur = (name, r)
    return spans


def compare(records: List[Dict[str, Any]], energy_of: Callable[[Dict[str, Any]], Optional[float]]):
    """[(activity, planned J, drawn J)] over the completed activities; asserts each has both numbers."""
    rows = []
    for name, first, nxt in activity_spans(records):
        planned = (first.get("guarantee") or {}).get("planned_j")
        e0, e1 = energy_of(first), energy_of(nxt)
        assert planned is not None and e0 is not None and e1 is not None, (name, planned, e0, e1)
        rows.append((name, planned, e1 - e0))
    return rows


def profile(name: str) -> Dict[str, Any]:
    return tomllib.loads((VEHICLES / f"{name}.toml").read_text())


def polynomial(overlay: Dict[str, Any]) -> Tuple[List[float], float]:
    """The overlay's propulsion coefficients and its base power."""
    m = overlay[MISSION]
    assert m["propulsion"]["model"] == "polynomial", m["propulsion"]
    return m["propulsion"]["coefficients_w"], m["base"]["power_w"]


def power_at(coeffs: List[float], base: float, v: float) -> float:
    return base + sum(c * v ** i for i, c in enumerate(coeffs))


def stated_rms_w(overlay: Dict[str, Any]) -> float:
    """The fit error the overlay states in its propulsion source ("fit RMS 7.2 W ...")."""
    src = overlay[MISSION]["propulsion"]["source"]
    return float(src.split("fit RMS ")[1].split(" W")[0])


def recalibrate(exe: str, run_dir: Path, out: Path, extra: Tuple[str, ...] = ()) -> Dict[str, Any]:
    p = subprocess.run([exe, "calibrate", str(run_dir), "--polynomial", "--out", str(out), *extra],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    refit = tomllib.loads(out.read_text())
    # calibrate writes the overlay without [propulsion] when the power fit fails; its report says why
    assert "propulsion" in refit.get(MISSION, {}), "no power fit in the overlay:\n" + p.stdout + p.stderr
    return refit


def assert_only_the_vehicle(text: str, run_dir: Path) -> None:
    """The overlay calibrate wrote holds no route length, activity hold or activities table, and names its runs by
    content id, not by the run folder's path on this machine."""
    t = tomllib.loads(text)
    assert "activities" not in t.get(MISSION, {}), text
    assert "length_m" not in text and "hold_s" not in text and "activities" not in text, text
    assert str(run_dir) not in text, text
    for run in t["calibration"]["runs"]:
        assert re.fullmatch(r"sha256:[0-9a-f]{64}", run), run


# The telemetry's resolution for a single flight's climb or descent (s): 5 Hz positions, and the companion's
# take-off command lands within a second of the arming it follows. A stated RMS of two like flights can be ~0.
VERTICAL_FLOOR_S = 1.0


def t975(df: int) -> float:
    """Student's t 97.5 % quantile for `df` degrees of freedom: bisection on the CDF, the density integrated by
    Simpson's rule (no SciPy in the venv). t975(2) = 4.303, t975(11) = 2.201 (test_profile_check.py, from tables)."""
    assert df >= 1, df
    c = math.gamma((df + 1) / 2) / (math.sqrt(df * math.pi) * math.gamma(df / 2))

    def tail_mass(x: float, steps: int = 4000) -> float:  # ∫_0^x of the density
        h = x / steps
        f = [c * (1 + (i * h) ** 2 / df) ** (-(df + 1) / 2) for i in range(steps + 1)]
        return h / 3 * (f[0] + f[-1] + 4 * sum(f[1:-1:2]) + 2 * sum(f[2:-1:2]))

    lo, hi = 0.0, 20.0
    for _ in range(50):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if tail_mass(mid) < 0.475 else (lo, mid)
    return (lo + hi) / 2


def sample_sd(rms: float, n: int, fitted: int) -> float:
    """The residuals' standard deviation from the RMS a fit of `fitted` parameters to `n` points states."""
    assert n > fitted, (n, fitted)
    return rms * math.sqrt(n / (n - fitted))


def derive_numbers(overlay: Dict[str, Any]) -> Tuple[Dict[str, float], Dict[str, str]]:
    """The overlay's [derive] vehicle numbers and their sources (calibration.sources)."""
    d = overlay[MISSION]["derive"]
    sources = overlay["calibration"]["sources"]
    keys = ("waypoint_overhead_s", "climb_speed_mps", "descent_speed_mps")
    for k in keys:
        assert k in d and f"{MISSION}:derive.{k}" in sources, (k, d, sources)
    return {k: d[k] for k in keys if k in d} | ({"speed_fraction": d["speed_fraction"]} if "speed_fraction" in d
                                                else {}), \
        {k: sources[f"{MISSION}:derive.{k}"] for k in keys}


def check_vehicle_numbers(shipped: Dict[str, Any], refit: Dict[str, Any]) -> None:
    """The leg model, climb and descent refitted to a new flight agree with the profile's within the 95 % band the
    profile's own data give (Student's t: the profile is fitted to a few flights, whose RMS alone understates the
    spread; a 1.96 s climb off a 0.79 s RMS of three flights failed CI at stop 48):
    - the time per waypoint: two estimates of one constant, the profile's over its n legs and the new flight's over
      its m, differ by t(n-1) * s * sqrt(1/n + 1/m), s the profile's residual sd;
    - the new flight's climb (and descent) took as long as the profile predicts for its height, within the
      prediction interval of one more flight, t(n-1) * s * sqrt(1 + 1/n), at least the telemetry's resolution."""
    (ship, src), (new, new_src) = derive_numbers(shipped), derive_numbers(refit)
    rms = float(re.search(r"fit RMS ([0-9.]+) s", src["waypoint_overhead_s"]).group(1))
    n = int(re.search(r"(\d+) legs in", src["waypoint_overhead_s"]).group(1))
    m = int(re.search(r"(\d+) legs in", new_src["waypoint_overhead_s"]).group(1))
    # the model fits c alone (t = L / v_cmd + c), or c and the speed's fraction: then the intercept's spread is wider
    # than this band (it depends on the legs' lengths, which the source does not give)
    fitted = 2 if "speed_fraction" in ship else 1
    tol = t975(n - fitted) * sample_sd(rms, n, fitted) * math.sqrt(1 / n + 1 / m)
    assert abs(new["waypoint_overhead_s"] - ship["waypoint_overhead_s"]) <= tol, (ship, new, rms, n, m, tol)
    # the commanded speed reached (or not) alike
    assert ("speed_fraction" in ship) == ("speed_fraction" in new), (ship, new)
    if "speed_fraction" in ship:
        assert abs(new["speed_fraction"] - ship["speed_fraction"]) <= 0.05, (ship, new)
    for k in ("climb_speed_mps", "descent_speed_mps"):
        e = float(re.search(r"against it ([0-9.]+) s", src[k]).group(1))
        n = int(re.search(r"(\d+) (?:climb|descent)\(s\) in", src[k]).group(1))
        h = float(re.search(r"([0-9.]+) m on average", new_src[k]).group(1))
        flown, predicted = h / new[k], h / ship[k]
        tol = max(t975(n - 1) * sample_sd(e, n, 1) * math.sqrt(1 + 1 / n), VERTICAL_FLOOR_S)
        assert abs(flown - predicted) <= tol, (k, h, flown, predicted, n, e, tol)
