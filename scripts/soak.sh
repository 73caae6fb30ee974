#!/usr/bin/env bash
# Soak run: a simulated hour of 50 Hz telemetry through the full fly decision cycle,
# live heap and VmRSS sampled after the 5-minute warm-up, every simulated 5 minutes and at the
# end; exits non-zero when the live heap grew by more than the tolerance. Not part of CI: it
# builds in release and takes minutes. Arguments go to the example (see
# companion-testkit/examples/soak.rs), e.g. `scripts/soak.sh --minutes 60 --scenario complete-1`.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}"
cargo build -q --release -p companion-testkit --example soak
start=$(date +%s)
"$CARGO_TARGET_DIR/release/examples/soak" "$@"
echo "soak.sh: wall time $(( $(date +%s) - start )) s" >&2
