"""`companion fly` against a real ArduCopter SITL, a fresh vehicle per test (conftest.py `arducopter`).

The companion connects through a relay (relay.py) to the vehicle's SERIAL1, so a test can black the link out,
cut it, or fill it with garbage, and knows every message the companion sent and when. The onboard monitors
(the camera application's NAMED_VALUE_FLOAT, and DISTANCE_SENSOR for the obstacle) talk on SERIAL2. A ground
station observer on SERIAL0 injects hazards the SITL way (PARAM_SET of SIM_*/BATT_*) and judges the flight as
a ground station sees it: armed, altitude reached, modes flown, MISSION_ITEM_REACHED, EXTENDED_SYS_STATE
landed, disarmed.

Speed-up: `SPEEDUP` (SITL physics N times wall time) is used where nothing judged depends on how fast the
vehicle moves relative to the companion's wall-clock timers (its decision cycle and link timeout); the
obstacle and link-cut tests fly at 1x (docs/sitl.md lists which).
"""
from __future__ import annotations

import os
import re
import subprocess
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional

import pytest

from helpers import COMPANION_LINK_TIMEOUT_S, all_actions, tracking_versions
from standin import mavlink

pytestmark = [pytest.mark.real_autopilot, pytest.mark.companion_fly]

SPEEDUP = float(os.environ.get("REAL_SITL_SPEEDUP", "3"))
FLY_TIMEOUT_S = float(os.environ.get("REAL_SITL_FLY_TIMEOUT", "420"))
NOMINAL_TARGET = dict(tgt_det=1, tgt_spd=1.5, trk_conf=0.9, lum=600, cpu_load=0.35)
# params/observations.toml vibration_mps2 threshold: above it the vibration counts as high
VIBRATION_HIGH_MPS2 = 15.0
LANDING_ACTIONS = {"land", "return_to_base", "replan_and_land"}
# What the companion sends that commands the vehicle (anything else it sends is telemetry or a request).
COMMAND_TYPES = {"COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT",
                 "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "SET_POSITION_TARGET_GLOBAL_INT",
                 "SET_POSITION_TARGET_LOCAL_NED"}
# Commands that only ask for data (stream rates, one message, parameters), not vehicle motion.
REQUEST_COMMANDS = {mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, mavlink.MAV_CMD_REQUEST_MESSAGE,
                    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES}


def vehicle_commands(msgs: List[Any]) -> List[Any]:
    return [m for m in msgs if m.get_type() in COMMAND_TYPES
            and not (m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command in REQUEST_COMMANDS)]


@dataclass
class Ctx:
    """What a scenario hook sees each tick (0.1 s)."""
    veh: Any
    mon: Any
    relay: Any
    run: Any
    t0: float
    airborne_at: Optional[float] = None
    marks: Dict[str, float] = field(default_factory=dict)

    @property
    def gcs(self) -> Any:
        return self.veh.gcs

    def airborne_for(self) -> float:
        return 0.0 if self.airborne_at is None else time.monotonic() - self.airborne_at

    def once(self, name: str) -> bool:
        if name in self.marks:
            return False
        self.marks[name] = time.monotonic()
        return True


@dataclass
class Flight:
    run: Any
    rc: Optional[int]
    records: List[Dict[str, Any]]
    ctx: Ctx

    def why(self) -> str:
        return self.run.output() + self.ctx.gcs.summary()


def nominal_target(ctx: Ctx) -> None:
    """The camera application finds the target a few seconds into the flight, slow and well lit."""
    if ctx.airborne_for() > 5.0 and ctx.once("target"):
        ctx.mon.set(**NOMINAL_TARGET)


def fly_real(veh: Any, fly: Any, monitors_factory: Any, relay: Any, scenario: Callable[[Ctx], None] = nominal_target,
             timeout: float = FLY_TIMEOUT_S, signing_key: Optional[bytes] = None, extra: tuple = ()) -> Flight:
    """Fly the companion's own tracking mission on `veh` through a relay; run `scenario` every 0.1 s; return
    once the vehicle has flown and is back on the ground disarmed, or the companion exited, or at `timeout`."""
    ap = veh.autopilot
    ap.signing_key = signing_key
    rl = relay(int(ap.url.rsplit(":", 1)[1]))
    mon = monitors_factory(ap)
    via = type(ap)(url=rl.url, monitor_url=ap.monitor_url, signing_key=signing_key)
    run = fly(via, extra=extra)
    ctx = Ctx(veh, mon, rl, run, time.monotonic())
    gcs = veh.gcs
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if run.proc.poll() is not None:
            break
        if gcs.armed and gcs.alt > 2.0 and ctx.airborne_at is None:
            ctx.airborne_at = time.monotonic()
        scenario(ctx)
        if ctx.airborne_at is not None and not gcs.armed and gcs.landed:
            break
        time.sleep(0.1)
    rc = run.wait_exit(30)
    return Flight(run, rc, run.records(), ctx)


def live_versions(run: Any) -> set:
    """Tracking versions in the decision log so far (read while the companion writes it)."""
    try:
        return tracking_versions(run.records())
    except AssertionError:          # the last line is being written
        return set()


def assert_flew_and_landed(f: Flight, min_alt: float = 15.0) -> None:
    """Judged from the vehicle: it armed, climbed, came back down and disarmed; the companion exited 0."""
    gcs = f.ctx.gcs
    assert gcs.ever_armed(), "the vehicle never armed" + f.why()
    assert gcs.max_alt >= min_alt, f"the vehicle climbed to {gcs.max_alt:.1f} m only" + f.why()
    gcs.wait(lambda: not gcs.armed and gcs.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND, 15.0,
             "the vehicle did not end landed and disarmed")
    assert f.rc == 0, f"companion fly exit code {f.rc}" + f.why()
    assert f.records, "empty decision log" + f.why()


def link_events(f: Flight) -> str:
    return " | ".join(e for r in f.records for e in r.get("link_events", []))


def mission_uploads(relay: Any) -> List[Any]:
    with relay._lock:
        return [(t, m) for (t, m, _) in relay.sent if m.get_type() == "MISSION_COUNT"]


# ------------------------------------------------------------------------------------------------
# the vehicle itself
# ------------------------------------------------------------------------------------------------

def test_real_fresh_vehicle_is_disarmed_full_and_without_mission(arducopter):
    """Each test's vehicle is new: disarmed, on the ground, full battery, no stored mission (`-w` and its own
    working directory); a reused vehicle keeps all four."""
    veh = arducopter(speedup=SPEEDUP)
    gcs = veh.gcs
    gcs.wait(lambda: gcs.battery_pct is not None and gcs.landed_state != 0, 30, "no BATTERY_STATUS/EXTENDED_SYS_STATE")
    assert not gcs.armed and gcs.landed
    assert gcs.battery_pct == 100
    assert gcs.param_get("MIS_TOTAL") <= 1.0          # home only
    other = arducopter(speedup=SPEEDUP)              # a second vehicle side by side: another instance
    assert other.sitl.ports.serial0 != veh.sitl.ports.serial0
    assert other.gcs.heartbeats > 0


# ------------------------------------------------------------------------------------------------
# the mission and the hazards
# ------------------------------------------------------------------------------------------------

def test_real_nominal_tracking_mission_end_to_end(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=SPEEDUP)
    f = fly_real(veh, fly, monitors_factory, relay)
    assert_flew_and_landed(f)
    gcs = veh.gcs
    modes = gcs.modes_flown()
    assert "GUIDED" in modes or "AUTO" in modes, modes
    assert gcs.reached_seqs(), "no MISSION_ITEM_REACHED: the route was not flown" + f.why()
    states = {r["state"] for r in f.records}
    actions = set(all_actions(f.records))
    assert "take_off" in actions, sorted(actions)
    assert states & {"target", "v0", "v1", "v2", "v3", "v4", "v5"} or any(a.startswith("track_v") for a in actions), \
        f"no tracking after the target was reported: states {sorted(states)}, actions {sorted(actions)}"
    assert actions & LANDING_ACTIONS, sorted(actions)
    assert len(mission_uploads(f.ctx.relay)) == 1, "the route was uploaded more than once"
    # The review tells how the flight ended: landed and disarmed, where, and how far from home.
    run_dir = next(p.parent for p in f.run.log_dir.rglob("decisions*.jsonl"))
    out = subprocess.run([os.environ["COMPANION_BIN"], "review", str(run_dir), "--summary"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    ended = [ln for ln in out.stdout.splitlines() if "landed and disarmed" in ln]
    assert ended, out.stdout[-2000:]
    m = re.search(r"([0-9]+) m from home", ended[0])
    assert m and int(m.group(1)) < 500, ended[0]


def test_real_companion_arms_only_in_the_mode_it_commanded(arducopter, fly, monitors_factory, relay):
    """Every arming of the vehicle (as the ground station saw it) happened in GUIDED, the mode the companion
    takes off in: never arm a vehicle in a mode the companion did not command."""
    veh = arducopter(speedup=SPEEDUP)

    def scenario(ctx: Ctx) -> None:
        if ctx.airborne_for() > 3.0 and ctx.once("airborne"):
            ctx.run.proc.terminate()          # only the start of the flight is judged

    f = fly_real(veh, fly, monitors_factory, relay, scenario, timeout=240)
    gcs = veh.gcs
    assert gcs.ever_armed(), f.why()
    with gcs._lock:
        arms = [t for t, a in gcs.armed_times if a]
        mode_at = [([m for tm, m in gcs.modes if tm <= t] or ["?"])[-1] for t in arms]
    assert mode_at and all(m == "GUIDED" for m in mode_at), f"armed in {mode_at}" + f.why()


@pytest.mark.sitl_hazard
def test_real_vibrations_switch_tracking_to_stabilised_v3(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=SPEEDUP)

    shaking = {"SIM_ACC1_RND": 20.0, "SIM_ACC2_RND": 20.0, "SIM_VIB_MOT_MAX": 400.0, "SIM_VIB_MOT_MULT": 2.0}

    def scenario(ctx: Ctx) -> None:
        if ctx.airborne_for() > 2.0 and ctx.once("vibration"):
            # SIM_VIB_MOT_MAX adds motor-frequency noise scaled by SIM_VIB_MOT_MULT on top of the accelerometer
            # noise SIM_ACC*_RND, so the noise must be non-zero for it to show in VIBRATION (SITL.cpp)
            for name, value in shaking.items():
                ctx.gcs.param_set(name, value)
        nominal_target(ctx)
        # this much shaking makes the EKF give up in the end: stop it once the companion has switched (or after
        # 30 s), so the flight ends with a normal landing the test can judge
        if "vibration" in ctx.marks and "calm" not in ctx.marks:
            since = time.monotonic() - ctx.marks["vibration"]
            if since > 30.0 or (int(since * 10) % 10 == 0 and "V3" in live_versions(ctx.run)):
                ctx.once("calm")
                for name in shaking:
                    ctx.gcs.param_set(name, 0.0)

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "vibration" in f.ctx.marks, "the hazard was never injected" + f.why()
    assert max(r.get("observations", {}).get("vibration_mps2", 0.0) for r in f.records) > VIBRATION_HIGH_MPS2, \
        "the companion never observed the vibration" + f.why()
    assert "V3" in tracking_versions(f.records), tracking_versions(f.records)
    assert_flew_and_landed(f)


def test_real_fast_target_switches_tracking_to_roi_resize_v2(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=SPEEDUP)

    def scenario(ctx: Ctx) -> None:
        if ctx.airborne_for() > 5.0 and ctx.once("fast"):
            ctx.mon.set(**{**NOMINAL_TARGET, "tgt_spd": 15.0})

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert max(r.get("observations", {}).get("target_speed_rel", 0.0) for r in f.records) >= 10.0
    assert "V2" in tracking_versions(f.records), tracking_versions(f.records)
    assert_flew_and_landed(f)


@pytest.mark.sitl_hazard
def test_real_low_battery_lands_or_returns(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=SPEEDUP)
    target_pct = 12.0

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 3.0 and "battery" not in ctx.marks:
            # AP_BattMonitor: remaining % = 100 * (BATT_CAPACITY - consumed mAh) / BATT_CAPACITY, so a capacity of
            # consumed / 0.88 reads 12 % at once (SIM_BATT_VOLTAGE moves the voltage, not the %)
            used = ctx.gcs.battery_consumed_mah
            if used and ctx.once("battery"):
                ctx.gcs.param_set("BATT_CAPACITY", max(1.0, used / (1.0 - target_pct / 100.0)))

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "battery" in f.ctx.marks, "the battery was never lowered" + f.why()
    after = veh.gcs.modes_since(f.ctx.marks["battery"])
    assert set(after) & {"LAND", "RTL"}, f"no LAND/RTL after the battery dropped: {after}" + f.why()
    assert set(all_actions(f.records)) & LANDING_ACTIONS, sorted(set(all_actions(f.records)))
    assert min(r.get("observations", {}).get("battery_pct", 100.0) for r in f.records) <= 15.0
    assert_flew_and_landed(f)


def test_real_obstacle_ahead_triggers_avoidance(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=1.0)          # the decision cycle is wall-clock: at 1x it has time to react

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 3.0 and ctx.gcs.mode in ("AUTO", "GUIDED") and ctx.gcs.alt > 10 and ctx.once("obstacle"):
            pass
        if "obstacle" in ctx.marks:
            # a forward obstacle sensor on the onboard computer, sent on the monitors' link (SITL's SERIAL2 serves
            # one TCP client): broadcast, so ArduPilot routes it to the companion's port (MAVLink_routing.cpp).
            # 35 m and closing at 15 m/s down to 3 m, for 30 s; then out of range.
            left = time.monotonic() - ctx.marks["obstacle"]
            dist_cm = int(max(300.0, 3500.0 - 1500.0 * left)) if left < 30.0 else 3999
            ctx.mon.conn.mav.distance_sensor_send(int(left * 1000) & 0xFFFFFFFF, 20, 4000, dist_cm,
                                                  mavlink.MAV_DISTANCE_SENSOR_LASER, 1,
                                                  mavlink.MAV_SENSOR_ROTATION_NONE, 0)

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "obstacle" in f.ctx.marks, "never flew straight long enough to place the obstacle" + f.why()
    t_obs = f.ctx.marks["obstacle"]
    assert min(r.get("observations", {}).get("obstacle_m", 1e9) for r in f.records) < 10.0, \
        "the companion never saw the obstacle" + f.why()
    assert "avoid_obstacle" in all_actions(f.records), sorted(set(all_actions(f.records)))
    reactions = vehicle_commands(f.ctx.relay.sent_between(t_obs, time.monotonic()))
    assert reactions, "no vehicle command after the obstacle appeared" + f.why()
    assert_flew_and_landed(f)


@pytest.mark.sitl_hazard
def test_real_gps_loss_hands_over_to_the_autopilots_failsafe(arducopter, fly, monitors_factory, relay):
    """SIM_GPS1_ENABLE 0 in flight: ArduCopter's EKF failsafe (FS_EKF_ACTION 1, copter.parm default) lands the
    vehicle; the companion must let it (no GUIDED/AUTO/position command after LAND) and end cleanly."""
    veh = arducopter(speedup=SPEEDUP)

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 8.0 and ctx.once("gps"):
            ctx.gcs.param_set("SIM_GPS1_ENABLE", 0)

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "gps" in f.ctx.marks, f.why()
    gcs = veh.gcs
    after = gcs.modes_since(f.ctx.marks["gps"])
    assert "LAND" in after, f"the autopilot did not land after the GPS loss: {after}" + f.why()
    t_land = [t for t, m in gcs.modes if m == "LAND" and t >= f.ctx.marks["gps"]][0]
    fights = [m for m in vehicle_commands(f.ctx.relay.sent_between(t_land, time.monotonic()))
              if m.get_type().startswith("SET_POSITION_TARGET") or m.get_type() in ("SET_MODE", "MISSION_COUNT")
              or (m.get_type() in ("COMMAND_LONG", "COMMAND_INT") and m.command in (
                  mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_CMD_NAV_TAKEOFF,
                  mavlink.MAV_CMD_MISSION_START) and not (m.command == mavlink.MAV_CMD_DO_SET_MODE and m.param2 == 9))]
    assert not fights, f"the companion fought the GPS-loss landing: {[str(m) for m in fights[:5]]}"
    assert gcs.max_alt >= 10.0
    gcs.wait(lambda: not gcs.armed and gcs.landed, 60.0, "not landed and disarmed after the GPS loss")
    assert f.rc == 0, f"companion fly exit code {f.rc}" + f.why()


# ------------------------------------------------------------------------------------------------
# the link
# ------------------------------------------------------------------------------------------------

def _link_cut(arducopter, fly, monitors_factory, relay, seconds: float) -> Flight:
    veh = arducopter(speedup=1.0)          # the cut and the companion's link timer are wall-clock

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 4.0 and ctx.once("cut"):
            ctx.marks["cut_end"] = ctx.relay.blackout(seconds)[1]

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "cut" in f.ctx.marks, f.why()
    start, end = f.ctx.marks["cut"], f.ctx.marks["cut_end"]
    grace = COMPANION_LINK_TIMEOUT_S + 0.5
    while_lost = vehicle_commands(f.ctx.relay.sent_between(start + grace, end))
    assert not while_lost, f"commands sent while the link was lost: {[m.get_type() for m in while_lost]}"
    uploads = mission_uploads(f.ctx.relay)
    assert len(uploads) <= 1, f"mission uploaded {len(uploads)} times"
    events = link_events(f)
    assert re.search(r"(?i)lost|timeout|silent", events), events[:500]
    assert re.search(r"(?i)restor|regain|recover|resum|back", events), events[:500]
    assert_flew_and_landed(f)
    return f


def test_real_five_second_link_cut(arducopter, fly, monitors_factory, relay):
    _link_cut(arducopter, fly, monitors_factory, relay, 5.0)


def test_real_sixty_second_link_cut(arducopter, fly, monitors_factory, relay):
    _link_cut(arducopter, fly, monitors_factory, relay, 60.0)


def test_real_tcp_connection_dropped_and_reconnected(arducopter, fly, monitors_factory, relay):
    """The relay closes the TCP connection in flight: the companion reconnects, uploads nothing again and
    finishes the mission."""
    veh = arducopter(speedup=SPEEDUP)

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 4.0 and ctx.once("drop"):
            ctx.relay.cut()

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert "drop" in f.ctx.marks
    assert f.ctx.relay.accepts >= 2, "the companion never reconnected" + f.why()
    assert len(mission_uploads(f.ctx.relay)) <= 1
    assert_flew_and_landed(f)


def test_real_garbage_bytes_on_the_link(arducopter, fly, monitors_factory, relay):
    veh = arducopter(speedup=SPEEDUP)

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.once("garbage"):
            ctx.relay.garbage_every(0.5)

    f = fly_real(veh, fly, monitors_factory, relay, scenario)
    assert f.ctx.relay.garbage_bytes > 0 and f.ctx.relay.malformed_frames > 0
    assert_flew_and_landed(f)
    events = link_events(f)
    assert re.search(r"(?i)garbage|malformed|bad|crc|invalid|corrupt|parse", events), \
        "the companion did not count the bad bytes/frames in its link_events" + events[:300]


def test_real_autopilot_reboot_mid_flight(arducopter, fly, monitors_factory, relay):
    """MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN from the ground station while flying. ArduPilot refuses to reboot an
    armed vehicle (GCS_MAVLINK::handle_preflight_reboot) unless forced with param6 = 20190226; SITL then
    re-executes itself, so the vehicle comes back on the ground, disarmed, and its sockets reopen. The
    companion must notice the loss, not command during it, reconnect, and not take off again by itself."""
    veh = arducopter(speedup=SPEEDUP)
    acks = {}

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 6.0 and ctx.once("reboot"):
            acks["plain"] = ctx.gcs.command_long(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1)
            acks["forced"] = ctx.gcs.command_long(mavlink.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1, 0, 0, 0, 0, 20190226,
                                                  timeout=2.0)
            ctx.marks["rebooted"] = time.monotonic()

    f = fly_real(veh, fly, monitors_factory, relay, scenario, timeout=240)
    assert "reboot" in f.ctx.marks, f.why()
    assert acks["plain"] in (mavlink.MAV_RESULT_FAILED, mavlink.MAV_RESULT_DENIED), acks
    gcs = veh.gcs
    gcs.wait(lambda: gcs.connects >= 2 and gcs.heartbeats > 0, 60, "the ground station did not see the reboot")
    assert f.ctx.relay.accepts >= 2, "the companion never reconnected after the reboot" + f.why()
    events = link_events(f)
    assert re.search(r"(?i)lost|timeout|silent|closed|disconnect", events), events[:500]
    assert gcs.arm_count(since=f.ctx.marks["rebooted"]) == 0, \
        "the companion armed the rebooted vehicle again by itself" + f.why()
    assert not gcs.armed and gcs.landed


# ------------------------------------------------------------------------------------------------
# MAVLink 2 signing with the key on the autopilot
# ------------------------------------------------------------------------------------------------

def test_real_signed_flight_with_the_key_on_the_autopilot(arducopter, fly, monitors_factory, relay):
    """SETUP_SIGNING from the ground station: ArduPilot stores the key and from then on accepts only signed
    frames (GCS_Signing.cpp). The companion, given the same key, signs everything and flies the mission."""
    veh = arducopter(speedup=SPEEDUP)
    key = os.urandom(32)
    veh.gcs.setup_signing(key)

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 4.0 and ctx.once("inject"):
            # an attacker on the link, unsigned, impersonating the autopilot and the camera application
            for _ in range(3):
                ctx.relay.inject_unsigned(mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 10000, 0, 3, 0, 0, 0, 0, 0,
                                                                             0, 0, 0, 0))
                ctx.relay.inject_unsigned(mavlink.MAVLink_battery_status_message(0, 0, 0, 2000, [3700] * 10, 0, 0, 0, 3))
                ctx.relay.inject_unsigned(mavlink.MAVLink_named_value_float_message(0, b"tgt_spd", 25.0),
                                          srccomp=mavlink.MAV_COMP_ID_CAMERA)

    f = fly_real(veh, fly, monitors_factory, relay, scenario, signing_key=key)
    assert "inject" in f.ctx.marks, f.why()
    sent = [m for (_, m, _) in f.ctx.relay.sent]
    assert sent and all(m._header.incompat_flags & mavlink.MAVLINK_IFLAG_SIGNED for m in sent), \
        "the companion sent unsigned frames"
    # the injected 3 % battery and 25 m/s target never reached the decisions
    assert min(r.get("observations", {}).get("battery_pct", 100.0) for r in f.records) > 5.0
    assert max(r.get("observations", {}).get("target_speed_rel", 0.0) for r in f.records) < 20.0
    assert "RTL" not in veh.gcs.modes_flown(), veh.gcs.modes_flown()
    assert_flew_and_landed(f)


def test_real_unsigned_companion_cannot_command_a_signing_autopilot(arducopter, fly, monitors_factory, relay):
    """Signing on the autopilot, no key for the companion: ArduPilot ignores its unsigned commands, so the
    vehicle never arms, and the companion says its commands went unanswered instead of flying blind."""
    veh = arducopter(speedup=SPEEDUP)
    key = os.urandom(32)
    veh.gcs.setup_signing(key)
    f = fly_real(veh, fly, monitors_factory, relay, timeout=90, extra=("--duration", "80s"))
    assert not veh.gcs.ever_armed(), "an unsigned companion armed a signing autopilot" + f.why()
    cmds = [c for r in f.records for c in r.get("commands", [])]
    assert not any(c.get("result") == "ACCEPTED" for c in cmds), cmds[:5]
