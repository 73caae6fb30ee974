//! Primitive vehicle actions as data: `params/commands.toml` maps `take_off`, `follow_trajectory`,
//! `avoid_obstacle`, `land`, `replan_and_land`, `return_to_base` to MAVLink steps, and
//! `params/missions/*_route.toml` gives the route `follow_trajectory` uploads.
//! `params/link.toml` gives stream rates, onboard monitor names and event thresholds.

use super::dialect::MavCmd;
use super::mission::MissionItem;
use super::modes::{Flavor, FlightMode};
use super::telemetry::{TelemetryConfig, displace};
use companion_core::mission::{ActionCatalogue, ActionKind};
use companion_core::spec::{ParamsFiles, SpecError, check_positive, check_range, read_toml};
use companion_core::vocabulary::ActionId;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// The route `follow_trajectory` uploads: the route TOML read, its mission items per autopilot.
mod route;
mod route_end;
pub use route::{MAX_ALTITUDE_M, MAX_WAYPOINTS, Route, Waypoint};
pub use route_end::{MAX_LOITER_TIME_S, RouteEnd};

/// One step of an action, as written in commands.toml (exactly one key per step).
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStep {
    mode: Option<String>,
    arm: Option<bool>,
    command: Option<String>,
    params: Option<Vec<f32>>,
    upload_mission: Option<bool>,
    reposition: Option<Offset>,
    goto_zone: Option<bool>,
}

/// Metres relative to the vehicle: forward along its heading, to its right, up.
#[derive(Debug, Clone, Copy, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Offset {
    /// Metres ahead along the vehicle's heading.
    #[serde(default)]
    pub forward_m: f64,
    /// Metres to the vehicle's right.
    #[serde(default)]
    pub right_m: f64,
    /// Metres up.
    #[serde(default)]
    pub up_m: f64,
}

/// A step the executor runs.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Switch flight mode (GUIDED, AUTO, LOITER, RTL, LAND, BRAKE, ...).
    Mode(FlightMode),
    /// Arm, once the autopilot reports ready.
    Arm,
    /// A COMMAND_LONG with these seven params.
    Command {
        /// MAV_CMD to send.
        command: MavCmd,
        /// param1..param7 as the command defines them.
        params: [f32; 7],
    },
    /// Upload the route (verified by download).
    UploadMission,
    /// MAV_CMD_DO_REPOSITION to an offset from the vehicle.
    Reposition(Offset),
    /// MAV_CMD_DO_REPOSITION to the zone the landing-zone monitor reported, if any.
    GotoZone,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAction {
    steps: Vec<RawStep>,
    #[serde(default)]
    description: String,
    /// A shell-only entry: the fly shell flies it in place of this action (a resume of an
    /// action already begun); no MDP proposes it.
    #[serde(default)]
    flown_for: Option<String>,
    /// The action commands nothing on the vehicle (`stay_on_ground`): its `steps` must be
    /// empty. Said explicitly so that a forgotten step list is still refused.
    #[serde(default)]
    nothing: bool,
}

/// What the vehicle is asked to fly: an action's own steps, or the shell-only entry of
/// params/commands.toml flown in its place (`flown_for`, the route's resume).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Flown {
    /// The action's own entry.
    Action(ActionId),
    /// The shell-only entry flown in place of the action.
    InPlaceOf(ActionId),
}

impl Flown {
    /// The catalogue action this is flown for.
    pub fn action(self) -> ActionId {
        match self {
            Flown::Action(a) | Flown::InPlaceOf(a) => a,
        }
    }
}

/// params/commands.toml resolved against the action catalogue (params/actions.toml): the steps
/// of each vehicle action by [`ActionId`], and the shell-only entries by the action they are
/// flown for. Names are kept only to write records.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ActionTable {
    /// The catalogue's action names, by id (what a record writes for an action).
    names: Vec<String>,
    /// Each vehicle action's steps, in order.
    steps: BTreeMap<ActionId, Vec<Step>>,
    /// Shell-only entries (`flown_for = "ACTION"`), by the action they are flown for: the
    /// entry's name and its steps.
    flown_for: BTreeMap<ActionId, (String, Vec<Step>)>,
}

fn parse_cmd(name: &str) -> Option<MavCmd> {
    // The generated enum is serde-tagged: {"type": "MAV_CMD_..."}.
    serde_json::from_value(serde_json::json!({ "type": name })).ok()
}

impl ActionTable {
    /// An empty table naming the actions of `catalogue` (entries come with [`ActionTable::insert`]).
    pub fn new(catalogue: &ActionCatalogue) -> Self {
        Self {
            names: catalogue.actions.iter().map(|a| a.id.clone()).collect(),
            ..Self::default()
        }
    }

    /// Give `flown` these steps; a shell-only entry ([`Flown::InPlaceOf`]) is named `name`.
    pub fn insert(&mut self, flown: Flown, name: &str, steps: Vec<Step>) {
        match flown {
            Flown::Action(a) => {
                self.steps.insert(a, steps);
            }
            Flown::InPlaceOf(a) => {
                self.flown_for.insert(a, (name.to_string(), steps));
            }
        }
    }

    /// The steps of `flown`; None when params/commands.toml gives it none.
    pub fn steps(&self, flown: Flown) -> Option<&[Step]> {
        match flown {
            Flown::Action(a) => self.steps.get(&a).map(Vec::as_slice),
            Flown::InPlaceOf(a) => self.flown_for.get(&a).map(|(_, s)| s.as_slice()),
        }
    }

    /// The name a record writes for `flown`: the action's, or the shell-only entry's.
    pub fn name(&self, flown: Flown) -> &str {
        if let Flown::InPlaceOf(a) = flown
            && let Some((name, _)) = self.flown_for.get(&a)
        {
            return name;
        }
        let action = self.names.get(flown.action().index());
        action.map_or("-", String::as_str)
    }

    /// The shell-only entry flown in place of `action`, if params/commands.toml has one.
    pub fn in_place_of(&self, action: ActionId) -> Option<Flown> {
        self.flown_for
            .contains_key(&action)
            .then_some(Flown::InPlaceOf(action))
    }

    /// Every entry's name, sorted (the file's entries as `check` lists them).
    pub fn entry_names(&self) -> Vec<&str> {
        let own = self.steps.keys().map(|&a| self.name(Flown::Action(a)));
        let shell = self.flown_for.values().map(|(n, _)| n.as_str());
        let mut names: Vec<&str> = own.chain(shell).collect();
        names.sort_unstable();
        names
    }

    /// Read and check params/commands.toml at `path`: every entry is a vehicle action of
    /// `catalogue` (params/actions.toml) or a shell-only entry flown for one
    /// (`flown_for = "ACTION"`, at most one per action).
    pub fn load(
        files: &ParamsFiles,
        path: &Path,
        catalogue: &ActionCatalogue,
    ) -> Result<Self, SpecError> {
        let raw: BTreeMap<String, RawAction> = read_toml(files, path)?;
        if raw.is_empty() {
            return Err(SpecError::new(
                path,
                "-",
                "no vehicle actions: the file must map each vehicle action to its steps",
            ));
        }
        let mut entries = BTreeMap::new();
        let mut flown_for = BTreeMap::new();
        for (name, a) in raw {
            let _ = a.description;
            if let Some(f) = &a.flown_for {
                flown_for.insert(name.clone(), f.clone());
            }
            let steps = entry_steps(path, &name, &a)?;
            entries.insert(name, steps);
        }
        let own: Vec<String> = entries
            .keys()
            .filter(|n| !flown_for.contains_key(*n))
            .cloned()
            .collect();
        let mut table = Self::new(catalogue);
        for (name, steps) in entries {
            let Some(of) = flown_for.get(&name) else {
                let id = own_entry(path, &name, catalogue)?;
                table.steps.insert(id, steps);
                continue;
            };
            // Flown for an entry of this file that is a catalogue action's own.
            let Some(id) = catalogue.id(of).filter(|_| own.contains(of)) else {
                return Err(SpecError::new(
                    path,
                    format!("{name}.flown_for"),
                    format!("`{of}` is not an entry of this file that an MDP action maps to"),
                ));
            };
            if let Some((other, _)) = table.flown_for.get(&id) {
                return Err(SpecError::new(
                    path,
                    format!("{name}.flown_for"),
                    format!(
                        "`{other}` is already flown for `{of}`: one shell-only entry per action"
                    ),
                ));
            }
            table.flown_for.insert(id, (name, steps));
        }
        Ok(table)
    }
}

/// The catalogue action an entry without `flown_for` is the steps of: it must be a vehicle
/// action of params/actions.toml.
fn own_entry(path: &Path, name: &str, catalogue: &ActionCatalogue) -> Result<ActionId, SpecError> {
    let Some(id) = catalogue.id(name) else {
        return Err(SpecError::new(
            path,
            name,
            "not an action of params/actions.toml, so no MDP proposes it (a shell-only \
             entry says so with `flown_for = \"ACTION\"`)",
        ));
    };
    if catalogue.by_id(id).kind != ActionKind::Vehicle {
        return Err(SpecError::new(
            path,
            name,
            "an application action (params/actions.toml): it runs on the platform, not \
             as MAVLink steps",
        ));
    }
    Ok(id)
}

/// The steps of entry `name`, checked.
fn entry_steps(path: &Path, name: &str, a: &RawAction) -> Result<Vec<Step>, SpecError> {
    if a.nothing && !a.steps.is_empty() {
        return Err(SpecError::new(
            path,
            format!("{name}.steps"),
            "`nothing = true` commands nothing: its steps must be empty",
        ));
    }
    if a.steps.is_empty() && !a.nothing {
        return Err(SpecError::new(
            path,
            format!("{name}.steps"),
            "an action needs at least one step (or `nothing = true`)",
        ));
    }
    a.steps
        .iter()
        .enumerate()
        .map(|(i, s)| step(path, format!("{name}.steps[{i}]"), s))
        .collect()
}

/// One step of an entry, checked (`entry` names it in errors).
fn step(path: &Path, entry: String, s: &RawStep) -> Result<Step, SpecError> {
    let set = [
        s.mode.is_some(),
        s.arm.is_some(),
        s.command.is_some(),
        s.upload_mission.is_some(),
        s.reposition.is_some(),
        s.goto_zone.is_some(),
    ]
    .iter()
    .filter(|b| **b)
    .count();
    if set != 1 {
        return Err(SpecError::new(
            path,
            entry,
            "a step has exactly one of mode, arm, command, upload_mission, reposition, goto_zone",
        ));
    }
    if s.params.is_some() && s.command.is_none() {
        return Err(SpecError::new(path, entry, "params only go with command"));
    }
    let step = if let Some(m) = &s.mode {
        let Some(mode) = FlightMode::from_name(m) else {
            return Err(SpecError::new(path, entry, format!("unknown mode {m:?}")));
        };
        Step::Mode(mode)
    } else if let Some(arm) = s.arm {
        if !arm {
            return Err(SpecError::new(
                path,
                entry,
                "arm = false is not a step (disarming is the autopilot's job)",
            ));
        }
        Step::Arm
    } else if let Some(c) = &s.command {
        let command = parse_cmd(c).ok_or_else(|| {
            SpecError::new(path, &entry, format!("unknown MAVLink command {c:?}"))
        })?;
        let p = s.params.clone().unwrap_or_default();
        if p.len() > 7 {
            return Err(SpecError::new(
                path,
                entry,
                format!("{} params; a command has at most 7", p.len()),
            ));
        }
        if p.iter().any(|v| !v.is_finite()) {
            return Err(SpecError::new(path, entry, "params must be finite numbers"));
        }
        let mut params = [0.0f32; 7];
        params[..p.len()].copy_from_slice(&p);
        Step::Command { command, params }
    } else if s.upload_mission == Some(true) {
        Step::UploadMission
    } else if let Some(o) = s.reposition {
        if ![o.forward_m, o.right_m, o.up_m]
            .iter()
            .all(|v| v.is_finite())
        {
            return Err(SpecError::new(path, entry, "offsets must be finite"));
        }
        Step::Reposition(o)
    } else if s.goto_zone == Some(true) {
        Step::GotoZone
    } else {
        return Err(SpecError::new(
            path,
            entry,
            "upload_mission / goto_zone must be true",
        ));
    };
    Ok(step)
}

/// `params/link.toml`: stream rates and telemetry settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkParams {
    /// Message name -> rate in Hz, requested with MAV_CMD_SET_MESSAGE_INTERVAL.
    pub streams: BTreeMap<String, f32>,
    /// Streams of `[streams]` an autopilot does not have, by flavour: never requested from it
    /// (`[streams_not_sent_by]`; ArduPilot answers each such request with a STATUSTEXT to the
    /// ground station).
    #[serde(default)]
    pub streams_not_sent_by: StreamsNotSentBy,
    /// Telemetry settings (`[telemetry]`).
    pub telemetry: TelemetryConfig,
    /// Seconds between decision cycles when nothing significant happens.
    pub decision_period_s: f64,
    /// Seconds to wait for the autopilot to report ready before an arm step fails.
    pub arm_wait_s: f64,
    /// Arm attempts, each only after a fresh ready report.
    pub max_arm_attempts: u32,
    /// The autopilot flies one vehicle action at a time: when a plan holds several, the first
    /// listed here is commanded (see link::mission_state::select_vehicle_action).
    #[serde(default)]
    pub vehicle_action_precedence: Vec<String>,
    /// The flight as the shell runs it: cycle rate limit, end-of-flight rule, landing at a
    /// zone, STATUSTEXT limits (`[flight]`, defaults when absent).
    #[serde(default)]
    pub flight: FlightParams,
    /// Values a ground station plots (`[ground_values]`; off when absent).
    #[serde(default)]
    pub ground_values: crate::ground_values::GroundValuesParams,
}

/// `params/link.toml` `[streams_not_sent_by]`: message names of `[streams]` per autopilot
/// flavour that it does not send, so they are not requested from it.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StreamsNotSentBy {
    /// Not requested from ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
    pub ardupilot: Vec<String>,
    /// Not requested from PX4 (MAV_AUTOPILOT_PX4).
    pub px4: Vec<String>,
}

/// `params/link.toml` `[flight]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlightParams {
    /// Least time between two decision cycles that events trigger (s); events in between are
    /// coalesced into the next allowed cycle.
    pub min_event_cycle_interval_s: f64,
    /// The vehicle must report itself on the ground and disarmed this long (s), over at least
    /// two cycles, before the flight counts as over.
    pub landed_confirm_s: f64,
    /// Without EXTENDED_SYS_STATE: disarmed and below this altitude above home (m) is on the
    /// ground.
    pub ground_altitude_m: f64,
    /// "Land at the zone": within this distance (m) of the zone before LAND.
    pub zone_radius_m: f64,
    /// Time allowed to reach the zone (s); then the vehicle lands where it is.
    pub zone_arrive_timeout_s: f64,
    /// The same STATUSTEXT is not sent again within this long (s); "ready, waiting for the
    /// operator" repeats at this interval.
    pub statustext_repeat_s: f64,
    /// At most this many STATUSTEXTs per second.
    pub statustext_max_per_s: u32,
    /// PX4: an accepted SET_MODE counts only once a HEARTBEAT shows the mode within this long (s).
    pub mode_confirm_s: f64,
    /// PX4: SET_MODE sent at most this many times while the vehicle stays in its earlier mode.
    pub max_mode_attempts: u32,
    /// A start by GUIDED (or by arming, with `--start-on-arm`), a takeover and a hand-back count
    /// only when every autopilot heartbeat over this long (s) agrees.
    pub operator_confirm_s: f64,
    /// A command addressed to the companion that waited longer than this (s) is refused with a
    /// COMMAND_ACK, never run late.
    pub command_max_age_s: f64,
    /// What the vehicle is told to do when the companion stops while it commands an armed
    /// vehicle (SIGINT, SIGTERM, a fatal error): `none`, `hold`, `rtl` or `land`.
    pub handoff: Handoff,
    /// Started next to an armed vehicle in the air: hand off at once, or resume its own flight
    /// on the operator's consent (crate::restart_in_air).
    pub restart_in_air: crate::restart_in_air::RestartInAir,
}

/// The hand-off when the companion stops in flight (params/link.toml `[flight] handoff`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Handoff {
    /// Tell the ground station only; the vehicle goes on with what it was doing.
    None,
    /// Hold position (LOITER) where it is.
    Hold,
    /// Return to launch and land there (the autopilot's own RTL).
    Rtl,
    /// Land where it is.
    Land,
}

impl Handoff {
    /// The flight mode the hand-off sets, if any.
    pub fn mode(self) -> Option<FlightMode> {
        match self {
            Handoff::None => None,
            Handoff::Hold => Some(FlightMode::Loiter),
            Handoff::Rtl => Some(FlightMode::Rtl),
            Handoff::Land => Some(FlightMode::Land),
        }
    }

    /// What the vehicle will do, for the pilot.
    pub fn pilot_words(self) -> &'static str {
        match self {
            Handoff::None => "vehicle continues",
            Handoff::Hold => "holding",
            Handoff::Rtl => "RTL",
            Handoff::Land => "landing",
        }
    }
}

impl Default for FlightParams {
    fn default() -> Self {
        Self {
            min_event_cycle_interval_s: 0.2,
            landed_confirm_s: 3.0,
            ground_altitude_m: 1.0,
            zone_radius_m: 3.0,
            zone_arrive_timeout_s: 60.0,
            statustext_repeat_s: 15.0,
            statustext_max_per_s: 2,
            mode_confirm_s: 3.0,
            max_mode_attempts: 3,
            operator_confirm_s: 2.0,
            command_max_age_s: 2.0,
            handoff: Handoff::Rtl,
            restart_in_air: Default::default(),
        }
    }
}

impl FlightParams {
    /// Every number finite and in range, against `decision_period_s`.
    fn check(&self, path: &Path, decision_period_s: f64) -> Result<(), SpecError> {
        let within = |v: f64, lo: f64, hi: f64| v.is_finite() && v > lo && v <= hi;
        let checks: [(&str, bool, String); 11] = [
            (
                "flight.min_event_cycle_interval_s",
                within(self.min_event_cycle_interval_s, 0.0, decision_period_s),
                format!("must be in (0, decision_period_s = {decision_period_s}] s"),
            ),
            (
                "flight.landed_confirm_s",
                within(self.landed_confirm_s, 0.0, 600.0),
                "must be in (0, 600] s".into(),
            ),
            (
                "flight.ground_altitude_m",
                within(self.ground_altitude_m, 0.0, 50.0),
                "must be in (0, 50] m".into(),
            ),
            (
                "flight.zone_radius_m",
                within(self.zone_radius_m, 0.0, 1000.0),
                "must be in (0, 1000] m".into(),
            ),
            (
                "flight.zone_arrive_timeout_s",
                within(self.zone_arrive_timeout_s, 0.0, 3600.0),
                "must be in (0, 3600] s".into(),
            ),
            (
                "flight.statustext_repeat_s",
                within(self.statustext_repeat_s, 0.0, 3600.0),
                "must be in (0, 3600] s".into(),
            ),
            (
                "flight.statustext_max_per_s",
                (1..=20).contains(&self.statustext_max_per_s),
                "must be 1..20".into(),
            ),
            (
                "flight.mode_confirm_s",
                within(self.mode_confirm_s, 0.0, 60.0),
                "must be in (0, 60] s".into(),
            ),
            (
                "flight.max_mode_attempts",
                (1..=10).contains(&self.max_mode_attempts),
                "must be 1..10".into(),
            ),
            (
                "flight.operator_confirm_s",
                within(self.operator_confirm_s, 0.0, 30.0),
                "must be in (0, 30] s".into(),
            ),
            (
                "flight.command_max_age_s",
                within(self.command_max_age_s, 0.0, 60.0),
                "must be in (0, 60] s".into(),
            ),
        ];
        for (entry, ok, why) in checks {
            if !ok {
                return Err(SpecError::new(path, entry, why));
            }
        }
        Ok(())
    }
}

/// Slowest stream rate a params file may ask for: one message per 10 s. The slowest stream the
/// link needs is HOME_POSITION at 0.2 Hz; anything slower is older than every freshness limit
/// the decisions use (the link timeout, `distance_max_age_s`), and a rate like `1e-40` Hz
/// becomes a message interval no autopilot can hold (MAV_CMD_SET_MESSAGE_INTERVAL takes
/// microseconds as a float).
pub const MIN_STREAM_HZ: f32 = 0.1;
/// Fastest stream rate a params file may ask for.
pub const MAX_STREAM_HZ: f32 = 100.0;

impl LinkParams {
    /// Read and check params/link.toml at `path`.
    pub fn load(files: &ParamsFiles, path: &Path) -> Result<Self, SpecError> {
        let p: LinkParams = read_toml(files, path)?;
        for (name, hz) in &p.streams {
            if <super::Msg as mavlink::Message>::message_id_from_name(name).is_none() {
                return Err(SpecError::new(
                    path,
                    format!("streams.{name}"),
                    "unknown MAVLink message name",
                ));
            }
            if !(hz.is_finite() && *hz >= MIN_STREAM_HZ && *hz <= MAX_STREAM_HZ) {
                return Err(SpecError::new(
                    path,
                    format!("streams.{name}"),
                    format!(
                        "rate {hz} Hz is out of range: must be in [{MIN_STREAM_HZ}, {MAX_STREAM_HZ}] Hz \
                         (slower than one message per 10 s is no stream: docs/params.md)"
                    ),
                ));
            }
        }
        // Durations become `Duration`s and timers: bounded so none can overflow or spin.
        check_range(
            path,
            "decision_period_s",
            p.decision_period_s,
            0.01,
            3600.0,
            " s",
        )?;
        check_positive(path, "arm_wait_s", p.arm_wait_s, 3600.0, " s")?;
        if !(1..=100).contains(&p.max_arm_attempts) {
            return Err(SpecError::new(
                path,
                "max_arm_attempts",
                format!("{} is out of range: must be in 1..=100", p.max_arm_attempts),
            ));
        }
        p.flight.check(path, p.decision_period_s)?;
        p.ground_values.check(path)?;
        for (flavour, names) in [
            ("ardupilot", &p.streams_not_sent_by.ardupilot),
            ("px4", &p.streams_not_sent_by.px4),
        ] {
            // A name not in [streams] is a typo that would leave the stream requested.
            if let Some(n) = names.iter().find(|n| !p.streams.contains_key(n.as_str())) {
                return Err(SpecError::new(
                    path,
                    format!("streams_not_sent_by.{flavour}"),
                    format!("{n} is not a stream of [streams]"),
                ));
            }
        }
        let t = &p.telemetry;
        if let Err((entry, reason)) = t.check_trust() {
            return Err(SpecError::new(path, entry, reason));
        }
        check_positive(
            path,
            "telemetry.obstacle_near_m",
            t.obstacle_near_m,
            1000.0,
            " m",
        )?;
        check_positive(
            path,
            "telemetry.distance_max_age_s",
            t.distance_max_age_s,
            3600.0,
            " s",
        )?;
        check_range(
            path,
            "telemetry.detection_threshold",
            t.detection_threshold,
            0.0,
            1.0,
            "",
        )?;
        if t.battery_thresholds_pct
            .iter()
            .any(|v| !(0.0..=100.0).contains(v))
        {
            return Err(SpecError::new(
                path,
                "telemetry.battery_thresholds_pct",
                "percentages must be in 0..100",
            ));
        }
        Ok(p)
    }

    /// (message id, rate Hz) in a stable order.
    pub fn stream_ids(&self) -> Vec<(u32, f32)> {
        self.streams
            .iter()
            .filter_map(|(n, hz)| {
                <super::Msg as mavlink::Message>::message_id_from_name(n).map(|id| (id, *hz))
            })
            .collect()
    }

    /// (flavour, message id) of each stream that autopilot flavour does not send.
    pub fn streams_not_sent(&self) -> Vec<(Flavor, u32)> {
        let ids = |names: &[String]| -> Vec<u32> {
            names
                .iter()
                .filter_map(|n| <super::Msg as mavlink::Message>::message_id_from_name(n))
                .collect()
        };
        let n = &self.streams_not_sent_by;
        let ap = ids(&n.ardupilot)
            .into_iter()
            .map(|id| (Flavor::ArduPilot, id));
        let px4 = ids(&n.px4).into_iter().map(|id| (Flavor::Px4, id));
        ap.chain(px4).collect()
    }
}

#[cfg(test)]
mod tests;
