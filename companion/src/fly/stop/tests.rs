//! The stop's words and hand-off in the shell, at the steps of a take-off.

use super::*;
use crate::fly::{FlyArgs, FlySetup};
use companion_link::actions::Flown;
use companion_link::dialect::*;
use companion_link::ingest::Frame;
use companion_link::modes::{FlightMode, ReportedMode};
use companion_link::operator::OperatorGate;
use mavlink::{MavHeader, MavlinkVersion};

const CONFIRM: Duration = Duration::from_secs(3);

fn s(v: f64) -> Duration {
    Duration::from_secs_f64(v)
}

fn frame(msg: Msg) -> Frame {
    Frame {
        header: MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        },
        msg,
        signed: false,
        version: MavlinkVersion::V2,
        raw: Vec::new(),
    }
}

/// ArduCopter's GUIDED and RTL custom modes.
const GUIDED: u32 = 4;
const RTL: f32 = 6.0;

fn hb(armed: bool) -> Frame {
    let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
    if armed {
        base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: GUIDED,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: base,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    }))
}

fn ack(command: MavCmd, result: MavResult) -> Frame {
    frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        ..COMMAND_ACK_DATA::DEFAULT
    }))
}

fn ready() -> Vec<Frame> {
    let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
    vec![
        frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: bit,
            onboard_control_sensors_enabled: bit,
            onboard_control_sensors_health: bit,
            ..SYS_STATUS_DATA::DEFAULT
        })),
        frame(Msg::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
            flags: EkfStatusFlags::EKF_ATTITUDE
                | EkfStatusFlags::EKF_VELOCITY_HORIZ
                | EkfStatusFlags::EKF_POS_HORIZ_ABS
                | EkfStatusFlags::EKF_POS_VERT_ABS,
            ..EKF_STATUS_REPORT_DATA::DEFAULT
        })),
    ]
}

fn commands(out: &[Msg]) -> Vec<(MavCmd, f32)> {
    out.iter()
        .filter_map(|m| match m {
            Msg::COMMAND_LONG(c) => Some((c.command, c.param2)),
            _ => None,
        })
        .collect()
}

fn texts(out: &[Msg]) -> Vec<String> {
    out.iter()
        .filter_map(|m| match m {
            Msg::STATUSTEXT(t) => Some(t.text.to_str().unwrap_or("").to_string()),
            _ => None,
        })
        .collect()
}

/// The shipped params' shell, started, and a vehicle (ArduCopter in GUIDED, ready, disarmed)
/// whose take-off has sent its ARM (answer not heard).
fn arm_sent() -> (Shell, Vehicle) {
    let args = FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550"]).unwrap();
    let setup = FlySetup::load(&args).unwrap();
    let mut shell = Shell::new(&setup);
    shell.operator = OperatorGate::started();
    let mut v = setup.vehicle(Duration::from_secs(3));
    let take_off = setup
        .catalogue
        .id(setup
            .states
            .actions()
            .action(companion_core::action_role::ActionRole::TakeOff))
        .expect("a take-off action");
    v.on_frame(s(0.0), &hb(false));
    for f in ready() {
        v.on_frame(s(0.1), &f);
    }
    // The mode step (sent and acknowledged, or already shown), then ARM.
    let mut out = v.request_actions(s(0.2), &[Flown::Action(take_off)]);
    out.extend(v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    ));
    out.extend(v.on_frame(s(1.0), &hb(false)));
    assert!(
        commands(&out)
            .iter()
            .any(|c| c.0 == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        "{out:?}"
    );
    (shell, v)
}

#[test]
fn a_stop_after_its_arm_was_accepted_hands_off_before_any_armed_heartbeat() {
    let (mut shell, mut v) = arm_sent();
    v.stop_commanding(s(1.1), "companion stopping");
    v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    let (out, stopped) = begin_stop(&mut shell, &mut v, Handoff::Rtl, "SIGINT", s(1.3), CONFIRM);
    assert_eq!(
        stopped,
        Stopped {
            commanded: true,
            up: true,
            was_commanding: true
        }
    );
    assert_eq!(texts(&out), vec!["Companion stopping: RTL, take over"]);
    assert_eq!(
        commands(&out),
        vec![(MavCmd::MAV_CMD_DO_SET_MODE, RTL)],
        "the hand-off mode"
    );
    let said: Vec<String> = shell.pending_events.iter().map(|e| e.to_string()).collect();
    assert!(
        said.iter().any(|e| e.contains("(SIGINT)")
            && e.contains("its ARM accepted")
            && e.contains("hand-off RTL")),
        "{said:?}"
    );
    assert_eq!(shell.operator.control, Control::Stopping);
}

#[test]
fn a_stop_after_its_arm_was_refused_says_so_and_commands_nothing() {
    let (mut shell, mut v) = arm_sent();
    v.stop_commanding(s(1.1), "companion stopping");
    v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_DENIED,
        ),
    );
    let (out, stopped) = begin_stop(&mut shell, &mut v, Handoff::Rtl, "SIGTERM", s(1.3), CONFIRM);
    assert!(!stopped.commanded && !stopped.up && stopped.was_commanding);
    assert_eq!(texts(&out), vec!["Companion stopping"]);
    assert!(commands(&out).is_empty(), "{out:?}");
    let said: Vec<String> = shell.pending_events.iter().map(|e| e.to_string()).collect();
    assert!(
        said.iter().any(|e| e
            == "companion stopping (SIGTERM); the vehicle is disarmed (the autopilot refused its ARM: DENIED)"),
        "{said:?}"
    );
    // The record holds the stop by kind, with its fields.
    assert!(
        shell.pending_events.iter().any(|e| matches!(e,
            Event::Stop(StopEvent::Down { why, refused })
                if why == "SIGTERM" && refused == &[("ARM".to_string(), "DENIED".to_string())])),
        "{:?}",
        shell.pending_events
    );
}

#[test]
fn a_stop_with_handoff_none_says_the_vehicle_continues() {
    let (mut shell, mut v) = arm_sent();
    v.on_frame(s(1.1), &hb(true));
    v.stop_commanding(s(1.2), "companion stopping");
    let (out, stopped) = begin_stop(&mut shell, &mut v, Handoff::None, "SIGINT", s(1.3), CONFIRM);
    assert_eq!(
        stopped,
        Stopped {
            commanded: false,
            up: true,
            was_commanding: true
        }
    );
    assert_eq!(
        texts(&out),
        vec!["Companion stopping: vehicle continues, take over"]
    );
    assert!(commands(&out).is_empty());
    assert!(
        shell.pending_events.iter().any(|e| matches!(e,
            Event::Stop(StopEvent::NoHandOff { why, up, .. }) if why == "SIGINT" && !up.is_empty())),
        "{:?}",
        shell.pending_events
    );
}

#[test]
fn a_pilot_who_took_over_is_left_flying() {
    let (mut shell, mut v) = arm_sent();
    v.on_frame(s(1.1), &hb(true));
    v.stop_commanding(s(1.2), "companion stopping");
    shell.operator.control = Control::TakenOver {
        mode: ReportedMode::Known(FlightMode::Loiter),
    };
    let (out, stopped) = begin_stop(&mut shell, &mut v, Handoff::Rtl, "SIGINT", s(1.3), CONFIRM);
    assert!(!stopped.commanded && stopped.up);
    assert_eq!(texts(&out), vec!["Companion stopping: not commanding"]);
    assert!(commands(&out).is_empty());
    assert!(
        shell.pending_events.iter().any(|e| matches!(e,
            Event::Stop(StopEvent::NotCommanding { why, was, .. }) if why == "SIGINT" && !was.is_empty())),
        "{:?}",
        shell.pending_events
    );
}

#[test]
fn a_refused_or_unanswered_hand_off_is_said_to_the_ground_station() {
    for (answer, said) in [
        (
            Some(MavResult::MAV_RESULT_FAILED),
            "Companion: hand-off refused, take over",
        ),
        (None, "Companion: hand-off unanswered, take over"),
    ] {
        let (mut shell, mut v) = arm_sent();
        v.on_frame(s(1.1), &hb(true));
        v.stop_commanding(s(1.2), "companion stopping");
        let (_, stopped) = begin_stop(&mut shell, &mut v, Handoff::Rtl, "SIGINT", s(1.3), CONFIRM);
        assert!(stopped.commanded);
        if let Some(result) = answer {
            v.on_frame(s(1.4), &ack(MavCmd::MAV_CMD_DO_SET_MODE, result));
        }
        let out = end_stop(&mut shell, &v, true, s(6.0));
        assert_eq!(texts(&out), vec![said]);
        let outcome = if answer.is_some() {
            StopEvent::HandOffFailed
        } else {
            StopEvent::HandOffUnanswered
        };
        assert!(
            shell.pending_events.contains(&Event::Stop(outcome)),
            "{:?}",
            shell.pending_events
        );
    }
    // Accepted: the record says so; the ground station already has the stop's words.
    let (mut shell, mut v) = arm_sent();
    v.on_frame(s(1.1), &hb(true));
    let (_, stopped) = begin_stop(&mut shell, &mut v, Handoff::Rtl, "SIGINT", s(1.3), CONFIRM);
    assert!(stopped.commanded);
    v.on_frame(
        s(1.4),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert!(end_stop(&mut shell, &v, true, s(1.5)).is_empty());
    assert!(
        shell.pending_events.iter().any(
            |e| e.to_string() == "companion stopping: the autopilot accepted the hand-off mode"
        )
    );
}
