//! A simulated autopilot link: the telemetry an ArduPilot copter streams to the companion (about
//! 50 frames/s, the message mix `params/link.toml` requests plus ATTITUDE, VFR_HUD and onboard
//! monitors), built from an [`Observations`] snapshot of the simulated world, and a minimal
//! responder that acknowledges commands and accepts mission uploads.
//!
//! Why: the ingest benchmark and the soak run need realistic byte streams and a `fly`
//! shell that reaches its normal states, without Python or a SITL. Pure: time comes in as a value.

use companion_core::observations::Observations;
use companion_link::Msg;
use companion_link::dialect::*;
use mavlink::types::CharArray;

/// What the world's observations do not say but an autopilot reports (armed, altitude, mode).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    pub armed: bool,
    pub altitude_m: f64,
    pub mission_seq: u16,
    /// ArduCopter custom mode (0 STABILIZE, 3 AUTO, 4 GUIDED, 6 RTL, 9 LAND).
    pub custom_mode: u32,
    pub groundspeed_mps: f64,
    /// Energy drawn from the battery since it was fitted (J): BATTERY_STATUS energy_consumed.
    pub energy_consumed_j: f64,
}

/// Which message goes in each of the 50 slots of one second (20 ms apart). Counts per second:
/// ATTITUDE 10, GLOBAL_POSITION_INT 5, DISTANCE_SENSOR 5, OBSTACLE_DISTANCE 5, SYS_STATUS,
/// GPS_RAW_INT, VIBRATION, EKF_STATUS_REPORT, VFR_HUD, CAMERA_TRACKING_IMAGE_STATUS 2 each,
/// HEARTBEAT, BATTERY_STATUS, WIND, MISSION_CURRENT, EXTENDED_SYS_STATE, SYSTEM_TIME 1 each,
/// six onboard NAMED_VALUE_FLOATs, and one rotating slot (HOME_POSITION, STATUSTEXT, the
/// monitor's HEARTBEAT). Rates of params/link.toml where it names them; the rest assumption.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Attitude,
    GlobalPos,
    Distance,
    ObstacleDist,
    SysStatus,
    GpsRaw,
    Vibration,
    Ekf,
    VfrHud,
    CamTracking,
    Heartbeat,
    Battery,
    Wind,
    MissionCurrent,
    ExtSysState,
    SystemTime,
    Monitor,
    Rotating,
}

const MIX: [(Kind, u32); 18] = [
    (Kind::Attitude, 10),
    (Kind::GlobalPos, 5),
    (Kind::Distance, 5),
    (Kind::ObstacleDist, 5),
    (Kind::SysStatus, 2),
    (Kind::GpsRaw, 2),
    (Kind::Vibration, 2),
    (Kind::Ekf, 2),
    (Kind::VfrHud, 2),
    (Kind::CamTracking, 2),
    (Kind::Heartbeat, 1),
    (Kind::Battery, 1),
    (Kind::Wind, 1),
    (Kind::MissionCurrent, 1),
    (Kind::ExtSysState, 1),
    (Kind::SystemTime, 1),
    (Kind::Monitor, 6),
    (Kind::Rotating, 1),
];

/// Frames per simulated second.
pub const FRAMES_PER_S: u32 = 50;

/// Onboard monitor names and the observation each reports: the link's default list.
use companion_link::telemetry::DEFAULT_ONBOARD as MONITORS;

/// Source of a frame: the autopilot (sys 1, comp 1) or the onboard camera monitor (comp 100).
pub const AUTOPILOT: (u8, u8) = (1, 1);
pub const MONITOR: (u8, u8) = (1, 100);

/// The 50-slot schedule of one second, interleaving each kind evenly.
fn schedule() -> Vec<Kind> {
    let mut v: Vec<(f64, usize, Kind)> = Vec::new();
    for (i, (k, n)) in MIX.iter().enumerate() {
        for j in 0..*n {
            v.push(((j as f64 + 0.5) / *n as f64, i, *k));
        }
    }
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    v.into_iter().map(|x| x.2).collect()
}

/// Telemetry generator: call [`Telemetry50::frame`] once per 20 ms slot.
pub struct Telemetry50 {
    slots: Vec<Kind>,
    slot: u64,
    /// Home (lat e7, lon e7, amsl m).
    pub home: (i32, i32, f64),
}

impl Default for Telemetry50 {
    fn default() -> Self {
        Self::new()
    }
}

impl Telemetry50 {
    pub fn new() -> Self {
        let slots = schedule();
        debug_assert_eq!(slots.len(), FRAMES_PER_S as usize);
        Self {
            slots,
            slot: 0,
            // ArduPilot SITL's default home.
            home: (-353632610, 1491652300, 584.0),
        }
    }

    /// Time of the next slot (s).
    pub fn next_time_s(&self) -> f64 {
        self.slot as f64 / FRAMES_PER_S as f64
    }

    /// The next slot's message and its source (system, component).
    pub fn frame(&mut self, obs: &Observations, v: &VehicleView) -> ((u8, u8), Msg) {
        let n = self.slot;
        let kind = self.slots[(n % FRAMES_PER_S as u64) as usize];
        let sec = n / FRAMES_PER_S as u64;
        self.slot += 1;
        let t = n as f64 / FRAMES_PER_S as f64;
        let boot_ms = (t * 1000.0) as u32 + 5000;
        let get = |k: &str, d: f64| obs.get(k).unwrap_or(d);
        // A slow circle around home while airborne.
        let ang = t / 60.0;
        let (north, east) = if v.altitude_m > 0.5 {
            (100.0 * ang.sin(), 100.0 * (1.0 - ang.cos()))
        } else {
            (0.0, 0.0)
        };
        let lat = self.home.0 + (north / 0.011131884) as i32;
        let lon = self.home.1
            + (east / 0.011131884 / (self.home.0 as f64 * 1e-7).to_radians().cos()) as i32;
        let battery = get("battery_pct", 100.0).clamp(0.0, 100.0);
        let obstacle_cm = (get("obstacle_m", 50.0) * 100.0).clamp(20.0, 4000.0) as u16;
        let ap = |m| (AUTOPILOT, m);
        match kind {
            Kind::Attitude => ap(Msg::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: boot_ms,
                yaw: (ang as f32).sin(),
                ..ATTITUDE_DATA::DEFAULT
            })),
            Kind::GlobalPos => {
                let spd = v.groundspeed_mps * 100.0;
                ap(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                    time_boot_ms: boot_ms,
                    lat,
                    lon,
                    alt: ((self.home.2 + v.altitude_m) * 1000.0) as i32,
                    relative_alt: (v.altitude_m * 1000.0) as i32,
                    vx: (spd * ang.cos()) as i16,
                    vy: (spd * ang.sin()) as i16,
                    vz: 0,
                    hdg: ((ang.to_degrees() + 90.0).rem_euclid(360.0) * 100.0) as u16,
                }))
            }
            Kind::Distance => ap(Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
                time_boot_ms: boot_ms,
                min_distance: 20,
                max_distance: 4000,
                current_distance: obstacle_cm,
                mavtype: MavDistanceSensor::MAV_DISTANCE_SENSOR_LASER,
                orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_NONE,
                ..DISTANCE_SENSOR_DATA::DEFAULT
            })),
            Kind::ObstacleDist => {
                let mut d = [4001u16; 72];
                for (i, x) in d.iter_mut().enumerate().take(12) {
                    *x = obstacle_cm.saturating_add(10 * i as u16).min(4000);
                }
                ap(Msg::OBSTACLE_DISTANCE(OBSTACLE_DISTANCE_DATA {
                    time_usec: (t * 1e6) as u64,
                    distances: d,
                    increment: 5,
                    min_distance: 20,
                    max_distance: 4000,
                    ..OBSTACLE_DISTANCE_DATA::DEFAULT
                }))
            }
            Kind::SysStatus => ap(Msg::SYS_STATUS(SYS_STATUS_DATA {
                // ArduCopter's usual sensor set, all healthy, prearm checks passing.
                onboard_control_sensors_present: sensors(),
                onboard_control_sensors_enabled: sensors(),
                onboard_control_sensors_health: sensors(),
                voltage_battery: (12600.0 + 4200.0 * battery / 100.0) as u16,
                current_battery: 1250,
                battery_remaining: battery as i8,
                load: 250,
                ..SYS_STATUS_DATA::DEFAULT
            })),
            Kind::GpsRaw => ap(Msg::GPS_RAW_INT(GPS_RAW_INT_DATA {
                time_usec: (t * 1e6) as u64,
                lat,
                lon,
                alt: ((self.home.2 + v.altitude_m) * 1000.0) as i32,
                eph: 121,
                epv: 200,
                fix_type: match get("gps_fix", 3.0) as u8 {
                    0 => GpsFixType::GPS_FIX_TYPE_NO_GPS,
                    1 => GpsFixType::GPS_FIX_TYPE_NO_FIX,
                    2 => GpsFixType::GPS_FIX_TYPE_2D_FIX,
                    _ => GpsFixType::GPS_FIX_TYPE_3D_FIX,
                },
                satellites_visible: get("gps_sats", 14.0) as u8,
                ..GPS_RAW_INT_DATA::DEFAULT
            })),
            Kind::Vibration => {
                let vib = get("vibration_mps2", 3.0) as f32;
                ap(Msg::VIBRATION(VIBRATION_DATA {
                    time_usec: (t * 1e6) as u64,
                    vibration_x: vib * 0.8,
                    vibration_y: vib * 0.9,
                    vibration_z: vib,
                    ..VIBRATION_DATA::DEFAULT
                }))
            }
            Kind::Ekf => ap(Msg::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
                flags: EkfStatusFlags::from_bits_truncate(0x3ff),
                velocity_variance: 0.05,
                pos_horiz_variance: 0.04,
                pos_vert_variance: 0.03,
                compass_variance: 0.02,
                ..EKF_STATUS_REPORT_DATA::DEFAULT
            })),
            Kind::VfrHud => ap(Msg::VFR_HUD(VFR_HUD_DATA {
                groundspeed: v.groundspeed_mps as f32,
                airspeed: v.groundspeed_mps as f32,
                alt: (self.home.2 + v.altitude_m) as f32,
                throttle: if v.armed { 45 } else { 0 },
                ..VFR_HUD_DATA::DEFAULT
            })),
            Kind::CamTracking => {
                let active = get("target_detected", 0.0) > 0.5;
                (
                    MONITOR,
                    Msg::CAMERA_TRACKING_IMAGE_STATUS(CAMERA_TRACKING_IMAGE_STATUS_DATA {
                        tracking_status: if active {
                            CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE
                        } else {
                            CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_IDLE
                        },
                        point_x: if active { 0.5 } else { f32::NAN },
                        point_y: if active { 0.5 } else { f32::NAN },
                        ..CAMERA_TRACKING_IMAGE_STATUS_DATA::DEFAULT
                    }),
                )
            }
            Kind::Heartbeat => ap(autopilot_heartbeat(v)),
            Kind::Battery => {
                let mut voltages = [u16::MAX; 10];
                voltages[..4].fill(3950);
                ap(Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
                    id: 0,
                    voltages,
                    current_battery: 1250,
                    // mAh at the 14.8 V nominal of a 4S pack; hJ
                    current_consumed: (v.energy_consumed_j / 3.6 / 14.8) as i32,
                    energy_consumed: (v.energy_consumed_j / 100.0) as i32,
                    battery_remaining: battery as i8,
                    temperature: 3200,
                    ..BATTERY_STATUS_DATA::DEFAULT
                }))
            }
            Kind::Wind => ap(Msg::WIND(WIND_DATA {
                direction: 200.0,
                speed: get("wind_mps", 2.0) as f32,
                speed_z: 0.0,
            })),
            Kind::MissionCurrent => ap(Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
                seq: v.mission_seq,
                ..MISSION_CURRENT_DATA::DEFAULT
            })),
            Kind::ExtSysState => ap(Msg::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
                landed_state: if v.altitude_m > 0.5 {
                    MavLandedState::MAV_LANDED_STATE_IN_AIR
                } else {
                    MavLandedState::MAV_LANDED_STATE_ON_GROUND
                },
                ..EXTENDED_SYS_STATE_DATA::DEFAULT
            })),
            Kind::SystemTime => ap(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 1_700_000_000_000_000 + (t * 1e6) as u64,
                time_boot_ms: boot_ms,
            })),
            Kind::Monitor => {
                let i = (n % FRAMES_PER_S as u64) as usize;
                let k = self.slots[..i]
                    .iter()
                    .filter(|k| **k == Kind::Monitor)
                    .count();
                let (name, obs_name) = MONITORS[k % MONITORS.len()];
                (
                    MONITOR,
                    Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                        time_boot_ms: boot_ms,
                        name: CharArray::from(name),
                        value: get(obs_name, 0.0) as f32,
                    }),
                )
            }
            Kind::Rotating => match sec % 3 {
                0 => ap(Msg::HOME_POSITION(HOME_POSITION_DATA {
                    latitude: self.home.0,
                    longitude: self.home.1,
                    altitude: (self.home.2 * 1000.0) as i32,
                    q: [1.0, 0.0, 0.0, 0.0],
                    ..HOME_POSITION_DATA::DEFAULT
                })),
                1 => ap(Msg::STATUSTEXT(STATUSTEXT_DATA {
                    severity: MavSeverity::MAV_SEVERITY_INFO,
                    text: CharArray::from("EKF3 IMU0 is using GPS"),
                    ..STATUSTEXT_DATA::DEFAULT
                })),
                _ => (
                    MONITOR,
                    Msg::HEARTBEAT(HEARTBEAT_DATA {
                        custom_mode: 0,
                        mavtype: MavType::MAV_TYPE_CAMERA,
                        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                        base_mode: MavModeFlag::empty(),
                        system_status: MavState::MAV_STATE_ACTIVE,
                        mavlink_version: 3,
                    }),
                ),
            },
        }
    }
}

fn sensors() -> MavSysStatusSensor {
    MavSysStatusSensor::from_bits_truncate(0x0020_FC2F)
        | MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK
}

/// An ArduCopter HEARTBEAT for this vehicle state.
pub fn autopilot_heartbeat(v: &VehicleView) -> Msg {
    let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED;
    if v.armed {
        base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
    }
    Msg::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: v.custom_mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode,
        system_status: if v.armed {
            MavState::MAV_STATE_ACTIVE
        } else {
            MavState::MAV_STATE_STANDBY
        },
        mavlink_version: 3,
    })
}

/// The autopilot's side of the command and mission protocols, as far as a soak run needs:
/// every command accepted, every mission upload requested item by item and accepted.
#[derive(Debug, Default)]
pub struct Responder {
    upload: Option<(u16, MavMissionType)>,
    pub commands_acked: u64,
    pub missions_accepted: u64,
}

impl Responder {
    /// Replies (from the autopilot) to one message the companion sent.
    pub fn respond(&mut self, msg: &Msg) -> Vec<Msg> {
        let (ts, tc) = (AUTOPILOT.0, OUR_COMPONENT);
        match msg {
            Msg::COMMAND_LONG(c) => {
                self.commands_acked += 1;
                vec![ack(c.command)]
            }
            Msg::COMMAND_INT(c) => {
                self.commands_acked += 1;
                vec![ack(c.command)]
            }
            Msg::MISSION_COUNT(c) => {
                self.upload = Some((c.count, c.mission_type));
                if c.count == 0 {
                    self.upload = None;
                    self.missions_accepted += 1;
                    return vec![mission_ack(c.mission_type)];
                }
                vec![Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                    seq: 0,
                    target_system: ts,
                    target_component: tc,
                    mission_type: c.mission_type,
                })]
            }
            Msg::MISSION_ITEM_INT(it) => match self.upload {
                Some((count, mt)) if it.seq + 1 < count => {
                    vec![Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                        seq: it.seq + 1,
                        target_system: ts,
                        target_component: tc,
                        mission_type: mt,
                    })]
                }
                Some((_, mt)) => {
                    self.upload = None;
                    self.missions_accepted += 1;
                    vec![mission_ack(mt)]
                }
                None => vec![],
            },
            Msg::MISSION_CLEAR_ALL(c) => vec![mission_ack(c.mission_type)],
            Msg::MISSION_REQUEST_LIST(c) => vec![Msg::MISSION_COUNT(MISSION_COUNT_DATA {
                count: 0,
                target_system: ts,
                target_component: tc,
                mission_type: c.mission_type,
                ..MISSION_COUNT_DATA::DEFAULT
            })],
            _ => vec![],
        }
    }
}

const OUR_COMPONENT: u8 = companion_link::OUR_COMPONENT_ID;

fn ack(command: MavCmd) -> Msg {
    Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result: MavResult::MAV_RESULT_ACCEPTED,
        target_system: AUTOPILOT.0,
        target_component: OUR_COMPONENT,
        ..COMMAND_ACK_DATA::DEFAULT
    })
}

fn mission_ack(mission_type: MavMissionType) -> Msg {
    Msg::MISSION_ACK(MISSION_ACK_DATA {
        target_system: AUTOPILOT.0,
        target_component: OUR_COMPONENT,
        mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
        mission_type,
        ..MISSION_ACK_DATA::DEFAULT
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use companion_link::ingest::{Encoder, Ingest};
    use companion_link::modes::{Flavor, ReportedMode};
    use companion_link::telemetry::{Telemetry, TelemetryConfig};
    use std::time::Duration;

    fn obs() -> Observations {
        let mut o = Observations::default();
        for (k, v) in [
            ("battery_pct", 63.0),
            ("obstacle_m", 8.5),
            ("vibration_mps2", 4.0),
            ("wind_mps", 6.0),
            ("gps_sats", 11.0),
            ("luminosity_lux", 120.0),
            ("target_detected", 1.0),
            ("cpu_load", 0.25),
        ] {
            o.set(k, v);
        }
        o
    }

    #[test]
    fn one_second_is_fifty_frames_with_the_stated_mix() {
        let s = schedule();
        assert_eq!(s.len(), 50);
        assert_eq!(MIX.iter().map(|m| m.1).sum::<u32>(), 50);
        for (k, n) in MIX {
            assert_eq!(s.iter().filter(|x| **x == k).count(), n as usize, "{k:?}");
        }
    }

    /// Encoded, ingested and read by the fly telemetry, the frames give back the world's values
    /// (hand-checked against `obs()`), so the soak run feeds the core what the world says.
    #[test]
    fn frames_round_trip_into_the_observations_fly_builds() {
        let v = VehicleView {
            armed: true,
            altitude_m: 20.0,
            mission_seq: 3,
            custom_mode: 3,
            groundspeed_mps: 5.0,
            energy_consumed_j: 12_300.0,
        };
        let mut telem = Telemetry50::new();
        let mut enc = Encoder::new(None);
        let mut ing = Ingest::new(None);
        let mut tel = Telemetry::new(TelemetryConfig::default());
        let mut frames = 0;
        for _ in 0..100 {
            let ((s, c), m) = telem.frame(&obs(), &v);
            enc.system_id = s;
            enc.component_id = c;
            for f in ing.push(&enc.encode(&m)) {
                frames += 1;
                tel.on_message(Duration::from_secs(1), &f.msg, Flavor::Other);
            }
        }
        assert_eq!(frames, 100);
        assert_eq!(tel.get("battery_pct"), Some(63.0));
        assert_eq!(tel.obstacle_m(Duration::from_secs(1)), Some(8.5));
        assert_eq!(tel.get("vibration_mps2"), Some(4.0));
        assert_eq!(tel.get("wind_mps"), Some(6.0));
        assert_eq!(tel.get("gps_sats"), Some(11.0));
        assert_eq!(tel.get("luminosity_lux"), Some(120.0));
        assert_eq!(tel.get("target_detected"), Some(1.0));
        assert_eq!(tel.get("cpu_load"), Some(0.25));
        assert_eq!(tel.get("altitude_m"), Some(20.0));
        assert_eq!(tel.get("mission_seq"), Some(3.0));
        assert_eq!(tel.get("energy_consumed_j"), Some(12_300.0));
        assert!(tel.armed);
        assert_eq!(tel.mode, Some(ReportedMode::Number(3)));
    }

    #[test]
    fn responder_walks_a_mission_upload_and_acks_commands() {
        let mut r = Responder::default();
        let count = Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count: 3,
            ..MISSION_COUNT_DATA::DEFAULT
        });
        let item = |seq| {
            Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
                seq,
                ..MISSION_ITEM_INT_DATA::DEFAULT
            })
        };
        let req = |m: &[Msg]| match m {
            [Msg::MISSION_REQUEST_INT(q)] => Some(q.seq),
            _ => None,
        };
        assert_eq!(req(&r.respond(&count)), Some(0));
        assert_eq!(req(&r.respond(&item(0))), Some(1));
        assert_eq!(req(&r.respond(&item(1))), Some(2));
        assert!(
            matches!(r.respond(&item(2)).as_slice(), [Msg::MISSION_ACK(a)] if a.mavtype == MavMissionResult::MAV_MISSION_ACCEPTED)
        );
        assert_eq!(r.missions_accepted, 1);
        let cmd = Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_NAV_TAKEOFF,
            ..COMMAND_LONG_DATA::DEFAULT
        });
        assert!(
            matches!(r.respond(&cmd).as_slice(), [Msg::COMMAND_ACK(a)] if a.command == MavCmd::MAV_CMD_NAV_TAKEOFF && a.result == MavResult::MAV_RESULT_ACCEPTED)
        );
    }
}
