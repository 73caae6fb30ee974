#!/usr/bin/env bash
# How the BFM-vs-reference ordering of Table 3 moves when the simulated world's QoS values move:
# every value of one hazard context of params/world.toml ([truth.qos.<context>]) shifted by
# -0.1 and +0.1 (clamped to [0, 1]), each scenario run on seeds 1..N with both models.
# Usage: scripts/qos_sweep.sh [N=200]   (needs target/debug/companion: cargo build --bin companion)
set -euo pipefail
cd "$(dirname "$0")/.."
N="${1:-200}"
BIN="${COMPANION_BIN:-target/debug/companion}"
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
run() { # params scenario -> "bfm mean±ci | reference mean±ci"
  "$BIN" simulate --params "$1" --scenario "$2" --model bfm,reference --runs "$N" --seed 1 --no-log 2>&1 \
    | tail -2 | awk '{printf "%s %s±%s  ", $1, $2, $5}'
}
echo "| scenario | context | shift | result (mean ± 95% CI over $N seeds) |"
echo "|---|---|---|---|"
for pair in vibrations:vibrations high-speed:high_speed; do
  scenario="${pair%%:*}"; context="${pair##*:}"
  echo "| $scenario | $context | 0 | $(run params "$scenario") |"
  for shift in -0.1 0.1; do
    rm -rf "$TMP/p"; cp -r params "$TMP/p"
    python3 - "$TMP/p/world.toml" "$context" "$shift" <<'PY'
import re, sys
path, context, shift = sys.argv[1], sys.argv[2], float(sys.argv[3])
lines = open(path).read().split("\n")
inside = False
for i, l in enumerate(lines):
    if l.startswith("["):
        inside = l.strip() == f"[truth.qos.{context}]"
        continue
    m = re.match(r"^(V\d) = ([0-9.]+)$", l)
    if inside and m:
        v = min(1.0, max(0.0, float(m.group(2)) + shift))
        lines[i] = f"{m.group(1)} = {v:.2f}"
open(path, "w").write("\n".join(lines))
PY
    echo "| $scenario | $context | $shift | $(run "$TMP/p" "$scenario") |"
  done
done
