"""`fly --gcs-sysid` names the operator's ground stations (issue 40, item 5): only those may start a mission. Against
the stand-in ArduCopter behind a relay (the proxy): a forged GCS HEARTBEAT from system 77 and its MISSION_START,
put on the link by the relay, arm nothing and are reported; the named ground station 255 then starts the flight.
"""
from __future__ import annotations

import dataclasses
import time

import pytest

from standin import mavlink
from test_gate_hostile import start_command
from test_operator_and_landing import events, motion_from_companion, stop, wait

pytestmark = [pytest.mark.companion_fly, pytest.mark.standin_only]


def gcs_heartbeat() -> object:
    return mavlink.MAVLink_heartbeat_message(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0,
                                             mavlink.MAV_STATE_ACTIVE, 3)


def test_with_gcs_sysid_a_forged_ground_station_77_and_its_start_arm_nothing(autopilot_factory, fly, relay, client):
    ap = autopilot_factory()
    sa = ap.standin
    r = relay(int(sa.url.rsplit(":", 1)[1]))
    run = fly(dataclasses.replace(ap, url=r.url), auto_start=False, extra=("--gcs-sysid", "255"))
    wait(lambda: sa.state()["position_ok"], 30, "the position estimate", run)
    wait(lambda: any(m.get_type() == "HEARTBEAT" for _, m, _ in r.sent), 20, "the companion", run)
    time.sleep(2.0)
    for _ in range(3):                                   # the forged station keeps speaking, as a real one would
        assert r.inject_unsigned(gcs_heartbeat(), srcsys=77, srccomp=190)
        time.sleep(0.5)
    t0 = time.monotonic()
    assert r.inject_unsigned(start_command(), srcsys=77, srccomp=190)

    def acks() -> list:
        return [m for m in r.sent_between(t0, time.monotonic() + 1, {"COMMAND_ACK"})
                if m.command == mavlink.MAV_CMD_MISSION_START]
    wait(lambda: acks(), 5, "the companion's answer", run)
    assert acks()[0].result == mavlink.MAV_RESULT_DENIED and acks()[0].target_system == 77, acks()[0]
    time.sleep(8.0)                                      # the forged start armed the vehicle 7 s later before
    assert not motion_from_companion(sa), [e.data for e in motion_from_companion(sa)]
    assert not sa.state()["armed"]

    # The named ground station 255 still starts it.
    gcs = client(sa.url)
    ack = gcs.start_mission()
    assert ack is not None and ack.result == mavlink.MAV_RESULT_ACCEPTED, ack
    wait(lambda: sa.state()["armed"], 30, "the start by 255", run)
    stop(run)
    evs = events(run.records())
    assert any("ground station 77/190 is heard" in e and "--gcs-sysid names 255" in e for e in evs), evs
    assert any("system 77 is not a ground station --gcs-sysid names (255)" in e for e in evs), evs
