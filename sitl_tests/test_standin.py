"""Tests of the stand-in autopilot itself, driven by a pymavlink client.

Expected values come from ArduPilot (source paths cited) and from hand computation with ArduCopter's
default parameters, not from the stand-in. They run without the companion binary.
"""
from __future__ import annotations

import math
import os
import socket
import time

import pytest

import standin as sap
from helpers import offset, wp
from standin import mavlink
from standin import mission as mission_protocol

pytestmark = pytest.mark.standin_only

HOME = (sap.HOME_LAT, sap.HOME_LON)
FAST = dict(speedup=10.0, ekf_ready_s=8.0)


def ready(sa, c, mode="GUIDED"):
    """Wait for the position estimate (EKF_STATUS_REPORT POS_HORIZ_ABS), then set `mode`."""
    c.wait("EKF_STATUS_REPORT", lambda m: m.flags & mavlink.EKF_POS_HORIZ_ABS, timeout=20)
    ack = c.set_mode(mode)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED


def airborne(sa, c, alt=10.0):
    ready(sa, c)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    assert c.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt).result == mavlink.MAV_RESULT_ACCEPTED
    sa.wait_for(lambda: sa.v.alt >= alt - 0.2, timeout=30, what="take-off altitude")
    # The altitude is visible a tick before the stand-in records the take-off as complete; on a
    # loaded machine that tick can be late, so wait for the record itself.
    sa.wait_for(lambda: sa.rec.of("takeoff_complete"), timeout=10, what="take-off complete")


# ------------------------------------------------------------------------------------------------
# heartbeat, arming, disarm delay
# ------------------------------------------------------------------------------------------------

def test_heartbeat_identifies_an_arducopter_quad(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    hb = c.wait("HEARTBEAT", timeout=5)
    assert hb.type == mavlink.MAV_TYPE_QUADROTOR
    assert hb.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.custom_mode == 0                       # STABILIZE at boot
    assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_arming_refused_with_prearm_text_until_position_estimate(standin, client):
    sa = standin(speedup=8.0, ekf_ready_s=40.0)        # ~5 wall s of "no position estimate"
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    # Disarmed, any mode may be selected (Copter::set_mode: "allow switching to any mode if disarmed")
    assert c.set_mode("GUIDED").result == mavlink.MAV_RESULT_ACCEPTED
    t0 = time.monotonic()
    ack = c.arm()
    # GCS_MAVLINK::handle_command_component_arm_disarm: a refused arm is MAV_RESULT_FAILED (4)
    assert ack.result == 4
    text = c.wait("STATUSTEXT", lambda m: m.text.startswith("PreArm:"), since=t0 - 0.5)
    assert text.text == "PreArm: Need Position Estimate"
    assert text.severity == mavlink.MAV_SEVERITY_CRITICAL
    assert not sa.v.armed
    ekf = c.wait("EKF_STATUS_REPORT", since=t0)
    assert not ekf.flags & mavlink.EKF_POS_HORIZ_ABS
    # once the estimate converges the same command succeeds and the heartbeat shows armed
    c.wait("EKF_STATUS_REPORT", lambda m: m.flags & mavlink.EKF_POS_HORIZ_ABS, timeout=20)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    c.wait("HEARTBEAT", lambda m: m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, timeout=5)


def test_arming_refused_in_auto(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    ready(sa, c, "AUTO")
    t0 = time.monotonic()
    assert c.arm().result == 4
    # AP_Arming_Copter::arm_checks: check_failed(true, "%s mode not armable", flightmode->name()); the
    # "Arm: " prefix is AP_Arming::check_failed's while running arming (not pre-arm) checks
    assert c.wait("STATUSTEXT", since=t0 - 0.5).text == "Arm: AUTO mode not armable"   # ModeAuto::allows_arming


PREARM = mavlink.MAV_SYS_STATUS_PREARM_CHECK   # 0x10000000 in common.xml MAV_SYS_STATUS_SENSOR


def test_sys_status_prearm_bit_follows_the_checks(standin, client):
    """GCS::update_sensor_status_flags (libraries/GCS_MAVLink/GCS.cpp): PREARM_CHECK always present, enabled
    while ARMING_CHECK != 0, healthy when armed or AP_Notify::flags.pre_arm_check (the checks pass)."""
    assert PREARM == 0x10000000
    sa = standin(speedup=8.0, ekf_ready_s=40.0)
    c = client(sa.url)
    assert c.set_mode("GUIDED").result == mavlink.MAV_RESULT_ACCEPTED
    t0 = time.monotonic()
    s = c.wait("SYS_STATUS", since=t0)
    assert s.onboard_control_sensors_present & PREARM and s.onboard_control_sensors_enabled & PREARM
    assert not s.onboard_control_sensors_health & PREARM          # no position estimate yet in GUIDED
    s = c.wait("SYS_STATUS", lambda m: m.onboard_control_sensors_health & PREARM, timeout=20)
    ekf = c.wait("EKF_STATUS_REPORT", since=time.monotonic())
    assert ekf.flags & mavlink.EKF_POS_HORIZ_ABS
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    t1 = time.monotonic()
    assert c.wait("SYS_STATUS", since=t1).onboard_control_sensors_health & PREARM
    # ARMING_CHECK 0: the bit stays present but is no longer enabled (no verdict to read)
    assert c.param_set("ARMING_CHECK", 0) is not None
    t2 = time.monotonic()
    s = c.wait("SYS_STATUS", since=t2 + 0.1)
    assert s.onboard_control_sensors_present & PREARM and not s.onboard_control_sensors_enabled & PREARM


def test_failing_prearm_check_is_repeated_every_30_s_while_disarmed(standin, client):
    """AP_Arming_Copter::update: checks at 1 Hz, failures displayed every PREARM_DISPLAY_PERIOD = 30 s with the
    counter starting at 15, so unprompted "PreArm:" texts come at about 15 s and 45 s of vehicle time."""
    sa = standin(speedup=10.0, ekf_ready_s=1000.0)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    texts = []
    deadline = time.monotonic() + 20
    while len(texts) < 2 and time.monotonic() < deadline:
        texts = [e for e in sa.rec.of("statustext") if e.data["text"].startswith("PreArm:")]
        time.sleep(0.05)
    assert len(texts) >= 2, texts
    assert texts[0].sim == pytest.approx(15.0, abs=0.5)
    assert texts[1].sim - texts[0].sim == pytest.approx(30.0, abs=0.5)
    assert texts[0].data["text"] == "PreArm: AHRS: waiting for home"    # STABILIZE at boot, EKF not aligned
    assert not sa.commands(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)          # nobody asked to arm


def test_takeoff_command_rules(standin, client):
    """GCS_MAVLINK_Copter::handle_MAV_CMD_NAV_TAKEOFF (ArduCopter/GCS_Mavlink.cpp) and Mode::do_user_takeoff
    (ArduCopter/takeoff.cpp): disarmed -> FAILED; COMMAND_INT in another frame than GLOBAL_RELATIVE_ALT ->
    DENIED; ALT_HOLD only with param3 (pilot may navigate) set; GUIDED armed on the ground -> ACCEPTED."""
    sa = standin(**FAST)
    c = client(sa.url)
    ready(sa, c)
    R = mavlink
    assert c.command_long(R.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10).result == R.MAV_RESULT_FAILED   # disarmed
    assert c.arm().result == R.MAV_RESULT_ACCEPTED
    assert c.command_int(R.MAV_CMD_NAV_TAKEOFF, R.MAV_FRAME_GLOBAL, z=10).result == R.MAV_RESULT_DENIED
    assert c.set_mode("ALT_HOLD").result == R.MAV_RESULT_ACCEPTED
    assert c.command_long(R.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10).result == R.MAV_RESULT_FAILED
    assert c.set_mode("GUIDED").result == R.MAV_RESULT_ACCEPTED
    assert c.command_int(R.MAV_CMD_NAV_TAKEOFF, R.MAV_FRAME_GLOBAL_RELATIVE_ALT, z=10).result == R.MAV_RESULT_ACCEPTED
    sa.wait_for(lambda: sa.v.alt > 1.0, timeout=10, what="climbing")


def test_armed_on_ground_disarms_after_disarm_delay(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    ready(sa, c)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    c.wait("HEARTBEAT", lambda m: not m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, timeout=15)
    arm, = sa.rec.of("arm")
    disarm, = sa.rec.of("disarm")
    assert disarm.data["reason"] == "disarm_delay"
    # DISARM_DELAY default 10 s (ArduCopter Parameters.cpp); measured on the simulated clock
    assert disarm.sim - arm.sim == pytest.approx(10.0, abs=0.3)


def test_take_off_prevents_auto_disarm_and_climbs_at_wpnav_speed_up(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    airborne(sa, c, alt=10.0)
    tk, = sa.rec.of("takeoff")
    done, = sa.rec.of("takeoff_complete")
    # 10 m at WPNAV_SPEED_UP 250 cm/s = 4.0 s
    assert done.sim - tk.sim == pytest.approx(4.0, abs=0.3)
    sa.wait_sim(12.0, timeout=20)
    assert sa.v.armed and not sa.v.landed
    assert not sa.rec.of("disarm")


def test_takeoff_refused_when_disarmed(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    ready(sa, c)
    ack = c.command_long(mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    assert ack.result == mavlink.MAV_RESULT_FAILED


def test_set_mode_message_is_acked_with_command_11(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    t0 = time.monotonic()
    c.mav.set_mode_send(1, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5)      # LOITER
    ack = c.wait("COMMAND_ACK", since=t0)
    # GCS_MAVLINK::handle_set_mode acks the SET_MODE message with command = its message id, 11
    assert ack.command == 11 and ack.result == mavlink.MAV_RESULT_ACCEPTED
    c.wait("HEARTBEAT", lambda m: m.custom_mode == 5, timeout=5)


def test_guided_requires_position_once_armed(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    airborne(sa, c)
    t0 = time.monotonic()
    assert c.param_set("SIM_GPS_DISABLE", 1).param_value == 1
    # EKF loses the absolute position after the dead-reckoning time, EKF failsafe lands (FS_EKF_ACTION=1)
    c.wait("HEARTBEAT", lambda m: m.custom_mode == 9, timeout=10, since=t0)
    assert c.set_mode("GUIDED").result == mavlink.MAV_RESULT_FAILED
    assert any("requires position" in e.data["text"] for e in sa.rec.of("statustext"))
    assert any(e.data["reason"] == "ekf_failsafe" for e in sa.mode_changes())


# ------------------------------------------------------------------------------------------------
# mission protocol (libraries/GCS_MAVLink/MissionItemProtocol*.cpp)
# ------------------------------------------------------------------------------------------------

def square(alt=10.0, side=30.0):
    lat0, lon0 = HOME
    a = offset(lat0, lon0, side, 0)
    b = offset(lat0, lon0, side, side)
    return [
        wp(lat0, lon0, 0, frame=mavlink.MAV_FRAME_GLOBAL),                 # seq 0: home placeholder
        wp(0, 0, alt, command=mavlink.MAV_CMD_NAV_TAKEOFF),
        wp(a[0], a[1], alt),
        wp(b[0], b[1], alt),
        wp(0, 0, 0, command=mavlink.MAV_CMD_NAV_LAND),
    ]


def test_mission_upload_uses_legacy_mission_request_and_download_returns_home_at_seq0(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    items = square()
    t0 = time.monotonic()
    ack = c.upload_mission(items)
    assert ack.type == mavlink.MAV_MISSION_ACCEPTED
    # MissionItemProtocol::queued_request_send asks with the legacy MISSION_REQUEST, one per item
    reqs = c.since(t0, "MISSION_REQUEST")
    assert sorted({m.seq for m in reqs}) == list(range(len(items)))
    assert not c.since(t0, "MISSION_REQUEST_INT")
    assert any(m.text == "Flight plan received" for m in c.since(t0, "STATUSTEXT"))

    # download: count includes home; seq 0 is home in an absolute frame
    t1 = time.monotonic()
    c.mav.mission_request_list_send(1, 1, 0)
    cnt = c.wait("MISSION_COUNT", since=t1)
    assert cnt.count == len(items)
    c.mav.mission_request_int_send(1, 1, 0, 0)
    home = c.wait("MISSION_ITEM_INT", lambda m: m.seq == 0, since=t1)
    assert home.frame == mavlink.MAV_FRAME_GLOBAL
    assert home.x == round(HOME[0] * 1e7) and home.y == round(HOME[1] * 1e7)
    assert home.z == pytest.approx(sap.HOME_ALT_AMSL)
    c.mav.mission_request_int_send(1, 1, 2, 0)
    it2 = c.wait("MISSION_ITEM_INT", lambda m: m.seq == 2, since=t1)
    assert it2.x == int(items[2]["lat"] * 1e7) and it2.y == int(items[2]["lon"] * 1e7)
    assert it2.command == mavlink.MAV_CMD_NAV_WAYPOINT and it2.z == pytest.approx(10.0)
    # legacy MISSION_REQUEST is answered with a float MISSION_ITEM, and warned about once
    c.mav.mission_request_send(1, 1, 3, 0)
    it3 = c.wait("MISSION_ITEM", lambda m: m.seq == 3, since=t1)
    # float32 degrees keep ~1e-5 deg at longitude 149 (the reason MISSION_ITEM_INT exists)
    assert it3.x == pytest.approx(items[3]["lat"], abs=2e-5) and it3.y == pytest.approx(items[3]["lon"], abs=2e-5)
    assert any("MISSION_REQUEST_INT" in m.text for m in c.since(t1, "STATUSTEXT"))
    upload, = sa.mission_uploads()
    assert [i["command"] for i in upload.data["items"]] == [16, 22, 16, 16, 21]


def test_mission_request_int_option_and_float_items_accepted(standin, client):
    sa = standin(mission_request_int=True, **FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    t0 = time.monotonic()
    assert c.upload_mission(square(), use_int=False).type == mavlink.MAV_MISSION_ACCEPTED
    assert len(c.since(t0, "MISSION_REQUEST_INT")) >= 5 and not c.since(t0, "MISSION_REQUEST")
    # a MISSION_ITEM upload is converted and warned about (GCS_MAVLINK::handle_mission_item)
    assert any("MISSION_ITEM_INT" in m.text for m in c.since(t0, "STATUSTEXT"))


def test_mission_errors_out_of_range_wrong_sequence_other_uploader_clear(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    other = client(sa.url, sysid=254, compid=190)
    c.wait("HEARTBEAT", timeout=5)
    assert c.upload_mission(square()).type == mavlink.MAV_MISSION_ACCEPTED
    # request past the end: MISSION_COUNT "to educate the GCS" then MAV_MISSION_ERROR
    t0 = time.monotonic()
    c.mav.mission_request_int_send(1, 1, 9, 0)
    assert c.wait("MISSION_COUNT", since=t0).count == 5
    assert c.wait("MISSION_ACK", since=t0).type == mavlink.MAV_MISSION_ERROR
    # start an upload, answer with the wrong seq: INVALID_SEQUENCE and the transfer stays open
    t1 = time.monotonic()
    c.mav.mission_count_send(1, 1, 3, 0)
    c.wait("MISSION_REQUEST", lambda m: m.seq == 0, since=t1)
    c.mav.mission_item_int_send(1, 1, 1, 6, 16, 0, 1, 0, 0, 0, 0, 0, 0, 10, 0)
    assert c.wait("MISSION_ACK", since=t1).type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    # someone else uploading meanwhile is DENIED, downloading meanwhile too
    t2 = time.monotonic()
    other.mav.mission_count_send(1, 1, 2, 0)
    assert other.wait("MISSION_ACK", since=t2).type == mavlink.MAV_MISSION_DENIED
    t_list = time.monotonic()          # before the request: its answer cannot come before it
    other.mav.mission_request_list_send(1, 1, 0)
    assert other.wait("MISSION_ACK", since=t_list).type == mavlink.MAV_MISSION_DENIED
    # finish the open upload correctly
    for seq in range(3):
        c.mav.mission_item_int_send(1, 1, seq, 6, 16, 0, 1, 0, 0, 0, 0, int(HOME[0] * 1e7), int(HOME[1] * 1e7), 10, 0)
        time.sleep(0.05)
    assert c.wait("MISSION_ACK", lambda m: m.type == mavlink.MAV_MISSION_ACCEPTED, since=t2, timeout=5)
    # clear: ACCEPTED, and only home remains
    t3 = time.monotonic()
    c.mav.mission_clear_all_send(1, 1, 0)
    assert c.wait("MISSION_ACK", since=t3).type == mavlink.MAV_MISSION_ACCEPTED
    c.mav.mission_request_list_send(1, 1, 0)
    assert c.wait("MISSION_COUNT", since=t3).count == 1


def test_mission_upload_times_out_with_operation_cancelled(standin, client, monkeypatch):
    monkeypatch.setattr(mission_protocol, "MISSION_UPLOAD_TIMEOUT_S", 1.5)   # ArduPilot's 8 s, shortened for the test
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    t0 = time.monotonic()
    c.mav.mission_count_send(1, 1, 4, 0)
    ack = c.wait("MISSION_ACK", since=t0, timeout=6)
    assert ack.type == mavlink.MAV_MISSION_OPERATION_CANCELLED
    # ArduPilot sends the ack, then the text: wait for it rather than read what arrived with the ack
    c.wait("STATUSTEXT", lambda m: m.text == "Mission upload timeout", since=t0, timeout=2)
    # requests were re-sent (every ~1 s) while waiting
    assert len([m for m in c.since(t0, "MISSION_REQUEST") if m.seq == 0]) >= 2


def test_set_current_and_mission_current(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    c.upload_mission(square())
    t0 = time.monotonic()
    c.mav.mission_set_current_send(1, 1, 3)
    mc = c.wait("MISSION_CURRENT", lambda m: m.seq == 3, since=t0, timeout=5)
    assert mc.total == 4          # MISSION_CURRENT.total excludes home
    c.mav.mission_request_int_send(1, 1, 3, 0)
    assert c.wait("MISSION_ITEM_INT", lambda m: m.seq == 3, since=t0).current == 1


def test_auto_mission_flies_waypoints_lands_and_disarms(standin, client):
    sa = standin(speedup=8.0, ekf_ready_s=8.0)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    c.upload_mission(square(alt=10.0, side=30.0))
    ready(sa, c)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    # AUTO on the ground, armed, mission starts with NAV_TAKEOFF; MISSION_START launches it
    assert c.command_long(mavlink.MAV_CMD_MISSION_START).result == mavlink.MAV_RESULT_ACCEPTED
    sa.wait_for(lambda: not sa.v.armed, timeout=60, what="mission end and disarm")
    reached = [e.data["seq"] for e in sa.rec.of("mission_item_reached")]
    assert reached == [1, 2, 3, 4]
    landed, = sa.rec.of("landed")
    # landed at the last waypoint (30 m N, 30 m E): within WPNAV_RADIUS 2 m, checked once per physics
    # sub-step (at most 0.05 s of sim time), so plus one sub-step of travel at 5 m/s (seen: 2.0003 m under load)
    assert math.hypot(landed.data["north"] - 30, landed.data["east"] - 30) < 2.0 + 5.0 * 0.05
    assert sa.rec.of("disarm")[-1].data["reason"] == "landed"
    assert sa.v.max_alt == pytest.approx(10.0, abs=0.3)
    # flight time is hand-computable: climb 10 m @2.5 (4 s) + 30 m and 30 m @5 m/s less the 2 m radii (~11.2 s)
    # + descent 10 m: 0 m above LAND_ALT_LOW then 10 m @0.5 m/s (20 s) = ~35 s, plus 1 s before disarm
    flight = sa.rec.of("disarm")[-1].sim - sa.rec.of("mode")[-1].sim
    assert 30.0 < flight < 42.0


def test_auto_refused_on_ground_without_takeoff_item(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    items = square()
    del items[1]                                  # no NAV_TAKEOFF first
    c.upload_mission(items)
    ready(sa, c)
    assert c.arm().result == mavlink.MAV_RESULT_ACCEPTED
    t0 = time.monotonic()
    assert c.set_mode("AUTO").result == mavlink.MAV_RESULT_FAILED
    # Since t0, not before it: the upload's "Flight plan received" may have come just before t0 (ready() returns at
    # once when the EKF converged during the upload), and the refusal's text is sent after t0 (before its ack).
    assert c.wait("STATUSTEXT", since=t0).text == "Auto: Missing Takeoff Cmd"   # ModeAuto::init


def test_rtl_returns_home_lands_and_disarms(standin, client):
    sa = standin(speedup=8.0, ekf_ready_s=8.0)
    c = client(sa.url)
    airborne(sa, c, alt=5.0)
    lat, lon = offset(HOME[0], HOME[1], 40, 0)
    ack = c.command_int(mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, -1, 0, 0, 0,
                        int(lat * 1e7), int(lon * 1e7), 5)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    sa.wait_for(lambda: sa.v.north > 39, timeout=20, what="reposition")
    assert c.command_long(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == mavlink.MAV_RESULT_ACCEPTED
    sa.wait_for(lambda: not sa.v.armed, timeout=60, what="RTL landing")
    # RTL climbs to RTL_ALT (15 m) before returning
    assert sa.v.max_alt == pytest.approx(15.0, abs=0.3)
    landed = sa.rec.of("landed")[-1]
    assert math.hypot(landed.data["north"], landed.data["east"]) < 2.0


def test_reposition_outside_guided_without_change_mode_flag_is_denied(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    airborne(sa, c)
    assert c.set_mode("LOITER").result == mavlink.MAV_RESULT_ACCEPTED
    ack = c.command_int(mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, -1, 0, 0, 0,
                        int(HOME[0] * 1e7), int(HOME[1] * 1e7), 10)
    assert ack.result == mavlink.MAV_RESULT_DENIED
    ack = c.command_int(mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, -1,
                        mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE, 0, 0, int(HOME[0] * 1e7), int(HOME[1] * 1e7), 10)
    assert ack.result == mavlink.MAV_RESULT_ACCEPTED
    c.wait("HEARTBEAT", lambda m: m.custom_mode == 4, timeout=5)


def test_set_position_target_only_in_guided(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    airborne(sa, c)
    c.set_mode("LOITER")
    c.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, 20, 0, -10, 0, 0, 0, 0, 0, 0, 0, 0)
    sa.wait_sim(3, timeout=10)
    assert abs(sa.v.north) < 0.5
    c.set_mode("GUIDED")
    c.mav.set_position_target_local_ned_send(0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, 0b110111111000, 20, 0, -10, 0, 0, 0, 0, 0, 0, 0, 0)
    sa.wait_for(lambda: sa.v.north > 19.9, timeout=20, what="guided position target")


# ------------------------------------------------------------------------------------------------
# message intervals and stream slowdown
# ------------------------------------------------------------------------------------------------

def test_set_message_interval_get_disable_and_unknown(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    gpi = mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, 50000).result == mavlink.MAV_RESULT_ACCEPTED
    t0 = time.monotonic()
    assert c.command_long(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, gpi).result == mavlink.MAV_RESULT_ACCEPTED
    assert c.wait("MESSAGE_INTERVAL", since=t0).interval_us == 50000
    fast = len(c.since(time.monotonic() - 0.01, "GLOBAL_POSITION_INT"))
    t1 = time.monotonic()
    time.sleep(2.0)
    n_fast = len(c.since(t1, "GLOBAL_POSITION_INT"))
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, 1000000).result == mavlink.MAV_RESULT_ACCEPTED
    t2 = time.monotonic()
    time.sleep(2.0)
    n_slow = len(c.since(t2, "GLOBAL_POSITION_INT"))
    assert n_fast > 3 * n_slow, (n_fast, n_slow)         # 20 Hz vs 1 Hz
    # -1 disables the message
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, -1).result == mavlink.MAV_RESULT_ACCEPTED
    time.sleep(0.3)
    assert c.none_within("GLOBAL_POSITION_INT", 1.5)
    # 0 restores the default
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, gpi, 0).result == mavlink.MAV_RESULT_ACCEPTED
    c.wait("GLOBAL_POSITION_INT", timeout=3)
    # an id with no ap_message mapping fails with ArduPilot's STATUSTEXT
    t3 = time.monotonic()
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 12345, 100000).result == mavlink.MAV_RESULT_FAILED
    assert c.wait("STATUSTEXT", since=t3).text == "No ap_message for mavlink id (12345)"
    del fast


def test_streams_slow_down_while_requesting_mission_items(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    ss = mavlink.MAVLINK_MSG_ID_SYS_STATUS
    c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, ss, 100000)      # 10 Hz
    t0 = time.monotonic()
    time.sleep(2.0)
    normal = len(c.since(t0, "SYS_STATUS"))
    c.mav.mission_count_send(1, 1, 3, 0)                                   # open an upload, answer nothing
    c.wait("MISSION_REQUEST", timeout=3)
    t1 = time.monotonic()
    time.sleep(2.0)
    during = len(c.since(t1, "SYS_STATUS"))
    hb_during = len(c.since(t1, "HEARTBEAT"))
    # get_reschedule_interval_ms: interval *= 4 while requesting items (10 Hz -> 2.5 Hz); heartbeats unaffected
    assert during < normal / 2, (normal, during)
    assert hb_during >= 1


# ------------------------------------------------------------------------------------------------
# telemetry and hazard injection
# ------------------------------------------------------------------------------------------------

def test_wind_only_in_flight_and_follows_sim_wind_spd(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    assert c.param_set("SIM_WIND_SPD", 7.5).param_value == pytest.approx(7.5)
    assert c.param_set("SIM_WIND_DIR", 90).param_value == pytest.approx(90)
    assert c.none_within("WIND", 1.5)                     # on the ground: none
    airborne(sa, c, alt=5.0)
    w = c.wait("WIND", timeout=5)
    assert w.speed == pytest.approx(7.5) and w.direction == pytest.approx(90)
    c.command_long(mavlink.MAV_CMD_NAV_LAND)
    sa.wait_for(lambda: not sa.v.armed, timeout=30, what="land")
    time.sleep(0.3)
    assert c.none_within("WIND", 1.5)


def test_vibration_battery_obstacle_and_gps_hazards_change_telemetry(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    airborne(sa, c, alt=10.0)
    # vibration: quiet in flight, then SIM_VIB_MOT_MAX raises VIBRATION above ArduPilot's 30 m/s/s "bad" line
    quiet = c.wait("VIBRATION", timeout=5)
    assert max(quiet.vibration_x, quiet.vibration_y, quiet.vibration_z) < 15
    # Each check reads the first message that arrived after the PARAM_VALUE answering the change (the stand-in
    # applies the parameter, then sends PARAM_VALUE, handlers.py `_h_PARAM_SET`; one link, in order): a time taken
    # before the PARAM_SET, even plus 50 ms, lets a message built before the change through when this reader is late.
    c.param_set("SIM_VIB_MOT_MAX", 400)
    t0 = time.monotonic()
    loud = c.wait("VIBRATION", since=t0, timeout=5)
    assert max(loud.vibration_x, loud.vibration_y, loud.vibration_z) > 30
    # battery: set 18 % -> SYS_STATUS / BATTERY_STATUS follow, and the charge state turns LOW
    c.param_set("SIM_BATT_PCT", 18)
    t1 = time.monotonic()
    ss = c.wait("SYS_STATUS", since=t1, timeout=5)
    assert 14 <= ss.battery_remaining <= 18             # it keeps draining (~1 %/wall s at speedup 10)
    bs = c.wait("BATTERY_STATUS", since=t1, timeout=5)
    assert 14 <= bs.battery_remaining <= 18 and bs.charge_state == mavlink.MAV_BATTERY_CHARGE_STATE_LOW
    # obstacle 12 m ahead: DISTANCE_SENSOR reads it in cm, forward
    t2 = time.monotonic()
    c.param_set("SIM_OBST_DIST", 12)
    ds = c.wait("DISTANCE_SENSOR", lambda m: m.current_distance <= 4000, since=t2, timeout=5)
    assert ds.current_distance == pytest.approx(1200, abs=30) and ds.orientation == 0
    # GPS off: no fix, GPS health bit cleared, then the EKF drops the absolute position
    c.param_set("SIM_GPS_DISABLE", 1)
    t3 = time.monotonic()
    g = c.wait("GPS_RAW_INT", since=t3, timeout=5)
    assert g.fix_type < 2 and g.satellites_visible == 0
    ss = c.wait("SYS_STATUS", since=t3, timeout=5)
    assert not ss.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_SENSOR_GPS
    c.wait("EKF_STATUS_REPORT", lambda m: not m.flags & mavlink.EKF_POS_HORIZ_ABS, since=t3, timeout=10)


def test_battery_drains_faster_in_flight_than_on_ground(standin, client):
    sa = standin(speedup=10.0, ekf_ready_s=8.0)
    c = client(sa.url)

    def sample():
        with sa.lock:
            return sa._sim, sa.v.consumed_ah

    ready(sa, c)
    t0, q0 = sample()
    sa.wait_sim(10, timeout=10)
    t1, q1 = sample()
    ground_a = (q1 - q0) / (t1 - t0) * 3600          # amps, disarmed
    airborne(sa, c, alt=5.0)
    t2, q2 = sample()
    sa.wait_sim(10, timeout=10)
    t3, q3 = sample()
    hover_a = (q3 - q2) / (t3 - t2) * 3600           # amps, hovering
    assert ground_a == pytest.approx(0.5, rel=0.05)
    assert hover_a == pytest.approx(14.0, rel=0.05)   # stand-in hover current, no wind


def test_obstacle_closes_in_while_flying_towards_it(standin, client):
    sa = standin(speedup=2.0, ekf_ready_s=2.0)
    c = client(sa.url)
    airborne(sa, c, alt=10.0)
    lat, lon = offset(HOME[0], HOME[1], 60, 0)
    c.command_int(mavlink.MAV_CMD_DO_REPOSITION, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, -1, 0, 0, 0,
                  int(lat * 1e7), int(lon * 1e7), 10)
    sa.wait_for(lambda: sa.v.north > 5, timeout=10, what="moving north")
    sa.place_obstacle(30.0)
    d1 = c.wait("DISTANCE_SENSOR", lambda m: m.current_distance <= 4000, timeout=5).current_distance
    sa.wait_sim(2.0, timeout=5)
    d2 = c.wait("DISTANCE_SENSOR", lambda m: m.current_distance <= 4000, since=time.monotonic(), timeout=5).current_distance
    assert d2 < d1 - 500                               # 2 s at 5 m/s: ~10 m closer
    sa.wait_for(lambda: sa.v.collided, timeout=10, what="collision recorded")


# ------------------------------------------------------------------------------------------------
# link robustness: garbage, signing, routing, outages
# ------------------------------------------------------------------------------------------------

def test_garbage_and_malformed_frames_are_counted_and_survived(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    junk = bytes(b for b in os.urandom(600) if b not in (0xFD, 0xFE))[:400]
    c.conn.write(junk)
    good = bytearray(c.mav.heartbeat_encode(6, 8, 0, 0, 0).pack(c.mav))
    good[-1] ^= 0xFF                                    # bad CRC
    c.conn.write(bytes(good))
    time.sleep(0.3)
    assert c.set_mode("LOITER").result == mavlink.MAV_RESULT_ACCEPTED
    assert sa.counters["rx_garbage_bytes"] >= len(junk)
    assert sa.counters["rx_bad_frames"] >= 1
    # and the stand-in's own injections reach the client without breaking it
    sa.inject_garbage(200)
    sa.inject_malformed()
    assert sa.counters["tx_garbage_bytes"] == 200 and sa.counters["tx_malformed_frames"] == 4
    t0 = time.monotonic()
    c.wait("HEARTBEAT", since=t0, timeout=5)


def test_signing_rejects_unsigned_commands(standin, client):
    key = bytes(range(32))
    sa = standin(signing_key=key, **FAST)
    signed = client(sa.url, signing_key=key)
    hb = signed.wait("HEARTBEAT", timeout=5)
    assert hb._signed                                   # everything the stand-in sends is signed
    intruder = client(sa.url, sysid=250)
    intruder.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 6, 0, 0, 0, 0, 0)   # RTL, unsigned
    time.sleep(0.5)
    assert not intruder.since(0, "COMMAND_ACK")
    assert sa.counters["rx_unsigned_rejected"] >= 1
    assert not [e for e in sa.commands() if e.data["src"][0] == 250]
    assert sa.v.mode == 0
    n0 = len(sa.commands(mavlink.MAV_CMD_DO_SET_MODE))
    assert signed.set_mode("LOITER").result == mavlink.MAV_RESULT_ACCEPTED
    # The stand-in records a command after it has sent its COMMAND_ACK (handlers.py `_command`): wait for the record
    sa.wait_for(lambda: len(sa.commands(mavlink.MAV_CMD_DO_SET_MODE)) > n0, timeout=2, what="the DO_SET_MODE recorded")
    assert sa.commands(mavlink.MAV_CMD_DO_SET_MODE)[-1].data["signed"] is True


def test_onboard_monitor_values_are_routed_to_other_links(standin, client):
    sa = standin(**FAST)
    companion = client(sa.url)
    companion.wait("HEARTBEAT", timeout=5)
    mon = sap.OnboardMonitors(sa.url).start()
    try:
        want = dict(tgt_det=1, tgt_spd=12.5, trk_conf=0.8, lum=90, cpu_load=0.7)
        t_set = time.monotonic()
        mon.set(**want)
        # The monitor was already sending its defaults: keep the newest value of each name (in
        # arrival order) until every one shows what was set, or the deadline.
        got = {}
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and any(
                got.get(k) != pytest.approx(v) for k, v in want.items()):
            for m in companion.since(t_set, "NAMED_VALUE_FLOAT"):
                if m.get_srcComponent() == mavlink.MAV_COMP_ID_CAMERA and m.value != 0.0:
                    got[m.name] = m.value
            time.sleep(0.05)
        assert got.get("tgt_det") == 1.0 and got.get("tgt_spd") == pytest.approx(12.5)
        assert got.get("lum") == pytest.approx(90) and got.get("cpu_load") == pytest.approx(0.7)
        # and the monitor hears the autopilot (its vehicle view works against a real SITL too)
        deadline = time.monotonic() + 3
        while time.monotonic() < deadline and mon.snapshot()["heartbeats"] < 1:
            time.sleep(0.05)
        assert mon.snapshot()["heartbeats"] >= 1 and mon.snapshot()["mode"] == "STABILIZE"
    finally:
        mon.stop()


def test_link_outage_silences_both_ways_and_records_dropped(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    sa.link_outage(2.5)
    time.sleep(0.5)                                     # let bytes already in flight drain
    t0 = time.monotonic()
    c.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_SET_MODE, 0, 1, 5, 0, 0, 0, 0, 0)
    time.sleep(1.3)
    assert not c.since(t0)                                 # nothing arrives during the cut
    dropped = sa.received("COMMAND_LONG", include_dropped=True)
    assert dropped and dropped[-1].data["dropped"] is True
    assert sa.v.mode == 0                                   # not acted on
    c.wait("HEARTBEAT", since=t0, timeout=3)                # resumes
    assert c.set_mode("LOITER").result == mavlink.MAV_RESULT_ACCEPTED


def test_udp_listen(standin, client):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    sa = standin(listen=f"udp:127.0.0.1:{port}", **FAST)
    c = client(f"udpout:127.0.0.1:{port}")
    c.mav.heartbeat_send(6, 8, 0, 0, 0)                     # the stand-in replies to the last sender
    assert c.wait("HEARTBEAT", timeout=5).autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA


def test_local_position_ned_is_off_until_requested(standin, client):
    sa = standin(**FAST)
    c = client(sa.url)
    c.wait("HEARTBEAT", timeout=5)
    assert c.none_within("LOCAL_POSITION_NED", 1.0)
    lpn = mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED
    assert c.command_long(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, lpn, 200000).result == mavlink.MAV_RESULT_ACCEPTED
    m = c.wait("LOCAL_POSITION_NED", timeout=3)
    assert (m.x, m.y, m.z) == (0.0, 0.0, 0.0)               # on the ground at home, NED


def test_monitors_set_and_read_parameters_and_request_their_streams(standin):
    """What the hazard tests use on a real SITL: PARAM_SET / PARAM_REQUEST_READ over the monitors' link, and
    SET_MESSAGE_INTERVAL for the telemetry their vehicle view needs (a SITL's SERIAL2 may stream nothing)."""
    sa = standin(**FAST)
    mon = sap.OnboardMonitors(sa.url, request_streams=True).start()
    try:
        sa.wait_for(lambda: mon.snapshot()["heartbeats"] > 0, timeout=10, what="a heartbeat at the monitors")
        assert mon.param_get("SIM_WIND_SPD") == 0.0
        mon.param_set("SIM_WIND_SPD", 7.0)
        sa.wait_for(lambda: sa.params["SIM_WIND_SPD"] == 7.0, timeout=5, what="PARAM_SET applied")
        assert mon.param_get("SIM_WIND_SPD") == 7.0
        sa.wait_for(lambda: len(sa.commands(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)) >= 4, timeout=5, what="intervals")
        asked = {int(e.data["params"][0]) for e in sa.commands(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL)}
        assert asked == {mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
                         mavlink.MAVLINK_MSG_ID_MISSION_CURRENT, mavlink.MAVLINK_MSG_ID_BATTERY_STATUS}
        sa.wait_for(lambda: mon.snapshot()["battery_pct"] is not None, timeout=5, what="BATTERY_STATUS in the view")
    finally:
        mon.stop()
