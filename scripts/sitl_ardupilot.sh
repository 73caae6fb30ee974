#!/usr/bin/env bash
# Fly the companion against a real ArduCopter SITL, headless and without MAVProxy: first the default
# mission on one vehicle, then the real-autopilot tests (sitl_tests/test_real_*.py), each on a fresh
# vehicle of its own (own working directory, own -I instance, -w), several side by side.
#
#   ARDUPILOT_DIR=~/ardupilot scripts/sitl_ardupilot.sh      # a built tree: ./waf configure --board sitl && ./waf copter
#   ARDUCOPTER_BIN=/path/to/arducopter SITL_DEFAULTS=/path/to/copter.parm scripts/sitl_ardupilot.sh
#
# The arducopter flags are the SITL binary's own (libraries/AP_HAL_SITL/SITL_cmdline.cpp: --model,
# --speedup, --defaults, -I/--instance, --home lat,lng,alt,yaw, -w/--wipe), the ones
# Tools/autotest/sim_vehicle.py passes for `-v ArduCopter -f quad` with --no-mavproxy. Ports (instance N):
# SERIAL0 tcp 5760+10N (SITL waits for a client there before it runs), SERIAL1 tcp 5762+10N (the
# companion), SERIAL2 tcp 5763+10N (the onboard-monitor test client).
#
# Everything runs in its own network namespace (unshare -n, loopback only) when that is possible (root),
# so no SITL port is reachable from outside and nothing collides with other SITLs on the machine.
#
# Environment:
#   ARDUPILOT_DIR / ARDUCOPTER_BIN   where ArduCopter SITL is (one of them is required)
#   SITL_DEFAULTS     defaults file     (default $ARDUPILOT_DIR/Tools/autotest/default_params/copter.parm)
#   SITL_SPEEDUP      SIM speedup of the default-mission flight (default 1)
#   SITL_BATT_CAPACITY  the pack of the default-mission flight, mAh (default 12000: see docs/guarantee.md)
#   SITL_HOME         lat,lng,alt,yaw   (default CMAC, -35.363261,149.165230,584,353)
#   SITL_FLY_TIMEOUT  seconds for the default-mission flight (default 600)
#   SITL_WORKERS      vehicles flown side by side by the tests (pytest-xdist workers, default 4)
#   SITL_PYTEST_ARGS  extra pytest arguments (default none)
#   SITL_KEEP_RUNS    copy the default flight's run folder (records, tlog) there, for `companion calibrate`
#   SITL_DEFAULT_ONLY fly the default mission only, no tests (with SITL_KEEP_RUNS: a profile flight)
#   COMPANION_BIN     the companion binary (default: built with cargo)
set -euo pipefail
SELF=$(realpath "$0")
cd "$(dirname "$0")/.."
ROOT=$PWD

# shellcheck source=lib/sitl_common.sh
. "$ROOT/scripts/lib/sitl_common.sh"

# ---- find ArduCopter SITL (fail fast, before building or starting anything) ----------------------
BIN=${ARDUCOPTER_BIN:-}
if [ -z "$BIN" ]; then
  [ -n "${ARDUPILOT_DIR:-}" ] || fail "no ArduPilot: set ARDUPILOT_DIR to a built ArduPilot tree (./waf configure --board sitl && ./waf copter) or ARDUCOPTER_BIN to an arducopter SITL binary. See docs/sitl.md."
  [ -d "$ARDUPILOT_DIR" ] || fail "ARDUPILOT_DIR=$ARDUPILOT_DIR is not a directory"
  BIN=$ARDUPILOT_DIR/build/sitl/bin/arducopter
fi
[ -f "$BIN" ] || fail "no arducopter SITL binary at $BIN (build it: cd \$ARDUPILOT_DIR && ./waf configure --board sitl && ./waf copter)"
[ -x "$BIN" ] || fail "$BIN is not executable"
DEFAULTS=${SITL_DEFAULTS:-}
if [ -z "$DEFAULTS" ]; then
  [ -n "${ARDUPILOT_DIR:-}" ] || fail "set SITL_DEFAULTS to ArduPilot's Tools/autotest/default_params/copter.parm (or ARDUPILOT_DIR)"
  DEFAULTS=$ARDUPILOT_DIR/Tools/autotest/default_params/copter.parm
fi
[ -f "$DEFAULTS" ] || fail "no defaults file at $DEFAULTS"
BIN=$(realpath "$BIN")
DEFAULTS=$(realpath "$DEFAULTS")

# ---- its own network namespace (loopback only) ----------------------------------------------------
if [ -z "${SITL_NETNS:-}" ]; then
  if [ "$(id -u)" = 0 ] && command -v unshare >/dev/null && unshare -n true 2>/dev/null; then
    export SITL_NETNS=1 ARDUCOPTER_BIN=$BIN SITL_DEFAULTS=$DEFAULTS
    exec unshare -n bash -c 'ip link set lo up && exec "$0" "$@"' "$SELF" "$@"
  fi
  echo "sitl_ardupilot.sh: note: no network namespace (needs root and unshare): SITL ports listen on all addresses of this machine" >&2
fi

for port in 5760 5762 5763; do
  if ss -ltn "sport = :$port" 2>/dev/null | grep -q LISTEN; then
    fail "tcp port $port is already in use (another SITL or MAVProxy?); stop it first"
  fi
done

# ---- what the run needs: python venv, companion binary --------------------------------------------
sitl_venv_and_companion

WORK=$(mktemp -d "${TMPDIR:-/tmp}/sitl-ardupilot.XXXXXX")
SITL_PID=""
KEEPER_PID=""
cleanup() {
  [ -n "$KEEPER_PID" ] && kill "$KEEPER_PID" 2>/dev/null || true
  [ -n "$SITL_PID" ] && kill "$SITL_PID" 2>/dev/null || true
  wait 2>/dev/null || true
  KEEPER_PID="" SITL_PID=""
  echo "SITL log and runs: $WORK"
}
trap cleanup EXIT

wait_listen() { # port seconds
  local i
  for ((i = 0; i < $2 * 10; i++)); do
    ss -ltn "sport = :$1" 2>/dev/null | grep -q LISTEN && return 0
    kill -0 "$SITL_PID" 2>/dev/null || fail "arducopter exited; see $WORK/arducopter.log"
    sleep 0.1
  done
  fail "nothing listens on tcp $1 after $2 s; see $WORK/arducopter.log"
}

# ---- start SITL (its eeprom.bin and logs go to the work dir; -w starts from the defaults) -----------
echo "== arducopter SITL: $BIN"
# The pack the tests' fixture flies (sitl_tests/conftest.py ARDUCOPTER_PACK): the companion reckons its energy goal
# from BATT_CAPACITY, and SITL's default 3300 mAh does not hold the default mission (docs/guarantee.md).
echo "BATT_CAPACITY ${SITL_BATT_CAPACITY:-12000}" >"$WORK/pack.parm"
(cd "$WORK" && exec "$BIN" --model + --speedup "${SITL_SPEEDUP:-1}" --defaults "$DEFAULTS,$WORK/pack.parm" -I0 \
  --home "${SITL_HOME:--35.363261,149.165230,584,353}" -w >"$WORK/arducopter.log" 2>&1) &
SITL_PID=$!
wait_listen 5760 60
# SERIAL0 holds the start-up until a client connects: a quiet ground station keeps it (1 Hz heartbeat).
.venv/bin/python - <<'EOF' >"$WORK/keeper.log" 2>&1 &
import time
from pymavlink import mavutil
m = mavutil.mavlink_connection("tcp:127.0.0.1:5760", source_system=254, source_component=190)
while True:
    m.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    m.recv_match(blocking=True, timeout=1.0)
    time.sleep(0.5)
EOF
KEEPER_PID=$!
wait_listen 5762 60
wait_listen 5763 60

# ---- the default mission (no onboard monitors: the target search ends at its time limit) -----------
echo "== companion fly --connect tcp:127.0.0.1:5762 (default mission)"
set +e
timeout "${SITL_FLY_TIMEOUT:-600}" "$COMPANION_BIN" fly --connect tcp:127.0.0.1:5762 --auto-start --once --log-dir "$WORK/runs"
fly_rc=$?
set -e
[ "$fly_rc" -eq 0 ] || fail "companion fly exited $fly_rc (run folder under $WORK/runs)"

# The default flight's run folder kept for `companion calibrate` (docs/calibrate.md: the vehicle profiles)
if [ -n "${SITL_KEEP_RUNS:-}" ]; then
  mkdir -p "$SITL_KEEP_RUNS" && cp -r "$WORK/runs/." "$SITL_KEEP_RUNS/"
  echo "== run folder kept in $SITL_KEEP_RUNS"
fi
# this vehicle has flown: the tests each start their own
kill "$KEEPER_PID" "$SITL_PID" 2>/dev/null || true
wait "$KEEPER_PID" "$SITL_PID" 2>/dev/null || true
KEEPER_PID="" SITL_PID=""

# ---- the real-autopilot tests: a fresh vehicle each ------------------------------------------------
if [ -n "${SITL_DEFAULT_ONLY:-}" ]; then echo "== SITL_DEFAULT_ONLY: tests not run"; exit 0; fi
echo "== pytest sitl_tests/test_real_*.py: a fresh ArduCopter SITL per test, ${SITL_WORKERS:-4} side by side"
export ARDUCOPTER_BIN=$BIN SITL_DEFAULTS=$DEFAULTS
# shellcheck disable=SC2086
.venv/bin/python -m pytest -q -n "${SITL_WORKERS:-4}" --durations=12 -p no:cacheprovider sitl_tests/test_real_*.py ${SITL_PYTEST_ARGS:-}
