//! `companion calibrate` end to end (docs/calibrate.md): a run folder generated here from a
//! known power model is fitted back; the overlay is read by `check` and `simulate` (`--params
//! FILE`); malformed run files and overlays are refused with file, line or entry and reason.

mod common;
use common::copy_dir;
use common::text;
use companion::decision_log::Header;
use companion::params::default_params_dir;
use companion_core::record::{DecisionRecord, GuaranteeRecord};
use std::path::Path;

/// The binary under test (named here: scripts/arm.sh skips tests that start it under qemu).
const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

/// The vehicle the generated run flies, unlike the shipped params (base 8 W, P0 60 W, Pi 140 W,
/// v0 6.3 m/s, CdA 0.05 m², U 80 m/s, ρ 1.225).
struct Truth {
    base: f64,
    p0: f64,
    pi: f64,
    v0: f64,
    cda: f64,
}

const TRUTH: Truth = Truth {
    base: 12.0,
    p0: 95.0,
    pi: 230.0,
    v0: 7.5,
    cda: 0.08,
};

/// The Zeng et al. model written out here, independently of the code under test.
fn truth_power(v: f64) -> f64 {
    let t = TRUTH;
    let induced =
        ((1.0 + v.powi(4) / (4.0 * t.v0.powi(4))).sqrt() - v * v / (2.0 * t.v0 * t.v0)).sqrt();
    t.base
        + t.p0 * (1.0 + 3.0 * v * v / (80.0 * 80.0))
        + t.pi * induced
        + 0.5 * 1.225 * t.cda * v.powi(3)
}

/// A run folder as `fly` writes it: header, then one record a second with the observations
/// calibrate reads. 20 s on the ground, then activities at speeds 0..16 m/s.
fn write_run(dir: &Path, speeds: &[(&str, f64, u32)], noise: bool) {
    let h = Header::new("test", std::time::SystemTime::UNIX_EPOCH);
    let mut f = companion_testkit::run_log::RunLog::create(dir, &h);
    let mut t = 0.0;
    let mut cycle = 0;
    let mut write = |activity: &str, armed: bool, v: f64, alt: f64, p: f64| {
        let volts = 15.0;
        let r = DecisionRecord {
            cycle,
            time_s: t,
            observations: [
                ("battery_v", volts),
                ("battery_current_a", p / volts),
                ("armed", if armed { 1.0 } else { 0.0 }),
                ("groundspeed_mps", v),
                ("altitude_m", alt),
            ]
            .into_iter()
            .map(|(k, x)| (k.to_string(), x))
            .collect(),
            guarantee: Some(GuaranteeRecord {
                activity_name: activity.into(),
                ..Default::default()
            }),
            ..Default::default()
        };
        f.record(&r);
        cycle += 1;
        t += 1.0;
    };
    for i in 0..20 {
        let e = if noise {
            [0.3, -0.2, 0.1, -0.4][i % 4]
        } else {
            0.0
        };
        write("take_off", false, 0.0, 0.0, TRUTH.base + e);
    }
    let mut k = 0usize;
    for (activity, v, secs) in speeds {
        for _ in 0..*secs {
            k += 1;
            let e = if noise {
                [3.0, -2.0, 1.0, -4.0, 2.0][k % 5]
            } else {
                0.0
            };
            write(activity, true, *v, 30.0, truth_power(*v) + e);
        }
    }
}

const FLIGHT: [(&str, f64, u32); 8] = [
    ("take_off", 0.0, 30),
    ("transit", 4.0, 30),
    ("transit", 8.0, 30),
    ("transit", 12.0, 30),
    ("transit_gps_degraded", 16.0, 30),
    ("obstacle_dense", 6.0, 40),
    ("tracking_area", 5.0, 60),
    ("landing_area", 2.0, 30),
];

fn overlay(path: &Path) -> toml::Table {
    std::fs::read_to_string(path).unwrap().parse().unwrap()
}

fn num(t: &toml::Table, file: &str, table: &str, key: &str) -> f64 {
    t[file][table][key]
        .as_float()
        .unwrap_or_else(|| panic!("{file} {table}.{key}"))
}

#[test]
fn a_generated_run_is_fitted_back_and_the_overlay_loads() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().join("runs");
    write_run(&runs.join("a"), &FLIGHT, true);
    write_run(&runs.join("b"), &FLIGHT, false);
    let out = tmp.path().join("fitted.toml");
    let o = companion(&[
        "calibrate",
        runs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let report = text(&o);
    eprintln!(
        "{report}\n{}",
        std::fs::read_to_string(&out).unwrap_or_default()
    );
    assert!(o.status.success(), "{report}");
    assert!(
        report.contains("fit error before (shipped params)"),
        "{report}"
    );
    assert!(report.contains("fit error after (fitted)"), "{report}");
    let t = overlay(&out);
    let m = "missions/tracking.toml";
    let hover =
        num(&t, m, "propulsion", "blade_profile_w") + num(&t, m, "propulsion", "induced_hover_w");
    assert!(
        (hover / (TRUTH.p0 + TRUTH.pi) - 1.0).abs() < 0.03,
        "hover {hover}: {report}"
    );
    assert!(
        (num(&t, m, "base", "power_w") - TRUTH.base).abs() < 0.5,
        "{report}"
    );
    let v0 = num(&t, m, "propulsion", "induced_velocity_mps");
    assert!((v0 / TRUTH.v0 - 1.0).abs() < 0.1, "v0 {v0}: {report}");
    let cda = num(&t, m, "propulsion", "drag_area_m2");
    assert!((cda / TRUTH.cda - 1.0).abs() < 0.15, "cda {cda}: {report}");
    // Every fitted number says where it came from, in place of ASSUMPTION.
    let src = t[m]["propulsion"]["source"].as_str().unwrap();
    assert!(
        src.contains("2 run(s)") && src.contains("fit RMS") && !src.contains("ASSUMPTION"),
        "{src}"
    );
    assert_eq!(t[m]["base"]["source"].as_str(), Some(src));
    // The durations are reported, never written: tracking_area flew 60 s in each run, a number
    // of this route's flights, not of the vehicle (docs/calibrate.md).
    assert!(
        report.contains("tracking_area          flown     60.0 s"),
        "{report}"
    );
    assert!(t[m].get("activities").is_none(), "{t:?}");
    let sources = t["calibration"]["sources"].as_table().unwrap();
    assert!(
        !sources.keys().any(|k| k.contains("activities")),
        "{sources:?}"
    );

    // check and simulate take the overlay; check's pre-flight estimate moves with it.
    let c = companion(&["check", "--params", out.to_str().unwrap(), "--json"]);
    assert!(c.status.success(), "{}", text(&c));
    let shipped = companion(&["check", "--json"]);
    assert_ne!(
        c.stdout, shipped.stdout,
        "the overlay changed nothing check shows"
    );
    // simulate flies with it, and its run replays: the log header holds the params as layered.
    let sim_runs = tmp.path().join("sim");
    let s = companion(&[
        "simulate",
        "--params",
        out.to_str().unwrap(),
        "--steps",
        "20",
        "--runs-dir",
        sim_runs.to_str().unwrap(),
    ]);
    assert!(s.status.success(), "{}", text(&s));
    let run = std::fs::read_dir(&sim_runs)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let log = std::fs::read_to_string(run.join("decisions.jsonl")).unwrap();
    let header = log.lines().next().unwrap();
    assert!(
        header.contains("blade_profile_w = 93."),
        "the header holds the overlaid mission: {header}"
    );
    let r = companion(&["replay", run.to_str().unwrap()]);
    assert!(r.status.success(), "{}", text(&r));
    // fly's own set-up reads it too.
    let mut args =
        companion::fly::FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"])
            .unwrap();
    args.params = Some(out.clone());
    companion::fly::FlySetup::load(&args).unwrap();
    std::fs::write(&out, "[\"missions/tracking.toml\".base]\npower_w = \"x\"\n").unwrap();
    let e = companion::fly::FlySetup::load(&args)
        .err()
        .expect("a malformed overlay stops fly's set-up");
    assert!(format!("{e:#}").contains("base.power_w"), "{e:#}");
}

#[test]
fn one_speed_is_reported_unidentifiable_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    write_run(&run, &[("transit", 5.0, 100)], false);
    let o = companion(&["calibrate", run.to_str().unwrap()]);
    let report = text(&o);
    assert!(report.contains("not fitted"), "{report}");
    assert!(
        report.contains("induced_velocity_mps") && report.contains("unidentifiable"),
        "{report}"
    );
}

#[test]
fn a_corrupted_run_file_names_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    write_run(&run, &FLIGHT, false);
    let log = run.join("decisions.jsonl");
    let mut lines: Vec<String> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    lines[3] = "{\"cycle\": \"three\", ".into();
    std::fs::write(&log, lines.join("\n") + "\n").unwrap();
    let o = companion(&["calibrate", run.to_str().unwrap()]);
    let e = text(&o);
    assert!(!o.status.success(), "{e}");
    assert!(e.contains("decisions.jsonl, line 4"), "{e}");
    assert!(!e.contains("panicked"), "{e}");

    let none = companion(&["calibrate", tmp.path().join("nothing").to_str().unwrap()]);
    assert!(!none.status.success());
    assert!(text(&none).contains("nothing"), "{}", text(&none));
}

#[test]
fn a_malformed_overlay_stops_start_up_with_file_entry_and_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = [
        (
            "[\"missions/tracking.toml\".propulsion]\nblade_profile_w = \"x\"\n",
            "propulsion.blade_profile_w",
        ),
        (
            "[\"missions/tracking.toml\".activities.nowhere]\nhold_s = 1.0\n",
            "activities.nowhere",
        ),
        (
            "[\"missions/nope.toml\".base]\npower_w = 1.0\n",
            "missions/nope.toml",
        ),
        (
            "[\"missions/tracking.toml\".base]\npower_w = inf\n",
            "base.power_w",
        ),
        ("not toml [", "not TOML"),
    ];
    for (i, (body, what)) in bad.iter().enumerate() {
        let p = tmp.path().join(format!("bad{i}.toml"));
        std::fs::write(&p, body).unwrap();
        for cmd in [
            &["check"][..],
            &["simulate", "--no-log", "--steps", "1"][..],
        ] {
            let mut args = cmd.to_vec();
            args.extend(["--params", p.to_str().unwrap()]);
            let o = companion(&args);
            let e = text(&o);
            assert!(!o.status.success(), "{body}: {e}");
            assert!(e.contains(what), "{body}: {e}");
            assert!(!e.contains("panicked"), "{e}");
        }
    }
}

/// Item 4 of issue 23: a world whose V3 keeps the target under vibrations in 30 % of the steps
/// (shipped truth 90 %, BN row P(C_V3 = activate | vibration only) = 0.9982). Calibrating the
/// shipped params on its runs recovers the row, and the recalibrated model tracks with another
/// version under vibrations. The world samples from world.toml's truth, never from the BN (the
/// core never reads the truth), so the copy's changed row is the truth's.
#[test]
fn a_changed_tracking_row_is_recovered_and_changes_the_version_flown() {
    let tmp = tempfile::tempdir().unwrap();
    let copy = tmp.path().join("params");
    std::fs::create_dir_all(&copy).unwrap();
    copy_dir(&default_params_dir(), &copy);
    let world = copy.join("world.toml");
    let w = std::fs::read_to_string(&world).unwrap();
    let at = w.find("[truth.qos.vibrations]").unwrap();
    let v3 = at + w[at..].find("V3 = 0.90").unwrap();
    std::fs::write(&world, format!("{}V3 = 0.30{}", &w[..v3], &w[v3 + 9..])).unwrap();
    const TRUE_ROW: f64 = 0.30;

    let runs = tmp.path().join("runs");
    for seed in 1..=6 {
        let o = companion(&[
            "simulate",
            "--params",
            copy.to_str().unwrap(),
            "--scenario",
            "vibrations",
            "--seed",
            &seed.to_string(),
            "--runs-dir",
            runs.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
    }
    let out = tmp.path().join("learned.toml");
    let o = companion(&[
        "calibrate",
        runs.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = overlay(&out);
    let rows = t["health/applications.toml"]["node"]["C_V3"]["override"]
        .as_array()
        .unwrap();
    let row = rows
        .iter()
        .find(|r| {
            let w = r["when"].as_table().unwrap();
            w["U_vibration"].as_str() == Some("present")
                && w["U_point_lost"].as_str() == Some("absent")
                && w["U_motion_lost"].as_str() == Some("absent")
        })
        .expect("the vibration-only row of C_V3 is learned");
    let p = row["p"][1].as_float().unwrap();
    // Tolerance 0.08: the prior (0.9982 worth 10 trials) pulls a row of ~300 trials by about
    // 0.02; the binomial's sd at 0.3 over 300 trials is 0.026.
    assert!((p - TRUE_ROW).abs() < 0.08, "learned {p}: {}", text(&o));

    let versions = |params: &str| -> Vec<String> {
        let o = companion(&[
            "simulate",
            "--params",
            params,
            "--scenario",
            "vibrations",
            "--seed",
            "1",
            "--no-log",
            "--json",
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let mut out: Vec<String> = v["decisions"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["evidence"]["A_vibration"] == "high")
            .flat_map(|r| {
                r["actions"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .filter_map(|a| a.as_str())
                    .filter(|a| a.starts_with("track_"))
                    .map(String::from)
                    .collect::<Vec<_>>()
            })
            .collect();
        out.dedup();
        out
    };
    let shipped = default_params_dir();
    assert_eq!(versions(shipped.to_str().unwrap()), ["track_v3"]);
    let learned = versions(out.to_str().unwrap());
    assert!(
        !learned.is_empty() && !learned.contains(&"track_v3".to_string()),
        "{learned:?}"
    );
}

/// A tlog entry: time stamp, then one MAVLink 2 frame from `(sys, comp)`.
fn tlog_entry(out: &mut Vec<u8>, t_us: u64, (sys, comp): (u8, u8), msg: &companion_link::Msg) {
    out.extend_from_slice(&t_us.to_be_bytes());
    let h = mavlink::MavHeader {
        system_id: sys.into(),
        component_id: comp,
        sequence: 0,
    };
    mavlink::write_v2_msg(out, h, msg).unwrap();
}

/// The tlog of a flight of [`FLIGHT`]'s speeds at 5 Hz: the autopilot (1/1) says armed,
/// position and pack; a ground station's frames (255/190) and the companion's own (1/191: the
/// autopilot's system, as a companion is; `fly` logs the frames it sends), each with a disarmed
/// heartbeat and a pack reading of 1 kW, are not the vehicle's and must not count. The
/// companion's heartbeat falls between the autopilot's and its pack reading, as it does in a
/// real tlog about one second in two.
fn write_tlog(path: &Path) {
    use companion_link::Msg;
    use companion_link::dialect::*;
    const AUTOPILOT: (u8, u8) = (1, 1);
    const COMPANION: (u8, u8) = (1, 191);
    const GCS: (u8, u8) = (255, 190);
    let hb = |armed: bool, autopilot| {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            autopilot,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
            } else {
                MavModeFlag::empty()
            },
            mavlink_version: 3,
            ..Default::default()
        })
    };
    let bat = |p: f64| {
        let mut voltages = [u16::MAX; 10];
        voltages[0] = 15_000;
        Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
            voltages,
            current_battery: (p / 15.0 * 100.0).round() as i16,
            battery_remaining: 80,
            current_consumed: -1,
            energy_consumed: -1,
            ..Default::default()
        })
    };
    let pos = |v: f64, alt_m: f64| {
        Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: 434_000_000,
            lon: 38_000_000,
            relative_alt: (alt_m * 1000.0) as i32,
            vx: (v * 100.0).round() as i16,
            hdg: u16::MAX,
            ..Default::default()
        })
    };
    let mut out = Vec::new();
    let mut t = 1_000_000u64;
    let mut step = |out: &mut Vec<u8>, armed: bool, v: f64, alt: f64, p: f64| {
        let invalid = MavAutopilot::MAV_AUTOPILOT_INVALID;
        tlog_entry(out, t, GCS, &hb(false, invalid));
        tlog_entry(out, t, GCS, &bat(1000.0));
        let ardupilot = MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA;
        tlog_entry(out, t, AUTOPILOT, &hb(armed, ardupilot));
        tlog_entry(out, t, AUTOPILOT, &pos(v, alt));
        tlog_entry(out, t, COMPANION, &hb(false, invalid));
        tlog_entry(out, t, COMPANION, &bat(1000.0));
        tlog_entry(out, t, AUTOPILOT, &bat(p));
        t += 200_000;
    };
    for _ in 0..100 {
        step(&mut out, false, 0.0, 0.0, TRUTH.base);
    }
    for (_, v, secs) in FLIGHT {
        for _ in 0..secs * 5 {
            step(&mut out, true, v, 30.0, truth_power(v));
        }
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn power_is_read_from_the_tlog_of_the_autopilot_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    // Records without any power observation: the fit can only come from the tlog.
    write_run(&run, &[("take_off", 0.0, 5)], false);
    let log = run.join("decisions.jsonl");
    let stripped: String = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(|l| l.replace("\"battery_current_a\"", "\"unused_a\"") + "\n")
        .collect();
    std::fs::write(&log, stripped).unwrap();
    write_tlog(&run.join("flight.tlog"));
    let out = tmp.path().join("o.toml");
    let o = companion(&[
        "calibrate",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let report = text(&o);
    assert!(o.status.success(), "{report}");
    let t = overlay(&out);
    let m = "missions/tracking.toml";
    assert!(
        (num(&t, m, "base", "power_w") - TRUTH.base).abs() < 0.5,
        "{report}"
    );
    let hover =
        num(&t, m, "propulsion", "blade_profile_w") + num(&t, m, "propulsion", "induced_hover_w");
    assert!(
        (hover / (TRUTH.p0 + TRUTH.pi) - 1.0).abs() < 0.03,
        "hover {hover}: {report}"
    );
    // 100 samples on the ground and 1,400 in the air at 5 Hz (the records' 5 are not used).
    assert!(
        report.contains("over 1500 samples (100 on the ground)"),
        "{report}"
    );

    // Garbage in the middle of the tlog: its byte offset and why.
    let mut bytes = std::fs::read(run.join("flight.tlog")).unwrap();
    let at = 8 + bytes[9] as usize + 12 + 8;
    bytes[at] = 0x42;
    std::fs::write(run.join("flight.tlog"), &bytes).unwrap();
    let o = companion(&["calibrate", run.to_str().unwrap()]);
    let e = text(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("flight.tlog, byte") && e.contains("found 0x42"),
        "{e}"
    );
}

/// The drift tuning is the mission's `[guarantee]` (an overlay may set it), range-checked with
/// file, entry and reason; the guarantee judges with it.
#[test]
fn the_drift_tuning_is_the_missions_and_range_checked() {
    use companion_core::guarantee::{Guarantee, PackReading, Progress, load_mission};
    let tmp = tempfile::tempdir().unwrap();
    let tuned = |name: &str, tolerance: f64| {
        let p = tmp.path().join(name);
        std::fs::write(
            &p,
            format!(
                "[\"missions/tracking.toml\".guarantee]\npower_drift_tolerance = {tolerance}\n\
                 power_drift_min_s = 2.0\nprior_weight_s = 0.0\n"
            ),
        )
        .unwrap();
        p
    };
    let ratio_two_after_5_s = |overlay: &Path| {
        let files = companion::params::read_params_dir(overlay).unwrap();
        let s = load_mission(&files, "tracking").unwrap();
        let mut g = Guarantee::start(s.clone()).unwrap();
        let ia = &s.problem.activities[1].ias[g.choice()[1]];
        let p = ia.cost[0] / ia.cost[1];
        let at = |t: f64| Progress {
            activity_index: 1,
            activity_fraction: 0.0,
            energy_used_j: None,
            battery_remaining_pct: Some(90.0),
            elapsed_s: t,
            failed_resources: &[],
            pack: PackReading {
                voltage_v: Some(12.0),
                current_a: Some(2.0 * p / 12.0),
                ..Default::default()
            },
        };
        g.watch(at(100.0));
        g.watch(at(105.0)).power.unwrap()
    };
    // Twice the predicted power for 5 s: judged (min 2 s), a drift beyond 50 %, none within 150 %.
    let tight = ratio_two_after_5_s(&tuned("tight.toml", 0.5));
    assert!(
        tight.drift && (tight.ratio.unwrap() - 2.0).abs() < 1e-9,
        "{tight:?}"
    );
    // Prior weight 0: the factor is the measured ratio.
    assert!((tight.energy_scale - 2.0).abs() < 1e-12, "{tight:?}");
    let loose = ratio_two_after_5_s(&tuned("loose.toml", 1.5));
    assert!(!loose.drift && loose.ratio.is_some(), "{loose:?}");

    let bad = tuned("bad.toml", 20.0);
    let o = companion(&["check", "--params", bad.to_str().unwrap()]);
    let e = text(&o);
    assert!(!o.status.success(), "{e}");
    assert!(
        e.contains("tracking.toml")
            && e.contains("guarantee.power_drift_tolerance")
            && e.contains("outside"),
        "{e}"
    );
}
