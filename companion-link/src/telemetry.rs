//! Telemetry → [`Observations`], and the significant events that trigger a decision cycle.
//!
//! Units and sources are listed in docs/mavlink.md. Onboard monitors (other onboard components:
//! the tracker, the landing-zone finder, the platform monitor) publish NAMED_VALUE_FLOAT; their
//! names map to observation names through `params/link.toml` `[onboard]`.

use super::Msg;
use super::dialect::*;
use super::modes::{Flavor, ReportedMode};
use companion_core::named_slots::SortedNames;
use companion_core::observations::{ObservationValues, Observations};
use companion_core::record::Event;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::time::Duration;

/// Thresholds and name mappings, from `params/link.toml`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TelemetryConfig {
    /// NAMED_VALUE_FLOAT name -> observation name.
    #[serde(default)]
    pub onboard: BTreeMap<String, String>,
    /// An obstacle closer than this (m) is an `obstacle detected` event.
    pub obstacle_near_m: f64,
    /// Battery percentages whose downward crossing is an event.
    pub battery_thresholds_pct: Vec<f64>,
    /// Distance readings older than this are ignored (s).
    pub distance_max_age_s: f64,
    /// `target_detected` above this counts as a detection.
    #[serde(default = "half")]
    pub detection_threshold: f64,
    /// Who may report onboard-monitor values besides the autopilot itself.
    #[serde(default)]
    pub monitors: MonitorSources,
    /// At most this many distinct unmapped NAMED_VALUE_FLOAT names (`onboard.<name>`) are kept;
    /// more are counted and dropped, so a flood of names cannot grow every record.
    #[serde(default = "default_max_onboard_names")]
    pub max_onboard_names: usize,
    /// Observation name -> [min, max]: a monitor value outside is counted and dropped (the last
    /// good value stays). Names not listed need only be finite.
    #[serde(default)]
    pub ranges: BTreeMap<String, [f64; 2]>,
    /// Onboard observations (values of `onboard`) kept for the record alone: nothing else need
    /// read them. Any other mapped observation nothing reads fails the load (a rename on one
    /// side only).
    #[serde(default)]
    pub recorded_only: Vec<String>,
    /// The observation vocabulary compiled once at load (`companion::vocabulary::Vocabulary`,
    /// set by `Params::load`), shared with the decision core: the telemetry writes the snapshot
    /// by its slots. Empty (every name in the snapshot's overflow) until set.
    #[serde(skip, default = "companion_core::named_slots::no_names")]
    pub vocabulary: SortedNames,
}

fn half() -> f64 {
    0.5
}

fn default_max_onboard_names() -> usize {
    32
}

/// Onboard-monitor sources (NAMED_VALUE_FLOAT, DISTANCE_SENSOR, OBSTACLE_DISTANCE,
/// CAMERA_TRACKING_IMAGE_STATUS) accepted besides the chosen autopilot, which always is.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MonitorSources {
    /// Component ids on the autopilot's own system (its system id, once chosen).
    #[serde(default)]
    pub autopilot_system_components: Vec<u8>,
    /// Further [system id, component id] pairs.
    #[serde(default)]
    pub sources: Vec<[u8; 2]>,
}

/// MAV_COMP_ID_CAMERA: the tracker and landing-zone finder in the tests and the stand-in.
pub const DEFAULT_MONITOR_COMPONENTS: [u8; 1] = [100];

impl Default for MonitorSources {
    fn default() -> Self {
        Self {
            autopilot_system_components: DEFAULT_MONITOR_COMPONENTS.to_vec(),
            sources: Vec::new(),
        }
    }
}

impl MonitorSources {
    /// May `(sys, comp)` report monitor values, given the chosen autopilot (None: not yet)?
    pub fn allows(&self, sys: u8, comp: u8, autopilot: Option<(u8, u8)>) -> bool {
        match autopilot {
            Some(ap) if ap == (sys, comp) => true,
            Some((ap_sys, _))
                if ap_sys == sys && self.autopilot_system_components.contains(&comp) =>
            {
                true
            }
            _ => self.sources.contains(&[sys, comp]),
        }
    }
}

/// Telemetry refused for being implausible, counted since start.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rejected {
    /// Values outside `[telemetry.ranges]`, non-finite, or positions off the globe.
    pub out_of_range: u64,
    /// Unmapped names beyond `max_onboard_names`, or not printable ASCII (a name becomes an
    /// observation key and reaches logs and terminals).
    pub names_dropped: u64,
    /// The latest value refused, for the link event (`zone_north_m = 1e9`).
    pub last: Option<String>,
}

/// Onboard monitor NAMED_VALUE_FLOAT names and the observation each reports, when
/// params/link.toml gives no `[onboard]` table (the same list it ships with).
pub const DEFAULT_ONBOARD: [(&str, &str); 6] = [
    ("tgt_det", "target_detected"),
    ("tgt_spd", "target_speed_rel"),
    ("trk_conf", "track_confidence"),
    ("lum", "luminosity_lux"),
    ("cpu_load", "cpu_load"),
    ("free_tiles", "free_tiles"),
];

/// Observations the telemetry produces from the autopilot's own messages (besides the onboard
/// monitors' names, params/link.toml `[telemetry.onboard]`): what `fly` can observe, checked
/// against what params/observations.toml declares. A test keeps it in step with `on_message`.
pub const TELEMETRY_OBSERVATIONS: [&str; 28] = [
    "battery_pct",
    "battery_v",
    "battery_current_a",
    "battery_capacity_mah",
    "battery_cells",
    "cruise_speed_mps",
    "climb_speed_mps",
    "descent_speed_mps",
    "energy_consumed_j",
    "consumed_mah",
    "lat_deg",
    "lon_deg",
    "altitude_m",
    "groundspeed_mps",
    "distance_home_m",
    "gps_fix",
    "gps_sats",
    "vibration_mps2",
    "vibration_clipping",
    "wind_mps",
    "wind_dir_deg",
    "mission_seq",
    "target_detected",
    "target_x",
    "target_y",
    "vehicle_time_s",
    "obstacle_m",
    "armed",
];

/// Observations the link itself reads (the `goto_zone` step flies to the zone they place), so an
/// onboard monitor's mapping to them (params/link.toml `[telemetry.onboard]`) has a reader.
pub const LINK_READS: [&str; 2] = ["zone_north_m", "zone_east_m"];

/// Which pack parameter an autopilot reported ([`Telemetry::on_pack_param`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PackParam {
    /// The pack's capacity (mAh).
    CapacityMah,
    /// Cells in series.
    Cells,
}

/// Which mission speed an autopilot parameter gave ([`Telemetry::on_speed_param`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeedParam {
    /// Horizontal speed between waypoints: observation `cruise_speed_mps`.
    Cruise,
    /// Climb speed: `climb_speed_mps`.
    Climb,
    /// Descent speed: `descent_speed_mps`.
    Descent,
}

impl SpeedParam {
    /// The observation it is reported as.
    pub fn observation(self) -> &'static str {
        match self {
            SpeedParam::Cruise => "cruise_speed_mps",
            SpeedParam::Climb => "climb_speed_mps",
            SpeedParam::Descent => "descent_speed_mps",
        }
    }
}

/// Fastest mission speed believed (m/s), the bound `[derive]` speeds have in params.
pub const MAX_MISSION_SPEED_MPS: f64 = 100.0;

/// Largest pack capacity believed (mAh): a 1,000 Ah pack is no drone's.
pub const MAX_PACK_CAPACITY_MAH: f64 = 1.0e6;
/// Most cells in series believed (a 24S pack is the largest in common use; 0 means "not set").
pub const MAX_PACK_CELLS: f64 = 24.0;

/// Longest NAMED_VALUE_FLOAT name: its `name` field is `char[10]`.
pub const NAMED_VALUE_NAME_MAX: usize = 10;

/// Most unlisted onboard names a params file may allow (each is one observation per record).
pub const MAX_ONBOARD_NAMES_LIMIT: usize = 1024;

impl TelemetryConfig {
    /// The trust settings a params file must get right: `(entry, reason)` of the first error.
    pub fn check_trust(&self) -> Result<(), (String, String)> {
        if self.max_onboard_names > MAX_ONBOARD_NAMES_LIMIT {
            return Err((
                "telemetry.max_onboard_names".into(),
                format!("at most {MAX_ONBOARD_NAMES_LIMIT}"),
            ));
        }
        for name in self.onboard.keys() {
            // NAMED_VALUE_FLOAT.name is char[10]: a longer name can never arrive, so the
            // mapping would silently never fire.
            if name.is_empty() || name.len() > NAMED_VALUE_NAME_MAX || !name.is_ascii() {
                return Err((
                    format!("telemetry.onboard.{}", name.escape_debug()),
                    format!(
                        "a NAMED_VALUE_FLOAT name is 1 to {NAMED_VALUE_NAME_MAX} ASCII \
                         characters ({} given)",
                        name.len()
                    ),
                ));
            }
        }
        for (name, [lo, hi]) in &self.ranges {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err((
                    format!("telemetry.ranges.{name}"),
                    "expected [min, max], finite, min <= max".into(),
                ));
            }
            // A range guards only what a NAMED_VALUE_FLOAT is written as: a key naming no such
            // observation (one side renamed) would let every value through unchecked.
            if !name.starts_with("onboard.") && !self.onboard.values().any(|o| o == name) {
                return Err((
                    format!("telemetry.ranges.{name}"),
                    format!(
                        "`{name}` is no observation of [telemetry.onboard] (nor `onboard.NAME`, an \
                         unmapped NAMED_VALUE_FLOAT): the range would guard nothing"
                    ),
                ));
            }
        }
        let m = &self.monitors;
        if m.autopilot_system_components.contains(&0) {
            return Err((
                "telemetry.monitors.autopilot_system_components".into(),
                "component 0 is the broadcast id, not a component".into(),
            ));
        }
        if m.sources.iter().any(|[s, c]| *s == 0 || *c == 0) {
            return Err((
                "telemetry.monitors.sources".into(),
                "system and component ids are 1..255 (0 is broadcast)".into(),
            ));
        }
        Ok(())
    }
}

impl Default for TelemetryConfig {
    fn default() -> Self {
        let onboard = DEFAULT_ONBOARD
            .into_iter()
            .map(|(a, b)| (a.to_string(), b.to_string()))
            .collect();
        Self {
            onboard,
            obstacle_near_m: 15.0,
            battery_thresholds_pct: vec![50.0, 30.0, 20.0, 10.0],
            distance_max_age_s: 2.0,
            detection_threshold: 0.5,
            monitors: MonitorSources::default(),
            max_onboard_names: default_max_onboard_names(),
            ranges: BTreeMap::new(),
            recorded_only: vec!["track_confidence".into()],
            vocabulary: companion_core::named_slots::no_names(),
        }
    }
}

/// Where the vehicle is (for relative missions and sidesteps).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Position {
    /// Latitude, degrees * 1e7.
    pub lat_e7: i32,
    /// Longitude, degrees * 1e7.
    pub lon_e7: i32,
    /// Altitude above home (m).
    pub alt_rel_m: f64,
    /// Altitude above mean sea level (m).
    pub alt_amsl_m: f64,
    /// Heading in degrees, None when the autopilot does not know.
    pub heading_deg: Option<f64>,
}

/// Telemetry state of one autopilot: observations by name plus position, mode and flight status.
#[derive(Debug, Clone, Default)]
pub struct Telemetry {
    /// Telemetry settings (params/link.toml `[telemetry]`).
    pub cfg: TelemetryConfig,
    /// The observations heard, by slot over `cfg.vocabulary`.
    values: ObservationValues,
    /// Latest GLOBAL_POSITION_INT, with the heading.
    pub position: Option<Position>,
    /// HOME_POSITION (lat e7, lon e7, amsl m).
    pub home: Option<(i32, i32, f64)>,
    /// The current flight mode, decoded for the autopilot's flavour.
    pub mode: Option<ReportedMode>,
    /// HEARTBEAT.custom_mode as last heard.
    pub custom_mode: u32,
    /// Whether the last HEARTBEAT said armed.
    pub armed: bool,
    /// EXTENDED_SYS_STATE landed state without its prefix (`ON_GROUND`, `IN_AIR`, ...).
    pub landed_state: Option<String>,
    /// MISSION_CURRENT sequence number as last heard.
    pub mission_seq: Option<u16>,
    distances: BTreeMap<u8, (f64, Duration)>,
    obstacle_scan: Option<(f64, Duration)>,
    /// Latest STATUSTEXT from the autopilot.
    pub last_text: Option<String>,
    /// Unmapped onboard names kept so far (bounded by `max_onboard_names`).
    onboard_names: usize,
    /// Telemetry refused as implausible, counted.
    pub rejected: Rejected,
    /// A non-zero wind reading was heard: the autopilot estimates the wind.
    wind_estimating: bool,
}

impl Telemetry {
    /// Empty telemetry with these settings.
    pub fn new(cfg: TelemetryConfig) -> Self {
        Self {
            values: ObservationValues::over(&cfg.vocabulary),
            cfg,
            ..Default::default()
        }
    }

    /// The observation named `name` (units in docs/params/health.md), if heard.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.values.get(name).copied()
    }

    /// Whether the autopilot has shown a wind estimate (a non-zero WIND or WIND_COV reading)
    /// since the link started; until then an all-zero reading gives no `wind_mps`.
    pub fn wind_estimating(&self) -> bool {
        self.wind_estimating
    }

    /// One wind reading: `raw` are the message's speed fields (all exactly zero while the
    /// autopilot does not estimate the wind), `speed` m/s and `dir_deg` the direction it blows
    /// from.
    fn on_wind(&mut self, raw: [f32; 3], speed: f64, dir_deg: f64) {
        if !(speed.is_finite() && dir_deg.is_finite()) {
            return;
        }
        if raw.iter().any(|v| *v != 0.0) {
            self.wind_estimating = true;
        }
        if self.wind_estimating {
            self.set("wind_mps", speed);
            self.set("wind_dir_deg", dir_deg);
        }
    }

    /// Update from one message. Returns significant events (`obstacle detected`, ...).
    pub fn on_message(&mut self, now: Duration, msg: &Msg, flavor: Flavor) -> Vec<Event> {
        let before_obstacle = self.obstacle_m(now);
        let before_target = self.get("target_detected");
        let before_battery = self.get("battery_pct");
        let mut events = Vec::new();
        match msg {
            Msg::HEARTBEAT(h) => self.on_heartbeat(h, flavor, &mut events),
            Msg::SYS_STATUS(s) => self.on_sys_status(s),
            Msg::BATTERY_STATUS(b) if b.id == 0 => self.on_battery_status(b),
            Msg::GLOBAL_POSITION_INT(p) if !on_globe(p.lat, p.lon) => {
                self.reject(format!("GLOBAL_POSITION_INT lat {} lon {}", p.lat, p.lon))
            }
            Msg::HOME_POSITION(h) if !on_globe(h.latitude, h.longitude) => self.reject(format!(
                "HOME_POSITION lat {} lon {}",
                h.latitude, h.longitude
            )),
            Msg::GLOBAL_POSITION_INT(p) => self.on_global_position(p),
            Msg::HOME_POSITION(h) => {
                self.home = Some((h.latitude, h.longitude, h.altitude as f64 / 1000.0))
            }
            Msg::GPS_RAW_INT(g) => {
                self.set("gps_fix", g.fix_type as u8 as f64);
                if g.satellites_visible != u8::MAX {
                    self.set("gps_sats", g.satellites_visible as f64);
                }
            }
            Msg::VIBRATION(v) => {
                self.set(
                    "vibration_mps2",
                    v.vibration_x.max(v.vibration_y).max(v.vibration_z) as f64,
                );
                self.set(
                    "vibration_clipping",
                    (v.clipping_0 as f64) + (v.clipping_1 as f64) + (v.clipping_2 as f64),
                );
            }
            Msg::WIND(w) => {
                // ArduPilot sends WIND with zero speeds while its EKF has no wind states (no
                // airspeed sensor, no drag fusion): that is no estimate, not calm air. The
                // direction is then atan2 of zeros (ArduCopter SITL: -180), so only the speeds
                // count. A non-zero speed shows the estimator runs; from then on zero is calm.
                self.on_wind(
                    [w.speed, w.speed_z, 0.0],
                    w.speed as f64,
                    w.direction as f64,
                );
            }
            Msg::WIND_COV(w) => {
                // PX4's wind estimate (north wind_x, east wind_y, m/s; NaN when unknown): the
                // speed, and the direction the wind blows from, as WIND gives it.
                let (x, y) = (w.wind_x as f64, w.wind_y as f64);
                let from_deg = (-y).atan2(-x).to_degrees().rem_euclid(360.0);
                self.on_wind([w.wind_x, w.wind_y, w.wind_z], x.hypot(y), from_deg);
            }
            Msg::EXTENDED_SYS_STATE(e) => {
                let s = crate::mavlink_name(&e.landed_state)
                    .trim_start_matches("MAV_LANDED_STATE_")
                    .to_string();
                if self.landed_state.as_deref() != Some(s.as_str()) {
                    self.landed_state = Some(s);
                }
            }
            Msg::MISSION_CURRENT(m) => {
                if self.mission_seq != Some(m.seq) {
                    self.mission_seq = Some(m.seq);
                    events.push(Event::Waypoint(m.seq));
                }
                self.set("mission_seq", m.seq as f64);
            }
            Msg::DISTANCE_SENSOR(d) => self.on_distance_sensor(now, d),
            Msg::OBSTACLE_DISTANCE(o) => {
                // UINT16_MAX: sector unknown; max_distance + 1: nothing there (MAVLink spec).
                let nearest = o
                    .distances
                    .iter()
                    .filter(|&&d| d != u16::MAX && d >= o.min_distance && d <= o.max_distance)
                    .min()
                    .map(|&d| d as f64 / 100.0);
                self.obstacle_scan = nearest.map(|m| (m, now));
            }
            Msg::CAMERA_TRACKING_IMAGE_STATUS(c) => self.on_camera_tracking(c),
            Msg::NAMED_VALUE_FLOAT(n) => {
                let name = n.name.to_str().unwrap_or("").trim();
                if !name.is_empty() {
                    self.on_named_value(name, n.value);
                }
            }
            Msg::SYSTEM_TIME(t) => {
                // The autopilot's clock: mission timings follow it (a SITL may run faster than
                // real time).
                self.set("vehicle_time_s", t.time_boot_ms as f64 / 1000.0);
            }
            Msg::STATUSTEXT(t) => {
                self.last_text = Some(t.text.to_str().unwrap_or("").to_string());
            }
            _ => {}
        }
        self.crossings(
            now,
            (before_obstacle, before_target, before_battery),
            &mut events,
        );
        events
    }

    /// HEARTBEAT: armed and mode, an event when either changes.
    fn on_heartbeat(&mut self, h: &HEARTBEAT_DATA, flavor: Flavor, events: &mut Vec<Event>) {
        let armed = h
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
        if armed != self.armed {
            events.push(if armed { Event::Armed } else { Event::Disarmed });
            self.armed = armed;
        }
        let mode = ReportedMode::decode(flavor, h.custom_mode);
        if self.mode != Some(mode) {
            events.push(Event::Mode(mode.to_string()));
            self.mode = Some(mode);
        }
        self.custom_mode = h.custom_mode;
    }

    /// SYS_STATUS: the battery, unless BATTERY_STATUS gives it.
    fn on_sys_status(&mut self, s: &SYS_STATUS_DATA) {
        if s.battery_remaining >= 0 && !self.values.contains_key("battery_status_pct") {
            self.set("battery_pct", s.battery_remaining as f64);
        }
        if s.voltage_battery != u16::MAX && !self.values.contains_key("battery_status_v") {
            self.set("battery_v", s.voltage_battery as f64 / 1000.0);
        }
        // cA, -1: not measured.
        if s.current_battery >= 0 && !self.values.contains_key("battery_status_v") {
            self.set("battery_current_a", s.current_battery as f64 / 100.0);
        }
    }

    /// BATTERY_STATUS of the first pack: charge, energy, voltage and current.
    fn on_battery_status(&mut self, b: &BATTERY_STATUS_DATA) {
        if b.battery_remaining >= 0 {
            self.set("battery_pct", b.battery_remaining as f64);
            self.set("battery_status_pct", b.battery_remaining as f64);
        }
        if b.energy_consumed >= 0 {
            self.set("energy_consumed_j", b.energy_consumed as f64 * 100.0); // hJ -> J
        }
        if b.current_consumed >= 0 {
            self.set("consumed_mah", b.current_consumed as f64);
        }
        // The pack voltage: the sum of the cells given (UINT16_MAX: no such cell; ArduPilot
        // puts the whole pack in cell 0 when it does not measure cells, PX4 each cell).
        let mv: u32 = b
            .voltages
            .iter()
            .filter(|v| **v != u16::MAX)
            .map(|v| *v as u32)
            .sum();
        if mv > 0 {
            self.set("battery_v", mv as f64 / 1000.0);
            self.set("battery_status_v", mv as f64 / 1000.0);
            // Current and voltage from one message: their product is the power drawn.
            if b.current_battery >= 0 {
                self.set("battery_current_a", b.current_battery as f64 / 100.0);
            } else {
                self.values.remove("battery_current_a");
            }
        }
    }

    /// GLOBAL_POSITION_INT on the globe: position, altitude, speed, distance home.
    fn on_global_position(&mut self, p: &GLOBAL_POSITION_INT_DATA) {
        let heading_deg = (p.hdg != u16::MAX).then(|| p.hdg as f64 / 100.0);
        let pos = Position {
            lat_e7: p.lat,
            lon_e7: p.lon,
            alt_rel_m: p.relative_alt as f64 / 1000.0,
            alt_amsl_m: p.alt as f64 / 1000.0,
            heading_deg,
        };
        self.position = Some(pos);
        self.set("lat_deg", p.lat as f64 * 1e-7);
        self.set("lon_deg", p.lon as f64 * 1e-7);
        self.set("altitude_m", pos.alt_rel_m);
        self.set(
            "groundspeed_mps",
            ((p.vx as f64).hypot(p.vy as f64)) / 100.0,
        );
        if let Some((hl, ho, _)) = self.home {
            let (n, e) = offset_m((hl, ho), (p.lat, p.lon));
            self.set("distance_home_m", n.hypot(e));
        }
    }

    /// DISTANCE_SENSOR: a horizontal reading in range, kept per sensor.
    fn on_distance_sensor(&mut self, now: Duration, d: &DISTANCE_SENSOR_DATA) {
        // Horizontal sensors only (yaw rotations 0..7); the downward rangefinder is altitude.
        let horizontal = (d.orientation as u32) <= 7;
        let valid = d.current_distance >= d.min_distance && d.current_distance <= d.max_distance;
        if horizontal && valid {
            self.distances
                .insert(d.id, (d.current_distance as f64 / 100.0, now));
        } else if horizontal {
            self.distances.remove(&d.id);
        }
    }

    /// CAMERA_TRACKING_IMAGE_STATUS: the target tracked, and where in the image.
    fn on_camera_tracking(&mut self, c: &CAMERA_TRACKING_IMAGE_STATUS_DATA) {
        let active = c
            .tracking_status
            .contains(CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE)
            && !c
                .tracking_status
                .contains(CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ERROR);
        self.set("target_detected", if active { 1.0 } else { 0.0 });
        if active && !c.point_x.is_nan() {
            self.set("target_x", c.point_x as f64);
            self.set("target_y", c.point_y as f64);
        }
    }

    /// The events of thresholds crossed by this message: obstacle near, target detected or
    /// lost, battery below a threshold (`before`: obstacle distance, target, battery before it).
    fn crossings(
        &self,
        now: Duration,
        before: (Option<f64>, Option<f64>, Option<f64>),
        events: &mut Vec<Event>,
    ) {
        let (before_obstacle, before_target, before_battery) = before;
        let near = self.cfg.obstacle_near_m;
        match (before_obstacle, self.obstacle_m(now)) {
            (b, Some(a)) if a < near && b.is_none_or(|b| b >= near) => {
                events.push(Event::ObstacleDetected)
            }
            (Some(b), a) if b < near && a.is_none_or(|a| a >= near) => {
                events.push(Event::ObstacleCleared)
            }
            _ => {}
        }
        let th = self.cfg.detection_threshold;
        match (
            before_target.unwrap_or(0.0) > th,
            self.get("target_detected").unwrap_or(0.0) > th,
        ) {
            (false, true) => events.push(Event::TargetDetected),
            (true, false) => events.push(Event::TargetLost),
            _ => {}
        }
        if let (Some(b), Some(a)) = (before_battery, self.get("battery_pct")) {
            for &t in &self.cfg.battery_thresholds_pct {
                if b > t && a <= t {
                    events.push(Event::BatteryBelow(t));
                }
            }
        }
    }

    fn set(&mut self, name: &str, v: f64) {
        self.values.set(name, v);
    }

    /// The pack as the autopilot's parameters describe it (the caller decoded the PARAM_VALUE):
    /// its capacity in mAh (`BATT_CAPACITY`, `BAT1_CAPACITY`; kept as reported, a zero or
    /// negative one means "not configured" and the guarantee falls back on params) or its cell
    /// count (`BAT1_N_CELLS`). An implausible value is refused and counted.
    pub fn on_pack_param(&mut self, what: PackParam, value: f64) {
        let (name, ok) = match what {
            PackParam::CapacityMah => (
                "battery_capacity_mah",
                value.is_finite() && value <= MAX_PACK_CAPACITY_MAH,
            ),
            PackParam::Cells => (
                "battery_cells",
                value.is_finite() && (0.0..=MAX_PACK_CELLS).contains(&value),
            ),
        };
        if ok {
            self.set(name, value);
        } else {
            self.reject(format!("{name} = {value}"));
        }
    }

    /// A mission speed from the autopilot's parameters, in m/s (the caller decoded the
    /// PARAM_VALUE and converted the unit); a value outside 0..100 m/s is refused and counted.
    pub fn on_speed_param(&mut self, what: SpeedParam, mps: f64) {
        let name = what.observation();
        if mps.is_finite() && mps > 0.0 && mps <= MAX_MISSION_SPEED_MPS {
            self.set(name, mps);
        } else {
            self.reject(format!("{name} = {mps}"));
        }
    }

    fn reject(&mut self, what: String) {
        self.rejected.out_of_range += 1;
        self.rejected.last = Some(what);
    }

    /// One NAMED_VALUE_FLOAT: mapped to its observation, checked against its declared range,
    /// and, when unmapped, kept only while the number of such names is under the cap.
    fn on_named_value(&mut self, name: &str, value: f32) {
        let (obs, mapped) = match self.cfg.onboard.get(name) {
            Some(o) => (o.clone(), true),
            None if name.bytes().all(|b| b.is_ascii_graphic()) => {
                (format!("onboard.{name}"), false)
            }
            None => {
                self.rejected.names_dropped += 1;
                return;
            }
        };
        let v = value as f64;
        let in_range = v.is_finite()
            && self
                .cfg
                .ranges
                .get(&obs)
                .is_none_or(|[lo, hi]| (*lo..=*hi).contains(&v));
        if !in_range {
            self.reject(format!("{obs} = {value}"));
            return;
        }
        if !mapped && !self.values.contains_key(&obs) {
            if self.onboard_names >= self.cfg.max_onboard_names {
                self.rejected.names_dropped += 1;
                return;
            }
            self.onboard_names += 1;
        }
        self.set(&obs, v);
    }

    /// Nearest horizontal obstacle from fresh distance sensors and the proximity scan.
    pub fn obstacle_m(&self, now: Duration) -> Option<f64> {
        let max_age = Duration::from_secs_f64(self.cfg.distance_max_age_s);
        let fresh = |t: &Duration| now.saturating_sub(*t) <= max_age;
        self.distances
            .values()
            .filter(|(_, t)| fresh(t))
            .map(|(d, _)| *d)
            .chain(
                self.obstacle_scan
                    .iter()
                    .filter(|(_, t)| fresh(t))
                    .map(|(d, _)| *d),
            )
            .reduce(f64::min)
    }

    /// One snapshot for the decision core.
    pub fn observations(&self, now: Duration, events: Vec<Event>) -> Observations {
        let mut values = self.values.clone();
        values.remove("battery_status_pct");
        values.remove("battery_status_v");
        if let Some(o) = self.obstacle_m(now) {
            values.set("obstacle_m", o);
        }
        values.set("armed", if self.armed { 1.0 } else { 0.0 });
        Observations {
            time_s: now.as_secs_f64(),
            // The mission state is estimated by the fly loop (it knows the route progress).
            state: String::new(),
            values,
            events,
        }
    }

    /// Telemetry worth plotting that is not an observation.
    pub fn vehicle(&self) -> BTreeMap<String, serde_json::Value> {
        let mut v = BTreeMap::new();
        if let Some(m) = &self.mode {
            v.insert("mode".into(), serde_json::Value::from(m.to_string()));
        }
        v.insert("armed".into(), serde_json::Value::from(self.armed));
        if let Some(p) = &self.position {
            v.insert("altitude_m".into(), serde_json::Value::from(p.alt_rel_m));
        }
        if let Some(b) = self.get("battery_pct") {
            v.insert("battery_pct".into(), serde_json::Value::from(b));
        }
        if let Some(s) = &self.landed_state {
            v.insert("landed_state".into(), serde_json::Value::from(s.clone()));
        }
        if let Some(s) = self.mission_seq {
            v.insert("mission_seq".into(), serde_json::Value::from(s));
        }
        v
    }
}

/// A position (degrees * 1e7) on the globe: latitude within ±90°, longitude within ±180°.
pub fn on_globe(lat_e7: i32, lon_e7: i32) -> bool {
    (-900_000_000..=900_000_000).contains(&lat_e7)
        && (-1_800_000_000..=1_800_000_000).contains(&lon_e7)
}

/// Metres north and east from `a` to `b` (equirectangular; fine over a mission's few km).
pub fn offset_m(a: (i32, i32), b: (i32, i32)) -> (f64, f64) {
    const M_PER_DEG: f64 = 111_319.49;
    let lat = a.0 as f64 * 1e-7;
    let n = (b.0 as f64 - a.0 as f64) * 1e-7 * M_PER_DEG;
    let e = (b.1 as f64 - a.1 as f64) * 1e-7 * M_PER_DEG * lat.to_radians().cos();
    (n, e)
}

/// The point `north`, `east` metres from `a`, in degrees * 1e7.
pub fn displace(a: (i32, i32), north_m: f64, east_m: f64) -> (i32, i32) {
    const M_PER_DEG: f64 = 111_319.49;
    let lat = a.0 as f64 * 1e-7;
    let dlat = north_m / M_PER_DEG;
    let dlon = east_m / (M_PER_DEG * lat.to_radians().cos().max(1e-6));
    // Stays on the globe: latitude clamped to the poles, longitude wrapped across ±180°.
    let lat_e7 = (a.0 as f64 + dlat * 1e7).clamp(-900_000_000.0, 900_000_000.0);
    let lon_e7 =
        (a.1 as f64 + dlon * 1e7 + 1_800_000_000.0).rem_euclid(3_600_000_000.0) - 1_800_000_000.0;
    (lat_e7.round() as i32, lon_e7.round() as i32)
}

#[cfg(test)]
mod tests;
