"""A pilot's words (issue 37 item 4), against the stand-in and a pymavlink ground station: in one flight with a refused
start, a tracking version switch, a re-allocation and a hand-off, each change of decision is ONE STATUSTEXT (MAVLink 2
chunks joined, as a ground station shows them), and no text repeats a number the ground station already plots
(docs/mavlink.md, "Values a ground station plots": the margins, the spendable energy, P_battery, the running version's
P_Vi, the cycle's time).

Which cycle a text belongs to comes from the companion's own flight.tlog: a cycle's texts are sent, and logged there,
before its record is written (`fly/cycle.rs`), so a text belongs to the first record written after it.
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
from standin.vocabulary import DEFAULT_PARAMS
from test_companion_fly import NOMINAL_TARGET
from test_operator_and_landing import COMPANION, wait
from test_verdict_standin import SMALL_PACK_MAH

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

# Texts that are not a decision (the waiting notice, repeated by design; the ground station's link).
ROUTINE = ("companion ready, waiting for the operator", "companion: ground station")


def tlog_texts(folder: Any) -> List[Tuple[float, str]]:
    """(time s since the epoch, text) of every STATUSTEXT the companion sent, chunks joined."""
    conn = mavutil.mavlink_connection(str(folder / "flight.tlog"), dialect="ardupilotmega")
    msgs = []
    while True:
        m = conn.recv_match(blocking=False)
        if m is None:
            break
        if m.get_type() == "STATUSTEXT" and m.get_srcComponent() == COMPANION and m.get_srcSystem() != 255:
            msgs.append(m)
    texts = joined_statustexts(msgs, COMPANION)
    # The time of each joined text: its first chunk's.
    starts = [m._timestamp for k, m in enumerate(msgs) if not (m.id != 0 and k > 0 and msgs[k - 1].id == m.id
                                                               and m.chunk_seq > 0)]
    assert len(starts) == len(texts), (len(starts), texts)
    return list(zip(starts, texts))


def owner(records: List[Dict[str, Any]], t: float) -> Optional[Dict[str, Any]]:
    """The first record written at or after `t` (s since the epoch)."""
    return next((r for r in records if r.get("utc_us", 0) / 1e6 >= t), None)


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
    """The plotted values `text` shows, as a text would round them: kJ (one decimal or whole), s, %, or bare."""
    hits = []
    for m in re.finditer(r"(?<![A-Za-z0-9.])(\d+(?:\.\d+)?)\s*(kJ|J|s|ms|%)?(?![A-Za-z0-9])", text):
        n, unit = float(m.group(1)), m.group(2)
        for name, v in values.items():
            if v is None or not math.isfinite(v):
                continue
            energy, prob = name.startswith("e_"), name.startswith("P_")
            shown = {"kJ": [abs(v) / 1000.0] if energy else [], "J": [abs(v)] if energy else [],
                     "s": [abs(v)] if name == "t_margin" else [], "ms": [abs(v)] if name == "cycle_ms" else [],
                     "%": [abs(v) * 100.0] if prob else [], None: [abs(v)]}[unit]
            if any(abs(n - s) < 0.05 + 0.5 * (not ("." in m.group(1))) * (s >= 10) for s in shown):
                hits.append(f"{m.group(0)} = {name} {v}")
    return hits


def test_each_change_of_decision_is_one_text_repeating_no_plotted_value(autopilot_factory, fly, client,
                                                                        monitors_factory):
    ap = autopilot_factory()
    sa = ap.standin
    mon = monitors_factory(ap)
    gcs = client(sa.url)
    # 1. A refused start: a pack too small for the mission (test_verdict_standin).
    assert sa.set_param("BATT_CAPACITY", SMALL_PACK_MAH)
    run = fly(ap, auto_start=False)
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)

    def judged_on(mah: float, refused: bool):
        return lambda: any(((r.get("guarantee") or {}).get("pack") or {}).get("capacity_mah") == mah
                           and bool((r.get("guarantee") or {}).get("verdict")) == refused for r in run.records())
    wait(judged_on(SMALL_PACK_MAH, True), 30, "a record judged on the small pack", run)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_DENIED, ack
    # The vehicle's own pack back: the start is granted.
    assert sa.set_param("BATT_CAPACITY", DEFAULT_PARAMS["BATT_CAPACITY"])
    wait(judged_on(DEFAULT_PARAMS["BATT_CAPACITY"], False), 30, "a record judged on the full pack", run)
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
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
    # The refusal: one text for the refused start, planned against available and what fits.
    refusal = [c for c, ts in by_record.items() if any(t.startswith("Start refused") for t in ts)]
    assert len(refusal) == 1, by_record
    text = one_text("the refused start", by_record[refusal[0]])
    assert ". " in text and ("Time " in text or "Fits" in text), text
    # The available energy is the plotted e_spend at that moment (issue 36 asks for it): only it is let through.
    checked.append(("refusal", re.sub(r"have [\d.]+ kJ at \d+%", "have ...", text),
                    plotted(cycle.get(refusal[0], {}))))
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
    assert any("lidar failed" in t for _, t, _ in checked), checked
    # The hand-off: one text, the stop's, and the autopilot accepted it (no second text).
    stops = [text for _, text in said if text.startswith("Companion stopping") or "hand-off" in text]
    text = one_text("the hand-off", stops)
    assert "RTL" in text, text
    checked.append(("hand-off", text, plotted(records[-1])))
    for what, text, values in checked:
        assert values, (what, "no plotted values to compare")
        assert not repeated(text, values), (what, text, repeated(text, values))
