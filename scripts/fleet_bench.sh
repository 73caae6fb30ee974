#!/usr/bin/env bash
# Benchmark of companion-fleet (docs/performance.md, "Fleet"; outside the test command):
# N generated runs (fly-like decision logs with the power observations calibrate reads, 200
# records each, three activities: two timed per run) ingested, reported and calibrated, and
# `companion calibrate RUN...` on the same runs, side by side; wall time and peak memory (maximum resident set size) from /usr/bin/time -v. Run at 100 and 1000 runs
# to see the memory stay flat:
#   scripts/fleet_bench.sh 100 && scripts/fleet_bench.sh 1000
# PROFILE=release (default) builds the binaries with --release; PROFILE=debug uses target/debug;
# SKIP_BUILD=1 uses the binaries as built.
set -euo pipefail
cd "$(dirname "$0")/.."
N=${1:-1000}
PROFILE=${PROFILE:-release}
if [ -n "${SKIP_BUILD:-}" ]; then
  :   # the binaries are built already
elif [ "$PROFILE" = release ]; then
  cargo build --quiet --release -p companion -p companion-fleet --bins
else
  cargo build --quiet -p companion -p companion-fleet --bins
fi
BIN="${CARGO_TARGET_DIR:-$PWD/target}/$PROFILE"
WORK=$(mktemp -d /tmp/fleet-bench.XXXXXX)
# KEEP=1 keeps the runs and the dataset (their folder is printed) for a closer look.
trap '[ -n "${KEEP:-}" ] && echo "kept: $WORK" || rm -rf "$WORK"' EXIT
python3 - "$WORK/runs" "$N" <<'PY'
import json, math, os, sys
out, n = sys.argv[1], int(sys.argv[2])
def power(v):   # a rotary-wing vehicle (Zeng et al. eq. 12): base 12, P0 95, Pi 230, v0 7.5, CdA 0.08
    ind = math.sqrt(math.sqrt(1 + v**4 / (4 * 7.5**4)) - v * v / (2 * 7.5**2))
    return 12 + 95 * (1 + 3 * v * v / 6400) + 230 * ind + 0.5 * 1.225 * 0.08 * v**3
for k in range(n):
    d = os.path.join(out, f"run{k:05d}")
    os.makedirs(d)
    with open(os.path.join(d, "decisions.jsonl"), "w") as f:
        day = 1 + k % 28
        f.write(json.dumps({"schema": 2, "kind": "header", "started_utc": f"2026-06-{day:02d}T12:00:00Z",
                            "git_revision": f"rev{k % 3}", "command": "companion fly --connect tcp:x",
                            "params": {}, "part": 0,
                            "plan": {"mission": "tracking", "route_file": f"route{k % 4}.plan", "zones_file": None,
                                     "activities": 3, "planned_energy_j": 50000.0,
                                     "planned_duration_s": 200.0}}) + "\n")
        for c in range(200):
            armed = c >= 20
            act = 0 if c < 100 else 1 if c < 150 else 2
            v = 0.0 if not armed else (c % 17) * 1.0
            p = 12.0 if not armed else power(v)
            p += math.sin(k * 7.0 + c) * 2.0
            rec = {"cycle": c, "time_s": float(c),
                   "observations": {"battery_v": 15.0, "battery_current_a": p / 15.0, "armed": 1.0 if armed else 0.0,
                                    "groundspeed_mps": v, "altitude_m": 30.0 if armed else 0.0},
                   "actions": ["follow_trajectory"] if armed else [],
                   "commands": [{"action": "take_off", "command": "MAV_CMD_NAV_TAKEOFF",
                                 "result": {"kind": w, "text": w}, "attempts": 1}
                                for w in ["TIMEOUT" if (k + c) % 97 == 0 else "ACCEPTED"]] if c % 50 == 0 else [],
                   # three activities, so calibrate times two completed ones per run (durations)
                   "guarantee": {"activity": act, "activity_name": ["transit", "survey", "return"][act],
                                 "goals": {"energy_j": 60000.0},
                                 "margins": {"energy_j": 10000.0 - c}, "planned_j": 50000.0, "planned_s": 200.0}}
            f.write(json.dumps(rec) + "\n")
PY
DS="$WORK/fleet"
TOTAL=0
# One command under /usr/bin/time -v: its wall time (s) and peak RSS (MB); the fleet's three
# commands' times add up to the total the 60 s target is about.
t() {
  /usr/bin/time -v "$@" >"$WORK/out" 2>"$WORK/time" || { echo "FAILED: $*" >&2; tail -5 "$WORK/out" "$WORK/time" >&2; exit 1; }
  python3 - "$WORK/time" <<'PY'
import re, sys
text = open(sys.argv[1]).read()
wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", text).group(1)
secs = 0.0
for part in wall.split(":"):
    secs = secs * 60 + float(part)
rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", text).group(1))
print(f"{secs:.1f} s wall, {rss / 1024:.0f} MB peak RSS")
PY
}
secs() { sed 's/ s wall.*//' <<<"$1"; }
echo "runs: $N ($PROFILE build; $(nproc) cores; load average at start: $(cut -d' ' -f1-3 /proc/loadavg))"
r=$(t "$BIN/companion-fleet" ingest "$WORK/runs" --into "$DS"); echo "  companion-fleet ingest:     $r"; TOTAL=$(python3 -c "print(round($TOTAL + $(secs "$r"), 1))")
r=$(t "$BIN/companion-fleet" report "$DS" --json); echo "  companion-fleet report:     $r"; TOTAL=$(python3 -c "print(round($TOTAL + $(secs "$r"), 1))")
r=$(t "$BIN/companion-fleet" calibrate "$DS" --json); echo "  companion-fleet calibrate:  $r"; TOTAL=$(python3 -c "print(round($TOTAL + $(secs "$r"), 1))")
echo "  companion-fleet total:      $TOTAL s (ingest + report + calibrate)"
echo "  companion calibrate RUN...: $(t "$BIN/companion" calibrate "$WORK/runs")"
echo "  dataset size: $(du -sh "$DS" | cut -f1); load average at end: $(cut -d' ' -f1-3 /proc/loadavg)"
