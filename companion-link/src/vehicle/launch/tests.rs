//! The stop's reading and verdict at each step of a take-off.

use super::super::tests::{
    a, ack, commands, connected, frame, hb, ready_frames, s, take_off_asked_when_ready, vehicle,
};
use super::*;
use crate::modes::ReportedMode;

const CONFIRM: Duration = Duration::from_secs(3);
const GUIDED: u32 = 4;

/// Taking off: GUIDED accepted and shown, the ARM sent at 1.0 s, its answer not yet heard.
fn arm_sent() -> Vehicle {
    let mut v = take_off_asked_when_ready();
    v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    let out = v.on_frame(s(1.0), &hb(GUIDED, false));
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
    assert!(v.launch_awaiting());
    v
}

fn verdict(v: &Vehicle, control: &Control, t: f64) -> StopVerdict {
    stop_verdict(control, &v.stop_reading(s(t), CONFIRM))
}

fn hands_off(verdict: &StopVerdict) -> bool {
    matches!(verdict, StopVerdict::HandOff(_))
}

#[test]
fn a_stop_with_the_arm_unanswered_keeps_it_waits_and_hands_off_once_accepted() {
    let mut v = arm_sent();
    v.stop_commanding(s(1.1), "companion stopping");
    assert!(!v.busy(), "the take-off job ended");
    assert!(
        v.launch_awaiting(),
        "the ARM in flight is kept for its answer"
    );
    let stopped = v.take_records();
    assert!(
        !stopped
            .iter()
            .any(|r| r.command == "ARM" && matches!(r.result, CommandOutcome::Cancelled(_))),
        "the ARM was recorded cancelled although the autopilot may act on it"
    );
    assert!(
        stopped.iter().any(|r| r.command == "MAV_CMD_NAV_TAKEOFF"
            && matches!(r.result, CommandOutcome::Cancelled(_)))
    );
    // Before its answer, the unanswered ARM alone makes the vehicle the companion's to hand off.
    let before = verdict(&v, &Control::Started, 1.2);
    assert!(hands_off(&before), "{before:?}");
    let out = v.on_frame(
        s(1.3),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(
        commands(&out).is_empty(),
        "the take-off went on after the stop: {out:?}"
    );
    assert!(!v.launch_awaiting());
    // No heartbeat has said armed yet: the accepted ARM is enough.
    assert!(!v.readiness.armed);
    assert_eq!(
        verdict(&v, &Control::Started, 1.4),
        StopVerdict::HandOff(vec!["its ARM accepted".into()])
    );
    // The ARM's answer is recorded.
    assert!(
        v.take_records()
            .iter()
            .any(|r| r.command == "ARM" && r.result == CommandOutcome::Accepted)
    );
}

#[test]
fn a_refused_arm_leaves_nothing_to_hand_off() {
    let mut v = arm_sent();
    v.stop_commanding(s(1.1), "companion stopping");
    v.on_frame(
        s(1.3),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_DENIED,
        ),
    );
    assert!(!v.launch_awaiting());
    assert_eq!(verdict(&v, &Control::Started, 1.4), StopVerdict::Down);
}

#[test]
fn an_arm_never_answered_counts_as_armed_and_is_not_resent() {
    let mut v = arm_sent();
    v.stop_commanding(s(1.1), "companion stopping");
    let mut sent = Vec::new();
    for t in [1.5, 2.0, 2.6, 3.5, 5.0] {
        sent.extend(commands(&v.tick(s(t))));
    }
    assert!(sent.is_empty(), "resent during the stop: {sent:?}");
    assert!(!v.launch_awaiting(), "the ARM's one attempt timed out");
    let got = verdict(&v, &Control::Started, 5.1);
    assert_eq!(
        got,
        StopVerdict::HandOff(vec!["its ARM unanswered (no answer)".into()])
    );
}

#[test]
fn an_arm_still_waiting_for_readiness_is_cancelled_and_never_sent() {
    let mut v = vehicle();
    connected(&mut v, GUIDED);
    v.on_frame(s(0.1), &frame(Msg::SYS_STATUS(SYS_STATUS_DATA::DEFAULT)));
    v.request_actions(s(0.2), &[a("take_off")]);
    v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    let mut out = v.on_frame(s(1.0), &hb(GUIDED, false));
    out.extend(v.tick(s(1.1)));
    assert!(commands(&out).is_empty(), "armed while not ready");
    assert!(
        v.take_records()
            .iter()
            .any(|r| r.command == "ARM" && matches!(r.result, CommandOutcome::WaitingReady(_)))
    );
    v.stop_commanding(s(1.2), "companion stopping");
    assert!(!v.launch_awaiting());
    // The autopilot becomes ready: nothing is armed by a stopped companion.
    let mut out = Vec::new();
    for f in ready_frames() {
        out.extend(v.on_frame(s(2.0), &f));
    }
    out.extend(v.on_frame(s(2.1), &hb(GUIDED, false)));
    out.extend(v.tick(s(2.2)));
    assert!(commands(&out).is_empty(), "armed after the stop: {out:?}");
    assert_eq!(verdict(&v, &Control::Started, 2.3), StopVerdict::Down);
}

#[test]
fn an_accepted_take_off_hands_off_before_any_heartbeat_says_armed() {
    let mut v = arm_sent();
    let out = v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
    v.on_frame(
        s(1.3),
        &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
    );
    v.stop_commanding(s(1.4), "companion stopping");
    assert!(!v.launch_awaiting());
    assert_eq!(
        verdict(&v, &Control::Started, 1.5),
        StopVerdict::HandOff(vec![
            "its ARM accepted".into(),
            "its take-off accepted".into()
        ])
    );
    // A start the gate voided (a disarmed heartbeat, spoofed or stale) does not hide it.
    assert!(hands_off(&verdict(&v, &Control::Waiting, 1.5)));
    // A pilot's confirmed takeover does: the pilot flies.
    let taken = Control::TakenOver {
        mode: ReportedMode::Known(FlightMode::Loiter),
    };
    assert!(!hands_off(&verdict(&v, &taken, 1.5)));
    v.on_frame(s(1.6), &hb(GUIDED, true));
    assert!(matches!(
        verdict(&v, &taken, 1.7),
        StopVerdict::NotCommanding(_)
    ));
}

#[test]
fn one_armed_heartbeat_is_enough_for_the_stop() {
    let mut v = vehicle();
    connected(&mut v, GUIDED);
    v.on_frame(s(1.0), &hb(GUIDED, true));
    // One heartbeat: far from the start's confirmation (two, over 2 s), enough for the stop.
    assert!(v.armed_for(s(1.1)) < Some(Duration::from_secs(2)));
    assert_eq!(
        verdict(&v, &Control::Started, 1.1),
        StopVerdict::HandOff(vec!["the autopilot reported it armed".into()])
    );
    // Not started, nothing launched: the vehicle is not the companion's to hand off.
    assert!(matches!(
        verdict(&v, &Control::Waiting, 1.1),
        StopVerdict::NotCommanding(_)
    ));
    // A later disarmed heartbeat does not clear it until the ground is confirmed.
    v.on_frame(s(1.5), &hb(GUIDED, false));
    assert!(hands_off(&verdict(&v, &Control::Started, 2.0)));
    // Not the companion's to hand off: its words follow the last heartbeat.
    assert_eq!(verdict(&v, &Control::Waiting, 2.0), StopVerdict::Down);
    // Every frame agreed for landed_confirm_s: down.
    assert_eq!(verdict(&v, &Control::Started, 4.6), StopVerdict::Down);
}

#[test]
fn a_position_in_the_air_is_enough_for_the_stop() {
    let mut v = vehicle();
    connected(&mut v, GUIDED);
    v.on_frame(
        s(1.0),
        &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            relative_alt: 3_000,
            lat: 473_977_000,
            lon: 85_455_000,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        })),
    );
    assert_eq!(
        verdict(&v, &Control::Started, 1.1),
        StopVerdict::HandOff(vec!["the autopilot reported it in the air".into()])
    );
}

#[test]
fn a_flight_landed_and_confirmed_down_is_not_handed_off() {
    let mut v = arm_sent();
    v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    v.on_frame(
        s(1.3),
        &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
    );
    v.on_frame(s(2.0), &hb(GUIDED, true));
    // Landed and disarmed (no position: on the ground by default) at 60 s.
    v.on_frame(s(60.0), &hb(GUIDED, false));
    let in_window = verdict(&v, &Control::Started, 62.0);
    assert!(hands_off(&in_window), "{in_window:?}");
    assert_eq!(verdict(&v, &Control::Started, 63.1), StopVerdict::Down);
    // A new ARM sent after that counts again.
    let mut w = arm_sent();
    w.on_frame(s(30.0), &hb(GUIDED, false));
    assert!(hands_off(&verdict(&w, &Control::Started, 30.0)));
}

#[test]
fn a_take_off_in_flight_at_the_stop_is_never_resent_and_counts_unanswered() {
    let mut v = arm_sent();
    let out = v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
    v.stop_commanding(s(1.3), "companion stopping");
    assert!(
        v.launch_awaiting(),
        "the take-off in flight is kept for its answer"
    );
    let mut sent = Vec::new();
    for t in [2.0, 2.8, 3.5, 4.5, 6.0] {
        sent.extend(commands(&v.tick(s(t))));
    }
    assert!(sent.is_empty(), "resent during the stop: {sent:?}");
    assert_eq!(
        verdict(&v, &Control::Started, 6.1),
        StopVerdict::HandOff(vec![
            "its ARM accepted".into(),
            "its take-off unanswered (no answer)".into()
        ])
    );
}

#[test]
fn launch_commands_are_arm_and_take_off_only() {
    let long = |c: MavCmd, p1: f32| CommandSpec::long(c, [p1, 0., 0., 0., 0., 0., 0.]);
    let of = |c: MavCmd, p1: f32| LaunchCommand::of(&long(c, p1));
    assert_eq!(
        of(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0),
        Some(LaunchCommand::Arm)
    );
    assert_eq!(of(MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0.0), None);
    assert_eq!(
        of(MavCmd::MAV_CMD_NAV_TAKEOFF, 0.0),
        Some(LaunchCommand::TakeOff)
    );
    assert_eq!(
        of(MavCmd::MAV_CMD_MISSION_START, 0.0),
        Some(LaunchCommand::TakeOff)
    );
    assert_eq!(of(MavCmd::MAV_CMD_DO_SET_MODE, 1.0), None);
    assert_eq!(of(MavCmd::MAV_CMD_DO_REPOSITION, -1.0), None);
}

#[test]
fn an_arm_accepted_before_a_refused_take_off_still_hands_off() {
    let mut v = arm_sent();
    v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    v.on_frame(
        s(1.3),
        &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_FAILED),
    );
    v.stop_commanding(s(1.4), "companion stopping");
    // The gate voids the start (the take-off failed): the armed vehicle is still the companion's.
    assert_eq!(
        verdict(&v, &Control::Waiting, 1.5),
        StopVerdict::HandOff(vec!["its ARM accepted".into()])
    );
}
