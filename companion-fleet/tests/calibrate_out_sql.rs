//! `companion-fleet calibrate DIR --out FILE` writes the overlay `companion calibrate RUN...
//! --out FILE` writes from the same runs (docs/fleet.md "Calibration"): the power model, the
//! legs' `[derive]` entries and the BN rows' overrides, each with its source, from the SQL sums;
//! only the writer's name differs. And `--statistics` gives the legs' and rates' queries with
//! the sums they gave (what scripts/fleet_spark.sh compares on Spark).

mod support;

use companion::calibrate::legs::fit_legs;
use companion::calibrate::{calibrate, shipped::Shipped};
use companion_testkit::leg_tlog::{Vehicle, rotary_wing_w, write_run};
use std::path::PathBuf;
use support::{close, fleet, write_simulated};

/// Runs with legs (a tlog: power samples, legs, climbs, descents) and simulated missions (BN
/// trials), in `dir`.
fn runs(dir: &std::path::Path) -> Vec<PathBuf> {
    let route = [(50.0, 0.0), (150.0, 0.0), (0.0, 100.0), (-150.0, 0.0)];
    let mut runs = Vec::new();
    for (k, (v, overhead, says_speed)) in [(8.0, 2.0, true), (7.0, 2.5, true), (6.0, 1.5, false)]
        .into_iter()
        .enumerate()
    {
        let d = dir.join(format!("legs{k}"));
        write_run(
            &d,
            &Vehicle {
                v,
                commanded: 10.0,
                overhead,
                legs: route.to_vec(),
                says_speed,
                power_w: rotary_wing_w,
            },
        );
        runs.push(d);
    }
    for (k, scenario) in ["complete-1", "vibrations", "lidar-failure"]
        .iter()
        .enumerate()
    {
        let d = dir.join(format!("sim{k}"));
        write_simulated(&d, scenario, k as u64 + 3);
        runs.push(d);
    }
    runs
}

/// An overlay as a table, its writer's name made calibrate's and its runs sorted (the fleet
/// lists them by id, calibrate in the order given).
fn normalised(text: &str) -> toml::Table {
    let mut t: toml::Table = text
        .replace("companion-fleet calibrate", "companion calibrate")
        .parse()
        .unwrap_or_else(|e| panic!("not TOML: {e}\n{text}"));
    let runs = t["calibration"]["runs"].as_array().unwrap().clone();
    let mut ids: Vec<String> = runs.iter().map(|v| v.as_str().unwrap().into()).collect();
    ids.sort();
    t["calibration"]
        .as_table_mut()
        .unwrap()
        .insert("runs".into(), ids.into());
    t
}

#[test]
fn the_fleet_overlay_is_calibrates_with_legs_and_bn_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = runs(&tmp.path().join("runs"));
    let ds = tmp.path().join("fleet");
    let ds_s = ds.to_str().unwrap();
    let mut args = vec!["ingest"];
    args.extend(runs.iter().map(|p| p.to_str().unwrap()));
    args.extend(["--into", ds_s, "--vehicle", "V"]);
    fleet(&args);
    // FLEET_TEST_DATASET=DIR: the same runs ingested into DIR too, kept (scripts/fleet_spark.sh
    // compares their statistics, legs and BN rows included, on Spark: docs/fleet.md).
    if let Some(keep) = std::env::var_os("FLEET_TEST_DATASET") {
        let n = args.len();
        args[n - 3] = keep.to_str().unwrap();
        fleet(&args);
    }
    let shipped = Shipped::load(&companion::params::default_params_dir()).unwrap();
    let cruise = shipped.cruise_mps.map(|v| {
        (
            v,
            format!("{} [derive].cruise_speed_mps", shipped.mission_file),
        )
    });
    assert!(cruise.is_some(), "the shipped mission plans with [derive]");
    let cal = calibrate(&shipped, runs.clone(), None, false, false, cruise).unwrap();
    // Every section is there to compare: power, legs, climb, descent, BN rows.
    assert!(cal.power.is_ok(), "{:?}", cal.power.as_ref().err());
    let m = fit_legs(&cal.legs.legs).expect("enough legs");
    assert!(!cal.legs.climbs.is_empty() && !cal.legs.descents.is_empty());
    assert!(!cal.rows.is_empty(), "the simulated runs teach BN rows");
    let want_path = tmp.path().join("calibrate.toml");
    let got_path = tmp.path().join("fleet.toml");
    let want = companion::calibrate::write::overlay(&shipped, &cal, &want_path).unwrap();
    fleet(&["calibrate", ds_s, "--out", got_path.to_str().unwrap()]);
    let got = std::fs::read_to_string(&got_path).unwrap();
    let (g, w) = (normalised(&got), normalised(&want));
    let mf = shipped.mission_file.as_str();
    assert!(
        w[mf]["derive"].get("waypoint_overhead_s").is_some(),
        "{want}"
    );
    assert!(w[mf]["derive"].get("climb_speed_mps").is_some(), "{want}");
    assert!(w["health/applications.toml"]["node"].is_table(), "{want}");
    assert_eq!(g, w, "fleet:\n{got}\ncalibrate:\n{want}");
    // The overlay reads as params, as calibrate's does.
    companion::calibrate::overlay::read_overlay(&got_path, companion::params::default_params_dir())
        .unwrap();

    // --statistics: the legs' sums and the rates', each with its query.
    let st: serde_json::Value =
        serde_json::from_str(&fleet(&["calibrate", ds_s, "--statistics"])).unwrap();
    let legs = &st["legs"];
    for name in [
        "legs_sums",
        "legs_centred",
        "climb_sums",
        "climb_residuals",
        "descent_sums",
        "descent_residuals",
    ] {
        assert!(
            legs[name]["query"]
                .as_str()
                .is_some_and(|q| q.contains("legs")),
            "{name}: {legs}"
        );
    }
    let n = legs["legs_sums"]["sums"]["n"].as_f64().unwrap();
    assert_eq!(n as usize, m.legs, "{legs}");
    let climbs: f64 = cal.legs.climbs.iter().map(|c| c.duration_s).sum();
    let t = legs["climb_sums"]["sums"]["t"].as_f64().unwrap();
    assert!(
        close(t, climbs),
        "climbs' time: fleet {t} vs calibrate {climbs}"
    );
}
