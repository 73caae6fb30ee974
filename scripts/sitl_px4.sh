#!/usr/bin/env bash
# Fly the companion against a real PX4 SITL (built-in SIH quadrotor, no Gazebo), headless, then run
# the PX4 sitl_tests (marked px4: a fresh PX4 per test, side by side).
#
#   PX4_SITL_DIR=../shared/sitl/px4 scripts/sitl_px4.sh
#   PX4_SITL_DIR=~/PX4-Autopilot/build/px4_sitl_default scripts/sitl_px4.sh   # after `make px4_sitl_default`
#
# PX4_SITL_DIR is a directory with bin/px4 and etc/ (default ../shared/sitl/px4 beside the checkout).
# The vehicle runs as PX4's own `make px4_sitl sihsim_quadx` does: airframe 10040 (sihsim_quadx),
# PX4_SIMULATOR=sihsim, `bin/px4 -d -i N etc`, in a fresh working directory (clean parameters). Ports
# for instance N (etc/init.d-posix/px4-rc.mavlink): PX4 sends the onboard link to udp 14540+N and
# listens for it on 14580+N (the companion listens on 14540+N and answers there); the GCS link is
# udp 18570+N. Everything runs inside its own network namespace (`unshare -n`, loopback up) when
# run as root, so nothing listens beyond it and no port meets another run's.
#
# Environment:
#   PX4_SITL_DIR       the PX4 SITL tree (see above)
#   PX4_INSTANCE       instance for the default flight (default: the first free one in 0-9)
#   PX4_FLY_TIMEOUT    seconds for the default-mission flight (default 900)
#   PX4_SIM_BAT_DRAIN  SIH's battery drain time of the default flight, s (default 1800: the px4-sih profile's)
#   PX4_VEHICLE        the vehicle profile of the default flight (default px4-sih; empty: the params' assumptions)
#   PX4_PYTEST_ARGS    extra pytest arguments (default: -n 2: two PX4 SIH vehicles at a time. SIH runs in real time, not lockstep: with four beside the ArduCopter tests on two cores one lost its baro data on take-off and failsafed, CI of stop 41)
#   SITL_KEEP_RUNS     copy the default flight's run folder (records, tlog) there, for `companion calibrate`
#   SITL_DEFAULT_ONLY  fly the default mission only, no tests (with SITL_KEEP_RUNS: a profile flight)
#   COMPANION_BIN      the companion binary (default: built with cargo)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

# shellcheck source=lib/sitl_common.sh
. "$ROOT/scripts/lib/sitl_common.sh"

# ---- find PX4 SITL (fail fast, before building or starting anything) ------------------------------
PX4_DIR=${PX4_SITL_DIR:-$ROOT/../shared/sitl/px4}
[ -d "$PX4_DIR" ] || fail "no PX4 SITL at $PX4_DIR: set PX4_SITL_DIR to a directory with bin/px4 and etc/ (PX4-Autopilot: git clone --recursive https://github.com/PX4/PX4-Autopilot && cd PX4-Autopilot && make px4_sitl_default, then PX4_SITL_DIR=\$PWD/build/px4_sitl_default). See docs/sitl.md."
[ -x "$PX4_DIR/bin/px4" ] || fail "no executable $PX4_DIR/bin/px4 (build it: make px4_sitl_default in PX4-Autopilot)"
[ -d "$PX4_DIR/etc" ] || fail "no $PX4_DIR/etc (PX4's start-up scripts and airframes)"
export PX4_SITL_DIR
PX4_SITL_DIR=$(cd "$PX4_DIR" && pwd)

# ---- what the run needs: python venv, companion binary ---------------------------------------------
sitl_venv_and_companion

# ---- into a private network namespace (re-run this script there once) ------------------------------
if [ -z "${SITL_PX4_IN_NETNS:-}" ] && [ "$(id -u)" = 0 ] && command -v unshare >/dev/null; then
  exec env SITL_PX4_IN_NETNS=1 unshare -n bash -c 'ip link set lo up && exec "$0" "$@"' "$0" "$@"
fi

WORK=$(mktemp -d "${TMPDIR:-/tmp}/sitl-px4.XXXXXX")
PX4_PID=""
cleanup() {
  [ -n "$PX4_PID" ] && kill "$PX4_PID" 2>/dev/null || true
  wait 2>/dev/null || true
  echo "PX4 log and runs: $WORK"
}
trap cleanup EXIT

# A runnable tree (bin/px4-* command links) and a free instance, the same way the tests get theirs.
read -r TREE INST < <(.venv/bin/python - <<'EOF'
import os, sys
sys.path.insert(0, "sitl_tests")
from pathlib import Path
from px4_sitl import InstanceLock, runnable_tree
tree = runnable_tree(Path(os.environ["PX4_SITL_DIR"]))
want = os.environ.get("PX4_INSTANCE")
n = int(want) if want else InstanceLock()._free()
print(tree, n)
EOF
)

# ---- start PX4 SIH (clean parameters in a fresh working directory) ---------------------------------
echo "== PX4 SITL (SIH quadrotor) instance $INST from $PX4_SITL_DIR"
mkdir -p "$WORK/px4"
(cd "$WORK/px4" && exec env PX4_SIMULATOR=sihsim PX4_SYS_AUTOSTART=10040 PX4_SIM_MODEL=sihsim_quadx HEADLESS=1 \
  PX4_PARAM_SIM_BAT_DRAIN="${PX4_SIM_BAT_DRAIN:-1800}" PATH="$TREE/bin:$PATH" \
  "$TREE/bin/px4" -d -i "$INST" "$TREE/etc" >"$WORK/px4.log" 2>&1 </dev/null) &
PX4_PID=$!
for _ in $(seq 1 300); do
  grep -q "Startup script returned successfully" "$WORK/px4.log" 2>/dev/null && break
  kill -0 "$PX4_PID" 2>/dev/null || fail "px4 exited; see $WORK/px4.log"
  sleep 0.1
done
grep -q "Startup script returned successfully" "$WORK/px4.log" || fail "PX4 did not start in 30 s; see $WORK/px4.log"

# ---- the default mission (no onboard monitors: the target search ends at its time limit) -----------
PORT=$((14540 + INST))
ONCE=""
"$COMPANION_BIN" fly --help 2>/dev/null | grep -q -- "--once" && ONCE="--once"
# The vehicle profile (params/vehicles/, docs/calibrate.md) the default mission flies with; PX4_VEHICLE= flies the
# params' assumptions. SIH's battery drains over SIM_BAT_DRAIN whatever the vehicle does: the profile was made at 1800 s.
VEHICLE=()
PROFILE=${PX4_VEHICLE-px4-sih}
# The profile was fitted on the typed activities (test_px4_profile.py compares them): the legacy plan, explicitly.
[ -n "$PROFILE" ] && VEHICLE=(--vehicle "$PROFILE" --legacy-plan)
echo "== companion fly --connect udpin:127.0.0.1:$PORT --auto-start $ONCE ${VEHICLE[*]} (default mission)"
set +e
timeout "${PX4_FLY_TIMEOUT:-900}" "$COMPANION_BIN" fly --connect "udpin:127.0.0.1:$PORT" --auto-start $ONCE \
  --log-dir "$WORK/runs" "${VEHICLE[@]}"
fly_rc=$?
set -e
[ "$fly_rc" -eq 0 ] || fail "companion fly exited $fly_rc (run folder under $WORK/runs, PX4 log $WORK/px4.log)"
# Landed and disarmed as PX4 itself logs it.
grep -q "Disarmed by landing\|Disarmed by auto preflight disarming\|Disarmed by land" "$WORK/px4.log" \
  || fail "PX4 did not report a disarm after landing; see $WORK/px4.log"
grep -q "Takeoff detected" "$WORK/px4.log" || fail "PX4 never took off; see $WORK/px4.log"
echo "== default mission flown: PX4 reports take-off, landing and disarm"
# The default flight's run folder kept for `companion calibrate` (docs/calibrate.md: the vehicle profiles)
if [ -n "${SITL_KEEP_RUNS:-}" ]; then
  mkdir -p "$SITL_KEEP_RUNS" && cp -r "$WORK/runs/." "$SITL_KEEP_RUNS/"
  echo "== run folder kept in $SITL_KEEP_RUNS"
fi
kill "$PX4_PID" 2>/dev/null || true
wait "$PX4_PID" 2>/dev/null || true
PX4_PID=""

# ---- the PX4 sitl_tests (a fresh vehicle each, side by side) --------------------------------------
if [ -n "${SITL_DEFAULT_ONLY:-}" ]; then echo "== SITL_DEFAULT_ONLY: tests not run"; exit 0; fi
echo "== pytest sitl_tests -m px4"
# shellcheck disable=SC2086
# the default flight's run, for test_px4_profile.py (the profile's prediction against what SIH reported)
export PX4_DEFAULT_RUN="$WORK/runs"
.venv/bin/python -m pytest -q --durations=8 -p no:cacheprovider sitl_tests/test_px4_flight.py sitl_tests/test_px4_profile.py sitl_tests/test_px4_autopilot_mission.py sitl_tests/test_px4_planned_flown.py -m px4 ${PX4_PYTEST_ARGS:--n 2}
