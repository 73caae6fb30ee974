//! `companion calibrate` fits how the vehicle flies (docs/calibrate.md, "How the vehicle flies"):
//! from a generated `flight.tlog` of a vehicle of known leg overhead, climb and descent, the
//! overlay's `[derive]` entries come back, each with its source; the overlay holds no route
//! length, no activity hold and no machine path; the derivation plans a route with them; too few
//! legs write nothing about legs, and legs flown faster than commanded are refused.

mod common;
use common::text;
use companion::decision_log::Header;
use companion_core::route_plan::Position;
use companion_link::Msg;
use companion_link::dialect::*;
use std::io::Write;
use std::path::Path;

const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

const HOME: (f64, f64) = (-35.363261, 149.165230);
const M: &str = "missions/tracking.toml";

/// The vehicle: cruise `v` m/s (the autopilot's WPNAV_SPEED says `commanded`), `overhead` s per
/// waypoint, 3 s of spin-up, then a 2 m/s climb to 20 m, and a 1 m/s descent.
struct Vehicle {
    v: f64,
    commanded: f64,
    overhead: f64,
    legs: Vec<(f64, f64)>,
}

/// A tlog as `fly` writes it, of the autopilot 1/1 alone, at 5 Hz on its clock.
struct Tlog {
    out: Vec<u8>,
    t: f64,
    pos: (f64, f64, f64),
    armed: bool,
}

impl Tlog {
    fn send(&mut self, msg: &Msg) {
        self.out
            .extend_from_slice(&((self.t * 1e6) as u64 + 1_000_000).to_be_bytes());
        let h = mavlink::MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        mavlink::write_v2_msg(&mut self.out, h, msg).unwrap();
    }

    /// One 0.2 s sample: heartbeat, position, pack (the SITL-like curve; 0 W disarmed).
    fn sample(&mut self, speed: f64) {
        let mut base = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if self.armed {
            base |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        self.send(&Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 3,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: base,
            mavlink_version: 3,
            ..Default::default()
        }));
        let p = Position::offset(HOME, self.pos.0, self.pos.1, self.pos.2);
        self.send(&Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: (self.t * 1000.0).round() as u32,
            lat: (p.lat_deg * 1e7).round() as i32,
            lon: (p.lon_deg * 1e7).round() as i32,
            relative_alt: (self.pos.2 * 1000.0).round() as i32,
            vx: (speed * 100.0).round() as i16,
            hdg: u16::MAX,
            ..Default::default()
        }));
        let w = if self.armed && self.pos.2 > 1.0 {
            350.0 + 0.6 * speed * speed - 0.03 * speed.powi(3)
        } else {
            0.0
        };
        let mut voltages = [u16::MAX; 10];
        voltages[0] = 15_000;
        self.send(&Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
            voltages,
            current_battery: (w / 15.0 * 100.0).round() as i16,
            battery_remaining: 80,
            current_consumed: -1,
            energy_consumed: -1,
            ..Default::default()
        }));
    }

    fn go(&mut self, d: (f64, f64, f64), secs: f64) {
        let n = (secs * 5.0).round().max(1.0) as usize;
        let speed = d.0.hypot(d.1) / secs;
        for _ in 0..n {
            self.t += secs / n as f64;
            self.pos.0 += d.0 / n as f64;
            self.pos.1 += d.1 / n as f64;
            self.pos.2 += d.2 / n as f64;
            self.sample(speed);
        }
    }
}

fn fly(v: &Vehicle) -> Vec<u8> {
    let mut l = Tlog {
        out: Vec::new(),
        t: 50.0,
        pos: (0.0, 0.0, 0.0),
        armed: false,
    };
    // The autopilot is heard (its heartbeat) before anything of it counts.
    l.go((0.0, 0.0, 0.0), 1.0);
    l.send(&Msg::PARAM_VALUE(PARAM_VALUE_DATA {
        param_id: "WPNAV_SPEED".into(),
        param_value: (v.commanded * 100.0) as f32,
        ..Default::default()
    }));
    // The mission as the autopilot answers the companion's check: home, take-off, waypoints.
    let n = v.legs.len() as u16 + 2;
    l.send(&Msg::MISSION_COUNT(MISSION_COUNT_DATA {
        count: n,
        ..Default::default()
    }));
    for seq in 0..n {
        let command = if seq == 1 {
            MavCmd::MAV_CMD_NAV_TAKEOFF
        } else {
            MavCmd::MAV_CMD_NAV_WAYPOINT
        };
        l.send(&Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
            seq,
            command,
            ..Default::default()
        }));
    }
    l.go((0.0, 0.0, 0.0), 20.0);
    l.armed = true;
    l.go((0.0, 0.0, 0.0), 3.0);
    l.go((0.0, 0.0, 20.0), 10.0);
    l.go((0.0, 0.0, 0.0), 1.0);
    l.send(&Msg::MISSION_ITEM_REACHED(MISSION_ITEM_REACHED_DATA {
        seq: 1,
    }));
    for (k, (dn, de)) in v.legs.iter().enumerate() {
        let seq = k as u16 + 2;
        l.send(&Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
            seq,
            ..Default::default()
        }));
        l.go((*dn, *de, 0.0), dn.hypot(*de) / v.v);
        l.go((0.0, 0.0, 0.0), v.overhead);
        l.send(&Msg::MISSION_ITEM_REACHED(MISSION_ITEM_REACHED_DATA {
            seq,
        }));
    }
    l.go((0.0, 0.0, 0.0), 30.0);
    l.go((0.0, 0.0, -20.0), 20.0);
    l.go((0.0, 0.0, 0.0), 2.0);
    l.armed = false;
    l.go((0.0, 0.0, 0.0), 5.0);
    l.out
}

/// A run folder: a decision log (header and one record) and the tlog.
fn write_run(dir: &Path, v: &Vehicle) {
    std::fs::create_dir_all(dir).unwrap();
    let mut f = std::fs::File::create(dir.join("decisions.jsonl")).unwrap();
    let h = Header::new("test", std::time::SystemTime::UNIX_EPOCH);
    writeln!(f, "{}", serde_json::to_string(&h).unwrap()).unwrap();
    let r = companion_core::record::DecisionRecord::default();
    writeln!(f, "{}", serde_json::to_string(&r).unwrap()).unwrap();
    std::fs::write(dir.join("flight.tlog"), fly(v)).unwrap();
}

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
