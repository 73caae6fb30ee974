//! The verdict against independent answers: the longest hold found by bisection against a scan
//! of every whole second, each hold compiled again from the mission's text and judged by the
//! exhaustive search (not the slopes, not the bisection, not the paper's algorithm).

use super::*;
use crate::guarantee::parse_mission;
use std::path::Path;

/// A small mission: climb, search (hold SEARCH s), tracking (hold TRACK s), land; two tasks of
/// two TIOs each, so four IAs an activity, 256 allocations. `CAP` Wh of battery, `LIMIT` s.
const MISSION: &str = r#"
[mission]
name = "small"
goal_order = ["energy_j", "duration_s"]
selection = "most_capable"
[goals.energy_j]
from_battery = true
[goals.duration_s]
bound = LIMIT
[battery]
capacity_wh = CAP
usable_fraction = 0.8
reserve_wh = 1.0
[propulsion]
model = "rotary_wing"
blade_profile_w = 60.0
induced_hover_w = 140.0
induced_velocity_mps = 6.3
tip_speed_mps = 80.0
drag_area_m2 = 0.05
air_density_kgm3 = 1.225
[base]
power_w = 8.0
[resources.gps]
power_w = 0.5
[resources.camera]
power_w = 2.0
[resources.lidar]
power_w = 6.0
[tasks.localisation]
tios = [
  { name = "gps", resources = ["gps"], capability = 0 },
  { name = "gps_vision", resources = ["gps", "camera"], capability = 1, v_max_mps = 6.0 },
]
[tasks.detect]
tios = [
  { name = "plain", capability = 0 },
  { name = "lidar", resources = ["lidar"], capability = 2, time_s = 5.0 },
]
[[activities]]
name = "take_off"
tasks = ["localisation", "detect"]
length_m = 30.0
v_max_mps = 2.5
[[activities]]
name = "search"
tasks = ["localisation", "detect"]
hold_s = SEARCH
hold_kind = "search"
[[activities]]
name = "tracking"
tasks = ["localisation", "detect"]
hold_s = TRACK
hold_speed_mps = 5.0
hold_kind = "tracking"
[[activities]]
name = "land"
tasks = ["localisation", "detect"]
length_m = 30.0
v_max_mps = 1.5
"#;

fn mission(cap_wh: f64, limit_s: f64, search_s: f64, track_s: f64) -> MissionSpec {
    let text = MISSION
        .replace("CAP", &format!("{cap_wh:?}"))
        .replace("LIMIT", &format!("{limit_s:?}"))
        .replace("SEARCH", &format!("{search_s:?}"))
        .replace("TRACK", &format!("{track_s:?}"));
    parse_mission(Path::new("small.toml"), &text).expect("the test mission compiles")
}

/// Whether any allocation meets every goal, by trying all of them.
fn fits_exhaustively(spec: &MissionSpec) -> bool {
    panorama::exhaustive(&spec.problem, spec.selection).is_some()
}

/// The longest whole-second hold of `kind` that fits, by compiling every hold from 0 up.
fn longest_by_scan(
    cap_wh: f64,
    limit_s: f64,
    search_s: f64,
    track_s: f64,
    kind: HoldKind,
) -> Option<f64> {
    let planned = match kind {
        HoldKind::Search => search_s,
        HoldKind::Tracking => track_s,
    };
    let mut best = None;
    for h in 0..=planned as u64 {
        let h = h as f64;
        let spec = match kind {
            HoldKind::Search => mission(cap_wh, limit_s, h, track_s),
            HoldKind::Tracking => mission(cap_wh, limit_s, search_s, h),
        };
        // What is named fits with the headroom below the goals (tuning.rs, FIT_HEADROOM).
        let mut spec = spec;
        let room = spec.tuning.fit_headroom;
        for g in &mut spec.problem.goals {
            g.bound -= g.bound.abs() * room;
        }
        if fits_exhaustively(&spec) {
            best = Some(h);
        }
    }
    best
}

#[test]
fn the_longest_hold_by_bisection_is_the_scan_over_every_second() {
    // Batteries from "fits as planned" down to "nothing fits", and a time limit that binds.
    let cases = [
        (40.0, 3000.0, 300.0, 120.0),
        (30.0, 3000.0, 300.0, 120.0),
        (20.0, 3000.0, 300.0, 120.0),
        (16.0, 3000.0, 300.0, 120.0),
        (14.0, 3000.0, 300.0, 120.0),
        (12.0, 3000.0, 300.0, 120.0),
        (8.0, 3000.0, 300.0, 120.0),
        (3.0, 3000.0, 300.0, 120.0),
        (40.0, 300.0, 300.0, 120.0),
        (40.0, 420.0, 300.0, 120.0),
    ];
    let mut seen = (0, 0, 0);
    for (cap, limit, search, track) in cases {
        let spec = mission(cap, limit, search, track);
        let v = judge(&spec, &[0.0, 0.0], Some(100.0));
        assert_eq!(
            v.fits,
            fits_exhaustively(&spec),
            "{cap} Wh {limit} s: {v:?}"
        );
        if v.fits {
            seen.0 += 1;
            assert_eq!(v.longest_search_s, None);
            continue;
        }
        for (kind, got) in [
            (HoldKind::Search, v.longest_search_s),
            (HoldKind::Tracking, v.longest_tracking_s),
        ] {
            let want = longest_by_scan(cap, limit, search, track, kind);
            assert_eq!(got, want, "{kind:?} at {cap} Wh {limit} s: {v:?}");
            if want.is_some() {
                seen.1 += 1;
            }
        }
        if v.longest_search_s.is_none() && v.longest_tracking_s.is_none() {
            seen.2 += 1;
            let route = mission(cap, limit, 0.0, 0.0);
            let lowest = lowest_totals(&route.problem);
            let e = v.route_energy_j.expect("the route's energy is said");
            assert!((e - lowest[0]).abs() < 1e-6, "{e} against {}", lowest[0]);
        }
    }
    // Every branch was exercised: fits, a shorter hold fits, nothing fits.
    assert!(seen.0 > 0 && seen.1 > 1 && seen.2 > 0, "{seen:?}");
}

#[test]
fn a_refusal_plans_the_cheapest_and_reckons_the_available_from_what_is_spent() {
    let spec = mission(12.0, 3000.0, 300.0, 120.0);
    let bound = spec.problem.goals[0].bound;
    let v = judge(&spec, &[1000.0, 60.0], Some(93.0));
    assert!(!v.fits);
    assert_eq!(v.available_energy_j, Some(bound - 1000.0));
    assert_eq!(v.available_duration_s, Some(3000.0 - 60.0));
    assert_eq!(v.battery_pct, Some(93.0));
    let lowest = lowest_totals(&spec.problem);
    assert_eq!(v.planned_energy_j, Some(lowest[0]));
    assert_eq!(v.planned_duration_s, Some(lowest[1]));
    assert_eq!(
        (v.planned_search_s, v.planned_tracking_s),
        (Some(300.0), Some(120.0))
    );
}

#[test]
fn a_mission_fitting_only_without_the_most_capable_ias_names_them() {
    // Between the cheapest allocation and the most capable one.
    let cheap = mission(1000.0, 3000.0, 300.0, 120.0);
    let best = most_capable(&cheap.problem, cheap.selection);
    let need_best = cheap.problem.totals(&best)[0];
    let lowest = lowest_totals(&cheap.problem)[0];
    // A battery whose bound lies halfway: capacity x 0.8 - 1 Wh = bound.
    let cap_wh = ((lowest + need_best) / 2.0 / 3600.0 + 1.0) / 0.8;
    let spec = mission(cap_wh, 3000.0, 300.0, 120.0);
    let v = judge(&spec, &[0.0, 0.0], Some(100.0));
    assert!(v.fits, "{v:?}");
    assert!(!v.lowered.is_empty(), "{v:?}");
    assert!((v.most_capable_energy_j.unwrap() - need_best).abs() < 1e-6);
    assert!(v.planned_energy_j.unwrap() <= spec.problem.goals[0].bound);
    assert_eq!(
        v.words()[1],
        "Time 457 s of 3000 s; fits with less capable IAs"
    );
    // With the whole pack: the most capable fit, nothing lowered.
    let v = judge(&cheap, &[0.0, 0.0], Some(100.0));
    assert!(v.fits && v.lowered.is_empty() && v.most_capable_energy_j.is_none());
}
