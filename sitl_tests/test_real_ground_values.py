"""Values a ground station plots (issue 37, item 1), against a fresh real ArduCopter SITL (skipped without the binary).

The companion runs next to the vehicle (no start: nothing moves) while a pymavlink ground station on SERIAL0 listens.
ArduCopter routes the companion's broadcast NAMED_VALUE_FLOAT / NAMED_VALUE_INT from its link to the ground station's,
as it does STATUSTEXT. Judged from the ground station: the values come from the companion's system and component
191, at params/link.toml's [ground_values] rate_hz (1 Hz) within 20 %, with the documented names, and each value
equals the decision record of the cycle its time_boot_ms names (the record's time_s in ms).
"""
from __future__ import annotations

import math
import time
import tomllib
from pathlib import Path

import pytest

from test_real_ardupilot import SPEEDUP

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

# docs/mavlink.md, "Values a ground station plots": always sent, and sent when the record has them.
ALWAYS = {"cycle", "actions", "cycle_ms"}
DOCUMENTED = ALWAYS | {"e_margin", "t_margin", "e_spend", "p_battery", "trk_ver", "p_trk_ver"}
# `actions`: bit n set for the chosen action the paper names An (params/actions.toml's `paper`).
PAPER_BIT = {a["id"]: int(a["paper"][1:]) for a in
             tomllib.loads((Path(__file__).parent.parent / "params" / "actions.toml").read_text())["action"]}


def expected(rec: dict, name: str):
    """The record's value under a plotted name (None when the record has none)."""
    g = rec.get("guarantee") or {}
    running = [p for p in (rec.get("resources") or {}).get("placements", []) if p["app"] == "tracking"]
    if name == "cycle":
        return rec["cycle"]
    if name == "actions":
        return sum(1 << PAPER_BIT[a] for a in set(rec["actions"]))
    if name == "cycle_ms":
        return rec.get("decide_ms")
    if name == "e_margin":
        return (g.get("margins") or {}).get("energy_j")
    if name == "t_margin":
        return (g.get("margins") or {}).get("duration_s")
    if name == "e_spend":
        return (g.get("pack") or {}).get("spendable_j")
    if name == "p_battery":
        return rec["probabilities"].get("P_battery")
    if name == "trk_ver":
        return int(running[0]["version"].lstrip("V")) if running else None
    if name == "p_trk_ver":
        return rec["probabilities"].get("P_" + running[0]["version"]) if running else None
    raise AssertionError(name)


def test_real_ground_station_plots_the_records_values_at_the_set_rate(arducopter, fly):
    veh = arducopter(speedup=SPEEDUP)
    gcs = veh.gcs
    run = fly(veh.autopilot, auto_start=False, once=False)
    gcs.wait(lambda: any(c == 191 for _, _, c, *_ in gcs.named_values), 90, "a first value from component 191")
    with gcs._lock:
        t_first = next(t for t, _, c, *_ in gcs.named_values if c == 191)
    window_s = 30.0
    time.sleep(window_s + 1.0)
    run.proc.terminate()
    assert run.wait_exit(20) == 0, run.output()
    with gcs._lock:
        ours = [v for v in gcs.named_values if v[2] == 191]
        others = [v for v in gcs.named_values if v[2] != 191]
    assert not others, f"values from another component: {others[:5]}"
    systems = {s for _, s, *_ in ours}
    assert systems == {1}, f"values from systems {systems}: the companion takes the autopilot's system id"
    names = {n for *_, n, _, _ in [(v[0], v[1], v[2], v[3], v[4], v[5]) for v in ours]}
    assert ALWAYS <= names, f"missing {ALWAYS - names}; got {sorted(names)}"
    assert names <= DOCUMENTED, f"undocumented names {names - DOCUMENTED}"
    # Rate: distinct sets (one time_boot_ms each) heard within the window after the first.
    sets = {}
    for t, _, _, name, value, tb in ours:
        sets.setdefault(tb, {"t": t, "values": {}})["values"][name] = value
    in_window = [s for s in sets.values() if t_first <= s["t"] < t_first + window_s]
    rate = len(in_window) / window_s
    assert 0.8 <= rate <= 1.2, f"{len(in_window)} value sets in {window_s:.0f} s: {rate:.2f} Hz, set 1 Hz"
    # Each set equals the record of its cycle.
    records = {round(r["time_s"] * 1000): r for r in run.records()}
    checked = 0
    for tb, s in sets.items():
        rec = records.get(tb)
        assert rec is not None, f"no record at time_s {tb / 1000:.3f} for the values {s['values']}"
        assert s["values"]["cycle"] == rec["cycle"]
        for name, value in s["values"].items():
            want = expected(rec, name)
            assert want is not None, f"{name} sent, the record of cycle {rec['cycle']} has none"
            assert math.isclose(value, want, rel_tol=1e-6, abs_tol=1e-3), \
                f"cycle {rec['cycle']}: {name} = {value}, the record says {want}"
            checked += 1
        for name in DOCUMENTED - set(s["values"]):
            assert expected(rec, name) is None, f"cycle {rec['cycle']}: {name} in the record, not sent"
    assert checked >= 3 * len(in_window)
    print(f"{len(in_window)} sets at {rate:.2f} Hz, {checked} values equal to their records; names {sorted(names)}")
