//! `companion calibrate` refuses what no airframe can be (issue 40, docs/calibrate.md): fits
//! outside the mission's `[power_bounds]` (a hover of 1e9 W or 1e-4 W, a curve falling below
//! zero before the mission's fastest speed), durations of zero length: non-zero exit, the
//! reason, and no overlay written. Frames count only from the autopilot `fly` would obey, and
//! each run once whatever names or links lead to it.

mod common;
use common::text;
use companion::decision_log::Header;
use companion_core::record::{DecisionRecord, GuaranteeRecord};
use std::path::{Path, PathBuf};

/// The binary under test (named here: scripts/arm.sh skips tests that start it under qemu).
const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

/// Speeds flown (m/s) and seconds at each, by activity.
const FLIGHT: [(&str, f64, u32); 6] = [
    ("take_off", 0.0, 30),
    ("transit", 2.0, 30),
    ("transit", 4.0, 30),
    ("transit_gps_degraded", 6.0, 30),
    ("obstacle_dense", 8.0, 30),
    ("tracking_area", 5.0, 30),
];

/// ArduCopter SITL's quad as calibrated (params/vehicles/arducopter-sitl.toml), base 0 W.
fn sitl_power(v: f64) -> f64 {
    354.0 + 0.6 * v * v - 0.034 * v * v * v
}

/// A run folder: header, 20 records on the ground at `ground_w`, then [`FLIGHT`] at
/// `power(v)`, one record a second (time from `clock(i)`); `power` None: no current recorded.
fn write_run(
    dir: &Path,
    ground_w: f64,
    power: Option<&dyn Fn(f64) -> f64>,
    clock: &dyn Fn(u32) -> f64,
) {
    let h = Header::new("test", std::time::SystemTime::UNIX_EPOCH);
    let mut f = companion_testkit::run_log::RunLog::create(dir, &h);
    let mut i = 0u32;
    let mut write = |activity: &str, armed: bool, v: f64, p: Option<f64>| {
        let mut obs = vec![
            ("armed", if armed { 1.0 } else { 0.0 }),
            ("groundspeed_mps", v),
            ("altitude_m", if armed { 30.0 } else { 0.0 }),
        ];
        if let Some(p) = p {
            obs.extend([("battery_v", 15.0), ("battery_current_a", p / 15.0)]);
        }
        let r = DecisionRecord {
            cycle: u64::from(i),
            time_s: clock(i),
            observations: obs.into_iter().map(|(k, x)| (k.to_string(), x)).collect(),
            guarantee: Some(GuaranteeRecord {
                activity_name: activity.into(),
                ..Default::default()
            }),
            ..Default::default()
        };
        f.record(&r);
        i += 1;
    };
    for _ in 0..20 {
        write("take_off", false, 0.0, power.map(|_| ground_w));
    }
    for (a, v, secs) in FLIGHT {
        for _ in 0..secs {
            write(a, true, v, power.map(|p| p(v)));
        }
    }
    // Landing completes the last activity.
    write("landing_area", true, 0.0, power.map(|p| p(0.0)));
}

fn seconds(i: u32) -> f64 {
    f64::from(i)
}

/// Calibrate `runs` into `out` (`extra` args after); the run's output.
fn calibrate(runs: &[&Path], out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args: Vec<&str> = vec!["calibrate", "--polynomial"];
    args.extend(runs.iter().map(|r| r.to_str().unwrap()));
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend(extra);
    companion(&args)
}

/// Exit non-zero, `why` in the output, and no overlay at `out`.
fn refused(o: &std::process::Output, out: &Path, why: &str) {
    let t = text(o);
    assert!(!o.status.success(), "accepted: {t}");
    assert!(t.contains(why), "expected {why:?} in: {t}");
    assert!(t.contains("nothing written"), "{t}");
    assert!(!out.exists(), "an overlay was written: {t}");
}

fn coefficients(out: &Path) -> Vec<f64> {
    let t: toml::Table = std::fs::read_to_string(out).unwrap().parse().unwrap();
    t["missions/tracking.toml"]["propulsion"]["coefficients_w"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_float().unwrap())
        .collect()
}

#[test]
fn absurd_and_vanishing_power_is_refused_and_nothing_written() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("o.toml");
    type Case<'a> = (&'a str, &'a dyn Fn(f64) -> f64, &'a str);
    let cases: [Case; 3] = [
        ("giga", &|_| 1e9, "hover power"),
        ("zero", &|_| 1e-4, "hover power"),
        // 354 W at hover, falling as v³: -254 W at 12 m/s, the mission's fastest (transit).
        ("falling", &|v| 354.0 - 0.35 * v * v * v, "m/s"),
    ];
    for (name, p, why) in cases {
        let run = tmp.path().join(name);
        write_run(&run, 0.0, Some(p), &seconds);
        let o = calibrate(&[&run], &out, &[]);
        refused(&o, &out, why);
        assert!(text(&o).contains("refused: fitted missions/tracking.toml propulsion"));
    }
    // The real vehicle's curve is accepted and written.
    let run = tmp.path().join("sitl");
    write_run(&run, 0.0, Some(&sitl_power), &seconds);
    let o = calibrate(&[&run], &out, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let c = coefficients(&out);
    assert!((c[0] - 354.0).abs() < 0.5, "{c:?}");
}

#[test]
fn durations_of_zero_length_are_refused_and_nothing_written() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    // Every record at the same time: every activity lasted 0 s.
    write_run(&run, 0.0, Some(&sitl_power), &|_| 100.0);
    let out = tmp.path().join("o.toml");
    let o = calibrate(&[&run], &out, &[]);
    refused(&o, &out, "zero or negative length");
}

#[cfg(unix)]
#[test]
fn a_run_named_50_times_or_linked_20_times_counts_once() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    write_run(&run, 0.0, Some(&sitl_power), &seconds);
    let once = tmp.path().join("once.toml");
    let o = calibrate(&[&run], &once, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let links = tmp.path().join("links");
    std::fs::create_dir(&links).unwrap();
    for i in 0..20 {
        std::os::unix::fs::symlink(&run, links.join(format!("l{i:02}"))).unwrap();
    }
    // A copy under another name is the same run too.
    let copy = tmp.path().join("copy");
    std::fs::create_dir(&copy).unwrap();
    std::fs::copy(run.join("decisions.jsonl"), copy.join("decisions.jsonl")).unwrap();
    let many = tmp.path().join("many.toml");
    let mut names: Vec<&Path> = vec![run.as_path(); 50];
    names.push(&links);
    names.push(&copy);
    let o = calibrate(&names, &many, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("calibrated from 1 run(s)"), "{t}");
    assert!(t.contains("counted once"), "{t}");
    assert_eq!(t.matches("the same content as").count(), 70, "{t}");
    // What was learned is what one run teaches: the same tables but for the names.
    let strip = |p: &Path| {
        let mut t: toml::Table = std::fs::read_to_string(p).unwrap().parse().unwrap();
        t.remove("calibration");
        t
    };
    assert_eq!(strip(&once), strip(&many));
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

/// A tlog at 5 Hz of [`FLIGHT`] from the autopilot 1/1 at [`sitl_power`], and an impostor
/// `impostor` heard first in every step: a quadrotor flying the same (its heartbeat and
/// position) on a 5 W pack.
fn write_tlog(path: &Path, impostor: (u8, u8)) {
    use companion_link::Msg;
    use companion_link::dialect::*;
    let hb = |armed: bool| {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
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
            relative_alt: (alt_m * 1000.0) as i32,
            vx: (v * 100.0).round() as i16,
            hdg: u16::MAX,
            ..Default::default()
        })
    };
    let mut out = Vec::new();
    let mut t = 1_000_000u64;
    let mut step = |out: &mut Vec<u8>, armed: bool, v: f64, alt: f64, p: f64| {
        tlog_entry(out, t, impostor, &hb(armed));
        tlog_entry(out, t, impostor, &pos(v, alt));
        tlog_entry(out, t, impostor, &bat(5.0));
        tlog_entry(out, t, (1, 1), &hb(armed));
        tlog_entry(out, t, (1, 1), &pos(v, alt));
        tlog_entry(out, t, (1, 1), &bat(p));
        t += 200_000;
    };
    for _ in 0..100 {
        step(&mut out, false, 0.0, 0.0, 0.0);
    }
    for (_, v, secs) in FLIGHT {
        for _ in 0..secs * 5 {
            step(&mut out, true, v, 30.0, sitl_power(v));
        }
    }
    std::fs::write(path, out).unwrap();
}

/// A run whose power is only in its tlog, with `impostor` in it.
fn tlog_run(dir: &Path, impostor: (u8, u8)) -> PathBuf {
    write_run(dir, 0.0, None, &seconds);
    write_tlog(&dir.join("flight.tlog"), impostor);
    dir.to_path_buf()
}

#[test]
fn an_impostor_on_another_component_heard_first_is_left_out_and_named() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tlog_run(&tmp.path().join("run"), (1, 2));
    let out = tmp.path().join("o.toml");
    let o = calibrate(&[&run], &out, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    // fly prefers component 1: the impostor's 5 W are not the vehicle's.
    let c = coefficients(&out);
    assert!((c[0] - 354.0).abs() < 1.0, "{c:?}: {t}");
    assert!(t.contains("from autopilot 1/1"), "{t}");
    assert!(t.contains("other autopilots left out"), "{t}");
    assert!(t.contains("1/2 ("), "{t}");
}

#[test]
fn an_impostor_system_heard_first_is_refused_or_pinned_out() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tlog_run(&tmp.path().join("run"), (7, 1));
    let out = tmp.path().join("o.toml");
    // Unpinned, fly would obey the first component-1 autopilot heard: the impostor's 5 W hover
    // is no airframe's, refused.
    let o = calibrate(&[&run], &out, &[]);
    refused(&o, &out, "hover power");
    assert!(text(&o).contains("from autopilot 7/1"), "{}", text(&o));
    // Pinned as fly is (--autopilot-sysid 1): the vehicle's own power, the impostor named.
    let o = calibrate(&[&run], &out, &["--autopilot-sysid", "1"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let c = coefficients(&out);
    assert!((c[0] - 354.0).abs() < 1.0, "{c:?}: {t}");
    assert!(t.contains("7/1 ("), "{t}");
    // A run fly flew pinned: its header's command line pins calibrate the same way.
    let log = run.join("decisions.jsonl");
    let body = std::fs::read_to_string(&log).unwrap();
    let h = Header::new(
        "companion fly --connect udpin:0.0.0.0:14550 --autopilot-sysid 1",
        std::time::SystemTime::UNIX_EPOCH,
    );
    let rest = body.split_once('\n').unwrap().1;
    std::fs::write(&log, serde_json::to_string(&h).unwrap() + "\n" + rest).unwrap();
    std::fs::remove_file(&out).unwrap();
    let o = calibrate(&[&run], &out, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!((coefficients(&out)[0] - 354.0).abs() < 1.0, "{t}");
    assert!(t.contains("from autopilot 1/1 (pinned)"), "{t}");
}

/// An overlay whose curve no airframe flies (zero power everywhere, a hover of 1e9 W, a base
/// above hover) stops check, simulate and fly's set-up with the overlay, the entry and why.
#[test]
fn an_overlay_no_airframe_flies_is_refused_by_check_simulate_and_fly() {
    let tmp = tempfile::tempdir().unwrap();
    let params = companion::params::default_params_dir();
    let cases = [
        (
            "[\"missions/tracking.toml\".propulsion]\nmodel = \"polynomial\"\ncoefficients_w = [0.0, 0.0, 0.0, 0.0]\n",
            "missions/tracking.toml.propulsion",
            "hover power 0.0000 W",
        ),
        (
            "[\"missions/tracking.toml\".propulsion]\nmodel = \"polynomial\"\ncoefficients_w = [1e9]\n",
            "missions/tracking.toml.propulsion",
            "outside",
        ),
        (
            "[\"missions/tracking.toml\".base]\npower_w = 500.0\n",
            "missions/tracking.toml.base.power_w",
            "not below the hover power",
        ),
    ];
    for (i, (body, entry, why)) in cases.into_iter().enumerate() {
        let overlay = tmp.path().join(format!("o{i}.toml"));
        let text_of = format!(
            "[calibration]\nparams = {:?}\n{body}",
            params.display().to_string()
        );
        std::fs::write(&overlay, text_of).unwrap();
        let o = overlay.to_str().unwrap();
        let runs = tmp.path().join("runs");
        for args in [
            vec!["check", "--params", o],
            vec![
                "simulate",
                "--params",
                o,
                "--steps",
                "2",
                "--runs-dir",
                runs.to_str().unwrap(),
            ],
        ] {
            let r = companion(&args);
            let t = text(&r);
            assert!(!r.status.success(), "{args:?} accepted: {t}");
            assert!(
                t.contains(o) && t.contains(entry) && t.contains(why),
                "{args:?}: {t}"
            );
        }
        let mut args = companion::fly::FlyArgs::from_cli([
            "--connect",
            "udpin:127.0.0.1:14550",
            "--auto-start",
        ])
        .unwrap();
        args.params = Some(overlay.clone());
        let e = companion::fly::FlySetup::load(&args)
            .err()
            .expect("fly's set-up refuses it");
        assert!(format!("{e:#}").contains(entry), "{e:#}");
    }
}

/// Run-folder names reach the terminal escaped, in the report and in an error.
#[cfg(unix)]
#[test]
fn run_folder_names_with_escape_sequences_are_shown_escaped() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run\x1b]0;owned\x07\x1b[2J");
    write_run(&run, 0.0, Some(&sitl_power), &seconds);
    let out = tmp.path().join("o.toml");
    let o = calibrate(&[&run], &out, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(!t.contains('\x1b') && !t.contains('\x07'), "{t:?}");
    assert!(t.contains("run\\u{1b}]0;owned\\u{7}"), "{t}");
    // The overlay names the run by its content, not by its name: no escape sequence reaches it.
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(
        !written.contains('\x1b') && !written.contains("owned"),
        "{written:?}"
    );
    let back: toml::Table = written.parse().unwrap();
    let runs = back["calibration"]["runs"].as_array().unwrap();
    assert!(runs[0].as_str().unwrap().starts_with("sha256:"), "{runs:?}");
    // A name that is no run folder: the error escaped too.
    let bad = tmp.path().join("none\x1b[31m");
    std::fs::create_dir(&bad).unwrap();
    let o = calibrate(&[&bad], &out, &[]);
    let t = text(&o);
    assert!(!o.status.success());
    assert!(
        !t.contains('\x1b') && t.contains("none\\u{1b}[31m"),
        "{t:?}"
    );
}

/// A fit whose error exceeds the mission's `max_fit_rms_fraction` is refused, nothing written:
/// half the readings 50 % high, half 50 % low, is no curve of the vehicle's.
#[test]
fn a_fit_whose_error_exceeds_the_stated_bound_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run");
    let k = std::cell::Cell::new(0u32);
    let scattered = |v: f64| {
        k.set(k.get() + 1);
        sitl_power(v) * if k.get().is_multiple_of(2) { 1.5 } else { 0.5 }
    };
    write_run(&run, 0.0, Some(&scattered), &seconds);
    let out = tmp.path().join("o.toml");
    let o = calibrate(&[&run], &out, &[]);
    refused(&o, &out, "max_fit_rms_fraction 0.2");
}
