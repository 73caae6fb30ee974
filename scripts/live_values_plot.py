#!/usr/bin/env python3
"""Capture the live decision channels of a real ArduCopter SITL flight with a Foxglove WebSocket client and draw
them: docs/live_values.svg (docs/decision-log.md, "Watching live").

A fresh ArduCopter SITL (../shared/sitl/ or $ARDUCOPTER, as the real tests find it), a pymavlink observer on SERIAL0
(SITL runs once a first client is there), `companion fly --auto-start --live 127.0.0.1:0` on SERIAL1 for
--seconds, and the test client of sitl_tests/test_live_foxglove.py subscribed to every channel from before the
first cycle. Plotted against the record's time: P_battery and the running tracking version's P_Vi
(/decisions/probabilities), the guarantee's energy margin and spendable energy (/decisions/guarantee), the values
the ground station plots too (docs/mavlink.md). The SVG is written by hand (no plotting library needed).

    COMPANION_BIN=target/debug/companion .venv/bin/python scripts/live_values_plot.py [--seconds 90] [--out docs/live_values.svg]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Tuple

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "sitl_tests"))

from real_autopilot import ArduCopterSitl, GcsObserver, find_arducopter, next_instance  # noqa: E402
from test_live_foxglove import Viewer, wait_live_url  # noqa: E402

Series = List[Tuple[float, float]]


def capture(seconds: float, speedup: float, work: Path) -> Tuple[Dict[str, Series], Dict[str, Series]]:
    binary, defaults, why = find_arducopter()
    if binary is None:
        sys.exit(f"no ArduCopter SITL: {why}")
    sitl = ArduCopterSitl(binary, defaults, next_instance(), work / "arducopter", speedup=speedup,
                          extra_defaults={"BATT_CAPACITY": 12000})
    sitl.start()
    gcs = GcsObserver(f"tcp:127.0.0.1:{sitl.ports.serial0}", alive=sitl.alive).start()
    try:
        sitl.wait_listening(sitl.ports.serial1, 30.0)
        err = work / "fly.err"
        cmd = [os.environ["COMPANION_BIN"], "fly", "--connect", f"tcp:127.0.0.1:{sitl.ports.serial1}",
               "--auto-start", "--once", "--log-dir", str(work / "runs"), "--live", "127.0.0.1:0",
               "--duration", f"{seconds:.0f}s"]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=open(err, "w"))
        viewer = Viewer(wait_live_url(err, proc)).start()
        proc.wait(timeout=seconds + 60)
        viewer.join()
    finally:
        gcs.stop()
        sitl.stop()
    probs: Dict[str, Series] = {}
    energy: Dict[str, Series] = {}
    for topic, _t, msg in viewer.messages:
        t = msg["time_s"]
        if topic == "/decisions/probabilities":
            for k in ("P_battery", "P_V1", "P_V2", "P_V3"):
                if k in msg:
                    probs.setdefault(k, []).append((t, msg[k]))
        elif topic == "/decisions/guarantee":
            margin = (msg.get("margins") or {}).get("energy_j")
            spend = (msg.get("pack") or {}).get("spendable_j")
            if margin is not None:
                energy.setdefault("energy margin (e_margin)", []).append((t, margin / 1000.0))
            if spend is not None:
                energy.setdefault("spendable (e_spend)", []).append((t, spend / 1000.0))
    return probs, energy


COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"]


def panel(x0: float, y0: float, w: float, h: float, title: str, unit: str, series: Dict[str, Series],
          t_max: float) -> List[str]:
    values = [v for s in series.values() for _, v in s] or [0.0, 1.0]
    lo, hi = min(values + [0.0]), max(values)
    hi = hi if hi > lo else lo + 1.0
    sx = lambda t: x0 + w * t / t_max  # noqa: E731
    sy = lambda v: y0 + h - h * (v - lo) / (hi - lo)  # noqa: E731
    out = [f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="#888"/>',
           f'<text x="{x0}" y="{y0 - 8}" font-size="14">{title}</text>',
           f'<text x="{x0 - 6}" y="{y0 + 4}" font-size="11" text-anchor="end">{hi:.3g} {unit}</text>',
           f'<text x="{x0 - 6}" y="{y0 + h}" font-size="11" text-anchor="end">{lo:.3g} {unit}</text>']
    if lo < 0 < hi:
        out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{sy(0):.1f}" y2="{sy(0):.1f}" stroke="#bbb" '
                   'stroke-dasharray="4 3"/>')
    for i, (name, s) in enumerate(sorted(series.items())):
        c = COLOURS[i % len(COLOURS)]
        pts = " ".join(f"{sx(t):.1f},{sy(v):.1f}" for t, v in s)
        out.append(f'<polyline fill="none" stroke="{c}" stroke-width="1.6" points="{pts}"/>')
        out.append(f'<text x="{x0 + w + 10}" y="{y0 + 16 + 16 * i}" font-size="12" fill="{c}">{name}</text>')
    return out


def render(probs: Dict[str, Series], energy: Dict[str, Series], out: Path) -> None:
    t_max = max([t for s in list(probs.values()) + list(energy.values()) for t, _ in s] + [1.0])
    w, h = 560, 170
    body = ['<svg xmlns="http://www.w3.org/2000/svg" width="860" height="520" font-family="sans-serif">',
            '<rect width="100%" height="100%" fill="white"/>',
            '<text x="20" y="26" font-size="16">companion fly --live: a real ArduCopter SITL flight, as a '
            'Foxglove WebSocket client received it</text>']
    body += panel(80, 70, w, h, "/decisions/probabilities", "", probs, t_max)
    body += panel(80, 300, w, h, "/decisions/guarantee", "kJ", energy, t_max)
    body.append(f'<text x="{80 + w / 2}" y="500" font-size="12" text-anchor="middle">record time_s '
                f'(0 to {t_max:.0f} s)</text>')
    body.append("</svg>")
    out.write_text("\n".join(body) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=90.0, help="wall seconds of flight (fly --duration)")
    ap.add_argument("--speedup", type=float, default=3.0)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "live_values.svg")
    ap.add_argument("--json", type=Path, help="also keep the captured series here")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        probs, energy = capture(a.seconds, a.speedup, Path(d))
    if not probs:
        sys.exit("nothing captured")
    if a.json:
        a.json.write_text(json.dumps({"probabilities": probs, "guarantee_kJ": energy}))
    render(probs, energy, a.out)
    print(f"{a.out}: {sum(map(len, probs.values()))} probability and {sum(map(len, energy.values()))} energy points")


if __name__ == "__main__":
    main()
