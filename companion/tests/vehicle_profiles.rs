//! The vehicle profiles in params/vehicles/ (docs/calibrate.md): `--vehicle NAME` loads each as the
//! params overlay it is, an unknown name is refused naming the profiles there, and every number a
//! profile sets carries its source (calibrate's runs, samples and fit error), never an ASSUMPTION.

mod common;

/// The binary under test (named here: scripts/arm.sh skips tests that start it under qemu).
const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

use companion::params::default_params_dir;

fn profiles() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(default_params_dir().join("vehicles"))
        .expect("params/vehicles/")
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    names.sort();
    names
}

#[test]
fn every_profile_loads_with_vehicle_and_changes_the_mission_power() {
    let names = profiles();
    assert!(
        names.contains(&"arducopter-sitl".to_string()) && names.contains(&"px4-sih".to_string())
    );
    let plain = companion(&["check", "--json"]);
    assert!(plain.status.success());
    let plain: serde_json::Value = serde_json::from_slice(&plain.stdout).unwrap();
    for name in &names {
        let o = companion(&["check", "--json", "--vehicle", name]);
        assert!(
            o.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        // the overlay reached the mission the guarantee compiles: its costs are not the shipped ones
        assert_ne!(
            v["guarantee"], plain["guarantee"],
            "{name}: the profile changed nothing in the guarantee"
        );
    }
}

#[test]
fn an_unknown_profile_is_refused_naming_the_ones_there() {
    let o = companion(&["check", "--vehicle", "no-such-drone"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no-such-drone") && err.contains("arducopter-sitl") && err.contains("px4-sih"),
        "{err}"
    );
    // a path is not a name
    let o = companion(&["check", "--vehicle", "../missions/tracking"]);
    assert!(!o.status.success());
    // a profile is an overlay: not on top of another overlay
    let overlay = default_params_dir().join("vehicles/px4-sih.toml");
    let o = companion(&[
        "check",
        "--params",
        overlay.to_str().unwrap(),
        "--vehicle",
        "px4-sih",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("overlay file"));
}

#[test]
fn every_number_a_profile_sets_has_a_calibrate_source() {
    for name in profiles() {
        let path = default_params_dir().join(format!("vehicles/{name}.toml"));
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("ASSUMPTION"), "{name}");
        let t: toml::Table = text.parse().unwrap();
        let sources = t["calibration"]["sources"]
            .as_table()
            .cloned()
            .unwrap_or_default();
        for (file, entries) in &t {
            if file == "calibration" {
                continue;
            }
            for (table, body) in entries.as_table().unwrap() {
                walk(&name, file, table, body, &sources);
            }
        }
    }
}

/// Every table holding a number has its own `source`, or each number has one in
/// `calibration.sources` under "FILE:PATH.KEY".
fn walk(name: &str, file: &str, path: &str, v: &toml::Value, sources: &toml::Table) {
    let Some(t) = v.as_table() else { return };
    let own = t.contains_key("source");
    for (k, x) in t {
        let at = format!("{path}.{k}");
        match x {
            toml::Value::Table(_) => walk(name, file, &at, x, sources),
            toml::Value::Float(_) | toml::Value::Integer(_) | toml::Value::Array(_) => assert!(
                own || sources.contains_key(&format!("{file}:{at}")),
                "{name}: {file} {at} has no source"
            ),
            _ => {}
        }
    }
}

/// A profile holds only the vehicle (issue 36): no route length, no activity hold, no
/// `activities` table (numbers of one route's flights, wrong for any other route the vehicle
/// flies), and no absolute path (a path on the machine that made it: nobody else can re-derive
/// it); its runs are named by their content id.
#[test]
fn no_profile_holds_a_route_number_an_activity_hold_or_a_machine_path() {
    let names = profiles();
    assert!(!names.is_empty());
    for name in names {
        let path = default_params_dir().join(format!("vehicles/{name}.toml"));
        let t: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
        let mut bad = Vec::new();
        route_numbers(&toml::Value::Table(t.clone()), &name, &mut bad);
        assert!(bad.is_empty(), "{name}: {bad:#?}");
        for run in t["calibration"]["runs"]
            .as_array()
            .expect("calibration.runs")
        {
            let id = run.as_str().unwrap_or_default();
            let hex = id.strip_prefix("sha256:").unwrap_or_default();
            assert!(
                hex.len() == 64 && hex.chars().all(|c| c.is_ascii_hexdigit()),
                "{name}: run {run} is no content id"
            );
        }
    }
}

/// Every key, table and string of `v` that is a route's number or a machine path, by where.
fn route_numbers(v: &toml::Value, at: &str, bad: &mut Vec<String>) {
    let absolute = |s: &str| {
        let b = s.as_bytes();
        s.starts_with('/')
            || s.starts_with('\\')
            || s.starts_with('~')
            || (b.len() > 2
                && b[0].is_ascii_alphabetic()
                && b[1] == b':'
                && matches!(b[2], b'/' | b'\\'))
    };
    match v {
        toml::Value::Table(t) => {
            for (k, x) in t {
                let here = format!("{at}.{k}");
                if matches!(k.as_str(), "length_m" | "hold_s" | "activities") {
                    bad.push(format!("{here}: a route's, not the vehicle's"));
                }
                // The sources' keys name entries: `FILE:activities.NAME.hold_s` is one too.
                if k.contains(":activities.") || k.ends_with(".length_m") || k.ends_with(".hold_s")
                {
                    bad.push(format!("{here}: a source of a route's number"));
                }
                route_numbers(x, &here, bad);
            }
        }
        toml::Value::Array(a) => a
            .iter()
            .enumerate()
            .for_each(|(i, x)| route_numbers(x, &format!("{at}[{i}]"), bad)),
        toml::Value::String(s) if absolute(s) => bad.push(format!("{at} = {s:?}: a machine path")),
        _ => {}
    }
}
