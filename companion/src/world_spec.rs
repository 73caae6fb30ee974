//! The simulated world's params: params/world.toml (the truth the world holds) and the scenario
//! files of params/scenarios/ (its hazards), read and checked with the rest of the params;
//! `crate::sim` runs them.

use companion_core::mission::MissionStates;
use companion_core::spec::{ParamsFiles, SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The observations the world itself computes (`computes`, in [`World::observe`]) and the ones it
/// reads from its baseline and hazards (`reads`, besides `truth.contexts`): the world's side of
/// the observation vocabulary checked at load (companion/src/vocabulary.rs).
pub const WORLD_OBSERVATIONS: [(&str, &str); 15] = [
    ("battery_pct", "computes"),
    ("cpu_load", "computes"),
    ("free_tiles", "computes"),
    ("target_detected", "computes"),
    ("zone_t_found", "computes"),
    ("zone_found", "computes"),
    ("avoidance_wp", "computes"),
    ("zone_t_lost", "computes"),
    ("waypoints_remaining", "computes"),
    (companion_core::evidence::ROUTE_ACTIVITY, "computes"),
    ("obstacle_m", "reads"),
    ("external_cpu_load", "reads"),
    ("failed_tiles", "reads"),
    ("wind_mps", "reads"),
    ("extra_power_w", "reads"),
];

/// params/world.toml.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSpec {
    pub step_s: f64,
    pub initial_state: String,
    /// Reconfigurable tiles on the board (params/platform.toml says 4).
    pub tiles: u32,
    /// The application whose variants the resource BN assesses; the monitors report the
    /// occupancy of the others (see `advance`).
    pub assessed_app: String,
    pub route: Route,
    pub vehicle: Vehicle,
    pub baseline: BTreeMap<String, f64>,
    pub truth: Truth,
    /// The mission's states and phases (params/mission.toml), which the world moves through.
    #[serde(skip)]
    pub states: MissionStates,
    /// The kinds of the derived plan's activities, in flight order: the world reports
    /// `route_activity` on them (`crate::sim_plan`); empty for the typed plan.
    #[serde(skip)]
    pub plan: Vec<companion_core::route_plan::ActivityKind>,
    /// The observation vocabulary compiled at load (`Params::load`): the world writes its
    /// snapshots by its slots. Empty (every name in the snapshot's overflow) until set.
    #[serde(skip, default = "companion_core::named_slots::no_names")]
    pub vocabulary: companion_core::named_slots::SortedNames,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Route {
    pub waypoints: u32,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vehicle {
    pub battery_wh: f64,
    pub hover_w: f64,
    pub wind_w_per_mps2: f64,
    pub climb_factor: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    pub p_leg: f64,
    pub p_detect: f64,
    pub p_zone_t: f64,
    pub p_zone: f64,
    pub obstacle_grace_steps: u32,
    /// An obstacle closer than this (m) must be avoided.
    pub obstacle_near_m: f64,
    /// context -> version -> probability that one tracking step keeps the target.
    pub qos: BTreeMap<String, BTreeMap<String, f64>>,
    pub contexts: BTreeMap<String, ContextRule>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContextRule {
    pub observation: String,
    pub above: Option<f64>,
    pub below: Option<f64>,
}

impl ContextRule {
    pub(crate) fn holds(&self, obs: &BTreeMap<String, f64>) -> bool {
        let Some(&v) = obs.get(&self.observation) else {
            return false;
        };
        self.above.is_some_and(|a| v > a) || self.below.is_some_and(|b| v < b)
    }
}

/// One scenario file in params/scenarios/.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    pub description: String,
    #[serde(default)]
    pub paper: String,
    #[serde(default = "default_steps")]
    pub steps: u32,
    #[serde(default, rename = "hazard")]
    pub hazards: Vec<Hazard>,
}

fn default_steps() -> u32 {
    100
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hazard {
    /// Shown in the Events column when the hazard starts.
    pub event: String,
    pub trigger: Trigger,
    /// Observations overridden while the hazard is in force.
    pub set: BTreeMap<String, f64>,
    /// Steps the hazard lasts; absent: until the end. An avoided obstacle ends early.
    pub duration: Option<u32>,
}

impl Hazard {
    /// The event said when the hazard starts: the world's own happening when the scenario names
    /// one (`obstacle detected`, `target lost`, ...), else the scenario's words as they are.
    pub fn started(&self) -> companion_core::record::Event {
        use companion_core::record::Event::*;
        let world = [
            TargetDetected,
            TargetLost,
            ObstacleDetected,
            ObstacleCleared,
            ObstacleAvoided,
            Collision,
            TZoneFound,
            EmergencyZoneFound,
            Landing,
            BatteryExhausted,
        ];
        world
            .into_iter()
            .find(|e| *e == self.event.as_str())
            .unwrap_or_else(|| Other(self.event.clone()))
    }
}

/// When a hazard starts: at an absolute step, or `after` steps into a mission phase.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Trigger {
    pub step: Option<u32>,
    pub phase: Option<String>,
    #[serde(default)]
    pub after: u32,
}

impl WorldSpec {
    pub fn load(files: &ParamsFiles) -> Result<Self, SpecError> {
        let file = files.dir().join("world.toml");
        let mut w: WorldSpec = read_toml(files, &file)?;
        w.states = MissionStates::load(files)?;
        if !w.states.has_state(&w.initial_state) {
            return Err(SpecError::new(
                &file,
                "initial_state",
                format!(
                    "`{}` is not a state of params/mission.toml",
                    w.initial_state
                ),
            ));
        }
        let prob = |entry: &str, p: f64| {
            if (0.0..=1.0).contains(&p) {
                Ok(())
            } else {
                Err(SpecError::new(
                    &file,
                    entry,
                    format!("{p} is not a probability"),
                ))
            }
        };
        prob("truth.p_leg", w.truth.p_leg)?;
        prob("truth.p_detect", w.truth.p_detect)?;
        prob("truth.p_zone_t", w.truth.p_zone_t)?;
        prob("truth.p_zone", w.truth.p_zone)?;
        for (ctx, table) in &w.truth.qos {
            for (v, p) in table {
                prob(&format!("truth.qos.{ctx}.{v}"), *p)?;
            }
        }
        for ctx in w.truth.contexts.keys() {
            if !w.truth.qos.contains_key(ctx) {
                return Err(SpecError::new(
                    &file,
                    format!("truth.contexts.{ctx}"),
                    "context has no truth.qos table",
                ));
            }
        }
        if !w.truth.qos.contains_key("nominal") {
            return Err(SpecError::new(
                &file,
                "truth.qos",
                "missing the `nominal` table",
            ));
        }
        if w.vehicle.battery_wh <= 0.0 || w.step_s <= 0.0 {
            return Err(SpecError::new(
                &file,
                "vehicle.battery_wh",
                "must be positive (and step_s too)",
            ));
        }
        Ok(w)
    }
}

impl Scenario {
    /// `name_or_path`: a scenario name in params/scenarios/ or a path to a TOML file.
    /// A scenario given by path is read from disk when the params set does not hold it.
    pub fn load(files: &ParamsFiles, name_or_path: &str) -> Result<Self, SpecError> {
        let file = resolve(files.dir(), "scenarios", name_or_path);
        let s: Scenario = if files.contains(&file) {
            read_toml(files, &file)?
        } else {
            let mut one = ParamsFiles::new(files.dir());
            crate::params_files::add_file(&mut one, &file);
            read_toml(&one, &file)?
        };
        // Every step's record is kept for the run's log: bounded as `simulate --steps` is.
        if !(1..=10_000).contains(&s.steps) {
            return Err(SpecError::new(
                &file,
                "steps",
                format!("{} is out of range: must be in 1..=10000", s.steps),
            ));
        }
        for (i, h) in s.hazards.iter().enumerate() {
            if h.trigger.step.is_none() == h.trigger.phase.is_none() {
                return Err(SpecError::new(
                    &file,
                    format!("hazard[{i}].trigger"),
                    "give exactly one of `step` or `phase`",
                ));
            }
            if h.set.is_empty() {
                return Err(SpecError::new(
                    &file,
                    format!("hazard[{i}].set"),
                    "sets no observation",
                ));
            }
        }
        // Phase triggers name the mission's declared phases (params/mission.toml).
        if s.hazards.iter().any(|h| h.trigger.phase.is_some()) {
            let states = MissionStates::load(files)?;
            for (i, h) in s.hazards.iter().enumerate() {
                if let Some(p) = &h.trigger.phase
                    && !states.has_phase(p)
                {
                    return Err(SpecError::new(
                        &file,
                        format!("hazard[{i}].trigger.phase"),
                        format!(
                            "`{p}` is not a phase of params/mission.toml ({})",
                            states.phases().join(", ")
                        ),
                    ));
                }
            }
        }
        Ok(s)
    }

    /// The scenario names shipped in params/scenarios/, sorted.
    pub fn names(params: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(params.join("scenarios"))
            .into_iter()
            .flatten()
            .flatten()
            .filter_map(|e| {
                let p = e.path();
                (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(str::to_owned))?
            })
            .collect();
        v.sort();
        v
    }
}

/// A name in `params/<dir>/NAME.toml`, or a path when it contains a separator or ends in .toml.
pub fn resolve(params: &Path, dir: &str, name_or_path: &str) -> PathBuf {
    if name_or_path.contains('/') || name_or_path.ends_with(".toml") {
        PathBuf::from(name_or_path)
    } else {
        params.join(dir).join(format!("{name_or_path}.toml"))
    }
}
