//! `companion calibrate` fits how the vehicle flies (docs/calibrate.md, "How the vehicle flies"):
//! from a generated `flight.tlog` of a vehicle of known leg overhead, climb and descent, the
//! overlay's `[derive]` entries come back, each with its source; the overlay holds no route
//! length, no activity hold and no machine path; the derivation plans a route with them; too few
//! legs write nothing about legs, and legs flown faster than commanded are refused.

mod common;
use common::text;
use companion_testkit::leg_tlog::{Vehicle, sitl_like_w, write_run};
use std::path::Path;

const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

const M: &str = "missions/tracking.toml";

const ROUTE: [(f64, f64); 5] = [
    (50.0, 0.0),
    (150.0, 0.0),
    (0.0, 100.0),
    (-150.0, 0.0),
    (0.0, -300.0),
];

fn calibrate(run: &Path, out: &Path) -> (std::process::Output, String) {
    let o = companion(&[
        "calibrate",
        run.to_str().unwrap(),
        "--polynomial",
        "--out",
        out.to_str().unwrap(),
    ]);
    let t = text(&o);
    (o, t)
}

#[test]
fn the_vehicles_legs_climb_and_descent_are_fitted_and_no_route_number_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let v = Vehicle {
        v: 8.0,
        commanded: 8.0,
        overhead: 2.5,
        legs: ROUTE.to_vec(),
        says_speed: true,
        power_w: sitl_like_w,
    };
    write_run(&run, &v);
    let out = tmp.path().join("o.toml");
    let (o, report) = calibrate(&run, &out);
    assert!(o.status.success(), "{report}");
    let written = std::fs::read_to_string(&out).unwrap();
    let t: toml::Table = written.parse().unwrap();
    let d = t[M]["derive"]
        .as_table()
        .unwrap_or_else(|| panic!("{written}"));
    let num = |k: &str| d[k].as_float().unwrap_or_else(|| panic!("{k}: {written}"));
    assert!((num("waypoint_overhead_s") - 2.5).abs() < 0.25, "{report}");
    assert!(!d.contains_key("speed_fraction"), "reached: {written}");
    // 20 m in 12.5 s (3 s of spin-up, 9.5 s to 19 m); 19 m down in 21 s (to the disarm).
    assert!((num("climb_speed_mps") - 1.6).abs() < 0.05, "{report}");
    assert!(
        (num("descent_speed_mps") - 19.0 / 21.0).abs() < 0.05,
        "{report}"
    );
    let sources = t["calibration"]["sources"].as_table().unwrap();
    let src = sources[&format!("{M}:derive.waypoint_overhead_s")]
        .as_str()
        .unwrap();
    assert!(
        src.contains("5 legs") && src.contains("fit RMS") && src.contains("WPNAV_SPEED"),
        "{src}"
    );
    for k in ["climb_speed_mps", "descent_speed_mps"] {
        assert!(sources.contains_key(&format!("{M}:derive.{k}")), "{k}");
    }
    // Only the vehicle: no route length, activity hold or activities table, and the run named
    // by its content, not by where it lies on this machine.
    assert!(
        !written.contains("length_m")
            && !written.contains("hold_s")
            && !written.contains("activities"),
        "{written}"
    );
    assert!(!written.contains(run.to_str().unwrap()), "{written}");
    let runs = t["calibration"]["runs"].as_array().unwrap();
    let id = runs[0].as_str().unwrap();
    assert!(
        id.len() == 7 + 64 && id.starts_with("sha256:"),
        "{id}: a content id"
    );

    // The derivation plans the default route with the vehicle's numbers: every leg holds the
    // overhead, the take-off climbs at the fitted rate.
    let c = companion(&[
        "check",
        "--json",
        "--params",
        out.to_str().unwrap(),
        "--mission",
        companion::params::default_params_dir()
            .join("missions/tracking_route.toml")
            .to_str()
            .unwrap(),
        "--home=-35.363261,149.165230",
    ]);
    assert!(c.status.success(), "{}", text(&c));
    let j: serde_json::Value = serde_json::from_slice(&c.stdout).unwrap();
    let acts = j["activities"].as_array().expect("activities");
    let legs: Vec<&serde_json::Value> = acts
        .iter()
        .filter(|a| a["name"].as_str().unwrap().starts_with("leg"))
        .collect();
    assert_eq!(legs.len(), 4, "{acts:?}");
    for l in legs {
        assert!(
            (l["hold_s"].as_f64().unwrap() - num("waypoint_overhead_s")).abs() < 1e-9,
            "{l}"
        );
    }
}

#[test]
fn too_few_legs_write_nothing_about_legs_and_legs_faster_than_commanded_are_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("few");
    let v = Vehicle {
        v: 8.0,
        commanded: 8.0,
        overhead: 2.5,
        legs: ROUTE[..2].to_vec(),
        says_speed: true,
        power_w: sitl_like_w,
    };
    write_run(&run, &v);
    let out = tmp.path().join("few.toml");
    let (o, report) = calibrate(&run, &out);
    assert!(o.status.success(), "{report}");
    assert!(
        report.contains("legs: not fitted") && report.contains("at least 3 needed"),
        "{report}"
    );
    let t: toml::Table = std::fs::read_to_string(&out).unwrap().parse().unwrap();
    let d = t[M].get("derive").and_then(|d| d.as_table());
    assert!(
        d.is_none_or(|d| !d.contains_key("waypoint_overhead_s")),
        "{d:?}"
    );

    // The autopilot says 4 m/s; the legs are flown at 8: not this vehicle's commanded speed.
    let run = tmp.path().join("fast");
    let v = Vehicle {
        v: 8.0,
        commanded: 4.0,
        overhead: 2.5,
        legs: ROUTE.to_vec(),
        says_speed: true,
        power_w: sitl_like_w,
    };
    write_run(&run, &v);
    let out = tmp.path().join("fast.toml");
    let (o, report) = calibrate(&run, &out);
    assert!(!o.status.success(), "{report}");
    assert!(
        report.contains("refused: legs: flown at") && report.contains("--cruise-speed-mps"),
        "{report}"
    );
    assert!(!out.exists(), "nothing written");
}

#[test]
fn a_profiles_leg_numbers_out_of_range_are_refused_naming_the_entry() {
    let tmp = tempfile::tempdir().unwrap();
    let params = companion::params::default_params_dir();
    for (entry, value) in [
        ("speed_fraction", "1.5"),
        ("speed_fraction", "0.0"),
        ("waypoint_overhead_s", "-1.0"),
        ("waypoint_overhead_s", "nan"),
    ] {
        let overlay = tmp.path().join("o.toml");
        std::fs::write(
            &overlay,
            format!(
                "[calibration]\nparams = {:?}\n[\"{M}\".derive]\n{entry} = {value}\n",
                params.to_str().unwrap()
            ),
        )
        .unwrap();
        let o = companion(&[
            "check",
            "--params",
            overlay.to_str().unwrap(),
            "--mission",
            params
                .join("missions/tracking_route.toml")
                .to_str()
                .unwrap(),
        ]);
        let e = text(&o);
        assert!(!o.status.success(), "{entry} = {value}: {e}");
        assert!(
            e.contains(&format!("derive.{entry}")),
            "{entry} = {value}: {e}"
        );
    }
}
