//! `companion check --mission FILE --zones FILE`: activities derived from an operator's route
//! (QGroundControl `.plan`, WPL 110, the route TOML; told by content) and GeoJSON zones, printed
//! with their source and planned by the pre-flight allocation; broken files refused with file,
//! item and reason; the default (no route, no zones) the shipped route and zones.

use std::path::Path;

mod common;

fn check(args: &[&str]) -> (Option<i32>, String, String) {
    common::check_run(env!("CARGO_BIN_EXE_companion"), args)
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// A zone over lon 0.001..0.002 on the equator: a leg from lon 0 to 0.003 crosses it in thirds.
const ZONES: &str = r#"{"type":"FeatureCollection","features":[{"type":"Feature",
 "properties":{"name":"canyon","constraints":["gps_degraded"]},
 "geometry":{"type":"Polygon","coordinates":[[[0.001,-0.001],[0.002,-0.001],[0.002,0.001],[0.001,0.001],[0.001,-0.001]]]}}]}"#;

const PLAN: &str = r#"{"fileType":"Plan","version":1,"mission":{"plannedHomePosition":[0,0,0],"items":[
 {"type":"SimpleItem","command":22,"frame":3,"params":[0,0,0,null,0,0,20],"autoContinue":true},
 {"type":"SimpleItem","command":178,"frame":2,"params":[1,5,-1,0,0,0,0],"autoContinue":true},
 {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0,0.003,20],"autoContinue":true},
 {"type":"SimpleItem","command":21,"frame":3,"params":[0,0,0,null,0,0,0],"autoContinue":true}]}}"#;

const WPL: &str = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t0\t0\t0\t1\n1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t20\t1\n\
2\t0\t3\t16\t0\t0\t0\t0\t0\t0.003\t20\t1\n3\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1\n";

#[test]
fn a_plan_and_zones_give_activities_with_their_source_and_the_allocation_plans_them() {
    let d = tempfile::tempdir().unwrap();
    // No .plan extension: the kind is told by content.
    let plan = write(d.path(), "mission.txt", PLAN);
    let zones = write(d.path(), "zones.geojson", ZONES);
    let (code, out, err) = check(&["--json", "--mission", &plan, "--zones", &zones]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let acts = v["activities"].as_array().expect("activities listed");
    let names: Vec<&str> = acts.iter().map(|a| a["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "take_off",
            "leghome-2.1",
            "leghome-2.2",
            "leghome-2.3",
            "land"
        ]
    );
    for a in acts {
        assert!(
            a["length_m"].is_f64()
                && a["hold_s"].is_f64()
                && a["constraints"].is_array()
                && a["source"].is_string(),
            "{a}"
        );
    }
    assert_eq!(acts[2]["constraints"], serde_json::json!(["gps_degraded"]));
    assert_eq!(
        acts[2]["source"],
        "leg home->2 (part 2 of 3), in zone canyon"
    );
    assert_eq!(acts[2]["speed_mps"], 5.0, "DO_CHANGE_SPEED's 5 m/s");
    let g = &v["guarantee"];
    let planned: Vec<&str> = g["activities"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        planned, names,
        "the allocation plans the derived activities"
    );
    assert!(
        g["ras0"]["totals"]["energy_j"].as_f64().unwrap() > 0.0,
        "{g}"
    );
    // For people: each activity with its source.
    let (code, text, err) = check(&["--mission", &plan, "--zones", &zones]);
    assert_eq!(code, Some(0), "{err}");
    assert!(text.contains("Activities derived from"), "{text}");
    assert!(
        text.contains("<- leg home->2 (part 2 of 3), in zone canyon"),
        "{text}"
    );
}

#[test]
fn a_wpl_file_named_dot_plan_is_read_as_wpl() {
    let d = tempfile::tempdir().unwrap();
    let wpl = write(d.path(), "mission.plan", WPL);
    let (code, out, err) = check(&["--json", "--mission", &wpl]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let names: Vec<&str> = v["activities"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["take_off", "leghome-2", "return", "land"]);
}

#[test]
fn the_route_toml_with_zones_and_home_splits_the_default_route() {
    let d = tempfile::tempdir().unwrap();
    // Home at 0,0; the default route's leg wp1 (50 m N) -> wpi (200 m N) crosses lat 0.001 (~110.6 m N).
    let zones = write(
        d.path(),
        "z.geojson",
        r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"constraints":["gps_degraded"]},
      "geometry":{"type":"Polygon","coordinates":[[[-0.01,0.001],[0.01,0.001],[0.01,0.01],[-0.01,0.01],[-0.01,0.001]]]}}]}"#,
    );
    let (code, out, err) = check(&["--json", "--zones", &zones, "--home", "0,0"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let acts = v["activities"].as_array().unwrap();
    let a = acts
        .iter()
        .find(|a| a["name"] == "leg1-2.1")
        .expect("wp1 -> wpi split");
    // 0.001 deg of latitude at the equator is 110.57 m (WGS84 meridian arc): 60.6 m after wp1.
    assert!((a["length_m"].as_f64().unwrap() - 60.57).abs() < 0.5, "{a}");
    let limits: Vec<f64> = acts
        .iter()
        .filter(|a| a["kind"] == "search" || a["kind"] == "tracking")
        .map(|a| a["hold_s"].as_f64().unwrap())
        .collect();
    assert_eq!(
        limits,
        [300.0, 20.0],
        "the route's search and tracking limits"
    );
    // Without --home a relative route cannot be placed among the zones.
    let (code, _, err) = check(&["--zones", &zones]);
    assert_eq!(code, Some(2));
    assert!(err.contains("needs --home LAT,LON"), "{err}");
}

/// The default plan is the route flown: the activities derived from
/// params/missions/tracking_route.toml and the shipped home-relative zones (no --home needed);
/// the typed activities are the legacy plan, chosen by naming the PANORAMA mission.
#[test]
fn without_route_or_zones_check_plans_the_default_route_and_zones() {
    let (code, out, err) = check(&["--json"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let derived: Vec<&str> = (v["activities"].as_array().expect("derived activities"))
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(derived.first(), Some(&"take_off"));
    assert_eq!(derived.last(), Some(&"land"));
    // The shipped canyon splits the two north-south legs.
    let degraded: Vec<&str> = (v["activities"].as_array().unwrap().iter())
        .filter(|a| a["constraints"] == serde_json::json!(["gps_degraded"]))
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(degraded, ["leg1-2.2", "leg3-4.2"]);
    let planned: Vec<&str> = (v["guarantee"]["activities"].as_array().unwrap().iter())
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        planned, derived,
        "the allocation plans the derived activities"
    );
    let plan = &v["plan"];
    assert!(
        plan["route_file"]
            .as_str()
            .unwrap()
            .ends_with("tracking_route.toml"),
        "{plan}"
    );
    assert!(
        plan["zones_file"]
            .as_str()
            .unwrap()
            .ends_with("tracking_zones.geojson"),
        "{plan}"
    );
    assert_eq!(plan["activities"], derived.len());
    let e = plan["planned_energy_j"].as_f64().unwrap();
    let energy = v["guarantee"]["ras0"]["totals"]["energy_j"]
        .as_f64()
        .unwrap();
    assert!((e - energy).abs() < 1e-6 * energy, "{plan}");
    let (_, text, _) = check(&[]);
    assert!(
        text.contains(&format!("plan: {} activities derived from", derived.len())),
        "{text}"
    );
    // The typed activities, chosen explicitly: the legacy plan.
    let (code, out, err) = check(&["--json", "--mission", "tracking"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v.get("activities").is_none());
    let planned: Vec<&str> = (v["guarantee"]["activities"].as_array().unwrap().iter())
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(planned[..2], ["take_off", "transit"]);
    assert!(v["plan"]["route_file"].is_null());
    // A PANORAMA mission given by name stays one.
    let (code, out, err) = check(&["--json", "--mission", "patrolling"]);
    assert_eq!(code, Some(0), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!(v.get("activities").is_none());
    assert_eq!(v["guarantee"]["mission"], "patrolling");
    assert_eq!(v["plan"]["mission"], "patrolling");
}

#[test]
fn broken_mission_and_zone_files_are_refused_with_file_item_and_reason() {
    let d = tempfile::tempdir().unwrap();
    let good_zones = write(d.path(), "good.geojson", ZONES);
    let cases: Vec<(String, Vec<String>, Vec<&str>)> = vec![
        {
            let p = write(
                d.path(),
                "unlim.plan",
                &PLAN.replace("\"command\":16", "\"command\":17"),
            );
            (
                p.clone(),
                vec!["--mission".into(), p],
                vec!["mission.items[2]", "LOITER_UNLIM"],
            )
        },
        {
            let p = write(d.path(), "short.waypoints", "QGC WPL 110\n1\t0\t3\t16\t0\n");
            (
                p.clone(),
                vec!["--mission".into(), p],
                vec!["line 2", "5 fields"],
            )
        },
        {
            let z = write(
                d.path(),
                "point.geojson",
                r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"constraints":["gps_degraded"]},"geometry":{"type":"Point","coordinates":[0,0]}}]}"#,
            );
            let p = write(d.path(), "m.plan", PLAN);
            (
                z.clone(),
                vec!["--mission".into(), p, "--zones".into(), z],
                vec!["features[0]", "not a Polygon"],
            )
        },
        {
            let z = write(
                d.path(),
                "fog.geojson",
                &ZONES.replace("gps_degraded", "fog"),
            );
            let p = write(d.path(), "m2.plan", PLAN);
            (
                z.clone(),
                vec!["--mission".into(), p, "--zones".into(), z],
                vec!["features[0].constraints", "`fog` is no constraint class"],
            )
        },
        {
            let p = write(d.path(), "garbage.plan", "\u{0}\u{1}not a mission");
            (
                p.clone(),
                vec!["--mission".into(), p, "--zones".into(), good_zones.clone()],
                vec!["not a QGroundControl .plan"],
            )
        },
    ];
    for (file, args, words) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (code, _, err) = check(&args);
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(err.contains(&file), "{args:?}: {err}");
        for w in words {
            assert!(err.contains(w), "{args:?}: `{w}` not in {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn zones_with_a_panorama_mission_plan_that_mission_and_need_its_derive_table() {
    let d = tempfile::tempdir().unwrap();
    let zones = write(d.path(), "z.geojson", ZONES);
    let (code, _, err) = check(&[
        "--mission",
        "patrolling",
        "--zones",
        &zones,
        "--home",
        "0,0",
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("patrolling.toml") && err.contains("no [derive] table"),
        "{err}"
    );
}
