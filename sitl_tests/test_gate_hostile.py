"""The operator gate under a hostile, unsigned link (issue 26), against the stand-in ArduCopter.

Each test injects frames the way the attacks did (impersonating the autopilot 1/1 unless said otherwise, several in one
write where the attack did) and asserts what the vehicle did, seen by the stand-in:

* two back-to-back spoofed "armed" heartbeats never arm the vehicle (even with --start-on-arm);
* one spoofed LOITER heartbeat in AUTO is a false alarm: the flight still ends landed and disarmed;
* one spoofed GUIDED heartbeat during a real pilot takeover sends no command;
* 5 s of spoofed "disarmed, on the ground" frames while the autopilot reports armed do not end the flight;
* a MISSION_START before the autopilot is heard is refused with an ACK, and the vehicle stays disarmed;
* a MISSION_START from an autopilot component id, or from a system that never sent a GCS heartbeat, is refused.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Any, List

import pytest

from standin import MODES, mavlink
from test_operator_and_landing import (COMPANION, events, motion_from_companion, short_route, stop,
                                       statustexts_from_companion, wait)

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]


def heartbeat(mode: str, armed: bool) -> Any:
    flags = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, flags,
                                             MODES[mode], mavlink.MAV_STATE_ACTIVE if armed else mavlink.MAV_STATE_STANDBY,
                                             3)


def start_command(cmd: int = mavlink.MAV_CMD_MISSION_START) -> Any:
    return mavlink.MAVLink_command_long_message(1, COMPANION, cmd, 0, 0, 0, 0, 0, 0, 0, 0)


def acks_from_companion(sa: Any, since: float = 0.0) -> List[dict]:
    return [e.data["fields"] for e in sa.received("COMMAND_ACK", include_dropped=True)
            if e.wall >= since and e.data["src"][1] == COMPANION]


def companion_armed(sa: Any) -> bool:
    """The companion sent an arm command."""
    return any(e.data["type"] == "COMMAND_LONG" and e.data["fields"].get("command") == mavlink.MAV_CMD_COMPONENT_ARM_DISARM
               and e.data["fields"].get("param1") == 1 for e in motion_from_companion(sa))


def test_two_back_to_back_spoofed_armed_heartbeats_never_arm_the_vehicle(autopilot_factory, fly):
    ap = autopilot_factory()
    sa = ap.standin
    run = fly(ap, auto_start=False, extra=("--start-on-arm",))
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    wait(lambda: any(e.data["src"][1] == COMPANION for e in sa.received("HEARTBEAT")), 20, "the companion", run)
    time.sleep(2.0)
    mode = sa.state()["mode"]
    for _ in range(3):                                    # three attempts, each two frames in one write
        sa.inject_unsigned_burst([heartbeat(mode, True), heartbeat(mode, True)])
        time.sleep(1.5)
    time.sleep(6.0)
    assert not companion_armed(sa), [e.data for e in motion_from_companion(sa)]
    assert not motion_from_companion(sa), [e.data for e in motion_from_companion(sa)]
    assert not sa.state()["armed"]
    stop(run)
    assert not any("mission started" in e or "start requested" in e for e in events(run.records()))


def test_one_spoofed_loiter_heartbeat_in_auto_still_ends_landed_and_disarmed(autopilot_factory, fly, tmp_path):
    ap = autopilot_factory(speedup=2.0, ekf_ready_s=4.0)
    sa = ap.standin
    run = fly(ap, mission=short_route(tmp_path))
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["alt"] > 10.0, 120, "the route in AUTO", run)
    sa.inject_unsigned(heartbeat("LOITER", True))
    wait(lambda: sa.rec.of("arm") and not sa.state()["armed"] and sa.state()["landed"], 240, "landed and disarmed", run)
    assert run.wait_exit(30) == 0, run.output()
    evs = events(run.records())
    assert any("false alarm" in e for e in evs), [e for e in evs if e.startswith("operator")]
    assert not any("the pilot or the autopilot has control" in e for e in evs)


def test_one_spoofed_guided_heartbeat_during_a_pilot_takeover_sends_no_command(autopilot_factory, fly, client):
    ap = autopilot_factory()
    sa = ap.standin
    gcs = client(sa.url)
    run = fly(ap)
    wait(lambda: sa.state()["mode"] == "AUTO" and sa.state()["alt"] > 10.0, 90, "the route in AUTO", run)
    assert gcs.set_mode("LOITER").result == mavlink.MAV_RESULT_ACCEPTED
    t_takeover = sa.wall()
    wait(lambda: any("pilot has control" in t for t in statustexts_from_companion(gcs)), 15, "the takeover confirmed",
         run)
    sa.inject_unsigned(heartbeat("GUIDED", True))
    time.sleep(6.0)
    after = motion_from_companion(sa, t_takeover + 0.3)
    assert not after, [e.data for e in after]
    assert sa.state()["mode"] == "LOITER"
    stop(run)
    assert not any("handed back" in e for e in events(run.records()))


def test_five_seconds_of_spoofed_landed_frames_do_not_end_the_flight(autopilot_factory, fly):
    ap = autopilot_factory()
    sa = ap.standin
    run = fly(ap)                                         # --once: a flight taken as over would exit
    wait(lambda: sa.state()["armed"] and sa.state()["alt"] > 10.0, 90, "the vehicle at 10 m", run)
    mode = sa.state()["mode"]
    down = [heartbeat(mode, False),
            mavlink.MAVLink_global_position_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0),
            mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_UNDEFINED, mavlink.MAV_LANDED_STATE_ON_GROUND)]
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5.0:
        sa.inject_unsigned_burst(down)
        time.sleep(0.05)
    time.sleep(3.0)
    assert run.proc.poll() is None, "fly took the spoofed frames as the end of the flight\n" + run.output()
    s = sa.state()
    assert s["armed"] and s["alt"] > 5.0, s
    stop(run)
    assert not any(e.startswith("flight over") for e in events(run.records()))


def test_a_mission_start_before_the_autopilot_is_heard_is_refused(autopilot_factory, fly, relay):
    ap = autopilot_factory()
    sa = ap.standin
    r = relay(int(sa.url.rsplit(":", 1)[1]))
    r.blackout(6.0)                                       # the companion connects, but hears nothing yet
    run = fly(dataclasses.replace(ap, url=r.url), auto_start=False)
    wait(lambda: r._pair is not None, 10, "the companion's connection", run)
    time.sleep(1.0)
    gcs_hb = mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                               mavlink.MAV_STATE_ACTIVE, 3)
    assert r.inject_unsigned(gcs_hb, srcsys=255, srccomp=190)
    assert r.inject_unsigned(start_command(), srcsys=255, srccomp=190)
    wait(lambda: any(m.get_type() == "COMMAND_ACK" for _, m, _ in r.sent), 5, "the companion's answer", run)
    ack = next(m for _, m, _ in r.sent if m.get_type() == "COMMAND_ACK")
    assert ack.command == mavlink.MAV_CMD_MISSION_START and ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED, ack
    wait(lambda: not r.in_blackout(), 10, "the end of the blackout")
    time.sleep(10.0)                                      # the autopilot is heard: nothing was queued for it
    assert not motion_from_companion(sa), [e.data for e in motion_from_companion(sa)]
    assert not sa.state()["armed"]
    stop(run)
    assert any("arrived before the autopilot was heard" in e for e in events(run.records()))


@pytest.mark.parametrize("sender", [(1, 1), (66, 1), (77, 190)], ids=["autopilot", "other-system-comp1", "no-gcs-heartbeat"])
def test_a_mission_start_not_from_a_ground_station_is_refused(autopilot_factory, fly, sender):
    ap = autopilot_factory()
    sa = ap.standin
    run = fly(ap, auto_start=False)
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    wait(lambda: any(e.data["src"][1] == COMPANION for e in sa.received("HEARTBEAT")), 20, "the companion", run)
    time.sleep(2.0)
    t0 = sa.wall()
    sa.inject_unsigned(start_command(), srcsys=sender[0], srccomp=sender[1])
    wait(lambda: acks_from_companion(sa, t0), 5, "the companion's answer", run)
    ack = acks_from_companion(sa, t0)[0]
    assert ack["command"] == mavlink.MAV_CMD_MISSION_START and ack["result"] == mavlink.MAV_RESULT_DENIED, ack
    time.sleep(6.0)
    assert not motion_from_companion(sa), [e.data for e in motion_from_companion(sa)]
    assert not sa.state()["armed"]
    stop(run)
    assert any("not a ground station" in e or "sent no GCS HEARTBEAT" in e for e in events(run.records()))
