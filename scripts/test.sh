#!/usr/bin/env bash
# The full test suite, from a fresh machine. It only adds to the machine: what is missing is installed
# (Debian's chromium for the review report test with --no-upgrade --no-install-recommends; pytest and
# pymavlink into the project's own .venv), nothing already there is upgraded. Then the Rust tests, the
# SITL tests against the stand-in, the real-autopilot tests (when an ArduCopter SITL or PX4 SITL is found:
# ARDUCOPTER_BIN/SITL_DEFAULTS and PX4_SITL_DIR, or ../shared/sitl/ beside the checkout), and the armv7 build.
# One progress line per stage with its elapsed time. The armv7 stage and the companion-fleet stage
# (scripts/fleet_tests.sh: DataFusion's build is most of the workspace's) run side by side in the
# background beside the stand-in and real-autopilot stages (niced: the flights keep their CPU), and
# report after them.
#
#   SKIP_ARM=1        skip the armv7 cross-build and qemu run
#   SKIP_FLEET=1      skip the companion-fleet stage
#   SKIP_REAL_SITL=1  skip the real-autopilot stage
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
STAGES=8
T_ALL=$SECONDS

fmt() { printf '%dm%02ds' $(($1 / 60)) $(($1 % 60)); }
stage_n=0
stage_name=""
stage_t=0
begin() { stage_n=$((stage_n + 1)); stage_name=$1; stage_t=$SECONDS; echo "== [$stage_n/$STAGES] $stage_name ..."; }
done_() { echo "== [$stage_n/$STAGES] $stage_name ... ${1:-ok} in $(fmt $((SECONDS - stage_t)))"; }
# The real-SITL scripts run in process groups of their own (setsid): stopped with this script.
ardu_pid=""
px4_pid=""
arm_pid=""
fleet_pid=""
stop_bg() { for p in $ardu_pid $px4_pid $arm_pid $fleet_pid; do kill -TERM -- "-$p" 2>/dev/null || true; done; }
trap 'rc=$?; stop_bg; [ $rc -ne 0 ] && echo "== [$stage_n/$STAGES] $stage_name ... FAILED (exit $rc) after $(fmt $((SECONDS - stage_t)))"; exit $rc' EXIT

SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"

# ---- 1: system packages, only those missing -------------------------------------------------------
begin "system: packages the tests need (only missing ones, nothing upgraded)"
if ! command -v chromium >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1; then
    $SUDO apt-get update -q >/dev/null
    $SUDO apt-get install -y -q --no-upgrade --no-install-recommends chromium >/dev/null
  else
    echo "chromium is missing and apt-get is unavailable: install Debian's chromium (or put a chromium on PATH) to run sitl_tests/test_review_report.py" >&2
    exit 1
  fi
  done_ "installed chromium"
else
  done_ "nothing missing"
fi

# ---- 2: python venv (pip installs into .venv only) ------------------------------------------------
begin "python: sitl_tests venv"
[ -x .venv/bin/python ] || python3 -m venv .venv
if .venv/bin/python - <<'EOF' 2>/dev/null
import importlib.metadata as md, re, sys
for line in open("sitl_tests/requirements.txt"):
    name = re.split(r"[<>=!~ \[]", line.strip())[0]
    if name:
        md.version(name)          # raises when missing
EOF
then
  done_ "nothing missing"
else
  .venv/bin/pip install --quiet --disable-pip-version-check -r sitl_tests/requirements.txt
  done_ "installed sitl_tests/requirements.txt into .venv"
fi

# ---- 3: rust ----------------------------------------------------------------------------------------
# companion-fleet is built and tested in its own stage (8), in the background beside stage 6.
# No shipped function over 150 lines (clippy.toml's too-many-lines-threshold): clippy-driver lints
# the workspace's libraries and binaries while they compile for the tests (scripts/lib/lint_wrapper.sh,
# as cargo's RUSTC_WORKSPACE_WRAPPER for every later build too, so none compiles them again); only that
# lint (the others are advice, not a gate); the testkit is test support, not shipped.
lint_note="functions over 150 lines NOT checked (no clippy-driver: rustup component add clippy)"
if clippy-driver --version >/dev/null 2>&1; then
  export RUSTC_WORKSPACE_WRAPPER="$ROOT/scripts/lib/lint_wrapper.sh"
  lint_note="shipped code linted for clippy::too_many_lines as it compiled"
  # A RUSTC_WRAPPER (sccache) would be handed the lint wrapper as its compiler, which it refuses.
  if [ -n "${RUSTC_WRAPPER:-}" ]; then
    echo "   RUSTC_WRAPPER=$RUSTC_WRAPPER unset for this run (it cannot wrap the lint wrapper)"
    unset RUSTC_WRAPPER
  fi
fi
begin "rust: cargo test (workspace, companion-fleet in stage 8; shipped code linted as it compiles)"
cargo test --workspace --exclude companion-fleet --quiet 2>&1
done_ "ok ($lint_note)"

# ---- 4: the companion binary the python tests fly ---------------------------------------------------
begin "build: companion binary (and the testkit's tlog sample writer) for sitl_tests"
cargo build --quiet -p companion -p companion-testkit --bins
export COMPANION_BIN="${CARGO_TARGET_DIR:-$ROOT/target}/debug/companion"
done_

# ---- in the background: the armv7 stage (7) and the fleet stage (8), side by side ----------------
# The armv7 cross-build and its qemu run, and companion-fleet's build and tests, start here, side by
# side at nice 19, beside the stand-in tests (5) and the real-SITL flights (6); nice keeps the tests',
# vehicles' and the companion's CPU theirs. Side by side, not in a chain: the armv7 part's qemu run
# is mostly one test binary on one core at a time, and the flights leave the rest idle (a chain of
# the two ended 13 min after stage 6 in stop 48's rehearsal, 88 % of both cores used over the run);
# their builds do not wait for each other (the armv7 release build locks target/release and
# target/armv7-*, the fleet's debug build target/debug). Stages 7 and 8 wait for their part and
# print its log. Each part's exit code goes to LOG.rc (written whole: renamed into place). The armv7
# builds are not linted again (the code is stage 3's); the fleet's build reuses stage 3's crates and
# lints the fleet's own code.
arm_log=$(mktemp "${TMPDIR:-/tmp}/arm-log.XXXXXX")
fleet_log=$(mktemp "${TMPDIR:-/tmp}/fleet-log.XXXXXX")
rm -f "$arm_log.rc" "$fleet_log.rc"
# part SKIP LOG CMD...: CMD's output to LOG, its exit code (0 when skipped) to LOG.rc
part() {
  local skip=$1 log=$2; shift 2
  setsid nice -n 19 bash -c '
    skip=$1 log=$2; shift 2
    rc=0; if [ "$skip" != 1 ]; then "$@" >"$log" 2>&1 || rc=$?; fi; echo "$rc" >"$log.rc.tmp"; mv "$log.rc.tmp" "$log.rc"
  ' background-part "$skip" "$log" "$@" &
}
part "${SKIP_ARM:-0}" "$arm_log" env -u RUSTC_WORKSPACE_WRAPPER ./scripts/arm.sh
arm_pid=$!
part "${SKIP_FLEET:-0}" "$fleet_log" ./scripts/fleet_tests.sh
fleet_pid=$!

# ---- 5: sitl_tests against the stand-in ------------------------------------------------------------
begin "python: pytest sitl_tests (stand-in)"
set +e
.venv/bin/python -m pytest -q -n 4 --durations=12 sitl_tests -m "not real_autopilot" --ignore-glob='sitl_tests/test_px4_*.py' \
  --ignore=sitl_tests/test_fleet.py
rc=$?
set -e
# pytest exits 5 when it collected nothing; that is a failure of the suite, not a pass.
[ "$rc" -eq 0 ] || exit "$rc"
done_

# ---- 6: real autopilots, ArduCopter and PX4 side by side -------------------------------------------
# Each script runs its vehicles in its own network namespace (ports cannot collide) and each vehicle
# uses a few % of a core, so the two run at once; their output goes to a log each, printed after.
begin "real autopilots: ArduCopter and PX4 SITL tests (side by side; the armv7 and fleet stages beside them)"
ardu_summary="ArduCopter: not run"
px4_summary="PX4: not run"
ARDUCOPTER_BIN=${ARDUCOPTER_BIN:-$ROOT/../shared/sitl/ardupilot/arducopter}
SITL_DEFAULTS=${SITL_DEFAULTS:-$(dirname "$ARDUCOPTER_BIN")/copter.parm}
PX4_SITL_DIR=${PX4_SITL_DIR:-$ROOT/../shared/sitl/px4}
ardu_pid=""
px4_pid=""
ardu_log=$(mktemp "${TMPDIR:-/tmp}/sitl-ardupilot-log.XXXXXX")
px4_log=$(mktemp "${TMPDIR:-/tmp}/sitl-px4-log.XXXXXX")
if [ "${SKIP_REAL_SITL:-0}" = 1 ]; then
  ardu_summary="ArduCopter: skipped (SKIP_REAL_SITL=1)"
  px4_summary="PX4: skipped (SKIP_REAL_SITL=1)"
else
  if [ -x "$ARDUCOPTER_BIN" ] && [ -f "$SITL_DEFAULTS" ]; then
    # the default-mission flight judges only "exit 0, landed, disarmed": 3x physics is enough for it
    ARDUCOPTER_BIN=$ARDUCOPTER_BIN SITL_DEFAULTS=$SITL_DEFAULTS SITL_SPEEDUP=${SITL_SPEEDUP:-3} \
      setsid ./scripts/sitl_ardupilot.sh >"$ardu_log" 2>&1 &
    ardu_pid=$!
    echo "   ArduCopter SITL: scripts/sitl_ardupilot.sh started (log $ardu_log)"
  else
    ardu_summary="ArduCopter: no SITL binary (ARDUCOPTER_BIN or ../shared/sitl/ardupilot/; docs/sitl.md), not run"
    echo "   $ardu_summary"
  fi
  if [ -d "$PX4_SITL_DIR" ] && [ -x scripts/sitl_px4.sh ]; then
    PX4_SITL_DIR=$PX4_SITL_DIR setsid ./scripts/sitl_px4.sh >"$px4_log" 2>&1 &
    px4_pid=$!
    echo "   PX4 SITL: scripts/sitl_px4.sh started (log $px4_log)"
  else
    px4_summary="PX4: no SITL (PX4_SITL_DIR or ../shared/sitl/px4; docs/sitl.md), not run"
    echo "   $px4_summary"
  fi
fi
# a line a minute while they fly, so the stage is never silent for long
alive() { [ -n "$1" ] && kill -0 "$1" 2>/dev/null; }
next_line=60
while alive "$ardu_pid" || alive "$px4_pid"; do
  sleep 5
  if [ $((SECONDS - stage_t)) -ge "$next_line" ]; then
    next_line=$((next_line + 60))
    running=""
    if alive "$ardu_pid"; then running="$running ArduCopter"; fi
    if alive "$px4_pid"; then running="$running PX4"; fi
    if alive "$arm_pid"; then running="$running (armv7 stage running)"; fi
    if alive "$fleet_pid"; then running="$running (fleet stage running)"; fi
    echo "   ... $(fmt $((SECONDS - stage_t))): still flying:$running"
  fi
done
counts() { { grep -E '^[0-9]+ (passed|failed|skipped|errors?|deselected|xfailed)' "$1" || true; } | tail -1 | sed 's/=//g; s/^ *//; s/ in [0-9.]*s.*$//'; }
real_rc=0
if [ -n "$ardu_pid" ]; then
  set +e; wait "$ardu_pid"; rc=$?; set -e
  echo "---- scripts/sitl_ardupilot.sh (exit $rc)"; cat "$ardu_log"
  c=$(counts "$ardu_log")
  ardu_summary="ArduCopter SITL: ${c:-no pytest summary}"
  [ "$rc" -eq 0 ] || real_rc=$rc
fi
if [ -n "$px4_pid" ]; then
  set +e; wait "$px4_pid"; rc=$?; set -e
  echo "---- scripts/sitl_px4.sh (exit $rc)"; cat "$px4_log"
  c=$(counts "$px4_log")
  px4_summary="PX4 SITL: ${c:-no pytest summary}"
  [ "$rc" -eq 0 ] || real_rc=$rc
fi
rm -f "$ardu_log" "$px4_log"
[ "$real_rc" -eq 0 ] || { echo "$ardu_summary; $px4_summary" >&2; exit "$real_rc"; }
done_ "ok ($ardu_summary; $px4_summary)"

# ---- 7: the board ------------------------------------------------------------------------------------
# armv7 (the SoCKit's Cortex-A9) release binary, engine and companion tests under qemu-user
# (docs/deploy-arm.md).
# A background part is done when its LOG.rc exists; a part that died without writing it failed.
wait_part() { while [ ! -f "$1.rc" ] && alive "$2"; do sleep 5; done; [ -f "$1.rc" ] && cat "$1.rc" || echo 1; }
begin "arm: scripts/arm.sh (armv7 cross-build, tests under qemu; started before stage 5)"
if [ "${SKIP_ARM:-0}" = 1 ]; then
  done_ "skipped (SKIP_ARM=1)"
else
  rc=$(wait_part "$arm_log" "$arm_pid")
  cat "$arm_log"
  [ "$rc" -eq 0 ] || exit "$rc"
  done_ "ok (waited $(fmt $((SECONDS - stage_t))) after stage 6)"
fi
rm -f "$arm_log" "$arm_log.rc"

# ---- 8: the fleet (ground side) -------------------------------------------------------------------------
# companion-fleet (docs/fleet.md): built, its Rust tests, its too-many-lines check and
# sitl_tests/test_fleet.py, beside the armv7 stage in the background.
begin "fleet: scripts/fleet_tests.sh (companion-fleet build and tests, test_fleet.py; beside stage 7 in the background)"
if [ "${SKIP_FLEET:-0}" = 1 ]; then
  done_ "skipped (SKIP_FLEET=1)"
else
  rc=$(wait_part "$fleet_log" "$fleet_pid")
  cat "$fleet_log"
  [ "$rc" -eq 0 ] || exit "$rc"
  done_ "ok (waited $(fmt $((SECONDS - stage_t))) after stage 7)"
fi
rm -f "$fleet_log" "$fleet_log.rc"
set +e; wait "$arm_pid" "$fleet_pid"; set -e
arm_pid=""
fleet_pid=""

echo "== real autopilots: $ardu_summary; $px4_summary"
echo "== all $STAGES stages passed in $(fmt $((SECONDS - T_ALL)))"
