//! Table 2, transcribed here independently of params/variants.toml, against the loaded catalogue.

mod common;
use common::params;
use fpga_model::{Implementation::*, Support::*, *};

/// (app, version, implementation, support, SW ms, HW ms) as read from the paper's Table 2, with
/// the two "HW" slow rows (V1 S, V4 S) read as SW (docs/params/platform.md).
const TABLE2: &[(&str, &str, Implementation, Support, f64, f64)] = &[
    ("tracking", "V0", S, SW, 285.0, 0.0),
    ("tracking", "V0", M, HW, 0.0, 10.0),
    ("tracking", "V0", F, HW, 0.0, 7.0),
    ("tracking", "V1", S, SW, 286.0, 0.0),
    ("tracking", "V1", M, SwHw, 1.0, 10.0),
    ("tracking", "V1", F, HW, 0.0, 7.0),
    ("tracking", "V2", S, SW, 730.0, 0.0),
    ("tracking", "V2", M, HW, 0.0, 10.0),
    ("tracking", "V2", F, HW, 0.0, 7.0),
    ("tracking", "V3", S, SW, 540.0, 0.0),
    ("tracking", "V3", M, SwHw, 285.0, 10.0),
    ("tracking", "V3", F, HW, 0.0, 10.0),
    ("tracking", "V4", S, SW, 540.0, 0.0),
    ("tracking", "V4", M, SwHw, 255.0, 10.0),
    ("tracking", "V4", F, HW, 0.0, 10.0),
    ("tracking", "V5", S, SwHw, 410.0, 10.0),
    ("tracking", "V5", M, SwHw, 30.0, 10.0),
    ("tracking", "V5", F, HW, 0.0, 10.0),
    ("landing_search", "zone_t", S, SW, 394.0, 0.0),
    ("landing_search", "zone_t", F, HW, 0.0, 7.0),
    ("landing_search", "emergency", S, SW, 255.0, 0.0),
    ("landing_search", "emergency", F, HW, 0.0, 7.0),
    ("obstacle_detection", "lidar", S, SW, 5.0, 0.0),
    ("obstacle_detection", "fusion", S, SW, 7.0, 0.0),
    ("obstacle_avoidance", "right_turn", S, SW, 1.0, 0.0),
    ("obstacle_avoidance", "path_planning", S, SW, 1000.0, 0.0),
    ("path_planning", "ga", S, SW, 1000.0, 0.0),
];

#[test]
fn catalogue_holds_every_table2_row_with_its_times() {
    let p = params();
    assert_eq!(p.catalogue.variants().len(), TABLE2.len());
    for &(app, version, imp, sup, sw, hw) in TABLE2 {
        let v = p
            .catalogue
            .variants()
            .iter()
            .find(|v| v.app == app && v.version == version && v.implementation == imp)
            .unwrap_or_else(|| panic!("missing {app} {version} {imp}"));
        assert_eq!(v.support, sup, "{app} {version} {imp}");
        assert_eq!(v.sw_ms(), sw, "{app} {version} {imp} SW ms");
        assert_eq!(v.hw_ms(), hw, "{app} {version} {imp} HW ms");
        assert_eq!(v.ms_per_frame(), sw + hw);
    }
}

#[test]
fn tiles_follow_the_documented_rule() {
    let p = params();
    for v in p.catalogue.variants() {
        let frame = if v.app == "tracking" && (v.version == "V2" || v.version == "V5") {
            2
        } else {
            1
        };
        let expected = match (v.support, v.implementation) {
            (SW, _) => 0,
            (SwHw, _) => 1,
            (HW, F) => 2 * frame,
            (HW, _) => frame,
        };
        assert_eq!(
            v.tiles, expected,
            "{} {} {}",
            v.app, v.version, v.implementation
        );
    }
}

#[test]
fn u_app_whole_part_is_tiles_and_fraction_is_full_duty_cpu() {
    let p = params();
    let find = |app: &str, ver: &str, imp| {
        p.catalogue
            .variants()
            .iter()
            .find(|v| v.app == app && v.version == ver && v.implementation == imp)
            .unwrap()
    };
    // V3 M: one tile, SW 285 of 295 ms on one of two cores -> 1 + 285/295/2.
    assert!((find("tracking", "V3", M).u_app(2) - (1.0 + 285.0 / 295.0 / 2.0)).abs() < 1e-12);
    // V1 M: one tile, SW 1 of 11 ms -> 1 + 1/22.
    assert!((find("tracking", "V1", M).u_app(2) - (1.0 + 1.0 / 22.0)).abs() < 1e-12);
    // A pure SW row occupies one core of two: 0.5. A pure HW row: its tiles exactly.
    assert_eq!(find("tracking", "V0", S).u_app(2), 0.5);
    assert_eq!(find("tracking", "V2", F).u_app(2), 4.0);
    for v in p.catalogue.variants() {
        let u = v.u_app(2);
        assert_eq!(
            u.trunc() as u8,
            v.tiles,
            "{} {} {}",
            v.app,
            v.version,
            v.implementation
        );
        assert!(u.fract() <= 0.5 + 1e-12);
    }
}

#[test]
fn implementations_come_slowest_first() {
    let p = params();
    let order: Vec<Implementation> = p
        .catalogue
        .implementations("tracking", "V5")
        .iter()
        .map(|v| v.implementation)
        .collect();
    assert_eq!(order, vec![S, M, F]);
    let labels: Vec<String> = p
        .catalogue
        .implementations("tracking", "V1")
        .iter()
        .map(|v| v.ms_label())
        .collect();
    assert_eq!(labels, vec!["286", "10 + 1", "7"]);
}

#[test]
fn required_rate_follows_the_relative_speed() {
    let p = params();
    let perf = &p.platform.performance["tracking"];
    // 5 m/s relative, a quarter of a 1.155 m window per frame: 5 / 0.28875 = 17.316 fps.
    let fps = perf.required_fps([3.0, 0.0], [8.0, 0.0]);
    assert!((fps - 5.0 / (0.25 * 1.155)).abs() < 1e-9);
    // Same speeds: the floor.
    assert_eq!(perf.required_fps([4.0, 1.0], [4.0, 1.0]), perf.min_fps);
    // Perpendicular velocities: |(0,6)-(8,0)| = 10 m/s.
    assert!((perf.required_fps([8.0, 0.0], [0.0, 6.0]) - 10.0 / 0.28875).abs() < 1e-9);
    assert_eq!(p.platform.cpu_level(0.29), 0);
    assert_eq!(p.platform.cpu_level(0.30), 1);
    assert_eq!(p.platform.cpu_level(0.85), 2);
}
