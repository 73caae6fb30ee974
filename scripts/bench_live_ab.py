#!/usr/bin/env python3
"""Two builds of `bench_live` side by side (docs/performance.md, "With a stalled live viewer"): each
round runs BEFORE then AFTER, full runs of CYCLES cycles per case, and prints every run's medians
and ratio, then each binary's ratios and their median. Alternating whole runs puts the machine's
drift on both. Build each with `cargo build --release -p companion-testkit --example bench_live`
and copy target/release/examples/bench_live aside.

    scripts/bench_live_ab.py BEFORE_BIN AFTER_BIN [CYCLES=20000] [ROUNDS=6]
"""
import json, os, statistics, subprocess, sys

bins = {"before": sys.argv[1], "after": sys.argv[2]}
n = int(sys.argv[3]) if len(sys.argv) > 3 else 20000
rounds = int(sys.argv[4]) if len(sys.argv) > 4 else 6
res = {"before": [], "after": []}
print("load at start", os.getloadavg())
for r in range(rounds):
    for b in ("before", "after"):
        out = subprocess.run([bins[b], str(n)], capture_output=True, text=True, check=True).stdout
        d = json.loads(out.strip().splitlines()[-1])
        m = {c["name"]: c["median_us"] for c in d["cases"]}
        res[b].append(d["ratio_of_medians"])
        print(b, f"no_live={m['no_live']:.2f} stalled={m['stalled_viewer']:.2f} ratio={d['ratio_of_medians']:.3f}",
              f"dropped={d['live_dropped']}", flush=True)
print("load at end", os.getloadavg())
for b, v in res.items():
    print(b, "ratios", " ".join(f"{x:.3f}" for x in v), "median", f"{statistics.median(v):.3f}")
