"""A pilot's words (issue 37 item 4), against the stand-in and a pymavlink ground station: in one flight with a refused
start, a tracking version switch, a re-allocation and a hand-off, each change of decision is ONE STATUSTEXT (MAVLink 2
chunks joined, as a ground station shows them), and no text repeats a number the ground station already plots
(docs/mavlink.md, "Values a ground station plots": the margins, the spendable energy, P_battery, the running version's
P_Vi, the cycle's time).

Which cycle a text belongs to comes from the companion's own flight.tlog: a cycle's record is stamped (`utc_us`,
the tlog's clock) before its texts are built and sent (`fly/cycle.rs`), so a text belongs to the last record stamped
before it (a text of the start gate or the stop, between cycles, to the cycle before it).
"""
from __future__ import annotations

import math
import re
import time
from typing import Any, Dict, List, Optional, Tuple

import pytest
from pymavlink import mavutil

from helpers import joined_statustexts
from standin import mavlink
from test_companion_fly import NOMINAL_TARGET
from test_operator_and_landing import COMPANION, wait

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

# Texts that are not a decision (the waiting notice, repeated by design; the ground station's link).
ROUTINE = ("companion ready, waiting for the operator", "companion: ground station")


def tlog_messages(folder: Any) -> List[Any]:
    conn = mavutil.mavlink_connection(str(folder / "flight.tlog"), dialect="ardupilotmega")
    out = []
    while True:
        m = conn.recv_match(blocking=False)
        if m is None:
            return out
        out.append(m)


def start_commands(folder: Any) -> List[float]:
    """When the ground station's MISSION_STARTs reached the companion (s since the epoch)."""
    return [m._timestamp for m in tlog_messages(folder) if m.get_type() == "COMMAND_LONG"
            and m.command == mavlink.MAV_CMD_MISSION_START and m.target_component == COMPANION]


def tlog_texts(folder: Any) -> List[Tuple[float, str]]:
    """(time s since the epoch, text) of every STATUSTEXT the companion sent, chunks joined."""
    msgs = [m for m in tlog_messages(folder) if m.get_type() == "STATUSTEXT" and m.get_srcComponent() == COMPANION]
    texts = joined_statustexts(msgs, COMPANION)
    # The time of each joined text: its first chunk's.
    starts = [m._timestamp for k, m in enumerate(msgs) if not (m.id != 0 and k > 0 and msgs[k - 1].id == m.id
                                                               and m.chunk_seq > 0)]
    assert len(starts) == len(texts), (len(starts), texts)
    return list(zip(starts, texts))


def owner(records: List[Dict[str, Any]], t: float) -> Optional[Dict[str, Any]]:
    """The last record stamped at or before `t` (s since the epoch)."""
    return next((r for r in reversed(records) if r.get("utc_us", 0) / 1e6 <= t), None)


def plotted(r: Dict[str, Any]) -> Dict[str, float]:
    """The numbers of record `r` the ground station plots (companion-link ground_values.rs), by unit."""
    g = r.get("guarantee") or {}
    out: Dict[str, float] = {}
    for name, key in (("e_margin", "energy_j"), ("t_margin", "duration_s")):
        if key in (g.get("margins") or {}):
            out[name] = g["margins"][key]
    spend = (g.get("pack") or {}).get("spendable_j")
    if spend is not None:
        out["e_spend"] = spend
    probs = r.get("probabilities") or {}
    for k, v in probs.items():
        if k == "P_battery" or re.fullmatch(r"P_V\d", k):
            out[k] = v
    if r.get("decide_ms") is not None:
        out["cycle_ms"] = r["decide_ms"]
    return out


def repeated(text: str, values: Dict[str, float]) -> List[str]:
    """The plotted values `text` shows, as a text would round them (to its number's decimals): energies as kJ or J,
    the time margin as s, the cycle's time as ms, probabilities as %, any value as a bare number. A distance (m) or
    a speed (m/s) is none of them; the digit of a name (`V3`) is not a number."""
    hits = []
    for m in re.finditer(r"(?<![A-Za-z0-9.])(\d+(?:\.\d+)?)(?:\s*(kJ|J|ms|s|%|m/s|m)(?![A-Za-z0-9]))?", text):
        n, unit = float(m.group(1)), m.group(2)
        decimals = len(m.group(1).partition(".")[2])
        tol = 0.5 * 10 ** -decimals + 1e-9
        for name, v in values.items():
            if v is None or not math.isfinite(v):
                continue
            energy = name.startswith("e_")
            shown = {"kJ": [v / 1000.0] if energy else [], "J": [v] if energy else [],
                     "s": [v] if name == "t_margin" else [], "ms": [v] if name == "cycle_ms" else [],
                     "%": [v * 100.0] if name.startswith("P_") else [], "m": [], "m/s": [], None: [v]}[unit]
            if any(abs(n - abs(x)) <= tol for x in shown):
                hits.append(f"{m.group(0)!r} = {name} {v}")
    return hits


def test_each_change_of_decision_is_one_text_repeating_no_plotted_value(autopilot_factory, fly, client,
                                                                        monitors_factory):
    ap = autopilot_factory()
    sa = ap.standin
    mon = monitors_factory(ap)
    gcs = client(sa.url)
    # 1. A refused start: the pack a third charged, too little for the mission.
    assert sa.set_param("SIM_BATT_PCT", 35)
    run = fly(ap, auto_start=False)
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)

    def judged_at(low: bool, after: int = -1):
        return lambda: any(r["cycle"] > after and "battery_pct" in (r.get("observations") or {})
                           and (r["observations"]["battery_pct"] < 50.0) == low
                           and bool((r.get("guarantee") or {}).get("verdict")) == low
                           and (r.get("guarantee") or {}).get("pack") for r in run.records())
    wait(judged_at(True), 30, "a record judged on the low pack", run)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_DENIED, run.output()
    # The pack charged: the start is granted.
    assert sa.set_param("SIM_BATT_PCT", 100)
    after = run.records()[-1]["cycle"]
    wait(judged_at(False, after), 30, "a record judged on the charged pack", run)
    # ... and the models' belief in the battery back up: they propose the take-off again.
    wait(lambda: any(r["cycle"] > after and "take_off" in r.get("actions", []) for r in run.records()), 60,
         "the take-off proposed again", run)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED, run.output()
    # 2. In flight: vibration (tracking switches to the stabilised V3), the target found, then the lidar driver's
    # failure (a re-allocation without the lidar); 3. then the companion is stopped: the hand-off.
    airborne: Optional[float] = None
    marks: Dict[str, float] = {}
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and run.proc.poll() is None:
        s = sa.state()
        if airborne is None and s["armed"] and s["alt"] > 2.0:
            airborne = time.monotonic()
        up = 0.0 if airborne is None else time.monotonic() - airborne
        if up > 2.0 and "vibration" not in marks:
            marks["vibration"] = time.monotonic()
            sa.set_param("SIM_VIB_MOT_MAX", 400)
        if up > 5.0 and "target" not in marks:
            marks["target"] = time.monotonic()
            mon.set(**NOMINAL_TARGET)
        recs = run.records() if up > 5.0 else []
        if "lidar" not in marks and any("track_v3" in r.get("actions", []) for r in recs):
            marks["lidar"] = time.monotonic()
            mon.set(lidar_fail=1)
        if "lidar" in marks and "stop" not in marks and \
                any(((r.get("guarantee") or {}).get("reallocation") or {}).get("trigger") == "failure" for r in recs):
            marks["stop"] = time.monotonic() + 3.0
        if "stop" in marks and time.monotonic() >= marks["stop"]:
            break
        time.sleep(0.2)
    assert "stop" in marks, f"the flight did not reach the re-allocation: {sorted(marks)}\n" + run.output()
    run.proc.terminate()
    assert run.wait_exit(30) is not None, run.output()

    records = run.records()
    folder = next(p for p in run.log_dir.iterdir() if p.is_dir())
    said = [(t, text) for t, text in tlog_texts(folder) if not text.startswith(ROUTINE)]
    by_record: Dict[int, List[str]] = {}
    for t, text in said:
        r = owner(records, t)
        by_record.setdefault(-1 if r is None else r["cycle"], []).append(text)
    cycle = {r["cycle"]: r for r in records}

    def one_text(what: str, texts: List[str]) -> str:
        assert len(texts) == 1, f"{what}: {texts}"
        return texts[0]

    checked: List[Tuple[str, str, Dict[str, float]]] = []
    # The refusal: the start gate answers the first MISSION_START at once, before the next cycle: one text, planned
    # against available and what fits.
    t_start = start_commands(folder)[0]
    t_next = next(r["utc_us"] / 1e6 for r in records if r["utc_us"] / 1e6 > t_start)
    text = one_text("the refused start", [x for t, x in said if t_start <= t < t_next])
    assert text.startswith("Start refused: ") and ". " in text and ("Time " in text or "Fits" in text), text
    # The available energy is the plotted e_spend at that moment (issue 36 asks for it): only it is let through.
    checked.append(("refusal", re.sub(r"have [\d.]+ kJ at \d+%", "have ...", text),
                    plotted(owner(records, t_start) or {})))
    # The version switch: the first record that tracks with V3 has one text, which says so.
    switch = next(r for r in records if "track_v3" in r.get("actions", []))
    text = one_text("the switch to V3", by_record.get(switch["cycle"], []))
    assert "tracking with V3" in text, text
    checked.append(("version switch", text, plotted(switch)))
    # The re-allocation (the lidar's failure): one text in its cycle, saying why and the plan in force.
    reallocs = [r for r in records if ((r.get("guarantee") or {}).get("reallocation") or {}).get("trigger")
                in ("failure", "margin")]
    assert reallocs, "no re-allocation for a failure"
    for r in reallocs:
        text = one_text(f"the re-allocation of cycle {r['cycle']}", by_record.get(r["cycle"], []))
        assert "plan changed" in text, text
        checked.append(("re-allocation", text, plotted(r)))
    assert any("lidar failed" in t.lower() for _, t, _ in checked), checked
    # The hand-off: one text, the stop's, and the autopilot accepted it (no second text).
    stops = [text for _, text in said if text.startswith("Companion stopping") or "hand-off" in text]
    text = one_text("the hand-off", stops)
    assert "RTL" in text, text
    checked.append(("hand-off", text, plotted(records[-1])))
    for what, text, values in checked:
        assert values, (what, "no plotted values to compare")
        assert not repeated(text, values), (what, text, repeated(text, values))
