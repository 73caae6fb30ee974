//! `companion-fleet calibrate` (SQL sufficient statistics over the dataset) fits the same power
//! model as `companion calibrate RUN...` (its library entry, the code the CLI runs) on the same
//! runs, within 1e-9 relative; `--vehicle` keeps one vehicle's runs; the overlay loads.

mod support;

use companion::calibrate::{calibrate, shipped::Shipped};
use companion::decision_log::Header;
use companion_core::record::{DecisionRecord, GuaranteeRecord};
use std::path::{Path, PathBuf};
use support::{FLEET, close, fleet};

/// A vehicle's power (Zeng et al. eq. 12 plus base), written out here apart from the code.
#[derive(Clone, Copy)]
struct Truth {
    base: f64,
    p0: f64,
    pi: f64,
    v0: f64,
    cda: f64,
}

fn power(t: Truth, v: f64) -> f64 {
    let induced =
        ((1.0 + v.powi(4) / (4.0 * t.v0.powi(4))).sqrt() - v * v / (2.0 * t.v0 * t.v0)).sqrt();
    t.base + t.p0 * (1.0 + 3.0 * v * v / 6400.0) + t.pi * induced + 0.5 * 1.225 * t.cda * v.powi(3)
}

/// Deterministic noise in [-a, a].
fn noise(i: u64, a: f64) -> f64 {
    let x = (i
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407)
        >> 33) as f64
        / (1u64 << 31) as f64;
    a * (2.0 * x - 1.0)
}

/// A run folder as `fly` writes it: records with the observations calibrate reads.
fn write_run(dir: &Path, t: Truth, seed: u64, speeds: &[(f64, u32)]) {
    let started =
        std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_750_000_000 + seed * 86_400);
    let h = Header::new("companion fly --connect tcp:x", started);
    let mut f = companion_testkit::run_log::RunLog::create(dir, &h);
    let mut cycle = 0u64;
    // The activity in force (calibrate's durations): a name per speed stretch, names repeating
    // within a run, every 7th record without one (skipped), the autopilot's clock (at 3x, with
    // jitter) in even runs only.
    let mut write = |armed: bool, v: f64, p: f64, activity: &str| {
        let volts = 15.0 + noise(cycle + seed, 0.5);
        let mut observations: std::collections::BTreeMap<String, f64> = [
            ("battery_v", volts),
            ("battery_current_a", p / volts),
            ("armed", if armed { 1.0 } else { 0.0 }),
            ("groundspeed_mps", v),
            ("altitude_m", if armed { 30.0 } else { 0.0 }),
        ]
        .into_iter()
        .map(|(k, x)| (k.to_string(), x))
        .collect();
        if seed % 2 == 0 {
            let jitter = noise(seed * 31 + cycle, 0.4);
            observations.insert("vehicle_time_s".into(), 500.0 + 3.0 * cycle as f64 + jitter);
        }
        let activity_name = if cycle % 7 == 3 { "" } else { activity };
        let r = DecisionRecord {
            cycle,
            time_s: cycle as f64,
            observations: observations.into_iter().collect(),
            guarantee: Some(GuaranteeRecord {
                activity_name: activity_name.to_string(),
                ..Default::default()
            }),
            ..Default::default()
        };
        f.record(&r);
        cycle += 1;
    };
    for i in 0..20 {
        write(false, 0.0, t.base + noise(seed * 1000 + i, 0.3), "take_off");
    }
    let mut k = 0;
    for (j, (v, n)) in speeds.iter().enumerate() {
        let activity = format!("leg{}", (j + seed as usize) % 3);
        for _ in 0..*n {
            k += 1;
            let v = v + noise(seed * 7 + k, 0.2).abs();
            write(true, v, power(t, v) + noise(seed * 13 + k, 3.0), &activity);
        }
    }
}

const A: Truth = Truth {
    base: 12.0,
    p0: 95.0,
    pi: 230.0,
    v0: 7.5,
    cda: 0.08,
};
const B: Truth = Truth {
    base: 9.0,
    p0: 70.0,
    pi: 180.0,
    v0: 6.0,
    cda: 0.05,
};

const SPEEDS: [(f64, u32); 6] = [
    (0.0, 30),
    (4.0, 30),
    (8.0, 30),
    (12.0, 30),
    (16.0, 30),
    (6.0, 40),
];

/// What `companion calibrate RUN...` learns from `runs`.
fn companion_fit(runs: Vec<PathBuf>) -> companion::calibrate::Calibration {
    let shipped = Shipped::load(&companion::params::default_params_dir()).unwrap();
    calibrate(&shipped, runs, None, false, false, None).unwrap()
}

fn assert_close(fleet: &serde_json::Value, cal: &companion::calibrate::Calibration) {
    let c = cal.power.as_ref().expect("the runs determine the model");
    let m = c.fitted;
    for (name, want) in [
        ("base_w", m.base_w),
        ("blade_profile_w", m.blade_profile_w),
        ("induced_hover_w", m.induced_hover_w),
        ("induced_velocity_mps", m.induced_velocity_mps),
        ("drag_area_m2", m.drag_area_m2),
        ("rms_w", c.rms_w),
        ("shipped_rms_w", c.shipped_rms_w),
        ("mean_w", c.mean_w),
    ] {
        let got = fleet[name]
            .as_f64()
            .unwrap_or_else(|| panic!("{name}: {fleet}"));
        assert!(close(got, want), "{name}: fleet {got} vs calibrate {want}");
    }
    assert_eq!(fleet["samples"].as_u64(), Some(c.samples));
    assert_eq!(fleet["ground_samples"].as_u64(), Some(c.ground_samples));
    // The activity durations: every activity calibrate timed, n, mean and spread.
    let got = fleet["durations"]["activities"]
        .as_object()
        .unwrap_or_else(|| panic!("durations: {fleet}"));
    let want = cal.durations.stats();
    assert!(!want.is_empty());
    assert_eq!(
        got.keys().collect::<Vec<_>>(),
        want.keys().collect::<Vec<_>>()
    );
    for (a, w) in want {
        let g = &got[a];
        assert_eq!(g["n"].as_u64(), Some(w.n), "{a}: {g}");
        for (field, want) in [("mean_s", w.mean()), ("sd_s", w.sd())] {
            let v = g[field].as_f64().unwrap();
            assert!(close(v, want), "{a}.{field}: fleet {v} vs calibrate {want}");
        }
    }
    let got_np = fleet["durations"]["non_positive"].as_object().unwrap();
    assert_eq!(
        got_np.len(),
        cal.durations.non_positive().len(),
        "{got_np:?}"
    );
}

#[test]
fn the_fleet_fit_equals_calibrate_on_the_same_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let mut a_runs = Vec::new();
    for s in 0..4 {
        let d = a.join(format!("run{s}"));
        write_run(&d, A, s, &SPEEDS);
        a_runs.push(d);
    }
    let mut b_runs = Vec::new();
    for s in 10..13 {
        let d = b.join(format!("run{s}"));
        write_run(&d, B, s, &SPEEDS[1..]);
        b_runs.push(d);
    }
    let ds = tmp.path().join("fleet");
    let ds_s = ds.to_str().unwrap();
    fleet(&[
        "ingest",
        a.to_str().unwrap(),
        "--into",
        ds_s,
        "--vehicle",
        "A",
    ]);
    fleet(&[
        "ingest",
        b.to_str().unwrap(),
        "--into",
        ds_s,
        "--vehicle",
        "B",
    ]);
    // One vehicle's runs
    let got: serde_json::Value =
        serde_json::from_str(&fleet(&["calibrate", ds_s, "--vehicle", "A", "--json"])).unwrap();
    assert_close(&got, &companion_fit(a_runs.clone()));
    // The two vehicles' fit differs from A's alone (the filter is not a no-op) ...
    let all: serde_json::Value =
        serde_json::from_str(&fleet(&["calibrate", ds_s, "--json"])).unwrap();
    assert_ne!(all["base_w"], got["base_w"]);
    // ... and equals calibrate over every run (a repeated run counts once on both sides).
    let mut every = a_runs.clone();
    every.extend(b_runs);
    every.push(a_runs[0].clone());
    assert_close(&all, &companion_fit(every));
    // The overlay loads in `companion`'s params reader and carries the fit.
    let out = tmp.path().join("fitted.toml");
    fleet(&[
        "calibrate",
        ds_s,
        "--vehicle",
        "A",
        "--out",
        out.to_str().unwrap(),
    ]);
    let (_, table) =
        companion::calibrate::overlay::read_overlay(&out, companion::params::default_params_dir())
            .unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("propulsion"), "{text}");
    assert!(table.contains_key("calibration"), "{table:?}");
}

/// A dataset under `dir` holding one run of vehicle A.
fn one_run_dataset(dir: &Path) -> PathBuf {
    let run = dir.join("r");
    write_run(&run, A, 1, &SPEEDS);
    let ds = dir.join("fleet");
    fleet(&[
        "ingest",
        run.to_str().unwrap(),
        "--into",
        ds.to_str().unwrap(),
    ]);
    ds
}

#[test]
fn a_vehicle_without_runs_is_refused_with_why() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = one_run_dataset(tmp.path());
    let o = std::process::Command::new(FLEET)
        .args(["calibrate", ds.to_str().unwrap(), "--vehicle", "nobody"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no power sample"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

/// Make the ingested dataset `ds` look written by fleet schema 3: no `stretches` table, and the
/// runs' `fleet_schema` 3.
fn downgrade_to_schema_3(ds: &Path) {
    use arrow::array::{ArrayRef, Int64Array};
    use parquet::arrow::ArrowWriter;
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let mut batches = 0;
    for entry in walk(ds) {
        let name = entry.file_name().unwrap().to_string_lossy().to_string();
        if name.starts_with("stretches") {
            std::fs::remove_file(&entry).unwrap();
            batches += 1;
        } else if name.starts_with("runs") && name.ends_with(".parquet") {
            let reader =
                ParquetRecordBatchReaderBuilder::try_new(std::fs::File::open(&entry).unwrap())
                    .unwrap();
            let schema = reader.schema().clone();
            let rows: Vec<_> = reader.build().unwrap().map(Result::unwrap).collect();
            let mut w =
                ArrowWriter::try_new(std::fs::File::create(&entry).unwrap(), schema, None).unwrap();
            for b in rows {
                let i = b.schema().index_of("fleet_schema").unwrap();
                let mut cols = b.columns().to_vec();
                cols[i] = std::sync::Arc::new(Int64Array::from(vec![3; b.num_rows()])) as ArrayRef;
                w.write(&arrow::record_batch::RecordBatch::try_new(b.schema(), cols).unwrap())
                    .unwrap();
            }
            w.close().unwrap();
        }
    }
    assert!(batches > 0, "no stretches table in {}", ds.display());
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

#[test]
fn a_dataset_of_fleet_schema_3_is_refused_with_re_ingest() {
    // Schema 3 had no `stretches` (the durations were windows over `records`): calibrate says to
    // re-ingest instead of failing on the missing table or timing nothing.
    let tmp = tempfile::tempdir().unwrap();
    let ds = one_run_dataset(tmp.path());
    downgrade_to_schema_3(&ds);
    for cmd in ["calibrate", "report"] {
        let o = std::process::Command::new(FLEET)
            .args([cmd, ds.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("re-ingest"),
            "{cmd}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}
