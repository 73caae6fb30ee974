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

echo "== build: companion binary for sitl_tests"
cargo build --quiet --bin companion
export COMPANION_BIN="$PWD/target/debug/companion"

echo "== python: pytest sitl_tests"
set +e
.venv/bin/python -m pytest -q sitl_tests
rc=$?
set -e
# pytest exits 5 when it collected nothing; that is a failure of the suite, not a pass.
exit $rc
