//! `companion check`'s verdict (issue 36 item 4) on a mission that does not fit: the planned and
//! the available energy and time, and the longest search the pack holds, in the text and under
//! `guarantee.verdict` in `--json`. The longest search is checked by planning the route again
//! with that search (it fits) and one second more (it does not), not by the bisection's own
//! arithmetic.

use std::path::Path;

mod common;

fn check(args: &[&str]) -> (Option<i32>, String, String) {
    common::check_run(env!("CARGO_BIN_EXE_companion"), args)
}

/// The shipped default route (params/missions/tracking_route.toml) with `search_s` of search.
fn route(dir: &Path, search_s: f64) -> String {
    let text = format!(
        r#"description = "the default route, a longer search"
frame = "relative"
altitude_m = 20.0
search_time_limit_s = {search_s:?}
tracking_time_limit_s = 20.0
takeoff_first = true
[[waypoint]]
north_m = 50.0
east_m = 0.0
[[waypoint]]
north_m = 200.0
east_m = 0.0
[[waypoint]]
north_m = 200.0
east_m = 100.0
[[waypoint]]
north_m = 50.0
east_m = 100.0
"#
    );
    let p = dir.join(format!("route-{search_s}.toml"));
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

fn verdict_of(route: &str) -> serde_json::Value {
    verdict_with(route, &[])
}

fn verdict_with(route: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["--json", "--mission", route];
    args.extend_from_slice(extra);
    let (code, out, err) = check(&args);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    v["guarantee"].clone()
}

#[test]
fn a_mission_that_does_not_fit_names_planned_available_and_the_longest_search() {
    let d = tempfile::tempdir().unwrap();
    // 900 s of search on the params' 74 Wh pack (199.8 kJ usable above the reserve).
    let long = route(d.path(), 900.0);
    let g = verdict_of(&long);
    let v = &g["verdict"];
    assert_eq!(v["fits"], false, "{v}");
    // Planned: the lowest total any allocation reaches, as the infeasibility says.
    let minimum = g["infeasible"]["minimum"].as_f64().expect("infeasible");
    assert_eq!(g["infeasible"]["constraint"], "energy_j");
    assert_eq!(v["planned_energy_j"].as_f64(), Some(minimum));
    // Available: the energy goal's bound, the full pack's, and the duration goal.
    assert_eq!(v["available_energy_j"].as_f64(), Some(199_800.0));
    assert_eq!(v["battery_pct"].as_f64(), Some(100.0));
    assert_eq!(v["available_duration_s"].as_f64(), Some(1500.0));
    let planned_s = v["planned_duration_s"].as_f64().unwrap();
    assert!(planned_s > 900.0 + 20.0, "{planned_s}");
    assert_eq!(v["planned_search_s"].as_f64(), Some(900.0));
    // No tracking alone makes up for 900 s of search.
    assert!(v.get("longest_tracking_s").is_none(), "{v}");
    let longest = v["longest_search_s"]
        .as_f64()
        .expect("a shorter search fits");
    assert!(
        longest > 0.0 && longest < 900.0 && longest.fract() == 0.0,
        "{longest}"
    );
    // That search fits, with room: the edge is further. Without the headroom (an overlay
    // setting `fit_headroom = 0`) the named search is the edge itself: it fits, a second more
    // does not.
    let at = verdict_of(&route(d.path(), longest));
    assert_eq!(at["verdict"]["fits"], true, "{}", at["verdict"]);
    assert!(at["ras0"].is_object());
    let overlay = d.path().join("no-headroom.toml");
    std::fs::write(
        &overlay,
        "[\"missions/tracking.toml\".guarantee]\nfit_headroom = 0.0\n",
    )
    .unwrap();
    let params = ["--params", overlay.to_str().unwrap()];
    let edge = verdict_with(&long, &params)["verdict"]["longest_search_s"]
        .as_f64()
        .expect("a shorter search fits at the edge");
    assert!(
        edge > longest,
        "the edge {edge} s is beyond the named {longest} s"
    );
    let at_edge = verdict_with(&route(d.path(), edge), &params);
    assert_eq!(at_edge["verdict"]["fits"], true, "{}", at_edge["verdict"]);
    let over = verdict_with(&route(d.path(), edge + 1.0), &params);
    assert_eq!(over["verdict"]["fits"], false, "{}", over["verdict"]);
    // The text says the same in words.
    let (code, text, err) = check(&["--mission", &long]);
    assert_eq!(code, Some(0), "{err}");
    let line = text
        .lines()
        .find(|l| l.starts_with("verdict: "))
        .expect("a verdict line");
    let want = format!(
        "verdict: does not fit: plan {:.0} kJ, have 200 kJ at 100%; Time {planned_s:.0} s of 1500 s; fits: search {longest:.0} s",
        minimum / 1000.0
    );
    assert_eq!(line, want);
}

#[test]
fn a_mission_that_fits_says_so_with_its_plan() {
    let d = tempfile::tempdir().unwrap();
    let g = verdict_of(&route(d.path(), 300.0));
    let v = &g["verdict"];
    assert_eq!(v["fits"], true, "{v}");
    let totals = &g["ras0"]["totals"];
    assert_eq!(v["planned_energy_j"], totals["energy_j"]);
    assert_eq!(v["planned_duration_s"], totals["duration_s"]);
    assert!(v.get("longest_search_s").is_none(), "{v}");
}
