//! The autopilot's own mission: downloaded, watched for a ground station's upload, flown
//! without an upload of ours.

use super::*;
use crate::mission::MissionItem;

fn watching() -> Vehicle {
    let mut t = ActionTable::new(&test_catalogue());
    t.insert(
        a("follow_trajectory"),
        "follow_trajectory",
        vec![Step::UploadMission, Step::Mode(FlightMode::Auto)],
    );
    let mut v = Vehicle::new(VehicleConfig::default(), t, None);
    v.watch_autopilot_mission();
    v
}

/// ArduPilot's answer to a download: home at seq 0, then the GCS's items.
fn mission(last_alt: f32) -> Vec<MissionItem> {
    vec![
        MissionItem::waypoint(-353_632_610, 1_491_652_300, 584.0),
        MissionItem {
            command: MavCmd::MAV_CMD_NAV_TAKEOFF,
            ..MissionItem::waypoint(0, 0, 20.0)
        },
        MissionItem::waypoint(-353_627_610, 1_491_652_300, last_alt),
    ]
}

fn requests(out: &[Msg]) -> (bool, Vec<u16>) {
    let list = out
        .iter()
        .any(|m| matches!(m, Msg::MISSION_REQUEST_LIST(_)));
    let seqs = out
        .iter()
        .filter_map(|m| match m {
            Msg::MISSION_REQUEST_INT(r) => Some(r.seq),
            _ => None,
        })
        .collect();
    (list, seqs)
}

/// Answer the download the vehicle started, as ArduPilot does: COUNT, then each requested item.
fn answer(v: &mut Vehicle, t: f64, items: &[MissionItem], px4: bool) {
    let f = |m| if px4 { px4_frame(m) } else { frame(m) };
    let mut out = v.on_frame(
        s(t),
        &f(Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count: items.len() as u16,
            ..MISSION_COUNT_DATA::DEFAULT
        })),
    );
    for _ in 0..items.len() {
        let (_, seqs) = requests(&out);
        let seq = seqs[0];
        let it = &items[seq as usize];
        out = v.on_frame(
            s(t),
            &f(Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
                seq,
                command: it.command,
                frame: it.frame,
                x: it.x,
                y: it.y,
                z: it.z,
                ..MISSION_ITEM_INT_DATA::DEFAULT
            })),
        );
    }
    assert!(
        out.iter().any(|m| matches!(m, Msg::MISSION_ACK(_))),
        "{out:?}"
    );
}

fn current(total: u16, mission_id: u32) -> Msg {
    Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
        total,
        mission_id,
        ..MISSION_CURRENT_DATA::DEFAULT
    })
}

#[test]
fn the_mission_is_downloaded_when_the_autopilot_is_chosen_and_handed_over_once() {
    let mut v = watching();
    let out = v.on_frame(s(0.0), &hb(0, false));
    assert!(requests(&out).0, "MISSION_REQUEST_LIST at once: {out:?}");
    assert_eq!(
        v.take_autopilot_mission(),
        None,
        "nothing before the answer"
    );
    answer(&mut v, 0.1, &mission(20.0), false);
    assert_eq!(
        v.take_autopilot_mission(),
        Some(AutopilotMission::Loaded(mission(20.0)))
    );
    assert_eq!(v.take_autopilot_mission(), None);
    // Not watching: nothing is downloaded.
    let mut plain = Vehicle::new(
        VehicleConfig::default(),
        ActionTable::new(&test_catalogue()),
        None,
    );
    let out: Vec<Msg> = (0..10)
        .flat_map(|t| plain.on_frame(s(t as f64), &hb(0, false)))
        .collect();
    assert!(!requests(&out).0);
}

#[test]
fn arducopter_same_length_change_is_found_by_the_periodic_download_home_excluded() {
    let mut v = watching();
    v.on_frame(s(0.0), &hb(0, false));
    answer(&mut v, 0.1, &mission(20.0), false);
    v.take_autopilot_mission();
    // Before the poll: no download.
    assert!(!requests(&v.on_frame(s(1.0), &hb(0, false))).0);
    let out = v.on_frame(s(0.1) + MISSION_POLL, &hb(0, false));
    assert!(requests(&out).0, "downloaded again after {MISSION_POLL:?}");
    // Home moved (ArduPilot resets it when arming): the same mission, no change.
    let mut moved = mission(20.0);
    moved[0].x += 100;
    answer(&mut v, 2.2, &moved, false);
    assert_eq!(v.take_autopilot_mission(), None);
    // A GCS uploaded a new last waypoint, same length.
    let out = v.on_frame(s(4.3), &hb(0, false));
    assert!(requests(&out).0);
    answer(&mut v, 4.4, &mission(35.0), false);
    assert_eq!(
        v.take_autopilot_mission(),
        Some(AutopilotMission::Changed(mission(35.0)))
    );
    let said = v.take_link_events();
    assert!(
        said.iter()
            .any(|e| e.to_string().contains("autopilot mission changed: 3 items")),
        "{said:?}"
    );
    assert!(
        v.take_events()
            .iter()
            .any(|e| e.to_string().contains("changed"))
    );
}

#[test]
fn a_changed_total_asks_for_the_mission_at_once() {
    let mut v = watching();
    v.on_frame(s(0.0), &hb(0, false));
    answer(&mut v, 0.1, &mission(20.0), false);
    v.take_autopilot_mission();
    assert!(!requests(&v.on_frame(s(0.2), &frame(current(2, 0)))).0);
    let out = v.on_frame(s(0.3), &frame(current(3, 0)));
    assert!(requests(&out).0, "a new total: downloaded before the poll");
    let mut longer = mission(20.0);
    longer.push(MissionItem::waypoint(-353_622_610, 1_491_652_300, 20.0));
    answer(&mut v, 0.4, &longer, false);
    assert_eq!(
        v.take_autopilot_mission(),
        Some(AutopilotMission::Changed(longer))
    );
}

#[test]
fn px4_mission_id_replaces_the_periodic_download() {
    let mut v = watching();
    let hb_px4 = px4_frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
        autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        ..HEARTBEAT_DATA::DEFAULT
    }));
    assert!(requests(&v.on_frame(s(0.0), &hb_px4)).0);
    let px4_mission = mission(20.0)[1..].to_vec();
    answer(&mut v, 0.1, &px4_mission, true);
    assert!(matches!(
        v.take_autopilot_mission(),
        Some(AutopilotMission::Loaded(i)) if i.len() == 2
    ));
    v.on_frame(s(0.2), &px4_frame(current(2, 0xabcd)));
    let later: Vec<Msg> = (1..10)
        .flat_map(|t| v.on_frame(s(t as f64), &px4_frame(current(2, 0xabcd))))
        .collect();
    assert!(!requests(&later).0, "an unchanged mission_id: no download");
    let out = v.on_frame(s(10.0), &px4_frame(current(2, 0x1234)));
    assert!(requests(&out).0, "a new mission_id: downloaded");
    let mut changed = px4_mission.clone();
    changed[1].z = 30.0;
    answer(&mut v, 10.1, &changed, true);
    assert_eq!(
        v.take_autopilot_mission(),
        Some(AutopilotMission::Changed(changed))
    );
}

#[test]
fn the_route_step_uploads_nothing_and_waits_for_the_downloaded_mission() {
    let mut v = watching();
    v.on_frame(s(0.0), &hb(0, false));
    // Asked before the download answered: refused, never flown on an unknown mission.
    v.request_actions(s(0.05), &[a("follow_trajectory")]);
    let recs = v.take_records();
    assert!(
        recs.iter().any(|r| r.command == "MISSION_UPLOAD"
            && r.result.to_string().contains("not downloaded yet")),
        "{recs:?}"
    );
    answer(&mut v, 0.1, &mission(20.0), false);
    v.exec.retry_failed_after = Duration::ZERO;
    let out = v.request_actions(s(10.0), &[a("follow_trajectory")]);
    assert!(
        !out.iter().any(|m| matches!(m, Msg::MISSION_COUNT(_))),
        "no upload of ours: {out:?}"
    );
    assert!(
        out.iter()
            .any(|m| matches!(m, Msg::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_DO_SET_MODE)),
        "AUTO on the autopilot's mission: {out:?}"
    );
    let recs = v.take_records();
    assert!(
        recs.iter()
            .any(|r| r.result.to_string().starts_with("SKIPPED")),
        "{recs:?}"
    );
}

#[test]
fn the_companions_own_verified_upload_is_no_change() {
    let mut v = watching();
    v.on_frame(s(0.0), &hb(0, false));
    answer(&mut v, 0.1, &mission(20.0), false);
    v.take_autopilot_mission();
    // An upload of ours (the protocol client drives it; the watch sees only its verified read-back).
    let ours = mission(42.0);
    let out = v.mission.upload(s(1.0), ours.clone()).unwrap();
    assert!(matches!(out[0], Msg::MISSION_COUNT(_)));
    for seq in 0..ours.len() as u16 {
        v.on_frame(
            s(1.1),
            &frame(Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                seq,
                ..MISSION_REQUEST_INT_DATA::DEFAULT
            })),
        );
    }
    v.on_frame(
        s(1.2),
        &frame(Msg::MISSION_ACK(MISSION_ACK_DATA {
            mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
            ..MISSION_ACK_DATA::DEFAULT
        })),
    );
    answer(&mut v, 1.3, &ours, false); // the verifying download
    assert_eq!(v.take_autopilot_mission(), None);
    // The next periodic download finds what we uploaded: still no change.
    let out = v.on_frame(s(1.3) + MISSION_POLL, &hb(0, false));
    assert!(requests(&out).0);
    answer(&mut v, 4.0, &ours, false);
    assert_eq!(
        v.take_autopilot_mission(),
        None,
        "our own upload is not a change"
    );
}
