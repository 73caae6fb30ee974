use super::*;
use crate::dialect::{MavCmd, MavFrame};
use crate::test_support::default_params_dir;

fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// The steps of the shipped action named `name`.
fn own<'a>(t: &'a ActionTable, name: &str) -> Option<&'a [Step]> {
    t.steps(Flown::Action(crate::test_support::catalogue().id(name)?))
}

#[test]
fn shipped_params_load() {
    let dir = default_params_dir();
    let t = crate::test_support::commands(&dir.join("commands.toml")).unwrap();
    for a in [
        "take_off",
        "follow_trajectory",
        "avoid_obstacle",
        "land",
        "replan_and_land",
        "return_to_base",
    ] {
        assert!(own(&t, a).is_some(), "{a} missing");
    }
    assert_eq!(own(&t, "take_off").unwrap()[1], Step::Arm);
    assert!(matches!(
        own(&t, "take_off").unwrap()[2],
        Step::Command {
            command: MavCmd::MAV_CMD_NAV_TAKEOFF,
            ..
        }
    ));
    assert_eq!(
        own(&t, "return_to_base").unwrap(),
        vec![Step::Mode(FlightMode::Rtl)]
    );
    // Staying on the ground commands nothing (an addition to the paper's actions).
    assert_eq!(own(&t, "stay_on_ground").unwrap(), Vec::<Step>::new());
    let r =
        crate::test_support::disk(Route::load)(&dir.join("missions/tracking_route.toml")).unwrap();
    assert!(r.waypoints.len() >= 3);
    let lp = crate::test_support::disk(LinkParams::load)(&dir.join("link.toml")).unwrap();
    assert_eq!(lp.stream_ids().len(), 15);
}

#[test]
fn bad_commands_are_rejected_with_entry() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        ("[x]\nsteps = []\n", "x.steps", "at least one"),
        (
            "[x]\nsteps = [{ mode = \"WARP\" }]\n",
            "x.steps[0]",
            "unknown mode",
        ),
        (
            "[x]\nsteps = [{ command = \"MAV_CMD_FLY_TO_MOON\" }]\n",
            "x.steps[0]",
            "unknown MAVLink command",
        ),
        (
            "[x]\nsteps = [{ mode = \"RTL\", arm = true }]\n",
            "x.steps[0]",
            "exactly one",
        ),
        (
            "[x]\nsteps = [{ arm = false }]\n",
            "x.steps[0]",
            "not a step",
        ),
        (
            "[x]\nsteps = [{ command = \"MAV_CMD_NAV_LAND\", params = [1,2,3,4,5,6,7,8] }]\n",
            "x.steps[0]",
            "at most 7",
        ),
        (
            "[x]\nsteps = [{ mode = \"RTL\", params = [1] }]\n",
            "x.steps[0]",
            "only go with command",
        ),
        (
            "[x]\nnothing = true\nsteps = [{ mode = \"RTL\" }]\n",
            "x.steps",
            "must be empty",
        ),
    ];
    for (text, entry, why) in cases {
        let p = write(&d, "c.toml", text);
        let e = crate::test_support::commands(&p).expect_err(text);
        assert_eq!(e.entry, entry, "{text}");
        assert!(e.reason.contains(why), "{text}: {e}");
    }
    let p = write(&d, "c.toml", "[x]\nstepz = []\n");
    assert!(crate::test_support::commands(&p).is_err());
}

#[test]
fn bad_routes_are_rejected_with_entry() {
    let d = tempfile::tempdir().unwrap();
    let cases = [
        (
            "altitude_m = 20\nwaypoint = []\n",
            "waypoint",
            "at least one",
        ),
        (
            "altitude_m = -1\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n",
            "altitude_m",
            "positive",
        ),
        (
            "frame = \"polar\"\naltitude_m = 20\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n",
            "frame",
            "expected",
        ),
        (
            "altitude_m = 20\n[[waypoint]]\nnorth_m = 1\n",
            "waypoint[0]",
            "north_m and east_m",
        ),
        (
            "altitude_m = 20\n[[waypoint]]\nlat_deg = 1\nlon_deg = 1\n",
            "waypoint[0]",
            "relative route",
        ),
        (
            "frame = \"absolute\"\naltitude_m = 20\n[[waypoint]]\nlat_deg = 91\nlon_deg = 1\n",
            "waypoint[0]",
            "latitude",
        ),
        (
            "altitude_m = 20\n[[waypoint]]\nnorth_m = 1\neast_m = 1\nalt_m = -5\n",
            "waypoint[0].alt_m",
            "0..=10000",
        ),
        (
            "altitude_m = 1e300\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n",
            "altitude_m",
            "out of range",
        ),
        (
            "altitude_m = 20000\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n",
            "altitude_m",
            "at most 10000",
        ),
        (
            "altitude_m = 20\n[[waypoint]]\nnorth_m = 1e9\neast_m = 1\n",
            "waypoint[0]",
            "50 km",
        ),
    ];
    let many = |n: usize| {
        "altitude_m = 20\n".to_string() + &"[[waypoint]]\nnorth_m = 1\neast_m = 1\n".repeat(n)
    };
    let (w1001, w70000) = (many(1001), many(70_000));
    let cases = cases.into_iter().chain([
        (w1001.as_str(), "waypoint", "at most 1000"),
        (w70000.as_str(), "-", "a params file is at most"),
    ]);
    for (text, entry, why) in cases {
        let p = write(&d, "r.toml", text);
        let e = crate::test_support::disk(Route::load)(&p).expect_err(text);
        assert_eq!(e.entry, entry, "{text}");
        assert!(e.reason.contains(why), "{text}: {e}");
    }
}

#[test]
fn relative_route_items_start_at_home() {
    let d = tempfile::tempdir().unwrap();
    let p = write(
        &d,
        "r.toml",
        "altitude_m = 25\n[[waypoint]]\nnorth_m = 100\neast_m = 0\n[[waypoint]]\nnorth_m = 0\neast_m = 50\nalt_m = 30\n",
    );
    let r = crate::test_support::disk(Route::load)(&p).unwrap();
    let home = (473_977_420, 85_455_940);
    let items = r.items(home);
    assert_eq!(
        items.len(),
        5,
        "home, take-off, two waypoints, RTL: {items:?}"
    );
    assert_eq!(items[4].command, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH);
    assert_eq!((items[0].x, items[0].y), home);
    assert_eq!(items[1].command, MavCmd::MAV_CMD_NAV_TAKEOFF);
    assert_eq!(items[1].z, 25.0);
    // 100 m north = 100 / 111319.49 deg = 8983 * 1e-7 deg.
    assert_eq!(items[2].x - home.0, 8983);
    assert_eq!(items[2].y, home.1);
    assert_eq!(items[3].z, 30.0);
    assert_eq!(items[2].z, 25.0);
}

#[test]
fn bad_link_params() {
    let d = tempfile::tempdir().unwrap();
    let base = "decision_period_s = 1.0\narm_wait_s = 30\nmax_arm_attempts = 3\n[telemetry]\nobstacle_near_m = 15\nbattery_thresholds_pct = [30]\ndistance_max_age_s = 2\n";
    let p = write(
        &d,
        "l.toml",
        &format!("{base}[streams]\nNOT_A_MESSAGE = 2\n"),
    );
    assert_eq!(
        crate::test_support::disk(LinkParams::load)(&p)
            .unwrap_err()
            .entry,
        "streams.NOT_A_MESSAGE"
    );
    let p = write(&d, "l.toml", &format!("{base}[streams]\nWIND = 0\n"));
    assert!(
        crate::test_support::disk(LinkParams::load)(&p)
            .unwrap_err()
            .reason
            .contains("rate")
    );
    let p = write(&d, "l.toml", &format!("{base}[streams]\nWIND = 1\n"));
    assert_eq!(
        crate::test_support::disk(LinkParams::load)(&p)
            .unwrap()
            .stream_ids(),
        vec![(168, 1.0)]
    );
}

#[test]
fn flight_params_are_checked_with_entry() {
    let d = tempfile::tempdir().unwrap();
    let base = "decision_period_s = 1.0\narm_wait_s = 30\nmax_arm_attempts = 3\n[streams]\nWIND = 1\n[telemetry]\nobstacle_near_m = 15\nbattery_thresholds_pct = [30]\ndistance_max_age_s = 2\n";
    let p = write(&d, "l.toml", base);
    assert_eq!(
        crate::test_support::disk(LinkParams::load)(&p)
            .unwrap()
            .flight,
        FlightParams::default()
    );
    for (line, entry) in [
        (
            "min_event_cycle_interval_s = 0",
            "flight.min_event_cycle_interval_s",
        ),
        (
            "min_event_cycle_interval_s = 2.0",
            "flight.min_event_cycle_interval_s",
        ),
        (
            "min_event_cycle_interval_s = nan",
            "flight.min_event_cycle_interval_s",
        ),
        ("landed_confirm_s = -1", "flight.landed_confirm_s"),
        ("zone_radius_m = inf", "flight.zone_radius_m"),
        (
            "zone_arrive_timeout_s = 1e30",
            "flight.zone_arrive_timeout_s",
        ),
        ("statustext_max_per_s = 0", "flight.statustext_max_per_s"),
    ] {
        let p = write(&d, "l.toml", &format!("{base}[flight]\n{line}\n"));
        assert_eq!(
            crate::test_support::disk(LinkParams::load)(&p)
                .unwrap_err()
                .entry,
            entry,
            "{line}"
        );
    }
    let p = write(&d, "l.toml", &format!("{base}[flight]\nzone_radius = 3\n"));
    assert!(
        crate::test_support::disk(LinkParams::load)(&p).is_err(),
        "unknown keys are refused"
    );
}

fn route(takeoff_first: bool) -> Route {
    Route {
        waypoints: vec![
            Waypoint::Relative {
                north_m: 50.0,
                east_m: 0.0,
                alt_m: 20.0,
            },
            Waypoint::Relative {
                north_m: 50.0,
                east_m: 50.0,
                alt_m: 20.0,
            },
        ],
        altitude_m: 20.0,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        takeoff_first,
        end: crate::actions::RouteEnd::ReturnToLaunch,
        operator_items: Vec::new(),
    }
}

/// PX4 has no home item and wants the take-off first; waypoints keep ArduPilot's seq numbers.
#[test]
fn px4_mission_has_takeoff_first_no_home_item_and_same_waypoint_seqs() {
    let home = (473_977_420, 85_455_940);
    for takeoff_first in [true, false] {
        let r = route(takeoff_first);
        let ap = r.mission_items(Flavor::ArduPilot, home);
        let px4 = r.mission_items(Flavor::Px4, home);
        assert_eq!(ap, r.items(home));
        assert_eq!(ap.len(), px4.len());
        let first_wp = if takeoff_first { 2 } else { 1 };
        let last = ap.len() - 1;
        assert_eq!(
            ap[first_wp..last],
            px4[first_wp..last],
            "waypoints at the same seq"
        );
        // No item at 0 m AMSL (ArduPilot's home placeholder) and none at lat/lon 0; the
        // mission's end is a LAND at wpf (on the ground: z 0), not ArduPilot's RTL.
        let (route_items, end) = px4.split_at(px4.len() - 1);
        assert_eq!(ap[last].command, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH);
        assert_eq!(end[0].command, MavCmd::MAV_CMD_NAV_LAND);
        assert_eq!((end[0].x, end[0].y), (px4[last - 1].x, px4[last - 1].y));
        assert!(
            route_items
                .iter()
                .all(|i| i.frame == MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT)
        );
        assert!(
            route_items
                .iter()
                .all(|i| i.x != 0 && i.y != 0 && i.z > 0.0),
            "{px4:?}"
        );
        if takeoff_first {
            assert_eq!(px4[0].command, MavCmd::MAV_CMD_NAV_TAKEOFF);
            assert_eq!((px4[0].x, px4[0].y, px4[0].z), (home.0, home.1, 20.0));
            assert_eq!(px4[1].command, MavCmd::MAV_CMD_NAV_WAYPOINT);
        } else {
            assert_eq!(px4[0], MissionItem::waypoint(home.0, home.1, 20.0));
        }
    }
}

/// Entries are checked against the action catalogue when the file loads: an entry is a vehicle
/// action's own or one shell-only entry flown for one, else the load names file, entry, reason.
#[test]
fn entries_are_resolved_against_the_action_catalogue() {
    let d = tempfile::tempdir().unwrap();
    let land = "[land]\nsteps = [{ mode = \"LAND\" }]\n";
    let resume = |name: &str, of: &str| {
        format!("[{name}]\nflown_for = \"{of}\"\nsteps = [{{ mode = \"AUTO\" }}]\n")
    };
    let cases = [
        (
            format!("{land}[landd]\nsteps = [{{ mode = \"LAND\" }}]\n"),
            "landd",
            "not an action of params/actions.toml",
        ),
        (
            format!("{land}[track_v3]\nsteps = [{{ mode = \"GUIDED\" }}]\n"),
            "track_v3",
            "an application action",
        ),
        (
            format!("{land}{}", resume("again", "nowhere")),
            "again.flown_for",
            "`nowhere` is not an entry of this file",
        ),
        (
            // A catalogue action, but without an entry of its own here.
            format!("{land}{}", resume("again", "return_to_base")),
            "again.flown_for",
            "`return_to_base` is not an entry of this file",
        ),
        (
            format!(
                "{land}{}{}",
                resume("again", "land"),
                resume("later", "land")
            ),
            "later.flown_for",
            "`again` is already flown for `land`",
        ),
    ];
    for (text, entry, why) in cases {
        let p = write(&d, "commands.toml", &text);
        let e = crate::test_support::commands(&p).expect_err(&text);
        assert_eq!(e.entry, entry, "{text}");
        assert!(e.reason.contains(why), "{text}: {e}");
        assert!(e.file.ends_with("commands.toml"), "{e}");
    }
}

/// The shell-only entry is found by the action it is flown for and named by its own name; the
/// action's own entry by the catalogue's name.
#[test]
fn a_shell_only_entry_is_flown_in_place_of_its_action() {
    let t = crate::test_support::commands(&default_params_dir().join("commands.toml")).unwrap();
    let cat = crate::test_support::catalogue();
    let follow = cat.id("follow_trajectory").unwrap();
    let resume = t.in_place_of(follow).expect("the shipped resume entry");
    assert_eq!(resume, Flown::InPlaceOf(follow));
    assert_eq!(t.name(resume), "follow_trajectory_resume");
    assert_eq!(t.name(Flown::Action(follow)), "follow_trajectory");
    assert_ne!(t.steps(resume), t.steps(Flown::Action(follow)));
    assert_eq!(t.in_place_of(cat.id("land").unwrap()), None);
}

/// Safe without the companion: after the last waypoint the mission loiters there for the search
/// time limit, then ends by itself in RTL or LAND as params/link.toml's hand-off says, so a dead
/// companion never leaves the vehicle hovering at wpf; on PX4 in a LAND at wpf whatever the
/// hand-off (the shell's own end: PX4 flies a mission RTL as its RTL mode, which raced the
/// shell's LAND and flew home where the plan lands at wpf). The waypoints keep their seq numbers.
#[test]
fn the_uploaded_mission_ends_with_the_search_loiter_then_rtl_or_land() {
    let home = (473_977_420, 85_455_940);
    let mut r = route(true);
    r.search_time_limit_s = Some(300.0);
    let wpf_seq = usize::from(r.last_waypoint_seq());
    assert_eq!(wpf_seq, 3, "home, take-off, wp1, wpf");
    for flavor in [Flavor::ArduPilot, Flavor::Px4] {
        let items = r.mission_items(flavor, home);
        assert_eq!(items.len(), wpf_seq + 3, "{flavor:?}: {items:?}");
        let (wpf, loiter, end) = (&items[wpf_seq], &items[wpf_seq + 1], &items[wpf_seq + 2]);
        assert_eq!(wpf.command, MavCmd::MAV_CMD_NAV_WAYPOINT);
        assert_eq!(loiter.command, MavCmd::MAV_CMD_NAV_LOITER_TIME);
        assert_eq!(
            loiter.params[0], 300.0,
            "loiter seconds = search_time_limit_s"
        );
        assert_eq!(
            (loiter.x, loiter.y, loiter.z),
            (wpf.x, wpf.y, wpf.z),
            "at wpf"
        );
        match flavor {
            Flavor::Px4 => {
                assert_eq!(end.command, MavCmd::MAV_CMD_NAV_LAND);
                assert_eq!(
                    (end.x, end.y, end.z),
                    (wpf.x, wpf.y, 0.0),
                    "PX4 lands at wpf"
                );
            }
            _ => assert_eq!(end.command, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH),
        }
    }
    r.end = RouteEnd::Land;
    assert_eq!(
        r.mission_items(Flavor::Px4, home).last(),
        r.items(home).last(),
        "the hand-off's LAND: the same end on both"
    );
    let items = r.items(home);
    let (wpf, end) = (&items[wpf_seq], items.last().unwrap());
    assert_eq!(end.command, MavCmd::MAV_CMD_NAV_LAND);
    assert_eq!((end.x, end.y, end.z), (wpf.x, wpf.y, 0.0), "lands at wpf");
    // Without a search limit the mission ends at wpf at once; a search longer than ArduPilot's
    // 16-bit loiter seconds is cut to them, never wrapped.
    r.search_time_limit_s = None;
    assert_eq!(r.items(home).len(), wpf_seq + 2);
    r.search_time_limit_s = Some(86_400.0);
    assert_eq!(r.items(home)[wpf_seq + 1].params[0], 65_535.0);
    assert_eq!(RouteEnd::for_handoff(Handoff::Land), RouteEnd::Land);
    for h in [Handoff::Rtl, Handoff::Hold, Handoff::None] {
        assert_eq!(RouteEnd::for_handoff(h), RouteEnd::ReturnToLaunch);
    }
}

/// An operator's mission (`fly --mission FILE.plan`) is uploaded as its items after home; one
/// that does not end the flight gets the route's end (RTL here), so a dead companion never
/// leaves the vehicle hovering; one ending with RTL or LAND gets nothing more. The mission
/// estimate's first and last waypoint are its first and last item flying to a position.
#[test]
fn an_operator_mission_is_uploaded_as_given_and_ended_when_it_does_not_end() {
    let home = (-353_632_610, 1_491_652_300);
    let takeoff = MissionItem {
        command: MavCmd::MAV_CMD_NAV_TAKEOFF,
        ..MissionItem::waypoint(0, 0, 20.0)
    };
    let speed = MissionItem {
        command: MavCmd::MAV_CMD_DO_CHANGE_SPEED,
        params: [1.0, 8.0, -1.0, 0.0],
        ..MissionItem::waypoint(0, 0, 0.0)
    };
    let wp1 = MissionItem::waypoint(-353_622_610, 1_491_652_300, 20.0);
    let wp2 = MissionItem::waypoint(-353_622_610, 1_491_672_300, 25.0);
    let mut r = route(true);
    r.operator_items = vec![takeoff.clone(), speed.clone(), wp1.clone(), wp2.clone()];
    let items = r.mission_items(Flavor::ArduPilot, home);
    assert_eq!(items.len(), 6, "{items:#?}");
    assert_eq!(items[0].x, home.0, "home at seq 0");
    assert_eq!(items[1..5], [takeoff.clone(), speed, wp1, wp2.clone()]);
    assert_eq!(items[5].command, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH);
    assert_eq!((r.first_waypoint_seq(), r.last_waypoint_seq()), (3, 4));
    // PX4 keeps an operator mission's end (the plan derives its return), in the frame it takes.
    let px4 = r.mission_items(Flavor::Px4, home);
    assert_eq!(px4[5].command, MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH);
    assert_eq!(
        px4[5].frame,
        MavFrame::MAV_FRAME_MISSION,
        "PX4: else UNSUPPORTED"
    );
    r.end = crate::actions::RouteEnd::Land;
    let items = r.items(home);
    assert_eq!(items[5].command, MavCmd::MAV_CMD_NAV_LAND);
    assert_eq!(
        (items[5].x, items[5].y),
        (wp2.x, wp2.y),
        "land at the last waypoint"
    );
    let land = MissionItem {
        command: MavCmd::MAV_CMD_NAV_LAND,
        ..MissionItem::waypoint(0, 0, 0.0)
    };
    r.operator_items = vec![takeoff, wp2, land];
    let items = r.items(home);
    assert_eq!(items.len(), 4, "ends with its own LAND: nothing added");
    assert_eq!((r.first_waypoint_seq(), r.last_waypoint_seq()), (2, 2));
}
