//! `companion-fleet calibrate` fits how the vehicle flies (legs, climb, descent: docs/fleet.md
//! "Calibration") from SQL sums over the dataset's `legs` table: the same leg model and
//! vertical rates as `companion calibrate RUN...` (its library entry) on the same runs, within
//! 1e-9 relative, with legs whose commanded speed is the autopilot's parameter and legs that
//! take calibrate's fallback speed. The tlog generator is companion-testkit's `leg_tlog`, as companion/tests/calibrate_legs.rs's.

mod support;

use companion::calibrate::legs::{LegModel, fit_legs, rate};
use companion::calibrate::{calibrate, shipped::Shipped};
use companion_testkit::leg_tlog::{Vehicle, rotary_wing_w, write_run};
use std::path::PathBuf;
use support::{assert_near, fleet};

fn assert_same(
    got: &serde_json::Value,
    m: &LegModel,
    climbs: Option<(f64, f64)>,
    descents: Option<(f64, f64)>,
) {
    let legs = &got["legs"];
    assert_eq!(legs["legs"].as_u64(), Some(m.legs as u64), "{got}");
    assert_near(&legs["overhead_s"], m.overhead_s, "overhead_s");
    assert_near(&legs["rms_s"], m.rms_s, "rms_s");
    assert_near(&legs["rms_before_s"], m.rms_before_s, "rms_before_s");
    for (name, want) in [
        ("speed_fraction", m.speed_fraction),
        ("fitted_fraction", m.fitted_fraction),
    ] {
        match want {
            Some(w) => assert_near(&legs[name], w, name),
            None => assert!(legs[name].is_null(), "{name}: {got}"),
        }
    }
    assert_near(&legs["commanded_mps"][0], m.commanded.0, "commanded lo");
    assert_near(&legs["commanded_mps"][1], m.commanded.1, "commanded hi");
    assert_near(&legs["lengths_m"][0], m.lengths.0, "lengths lo");
    assert_near(&legs["lengths_m"][1], m.lengths.1, "lengths hi");
    assert_eq!(
        legs["sources"].as_array().unwrap().len(),
        m.sources.len(),
        "{got}"
    );
    for (kind, want) in [("climb", climbs), ("descent", descents)] {
        let (r, rms) = want.expect("the flights climb and descend");
        assert_near(&got[kind]["speed_mps"], r, kind);
        assert_near(&got[kind]["rms_s"], rms, kind);
    }
}

#[test]
fn the_fleet_legs_climb_and_descent_equal_calibrates() {
    let tmp = tempfile::tempdir().unwrap();
    let runs_dir = tmp.path().join("runs");
    let route = [
        (50.0, 0.0),
        (150.0, 0.0),
        (0.0, 100.0),
        (-150.0, 0.0),
        (0.0, -300.0),
    ];
    let vehicles = [
        // the autopilot's parameter: 10 m/s commanded, 8 flown
        Vehicle {
            v: 8.0,
            commanded: 10.0,
            overhead: 2.0,
            legs: route.to_vec(),
            says_speed: true,
            power_w: rotary_wing_w,
        },
        Vehicle {
            v: 7.5,
            commanded: 10.0,
            overhead: 2.5,
            legs: route[1..].to_vec(),
            says_speed: true,
            power_w: rotary_wing_w,
        },
        // no commanded speed in the tlog: calibrate's fallback
        Vehicle {
            v: 6.0,
            commanded: 10.0,
            overhead: 1.5,
            legs: route.to_vec(),
            says_speed: false,
            power_w: rotary_wing_w,
        },
    ];
    let mut runs: Vec<PathBuf> = Vec::new();
    for (k, v) in vehicles.iter().enumerate() {
        let d = runs_dir.join(format!("run{k}"));
        write_run(&d, v);
        runs.push(d);
    }
    let ds = tmp.path().join("fleet");
    let ds_s = ds.to_str().unwrap();
    fleet(&[
        "ingest",
        runs_dir.to_str().unwrap(),
        "--into",
        ds_s,
        "--vehicle",
        "V",
    ]);
    let shipped = Shipped::load(&companion::params::default_params_dir()).unwrap();
    for fallback in [None, Some(12.0)] {
        let mut args = vec!["calibrate", ds_s, "--json"];
        let given = fallback.map(|f: f64| f.to_string());
        let cruise = match &given {
            Some(f) => {
                args.extend(["--cruise-speed-mps", f.as_str()]);
                fallback.map(|f| (f, "--cruise-speed-mps".to_string()))
            }
            None => shipped.cruise_mps.map(|v| (v, "params".to_string())),
        };
        let got: serde_json::Value = serde_json::from_str(&fleet(&args)).unwrap();
        let cal = calibrate(&shipped, runs.clone(), None, false, false, cruise.clone()).unwrap();
        let m = fit_legs(&cal.legs.legs).expect("enough legs");
        // the fallback's legs are in (calibrate has one: the params' or the flag's)
        assert!(cruise.is_some() && m.sources.len() == 2, "{m:?}");
        assert_same(&got, &m, rate(&cal.legs.climbs), rate(&cal.legs.descents));
    }
}
