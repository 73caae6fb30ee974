//! `simulate` judges the derived plan (issue 36): by default the shipped route and zones,
//! `--mission FILE.plan` and `--zones FILE` as `check` takes them, `--mission tracking` the typed
//! legacy plan; the plan line says which, and the records walk the derived activities in order.

use serde_json::Value;
use std::process::Command;

fn simulate(args: &[&str]) -> (Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_companion"))
        .env("COMPANION_PARAMS", companion::params::default_params_dir())
        .args(["simulate", "--no-log", "--json"])
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{args:?}: {err}");
    (serde_json::from_slice(&out.stdout).unwrap(), err)
}

fn walked(v: &Value) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for r in v["decisions"].as_array().unwrap() {
        if let Some(n) = r["guarantee"]["activity_name"].as_str()
            && out.last().map(String::as_str) != Some(n)
        {
            out.push(n.to_string());
        }
    }
    out
}

const PLAN: &str = r#"{"fileType":"Plan","version":1,"mission":{"plannedHomePosition":[0,0,0],"items":[
 {"type":"SimpleItem","command":22,"frame":3,"params":[0,0,0,null,0,0,20],"autoContinue":true},
 {"type":"SimpleItem","command":178,"frame":2,"params":[1,5,-1,0,0,0,0],"autoContinue":true},
 {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0,0.003,20],"autoContinue":true},
 {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0.002,0.003,20],"autoContinue":true},
 {"type":"SimpleItem","command":21,"frame":3,"params":[0,0,0,null,0,0,0],"autoContinue":true}]}}"#;

/// A zone over lon 0.001..0.002 on the equator: the .plan's first leg crosses it in thirds.
const ZONES: &str = r#"{"type":"FeatureCollection","features":[{"type":"Feature",
 "properties":{"name":"canyon","constraints":["gps_degraded"]},
 "geometry":{"type":"Polygon","coordinates":[[[0.001,-0.001],[0.002,-0.001],[0.002,0.001],[0.001,0.001],[0.001,-0.001]]]}}]}"#;

#[test]
fn simulate_walks_the_default_derived_plan_in_flight_order() {
    let (v, _) = simulate(&[]);
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
    assert!(plan["planned_energy_j"].as_f64().unwrap() > 0.0);
    let seen = walked(&v);
    assert_eq!(
        seen.first().map(String::as_str),
        Some("take_off"),
        "{seen:?}"
    );
    assert!(
        seen.iter().filter(|a| a.starts_with("leg")).count() >= 3,
        "{seen:?}"
    );
    assert!(seen.contains(&"tracking".to_string()), "{seen:?}");
    // Flight order: each activity's derived name sorts after the previous one in the plan.
    let (check, _) = {
        let out = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args(["check", "--json"])
            .output()
            .unwrap();
        (serde_json::from_slice::<Value>(&out.stdout).unwrap(), ())
    };
    let derived: Vec<&str> = (check["activities"].as_array().unwrap().iter())
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    let order: Vec<usize> = (seen.iter())
        .map(|a| {
            derived
                .iter()
                .position(|d| d == a)
                .expect("a derived activity")
        })
        .collect();
    assert!(order.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
}

#[test]
fn simulate_takes_a_plan_file_and_zones_and_the_typed_plan_by_name() {
    let d = tempfile::tempdir().unwrap();
    let plan = d.path().join("m.plan");
    let zones = d.path().join("z.geojson");
    std::fs::write(&plan, PLAN).unwrap();
    std::fs::write(&zones, ZONES).unwrap();
    let (plan_s, zones_s) = (plan.to_str().unwrap(), zones.to_str().unwrap());
    let (v, _) = simulate(&["--mission", plan_s, "--zones", zones_s]);
    assert_eq!(v["plan"]["route_file"], plan_s);
    assert_eq!(v["plan"]["zones_file"], zones_s);
    let seen = walked(&v);
    assert!(
        seen.iter().all(|a| a == "take_off"
            || a.starts_with("leghome-2")
            || a.starts_with("leg2-3")
            || a == "land"),
        "{seen:?}"
    );
    assert!(
        seen.iter().any(|a| a.starts_with("leghome-2.")),
        "the zone splits the first leg: {seen:?}"
    );
    // Without zones the .plan's legs are whole.
    let (v, _) = simulate(&["--mission", plan_s]);
    assert!(v["plan"]["zones_file"].is_null());
    assert_eq!(
        v["plan"]["activities"], 4,
        "take-off, two legs, land: {}",
        v["plan"]
    );
    // The typed activities, chosen by name: the legacy plan.
    let (v, _) = simulate(&["--mission", "tracking"]);
    assert!(v["plan"]["route_file"].is_null());
    assert!(walked(&v).contains(&"tracking_area".to_string()));
}

/// `fly --mission FILE.plan | WPL` flies the operator's items (sitl_tests/test_plan_file_standin.py
/// flies them); a file it cannot plan stops it before any socket, naming the file and the item,
/// and leaves no run folder.
#[test]
fn fly_refuses_a_malformed_plan_or_wpl_mission_before_any_socket() {
    let d = tempfile::tempdir().unwrap();
    // LOITER_UNLIM (17) never ends: no plan holds it.
    let unlimited = PLAN.replacen("\"command\":16", "\"command\":17", 1);
    for (name, text, item) in [
        ("m.plan", unlimited.as_str(), "items[2]"),
        ("m.txt", "QGC WPL 110\n0\t1\t0\t16\t0\n", "line 2"),
    ] {
        let f = d.path().join(name);
        std::fs::write(&f, text).unwrap();
        let runs = d.path().join("runs");
        let out = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args([
                "fly",
                "--connect",
                "tcp:127.0.0.1:1",
                "--connect-timeout",
                "2",
                "--mission",
            ])
            .arg(&f)
            .arg("--log-dir")
            .arg(&runs)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        assert!(err.contains(f.to_str().unwrap()), "{err}");
        assert!(err.contains(item), "{err}");
        assert!(!err.contains("connect"), "refused before any socket: {err}");
        assert!(!runs.exists(), "no run folder");
    }
}

/// `fly` says which plan it judges before any socket (stdout) and in the run folder's header:
/// the derived default, or the typed activities with `--legacy-plan`.
#[test]
fn fly_prints_and_logs_the_plan_it_judges() {
    let d = tempfile::tempdir().unwrap();
    for (legacy, want) in [(false, "activities derived from"), (true, "(legacy plan)")] {
        let runs = d.path().join(format!("runs-{legacy}"));
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_companion"));
        cmd.env("COMPANION_PARAMS", companion::params::default_params_dir())
            .args([
                "fly",
                "--connect",
                "tcp:127.0.0.1:1",
                "--connect-timeout",
                "1s",
            ])
            .arg("--log-dir")
            .arg(&runs);
        if legacy {
            cmd.arg("--legacy-plan");
        }
        let out = cmd.output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            stdout
                .lines()
                .any(|l| l.starts_with("plan: ") && l.contains(want)),
            "{stdout}"
        );
        let log = std::fs::read_dir(&runs)
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let text = std::fs::read_to_string(log.join("decisions.jsonl")).unwrap();
        let header: Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
        let plan = &header["plan"];
        assert_eq!(plan["route_file"].is_null(), legacy, "{plan}");
        assert_eq!(plan.get("derived").is_none(), legacy, "{plan}");
        assert!(plan["planned_energy_j"].as_f64().unwrap() > 0.0, "{plan}");
    }
}
