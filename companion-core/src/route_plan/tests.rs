use super::*;
use std::path::Path;

const SETTINGS: DeriveSettings = DeriveSettings {
    cruise_speed_mps: 10.0,
    climb_speed_mps: 2.5,
    descent_speed_mps: 1.5,
    waypoint_overhead_s: 0.0,
    speed_fraction: 1.0,
    rtl_loiter_s: 0.0,
};

/// Great-circle distance on a sphere of the mean Earth radius, by hand (independent of `geo`).
fn haversine_m(lat1: f64, lon1: f64, lat2: f64, lon2: f64) -> f64 {
    let r = 6_371_008.8;
    let (p1, p2) = (lat1.to_radians(), lat2.to_radians());
    let dp = p2 - p1;
    let dl = (lon2 - lon1).to_radians();
    let a = (dp / 2.0).sin().powi(2) + p1.cos() * p2.cos() * (dl / 2.0).sin().powi(2);
    2.0 * r * a.sqrt().asin()
}

fn wp(index: usize, lat: f64, lon: f64, alt: f64) -> Item {
    Item {
        index,
        kind: ItemKind::Waypoint(Position {
            lat_deg: lat,
            lon_deg: lon,
            alt_m: alt,
        }),
    }
}

fn route(home: (f64, f64), items: Vec<Item>) -> PlannedRoute {
    PlannedRoute {
        file: "r.plan".into(),
        home: Some(home),
        items,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        zones: vec![],
    }
}

fn square_zone(lon0: f64, lon1: f64, lat0: f64, lat1: f64, constraint: &str) -> String {
    format!(
        r#"{{"type":"FeatureCollection","features":[{{"type":"Feature","properties":{{"name":"sq","constraints":["{constraint}"]}},
        "geometry":{{"type":"Polygon","coordinates":[[[{lon0},{lat0}],[{lon1},{lat0}],[{lon1},{lat1}],[{lon0},{lat1}],[{lon0},{lat0}]]]}}}}]}}"#
    )
}

#[test]
fn a_leg_is_its_geodesic_length_checked_against_haversine_by_hand() {
    let (lat0, lon0, lat1, lon1) = (-35.363, 149.165, -35.360, 149.170);
    let r = route((lat0, lon0), vec![wp(1, lat1, lon1, 0.0)]);
    let acts = derive_activities(&r, &[], &SETTINGS);
    let leg = acts.iter().find(|a| a.kind == ActivityKind::Leg).unwrap();
    let by_hand = haversine_m(lat0, lon0, lat1, lon1);
    // The sphere and the WGS84 ellipsoid differ by at most ~0.5 %.
    assert!(
        (leg.length_m - by_hand).abs() / by_hand < 0.005,
        "{} vs {by_hand}",
        leg.length_m
    );
    assert!(leg.length_m > 500.0);
    assert_eq!(leg.source, "leg home->1");
    assert_eq!(leg.speed_mps, 10.0);
}

#[test]
fn a_leg_adds_its_climb_and_take_off_and_landing_are_vertical() {
    let r = route(
        (0.0, 0.0),
        vec![
            Item {
                index: 0,
                kind: ItemKind::TakeOff { alt_m: 20.0 },
            },
            wp(1, 0.0, 0.001, 50.0),
        ],
    );
    let acts = derive_activities(&r, &[], &SETTINGS);
    let names: Vec<&str> = acts.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["take_off", "leghome-1", "land"]);
    assert_eq!(acts[0].length_m, 20.0);
    assert_eq!(acts[0].speed_mps, 2.5);
    let ground = haversine_m(0.0, 0.0, 0.0, 0.001);
    assert!(
        (acts[1].length_m - (ground + 30.0)).abs() < 0.5,
        "{}",
        acts[1].length_m
    );
    assert_eq!(acts[2].length_m, 50.0);
    assert_eq!(acts[2].speed_mps, 1.5);
}

#[test]
fn a_square_zone_crossed_by_a_straight_leg_splits_it_at_its_edges() {
    // Along the equator from lon 0 to 0.003; the zone spans lon 0.001..0.002: thirds.
    let zones = parse_zones(
        Path::new("z.geojson"),
        &square_zone(0.001, 0.002, -0.001, 0.001, "gps_degraded"),
    )
    .unwrap();
    let r = route((0.0, 0.0), vec![wp(1, 0.0, 0.003, 0.0)]);
    let acts = derive_activities(&r, &zones, &SETTINGS);
    let legs: Vec<&DerivedActivity> = acts
        .iter()
        .filter(|a| a.kind == ActivityKind::Leg)
        .collect();
    assert_eq!(legs.len(), 3, "{acts:#?}");
    let total = haversine_m(0.0, 0.0, 0.0, 0.003);
    for l in &legs {
        assert!((l.length_m - total / 3.0).abs() < 0.01 * total, "{l:?}");
    }
    assert!(legs[0].constraints.is_empty());
    assert_eq!(legs[1].constraints, ["gps_degraded"]);
    assert!(legs[2].constraints.is_empty());
    assert_eq!(legs[1].name, "leghome-1.2");
    assert_eq!(legs[1].source, "leg home->1 (part 2 of 3), in zone sq");
    // The landing at the end of the leg is outside the zone.
    assert!(acts.last().unwrap().constraints.is_empty());
}

#[test]
fn the_vehicles_waypoint_overhead_and_speed_fraction_reach_every_leg_once() {
    // A leg split in three by a zone, then an RTL: the overhead is held once per leg (half where
    // it speeds up, half where it brakes) and once by the return; take-off, landing and the search
    // are not legs.
    let zones = parse_zones(
        Path::new("z.geojson"),
        &square_zone(0.001, 0.002, -0.001, 0.001, "gps_degraded"),
    )
    .unwrap();
    let mut r = route(
        (0.0, 0.0),
        vec![
            Item {
                index: 0,
                kind: ItemKind::TakeOff { alt_m: 20.0 },
            },
            wp(1, 0.0, 0.003, 20.0),
            Item {
                index: 2,
                kind: ItemKind::ReturnToLaunch,
            },
        ],
    );
    r.search_time_limit_s = Some(30.0);
    let vehicle = DeriveSettings {
        waypoint_overhead_s: 4.5,
        speed_fraction: 0.8,
        ..SETTINGS
    };
    let acts = derive_activities(&r, &zones, &vehicle);
    // The middle third crosses the zone at the commanded 10 m/s; the end thirds, where the
    // vehicle accelerates and brakes, share the rest of the leg's L/8 s: (2L/3)/(L/8 - L/30).
    let ends = 80.0 / 11.0;
    let holds: Vec<(&str, f64, f64)> = acts
        .iter()
        .map(|a| (a.name.as_str(), a.hold_s, (a.speed_mps * 1e9).round() / 1e9))
        .collect();
    let ends = (ends * 1e9_f64).round() / 1e9;
    assert_eq!(
        holds,
        [
            ("take_off", 0.0, 2.5),
            ("leghome-1.1", 2.25, ends),
            ("leghome-1.2", 0.0, 10.0),
            ("leghome-1.3", 2.25, ends),
            ("search", 30.0, 0.0),
            ("return.1", 2.25, ends),
            ("return.2", 0.0, 10.0),
            ("return.3", 2.25, ends),
            ("land", 0.0, 1.5),
        ]
    );
    // A leg's moving time is the leg model's, L / (0.8 * 10), however it is split.
    let legs = acts.iter().filter(|a| a.kind == ActivityKind::Leg);
    let (moving_s, length_m) = legs.fold((0.0, 0.0), |(t, l), a| {
        (t + a.length_m / a.speed_mps, l + a.length_m)
    });
    assert!(
        (moving_s - length_m / 8.0).abs() < 1e-9,
        "{moving_s} vs {}",
        length_m / 8.0
    );
    // The defaults (no profile) plan as before: no hold on a leg, the commanded speed.
    let plain = derive_activities(&r, &zones, &SETTINGS);
    assert!(
        plain
            .iter()
            .filter(|a| matches!(a.kind, ActivityKind::Leg | ActivityKind::Return))
            .all(|a| a.hold_s == 0.0 && a.speed_mps == 10.0)
    );
}

#[test]
fn a_leg_ending_inside_a_zone_is_split_once_and_the_landing_there_is_constrained() {
    let zones = parse_zones(
        Path::new("z.geojson"),
        &square_zone(0.002, 0.004, -0.001, 0.001, "obstacle_dense"),
    )
    .unwrap();
    let r = route((0.0, 0.0), vec![wp(1, 0.0, 0.003, 0.0)]);
    let acts = derive_activities(&r, &zones, &SETTINGS);
    let legs: Vec<_> = acts
        .iter()
        .filter(|a| a.kind == ActivityKind::Leg)
        .collect();
    assert_eq!(legs.len(), 2);
    assert!((legs[0].length_m / (legs[0].length_m + legs[1].length_m) - 2.0 / 3.0).abs() < 1e-6);
    assert_eq!(acts.last().unwrap().constraints, ["obstacle_dense"]);
}

const PLAN: &str = r#"{"fileType":"Plan","version":1,"groundStation":"QGroundControl",
 "geoFence":{"version":2,"circles":[],"polygons":[
   {"inclusion":true,"version":1,"polygon":[[1,1],[1,2],[2,2]]},
   {"inclusion":true,"version":1,"name":"canyon","constraints":["gps_degraded"],
    "polygon":[[-0.001,0.001],[-0.001,0.002],[0.001,0.002],[0.001,0.001]]}]},
 "mission":{"version":2,"firmwareType":3,"vehicleType":2,"cruiseSpeed":15,"hoverSpeed":5,
  "plannedHomePosition":[0,0,100],
  "items":[
   {"type":"SimpleItem","command":22,"frame":3,"params":[0,0,0,null,0,0,20],"autoContinue":true,"doJumpId":1},
   {"type":"SimpleItem","command":178,"frame":2,"params":[1,4,-1,0,0,0,0],"autoContinue":true,"doJumpId":2},
   {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0,0.003,20],"autoContinue":true,"doJumpId":3},
   {"type":"SimpleItem","command":19,"frame":0,"params":[30,0,0,null,0,0.003,130],"autoContinue":true,"doJumpId":4},
   {"type":"SimpleItem","command":18,"frame":3,"params":[2,0,20,null,0,0.003,30],"autoContinue":true,"doJumpId":5},
   {"type":"SimpleItem","command":20,"frame":2,"params":[0,0,0,0,0,0,0],"autoContinue":true,"doJumpId":6}]},
 "rallyPoints":{"version":2,"points":[]}}"#;

#[test]
fn a_qgc_plan_gives_take_off_speed_changes_loiters_return_and_landing() {
    let r = parse_plan(Path::new("m.plan"), PLAN, 4.0).unwrap();
    assert_eq!(r.home, Some((0.0, 0.0)));
    assert_eq!(r.zones.len(), 1, "only the tagged fence polygon is a zone");
    assert_eq!(r.zones[0].name, "canyon");
    let acts = derive_activities(&r, &[], &SETTINGS);
    let names: Vec<&str> = acts.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "take_off",
            "leghome-2.1",
            "leghome-2.2",
            "leghome-2.3",
            "leg2-3",
            "loiter3",
            "loiter4",
            "return.1",
            "return.2",
            "return.3",
            "land"
        ],
        "{acts:#?}"
    );
    // DO_CHANGE_SPEED's 4 m/s for every leg after it.
    assert!(
        acts[1..]
            .iter()
            .filter(|a| a.kind == ActivityKind::Leg)
            .all(|a| a.speed_mps == 4.0)
    );
    // The autopilot's hover over home before the RTL descends is the return's last piece's.
    let loitering = DeriveSettings {
        rtl_loiter_s: 5.0,
        ..SETTINGS
    };
    let held: Vec<f64> = derive_activities(&r, &[], &loitering)
        .iter()
        .filter(|a| a.kind == ActivityKind::Return)
        .map(|a| a.hold_s)
        .collect();
    assert_eq!(held, [0.0, 0.0, 5.0]);
    // The RTL flies at the autopilot's return speed (its cruise), not the DO_CHANGE_SPEED's.
    assert!(
        acts.iter()
            .filter(|a| a.kind == ActivityKind::Return)
            .all(|a| a.speed_mps == SETTINGS.cruise_speed_mps && a.speed_mps != 4.0),
        "{acts:#?}"
    );
    assert_eq!(acts[2].constraints, ["gps_degraded"]);
    // The AMSL 130 m of item 3 is 30 m above the 100 m home: the climb to it is 10 m.
    assert!((acts[4].length_m - 10.0).abs() < 1e-6);
    assert_eq!(acts[5].hold_s, 30.0);
    // Two turns of 20 m at 4 m/s.
    assert!((acts[6].hold_s - 2.0 * std::f64::consts::TAU * 20.0 / 4.0).abs() < 1e-9);
    assert_eq!(acts[9].source, "leg 4->home (part 3 of 3)");
    assert_eq!(acts[10].length_m, 30.0);
    assert!(acts[10].source.contains("RTL"));
}

#[test]
fn route_limits_are_holds_at_the_last_waypoint_before_landing() {
    let mut r = route((0.0, 0.0), vec![wp(0, 0.0, 0.001, 20.0)]);
    r.search_time_limit_s = Some(300.0);
    r.tracking_time_limit_s = Some(20.0);
    let acts = derive_activities(&r, &[], &SETTINGS);
    let names: Vec<&str> = acts.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["leghome-0", "search", "tracking", "land"]);
    assert_eq!(acts[1].hold_s, 300.0);
    assert_eq!(acts[2].hold_s, 20.0);
    assert!(acts[1].source.contains("search time limit 300 s at 0"));
}

const WPL: &str = "QGC WPL 110\n\
0\t1\t0\t16\t0\t0\t0\t0\t0.0\t0.0\t50.0\t1\n\
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t15\t1\n\
2\t0\t3\t16\t0\t0\t0\t0\t0.0\t0.002\t15\t1\n\
3\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1\n";

#[test]
fn a_wpl_file_gives_home_take_off_waypoints_and_landing() {
    let r = parse_wpl(Path::new("m.waypoints"), WPL, 4.0).unwrap();
    assert_eq!(r.home, Some((0.0, 0.0)));
    let acts = derive_activities(&r, &[], &SETTINGS);
    let names: Vec<&str> = acts.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["take_off", "leghome-2", "land"]);
    assert_eq!(acts[0].length_m, 15.0);
    assert_eq!(acts[2].length_m, 15.0);
}

#[test]
fn the_kind_is_told_by_content_not_extension() {
    let p = Path::new("mission.txt");
    assert_eq!(detect_kind(p, WPL).unwrap(), MissionSourceKind::Wpl110);
    assert_eq!(detect_kind(p, PLAN).unwrap(), MissionSourceKind::QgcPlan);
    assert_eq!(
        detect_kind(p, "altitude_m = 3\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n").unwrap(),
        MissionSourceKind::RouteToml
    );
    assert_eq!(
        detect_kind(p, "[mission]\nname = \"x\"\n").unwrap(),
        MissionSourceKind::PanoramaToml
    );
    let e = detect_kind(p, "hello = ").unwrap_err();
    assert!(e.reason.contains("not a QGroundControl .plan"), "{e}");
}

fn plan_with_item(item: &str) -> String {
    format!(r#"{{"fileType":"Plan","mission":{{"plannedHomePosition":[0,0,0],"items":[{item}]}}}}"#)
}

#[test]
fn broken_plans_are_refused_with_the_item_and_the_reason() {
    let p = Path::new("bad.plan");
    let cases: &[(String, &str, &str)] = &[
        ("{\"fileType\":\"Plan\"".into(), "-", "not JSON"),
        ("{\"fileType\":\"Other\"}".into(), "fileType", "Plan"),
        ("{\"fileType\":\"Plan\",\"mission\":{}}".into(), "mission.items", "list"),
        (plan_with_item(r#"{"type":"SimpleItem","command":17,"frame":3,"params":[0,0,0,0,1,1,10]}"#), "mission.items[0]", "LOITER_UNLIM"),
        (plan_with_item(r#"{"type":"ComplexItem","complexItemType":"survey"}"#), "mission.items[0]", "complex item"),
        (plan_with_item(r#"{"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0]}"#), "mission.items[0]", "7 values"),
        (plan_with_item(r#"{"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,0,95,1,10]}"#), "mission.items[0]", "latitude"),
        (plan_with_item(r#"{"type":"SimpleItem","command":16,"frame":10,"params":[0,0,0,0,1,1,10]}"#), "mission.items[0]", "frame 10"),
        (plan_with_item(r#"{"type":"SimpleItem","command":183,"frame":2,"params":[0,0,0,0,0,0,0]}"#), "mission.items[0]", "command 183"),
        (plan_with_item(r#"{"type":"SimpleItem","command":178,"frame":2,"params":[1,"fast",0,0,0,0,0]}"#), "mission.items[0]", "params[1]"),
        (r#"{"fileType":"Plan","mission":{"items":[]},"geoFence":{"polygons":[{"constraints":["x"],"polygon":[[0,0],[0,1]]}]}}"#.into(), "geoFence.polygons[0]", "ring"),
        (r#"{"fileType":"Plan","mission":{"items":[]},"geoFence":{"polygons":[{"constraints":[],"polygon":[[0,0],[0,1],[1,1]]}]}}"#.into(), "geoFence.polygons[0]", "empty"),
    ];
    for (text, entry, reason) in cases {
        let e = parse_plan(p, text, 4.0).unwrap_err();
        assert_eq!(e.file, p);
        assert_eq!(e.entry, *entry, "{text}: {e}");
        assert!(e.reason.contains(reason), "{text}: {e}");
    }
}

#[test]
fn broken_wpl_files_are_refused_with_the_line_and_the_reason() {
    let p = Path::new("bad.waypoints");
    let cases: &[(&str, &str, &str)] = &[
        ("QGC WPL 100\n", "line 1", "QGC WPL 110"),
        ("QGC WPL 110\n1\t0\t3\t16\t0\n", "line 2", "5 fields"),
        (
            "QGC WPL 110\n\n1\t0\t3\t16\t0\t0\t0\t0\tx\t0\t10\t1\n",
            "line 3",
            "field 9",
        ),
        (
            "QGC WPL 110\n1\t0\t3\t17\t0\t0\t0\t0\t1\t1\t10\t1\n",
            "line 2",
            "seq 1: LOITER_UNLIM",
        ),
        (
            "QGC WPL 110\n1\t0\t0\t16\t0\t0\t0\t0\t1\t1\t10\t1\n",
            "line 2",
            "no home altitude",
        ),
        (
            "QGC WPL 110\n-1\t0\t3\t16\t0\t0\t0\t0\t1\t1\t10\t1\n",
            "line 2",
            "seq",
        ),
    ];
    for (text, entry, reason) in cases {
        let e = parse_wpl(p, text, 4.0).unwrap_err();
        assert_eq!(e.entry, *entry, "{text}: {e}");
        assert!(e.reason.contains(reason), "{text}: {e}");
    }
}

#[test]
fn broken_zone_files_are_refused_with_the_feature_and_the_reason() {
    let p = Path::new("bad.geojson");
    let feature = |geometry: &str, props: &str| {
        format!(
            r#"{{"type":"FeatureCollection","features":[{{"type":"Feature","properties":{props},"geometry":{geometry}}}]}}"#
        )
    };
    let square = r#"{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}"#;
    let cases: Vec<(String, &str, &str)> = vec![
        ("[1,2".into(), "-", "not GeoJSON"),
        (square.into(), "-", "FeatureCollection"),
        (
            feature(
                r#"{"type":"Point","coordinates":[0,0]}"#,
                r#"{"constraints":["a"]}"#,
            ),
            "features[0]",
            "not a Polygon",
        ),
        (
            feature(square, "{}"),
            "features[0]",
            "properties.constraints",
        ),
        (
            feature(square, r#"{"constraints":"gps_degraded"}"#),
            "features[0].properties.constraints",
            "list",
        ),
        (
            feature(square, r#"{"constraints":[]}"#),
            "features[0].properties.constraints",
            "empty",
        ),
        (
            feature(square, r#"{"constraints":[3]}"#),
            "features[0].properties.constraints",
            "3",
        ),
        (
            feature(
                r#"{"type":"Polygon","coordinates":[[[0,0],[200,0],[1,1],[0,0]]]}"#,
                r#"{"constraints":["a"]}"#,
            ),
            "features[0]",
            "longitude",
        ),
        (
            feature("null", r#"{"constraints":["a"]}"#),
            "features[0]",
            "no geometry",
        ),
    ];
    for (text, entry, reason) in &cases {
        let e = parse_zones(p, text).unwrap_err();
        assert_eq!(e.entry, *entry, "{text}: {e}");
        assert!(e.reason.contains(reason), "{text}: {e}");
    }
}

#[test]
fn a_multipolygon_zone_with_a_hole_constrains_only_its_area() {
    let text = r#"{"type":"FeatureCollection","features":[{"type":"Feature","id":"ring","properties":{"constraints":["obstacle_dense","gps_degraded"]},
      "geometry":{"type":"MultiPolygon","coordinates":[[[[0.001,-0.001],[0.005,-0.001],[0.005,0.001],[0.001,0.001],[0.001,-0.001]],
                                                         [[0.002,-0.0005],[0.004,-0.0005],[0.004,0.0005],[0.002,0.0005],[0.002,-0.0005]]]]}}]}"#;
    let zones = parse_zones(Path::new("z.geojson"), text).unwrap();
    assert_eq!(zones[0].name, "ring");
    let r = route((0.0, 0.0), vec![wp(1, 0.0, 0.006, 0.0)]);
    let acts = derive_activities(&r, &zones, &SETTINGS);
    let c: Vec<Vec<String>> = acts
        .iter()
        .filter(|a| a.kind == ActivityKind::Leg)
        .map(|a| a.constraints.clone())
        .collect();
    let both = vec!["gps_degraded".to_string(), "obstacle_dense".to_string()];
    assert_eq!(c, [vec![], both.clone(), vec![], both, vec![]]);
}

proptest::proptest! {
    #[test]
    fn random_bytes_never_panic_a_parser(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..400)) {
        let text = String::from_utf8_lossy(&bytes);
        let p = Path::new("fuzz");
        let _ = detect_kind(p, &text);
        let _ = parse_zones(p, &text);
        let _ = parse_plan(p, &text, 4.0);
        let _ = parse_wpl(p, &format!("QGC WPL 110\n{text}"), 4.0);
    }

    #[test]
    fn random_numbers_in_a_plan_never_panic_the_derivation(vals in proptest::collection::vec(-1e3f64..1e3, 14)) {
        let item = |c: u64, v: &[f64]| format!(r#"{{"type":"SimpleItem","command":{c},"frame":3,"params":[{},{},{},{},{},{},{}]}}"#, v[0], v[1], v[2], v[3], v[4], v[5], v[6]);
        let text = format!(r#"{{"fileType":"Plan","mission":{{"items":[{},{}]}}}}"#, item(16, &vals[..7]), item(19, &vals[7..]));
        if let Ok(r) = parse_plan(Path::new("p"), &text, 4.0) {
            let acts = derive_activities(&r, &[], &SETTINGS);
            proptest::prop_assert!(acts.iter().all(|a| a.length_m.is_finite() && a.length_m >= 0.0 && a.hold_s >= 0.0));
        }
    }

    /// What an autopilot answers is the network's: any numbers, any command and frame (f32 NaN and
    /// infinities included), refused or planned, never a panic or a negative length.
    #[test]
    fn any_autopilot_mission_is_refused_or_planned_never_a_panic(
        raw in proptest::collection::vec((0u64..300, 0u64..12, proptest::collection::vec(proptest::num::f32::ANY, 7)), 0..6),
        home_at_seq0 in proptest::bool::ANY,
    ) {
        let items: Vec<AutopilotItem> = raw.iter().enumerate().map(|(seq, (command, frame, p))| AutopilotItem {
            seq,
            command: *command,
            frame: *frame,
            params: std::array::from_fn(|k| f64::from(p[k])),
        }).collect();
        if let Ok(r) = parse_autopilot_mission(&items, home_at_seq0, None, 4.0) {
            let acts = derive_activities(&r, &[], &SETTINGS);
            proptest::prop_assert!(acts.iter().all(|a| a.length_m.is_finite() && a.length_m >= 0.0 && a.hold_s >= 0.0));
        }
    }
}

#[test]
fn derived_activities_replace_the_typed_ones_in_the_shipped_mission_and_allocate() {
    let params = crate::shipped::params();
    let settings = crate::guarantee::derive_settings(&params, "tracking").unwrap();
    assert_eq!(settings.cruise_speed_mps, 10.0);
    let zones = parse_zones(
        Path::new("z.geojson"),
        &square_zone(0.001, 0.002, -0.001, 0.001, "gps_degraded"),
    )
    .unwrap();
    let mut r = route(
        (0.0, 0.0),
        vec![
            Item {
                index: 0,
                kind: ItemKind::TakeOff { alt_m: 20.0 },
            },
            wp(1, 0.0, 0.003, 20.0),
        ],
    );
    r.search_time_limit_s = Some(300.0);
    r.tracking_time_limit_s = Some(20.0);
    let acts = derive_activities(&r, &zones, &settings);
    let spec = crate::guarantee::derived_mission(
        &params,
        "tracking",
        &acts,
        &[(Path::new("z.geojson"), &zones)],
    )
    .unwrap();
    let names: Vec<&str> = spec
        .problem
        .activities
        .iter()
        .map(|a| a.name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "take_off",
            "leghome-1.1",
            "leghome-1.2",
            "leghome-1.3",
            "search",
            "tracking",
            "land"
        ]
    );
    // In the GPS-degraded piece only the vision localisation is left (the class's rule).
    let typed = crate::guarantee::load_mission(&params, "tracking").unwrap();
    assert!(spec.problem.activities[2].ias.len() < spec.problem.activities[1].ias.len());
    let pre = crate::guarantee::Guarantee::pre_flight(&spec)
        .expect("the short route fits the shipped pack");
    let typed_pre = crate::guarantee::Guarantee::pre_flight(&typed).unwrap();
    assert!(
        pre.totals["energy_j"] < typed_pre.totals["energy_j"],
        "{:?} vs {:?}",
        pre.totals,
        typed_pre.totals
    );
}

#[test]
fn a_zone_naming_no_constraint_class_of_the_mission_is_refused_with_the_zone() {
    let params = crate::shipped::params();
    let zones = parse_zones(
        Path::new("z.geojson"),
        &square_zone(0.001, 0.002, -0.001, 0.001, "fog"),
    )
    .unwrap();
    let r = route((0.0, 0.0), vec![wp(1, 0.0, 0.003, 20.0)]);
    let acts = derive_activities(&r, &zones, &SETTINGS);
    let e = crate::guarantee::derived_mission(
        &params,
        "tracking",
        &acts,
        &[(Path::new("z.geojson"), &zones)],
    )
    .unwrap_err();
    assert_eq!(e.file, Path::new("z.geojson"));
    assert_eq!(e.entry, "features[0].constraints");
    assert!(e.reason.contains("`fog` is no constraint class"), "{e}");
}

/// WPL's mission as ArduPilot answers a download: its home at seq 0 in the absolute frame.
fn autopilot_items_of_wpl() -> Vec<AutopilotItem> {
    WPL.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l.split('\t').map(|x| x.parse().unwrap()).collect();
            AutopilotItem {
                seq: f[0] as usize,
                command: f[3] as u64,
                frame: f[2] as u64,
                params: [f[4], f[5], f[6], f[7], f[8], f[9], f[10]],
            }
        })
        .collect()
}

#[test]
fn an_autopilot_mission_plans_as_the_same_wpl_file() {
    let mut items = autopilot_items_of_wpl();
    // ArduPilot's home has a real position once it has a fix.
    items[0].params[4] = -35.363261;
    items[0].params[5] = 149.165230;
    items[2].params[4] = -35.363261;
    items[2].params[5] = 149.167230;
    let r = parse_autopilot_mission(&items, true, None, 4.0).unwrap();
    assert_eq!(r.home, Some((-35.363261, 149.165230)));
    assert_eq!(r.file, Path::new(AUTOPILOT_MISSION));
    let idx: Vec<usize> = r.items.iter().map(|i| i.index).collect();
    assert_eq!(idx, [1, 2, 3], "home is not flown");
    let acts = derive_activities(&r, &[], &SETTINGS);
    let names: Vec<&str> = acts.iter().map(|a| a.name.as_str()).collect();
    assert_eq!(names, ["take_off", "leghome-2", "land"]);
    let d = haversine_m(-35.363261, 149.165230, -35.363261, 149.167230);
    assert!(
        (acts[1].length_m - d).abs() / d < 0.01,
        "{}",
        acts[1].length_m
    );
}

#[test]
fn a_px4_mission_has_no_home_item_and_takes_the_reported_home() {
    let mut items = autopilot_items_of_wpl();
    items.remove(0);
    for (k, it) in items.iter_mut().enumerate() {
        it.seq = k;
    }
    // An absolute waypoint needs home's altitude: none reported, refused with the item.
    items[1].frame = 0;
    items[1].params[6] = 65.0;
    let e = parse_autopilot_mission(&items, false, None, 4.0).unwrap_err();
    assert_eq!(
        e.to_string(),
        "autopilot mission: item 1: an absolute (AMSL) altitude and no home altitude"
    );
    let r = parse_autopilot_mission(&items, false, Some((0.0, 0.0, 50.0)), 4.0).unwrap();
    assert_eq!(r.items[0].index, 0, "PX4's seq 0 is flown");
    assert!(matches!(r.items[1].kind, ItemKind::Waypoint(p) if p.alt_m == 15.0));
}

#[test]
fn an_unplannable_autopilot_item_is_refused_with_its_seq_and_reason() {
    let mut items = autopilot_items_of_wpl();
    items[2].command = 17; // LOITER_UNLIM
    let e = parse_autopilot_mission(&items, true, None, 4.0).unwrap_err();
    let said = e.to_string();
    assert!(
        said.starts_with("autopilot mission: item 2: LOITER_UNLIM"),
        "{said}"
    );
    items[2].command = 203; // DO_DIGICAM_CONTROL
    let e = parse_autopilot_mission(&items, true, None, 4.0).unwrap_err();
    assert!(e.to_string().contains("item 2: command 203"), "{e}");
}

/// A home-relative zones file (`"frame": "home_relative"`, `[east_m, north_m]`) sits on the same
/// route wherever home is: the same split at SITL's home and at PX4 SIH's; without a home it is
/// refused naming the file; an unknown frame or a position beyond 100 km is refused.
#[test]
fn a_home_relative_zone_splits_the_same_leg_wherever_home_is() {
    let text = r#"{"type": "FeatureCollection", "frame": "home_relative", "features": [
        {"type": "Feature", "properties": {"constraints": ["gps_degraded"]},
         "geometry": {"type": "Polygon", "coordinates":
           [[[-50, 100], [50, 100], [50, 200], [-50, 200], [-50, 100]]]}}]}"#;
    let p = Path::new("rel.geojson");
    assert!(zones_home_relative(text));
    for home in [(-35.363261, 149.165230), (47.397742, 8.545594)] {
        let zones = parse_zones_at(p, text, Some(home)).unwrap();
        // Due north 300 m: out 100 m, in 100 m, out 100 m.
        let r = route(
            home,
            vec![Item {
                index: 1,
                kind: ItemKind::Waypoint(Position::offset(home, 300.0, 0.0, 0.0)),
            }],
        );
        let acts = derive_activities(&r, &zones, &SETTINGS);
        let legs: Vec<_> = (acts.iter())
            .filter(|a| a.kind == ActivityKind::Leg)
            .collect();
        assert_eq!(legs.len(), 3, "{acts:#?}");
        for l in &legs {
            assert!((l.length_m - 100.0).abs() < 0.5, "{l:?}");
        }
        assert_eq!(legs[1].constraints, ["gps_degraded"]);
    }
    let e = parse_zones(p, text).unwrap_err().to_string();
    assert!(e.contains("rel.geojson") && e.contains("need home"), "{e}");
    let e = parse_zones_at(p, &text.replace("home_relative", "utm"), Some((0.0, 0.0)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("frame") && e.contains("home_relative"), "{e}");
    let e = parse_zones_at(p, &text.replace("[50, 200]", "[50, 2e6]"), Some((0.0, 0.0)))
        .unwrap_err()
        .to_string();
    assert!(e.contains("features[0]") && e.contains("100 km"), "{e}");
}

/// A leg is planned as the vehicle flies it: at the commanded speed (the route's DO_CHANGE_SPEED
/// or the autopilot's cruise speed) through the profile's leg model, t = L / (fraction x v) +
/// overhead, whichever IA runs: `fly` commands no IA's speed, so a TIO's cap (vision 6 m/s,
/// IR/US fusion 4 m/s) does not slow the plan below what is flown.
#[test]
fn a_leg_at_the_commanded_speed_takes_the_profiles_time_whatever_the_ia() {
    let params = crate::shipped::params();
    let vehicle = DeriveSettings {
        cruise_speed_mps: 10.0,
        waypoint_overhead_s: 4.5,
        speed_fraction: 0.8,
        ..SETTINGS
    };
    let r = route(
        (0.0, 0.0),
        vec![
            Item {
                index: 0,
                kind: ItemKind::TakeOff { alt_m: 20.0 },
            },
            wp(1, 0.0, 0.003, 20.0),
            Item {
                index: 2,
                kind: ItemKind::ChangeSpeed { mps: 5.0 },
            },
            wp(3, 0.0, 0.0, 20.0),
        ],
    );
    let acts = derive_activities(&r, &[], &vehicle);
    let spec = crate::guarantee::derived_mission(&params, "tracking", &acts, &[]).unwrap();
    let dur = (spec.problem.goals.iter())
        .position(|g| g.name == crate::guarantee::DURATION)
        .unwrap();
    for (name, v_cmd) in [("leghome-1", 10.0), ("leg1-3", 5.0)] {
        let j = acts.iter().position(|a| a.name == name).unwrap();
        let length = acts[j].length_m;
        let want = length / (0.8 * v_cmd) + 4.5;
        let info = &spec.activities[j];
        assert!(
            info.ia_tios.iter().flatten().any(|t| t == "fusion"),
            "the 4 m/s TIO is an alternative: {:?}",
            info.ia_tios
        );
        for (i, ia) in spec.problem.activities[j].ias.iter().enumerate() {
            assert_eq!(info.ia_speed[i], Some(0.8 * v_cmd), "{name} {}", ia.name);
            assert!(
                (ia.cost[dur] - want).abs() < 1e-9,
                "{name} {}: {} s, want {want} s",
                ia.name,
                ia.cost[dur]
            );
        }
    }
}
