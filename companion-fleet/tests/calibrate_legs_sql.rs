//! `companion-fleet calibrate` fits how the vehicle flies (legs, climb, descent: docs/fleet.md
//! "Calibration") from SQL sums over the dataset's `legs` table: the same leg model and
//! vertical rates as `companion calibrate RUN...` (its library entry) on the same runs, within
//! 1e-9 relative, with legs whose commanded speed is the autopilot's parameter and legs that
//! take calibrate's fallback speed. The tlog generator is companion/tests/calibrate_legs.rs's.

use companion::calibrate::legs::{LegModel, fit_legs, rate};
use companion::calibrate::{calibrate, shipped::Shipped};
use companion::decision_log::Header;
use companion_core::route_plan::Position;
use companion_link::Msg;
use companion_link::dialect::*;
use std::io::Write;
use std::path::{Path, PathBuf};

const FLEET: &str = env!("CARGO_BIN_EXE_companion-fleet");

const HOME: (f64, f64) = (-35.363261, 149.165230);

/// The vehicle: cruise `v` m/s (the autopilot's WPNAV_SPEED says `commanded`), `overhead` s per
/// waypoint, 3 s of spin-up, then a 2 m/s climb to 20 m, and a 1 m/s descent.
struct Vehicle {
    v: f64,
    commanded: f64,
    overhead: f64,
    legs: Vec<(f64, f64)>,
    /// The autopilot's WPNAV_SPEED is in the tlog (else calibrate's fallback speed counts).
    says_speed: bool,
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
            // A rotary-wing vehicle (Zeng et al. eq. 12, v0 7.5 m/s): the power fit is
            // determined, so calibrate goes on to the legs.
            let r = speed * speed / (7.5 * 7.5);
            let induced = ((1.0 + r * r / 4.0).sqrt() - r / 2.0).max(0.0).sqrt();
            12.0 + 95.0 * (1.0 + 3.0 * speed * speed / 6400.0)
                + 230.0 * induced
                + 0.5 * 1.225 * 0.08 * speed.powi(3)
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
    if v.says_speed {
        l.send(&Msg::PARAM_VALUE(PARAM_VALUE_DATA {
            param_id: "WPNAV_SPEED".into(),
            param_value: (v.commanded * 100.0) as f32,
            ..Default::default()
        }));
    }
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

fn fleet(args: &[&str]) -> String {
    let o = std::process::Command::new(FLEET)
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "companion-fleet {args:?}\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

fn close(got: &serde_json::Value, want: f64, what: &str) {
    let g = got
        .as_f64()
        .unwrap_or_else(|| panic!("{what}: not a number: {got}"));
    assert!(
        (g - want).abs() <= 1e-9 * want.abs().max(1e-12),
        "{what}: fleet {g} vs calibrate {want}"
    );
}

fn assert_same(
    got: &serde_json::Value,
    m: &LegModel,
    climbs: Option<(f64, f64)>,
    descents: Option<(f64, f64)>,
) {
    let legs = &got["legs"];
    assert_eq!(legs["legs"].as_u64(), Some(m.legs as u64), "{got}");
    close(&legs["overhead_s"], m.overhead_s, "overhead_s");
    close(&legs["rms_s"], m.rms_s, "rms_s");
    close(&legs["rms_before_s"], m.rms_before_s, "rms_before_s");
    for (name, want) in [
        ("speed_fraction", m.speed_fraction),
        ("fitted_fraction", m.fitted_fraction),
    ] {
        match want {
            Some(w) => close(&legs[name], w, name),
            None => assert!(legs[name].is_null(), "{name}: {got}"),
        }
    }
    close(&legs["commanded_mps"][0], m.commanded.0, "commanded lo");
    close(&legs["commanded_mps"][1], m.commanded.1, "commanded hi");
    close(&legs["lengths_m"][0], m.lengths.0, "lengths lo");
    close(&legs["lengths_m"][1], m.lengths.1, "lengths hi");
    assert_eq!(
        legs["sources"].as_array().unwrap().len(),
        m.sources.len(),
        "{got}"
    );
    for (kind, want) in [("climb", climbs), ("descent", descents)] {
        let (r, rms) = want.expect("the flights climb and descend");
        close(&got[kind]["speed_mps"], r, kind);
        close(&got[kind]["rms_s"], rms, kind);
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
        },
        Vehicle {
            v: 7.5,
            commanded: 10.0,
            overhead: 2.5,
            legs: route[1..].to_vec(),
            says_speed: true,
        },
        // no commanded speed in the tlog: calibrate's fallback
        Vehicle {
            v: 6.0,
            commanded: 10.0,
            overhead: 1.5,
            legs: route.to_vec(),
            says_speed: false,
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
