//! Tests of the vehicle link: choice, streams, liveness, the executor.

use super::*;
use crate::actions::Flown;
use companion_core::action_role::ActionRoles;
use companion_core::mission::{Action, ActionCatalogue, ActionKind};
use mavlink::{MavHeader, MavlinkVersion};

mod mission_watch;
mod speeds;

pub(super) fn s(v: f64) -> Duration {
    Duration::from_secs_f64(v)
}

pub(super) fn frame(msg: Msg) -> Frame {
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

pub(super) fn hb(mode: u32, armed: bool) -> Frame {
    frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: if armed {
            MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        } else {
            MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        },
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    }))
}

pub(super) fn ready_frames() -> Vec<Frame> {
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

fn not_ready() -> Frame {
    let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
    frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
        onboard_control_sensors_present: bit,
        onboard_control_sensors_enabled: bit,
        ..SYS_STATUS_DATA::DEFAULT
    }))
}

pub(super) fn ack(command: MavCmd, result: MavResult) -> Frame {
    frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        ..COMMAND_ACK_DATA::DEFAULT
    }))
}

/// The actions these tests fly: the shipped names and two of their own.
const TEST_ACTIONS: [&str; 12] = [
    "stay_on_ground",
    "take_off",
    "follow_trajectory",
    "avoid_obstacle",
    "land",
    "replan_and_land",
    "return_to_base",
    "track_v3",
    "hold",
    "go",
    "search_zone_t",
    "detect_target",
];

fn test_catalogue() -> ActionCatalogue {
    let action = |name: &str| Action {
        id: name.to_string(),
        paper: String::new(),
        kind: ActionKind::Vehicle,
        label: name.to_string(),
        app: None,
        version: None,
        role: None,
    };
    ActionCatalogue::new(TEST_ACTIONS.map(action).to_vec(), ActionRoles::undeclared())
}

/// The action `name` of [`TEST_ACTIONS`], flown by its own entry.
pub(super) fn a(name: &str) -> Flown {
    Flown::Action(test_catalogue().id(name).expect(name))
}

fn table() -> ActionTable {
    let mut t = ActionTable::new(&test_catalogue());
    t.insert(
        a("take_off"),
        "take_off",
        vec![
            Step::Mode(FlightMode::Guided),
            Step::Arm,
            Step::Command {
                command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                params: [0., 0., 0., 0., 0., 0., 10.],
            },
        ],
    );
    t.insert(
        a("return_to_base"),
        "return_to_base",
        vec![Step::Mode(FlightMode::Rtl)],
    );
    t
}

pub(super) fn vehicle() -> Vehicle {
    let cfg = VehicleConfig {
        streams: vec![(168, 1.0)],
        ..VehicleConfig::default()
    };
    Vehicle::new(cfg, table(), None)
}

pub(super) fn commands(out: &[Msg]) -> Vec<MavCmd> {
    out.iter()
        .filter_map(|m| {
            if let Msg::COMMAND_LONG(c) = m {
                Some(c.command)
            } else {
                None
            }
        })
        .collect()
}

/// Connect, let the stream request complete.
pub(super) fn connected(v: &mut Vehicle, mode: u32) {
    let out = v.on_frame(s(0.0), &hb(mode, false));
    assert_eq!(v.target, Some((1, 1)));
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL],
        "streams requested on connect"
    );
    v.on_frame(
        s(0.05),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(v.take_events().contains(&Event::Link(LinkEvent::Connected)));
}

/// A vehicle connected in STABILIZE and reporting ready, asked to take off at 0.2 s: GUIDED sent.
pub(super) fn take_off_asked_when_ready() -> Vehicle {
    let mut v = vehicle();
    connected(&mut v, 0);
    for f in ready_frames() {
        v.on_frame(s(0.1), &f);
    }
    let out = v.request_actions(s(0.2), &[a("take_off")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v
}

#[test]
fn arms_only_once_the_vehicle_reports_the_mode_it_was_set_to() {
    // ArduCopter SITL: GUIDED accepted, then STABILIZE from its RC mode switch.
    let mut v = take_off_asked_when_ready();
    // The ack comes before any heartbeat shows the new mode: no ARM yet.
    let out = v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert!(commands(&out).is_empty(), "armed before the mode was seen");
    // The next heartbeat says STABILIZE (0): not armed, the take-off fails and says why.
    let mut out = v.on_frame(s(1.0), &hb(0, false));
    out.extend(v.tick(s(1.1)));
    assert!(
        !commands(&out).contains(&MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        "armed in STABILIZE"
    );
    assert!(v.take_records().iter().any(|r| {
        r.command == "ARM"
            && matches!(&r.result, CommandOutcome::Failed(Some(why))
                if why.starts_with("vehicle in STABILIZE, not GUIDED"))
    }));
    // Asked again after the retry delay: GUIDED is set again, and with GUIDED reported it arms.
    let out = v.request_actions(s(7.0), &[a("take_off")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v.on_frame(
        s(7.1),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    let out = v.on_frame(s(7.5), &hb(4, false));
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
}

/// A heartbeat the autopilot sent before it handled SET_MODE can arrive after we sent the
/// command: it still shows the old mode and is no sign that the vehicle left the mode it was
/// set to. Only a heartbeat heard after the ACK shows the mode (seen in the TCP loopback test,
/// about one flight in fifteen: the take-off failed "vehicle in STABILIZE, not GUIDED").
#[test]
fn a_heartbeat_from_before_the_mode_ack_does_not_fail_the_take_off() {
    let mut v = take_off_asked_when_ready();
    // In flight when we sent SET_MODE: the old mode (STABILIZE, 0).
    let out = v.on_frame(s(0.25), &hb(0, false));
    assert!(commands(&out).is_empty());
    let out = v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert!(commands(&out).is_empty(), "armed before the mode was seen");
    assert!(
        !v.take_records()
            .iter()
            .any(|r| r.command == "ARM" && matches!(r.result, CommandOutcome::Failed(_))),
        "a heartbeat from before the ACK failed the take-off"
    );
    // The first heartbeat after the ACK shows GUIDED: ARM.
    let out = v.on_frame(s(1.0), &hb(4, false));
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
}

/// An action that commands nothing (stay_on_ground) supersedes a take-off being flown, and a
/// take-off asked for again afterwards starts afresh (it used to stay "running" and never
/// resumed: seen on ArduCopter SITL).
#[test]
fn take_off_after_staying_on_the_ground_starts_again() {
    let mut t = table();
    t.insert(a("stay_on_ground"), "stay_on_ground", Vec::new());
    let mut v = Vehicle::new(
        VehicleConfig {
            streams: vec![(168, 1.0)],
            ..VehicleConfig::default()
        },
        t,
        None,
    );
    connected(&mut v, 0);
    for f in ready_frames() {
        v.on_frame(s(0.1), &f);
    }
    let out = v.request_actions(s(0.2), &[a("take_off")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v.on_frame(
        s(0.25),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    let out = v.request_actions(s(0.3), &[a("stay_on_ground")]);
    assert!(out.is_empty(), "staying commands nothing");
    assert!(
        v.take_records()
            .iter()
            .any(|r| r.action == "take_off" && r.result == CommandOutcome::Superseded)
    );
    // GUIDED reported: no arming while staying.
    let out = v.on_frame(s(0.5), &hb(4, false));
    assert!(
        commands(&out).is_empty(),
        "armed while staying on the ground"
    );
    let mut out = v.request_actions(s(1.3), &[a("take_off")]);
    out.extend(v.on_frame(s(1.4), &hb(4, false)));
    out.extend(v.tick(s(1.5)));
    let sent = commands(&out);
    assert!(
        sent.contains(&MavCmd::MAV_CMD_DO_SET_MODE)
            || sent.contains(&MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
        "take-off again: {sent:?}"
    );
}

#[test]
fn take_off_waits_for_readiness_before_arming() {
    let mut v = vehicle();
    connected(&mut v, 0);
    v.on_frame(s(0.1), &not_ready());
    let out = v.request_actions(s(0.2), &[a("take_off")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v.stamp_latency(s(0.15), s(0.2));
    let recs = v.take_records();
    assert_eq!(recs[0].latency_ms, Some(50.0));
    let out = v.on_frame(
        s(0.3),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert!(
        commands(&out).is_empty(),
        "must not arm a vehicle that reports not ready"
    );
    assert!(
        v.take_records()
            .iter()
            .any(|r| matches!(r.result, CommandOutcome::WaitingReady(_)))
    );
    v.on_frame(s(3.0), &hb(4, false));
    assert!(commands(&v.tick(s(5.0))).is_empty());
    let mut out = Vec::new();
    for f in ready_frames() {
        out.extend(v.on_frame(s(6.0), &f));
    }
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
    let out = v.on_frame(
        s(6.1),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
    v.on_frame(
        s(6.2),
        &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert!(!v.busy());
    // Asking again for the finished action does nothing.
    assert!(v.request_actions(s(7.0), &[a("take_off")]).is_empty());
}

#[test]
fn failed_arm_is_retried_only_after_a_fresh_ready_report() {
    let mut v = vehicle();
    connected(&mut v, 4);
    for f in ready_frames() {
        v.on_frame(s(0.1), &f);
    }
    let out = v.request_actions(s(0.2), &[a("take_off")]);
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM],
        "already GUIDED: straight to arm"
    );
    // ArduPilot refuses: prearm failed.
    let out = v.on_frame(
        s(0.3),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_FAILED,
        ),
    );
    assert!(commands(&out).is_empty());
    assert!(commands(&v.tick(s(2.0))).is_empty(), "no blind retry");
    assert!(commands(&v.on_frame(s(2.5), &not_ready())).is_empty());
    let out = v.on_frame(s(3.0), &ready_frames()[0]);
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM],
        "retried after the autopilot reported ready again"
    );
    let out = v.on_frame(
        s(3.1),
        &ack(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
}

#[test]
fn arm_gives_up_when_never_ready() {
    let mut v = vehicle();
    connected(&mut v, 4);
    v.on_frame(s(0.1), &not_ready());
    v.request_actions(s(0.2), &[a("take_off")]);
    for t in 1..=61 {
        v.on_frame(s(t as f64), &hb(4, false));
        assert!(commands(&v.tick(s(t as f64 + 0.5))).is_empty());
    }
    assert!(!v.busy());
    assert!(
        v.take_records()
            .iter()
            .any(|r| matches!(r.result, CommandOutcome::NotReady(_)))
    );
}

#[test]
fn link_loss_drops_commands_and_resume_does_not_replay() {
    let mut v = vehicle();
    connected(&mut v, 0);
    let out = v.request_actions(s(1.0), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    // Silence: the autopilot is gone.
    assert!(
        commands(&v.tick(s(2.5)))
            .iter()
            .all(|c| *c == MavCmd::MAV_CMD_DO_SET_MODE),
        "resend while alive is fine"
    );
    let out = v.tick(s(4.1));
    assert!(out.is_empty());
    assert!(!v.liveness.alive());
    assert!(v.take_events().contains(&Event::Link(LinkEvent::Lost)));
    assert!(
        v.take_records()
            .iter()
            .any(|r| matches!(r.result, CommandOutcome::Cancelled(_)))
    );
    assert_eq!(v.commands.pending_count(), 0);
    for t in [5.0, 10.0, 20.0] {
        assert!(v.tick(s(t)).is_empty(), "nothing sent while lost");
    }
    assert!(v.request_actions(s(20.0), &[a("take_off")]).is_empty());
    assert!(
        v.take_records()
            .iter()
            .any(|r| matches!(r.result, CommandOutcome::NotSent(_)))
    );
    // Autopilot back: only stream requests go out, never the old SET_MODE.
    let out = v.on_frame(s(21.0), &hb(0, false));
    assert!(v.take_events().contains(&Event::Link(LinkEvent::Regained)));
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL]);
    let out = v.on_frame(
        s(21.1),
        &ack(
            MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(commands(&out).is_empty());
    v.on_frame(s(23.0), &hb(0, false));
    assert!(commands(&v.tick(s(24.0))).is_empty());
    // A fresh decision may command again.
    let out = v.request_actions(s(25.0), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
}

#[test]
fn reboot_re_requests_streams_and_resets_readiness() {
    let mut v = vehicle();
    connected(&mut v, 0);
    for f in ready_frames() {
        v.on_frame(s(0.1), &f);
    }
    assert!(v.readiness.check().is_ok());
    // Past the minimum interval since the connect's stream requests.
    v.on_frame(
        s(5.5),
        &frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
            time_unix_usec: 0,
            time_boot_ms: 90_000,
        })),
    );
    let out = v.on_frame(
        s(6.0),
        &frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
            time_unix_usec: 0,
            time_boot_ms: 500,
        })),
    );
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL]);
    assert!(v.take_events().contains(&Event::Link(LinkEvent::Rebooted)));
    assert!(v.readiness.check().is_err());
}

fn system_time(ms: u32) -> Frame {
    frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
        time_unix_usec: 0,
        time_boot_ms: ms,
    }))
}

/// Acknowledge every stream request in `out` and those the acks release; how many went out.
fn ack_streams(v: &mut Vehicle, t: f64, out: &[Msg]) -> usize {
    let mut out = out.to_vec();
    let mut n = 0;
    while commands(&out).contains(&MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL) {
        n += 1;
        out = v.on_frame(
            s(t),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
    }
    n
}

/// Message ids the vehicle asks for with SET_MESSAGE_INTERVAL after a HEARTBEAT of
/// `autopilot`, with the shipped params/link.toml, every request acknowledged in turn.
fn streams_requested(autopilot: MavAutopilot) -> Vec<u32> {
    let path = crate::test_support::default_params_dir().join("link.toml");
    let link = crate::test_support::disk(crate::actions::LinkParams::load)(&path).unwrap();
    let cfg = VehicleConfig {
        streams: link.stream_ids(),
        streams_not_sent: link.streams_not_sent(),
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, table(), None);
    let mut heartbeat = hb(0, false);
    if let Msg::HEARTBEAT(h) = &mut heartbeat.msg {
        h.autopilot = autopilot;
    }
    let mut out = v.on_frame(s(0.0), &heartbeat);
    let mut ids = Vec::new();
    for _ in 0..100 {
        let asked: Vec<u32> = out
            .iter()
            .filter_map(|m| match m {
                Msg::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                    Some(c.param1 as u32)
                }
                _ => None,
            })
            .collect();
        if asked.is_empty() {
            break;
        }
        ids.extend(asked);
        out = v.on_frame(
            s(0.1),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
    }
    ids
}

/// ArduPilot has no ESTIMATOR_STATUS (230), OBSTACLE_DISTANCE (330) or STATUSTEXT (253) in
/// its ap_message map: asking makes it send `No ap_message for mavlink id (N)` to the ground
/// station on every connect. PX4 has those streams and no EKF_STATUS_REPORT (193) or WIND
/// (168).
#[test]
fn each_autopilot_is_asked_only_for_streams_it_has() {
    let ardupilot = streams_requested(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
    for id in [230, 330, 253] {
        assert!(
            !ardupilot.contains(&id),
            "ArduPilot asked for {id}: {ardupilot:?}"
        );
    }
    for id in [1, 33, 147, 193, 168, 241, 245, 42, 242, 2] {
        assert!(
            ardupilot.contains(&id),
            "ArduPilot not asked for {id}: {ardupilot:?}"
        );
    }
    let px4 = streams_requested(MavAutopilot::MAV_AUTOPILOT_PX4);
    for id in [230, 330, 253, 1, 33, 147, 241, 245, 242, 2] {
        assert!(px4.contains(&id), "PX4 not asked for {id}: {px4:?}");
    }
    for id in [193, 168] {
        assert!(!px4.contains(&id), "PX4 asked for {id}: {px4:?}");
    }
    // An autopilot of neither flavour is asked for everything listed.
    let other = streams_requested(MavAutopilot::MAV_AUTOPILOT_GENERIC);
    assert!(
        other.len() > px4.len() && other.len() > ardupilot.len(),
        "{other:?}"
    );
}

/// 35 spoofed "reboots" (the boot clock jumping back and forth) in 3.5 s cannot multiply the
/// stream requests: at most one set per minimum interval, and the last one still goes out.
#[test]
fn spoofed_system_time_cannot_multiply_stream_requests() {
    let cfg = VehicleConfig {
        streams: vec![(1, 2.0), (33, 5.0), (168, 1.0)],
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, table(), None);
    let mut sent = 0;
    let out = v.on_frame(s(0.0), &hb(0, false));
    sent += ack_streams(&mut v, 0.0, &out);
    for i in 0..35u32 {
        let t = 0.1 + i as f64 * 0.1;
        let ms = if i % 2 == 0 { 500_000 } else { 1_000 };
        let out = v.on_frame(s(t), &system_time(ms));
        sent += ack_streams(&mut v, t, &out);
        let out = v.tick(s(t + 0.05));
        sent += ack_streams(&mut v, t + 0.05, &out);
    }
    assert_eq!(sent, 3, "only the connect's set within the first 5 s");
    for k in 0..40 {
        let t = 4.0 + k as f64 * 0.1;
        if k % 10 == 0 {
            v.on_frame(s(t), &hb(0, false));
        }
        let out = v.tick(s(t));
        sent += ack_streams(&mut v, t, &out);
    }
    assert_eq!(sent, 6, "one deferred set once the interval passed, not 35");
}

/// A TCP link that keeps reconnecting without the autopilot saying anything is lost: a
/// reconnect is not a message from the autopilot.
#[test]
fn reconnects_alone_do_not_keep_the_link_alive() {
    let mut v = vehicle();
    connected(&mut v, 0);
    for k in 1..=10 {
        let t = k as f64 * 0.5;
        v.on_reconnect(s(t));
        v.tick(s(t));
    }
    assert!(!v.liveness.alive());
    assert!(v.take_events().contains(&Event::Link(LinkEvent::Lost)));
}

fn from(sys: u8, comp: u8, mut f: Frame) -> Frame {
    f.header.system_id = sys as u32;
    f.header.component_id = comp;
    f
}

/// A fake autopilot heard first is not obeyed when `--autopilot-sysid` names the real one,
/// and a second autopilot after the choice is reported, never followed.
#[test]
fn autopilot_sysid_chooses_and_others_are_reported_not_obeyed() {
    let cfg = VehicleConfig {
        autopilot_sysid: Some(1),
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, table(), None);
    v.on_frame(s(0.0), &from(7, 1, hb(4, true)));
    assert_eq!(v.target, None, "sysid 7 is not the one asked for");
    assert!(!v.liveness.alive());
    v.on_frame(s(0.5), &hb(0, false));
    assert_eq!(v.target, Some((1, 1)));
    // The impostor keeps talking: reported once, counted, never drives the state.
    for t in 1..5 {
        v.on_frame(s(t as f64), &from(7, 1, hb(4, true)));
    }
    assert!(!v.telemetry.armed, "armed came only from the impostor");
    assert_eq!(
        v.telemetry.mode,
        Some(ReportedMode::Known(FlightMode::Stabilize))
    );
    let evs = v.take_link_events();
    let reports: Vec<_> = evs
        .iter()
        .filter(|e| {
            matches!(
                e,
                LinkEvent::OtherAutopilot {
                    system: 7,
                    component: 1,
                    ..
                }
            )
        })
        .collect();
    assert_eq!(reports.len(), 1, "{evs:?}");
    assert!(
        evs.iter()
            .any(|e| e.to_string().contains("5 heartbeats from other autopilots")),
        "{evs:?}"
    );
    // Its acks do not finish our commands either.
    let out = v.request_actions(s(5.0), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v.on_frame(
        s(5.1),
        &from(
            7,
            1,
            ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        ),
    );
    assert!(
        v.busy(),
        "an ack from another system is not our autopilot's"
    );
}

/// Issue 26: `--autopilot-sysid 1` pinned only the system, so an impostor 1/2 heard first
/// became the autopilot. The pin is system and component: 1/2 is reported, 1/1 chosen, and
/// only 1/1's frames drive the state.
#[test]
fn the_pin_names_the_component_and_an_impostor_on_another_component_is_refused() {
    let cfg = VehicleConfig {
        autopilot_sysid: Some(1),
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, table(), None);
    for t in 0..3 {
        v.on_frame(s(t as f64), &from(1, 2, hb(4, true)));
    }
    assert_eq!(v.target, None, "1/2 is not the pinned 1/1");
    v.on_frame(s(3.0), &hb(0, false));
    assert_eq!(v.target, Some((1, 1)));
    v.on_frame(s(3.5), &from(1, 2, hb(4, true)));
    assert!(!v.telemetry.armed, "armed came only from the impostor 1/2");
    let evs = v.take_link_events();
    assert!(
        evs.iter().any(|e| matches!(
            e,
            LinkEvent::OtherAutopilot {
                system: 1,
                component: 2,
                ..
            }
        )),
        "{evs:?}"
    );
    assert!(
        !evs.iter()
            .any(|e| e.to_string().contains("first autopilot heard")),
        "a pinned choice is not 'the first heard': {evs:?}"
    );
    assert_eq!(v.identity_note(), None);
}

/// `--autopilot-compid` moves the pin to another component: then 1/1 is the stranger.
#[test]
fn autopilot_compid_pins_another_component() {
    let cfg = VehicleConfig {
        autopilot_sysid: Some(1),
        autopilot_compid: 2,
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, table(), None);
    v.on_frame(s(0.0), &hb(0, false));
    assert_eq!(v.target, None);
    v.on_frame(s(0.5), &from(1, 2, hb(0, false)));
    assert_eq!(v.target, Some((1, 2)));
}

/// Without a pin, the autopilot component (1) is preferred over an impostor on another
/// component heard first, and the choice is said with how to pin it.
#[test]
fn without_a_pin_component_1_is_preferred_and_the_choice_is_named() {
    let mut v = vehicle();
    v.on_frame(s(0.0), &from(1, 2, hb(4, true)));
    v.on_frame(s(1.0), &from(1, 2, hb(4, true)));
    assert_eq!(v.target, None, "1/2 waits for a component-1 autopilot");
    v.on_frame(s(1.5), &hb(0, false));
    assert_eq!(v.target, Some((1, 1)));
    v.on_frame(s(2.0), &from(1, 2, hb(4, true)));
    assert!(!v.telemetry.armed);
    let note = v.identity_note().expect("an unpinned choice is named");
    assert!(note.contains("autopilot 1/1"), "{note}");
    assert!(note.contains("first autopilot heard"), "{note}");
    assert!(note.contains("--autopilot-sysid 1"), "{note}");
    let evs: Vec<String> = v.take_link_events().iter().map(|e| e.to_string()).collect();
    assert!(evs.iter().any(|e| e == &note), "{evs:?}");
    assert!(
        evs.iter().any(|e| e.contains("another autopilot 1/2")),
        "{evs:?}"
    );
}

/// An autopilot that speaks only from another component is still chosen (alone on the link
/// for the wait), and the note says how to pin it, component included.
#[test]
fn without_a_pin_a_lone_autopilot_on_another_component_is_chosen_after_the_wait() {
    let mut v = vehicle();
    v.on_frame(s(0.0), &from(3, 2, hb(0, false)));
    v.on_frame(s(1.0), &from(3, 2, hb(0, false)));
    assert_eq!(v.target, None);
    v.on_frame(s(2.0), &from(3, 2, hb(0, false)));
    assert_eq!(v.target, Some((3, 2)));
    let note = v.identity_note().unwrap();
    assert!(
        note.contains("--autopilot-sysid 3 --autopilot-compid 2"),
        "{note}"
    );
}

#[test]
fn only_vehicles_with_an_autopilot_are_chosen() {
    let mut v = vehicle();
    for (mavtype, autopilot) in [
        (MavType::MAV_TYPE_GCS, MavAutopilot::MAV_AUTOPILOT_INVALID),
        (
            MavType::MAV_TYPE_QUADROTOR,
            MavAutopilot::MAV_AUTOPILOT_INVALID,
        ),
        (
            MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        ),
        (
            MavType::MAV_TYPE_ADSB,
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        ),
        (MavType::MAV_TYPE_GIMBAL, MavAutopilot::MAV_AUTOPILOT_PX4),
    ] {
        let f = from(
            3,
            50,
            frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
                mavtype,
                autopilot,
                ..HEARTBEAT_DATA::DEFAULT
            })),
        );
        v.on_frame(s(0.0), &f);
        assert_eq!(v.target, None, "{mavtype:?} {autopilot:?}");
    }
    v.on_frame(s(0.1), &hb(0, false));
    assert_eq!(v.target, Some((1, 1)));
}

fn nvf(name: &str, value: f32) -> Msg {
    Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
        time_boot_ms: 0,
        value,
        name: name.into(),
    })
}

fn zone_vehicle() -> Vehicle {
    let mut t = table();
    t.insert(
        a("replan_and_land"),
        "replan_and_land",
        vec![Step::GotoZone, Step::Mode(FlightMode::Land)],
    );
    let mut cfg = VehicleConfig::default();
    cfg.telemetry.onboard.extend([
        ("zone_n".into(), "zone_north_m".into()),
        ("zone_e".into(), "zone_east_m".into()),
    ]);
    cfg.telemetry
        .ranges
        .insert("zone_north_m".into(), [-1000.0, 1000.0]);
    cfg.telemetry
        .ranges
        .insert("zone_east_m".into(), [-1000.0, 1000.0]);
    let mut v = Vehicle::new(cfg, t, None);
    v.on_frame(s(0.0), &hb(4, true));
    v.on_frame(
        s(0.0),
        &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: 473_977_420,
            lon: 1_799_900_000,
            relative_alt: 20_000,
            hdg: 0,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        })),
    );
    v
}

fn repositions(out: &[Msg]) -> usize {
    out.iter()
        .filter(|m| matches!(m, Msg::COMMAND_INT(c) if c.command == MavCmd::MAV_CMD_DO_REPOSITION))
        .count()
}

/// A landing zone from an unknown system is never flown to; one from the allowed camera is.
#[test]
fn landing_zone_from_an_unknown_sysid_produces_no_reposition() {
    let mut v = zone_vehicle();
    v.on_frame(s(0.1), &from(99, 100, frame(nvf("zone_n", 30.0))));
    v.on_frame(s(0.1), &from(99, 100, frame(nvf("zone_e", -5_000_000.0))));
    v.on_frame(s(0.1), &from(1, 77, frame(nvf("zone_e", 40.0))));
    assert_eq!(v.telemetry.get("zone_north_m"), None);
    assert_eq!(v.telemetry.get("zone_east_m"), None);
    let out = v.request_actions(s(0.2), &[a("replan_and_land")]);
    assert_eq!(repositions(&out), 0, "{out:?}");
    assert!(v.take_link_events().iter().any(|e| {
        e.to_string()
            .contains("3 monitor frames from components not allowed")
    }));

    let mut v = zone_vehicle();
    v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_n", 30.0))));
    v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_e", -5_000_000.0))));
    assert_eq!(v.telemetry.get("zone_east_m"), None, "out of range");
    v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_e", 40.0))));
    let out = v.request_actions(s(0.2), &[a("replan_and_land")]);
    assert_eq!(repositions(&out), 1);
    match &out[0] {
        Msg::COMMAND_INT(c) => {
            assert!(crate::telemetry::on_globe(c.x, c.y), "{} {}", c.x, c.y);
        }
        other => panic!("{other:?}"),
    }
}

/// A DISTANCE_SENSOR from a foreign system raises no obstacle event (so no mode toggling).
#[test]
fn foreign_distance_sensor_raises_no_obstacle() {
    let mut v = vehicle();
    connected(&mut v, 4);
    let near = frame(Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
        min_distance: 20,
        max_distance: 4000,
        current_distance: 300,
        orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_NONE,
        ..DISTANCE_SENSOR_DATA::DEFAULT
    }));
    for k in 0..30 {
        v.on_frame(s(1.0 + k as f64 * 0.1), &from(77, 158, near.clone()));
    }
    assert!(
        !v.take_events()
            .iter()
            .any(|e| e.to_string().contains("obstacle"))
    );
    assert_eq!(v.telemetry.obstacle_m(s(3.0)), None);
    assert_eq!(v.foreign_monitor_frames(), 30);
    // The autopilot's own rangefinder still counts.
    v.on_frame(s(4.0), &near);
    assert!(v.take_events().contains(&Event::ObstacleDetected));
}

#[test]
fn unmapped_actions_are_recorded_not_sent() {
    let mut v = vehicle();
    connected(&mut v, 0);
    assert!(v.request_actions(s(1.0), &[a("track_v3")]).is_empty());
    assert_eq!(v.take_records()[0].result, CommandOutcome::Unmapped);
}

#[test]
fn other_components_do_not_keep_the_link_alive() {
    let mut v = vehicle();
    connected(&mut v, 0);
    let mut gcs = hb(0, false);
    gcs.header.component_id = 190;
    for t in 1..10 {
        v.on_frame(s(t as f64), &gcs);
        v.tick(s(t as f64));
    }
    assert!(!v.liveness.alive());
}

fn route_vehicle() -> Vehicle {
    use crate::actions::{Route, Waypoint};
    let mut t = table();
    t.insert(
        a("follow_trajectory"),
        "follow_trajectory",
        vec![Step::UploadMission, Step::Mode(FlightMode::Auto)],
    );
    t.insert(
        a("avoid_obstacle"),
        "avoid_obstacle",
        vec![Step::Reposition(Offset {
            forward_m: 0.0,
            right_m: 8.0,
            up_m: 0.0,
        })],
    );
    let route = Route {
        waypoints: vec![Waypoint::Relative {
            north_m: 100.0,
            east_m: 0.0,
            alt_m: 20.0,
        }],
        altitude_m: 20.0,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        takeoff_first: false,
        end: crate::actions::RouteEnd::ReturnToLaunch,
        operator_items: Vec::new(),
    };
    let cfg = VehicleConfig {
        streams: vec![],
        ..VehicleConfig::default()
    };
    let mut v = Vehicle::new(cfg, t, Some(route));
    v.on_frame(s(0.0), &hb(4, true));
    v.on_frame(
        s(0.0),
        &frame(Msg::HOME_POSITION(HOME_POSITION_DATA {
            latitude: 473_977_420,
            longitude: 85_455_940,
            altitude: 488_000,
            ..HOME_POSITION_DATA::DEFAULT
        })),
    );
    v.on_frame(
        s(0.0),
        &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: 473_977_420,
            lon: 85_455_940,
            relative_alt: 20_000,
            hdg: 9000,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        })),
    );
    v.take_records();
    v
}

#[test]
fn the_route_items_mode_is_its_own_end_and_only_while_the_autopilot_reports_it() {
    // route_vehicle's route on ArduPilot: seq 0 home, 1 the waypoint, 2 NAV_RETURN_TO_LAUNCH.
    let mut v = route_vehicle();
    let current = |seq| {
        frame(Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
            seq,
            total: 3,
            ..MISSION_CURRENT_DATA::DEFAULT
        }))
    };
    let (auto, rtl, land) = (3, 6, 9); // ArduCopter's custom modes
    for (mode, seq, expect) in [
        (rtl, 2, Some(FlightMode::Rtl)),
        (land, 2, Some(FlightMode::Rtl)), // the item's mode, whichever of the two is reported
        (rtl, 1, None),                   // a waypoint flies no mode of its own
        (auto, 2, None),                  // neither RTL nor LAND reported
        (rtl, 7, None),                   // past the route's end
    ] {
        v.on_frame(s(1.0), &hb(mode, true));
        v.on_frame(s(1.0), &current(seq));
        assert_eq!(v.mission_item_mode(), expect, "mode {mode}, seq {seq}");
    }
}

#[test]
fn px4s_route_item_mode_is_the_land_it_was_given() {
    let route = px4_route();
    let mut v = Vehicle::new(VehicleConfig::default(), table(), Some(route));
    px4_ready(&mut v, 0.0);
    // PX4's upload: take-off, a waypoint over home, the waypoint, NAV_LAND (never its RTL).
    let land_mode = modes::px4_custom_mode(4, 6);
    for (seq, expect) in [(3, Some(FlightMode::Land)), (2, None)] {
        for msg in [
            Msg::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: land_mode,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
                base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }),
            Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
                seq,
                total: 4,
                ..MISSION_CURRENT_DATA::DEFAULT
            }),
        ] {
            v.on_frame(s(1.0), &px4_frame(msg));
        }
        assert_eq!(v.mission_item_mode(), expect, "seq {seq}");
    }
}

/// Run the autopilot side of upload + download; `stored` is what the autopilot keeps.
fn serve_upload(v: &mut Vehicle, first: Vec<Msg>, stored_alt: f32) -> Vec<Msg> {
    let count = match &first[0] {
        Msg::MISSION_COUNT(c) => c.count,
        other => panic!("expected MISSION_COUNT, got {other:?}"),
    };
    let mut items = Vec::new();
    for seq in 0..count {
        let out = v.on_frame(
            s(1.0),
            &frame(Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                seq,
                target_system: 1,
                target_component: 191,
                ..MISSION_REQUEST_INT_DATA::DEFAULT
            })),
        );
        match &out[0] {
            Msg::MISSION_ITEM_INT(i) => items.push(i.clone()),
            other => panic!("{other:?}"),
        }
    }
    let out = v.on_frame(
        s(1.1),
        &frame(Msg::MISSION_ACK(MISSION_ACK_DATA {
            mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
            ..MISSION_ACK_DATA::DEFAULT
        })),
    );
    assert!(
        matches!(out[0], Msg::MISSION_REQUEST_LIST(_)),
        "verification download starts: {out:?}"
    );
    let mut out = v.on_frame(
        s(1.2),
        &frame(Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count,
            ..MISSION_COUNT_DATA::DEFAULT
        })),
    );
    for (i, mut it) in items.into_iter().enumerate() {
        if i > 0 && it.command == MavCmd::MAV_CMD_NAV_WAYPOINT {
            it.z = stored_alt;
        }
        assert!(
            matches!(out[0], Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA { seq, .. }) if seq as usize == i),
            "{out:?}"
        );
        out = v.on_frame(s(1.3), &frame(Msg::MISSION_ITEM_INT(it)));
    }
    out
}

#[test]
fn follow_trajectory_uploads_verifies_then_switches_to_auto() {
    let mut v = route_vehicle();
    let out = v.request_actions(s(1.0), &[a("follow_trajectory")]);
    let out = serve_upload(&mut v, out, 20.0);
    assert!(
        matches!(out[0], Msg::MISSION_ACK(_)),
        "download acknowledged"
    );
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_DO_SET_MODE],
        "AUTO only after the verified upload"
    );
    match &out[1] {
        Msg::COMMAND_LONG(c) => assert_eq!(c.param2, 3.0, "ArduPilot AUTO"),
        other => panic!("{other:?}"),
    }
    assert!(
        v.take_records()
            .iter()
            .any(|r| r.result == CommandOutcome::AcceptedVerified { items: 3 }),
        "home, the waypoint, the mission's own end (RTL)"
    );
}

#[test]
fn a_mission_that_does_not_verify_is_never_flown() {
    let mut v = route_vehicle();
    let out = v.request_actions(s(1.0), &[a("follow_trajectory")]);
    let out = serve_upload(&mut v, out, 35.0);
    assert!(
        commands(&out).is_empty(),
        "no AUTO after a mismatch: {out:?}"
    );
    assert!(!v.busy());
    let recs = v.take_records();
    // The typed error's sentence, never its Debug text (`UploadVerified`, `VerifyMismatch(..)`).
    assert!(
        recs.iter().any(|r| r.command == "MISSION_UPLOAD"
            && matches!(&r.result, CommandOutcome::Failed(Some(why))
                if why.starts_with("read back differs: item ") && why.contains("altitude"))),
        "{recs:?}"
    );
    assert!(recs.iter().any(
        |r| r.command == "SET_MODE AUTO" && matches!(r.result, CommandOutcome::Skipped(_))
    ));
}

fn zone_route_vehicle() -> Vehicle {
    let mut v = route_vehicle();
    v.actions.insert(
        a("land"),
        "land",
        vec![Step::GotoZone, Step::Mode(FlightMode::Land)],
    );
    v.cfg.zone_radius_m = 3.0;
    v.cfg.zone_arrive_timeout = Duration::from_secs(60);
    let onboard = &mut v.telemetry.cfg.onboard;
    onboard.insert("zone_n".into(), "zone_north_m".into());
    onboard.insert("zone_e".into(), "zone_east_m".into());
    // The landing-zone monitor: the zone 40 m north of the vehicle.
    for (name, value) in [("zone_n", 40.0), ("zone_e", 0.0)] {
        let mut f = frame(Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: 0,
            value,
            name: name.into(),
        }));
        f.header.component_id = 100;
        v.on_frame(s(0.5), &f);
    }
    v
}

fn at(v: &mut Vehicle, t: f64, north_m: f64) -> Vec<Msg> {
    let (lat, lon) = displace((473_977_420, 85_455_940), north_m, 0.0);
    v.on_frame(
        s(t),
        &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat,
            lon,
            relative_alt: 20_000,
            hdg: 9000,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        })),
    )
}

#[test]
fn land_at_the_zone_flies_within_the_radius_before_land() {
    let mut v = zone_route_vehicle();
    let out = v.request_actions(s(1.0), &[a("land")]);
    let target = match &out[..] {
        [Msg::COMMAND_INT(c)] if c.command == MavCmd::MAV_CMD_DO_REPOSITION => (c.x, c.y),
        other => panic!("{other:?}"),
    };
    let (n, _) = crate::telemetry::offset_m((473_977_420, 85_455_940), target);
    assert!((n - 40.0).abs() < 0.1, "zone 40 m north: {n}");
    let out = v.on_frame(
        s(1.1),
        &ack(
            MavCmd::MAV_CMD_DO_REPOSITION,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(
        commands(&out).is_empty(),
        "accepted is not arrived: {out:?}"
    );
    for (t, north) in [(2.0, 5.0), (5.0, 20.0), (8.0, 36.0)] {
        assert!(commands(&at(&mut v, t, north)).is_empty(), "{north} m");
        assert!(commands(&v.tick(s(t + 0.05))).is_empty());
    }
    assert!(v.busy());
    let out = at(&mut v, 10.0, 38.5);
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_DO_SET_MODE],
        "LAND once within 3 m"
    );
    let recs = v.take_records();
    assert!(
        recs.iter()
            .any(|r| r.command == "ARRIVE (zone)"
                && matches!(r.result, CommandOutcome::Arrived(_))),
        "{recs:?}"
    );
}

#[test]
fn land_at_the_zone_lands_where_it_is_after_the_arrive_timeout() {
    let mut v = zone_route_vehicle();
    v.request_actions(s(1.0), &[a("land")]);
    v.on_frame(
        s(1.1),
        &ack(
            MavCmd::MAV_CMD_DO_REPOSITION,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    assert!(commands(&at(&mut v, 30.0, 2.0)).is_empty());
    let out = at(&mut v, 61.5, 2.0);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    assert!(v.take_records().iter().any(
        |r| matches!(&r.result, CommandOutcome::Timeout(Some(why)) if why.contains("landing here"))
    ));
}

#[test]
fn stop_actions_cancels_the_running_action_and_nothing_is_resent() {
    let mut v = vehicle();
    connected(&mut v, 0);
    let out = v.request_actions(s(1.0), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    v.stop_actions(s(1.2), "pilot took control");
    assert!(!v.busy());
    assert!(v.take_records().iter().any(|r| r.command == "SET_MODE RTL"
        && r.result == CommandOutcome::Cancelled(Some("pilot took control".into()))));
    for t in [2.0, 3.0, 5.0] {
        v.on_frame(s(t), &hb(0, false));
        assert!(commands(&v.tick(s(t + 0.5))).is_empty(), "no resend at {t}");
    }
    // Asked again later (control handed back), the same action runs afresh.
    let out = v.request_actions(s(6.0), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    assert_eq!(
        v.commanded_modes().last().map(|m| m.0),
        Some(FlightMode::Rtl)
    );
}

#[test]
fn commands_addressed_to_the_companion_are_kept_for_the_shell() {
    let mut v = vehicle();
    connected(&mut v, 0);
    let start = |comp: u8| {
        let mut f = frame(Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_MISSION_START,
            target_system: 1,
            target_component: comp,
            ..COMMAND_LONG_DATA::DEFAULT
        }));
        f.header.system_id = 255;
        f.header.component_id = 190;
        f
    };
    v.on_frame(s(1.0), &start(191));
    v.on_frame(s(1.1), &start(1)); // for the autopilot: not ours
    assert_eq!(
        v.take_commands_to_us(),
        vec![CommandToUs {
            command: MavCmd::MAV_CMD_MISSION_START,
            from: (255, 190),
            at: s(1.0),
            before_autopilot: false
        }]
    );
    assert!(v.take_commands_to_us().is_empty());
}

#[test]
fn a_command_before_the_autopilot_is_kept_marked_so_the_shell_can_refuse_it() {
    let mut v = Vehicle::new(VehicleConfig::default(), ActionTable::default(), None);
    let mut f = frame(Msg::COMMAND_LONG(COMMAND_LONG_DATA {
        command: MavCmd::MAV_CMD_MISSION_START,
        target_system: crate::DEFAULT_SYSTEM_ID,
        target_component: crate::OUR_COMPONENT_ID,
        ..COMMAND_LONG_DATA::DEFAULT
    }));
    f.header.system_id = 66;
    v.on_frame(s(0.5), &f);
    let got = v.take_commands_to_us();
    assert_eq!(got.len(), 1);
    assert!(got[0].before_autopilot);
    assert_eq!(got[0].from.0, 66);
}

#[test]
fn the_end_of_flight_window_resets_on_any_frame_that_says_airborne() {
    let mut v = vehicle();
    connected(&mut v, 0);
    let hb = |armed: bool| hb(0, armed);
    let pos = |alt_mm: i32| {
        frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            relative_alt: alt_mm,
            lat: 473_977_000,
            lon: 85_455_000,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        }))
    };
    v.on_frame(s(1.0), &pos(20_000));
    v.on_frame(s(1.1), &hb(false)); // a disarmed heartbeat at 20 m: not down
    assert_eq!(v.down_for(s(1.2)), None);
    v.on_frame(s(1.3), &pos(100));
    v.on_frame(s(1.4), &hb(false));
    assert_eq!(v.down_for(s(2.4)), Some(Duration::from_secs(1)));
    v.on_frame(s(2.5), &hb(true)); // the real armed heartbeat in between
    assert_eq!(v.down_for(s(2.6)), None);
    assert_eq!(v.armed_for(s(3.5)), Some(Duration::from_secs(1)));
    v.on_frame(s(3.6), &hb(false));
    assert_eq!(v.armed_for(s(3.7)), None);
    assert!(v.down_for(s(3.7)).is_some());
    v.on_frame(s(3.8), &pos(15_000)); // a position in the air
    assert_eq!(v.down_for(s(3.9)), None);
}

#[test]
fn a_mode_reported_before_our_last_mode_command_is_not_already_set() {
    let mut v = route_vehicle();
    v.actions
        .insert(a("land"), "land", vec![Step::Mode(FlightMode::Land)]);
    v.on_frame(s(1.0), &hb(9, true)); // LAND
    // A sidestep: GUIDED accepted, the heartbeat still says LAND.
    v.request_actions(s(1.1), &[a("avoid_obstacle")]);
    v.on_frame(
        s(1.2),
        &ack(
            MavCmd::MAV_CMD_DO_REPOSITION,
            MavResult::MAV_RESULT_ACCEPTED,
        ),
    );
    let out = v.request_actions(s(1.3), &[a("land")]);
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_DO_SET_MODE],
        "LAND sent again, not taken as already set"
    );
    // With a fresh heartbeat in LAND and nothing commanded since, LAND is already set.
    v.on_frame(
        s(1.4),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    v.on_frame(s(2.5), &hb(9, true));
    v.take_records();
    v.request_actions(s(2.6), &[a("return_to_base")]);
    v.on_frame(
        s(2.7),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    v.on_frame(s(3.5), &hb(6, true)); // RTL
    let out = v.request_actions(s(3.6), &[a("land")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
}

#[test]
fn armed_heartbeats_count_consecutive_reports() {
    let mut v = vehicle();
    connected(&mut v, 0);
    v.on_frame(s(1.0), &hb(0, true));
    v.on_frame(s(2.0), &hb(0, true));
    assert_eq!(v.armed_heartbeats, 2);
    v.on_frame(s(3.0), &hb(0, false));
    assert_eq!(v.armed_heartbeats, 0);
}

#[test]
fn sidestep_is_to_the_right_of_the_heading() {
    let mut v = route_vehicle();
    // Heading east (90 deg): 8 m to the right is 8 m south.
    let out = v.request_actions(s(1.0), &[a("avoid_obstacle")]);
    match &out[0] {
        Msg::COMMAND_INT(c) => {
            assert_eq!(c.command, MavCmd::MAV_CMD_DO_REPOSITION);
            let (n, e) = crate::telemetry::offset_m((473_977_420, 85_455_940), (c.x, c.y));
            assert!(
                (n + 8.0).abs() < 0.05 && e.abs() < 0.05,
                "north {n} east {e}"
            );
            assert_eq!(c.z, 20.0);
        }
        other => panic!("{other:?}"),
    }
}

/// A one-waypoint route 30 m north at 15 m, taking off first: four items on PX4.
fn px4_route() -> crate::actions::Route {
    crate::actions::Route {
        waypoints: vec![crate::actions::Waypoint::Relative {
            north_m: 30.0,
            east_m: 0.0,
            alt_m: 15.0,
        }],
        altitude_m: 15.0,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        takeoff_first: true,
        end: crate::actions::RouteEnd::ReturnToLaunch,
        operator_items: Vec::new(),
    }
}

fn px4_frame(msg: Msg) -> Frame {
    let mut f = frame(msg);
    f.header.system_id = 2; // PX4 instance 1: MAV_SYS_ID 2
    f
}

/// PX4 SITL's own evidence (no EKF_STATUS_REPORT): STANDBY heartbeat in Hold, the prearm bit
/// in SYS_STATUS health only, ESTIMATOR_STATUS 1023, home at 488 m AMSL.
fn px4_ready(v: &mut Vehicle, t: f64) -> Vec<Msg> {
    let mut out = Vec::new();
    for msg in [
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: modes::px4_custom_mode(4, 3),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        }),
        Msg::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: MavSysStatusSensor::from_bits_truncate(0x0300_402f),
            onboard_control_sensors_enabled: MavSysStatusSensor::from_bits_truncate(0x0301_402f),
            onboard_control_sensors_health: MavSysStatusSensor::from_bits_truncate(0x1320_c83f),
            ..SYS_STATUS_DATA::DEFAULT
        }),
        Msg::ESTIMATOR_STATUS(ESTIMATOR_STATUS_DATA {
            flags: EstimatorStatusFlags::from_bits_truncate(1023),
            ..ESTIMATOR_STATUS_DATA::DEFAULT
        }),
        Msg::HOME_POSITION(HOME_POSITION_DATA {
            latitude: 473_977_420,
            longitude: 85_455_940,
            altitude: 488_000,
            ..HOME_POSITION_DATA::DEFAULT
        }),
    ] {
        out.extend(v.on_frame(s(t), &px4_frame(msg)));
    }
    out
}

#[test]
fn px4_arms_on_its_own_evidence_and_takes_off_to_amsl_altitude() {
    let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
    px4_ready(&mut v, 0.0);
    assert_eq!((v.flavor, v.target), (Flavor::Px4, Some((2, 1))));
    let out = v.request_actions(s(0.5), &[a("take_off")]);
    // Hold already stands for GUIDED on PX4; ready without any EKF_STATUS_REPORT.
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
    let mut ack_arm = px4_frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
        result: MavResult::MAV_RESULT_ACCEPTED,
        ..COMMAND_ACK_DATA::DEFAULT
    }));
    ack_arm.header.component_id = 1;
    let out = v.on_frame(s(0.6), &ack_arm);
    match &out[..] {
        [Msg::COMMAND_LONG(c)] => {
            assert_eq!(c.command, MavCmd::MAV_CMD_NAV_TAKEOFF);
            assert_eq!(c.param7, 498.0, "home 488 m AMSL + 10 m");
            assert!(c.param4.is_nan() && c.param5.is_nan() && c.param6.is_nan());
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn px4_not_ready_while_prearm_health_bit_is_clear() {
    let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
    px4_ready(&mut v, 0.0);
    v.on_frame(
        s(0.1),
        &px4_frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_health: MavSysStatusSensor::from_bits_truncate(0x0320_c83f),
            ..SYS_STATUS_DATA::DEFAULT
        })),
    );
    let out = v.request_actions(s(0.5), &[a("take_off")]);
    assert!(commands(&out).is_empty(), "{out:?}");
}

#[test]
fn px4_auto_waits_until_px4_reports_the_uploaded_mission_loaded_and_valid() {
    let mut t = table();
    t.insert(
        a("follow_trajectory"),
        "follow_trajectory",
        vec![Step::UploadMission, Step::Mode(FlightMode::Auto)],
    );
    let route = px4_route();
    let mut v = Vehicle::new(VehicleConfig::default(), t, Some(route));
    px4_ready(&mut v, 0.0);
    let out = v.request_actions(s(1.0), &[a("follow_trajectory")]);
    assert!(
        matches!(&out[0], Msg::MISSION_COUNT(c) if c.count == 4),
        "{out:?}"
    );
    let mut sent = Vec::new();
    for seq in 0..4 {
        let out = v.on_frame(
            s(1.0),
            &px4_frame(Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                seq,
                ..MISSION_REQUEST_INT_DATA::DEFAULT
            })),
        );
        match &out[0] {
            Msg::MISSION_ITEM_INT(i) => sent.push(i.clone()),
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(
        sent[0].command,
        MavCmd::MAV_CMD_NAV_TAKEOFF,
        "PX4: take-off first"
    );
    assert_eq!((sent[0].x, sent[0].y), (473_977_420, 85_455_940));
    v.on_frame(
        s(1.1),
        &px4_frame(Msg::MISSION_ACK(MISSION_ACK_DATA {
            mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
            ..MISSION_ACK_DATA::DEFAULT
        })),
    );
    let mut out = v.on_frame(
        s(1.2),
        &px4_frame(Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count: 4,
            ..MISSION_COUNT_DATA::DEFAULT
        })),
    );
    for it in sent {
        out = v.on_frame(s(1.3), &px4_frame(Msg::MISSION_ITEM_INT(it)));
    }
    assert!(matches!(out[0], Msg::MISSION_ACK(_)), "verified: {out:?}");
    assert!(
        commands(&out).is_empty(),
        "no AUTO before PX4 reports the mission"
    );
    assert!(commands(&v.tick(s(2.0))).is_empty());
    let stale = Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
        total: 0,
        ..MISSION_CURRENT_DATA::DEFAULT
    });
    assert!(commands(&v.on_frame(s(2.1), &px4_frame(stale))).is_empty());
    // The MAVLink module counts the upload at once; the navigator has not yet found it valid.
    let not_valid = Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
        total: 4,
        mission_state: MissionState::MISSION_STATE_NO_MISSION,
        ..MISSION_CURRENT_DATA::DEFAULT
    });
    assert!(
        commands(&v.on_frame(s(2.3), &px4_frame(not_valid))).is_empty(),
        "no AUTO while PX4 reports the mission not valid"
    );
    let loaded = Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
        total: 4,
        mission_state: MissionState::MISSION_STATE_NOT_STARTED,
        ..MISSION_CURRENT_DATA::DEFAULT
    });
    assert!(
        commands(&v.on_frame(s(2.5), &px4_frame(loaded))).is_empty(),
        "valid: AUTO waits for PX4's commander (10 Hz checks) to see it too"
    );
    let out = v.tick(s(2.9));
    match &out[..] {
        [Msg::COMMAND_LONG(c)] => {
            assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
            assert_eq!(
                (c.param1, c.param2, c.param3),
                (1.0, 4.0, 4.0),
                "AUTO.MISSION"
            );
        }
        other => panic!("{other:?}"),
    }
}

fn px4_heartbeat(main: u8, sub: u8) -> Frame {
    px4_frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: modes::px4_custom_mode(main, sub),
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    }))
}

#[test]
fn px4_mode_change_waits_out_the_takeoff_but_return_does_not() {
    let mut t = table();
    t.insert(a("hold"), "hold", vec![Step::Mode(FlightMode::Loiter)]);
    let mut v = Vehicle::new(VehicleConfig::default(), t, None);
    px4_ready(&mut v, 0.0);
    v.on_frame(s(1.0), &px4_heartbeat(4, 2)); // AUTO.TAKEOFF
    assert!(commands(&v.request_actions(s(1.1), &[a("hold")])).is_empty());
    assert!(commands(&v.on_frame(s(2.0), &px4_heartbeat(4, 2))).is_empty());
    assert!(commands(&v.tick(s(2.5))).is_empty(), "still taking off");
    // Returning home is never held back.
    let out = v.request_actions(s(2.6), &[a("return_to_base")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    // Hold again, once PX4 has ended the take-off: sent at once.
    let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
    v.actions
        .insert(a("hold"), "hold", vec![Step::Mode(FlightMode::Auto)]);
    px4_ready(&mut v, 0.0);
    v.on_frame(s(1.0), &px4_heartbeat(4, 2));
    assert!(commands(&v.request_actions(s(1.1), &[a("hold")])).is_empty());
    let out = v.on_frame(s(3.0), &px4_heartbeat(4, 3)); // PX4 switched itself to Hold
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
}

fn px4_ack(command: MavCmd, result: MavResult) -> Frame {
    let mut f = px4_frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        ..COMMAND_ACK_DATA::DEFAULT
    }));
    f.header.component_id = 1;
    f
}

/// A PX4 vehicle in Hold with an action "go": AUTO, then LAND (to see when AUTO counts done).
fn px4_go() -> Vehicle {
    let mut t = table();
    t.insert(
        a("go"),
        "go",
        vec![Step::Mode(FlightMode::Auto), Step::Mode(FlightMode::Land)],
    );
    let mut v = Vehicle::new(VehicleConfig::default(), t, None);
    px4_ready(&mut v, 0.0);
    v.on_frame(s(0.5), &px4_heartbeat(4, 3));
    v.take_records();
    v
}

fn results(v: &mut Vehicle) -> Vec<String> {
    v.take_records()
        .iter()
        .map(|r| format!("{} {}", r.command, r.result))
        .collect()
}

// Seen on PX4 SITL: DO_SET_MODE AUTO ACCEPTED, then TEMPORARILY_REJECTED, vehicle in LOITER.
#[test]
fn px4_accepted_mode_counts_only_when_a_heartbeat_shows_it_and_is_sent_again_if_not() {
    let mut v = px4_go();
    let out = v.request_actions(s(1.0), &[a("go")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    let ok = MavResult::MAV_RESULT_ACCEPTED;
    let out = v.on_frame(s(1.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
    assert!(
        commands(&out).is_empty(),
        "LAND only once AUTO shows: {out:?}"
    );
    for t in [2.0, 3.0, 4.0] {
        assert!(commands(&v.on_frame(s(t), &px4_heartbeat(4, 3))).is_empty());
    }
    // 3 s after ACCEPTED, still in Hold: the command had no effect, send it again.
    let out = v.tick(s(4.2));
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    let r = results(&mut v);
    let pos = |p: &str| r.iter().position(|x| x.starts_with(p));
    assert!(pos("SET_MODE AUTO ACCEPTED") < pos("SET_MODE AUTO NOT_CONFIRMED (still LOITER"));
    assert!(pos("SET_MODE AUTO NOT_CONFIRMED").is_some(), "{r:?}");
    v.on_frame(s(4.3), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
    // A heartbeat from before the acceptance does not count; the next one in AUTO does.
    let out = v.on_frame(s(5.0), &px4_heartbeat(4, 4));
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_DO_SET_MODE],
        "now LAND"
    );
    match &out[..] {
        [Msg::COMMAND_LONG(c)] => assert_eq!((c.param2, c.param3), (4.0, 6.0), "AUTO.LAND"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn px4_mode_that_never_shows_fails_after_the_attempts_and_another_mode_is_never_overridden() {
    let ok = MavResult::MAV_RESULT_ACCEPTED;
    let mut v = px4_go();
    let mut sent = commands(&v.request_actions(s(1.0), &[a("go")])).len();
    let mut t = 1.0;
    for _ in 0..6 {
        v.on_frame(s(t + 0.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
        v.on_frame(s(t + 1.0), &px4_heartbeat(4, 3));
        sent += commands(&v.tick(s(t + 3.5))).len();
        t += 3.5;
    }
    let r = results(&mut v);
    assert_eq!(sent, 3, "max_mode_attempts = 3 in all: {r:?}");
    assert!(
        r.iter().any(
            |x| x == "SET_MODE AUTO FAILED (accepted 3 times, but the vehicle stays in LOITER)"
        ),
        "{r:?}"
    );
    assert_eq!(
        r.last().map(String::as_str),
        Some("SET_MODE LAND SKIPPED (earlier step failed)")
    );

    // The pilot switches to Position right after AUTO is accepted: never overridden.
    let mut v = px4_go();
    v.request_actions(s(1.0), &[a("go")]);
    v.on_frame(s(1.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
    v.on_frame(s(2.0), &px4_heartbeat(3, 0)); // POSCTL
    assert!(commands(&v.tick(s(4.5))).is_empty());
    assert!(commands(&v.tick(s(9.0))).is_empty());
    let r = results(&mut v);
    assert!(
        r.iter()
            .any(|x| x.ends_with("went to POSHOLD, not AUTO: not overriding)")),
        "{r:?}"
    );
}

#[test]
fn ardupilot_accepted_mode_is_the_mode() {
    // ArduPilot acknowledges DO_SET_MODE after set_mode() succeeded: no wait.
    let mut t = table();
    t.insert(
        a("go"),
        "go",
        vec![Step::Mode(FlightMode::Auto), Step::Mode(FlightMode::Land)],
    );
    let mut v = Vehicle::new(VehicleConfig::default(), t, None);
    v.on_frame(s(0.0), &hb(5, true)); // LOITER
    let out = v.request_actions(s(1.0), &[a("go")]);
    assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    let out = v.on_frame(
        s(1.1),
        &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
    );
    assert_eq!(
        commands(&out),
        vec![MavCmd::MAV_CMD_DO_SET_MODE],
        "LAND at once"
    );
}

fn param_requests(out: &[Msg]) -> Vec<String> {
    out.iter()
        .filter_map(|m| match m {
            Msg::PARAM_REQUEST_READ(p) => Some(p.param_id.to_str().unwrap_or("").to_string()),
            _ => None,
        })
        .collect()
}

fn param_value(name: &str, value: f32, param_type: MavParamType) -> Msg {
    Msg::PARAM_VALUE(PARAM_VALUE_DATA {
        param_value: value,
        param_id: name.into(),
        param_type,
        ..PARAM_VALUE_DATA::DEFAULT
    })
}

#[test]
fn ardupilot_pack_capacity_is_read_retried_until_answered_and_observed() {
    let mut v = vehicle();
    let mut asked = Vec::new();
    for t in 0..20 {
        asked.extend(param_requests(&v.on_frame(s(t as f64), &hb(0, false))));
    }
    // Asked, re-asked every PACK_PARAM_RETRY while unanswered, never more than the attempts.
    asked.retain(|n| n == "BATT_CAPACITY");
    assert_eq!(asked, vec!["BATT_CAPACITY"; PACK_PARAM_ATTEMPTS as usize]);
    // A parameter nobody asked for changes nothing.
    v.on_frame(
        s(21.0),
        &frame(param_value(
            "BATT_LOW_MAH",
            500.0,
            MavParamType::MAV_PARAM_TYPE_INT32,
        )),
    );
    assert_eq!(v.telemetry.get("battery_capacity_mah"), None);
    // ArduPilot casts its integer parameters to float.
    v.on_frame(
        s(22.0),
        &frame(param_value(
            "BATT_CAPACITY",
            3300.0,
            MavParamType::MAV_PARAM_TYPE_INT32,
        )),
    );
    assert_eq!(v.telemetry.get("battery_capacity_mah"), Some(3300.0));
    // Answered at once: asked once only.
    let mut v = vehicle();
    v.on_frame(s(0.0), &hb(0, false));
    v.on_frame(
        s(0.5),
        &frame(param_value(
            "BATT_CAPACITY",
            5000.0,
            MavParamType::MAV_PARAM_TYPE_REAL32,
        )),
    );
    let out: Vec<Msg> = (1..6)
        .flat_map(|t| v.on_frame(s(t as f64), &hb(0, false)))
        .collect();
    assert!(
        !param_requests(&out).iter().any(|n| n == "BATT_CAPACITY"),
        "answered: not asked again"
    );
}

#[test]
fn px4_pack_parameters_are_decoded_bytewise_and_an_unset_capacity_is_said() {
    let mut v = vehicle();
    let out = px4_ready(&mut v, 0.0);
    assert_eq!(
        param_requests(&out)[..2],
        ["BAT1_CAPACITY".to_string(), "BAT1_N_CELLS".to_string()]
    );
    // PX4 SIH: capacity -1 (a float parameter), 4 cells (an int32, sent bytewise).
    v.on_frame(
        s(1.0),
        &px4_frame(param_value(
            "BAT1_CAPACITY",
            -1.0,
            MavParamType::MAV_PARAM_TYPE_REAL32,
        )),
    );
    v.on_frame(
        s(1.1),
        &px4_frame(param_value(
            "BAT1_N_CELLS",
            f32::from_bits(4),
            MavParamType::MAV_PARAM_TYPE_INT32,
        )),
    );
    assert_eq!(v.telemetry.get("battery_capacity_mah"), Some(-1.0));
    assert_eq!(v.telemetry.get("battery_cells"), Some(4.0));
    let said = v
        .take_link_events()
        .iter()
        .map(|e| e.to_string())
        .collect::<Vec<_>>();
    assert!(
        said.iter()
            .any(|e| e.contains("BAT1_CAPACITY = -1") && e.contains("params [battery]")),
        "{said:?}"
    );
}

/// `tracker_onboard_only` (fly --learn-cpt with a dedicated onboard link on an unsigned
/// autopilot link): the tracker's reports on the autopilot link are refused from the allowed
/// tracker 1/100 and from the autopilot's own ids alike; the same report from the onboard link
/// counts; the autopilot's rangefinder still does.
#[test]
fn tracker_reports_only_from_the_onboard_link_when_asked() {
    let mut v = Vehicle::new(
        VehicleConfig {
            tracker_onboard_only: true,
            ..VehicleConfig::default()
        },
        table(),
        None,
    );
    v.on_frame(s(0.0), &hb(4, false));
    assert_eq!(v.target, Some((1, 1)));
    v.on_frame(s(0.1), &from(1, 100, frame(nvf("tgt_det", 1.0))));
    v.on_frame(s(0.2), &frame(nvf("tgt_det", 1.0)));
    assert_eq!(v.telemetry.get("target_detected"), None);
    assert_eq!(v.foreign_monitor_frames(), 2);
    v.on_monitor_frame(s(0.3), &from(1, 100, frame(nvf("tgt_det", 1.0))));
    assert_eq!(v.telemetry.get("target_detected"), Some(1.0));
    let near = frame(Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
        min_distance: 20,
        max_distance: 4000,
        current_distance: 300,
        orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_NONE,
        ..DISTANCE_SENSOR_DATA::DEFAULT
    }));
    v.on_frame(s(0.4), &near);
    assert!(v.take_events().contains(&Event::ObstacleDetected));
    // Without the setting, the allowed tracker on the autopilot link counts (as before).
    let mut v = vehicle();
    v.on_frame(s(0.0), &hb(4, false));
    v.on_frame(s(0.1), &from(1, 100, frame(nvf("tgt_det", 1.0))));
    assert_eq!(v.telemetry.get("target_detected"), Some(1.0));
}
