"""The operator in command and a flight never left half done, against the stand-in ArduCopter.

* Without `--auto-start` the companion commands no motion: the vehicle stays disarmed, the companion keeps running
  and tells the ground station it is waiting (STATUSTEXT from component 191).
* The operator starts the mission by arming the vehicle from a ground station, or by sending MAV_CMD_MISSION_START to
  component 191; a pilot's mode change (LOITER) stops the companion's commands until control is handed back.
* One spoofed "disarmed" HEARTBEAT at altitude neither ends `fly` nor the flight.
* An obstacle during the landing: the companion sidesteps, then lands again, and the vehicle ends landed and disarmed.
* "Land at the found zone" flies to the zone (within params/link.toml `zone_radius_m`) before LAND.
* Against real ArduCopter SITL (skipped when the binary is absent): without `--auto-start` the vehicle stays disarmed
  and the STATUSTEXT reaches a GCS client on the second port.
"""
from __future__ import annotations

import math
import sys
import os
import shutil
import socket
import subprocess
import time
from pathlib import Path
from typing import Any, List, Optional

import pytest

from helpers import GcsClient, joined_statustexts
from standin import MODES, mavlink

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]

COMPANION = 191
MOTION_TYPES = {"COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT",
                "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "SET_POSITION_TARGET_GLOBAL_INT",
                "SET_POSITION_TARGET_LOCAL_NED"}
# Stream requests are not motion: the companion keeps asking for telemetry while it waits.
STREAM_COMMANDS = {mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE}
# params/link.toml [flight] zone_radius_m
ZONE_RADIUS_M = 3.0


def motion_from_companion(sa: Any, since_wall: float = 0.0) -> List[Any]:
    """Vehicle commands the stand-in received from the companion (component 191) after `since_wall`, streams
    excluded."""
    out = []
    for e in sa.received(include_dropped=True):
        d = e.data
        if e.wall < since_wall or d["src"][1] != COMPANION or d["type"] not in MOTION_TYPES:
            continue
        if d["type"] in ("COMMAND_LONG", "COMMAND_INT") and d["fields"].get("command") in STREAM_COMMANDS:
            continue
        out.append(e)
    return out


def short_route(tmp_path: Path, search_s: float = 4.0) -> Path:
    """One waypoint 30 m north at 20 m; the search at it ends after `search_s` (autopilot clock), then the
    mission lands."""
    p = tmp_path / "short_route.toml"
    p.write_text(f"altitude_m = 20.0\nsearch_time_limit_s = {search_s}\ntracking_time_limit_s = 20.0\n"
                 "takeoff_first = true\n[[waypoint]]\nnorth_m = 30.0\neast_m = 0.0\n")
    return p


def wait(pred, timeout: float, what: str, run: Any = None, poll: float = 0.05) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return
        if run is not None and run.proc.poll() is not None:
            raise AssertionError(f"companion exited ({run.proc.returncode}) while waiting for {what}\n{run.output()}")
        time.sleep(poll)
    raise AssertionError(f"timed out after {timeout}s waiting for {what}" + (f"\n{run.output()}" if run else ""))


def statustexts_from_companion(gcs: GcsClient, since: float = 0.0) -> List[str]:
    """Chunks joined: one text each, as the ground station shows it."""
    return joined_statustexts(gcs.since(since, "STATUSTEXT"), COMPANION)


def events(records: List[dict]) -> List[str]:
    return [e for r in records for e in r.get("events", [])]


def stop(run: Any) -> None:
    run.proc.terminate()
    run.proc.wait(timeout=15)


# ------------------------------------------------------------------------------------------------------------------

def test_without_auto_start_the_vehicle_stays_disarmed_and_the_companion_waits(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, auto_start=False)
    # The position estimate is ready after 8 s simulated (2 s wall): give the companion three times as long as it
    # needed with --auto-start to arm.
    wait(lambda: sa.state()["position_ok"], 30, "the stand-in's position estimate", run)
    wait(lambda: any(e.data["src"][1] == COMPANION for e in sa.received("HEARTBEAT")), 20, "the companion", run)
    # A ground station heard for a moment, then silent (more than 5 s).
    for _ in range(3):
        gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
        time.sleep(0.5)
    time.sleep(8.0)
    assert run.proc.poll() is None, "fly exited while waiting for the operator\n" + run.output()
    assert not sa.rec.of("arm"), "armed without the operator"
    assert not sa.state()["armed"]
    assert not motion_from_companion(sa), [e.data for e in motion_from_companion(sa)]
    texts = statustexts_from_companion(gcs)
    assert any("waiting for the operator" in t for t in texts), texts
    # Rate-limited: one reminder per statustext_repeat_s (15 s), not one per cycle.
    assert sum("waiting for the operator" in t for t in texts) <= 2, texts
    # The one GCS heartbeat sent at the start went silent: the companion says so (to whoever still hears); its
    # timeout is 5 s plus a cycle, so on a loaded machine the words may come after the 8 s above: wait for them.
    wait(lambda: any("link to the ground station lost" in t for t in statustexts_from_companion(gcs)), 10,
         "the STATUSTEXT 'link to the ground station lost'", run)
    stop(run)
    records = run.records()
    assert records and all(r.get("vehicle", {}).get("operator") == "waiting" for r in records[-3:])
    assert all(isinstance(r.get("utc_us"), int) and r["utc_us"] > 1.6e15 for r in records)
    # The journal view: plain lines (stderr is a file here, not a terminal), the wait said there too.
    err = run.stderr_path.read_text()
    assert "\x1b[" not in err, err[:500]
    assert "waiting for the operator" in err, err[:2000]


def test_a_heartbeat_flood_alternating_modes_is_coalesced_into_rate_limited_cycles(autopilot_factory, fly):
    ap = autopilot_factory()
    sa = ap.standin
    run = fly(ap, auto_start=False)
    wait(lambda: any(e.data["src"][1] == COMPANION for e in sa.received("HEARTBEAT")), 20, "the companion", run)
    time.sleep(2.0)
    hb = [mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, MODES[m],
                                            mavlink.MAV_STATE_STANDBY, 3) for m in ("AUTO", "GUIDED")]
    sent = 0
    t0 = time.monotonic()
    while time.monotonic() - t0 < 4.0:
        for m in hb:
            sa.inject_unsigned(m)
            sent += 1
        time.sleep(0.002)
    flood_s = time.monotonic() - t0
    time.sleep(1.0)
    stop(run)
    records = run.records()
    mode_events = [r for r in records if any(e.startswith("mode ") for e in r.get("events", []))]
    # params/link.toml: min_event_cycle_interval_s 0.2 and decision_period_s 1: at most 5 + 1 cycles a second.
    bound = (flood_s + 1.0) * (1 / 0.2 + 1) + 2
    print(f"heartbeat flood: {sent} heartbeats in {flood_s:.1f} s -> {len(mode_events)} cycles with mode events, "
          f"{len(records)} records in all")
    assert sent > 500, sent
    assert len(mode_events) <= bound, f"{len(mode_events)} cycles with mode events for {sent} heartbeats in {flood_s:.1f} s"
    assert all(len(r.get("events", [])) <= 65 for r in records)


def test_bad_params_stop_fly_before_any_run_folder(tmp_path):
    params = tmp_path / "params"
    shutil.copytree(Path(__file__).parent.parent / "params", params)
    link = params / "link.toml"
    link.write_text(link.read_text().replace("min_event_cycle_interval_s = 0.2", "min_event_cycle_interval_s = -1"))
    runs = tmp_path / "runs"
    out = subprocess.run([os.environ["COMPANION_BIN"], "fly", "--connect", "tcp:127.0.0.1:1", "--params", str(params),
                          "--log-dir", str(runs)], capture_output=True, text=True, timeout=60)
    assert out.returncode != 0
    assert "link.toml" in out.stderr and "min_event_cycle_interval_s" in out.stderr, out.stderr
    assert not runs.exists() or not any(runs.iterdir()), list(runs.iterdir())


def test_pilot_arming_from_the_gcs_starts_the_mission_with_start_on_arm(autopilot_factory, fly, client):
    # speedup 2: ArduCopter disarms an idle armed vehicle after DISARM_DELAY (10 s simulated, 5 s wall here); the
    # companion needs every heartbeat armed over operator_confirm_s (2 s) to take the arming as the pilot's start.
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, auto_start=False, extra=("--start-on-arm",))
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    time.sleep(2.0)
    assert not motion_from_companion(sa)
    t_arm = sa.wall()
    ack = gcs.arm()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
    wait(lambda: sa.state()["alt"] > 5.0, 60, "the take-off after the pilot armed", run)
    cmds = motion_from_companion(sa, t_arm)
    assert cmds, "no command from the companion after the pilot armed"
    assert not motion_from_companion(sa, 0.0)[0].wall < t_arm, "commanded before the operator's start"
    stop(run)
    assert any("mission started (the pilot armed" in e for e in events(run.records())), events(run.records())[:20]


def test_pilot_arming_without_start_on_arm_starts_nothing(autopilot_factory, fly, client):
    # Arming for a manual flight is not a start: the companion commands nothing, the record stays `waiting`.
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, auto_start=False)
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    time.sleep(2.0)
    t_arm = sa.wall()
    ack = gcs.arm()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
    time.sleep(6.0)
    assert not motion_from_companion(sa, t_arm), [e.data for e in motion_from_companion(sa, t_arm)]
    assert sa.state()["alt"] < 1.0, sa.state()
    stop(run)
    assert all(r.get("vehicle", {}).get("operator") == "waiting" for r in run.records()), \
        sorted({r.get("vehicle", {}).get("operator") for r in run.records()})
    assert not any("mission started" in e for e in events(run.records()))


def test_gcs_start_command_to_component_191_starts_the_mission(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, auto_start=False)
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    # The companion must be known on the link before the stand-in routes a command to it (it routes by component).
    wait(lambda: any(COMPANION == c for s, c in [tuple(x) for x in
                     [e.data["src"] for e in sa.received("HEARTBEAT")]]), 10, "the companion's heartbeat", run)
    time.sleep(2.0)
    assert not sa.rec.of("arm")
    t0 = sa.wall()
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED and ack.get_srcComponent() == COMPANION, ack
    # A command the companion does not implement is answered, not ignored.
    ack = gcs.command_long(mavlink.MAV_CMD_DO_SET_SERVO, 1, 1500)
    assert ack.result == mavlink.MAV_RESULT_UNSUPPORTED and ack.get_srcComponent() == COMPANION, ack
    wait(lambda: sa.state()["alt"] > 5.0, 60, "the take-off after MISSION_START", run)
    assert sa.rec.of("arm") and sa.rec.of("arm")[0].wall >= t0
    stop(run)
    assert any("MAV_CMD_MISSION_START" in e for e in events(run.records()))


def test_pilot_takeover_in_loiter_stops_the_companion_until_handed_back(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap)                                          # --auto-start: straight to the mission
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["alt"] > 10.0, 90, "the route in AUTO", run)
    ack = gcs.set_mode("LOITER")
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    t_takeover = sa.wall()
    time.sleep(8.0)
    after = motion_from_companion(sa, t_takeover + 0.3)
    assert not after, f"the companion kept commanding after the pilot took over: {[e.data for e in after]}"
    assert sa.state()["mode"] == "LOITER"
    assert run.proc.poll() is None
    # Handed back with the start command: the companion commands again.
    t_back = sa.wall()
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    wait(lambda: motion_from_companion(sa, t_back), 15, "a command after the hand-back", run)
    stop(run)
    evs = events(run.records())
    assert any("mode LOITER was not commanded by the companion" in e for e in evs), evs[:40]
    assert any("control handed back" in e for e in evs)
    assert any(r.get("vehicle", {}).get("operator") == "taken_over" for r in run.records())


def test_one_spoofed_disarmed_heartbeat_at_altitude_leaves_the_flight_going(autopilot_factory, fly):
    ap = autopilot_factory()
    sa = ap.standin
    run = fly(ap)
    wait(lambda: sa.state()["armed"] and sa.state()["alt"] > 10.0, 90, "the vehicle at 10 m", run)
    mode = MODES[sa.state()["mode"]]
    spoof = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                              mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode,
                                              mavlink.MAV_STATE_STANDBY, 3)
    t_spoof = sa.wall()
    sa.inject_unsigned(spoof)                              # sysid 1 / comp 1, "disarmed"
    time.sleep(8.0)
    assert run.proc.poll() is None, "fly exited after one spoofed heartbeat\n" + run.output()
    s = sa.state()
    assert s["armed"] and s["alt"] > 5.0, s
    landing = [e.data for e in sa.mode_changes() if e.wall >= t_spoof and e.data["new"] in ("LAND", "RTL")]
    assert not landing, f"a spoofed heartbeat made the companion land: {landing}"
    stop(run)
    after = [r for r in run.records() if "disarmed" in r.get("events", [])]
    assert after and all(r["state"] != "landing" for r in after), [(r["state"], r["events"]) for r in after]


def test_obstacle_during_land_ends_landed_and_disarmed(autopilot_factory, fly, tmp_path):
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    run = fly(ap, mission=short_route(tmp_path))
    marks = {}

    def descending() -> bool:
        s = sa.state()
        return s["mode"] in ("LAND", "RTL") and s["armed"] and 8.0 < s["alt"] < 18.5 and sa.v.vd > 0.2

    wait(descending, 180, "the landing descent", run)
    marks["obstacle"] = sa.wall()
    sa.set_param("SIM_OBST_DIST", 6)                       # 6 m ahead, during the landing
    wait(lambda: not sa.state()["armed"] and sa.state()["landed"], 180, "landed and disarmed", run)
    rc = run.wait_exit(30)
    assert rc == 0, run.output()
    assert not sa.rec.of("collision")
    records = run.records()
    t_obs = marks["obstacle"]
    reactions = [e for e in motion_from_companion(sa, t_obs)
                 if e.data["type"] == "COMMAND_INT" and e.data["fields"]["command"] == mavlink.MAV_CMD_DO_REPOSITION]
    assert reactions, "no sidestep during the landing"
    landing_modes = [e.data for e in sa.mode_changes() if e.wall > reactions[0].wall and e.data["new"] in ("LAND", "RTL")]
    assert landing_modes, f"the landing was not resumed after the sidestep: {[e.data for e in sa.mode_changes()]}"
    assert any(e.startswith("landing: ") and "again" in e for e in events(records)), events(records)[-30:]


def test_after_landing_fly_waits_for_the_operator_and_flies_again(autopilot_factory, fly, client, tmp_path):
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap, mission=short_route(tmp_path), once=False)
    wait(lambda: sa.rec.of("arm") and not sa.state()["armed"] and sa.state()["landed"], 240, "the first landing", run)
    t_down = sa.wall()
    time.sleep(6.0)
    assert run.proc.poll() is None, "fly exited after the landing without --once\n" + run.output()
    # the start is taken once the companion has seen the flight over (landed and disarmed, confirmed): wait for it
    wait(lambda: any(e.startswith("flight over: landed and disarmed; waiting for the operator")
                     for e in events(run.records())), 30, "the companion waiting for the operator again", run, poll=0.5)
    assert len(sa.rec.of("arm")) == 1, "--auto-start armed again: it starts the first flight only"
    assert not motion_from_companion(sa, t_down + 4.0), "commanded after the landing without an operator start"
    ack = gcs.start_mission()
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    wait(lambda: len(sa.rec.of("arm")) == 2 and sa.state()["alt"] > 5.0, 90, "the second take-off", run)
    stop(run)
    evs = events(run.records())
    assert any(e.startswith("flight over: landed and disarmed; waiting for the operator") for e in evs), evs[-30:]


def test_land_at_the_found_zone_flies_there_before_land(autopilot_factory, fly, tmp_path):
    from pymavlink import mavutil
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    # The landing-zone monitor (camera component of the vehicle): the zone 40 m north of the drone.
    zone = mavutil.mavlink_connection(sa.url, source_system=1, source_component=mavlink.MAV_COMP_ID_CAMERA,
                                      dialect="ardupilotmega")
    run = fly(ap, mission=short_route(tmp_path))
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and run.proc.poll() is None:
            zone.mav.named_value_float_send(0, b"zone_n", 40.0)
            zone.mav.named_value_float_send(0, b"zone_e", 0.0)
            zone.recv_match(blocking=False)
            if sa.rec.of("arm") and not sa.state()["armed"] and sa.state()["landed"]:
                break
            time.sleep(0.2)
    finally:
        zone.close()
    assert run.wait_exit(30) == 0, run.output()
    goto = [e for e in motion_from_companion(sa)
            if e.data["type"] == "COMMAND_INT" and e.data["fields"]["command"] == mavlink.MAV_CMD_DO_REPOSITION]
    assert goto, "no reposition to the zone"
    f = goto[-1].data["fields"]
    zn, ze = sa._ne_of(f["x"] * 1e-7, f["y"] * 1e-7)
    s = sa.state()
    off = math.hypot(s["north"] - zn, s["east"] - ze)
    assert off <= ZONE_RADIUS_M + 0.5, f"landed {off:.1f} m from the zone ({zn:.1f}, {ze:.1f}); at {s}"
    land = [e for e in sa.mode_changes() if e.data["new"] == "LAND" and e.wall > goto[-1].wall]
    assert land, [e.data for e in sa.mode_changes()]
    cmds = [c for r in run.records() for c in r.get("commands", [])]
    assert any(c["command"] == "ARRIVE (zone)" and c["result"].startswith("ARRIVED") for c in cmds), cmds[-10:]


# ------------------------------------------------------------------------------------------------------------------
# Real ArduCopter SITL (the operator default): skipped unless the binary is there.

# Found as every real-SITL test finds it: ARDUCOPTER_BIN / SITL_DEFAULTS, else ../shared/sitl/ardupilot/.
from real_autopilot import find_arducopter  # noqa: E402

_bin, _defaults, _why_not = find_arducopter()
ARDUCOPTER = str(_bin) if _bin else "/nonexistent/arducopter"
ARDUPILOT_DEFAULTS = str(_defaults) if _defaults else "/nonexistent/copter.parm"


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.mark.skipif(not (os.path.exists(ARDUCOPTER) and shutil.which("unshare")),
                    reason=_why_not or "no unshare here (util-linux) to give the SITL its own network namespace")
def test_real_arducopter_without_auto_start_stays_disarmed_and_says_so(tmp_path):
    """Runs the SITL and the companion inside one fresh network namespace (the script below), then reads the GCS
    client's findings from a JSON file."""
    script = tmp_path / "run.sh"
    result = tmp_path / "result.json"
    here = Path(__file__).parent
    defaults = f"--defaults {ARDUPILOT_DEFAULTS}" if os.path.exists(ARDUPILOT_DEFAULTS) else ""
    script.write_text(f"""set -e
ip link set lo up
cd {tmp_path}
{ARDUCOPTER} --model + --speedup 1 -I0 -w {defaults} --home -35.363261,149.165230,584,353 > sitl.log 2>&1 &
SITL=$!
trap 'kill $SITL $KEEPER $FLY 2>/dev/null || true' EXIT
wait_port() {{ for i in $(seq 1 300); do (exec 3<>/dev/tcp/127.0.0.1/$1) 2>/dev/null && return 0; sleep 0.2; done; return 1; }}
wait_port 5760
# SERIAL0 holds the start-up until a client connects: a quiet ground station keeps it.
{sys.executable} -c "
import time, socket
s = socket.create_connection(('127.0.0.1', 5760))
while True:
    s.recv(65536) or time.sleep(0.1)
" &
KEEPER=$!
wait_port 5762
wait_port 5763
{os.environ["COMPANION_BIN"]} fly --connect tcp:127.0.0.1:5762 --log-dir {tmp_path}/runs > fly.out 2> fly.err &
FLY=$!
{sys.executable} - <<'EOF'
import json, sys, time
sys.path.insert(0, {str(here)!r})
from helpers import GcsClient
from standin import mavlink
g = GcsClient("tcp:127.0.0.1:5763")
t0 = time.monotonic()
armed_seen = False
while time.monotonic() - t0 < 60:
    g.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, mavlink.MAV_STATE_ACTIVE)
    for m in g.since(t0, "HEARTBEAT"):
        if m.get_srcComponent() == 1 and m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
            armed_seen = True
    time.sleep(1.0)
texts = [m.text for m in g.since(t0, "STATUSTEXT") if m.get_srcComponent() == 191]
json.dump({{"armed_seen": armed_seen, "texts": texts,
           "heartbeats": len([m for m in g.since(t0, "HEARTBEAT") if m.get_srcComponent() == 1])}},
          open({str(result)!r}, "w"))
g.close()
EOF
kill -0 $FLY && echo "fly still running" > fly.alive
""")
    out = subprocess.run(["unshare", "-n", "bash", str(script)], capture_output=True, text=True, timeout=180)
    assert result.exists(), out.stdout[-2000:] + out.stderr[-2000:]
    import json
    r = json.loads(result.read_text())
    print("real ArduCopter SITL, 60 s without --auto-start:", r)
    assert r["heartbeats"] > 10, r
    assert not r["armed_seen"], "the vehicle was armed without the operator"
    assert any("waiting for the operator" in t for t in r["texts"]), r
    assert (tmp_path / "fly.alive").exists(), (tmp_path / "fly.err").read_text()[-2000:]
