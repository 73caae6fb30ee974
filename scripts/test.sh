#!/usr/bin/env bash
# The full test suite, from a fresh machine: installs what it needs (a Python venv with pytest and
# pymavlink, Debian's chromium for the review report test), then runs the Rust tests and the SITL tests.
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== rust: cargo test (workspace)"
cargo test --workspace --quiet 2>&1

echo "== python: sitl_tests venv"
if [ ! -x .venv/bin/python ]; then
  python3 -m venv .venv
fi
.venv/bin/pip install --quiet --disable-pip-version-check -r sitl_tests/requirements.txt

echo "== system: chromium for the review report test"
if ! command -v chromium >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1; then
    SUDO=""
    if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
    $SUDO apt-get update
    $SUDO apt-get install -y chromium
  else
    echo "chromium is missing and apt-get is unavailable: install Debian's chromium (or put a chromium on PATH) to run sitl_tests/test_review_report.py" >&2
    exit 1
  fi
fi

echo "== build: companion binary for sitl_tests"
cargo build --quiet --bin companion
export COMPANION_BIN="${CARGO_TARGET_DIR:-$PWD/target}/debug/companion"

echo "== python: pytest sitl_tests"
set +e
.venv/bin/python -m pytest -q -n 4 sitl_tests
rc=$?
set -e
# pytest exits 5 when it collected nothing; that is a failure of the suite, not a pass.
[ "$rc" -eq 0 ] || exit "$rc"

# The board: armv7 (the SoCKit's Cortex-A9) release binary, engine and companion tests under
# qemu-user (docs/deploy-arm.md). SKIP_ARM=1 skips it on a developer's quick run.
if [ "${SKIP_ARM:-0}" = 1 ]; then
  echo "== arm: skipped (SKIP_ARM=1)"
else
  echo "== arm: scripts/arm.sh"
  ./scripts/arm.sh
fi
