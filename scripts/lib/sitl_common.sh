# Shared start-up of scripts/sitl_ardupilot.sh and scripts/sitl_px4.sh; sourced, never run. The caller
# has cd'ed to the checkout root and set ROOT to it.

# fail MESSAGE: the calling script's name and MESSAGE on stderr, exit 2 (the refusal the tests check).
fail() { echo "${0##*/}: $*" >&2; exit 2; }

# What a SITL run needs: the python venv of sitl_tests (created on first use) and the companion binary
# (COMPANION_BIN, or a debug build with cargo), exported as COMPANION_BIN for the tests.
sitl_venv_and_companion() {
  if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
    .venv/bin/pip install --quiet --disable-pip-version-check -r sitl_tests/requirements.txt
  fi
  if [ -z "${COMPANION_BIN:-}" ]; then
    cargo build --quiet --bin companion
    COMPANION_BIN="${CARGO_TARGET_DIR:-$ROOT/target}/debug/companion"
  fi
  export COMPANION_BIN
}
