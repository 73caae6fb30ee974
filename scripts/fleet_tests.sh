#!/usr/bin/env bash
# companion-fleet's stage of scripts/test.sh (docs/fleet.md): the fleet crate is ground side only
# and its build (DataFusion, Arrow, Parquet) is most of the workspace's, so it is built and tested
# apart from stage 3, in the background at nice 19 beside the real-SITL flights (after the armv7
# stage, in the same chain). Its too-many-lines check (while it compiles), its Rust tests, and
# sitl_tests/test_fleet.py (50 simulated runs and 3 stand-in flights ingested, the report against
# an independent script, pyarrow/DuckDB, SIGKILL mid-ingest). Needs COMPANION_BIN (stage 4's).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
T0=$SECONDS
PYTHON=${PYTHON:-$ROOT/.venv/bin/python}
export COMPANION_BIN=${COMPANION_BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/debug/companion}
step() { echo "-- fleet: $1 ($((SECONDS - T0)) s)"; }
# No shipped function over 150 lines: clippy-driver lints the fleet's library and binary as they
# compile (scripts/lib/lint_wrapper.sh; scripts/test.sh exports it for every build, so the
# workspace crates stage 3 compiled are reused). A separate `cargo clippy` would compile DataFusion
# a second time in check mode (~6 min of CI).
lint="NOT linted (no clippy-driver)"
if clippy-driver --version >/dev/null 2>&1; then
  export RUSTC_WORKSPACE_WRAPPER=${RUSTC_WORKSPACE_WRAPPER:-$ROOT/scripts/lib/lint_wrapper.sh}
  lint="clippy::too_many_lines linted as it compiles"
  unset RUSTC_WRAPPER # sccache would be handed the lint wrapper as its compiler, which it refuses
fi
step "cargo build -p companion-fleet --bins --tests ($lint)"
cargo build --quiet -p companion-fleet --bins --tests 2>&1
step "cargo test -p companion-fleet"
cargo test --quiet -p companion-fleet 2>&1
step "pytest sitl_tests/test_fleet.py"
"$PYTHON" -m pytest -q -n 2 sitl_tests/test_fleet.py
step "done"
