"""What the vehicle-profile tests (issue 23 item 5) compare, shared by the ArduCopter and PX4 ones: per activity of
a flown default mission, the guarantee's estimate in force when the activity began (`guarantee.planned_j`,
the pre-flight plan's cell while nothing was re-allocated) against the energy the autopilot reports drawn over it
(`energy_of`, from the observations the companion copied off the autopilot's BATTERY_STATUS), and the profile's
power curve against the one `companion calibrate` fits to the new flight."""
from __future__ import annotations

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


def recalibrate(exe: str, run_dir: Path, out: Path) -> Dict[str, Any]:
    p = subprocess.run([exe, "calibrate", str(run_dir), "--polynomial", "--out", str(out)], capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    refit = tomllib.loads(out.read_text())
    # calibrate writes the overlay without [propulsion] when the power fit fails; its report says why
    assert "propulsion" in refit.get(MISSION, {}), "no power fit in the overlay:\n" + p.stdout + p.stderr
    return refit
