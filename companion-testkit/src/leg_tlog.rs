//! A generated `flight.tlog` of a vehicle of known leg overhead, climb and descent (calibrate's
//! "How the vehicle flies", docs/calibrate.md): the fixture `companion calibrate`'s leg tests
//! (companion/tests/calibrate_legs.rs) and the fleet's SQL equality test
//! (companion-fleet/tests/calibrate_legs_sql.rs) both fly.

use companion::decision_log::Header;
use companion_core::route_plan::Position;
use companion_link::Msg;
use companion_link::dialect::*;
use std::path::Path;

/// A rotary-wing vehicle's power (Zeng et al. eq. 12, v0 7.5 m/s): a determined power fit,
/// so calibrate goes on to the legs.
pub fn rotary_wing_w(speed: f64) -> f64 {
    let r = speed * speed / (7.5 * 7.5);
    let induced = ((1.0 + r * r / 4.0).sqrt() - r / 2.0).max(0.0).sqrt();
    12.0 + 95.0 * (1.0 + 3.0 * speed * speed / 6400.0)
        + 230.0 * induced
        + 0.5 * 1.225 * 0.08 * speed.powi(3)
}

/// A SITL-like curve (not the rotary-wing model's shape).
pub fn sitl_like_w(speed: f64) -> f64 {
    350.0 + 0.6 * speed * speed - 0.03 * speed.powi(3)
}

/// Where the flights start.
pub const HOME: (f64, f64) = (-35.363261, 149.165230);

/// The vehicle: cruise `v` m/s (the autopilot's WPNAV_SPEED says `commanded`), `overhead` s per
/// waypoint, 3 s of spin-up, then a 2 m/s climb to 20 m, and a 1 m/s descent.
pub struct Vehicle {
    pub v: f64,
    pub commanded: f64,
    pub overhead: f64,
    /// Each leg's (north, east) in m.
    pub legs: Vec<(f64, f64)>,
    /// The autopilot's WPNAV_SPEED is in the tlog (else calibrate's fallback speed counts).
    pub says_speed: bool,
    /// The pack's power in the air (W) at a horizontal speed (m/s).
    pub power_w: fn(f64) -> f64,
}

/// A tlog as `fly` writes it, of the autopilot 1/1 alone, at 5 Hz on its clock.
struct Tlog {
    power_w: fn(f64) -> f64,
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

    /// One 0.2 s sample: heartbeat, position, pack (the vehicle's power in the air; 0 W disarmed).
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
            (self.power_w)(speed)
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

/// The vehicle's flight as `fly` writes its tlog.
pub fn fly(v: &Vehicle) -> Vec<u8> {
    let mut l = Tlog {
        power_w: v.power_w,
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
pub fn write_run(dir: &Path, v: &Vehicle) {
    let h = Header::new("test", std::time::SystemTime::UNIX_EPOCH);
    let mut f = crate::run_log::RunLog::create(dir, &h);
    let r = companion_core::record::DecisionRecord::default();
    f.record(&r);
    std::fs::write(dir.join("flight.tlog"), fly(v)).unwrap();
}
