//! The `guarantee` stage: PANORAMA performance guarantee (energy, duration) over a mission.
//!
//! Loads a mission (`params/missions/NAME.toml`: activities, tasks and their TIOs, core-oriented
//! constraints, end-oriented goals in the user's order, and the energy/duration model), builds
//! every implementation alternative with its estimated cost, runs the paper's allocation
//! ([`Guarantee::pre_flight`], RAS0), and in flight ([`Guarantee::watch`]) computes margins and
//! drift, and re-allocates the remaining activities when a margin turns negative or a resource
//! fails. When no allocation remains it says so (`infeasible`), it never hides it.
//!
//! Pure apart from [`load_mission`] (which reads the file): no clock, time comes in [`Progress`].

use crate::record::{GuaranteeRecord, Reallocation};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use panorama::{
    Activity, CoreConstraint, Goal, Ia, Infeasible, MarginReport, Measured, Problem, Selection,
    Task, Tio,
};
use serde::Deserialize;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Indicator names the cost model produces; goals may name only these.
pub const ENERGY: &str = "energy_j";
pub const DURATION: &str = "duration_s";

// ---------------------------------------------------------------- file format

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MissionFile {
    mission: MissionHeader,
    goals: BTreeMap<String, GoalFile>,
    #[serde(default)]
    battery: Option<BatteryFile>,
    propulsion: Propulsion,
    /// Always-on electronics (W).
    #[serde(default)]
    base: ResourceFile,
    #[serde(default)]
    resources: BTreeMap<String, ResourceFile>,
    #[serde(default)]
    compute: Option<ComputeFile>,
    tasks: BTreeMap<String, TaskFile>,
    #[serde(default)]
    constraints: BTreeMap<String, ConstraintClass>,
    activities: Vec<ActivityFile>,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MissionHeader {
    name: String,
    #[serde(default)]
    description: String,
    #[serde(default)]
    source: String,
    goal_order: Vec<String>,
    /// `most_capable` or `highest_cost`.
    selection: String,
    #[serde(default)]
    selection_goal: Option<String>,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct GoalFile {
    /// Explicit bound; for `energy_j` it may instead come from `[battery]`.
    #[serde(default)]
    bound: Option<f64>,
    #[serde(default)]
    from_battery: bool,
    #[serde(default)]
    source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct BatteryFile {
    capacity_wh: f64,
    usable_fraction: f64,
    reserve_wh: f64,
    #[serde(default)]
    source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
enum Propulsion {
    /// `P(v) = sum_i c_i v^i` (W), e.g. a ground robot's motion power fitted on measurements.
    Polynomial {
        coefficients_w: Vec<f64>,
        #[serde(default)]
        source: String,
    },
    /// Rotary-wing power (Zeng, Xu, Zhang 2019, eq. 12): blade profile + induced + parasitic.
    /// `P(v) = P0 (1 + 3 v²/U²) + Pi sqrt(sqrt(1 + v⁴/(4 v0⁴)) - v²/(2 v0²)) + ½ ρ CdA v³`.
    RotaryWing {
        blade_profile_w: f64,
        induced_hover_w: f64,
        induced_velocity_mps: f64,
        tip_speed_mps: f64,
        drag_area_m2: f64,
        air_density_kgm3: f64,
        #[serde(default)]
        source: String,
    },
}

impl Propulsion {
    fn power(&self, v: f64) -> f64 {
        match self {
            Propulsion::Polynomial { coefficients_w, .. } => {
                coefficients_w.iter().rev().fold(0.0, |acc, c| acc * v + c)
            }
            Propulsion::RotaryWing {
                blade_profile_w: p0,
                induced_hover_w: pi,
                induced_velocity_mps: v0,
                tip_speed_mps: u,
                drag_area_m2: cda,
                air_density_kgm3: rho,
                ..
            } => {
                let r = v * v / (v0 * v0);
                let induced = ((1.0 + r * r / 4.0).sqrt() - r / 2.0).max(0.0).sqrt();
                p0 * (1.0 + 3.0 * v * v / (u * u)) + pi * induced + 0.5 * rho * cda * v * v * v
            }
        }
    }
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ResourceFile {
    power_w: f64,
    #[serde(default)]
    source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ComputeFile {
    /// Watts per fully loaded core.
    cpu_w_per_core: f64,
    /// Watts per active FPGA tile.
    tile_w: f64,
    cores: f64,
    tile_names: Vec<String>,
    #[serde(default)]
    source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TaskFile {
    tios: Vec<TioFile>,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct TioFile {
    name: String,
    #[serde(default)]
    resources: Vec<String>,
    #[serde(default)]
    capability: f64,
    /// Speed cap this TIO imposes (sensor range, frame stability).
    #[serde(default)]
    v_max_mps: Option<f64>,
    /// Fixed time this TIO adds to the activity (e.g. a search's dwell).
    #[serde(default)]
    time_s: f64,
    /// Cores' worth of CPU load while active.
    #[serde(default)]
    cpu_load: f64,
    /// FPGA tiles occupied while active.
    #[serde(default)]
    tiles: u32,
    /// Variant catalogue reference (app/version/implementation): loaded from a params directory,
    /// `tiles` and `cpu_load` must be that variant's (params/variants.toml is the one Table 2).
    #[serde(default)]
    variant: Option<String>,
    #[serde(default)]
    description: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConstraintClass {
    #[serde(default)]
    rules: Vec<CoreConstraint>,
    #[serde(default)]
    description: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ActivityFile {
    name: String,
    #[serde(default)]
    objective: String,
    #[serde(default)]
    env: String,
    tasks: Vec<String>,
    #[serde(default)]
    length_m: f64,
    #[serde(default)]
    v_max_mps: Option<f64>,
    /// Fixed time spent in the activity besides moving (turn, detection, climb, tracking hold).
    #[serde(default)]
    hold_s: f64,
    /// Propulsion speed during the hold (0: stationary / hover).
    #[serde(default)]
    hold_speed_mps: f64,
    #[serde(default)]
    constraints: Vec<String>,
    #[serde(default)]
    x_start_m: Option<f64>,
    #[serde(default)]
    x_end_m: Option<f64>,
}

// ---------------------------------------------------------------- compiled mission

/// One activity as flown: its tasks and, per IA (same order as in [`MissionSpec::problem`]),
/// the TIO names and the speed the estimate assumes.
#[derive(Debug, Clone, PartialEq)]
pub struct ActivityInfo {
    pub name: String,
    pub objective: String,
    pub env: String,
    pub tasks: Vec<String>,
    pub constraints: Vec<String>,
    /// Per IA: TIO name per task.
    pub ia_tios: Vec<Vec<String>>,
    /// Per IA: speed used for the estimate (m/s), `None` when the activity does not move.
    pub ia_speed: Vec<Option<f64>>,
    /// IA count before the core-oriented constraints (the objective's n_IA in Table 5).
    pub n_ia_unconstrained: usize,
}

/// A loaded, validated mission: the generic problem plus what the text and JSON views need.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionSpec {
    pub name: String,
    pub file: PathBuf,
    pub description: String,
    pub problem: Problem,
    pub selection: Selection,
    pub activities: Vec<ActivityInfo>,
    /// Usable battery energy (J) before the reserve, when a `[battery]` is given: turns a
    /// remaining-percentage reading into consumed joules.
    pub battery_capacity_j: Option<f64>,
    /// Tile names of the platform (a failure of one reduces the tiles available).
    pub tile_names: Vec<String>,
}

/// Resolve `--mission`: a path the params set holds (the shell adds a mission file given by
/// path), else `params/missions/NAME.toml`.
pub fn mission_path(params: &ParamsFiles, mission: &str) -> PathBuf {
    let p = Path::new(mission);
    if params.contains(p) {
        return p.to_path_buf();
    }
    params
        .dir()
        .join("missions")
        .join(format!("{mission}.toml"))
}

/// Load and validate a mission by name or path.
pub fn load_mission(params: &ParamsFiles, mission: &str) -> Result<MissionSpec, SpecError> {
    let params_dir = params.dir();
    let path = mission_path(params, mission);
    let file: MissionFile = read_toml(params, &path)?;
    let platform =
        crate::resources::load_platform(params, &params_dir.join(crate::resources::PLATFORM_FILE))?;
    let catalogue = crate::resources::load_variants(
        params,
        &params_dir.join(crate::resources::VARIANTS_FILE),
        &platform,
    )?;
    check_against_catalogue(&path, &file, &catalogue)?;
    compile(&path, file)
}

/// Every TIO naming a `variant` (`app/version/implementation`) must occupy what
/// params/variants.toml says: its tiles, and as `cpu_load` its SW milliseconds per frame / 1000
/// (cores' worth at one frame per second).
fn check_against_catalogue(
    path: &Path,
    f: &MissionFile,
    catalogue: &fpga_model::Catalogue,
) -> Result<(), SpecError> {
    for (task, t) in &f.tasks {
        for (i, tio) in t.tios.iter().enumerate() {
            let Some(v) = &tio.variant else { continue };
            let entry = format!("tasks.{task}.tios[{i}]");
            // `app/version/implementation`, or `app/version` for a version with one implementation.
            let mut parts = v.splitn(3, '/');
            let (Some(app), Some(version), imp) = (parts.next(), parts.next(), parts.next()) else {
                return Err(SpecError::new(
                    path,
                    format!("{entry}.variant"),
                    format!("`{v}` is not app/version[/implementation]"),
                ));
            };
            let impls = catalogue.implementations(app, version);
            let found = match imp {
                Some(imp) => impls
                    .into_iter()
                    .find(|x| x.implementation.to_string() == imp),
                None if impls.len() == 1 => impls.into_iter().next(),
                None => None,
            };
            let Some(x) = found else {
                return Err(SpecError::new(
                    path,
                    format!("{entry}.variant"),
                    format!("no single variant `{v}` in params/variants.toml"),
                ));
            };
            if tio.tiles != u32::from(x.tiles) {
                return Err(SpecError::new(
                    path,
                    format!("{entry}.tiles"),
                    format!(
                        "{} tiles, params/variants.toml gives {v} {} tiles",
                        tio.tiles, x.tiles
                    ),
                ));
            }
            let cpu = x.sw_ms() / 1000.0;
            if (tio.cpu_load - cpu).abs() > 1e-9 {
                return Err(SpecError::new(
                    path,
                    format!("{entry}.cpu_load"),
                    format!(
                        "{}, params/variants.toml gives {v} {} ms of SW per frame ({cpu})",
                        tio.cpu_load,
                        x.sw_ms()
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Parse a mission from TOML text (`path` only names it in errors).
pub fn parse_mission(path: &Path, text: &str) -> Result<MissionSpec, SpecError> {
    let file: MissionFile =
        toml::from_str(text).map_err(|e| SpecError::new(path, "-", e.message().to_string()))?;
    compile(path, file)
}

fn tile_slot(k: usize) -> String {
    format!("tile_slot:{k}")
}

fn compile(path: &Path, f: MissionFile) -> Result<MissionSpec, SpecError> {
    let err = |entry: String, reason: String| SpecError::new(path, entry, reason);
    let finite_nonneg = |entry: String, x: f64, what: &str| {
        if !x.is_finite() || x < 0.0 {
            Err(err(
                entry,
                format!("{what} must be a finite non-negative number, got {x}"),
            ))
        } else {
            Ok(())
        }
    };

    // Goals, in the user's order.
    if f.mission.goal_order.is_empty() {
        return Err(err(
            "mission.goal_order".into(),
            "at least one end-oriented goal is required".into(),
        ));
    }
    let mut goals = Vec::new();
    let mut seen = BTreeSet::new();
    for (k, name) in f.mission.goal_order.iter().enumerate() {
        let entry = format!("mission.goal_order[{k}]");
        let g = f.goals.get(name).ok_or_else(|| {
            err(
                entry.clone(),
                format!(
                    "unknown goal `{name}` (defined: {})",
                    f.goals.keys().cloned().collect::<Vec<_>>().join(", ")
                ),
            )
        })?;
        if !seen.insert(name.clone()) {
            return Err(err(entry, format!("goal `{name}` listed twice")));
        }
        if name != ENERGY && name != DURATION {
            return Err(err(
                format!("goals.{name}"),
                format!("no model for indicator `{name}` (known: {ENERGY}, {DURATION})"),
            ));
        }
        let bound = match (g.bound, g.from_battery, &f.battery) {
            (Some(b), false, _) => b,
            (None, true, Some(b)) if name == ENERGY => {
                for (k, x) in [("capacity_wh", b.capacity_wh), ("reserve_wh", b.reserve_wh)] {
                    finite_nonneg(format!("battery.{k}"), x, "energy")?;
                }
                if !(0.0..=1.0).contains(&b.usable_fraction) {
                    return Err(err(
                        "battery.usable_fraction".into(),
                        "must be within [0, 1]".into(),
                    ));
                }
                (b.capacity_wh * b.usable_fraction - b.reserve_wh) * 3600.0
            }
            (None, true, None) => {
                return Err(err(
                    format!("goals.{name}.from_battery"),
                    "no [battery] table".into(),
                ));
            }
            _ => {
                return Err(err(
                    format!("goals.{name}"),
                    "give exactly one of `bound` or `from_battery = true` (energy only)".into(),
                ));
            }
        };
        finite_nonneg(
            format!("goals.{name}.bound"),
            bound,
            "goal bound (negative energy or time)",
        )?;
        goals.push(Goal {
            name: name.clone(),
            bound,
        });
    }
    for name in f.goals.keys() {
        if !seen.contains(name) {
            return Err(err(
                format!("goals.{name}"),
                "goal not listed in mission.goal_order".into(),
            ));
        }
    }
    let selection = match (f.mission.selection.as_str(), &f.mission.selection_goal) {
        ("most_capable", None) => Selection::MostCapable,
        ("highest_cost", Some(g)) => {
            Selection::HighestCost(goals.iter().position(|x| &x.name == g).ok_or_else(|| {
                err(
                    "mission.selection_goal".into(),
                    format!("unknown goal `{g}`"),
                )
            })?)
        }
        (s, _) => {
            return Err(err(
                "mission.selection".into(),
                format!("`{s}`: expected `most_capable`, or `highest_cost` with `selection_goal`"),
            ));
        }
    };

    // Powers.
    finite_nonneg(
        "base.power_w".into(),
        f.base.power_w,
        "power (negative energy)",
    )?;
    for (name, r) in &f.resources {
        finite_nonneg(
            format!("resources.{name}.power_w"),
            r.power_w,
            "power (negative energy)",
        )?;
    }
    if let Some(c) = &f.compute {
        finite_nonneg(
            "compute.cpu_w_per_core".into(),
            c.cpu_w_per_core,
            "power (negative energy)",
        )?;
        finite_nonneg("compute.tile_w".into(), c.tile_w, "power (negative energy)")?;
        finite_nonneg("compute.cores".into(), c.cores, "core count")?;
    }
    let tiles_total = f.compute.as_ref().map_or(0, |c| c.tile_names.len());

    // Tasks and TIOs.
    let mut tasks: BTreeMap<&str, (Task, &TaskFile)> = BTreeMap::new();
    for (tname, t) in &f.tasks {
        if t.tios.is_empty() {
            return Err(err(
                format!("tasks.{tname}.tios"),
                "a task needs at least one TIO".into(),
            ));
        }
        let mut names = BTreeSet::new();
        for (k, tio) in t.tios.iter().enumerate() {
            let e = format!("tasks.{tname}.tios[{k}]");
            if !names.insert(tio.name.as_str()) {
                return Err(err(e, format!("duplicate TIO `{}`", tio.name)));
            }
            for r in &tio.resources {
                if !f.resources.contains_key(r) {
                    return Err(err(
                        format!("{e}.resources"),
                        format!("unknown resource `{r}` (not in [resources])"),
                    ));
                }
            }
            finite_nonneg(format!("{e}.time_s"), tio.time_s, "time")?;
            finite_nonneg(format!("{e}.cpu_load"), tio.cpu_load, "CPU load")?;
            if let Some(v) = tio.v_max_mps
                && !(v.is_finite() && v > 0.0)
            {
                return Err(err(
                    format!("{e}.v_max_mps"),
                    format!("must be > 0, got {v}"),
                ));
            }
            if (tio.tiles > 0 || tio.cpu_load > 0.0) && f.compute.is_none() {
                return Err(err(
                    e,
                    "uses CPU or tiles but the mission has no [compute] table".into(),
                ));
            }
            if tio.tiles as usize > tiles_total && f.compute.is_some() {
                return Err(err(
                    format!("{e}.tiles"),
                    format!("{} tiles > {tiles_total} on the platform", tio.tiles),
                ));
            }
        }
        let task = Task {
            name: tname.clone(),
            tios: t
                .tios
                .iter()
                .map(|x| Tio {
                    name: x.name.clone(),
                    resources: x.resources.clone(),
                })
                .collect(),
        };
        tasks.insert(tname.as_str(), (task, t));
    }
    // Constraint classes: every rule names a known task, TIO and resource.
    for (cname, c) in &f.constraints {
        for (k, rule) in c.rules.iter().enumerate() {
            let e = format!("constraints.{cname}.rules[{k}]");
            let (task, _) = tasks.get(rule.task()).ok_or_else(|| {
                err(
                    format!("{e}.task"),
                    format!("unknown task `{}`", rule.task()),
                )
            })?;
            match rule {
                CoreConstraint::Require { resource, .. }
                | CoreConstraint::Forbid { resource, .. } => {
                    if !f.resources.contains_key(resource) {
                        return Err(err(
                            format!("{e}.resource"),
                            format!("unknown resource `{resource}`"),
                        ));
                    }
                }
                CoreConstraint::Only { tios, .. } => {
                    for t in tios {
                        if !task.tios.iter().any(|x| &x.name == t) {
                            return Err(err(
                                format!("{e}.tios"),
                                format!("unknown TIO `{t}` for task `{}`", task.name),
                            ));
                        }
                    }
                }
            }
        }
    }

    // Activities: expand IAs and cost them.
    if f.activities.is_empty() {
        return Err(err(
            "activities".into(),
            "a mission needs at least one activity".into(),
        ));
    }
    let e_idx = goals.iter().position(|g| g.name == ENERGY);
    let d_idx = goals.iter().position(|g| g.name == DURATION);
    let mut acts = Vec::new();
    let mut infos = Vec::new();
    for (j, a) in f.activities.iter().enumerate() {
        let e = format!("activities[{j}]");
        if a.tasks.is_empty() {
            return Err(err(
                format!("{e}.tasks"),
                "an activity needs at least one task".into(),
            ));
        }
        let mut ts = Vec::new();
        let mut tfs = Vec::new();
        for (k, t) in a.tasks.iter().enumerate() {
            let (task, tf) = tasks
                .get(t.as_str())
                .ok_or_else(|| err(format!("{e}.tasks[{k}]"), format!("unknown task `{t}`")))?;
            ts.push(task.clone());
            tfs.push(*tf);
        }
        let mut rules = Vec::new();
        for (k, c) in a.constraints.iter().enumerate() {
            let class = f.constraints.get(c).ok_or_else(|| {
                err(
                    format!("{e}.constraints[{k}]"),
                    format!("unknown constraint class `{c}`"),
                )
            })?;
            rules.extend(class.rules.iter().cloned());
        }
        finite_nonneg(format!("{e}.length_m"), a.length_m, "length")?;
        finite_nonneg(format!("{e}.hold_s"), a.hold_s, "time")?;
        finite_nonneg(format!("{e}.hold_speed_mps"), a.hold_speed_mps, "speed")?;
        let n_all: usize = ts.iter().map(|t| t.tios.len()).product();
        let combos = panorama::combine(&ts, &rules);
        if combos.is_empty() {
            return Err(err(
                e.to_string(),
                format!(
                    "activity `{}` has no implementation alternative left after its constraints {:?}",
                    a.name, a.constraints
                ),
            ));
        }
        let mut ias = Vec::new();
        let mut ia_tios = Vec::new();
        let mut ia_speed = Vec::new();
        for combo in combos {
            let tios: Vec<&TioFile> = combo
                .iter()
                .enumerate()
                .map(|(k, &i)| &tfs[k].tios[i])
                .collect();
            let mut resources: BTreeSet<String> = tios
                .iter()
                .flat_map(|t| t.resources.iter().cloned())
                .collect();
            let speed = if a.length_m > 0.0 {
                let cap = tios
                    .iter()
                    .filter_map(|t| t.v_max_mps)
                    .fold(f64::INFINITY, f64::min);
                let v = a.v_max_mps.unwrap_or(f64::INFINITY).min(cap);
                if !(v.is_finite() && v > 0.0) {
                    return Err(err(
                        format!("{e}.v_max_mps"),
                        format!(
                            "activity `{}` moves {} m but has no finite positive speed",
                            a.name, a.length_m
                        ),
                    ));
                }
                Some(v)
            } else {
                None
            };
            let t_move = speed.map_or(0.0, |v| a.length_m / v);
            let t_hold = a.hold_s + tios.iter().map(|t| t.time_s).sum::<f64>();
            let duration = t_move + t_hold;
            let cpu: f64 = tios.iter().map(|t| t.cpu_load).sum();
            let tiles: u32 = tios.iter().map(|t| t.tiles).sum();
            let compute_w = f
                .compute
                .as_ref()
                .map_or(0.0, |c| c.cpu_w_per_core * cpu + c.tile_w * tiles as f64);
            let sensors_w: f64 = resources.iter().map(|r| f.resources[r].power_w).sum();
            let payload_w = f.base.power_w + sensors_w + compute_w;
            let energy = speed.map_or(0.0, |v| f.propulsion.power(v) * t_move)
                + f.propulsion.power(a.hold_speed_mps) * t_hold
                + payload_w * duration;
            let name = tios
                .iter()
                .map(|t| t.name.as_str())
                .collect::<Vec<_>>()
                .join(" ");
            if !energy.is_finite() || energy < 0.0 {
                return Err(err(
                    e.to_string(),
                    format!(
                        "IA `{name}` has negative or non-finite energy {energy} J (check the propulsion model)"
                    ),
                ));
            }
            if let Some(c) = &f.compute
                && (cpu > c.cores + 1e-9 || tiles as usize > tiles_total)
            {
                continue; // never placeable on the platform: not an alternative
            }
            for k in 1..=tiles as usize {
                resources.insert(tile_slot(k));
            }
            let mut cost = vec![0.0; goals.len()];
            if let Some(i) = e_idx {
                cost[i] = energy;
            }
            if let Some(i) = d_idx {
                cost[i] = duration;
            }
            ias.push(Ia {
                name: name.clone(),
                cost,
                capability: tios.iter().map(|t| t.capability).sum(),
                resources: resources.into_iter().collect(),
            });
            ia_tios.push(tios.iter().map(|t| t.name.clone()).collect());
            ia_speed.push(speed);
        }
        if ias.is_empty() {
            return Err(err(
                e.to_string(),
                format!(
                    "activity `{}`: no alternative fits the platform's CPU and tiles",
                    a.name
                ),
            ));
        }
        acts.push(Activity {
            name: a.name.clone(),
            ias,
        });
        infos.push(ActivityInfo {
            name: a.name.clone(),
            objective: a.objective.clone(),
            env: a.env.clone(),
            tasks: a.tasks.clone(),
            constraints: a.constraints.clone(),
            ia_tios,
            ia_speed,
            n_ia_unconstrained: n_all,
        });
        let _ = (a.x_start_m, a.x_end_m);
    }
    let mut names = BTreeSet::new();
    for (j, a) in f.activities.iter().enumerate() {
        if !names.insert(a.name.as_str()) {
            return Err(err(
                format!("activities[{j}].name"),
                format!("duplicate activity `{}`", a.name),
            ));
        }
    }
    let battery_capacity_j = f.battery.as_ref().map(|b| b.capacity_wh * 3600.0);
    Ok(MissionSpec {
        name: f.mission.name,
        file: path.to_path_buf(),
        description: f.mission.description,
        problem: Problem {
            goals,
            activities: acts,
        },
        selection,
        activities: infos,
        battery_capacity_j,
        tile_names: f.compute.map(|c| c.tile_names).unwrap_or_default(),
    })
}

// ---------------------------------------------------------------- pre-flight

/// The pre-flight allocation: RAS0, its NGA and initial margins (per goal, `goal - estimate`).
#[derive(Debug, Clone, PartialEq)]
pub struct Ras0 {
    pub choice: Vec<usize>,
    pub totals: BTreeMap<String, f64>,
    pub margins: BTreeMap<String, f64>,
    pub nga: Option<u128>,
}

/// One row of a PANORAMA Table 7: the RAS label, why it was computed, the activity it starts at,
/// and per activity the chosen IA (`None` for activities before `from_activity`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RasRow {
    pub label: String,
    pub reason: String,
    pub from_activity: usize,
    pub cells: Vec<Option<String>>,
}

/// In-flight progress, as measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress<'a> {
    /// Activity being flown (index into the mission's activities).
    pub activity_index: usize,
    /// Fraction of that activity already flown (0..1; 0 when unknown, the conservative choice).
    pub activity_fraction: f64,
    /// Consumed energy from battery telemetry, when the autopilot reports it.
    pub energy_used_j: Option<f64>,
    /// Remaining battery percentage, used when `energy_used_j` is not given.
    pub battery_remaining_pct: Option<f64>,
    pub elapsed_s: f64,
    /// Resources reported failed (sensor names, tile names); cumulative use is fine.
    pub failed_resources: &'a [String],
}

/// The guarantee stage's state across cycles: the mission, the RAS in force and its history.
#[derive(Debug, Clone)]
pub struct Guarantee {
    pub spec: MissionSpec,
    choice: Vec<usize>,
    failed: Vec<String>,
    first_pct: Option<f64>,
    rows: Vec<RasRow>,
    /// Buffers reused by [`Guarantee::watch_into`] (no allocation on a cycle that keeps the RAS).
    scratch: WatchScratch,
}

#[derive(Debug, Clone)]
struct WatchScratch {
    failed: Vec<String>,
    zero: Measured,
    m: Measured,
    report: MarginReport,
}

impl Default for WatchScratch {
    fn default() -> Self {
        let measured = Measured {
            activity: 0,
            fraction: 0.0,
            so_far: Vec::new(),
        };
        Self {
            failed: Vec::new(),
            zero: measured.clone(),
            m: measured,
            report: MarginReport {
                estimated_so_far: Vec::new(),
                remainder: Vec::new(),
                margin: Vec::new(),
                drift: Vec::new(),
            },
        }
    }
}

/// `named(goals, v)` into a reused map: values overwritten in place when it already holds
/// exactly the goal names.
fn named_into(goals: &[Goal], v: &[f64], out: &mut BTreeMap<String, f64>) {
    if out.len() == goals.len() {
        let mut all = true;
        for (g, x) in goals.iter().zip(v) {
            match out.get_mut(g.name.as_str()) {
                Some(y) => *y = *x,
                None => {
                    all = false;
                    break;
                }
            }
        }
        if all {
            return;
        }
    }
    *out = named(goals, v);
}

pub(crate) fn named(goals: &[Goal], v: &[f64]) -> BTreeMap<String, f64> {
    goals
        .iter()
        .zip(v)
        .map(|(g, x)| (g.name.clone(), *x))
        .collect()
}

impl Guarantee {
    /// PANORAMA P2: RAS0 by the paper's algorithm, or which goal fails and by how much.
    pub fn pre_flight(spec: &MissionSpec) -> Result<Ras0, Infeasible> {
        let a = panorama::allocate(&spec.problem, spec.selection)?;
        let goals = &spec.problem.goals;
        let margins: Vec<f64> = goals
            .iter()
            .zip(&a.totals)
            .map(|(g, t)| g.bound - t)
            .collect();
        Ok(Ras0 {
            totals: named(goals, &a.totals),
            margins: named(goals, &margins),
            nga: panorama::nga(&spec.problem),
            choice: a.choice,
        })
    }

    /// Start the mission with RAS0; errs (with the numbers) when the mission cannot be performed.
    pub fn start(spec: MissionSpec) -> Result<Self, Infeasible> {
        let ras0 = Self::pre_flight(&spec)?;
        let rows = vec![RasRow {
            label: "RAS0".into(),
            reason: "pre-flight allocation".into(),
            from_activity: 0,
            cells: ras0
                .choice
                .iter()
                .enumerate()
                .map(|(j, &i)| Some(spec.problem.activities[j].ias[i].name.clone()))
                .collect(),
        }];
        Ok(Self {
            choice: ras0.choice,
            spec,
            failed: Vec::new(),
            first_pct: None,
            rows,
            scratch: WatchScratch::default(),
        })
    }

    /// The RAS in force: IA index per activity.
    pub fn choice(&self) -> &[usize] {
        &self.choice
    }

    /// Every RAS computed so far, RAS0 first: the rows of a PANORAMA Table 7.
    /// Estimated cost of activity `activity` on goal `goal` under the allocation in force (e.g. its
    /// duration in seconds), so a caller can tell how far into the activity it is.
    pub fn estimated(&self, activity: usize, goal: &str) -> Option<f64> {
        let p = &self.spec.problem;
        let g = p.goals.iter().position(|x| x.name == goal)?;
        let ia = p
            .activities
            .get(activity)?
            .ias
            .get(*self.choice.get(activity)?)?;
        ia.cost.get(g).copied()
    }

    /// Name of the implementation alternative in force for `activity` (a RAS cell, e.g.
    /// `gps_vision lidar V4.F`).
    pub fn allocated(&self, activity: usize) -> Option<&str> {
        let p = &self.spec.problem;
        let ia = p
            .activities
            .get(activity)?
            .ias
            .get(*self.choice.get(activity)?)?;
        Some(ia.name.as_str())
    }

    pub fn ras_rows(&self) -> &[RasRow] {
        &self.rows
    }

    /// Consumed energy: `energy_used_j` if given, else the drop of the battery percentage since
    /// the first reading times the battery capacity, else `None` (the plan's estimate is used).
    fn energy_used(&mut self, p: &Progress) -> Option<f64> {
        p.energy_used_j.or_else(|| {
            let pct = p.battery_remaining_pct?;
            let cap = self.spec.battery_capacity_j?;
            let first = *self.first_pct.get_or_insert(pct);
            Some(((first - pct) / 100.0 * cap).max(0.0))
        })
    }

    /// PANORAMA P3, one cycle: margins and drift for the RAS in force; a new RAS for the reduced
    /// mission when a margin is negative or a failed resource is used from now on; `infeasible`
    /// set (with the goal and excess in `infeasible_reason`) when no RAS remains.
    pub fn watch(&mut self, progress: Progress) -> GuaranteeRecord {
        let mut rec = GuaranteeRecord::default();
        self.watch_into(progress, &mut rec);
        rec
    }

    /// As [`Guarantee::watch`], overwriting a reused record. A cycle that keeps the RAS in force
    /// (no negative margin, no failed resource in the plan) allocates nothing once the record
    /// and the internal buffers have their shape; a re-allocation builds its strings as before.
    pub fn watch_into(&mut self, progress: Progress, rec: &mut GuaranteeRecord) {
        let energy = self.energy_used(&progress);
        let p = &self.spec.problem;
        let n = p.activities.len();
        let at = progress.activity_index.min(n.saturating_sub(1));
        let fraction = if progress.activity_index >= n {
            1.0
        } else {
            progress.activity_fraction.clamp(0.0, 1.0)
        };
        for r in progress.failed_resources {
            if !self.failed.contains(r) {
                self.failed.push(r.clone());
            }
        }
        // A failed tile removes the highest tile slot still available.
        let failed_tiles = self
            .failed
            .iter()
            .filter(|r| self.spec.tile_names.contains(r))
            .count();
        let total_tiles = self.spec.tile_names.len();
        let sc = &mut self.scratch;
        // failed = self.failed + the lost tile slots, written over the reused strings.
        let slots = total_tiles - failed_tiles.min(total_tiles) + 1..=total_tiles;
        let names = self
            .failed
            .iter()
            .map(|r| (Some(r), 0))
            .chain(slots.map(|k| (None, k)));
        let mut len = 0;
        for (name, k) in names {
            if len == sc.failed.len() {
                sc.failed.push(String::new());
            }
            let out = &mut sc.failed[len];
            match name {
                Some(r) => out.clone_from(r),
                None => {
                    use std::fmt::Write;
                    out.clear();
                    let _ = write!(out, "tile_slot:{k}");
                }
            }
            len += 1;
        }
        sc.failed.truncate(len);
        let failed = &sc.failed;

        sc.zero.activity = at;
        sc.zero.fraction = fraction;
        sc.zero.so_far.clear();
        sc.zero.so_far.resize(p.goals.len(), 0.0);
        panorama::margins_into(p, &self.choice, &sc.zero, &mut sc.report);
        let est = &sc.report.estimated_so_far;
        sc.m.activity = at;
        sc.m.fraction = fraction;
        sc.m.so_far.clear();
        sc.m.so_far.extend(
            p.goals
                .iter()
                .enumerate()
                .map(|(g, goal)| match goal.name.as_str() {
                    ENERGY => energy.unwrap_or(est[g]),
                    DURATION => progress.elapsed_s,
                    _ => est[g],
                }),
        );
        let m = &sc.m;
        panorama::margins_into(p, &self.choice, m, &mut sc.report);
        let report = &sc.report;

        rec.activity = at;
        rec.activity_name.clone_from(&p.activities[at].name);
        named_into(&p.goals, &report.margin, &mut rec.margins);
        if rec.goals.len() != p.goals.len()
            || !p
                .goals
                .iter()
                .all(|g| match rec.goals.get_mut(g.name.as_str()) {
                    Some(b) => {
                        *b = g.bound;
                        true
                    }
                    None => false,
                })
        {
            rec.goals = p.goals.iter().map(|g| (g.name.clone(), g.bound)).collect();
        }
        named_into(&p.goals, &report.drift, &mut rec.drift);
        rec.reallocation = None;
        rec.infeasible = false;
        rec.infeasible_reason = None;
        rec.failed_resources.clone_from(&self.failed);
        if progress.activity_index >= n {
            return; // mission over: margins are final, nothing left to re-allocate
        }
        // The common case, decided without building any string.
        let any_failed = (at..n)
            .flat_map(|j| p.activities[j].ias[self.choice[j]].resources.iter())
            .any(|r| failed.contains(r));
        if !any_failed && !report.margin.iter().any(|x| *x < 0.0) {
            return;
        }
        let uses_failed: Vec<String> = (at..n)
            .flat_map(|j| p.activities[j].ias[self.choice[j]].resources.iter())
            .filter(|r| failed.contains(r))
            .cloned()
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let negative: Vec<String> = p
            .goals
            .iter()
            .zip(&report.margin)
            .filter(|(_, x)| **x < 0.0)
            .map(|(g, x)| format!("{} margin {x:.1}", g.name))
            .collect();
        let mut why = Vec::new();
        if !negative.is_empty() {
            why.push(format!("negative {}", negative.join(", ")));
        }
        if !uses_failed.is_empty() {
            let shown: Vec<String> = uses_failed
                .iter()
                .map(|r| {
                    if r.starts_with("tile_slot:") {
                        "FPGA tile".to_string()
                    } else {
                        r.clone()
                    }
                })
                .collect::<BTreeSet<_>>()
                .into_iter()
                .collect();
            why.push(format!("failed resource in plan: {}", shown.join(", ")));
        }
        let reason = why.join("; ");
        let mut reason = reason;
        let found = panorama::reallocate_or_exact(
            p,
            &self.choice,
            m,
            failed,
            self.spec.selection,
            EXACT_FALLBACK_NODES,
        )
        .map(|(c, exact)| {
            if exact {
                // The paper's greedy can miss a feasible allocation when goals interact.
                reason.push_str(" (exact search: the paper's algorithm found none)");
            }
            c
        });
        match found {
            Ok(c) => {
                let after = panorama::margins(p, &c, m);
                self.choice = c;
                let label = format!("RAS{}", self.rows.len());
                self.rows.push(RasRow {
                    label,
                    reason: format!("{} during {}", reason, p.activities[at].name),
                    from_activity: at,
                    cells: (0..n)
                        .map(|j| {
                            (j >= at).then(|| p.activities[j].ias[self.choice[j]].name.clone())
                        })
                        .collect(),
                });
                rec.reallocation = Some(Reallocation {
                    reason,
                    allocation: (at..n)
                        .map(|j| {
                            (
                                p.activities[j].name.clone(),
                                p.activities[j].ias[self.choice[j]].name.clone(),
                            )
                        })
                        .collect(),
                    margins_after: named(&p.goals, &after.margin),
                });
            }
            Err(e) => {
                rec.infeasible = true;
                rec.infeasible_reason = Some(format!(
                    "{reason}: no allocation of the remaining activities: {e}"
                ));
            }
        }
    }
}

/// Node budget of the exact fallback: bounded work per cycle.
const EXACT_FALLBACK_NODES: u64 = 200_000;
