//! `companion-fleet calibrate` learns the health BN's CPT rows from SQL counts over the
//! dataset's `bn_trials` (docs/fleet.md "Calibration"): the same rows, counts and learned
//! probabilities as `companion calibrate RUN...` (its library entry) on the same runs, over all
//! and per vehicle. The runs are simulated missions (the world's outcome after each cycle is what
//! the counts read) written as `simulate` writes them, and old (schema-1) simulate logs.

mod support;

use companion::calibrate::cpt::LearnedRow;
use companion::calibrate::{calibrate, shipped::Shipped};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use support::{assert_near, fleet, write_simulated};

type Key = (String, Vec<(String, String)>);

fn by_row(rows: &[LearnedRow]) -> BTreeMap<Key, &LearnedRow> {
    rows.iter()
        .map(|r| ((r.node.clone(), r.when.clone()), r))
        .collect()
}

/// The fleet's `bn_rows` equal calibrate's learned rows: the same rows, counts, shipped and
/// learned probabilities.
fn assert_same_rows(got: &serde_json::Value, want: &[LearnedRow]) {
    let got = got.as_array().unwrap_or_else(|| panic!("bn_rows: {got}"));
    let want = by_row(want);
    assert_eq!(got.len(), want.len(), "{got:?}\n{want:?}");
    for g in got {
        let when: Vec<(String, String)> = serde_json::from_value(g["when"].clone()).unwrap();
        let key = (g["node"].as_str().unwrap().to_string(), when);
        let w = want
            .get(&key)
            .unwrap_or_else(|| panic!("{key:?} not learned by calibrate"));
        assert_eq!(
            g["success_state"].as_str(),
            Some(w.success_state),
            "{key:?}"
        );
        assert_eq!(g["successes"].as_u64(), Some(w.successes), "{key:?}");
        assert_eq!(g["trials"].as_u64(), Some(w.trials), "{key:?}");
        assert_near(&g["shipped"], w.shipped, "shipped");
        assert_near(&g["learned"], w.learned, "learned");
    }
}

#[test]
fn the_fleet_bn_rows_equal_calibrates() {
    let tmp = tempfile::tempdir().unwrap();
    let fixtures =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../companion/tests/fixtures/schema1");
    let old: Vec<PathBuf> = ["simulate-complete-1", "simulate-lidar-failure"]
        .iter()
        .map(|n| fixtures.join(n))
        .collect();
    let mut a: Vec<PathBuf> = Vec::new();
    let mut b: Vec<PathBuf> = Vec::new();
    for (k, scenario) in [
        "complete-1",
        "vibrations",
        "nominal",
        "lidar-failure",
        "complete-1",
    ]
    .iter()
    .enumerate()
    {
        let d = tmp.path().join(format!("runs-a/run{k}"));
        write_simulated(&d, scenario, k as u64 + 1);
        a.push(d);
    }
    for (k, scenario) in ["vibrations", "complete-1", "nominal"].iter().enumerate() {
        let d = tmp.path().join(format!("runs-b/run{k}"));
        write_simulated(&d, scenario, k as u64 + 11);
        b.push(d);
    }
    a.extend(old);
    let ds = tmp.path().join("fleet");
    let ds_s = ds.to_str().unwrap();
    for (runs, vehicle) in [(&a, "A"), (&b, "B")] {
        let mut args = vec!["ingest"];
        args.extend(runs.iter().map(|p| p.to_str().unwrap()));
        args.extend(["--into", ds_s, "--vehicle", vehicle]);
        fleet(&args);
    }
    let shipped = Shipped::load(&companion::params::default_params_dir()).unwrap();
    let learned = |runs: Vec<PathBuf>| {
        calibrate(&shipped, runs, None, false, false, None)
            .unwrap()
            .rows
    };
    let all: Vec<PathBuf> = a.iter().chain(&b).cloned().collect();
    let want = learned(all);
    // Both kinds of countable rows are in these runs: error nodes and tracking versions.
    assert!(want.iter().any(|r| r.success_state == "absent"), "{want:?}");
    assert!(
        want.iter().any(|r| r.success_state == "activate"),
        "{want:?}"
    );
    assert!(want.iter().any(|r| r.trials > 1), "{want:?}");
    let got: serde_json::Value =
        serde_json::from_str(&fleet(&["calibrate", ds_s, "--json"])).unwrap();
    assert_same_rows(&got["bn_rows"], &want);
    for (vehicle, runs) in [("A", &a), ("B", &b)] {
        let got: serde_json::Value =
            serde_json::from_str(&fleet(&["calibrate", ds_s, "--json", "--vehicle", vehicle]))
                .unwrap();
        assert_same_rows(&got["bn_rows"], &learned(runs.clone()));
    }
}
