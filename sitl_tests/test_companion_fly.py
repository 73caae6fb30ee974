"""The real `companion fly` against an autopilot: the stand-in ArduCopter by default, a real SITL with SITL_URL.

Each test flies the companion's own tracking mission (from params/), with the onboard monitors
(NAMED_VALUE_FLOAT tgt_det/tgt_spd/trk_conf/lum/cpu_load) playing the camera application, injects one hazard,
and checks what reached the autopilot (the stand-in's recording) and what the companion decided (its decision
log: JSON Lines of DecisionRecord, companion-core/src/record.rs). Names checked are the shared vocabulary of the
project brief: states `wp1`, `landing`, `target`, `v0`..`v5`; actions `take_off`, `avoid_obstacle`, `land`,
`return_to_base`, `replan_and_land`, `track_v0`..`track_v5`; observations `vibration_mps2`,
`target_speed_rel`, `battery_pct`.
"""
from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional

import pytest

from helpers import COMPANION_LINK_TIMEOUT_S, all_actions, tracking_versions
from standin import mavlink

pytestmark = pytest.mark.companion_fly

COMMAND_TYPES = {"COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT",
                 "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT", "SET_POSITION_TARGET_GLOBAL_INT",
                 "SET_POSITION_TARGET_LOCAL_NED", "PARAM_SET"}
NOMINAL_TARGET = dict(tgt_det=1, tgt_spd=1.5, trk_conf=0.9, lum=600, cpu_load=0.35)
LANDING_ACTIONS = {"land", "return_to_base", "replan_and_land"}
FLY_TIMEOUT_S = float(os.environ.get("SITL_FLY_TIMEOUT", "240"))

# Hazards on a real ArduPilot SITL, set with PARAM_SET (names from libraries/SITL/SITL.cpp and AP_BattMonitor;
# the same as MAVProxy's `param set`). Not exercised here (no ArduPilot on this machine): see docs/sitl.md.
#  - vibration: SIM_VIB_MOT_MAX (Hz) adds motor-frequency noise scaled by SIM_VIB_MOT_MULT relative to the
#    accelerometer noise SIM_ACC1_RND/SIM_ACC2_RND (m/s/s), so the noise must be non-zero for it to show.
REAL_SITL_VIBRATION = {"SIM_ACC1_RND": 20.0, "SIM_ACC2_RND": 20.0, "SIM_VIB_MOT_MAX": 400.0, "SIM_VIB_MOT_MULT": 2.0}
#  - low battery: AP_BattMonitor's remaining % is 100 * (BATT_CAPACITY - consumed mAh) / BATT_CAPACITY, so a
#    capacity of consumed / 0.88 reads 12 % at once (SITL's SIM_BATT_VOLTAGE moves the voltage, not the %).
BATTERY_TARGET_PCT = 12.0


@dataclass
class Ctx:
    """What a scenario hook sees each tick (0.1 s)."""
    ap: Any
    mon: Any
    t0: float
    airborne_at: Optional[float] = None
    marks: Dict[str, float] = field(default_factory=dict)
    # real SITL: the values hazard parameters had before the test, restored after the flight (the SITL is shared)
    saved_params: Dict[str, float] = field(default_factory=dict)

    def airborne_for(self) -> float:
        return 0.0 if self.airborne_at is None else time.monotonic() - self.airborne_at

    def set_param(self, name: str, value: float) -> None:
        """A hazard parameter: the stand-in's set_param, or PARAM_SET over the monitors' link on a real SITL."""
        if self.ap.standin is not None:
            self.ap.standin.set_param(name, value)
            return
        if name not in self.saved_params:
            old = self.mon.param_get(name)
            if old is None:
                raise AssertionError(f"SITL did not answer PARAM_REQUEST_READ {name}")
            self.saved_params[name] = old
        self.mon.param_set(name, value)

    def restore_params(self) -> None:
        for name, value in self.saved_params.items():
            self.mon.param_set(name, value)

    def once(self, name: str) -> bool:
        if name in self.marks:
            return False
        self.marks[name] = time.monotonic()
        if self.ap.standin is not None:
            self.marks[name + "@wall"] = self.ap.standin.wall()
        return True


@dataclass
class Flight:
    run: Any
    rc: Optional[int]
    records: List[Dict[str, Any]]
    ctx: Ctx
    flew: bool
    ended_disarmed: bool

    def why(self) -> str:
        return self.run.output()


def view(ap: Any, mon: Any) -> Dict[str, Any]:
    if ap.standin is not None:
        s = ap.standin.state()
        return {"armed": s["armed"], "alt": s["alt"], "landed": s["landed"], "mode": s["mode"]}
    v = mon.snapshot()
    return {"armed": v["armed"], "alt": v["alt"], "landed": v["landed_state"] == mavlink.MAV_LANDED_STATE_ON_GROUND,
            "mode": v["mode"]}


def nominal_target(ctx: Ctx) -> None:
    """The camera application finds the target a few seconds into the flight, slow and well lit."""
    if ctx.airborne_for() > 5.0 and ctx.once("target"):
        ctx.mon.set(**NOMINAL_TARGET)


def fly_mission(ap: Any, fly: Any, monitors_factory: Any, scenario: Callable[[Ctx], None] = nominal_target,
                timeout: float = FLY_TIMEOUT_S, extra: tuple = ()) -> Flight:
    mon = monitors_factory(ap)
    run = fly(ap, extra=extra)
    ctx = Ctx(ap, mon, time.monotonic())
    flew = False
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if run.proc.poll() is not None:
            break
        v = view(ap, mon)
        if v["armed"] and v["alt"] > 2.0 and ctx.airborne_at is None:
            ctx.airborne_at = time.monotonic()
            flew = True
        scenario(ctx)
        if flew and not v["armed"] and v["landed"]:
            break
        time.sleep(0.1)
    rc = run.wait_exit(30)
    ctx.restore_params()
    # On a real SITL the view comes from telemetry (1 Hz heartbeat): the companion may see the disarm first.
    settle = time.monotonic() + 5.0
    v = view(ap, mon)
    while flew and (v["armed"] or not v["landed"]) and time.monotonic() < settle:
        time.sleep(0.1)
        v = view(ap, mon)
    return Flight(run, rc, run.records(), ctx, flew, ended_disarmed=not v["armed"] and v["landed"])


def assert_mission_completed(f: Flight) -> None:
    assert f.flew, "the vehicle never left the ground\n" + f.why()
    assert f.ended_disarmed, "the vehicle did not end landed and disarmed\n" + f.why()
    assert f.rc == 0, f"companion fly exit code {f.rc}\n" + f.why()
    assert f.records, "empty decision log\n" + f.why()


def commands_from_companion(sa: Any, since_wall: float = 0.0) -> List[Any]:
    """Vehicle commands the stand-in received from the companion (not the monitors), after `since_wall`."""
    return [e for e in sa.received(include_dropped=True)
            if e.data["type"] in COMMAND_TYPES and e.data["src"][1] != mavlink.MAV_COMP_ID_CAMERA and e.wall >= since_wall]


# ------------------------------------------------------------------------------------------------

def test_nominal_tracking_mission_end_to_end(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()
    f = fly_mission(ap, fly, monitors_factory)
    assert_mission_completed(f)
    states = {r["state"] for r in f.records}
    actions = set(all_actions(f.records))
    assert "take_off" in actions, sorted(actions)
    assert "wp1" in states, sorted(states)
    assert "landing" in states, sorted(states)
    assert states & {"target", "v0", "v1", "v2", "v3", "v4", "v5"} or any(a.startswith("track_v") for a in actions), \
        f"no tracking after the target was detected: states {sorted(states)}, actions {sorted(actions)}"
    assert actions & LANDING_ACTIONS, sorted(actions)
    # every action the core says runs was proposed by an MDP in the same record; what the shell
    # flew on its own safety rules (the flight's end) is apart, in shell_actions, with its reason
    for r in f.records:
        proposed = {a for p in r.get("proposals", []) for a in p.get("actions", [])}
        unproposed = [a for a in r.get("actions", []) if a not in proposed]
        assert not unproposed, (r.get("cycle"), unproposed, r.get("proposals"))
    if ap.standin is not None:
        sa = ap.standin
        assert sa.rec.of("arm"), "never armed"
        assert sa.v.max_alt >= 5.0 and sa.v.max_dist >= 20.0, (sa.v.max_alt, sa.v.max_dist)
        assert not sa.rec.of("collision")
        # every command the companion sent was answered and is logged with a result
        logged = [c for r in f.records for c in r.get("commands", [])]
        assert logged and all(c.get("result") for c in logged)
        assert any(c["result"] == "ACCEPTED" for c in logged)


@pytest.mark.sitl_hazard
def test_vibrations_switch_tracking_to_stabilised_v3(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()

    def scenario(ctx: Ctx) -> None:
        # the paper's section 7.1 context: vibrating airframe while the target is tracked
        if ctx.airborne_for() > 2.0 and ctx.once("vibration"):
            if ctx.ap.standin is not None:
                ctx.set_param("SIM_VIB_MOT_MAX", 400)       # stand-in: VIBRATION ~ 45 m/s/s in flight
            else:
                for name, value in REAL_SITL_VIBRATION.items():
                    ctx.set_param(name, value)
        nominal_target(ctx)

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert_mission_completed(f)
    assert "vibration" in f.ctx.marks, "the hazard was never injected (target phase not reached)"
    assert max(r.get("observations", {}).get("vibration_mps2", 0.0) for r in f.records) > 30.0, \
        "the companion never observed the vibration"
    assert "V3" in tracking_versions(f.records), tracking_versions(f.records)


def test_high_speed_target_switches_tracking_to_roi_resize_v2(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()

    def scenario(ctx: Ctx) -> None:
        # the target is fast from the moment it is detected
        if ctx.airborne_for() > 5.0 and ctx.once("fast"):
            ctx.mon.set(**{**NOMINAL_TARGET, "tgt_spd": 15.0})

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert_mission_completed(f)
    assert max(r.get("observations", {}).get("target_speed_rel", 0.0) for r in f.records) >= 10.0
    assert "V2" in tracking_versions(f.records), tracking_versions(f.records)


@pytest.mark.sitl_hazard
def test_low_battery_lands_or_returns(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 3.0 and "battery" not in ctx.marks:
            if ctx.ap.standin is not None:
                ctx.once("battery")
                ctx.set_param("SIM_BATT_PCT", BATTERY_TARGET_PCT)
            else:
                used = ctx.mon.snapshot()["battery_consumed_mah"]
                if used is not None and used > 0 and ctx.once("battery"):
                    ctx.set_param("BATT_CAPACITY", max(1.0, used / (1.0 - BATTERY_TARGET_PCT / 100.0)))

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert "battery" in f.ctx.marks
    assert f.flew and f.ended_disarmed, f.why()
    if ap.standin is not None:
        sa = ap.standin
        t_bat = f.ctx.marks["battery@wall"]
        changes = [e.data for e in sa.mode_changes()]
        to_land = [e for e in sa.mode_changes() if e.wall >= t_bat and e.data["new"] in ("LAND", "RTL")
                   and e.data["reason"] != "ekf_failsafe"]
    else:
        changes = f.ctx.mon.snapshot()["modes"]
        to_land = [m for t, m in changes if t >= f.ctx.marks["battery"] and m in ("LAND", "RTL")]
    assert to_land, f"no LAND/RTL after the battery dropped: {changes}"
    assert set(all_actions(f.records)) & LANDING_ACTIONS
    assert min(r.get("observations", {}).get("battery_pct", 100.0) for r in f.records) <= 15.0
    assert f.rc == 0, f.why()


@pytest.mark.standin_only(reason="judges collisions from the stand-in's own obstacle placement and recording; on a real autopilot: test_real_ardupilot.py::test_real_obstacle_ahead_triggers_avoidance")
def test_obstacle_triggers_avoidance_command(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory(speedup=2.0)              # slower so a ~1 Hz decision loop has time to react

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        sa = ctx.ap.standin
        moving = abs(sa.v.vn) + abs(sa.v.ve) > 1.0
        if ctx.airborne_for() > 3.0 and moving and ctx.once("obstacle"):
            sa.set_param("SIM_OBST_DIST", 35)          # DISTANCE_SENSOR forward, 35 m and closing

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert "obstacle" in f.ctx.marks, "never flew straight long enough to place the obstacle"
    sa = ap.standin
    t_obs = f.ctx.marks["obstacle@wall"]
    assert "avoid_obstacle" in all_actions(f.records), sorted(set(all_actions(f.records)))
    reactions = [e for e in commands_from_companion(sa, t_obs)
                 if e.data["type"].startswith("SET_POSITION_TARGET") or e.data["type"] in ("SET_MODE", "MISSION_COUNT")
                 or (e.data["type"] in ("COMMAND_LONG", "COMMAND_INT") and e.data["fields"]["command"] in (
                     mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_CMD_DO_SET_MODE, mavlink.MAV_CMD_DO_SET_MISSION_CURRENT,
                     mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_CONDITION_YAW))]
    assert reactions, "no vehicle command after the obstacle appeared"
    assert not sa.rec.of("collision"), "flew into the obstacle"
    assert_mission_completed(f)


@pytest.mark.standin_only(reason="uses the stand-in's link outage and its record of what arrived; on a real autopilot (relay blackout): test_real_ardupilot.py::test_real_five_second_link_cut")
def test_five_second_link_cut(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory()
    grace = COMPANION_LINK_TIMEOUT_S + 0.5    # wall seconds the companion may take to notice the silence

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 4.0 and ctx.once("cut"):
            ctx.ap.standin.link_outage(5.0)

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert "cut" in f.ctx.marks
    sa = ap.standin
    start, end = sa.rec.of("link_outage")[0].data["start"], sa.rec.of("link_outage")[0].data["end"]
    sent_while_lost = [e.data["type"] for e in commands_from_companion(sa, start + grace) if e.wall < end]
    assert not sent_while_lost, f"commands sent while the link was lost: {sent_while_lost}"
    uploads = sa.mission_uploads()
    assert len(uploads) <= 1, f"mission uploaded {len(uploads)} times"
    counts = [e for e in sa.received("MISSION_COUNT") if e.wall > end]
    assert not (uploads and counts and uploads[0].wall < start), "mission upload restarted after the link came back"
    events = " | ".join(e for r in f.records for e in r.get("link_events", []))
    assert re.search(r"(?i)lost|timeout|silent", events), events[:500]
    assert re.search(r"(?i)restor|regain|recover|resum|back", events), events[:500]
    assert_mission_completed(f)


@pytest.mark.standin_only(reason="uses the stand-in's byte injection; on a real autopilot (relay injection): test_real_ardupilot.py::test_real_garbage_bytes_on_the_link")
def test_garbage_and_malformed_frames_on_the_link(autopilot_factory, fly, monitors_factory):
    ap = autopilot_factory(garbage_period_wall=0.5)
    f = fly_mission(ap, fly, monitors_factory)
    sa = ap.standin
    assert sa.counters["tx_garbage_bytes"] > 0 and sa.counters["tx_malformed_frames"] > 0
    assert_mission_completed(f)
    events = " ".join(e for r in f.records for e in r.get("link_events", []))
    assert re.search(r"(?i)garbage|malformed|bad|crc|invalid|corrupt|parse", events), \
        "the companion did not count the bad bytes/frames in its link_events"


@pytest.mark.standin_only(reason="uses the stand-in's unsigned injection and its signature counters; on a real autopilot (SETUP_SIGNING, relay injection): test_real_ardupilot.py::test_real_signed_flight_with_the_key_on_the_autopilot")
def test_signing_on_unsigned_injection_is_ignored(autopilot_factory, fly, monitors_factory):
    key = os.urandom(32)
    ap = autopilot_factory(signing_key=key)

    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        sa = ctx.ap.standin
        if ctx.airborne_for() > 4.0 and ctx.once("inject"):
            for _ in range(3):
                # an attacker, unsigned, impersonating the autopilot and the camera application
                sa.inject_unsigned(mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 10000, 0, 3, 0, 0, 0, 0, 0, 0, 0, 0, 0))
                sa.inject_unsigned(mavlink.MAVLink_command_long_message(0, 0, mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0))
                sa.inject_unsigned(mavlink.MAVLink_named_value_float_message(0, b"tgt_spd", 25.0),
                                   srccomp=mavlink.MAV_COMP_ID_CAMERA)

    f = fly_mission(ap, fly, monitors_factory, scenario)
    assert "inject" in f.ctx.marks
    sa = ap.standin
    assert_mission_completed(f)
    # everything the companion sent was signed with the key (the stand-in rejects anything else)
    assert sa.counters["rx_unsigned_rejected"] == 0 and sa.counters["rx_bad_signature"] == 0
    mine = commands_from_companion(sa)
    assert mine and all(e.data["signed"] for e in mine)
    # the injected 3 % battery and 25 m/s target never reached the decisions
    assert min(r.get("observations", {}).get("battery_pct", 100.0) for r in f.records) > 50.0
    assert max(r.get("observations", {}).get("target_speed_rel", 0.0) for r in f.records) < 20.0
    t_inj = f.ctx.marks["inject@wall"]
    assert not [e for e in sa.mode_changes() if e.wall >= t_inj and e.data["new"] == "RTL"]


@pytest.mark.standin_only(reason="counts the stand-in's mission uploads")
def test_route_is_resumed_by_the_entry_params_mark_for_it(autopilot_factory, fly, monitors_factory, tmp_path):
    """The shell flies `follow_trajectory` again as the commands.toml entry marked `flown_for` it
    (whatever its name), so the route is resumed in AUTO, never uploaded a second time."""
    import shutil
    params = tmp_path / "params"
    shutil.copytree(os.path.join(os.path.dirname(__file__), "..", "params"), params)
    commands = params / "commands.toml"
    text = commands.read_text()
    assert "[follow_trajectory_resume]" in text
    commands.write_text(text.replace("[follow_trajectory_resume]", "[resume_the_route]"))
    ap = autopilot_factory()
    mon = monitors_factory(ap)
    run = fly(ap, extra=("--params", str(params)))
    ctx = Ctx(ap, mon, time.monotonic())
    deadline = time.monotonic() + FLY_TIMEOUT_S
    resumed = []
    while time.monotonic() < deadline and run.proc.poll() is None and not resumed:
        v = view(ap, mon)
        if v["armed"] and v["alt"] > 2.0 and ctx.airborne_at is None:
            ctx.airborne_at = time.monotonic()
        nominal_target(ctx)
        resumed = [c for r in run.records() for c in r.get("commands", []) if c.get("action") == "resume_the_route"]
        time.sleep(0.2)
    assert resumed, "follow_trajectory never flown again as the renamed resume entry\n" + run.output()
    assert all(c["command"] != "MISSION_UPLOAD" for c in resumed), resumed
    assert len(ap.standin.mission_uploads()) == 1, ap.standin.mission_uploads()


@pytest.mark.standin_only(reason="the stand-in's onboard monitors report the lidar driver's failure")
def test_lidar_driver_failure_report_turns_obstacle_detection_to_fusion(autopilot_factory, fly, monitors_factory):
    """`lidar_fail` from an onboard monitor (params/link.toml [telemetry.onboard]) is the observation
    `lidar_failed`: evidence for the sensors health manager (P_lidar falls, the navigation MDP turns
    to fusion) and a failed resource for the guarantee (a re-allocation without the lidar)."""
    def scenario(ctx: Ctx) -> None:
        nominal_target(ctx)
        if ctx.airborne_for() > 3.0 and ctx.once("lidar"):
            ctx.mon.set(lidar_fail=1)

    f = fly_mission(autopilot_factory(), fly, monitors_factory, scenario)
    assert "lidar" in f.ctx.marks, f.why()
    failed = [r for r in f.records if (r.get("observations") or {}).get("lidar_failed") == 1.0]
    assert failed, "lidar_failed never observed\n" + f.why()
    first = failed[0]["cycle"]
    later = [r for r in f.records if r["cycle"] >= first]
    assert any(r["probabilities"].get("P_lidar", 1.0) < 0.5 for r in later), [r["probabilities"].get("P_lidar") for r in later][:5]
    assert any("detect_obstacles_fusion" in r.get("actions", []) for r in later), sorted({a for r in later for a in r.get("actions", [])})
    assert not any("detect_obstacles_lidar" in r.get("actions", []) for r in later[3:]), "lidar detection kept running"
    assert any("lidar" in ((r.get("guarantee") or {}).get("failed_resources") or []) for r in later)
