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

mod binding;
mod compile;
mod derived;
pub mod power_bounds;
mod reason;
mod replan;
mod schema;
mod tuning;
mod verdict;

use crate::record::{
    CapacitySource, CellsSource, EnergySource, GuaranteeRecord, PackRecord, PowerRecord,
    Reallocation, ReallocationTrigger,
};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use compile::{check_against_catalogue, compile};
pub use derived::{derive_settings, derived_mission};
use panorama::{Goal, Infeasible, MarginReport, Measured, Problem, Selection};
use schema::MissionFile;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
pub use tuning::{
    ENERGY_SCALE_BOUNDS, POWER_DRIFT_MIN_S, POWER_DRIFT_TOLERANCE, PRIOR_WEIGHT_S, Tuning,
};
pub use verdict::{HoldKind, judge};

/// Indicator names the cost model produces; goals may name only these.
pub const ENERGY: &str = "energy_j";
/// Indicator name of the mission's duration (s).
pub const DURATION: &str = "duration_s";

// ---------------------------------------------------------------- compiled mission

/// One activity as flown: its tasks and, per IA (same order as in [`MissionSpec::problem`]),
/// the TIO names and the speed the estimate assumes.
#[derive(Debug, Clone, PartialEq)]
pub struct ActivityInfo {
    /// Activity name from the mission file (`take_off`, `transit`, ...).
    pub name: String,
    /// What the activity achieves (`reach wp1`).
    pub objective: String,
    /// Environment it is flown in (`GPS-degraded zone`).
    pub env: String,
    /// Tasks to be run throughout the activity (`localisation`, `obstacle_detection`).
    pub tasks: Vec<String>,
    /// Core-oriented constraint classes in force (`gps_degraded`).
    pub constraints: Vec<String>,
    /// Per IA: TIO name per task.
    pub ia_tios: Vec<Vec<String>>,
    /// Per IA: speed used for the estimate (m/s), `None` when the activity does not move.
    pub ia_speed: Vec<Option<f64>>,
    /// IA count before the core-oriented constraints (the objective's n_IA in Table 5).
    pub n_ia_unconstrained: usize,
    /// The activity's hold as compiled (s).
    pub hold_s: f64,
    /// Whether the hold is the mission's search or tracking time (`hold_kind`).
    pub hold_kind: Option<HoldKind>,
    /// Per IA: the energy one more second of hold costs (J/s): the hold's propulsion power and
    /// the payload's. Each IA's energy estimate is affine in the hold, with this slope.
    pub ia_hold_w: Vec<f64>,
}

/// A loaded, validated mission: the generic problem plus what the text and JSON views need.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionSpec {
    /// Mission name (params/missions/NAME.toml).
    pub name: String,
    /// File it was loaded from.
    pub file: PathBuf,
    /// Free text from the file.
    pub description: String,
    /// The generic PANORAMA problem: activities, IAs, goals.
    pub problem: Problem,
    /// How an IA is picked among those every goal leaves.
    pub selection: Selection,
    /// Per activity, what the text and JSON views show.
    pub activities: Vec<ActivityInfo>,
    /// Usable battery energy (J) before the reserve, when a `[battery]` is given: turns a
    /// remaining-percentage reading into consumed joules.
    pub battery_capacity_j: Option<f64>,
    /// What the energy goal keeps back of a full pack, as a fraction of its capacity: the part
    /// never drawn (`1 - usable_fraction`) plus the reserve (`reserve_wh / capacity_wh`). Applied
    /// to the pack the autopilot describes.
    pub battery_kept_back: Option<f64>,
    /// Tile names of the platform (a failure of one reduces the tiles available).
    pub tile_names: Vec<String>,
    /// How a measured power drift is judged and learned (`[guarantee]`).
    pub tuning: Tuning,
    /// `[power_bounds]`, when the mission states them.
    pub power_bounds: Option<power_bounds::PowerBounds>,
    /// The fastest the mission flies (m/s): its activities' speed caps and hold speeds.
    pub fastest_mps: f64,
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
    let path = mission_path(params, mission);
    let file: MissionFile = read_toml(params, &path)?;
    compile_against_catalogue(params, &path, file)
}

/// A mission file checked against params' variant catalogue (on its platform), then compiled.
fn compile_against_catalogue(
    params: &ParamsFiles,
    path: &Path,
    file: MissionFile,
) -> Result<MissionSpec, SpecError> {
    let params_dir = params.dir();
    let platform =
        crate::resources::load_platform(params, &params_dir.join(crate::resources::PLATFORM_FILE))?;
    let catalogue = crate::resources::load_variants(
        params,
        &params_dir.join(crate::resources::VARIANTS_FILE),
        &platform,
    )?;
    check_against_catalogue(path, &file, &catalogue)?;
    compile(path, file)
}

/// Parse a mission from TOML text (`path` only names it in errors).
pub fn parse_mission(path: &Path, text: &str) -> Result<MissionSpec, SpecError> {
    let file: MissionFile =
        toml::from_str(text).map_err(|e| SpecError::new(path, "-", e.message().to_string()))?;
    compile(path, file)
}

// ---------------------------------------------------------------- pre-flight

/// The pre-flight allocation: RAS0, its NGA and initial margins (per goal, `goal - estimate`).
#[derive(Debug, Clone, PartialEq)]
pub struct Ras0 {
    /// Chosen IA index per activity.
    pub choice: Vec<usize>,
    /// Estimated total per indicator (`energy_j` J, `duration_s` s).
    pub totals: BTreeMap<String, f64>,
    /// Goal minus estimate per goal, in the goal's unit.
    pub margins: BTreeMap<String, f64>,
    /// Number of global alternatives (PANORAMA eq. 6); `None` when it overflows.
    pub nga: Option<u128>,
}

/// One row of a PANORAMA Table 7: the RAS label, why it was computed, the activity it starts at,
/// and per activity the chosen IA (`None` for activities before `from_activity`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RasRow {
    /// RAS label (`RAS0`, `RAS1`, ...).
    pub label: String,
    /// Why this RAS was computed (pre-flight, or the in-flight trigger).
    pub reason: String,
    /// Index of the first activity it allocates.
    pub from_activity: usize,
    /// Chosen IA name per activity.
    pub cells: Vec<Option<String>>,
}

/// In-flight progress, as measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress<'a> {
    /// Activity being flown (index into the mission's activities).
    pub activity_index: usize,
    /// Fraction of that activity already flown (0..1; 0 when unknown, the conservative choice).
    pub activity_fraction: f64,
    /// Energy the autopilot reports consumed since it booted (BATTERY_STATUS.energy_consumed),
    /// when it reports it. Counts from the boot, not from a full pack.
    pub energy_used_j: Option<f64>,
    /// Remaining battery percentage the autopilot reports (of the full pack): the energy still
    /// in the pack, with the mission's `[battery]` capacity.
    pub battery_remaining_pct: Option<f64>,
    /// Time since the mission started (s).
    pub elapsed_s: f64,
    /// Resources reported failed (sensor names, tile names); cumulative use is fine.
    pub failed_resources: &'a [String],
    /// What the autopilot says of its pack besides the percentage (all `None` in `simulate`).
    pub pack: PackReading,
}

/// The observations a [`PackReading`] is read from, in its field order: the vocabulary the link's
/// telemetry must write (`companion check` refuses a params set or build where fly's telemetry
/// writes one of them under another name: the energy goal would silently fall back to the
/// params' pack in flight).
pub const PACK_OBSERVATIONS: [&str; 7] = [
    "battery_capacity_mah",
    "battery_cells",
    "battery_v",
    "battery_current_a",
    "consumed_mah",
    "vehicle_time_s",
    "armed",
];

/// The pack as the autopilot reports it (fly's telemetry; docs/mavlink.md).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PackReading {
    /// Capacity parameter (`BATT_CAPACITY`, `BAT1_CAPACITY`, mAh); zero or negative: not set.
    pub capacity_mah: Option<f64>,
    /// Cells in series (PX4 `BAT1_N_CELLS`); zero: not set.
    pub cells: Option<f64>,
    /// Pack voltage now (V).
    pub voltage_v: Option<f64>,
    /// Current drawn now (A).
    pub current_a: Option<f64>,
    /// Charge consumed (BATTERY_STATUS.current_consumed, mAh), counted by the autopilot from a
    /// full pack or from its last battery reset.
    pub consumed_mah: Option<f64>,
    /// The autopilot's clock (s, SYSTEM_TIME): an activity's time is counted on it, since the
    /// consumed energy accrues on it (a SITL may run faster than the companion's clock).
    pub vehicle_time_s: Option<f64>,
    /// Whether the vehicle is armed (`None`: not known). Disarmed, nothing is flown: the
    /// activity's power is not judged (on the ground before the take-off it draws next to
    /// nothing, which is no drift) and its measurement starts again at the arming.
    pub armed: Option<bool>,
}

/// Nominal voltage of a lithium-polymer cell (V): a pack's rated energy is its capacity at this
/// voltage a cell (ASSUMPTION: LiPo or Li-ion packs, as both autopilots' defaults are).
pub const NOMINAL_CELL_V: f64 = 3.7;
/// Highest voltage a cell is taken to hold (V) when the cells are counted from the pack voltage:
/// a charged LiPo is 4.2 V, so `ceil(V / 4.25)` counts a 3S pack anywhere from 8.5 to 12.75 V.
pub const MAX_CELL_V: f64 = 4.25;
/// What the guarantee keeps across cycles to measure the activity in force.
#[derive(Debug, Clone, Default)]
struct PowerState {
    /// Activity, when it began (s), the autopilot's consumed energy then (J).
    activity: Option<(usize, f64, Option<f64>)>,
    /// Measured power integrated since the activity began (J), and the last (time, power).
    integrated_j: f64,
    last: Option<(f64, f64)>,
    /// A drift was already said for this activity.
    drift_said: bool,
}

/// The guarantee stage's state across cycles: the mission, the RAS in force and its history.
#[derive(Debug, Clone)]
pub struct Guarantee {
    /// The mission being flown.
    pub spec: MissionSpec,
    choice: Vec<usize>,
    failed: Vec<String>,
    rows: Vec<RasRow>,
    /// Re-allocations so far (RAS0 not counted): the plan following what runs back to an
    /// allocation already in `rows` counts here but adds no row.
    reallocations: usize,
    /// The alternatives' names as tokens, per activity (binding.rs).
    tokens: Vec<binding::ActivityTokens>,
    /// Buffers reused by [`Guarantee::watch_into`] (no allocation on a cycle that keeps the RAS).
    scratch: WatchScratch,
    /// The energy goal's index and its bound from the mission file (params' `[battery]`).
    energy_goal: Option<(usize, f64)>,
    /// Cells counted from the first pack voltage heard (kept: the voltage sags in flight).
    cells_seen: Option<f64>,
    /// The remaining activities' energy estimates as compiled (`energy_scale` applies to them).
    base_energy: Vec<Vec<f64>>,
    power: PowerState,
    /// The factor on the remaining activities' energy estimates (1 until a drift is measured).
    energy_scale: f64,
}

#[derive(Debug, Clone)]
struct WatchScratch {
    failed: Vec<String>,
    zero: Measured,
    m: Measured,
    report: MarginReport,
    /// Which alternatives of one activity meet the goals with the rest of the plan (binding.rs).
    swap: panorama::SwapCheck,
    /// The margins of the plan after a re-allocation (binding.rs).
    alt: MarginReport,
    /// The reduced mission a re-allocation searches, kept (asked every cycle while the
    /// guarantee cannot be met).
    reallocator: panorama::Reallocator,
    /// Per token id of the activity: carried by a feasible alternative, offered (binding.rs).
    version_flags: (Vec<bool>, Vec<bool>),
    /// The last re-allocation record, its strings and maps kept to be rewritten in place by
    /// the next one (a version flipping every cycle re-allocates every cycle, allocation-free).
    spare: Option<Reallocation>,
    /// The placements an activity names, as (token id, placement index) (binding.rs).
    running_ids: Vec<(usize, usize)>,
    /// Why the plan must change, and the last record's `infeasible_reason`: kept to be
    /// rewritten, as the watch says "cannot" every cycle until the goals are met again.
    reason: String,
    spare_reason: String,
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
            swap: panorama::SwapCheck::default(),
            reallocator: panorama::Reallocator::default(),
            alt: MarginReport {
                estimated_so_far: Vec::new(),
                remainder: Vec::new(),
                margin: Vec::new(),
                drift: Vec::new(),
            },
            version_flags: (Vec::new(), Vec::new()),
            spare: None,
            running_ids: Vec::new(),
            reason: String::new(),
            spare_reason: String::new(),
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
        Ok(Self::with_ras0(spec, ras0, "pre-flight allocation"))
    }

    /// [`Guarantee::start`], or, when the params' goals cannot be met before the flight, the
    /// allocation the paper's algorithm makes with the goals' bounds lifted (the most capable IAs):
    /// in `fly` the energy goal is reckoned again from the pack the autopilot reports (a profile's
    /// power against the params' pack is not the vehicle's), and the margins, negative while the
    /// goals are unmet, are what the launch verdict reads. `None` only when no IA exists.
    pub fn start_or_unbounded(spec: MissionSpec) -> Option<Self> {
        match Self::pre_flight(&spec) {
            Ok(ras0) => Some(Self::with_ras0(spec, ras0, "pre-flight allocation")),
            Err(_) => {
                let mut lifted = spec.clone();
                for g in &mut lifted.problem.goals {
                    g.bound = f64::MAX;
                }
                let ras0 = Self::pre_flight(&lifted).ok()?;
                Some(Self::with_ras0(
                    spec,
                    ras0,
                    "pre-flight allocation, goals' bounds lifted (unmet with the params' values)",
                ))
            }
        }
    }

    fn with_ras0(spec: MissionSpec, ras0: Ras0, reason: &str) -> Self {
        let tokens = binding::ActivityTokens::of(&spec.problem);
        let rows = vec![RasRow {
            label: "RAS0".into(),
            reason: reason.into(),
            from_activity: 0,
            cells: ras0
                .choice
                .iter()
                .enumerate()
                .map(|(j, &i)| Some(spec.problem.activities[j].ias[i].name.clone()))
                .collect(),
        }];
        let energy_goal = spec
            .problem
            .goals
            .iter()
            .position(|g| g.name == ENERGY)
            .map(|e| (e, spec.problem.goals[e].bound));
        let base_energy = match energy_goal {
            Some((e, _)) => spec
                .problem
                .activities
                .iter()
                .map(|a| a.ias.iter().map(|ia| ia.cost[e]).collect())
                .collect(),
            None => Vec::new(),
        };
        Self {
            choice: ras0.choice,
            spec,
            failed: Vec::new(),
            rows,
            reallocations: 0,
            tokens,
            scratch: WatchScratch::default(),
            energy_goal,
            cells_seen: None,
            base_energy,
            power: PowerState::default(),
            energy_scale: 1.0,
        }
    }

    /// Re-allocations so far (RAS0 not counted), the plan following what runs included.
    pub fn reallocations(&self) -> usize {
        self.reallocations
    }

    /// A RAS row for the plan in force from activity `at` on.
    fn push_row(&mut self, at: usize, reason: &str) {
        let p = &self.spec.problem;
        let n = p.activities.len();
        self.rows.push(RasRow {
            label: format!("RAS{}", self.rows.len()),
            reason: format!("{reason} during {}", p.activities[at].name),
            from_activity: at,
            cells: (0..n)
                .map(|j| (j >= at).then(|| p.activities[j].ias[self.choice[j]].name.clone()))
                .collect(),
        });
    }

    /// The re-allocation of this cycle into `rec`, for the plan in force from activity `at`
    /// on: its margins in the record's `margins_after`, the text `reason` writes. Rewrites the last record's strings in place (no allocation once warm).
    fn write_reallocation(
        &mut self,
        at: usize,
        trigger: ReallocationTrigger,
        rec: &mut GuaranteeRecord,
        reason: impl FnOnce(&mut String, &Problem),
    ) {
        let p = &self.spec.problem;
        let n = p.activities.len();
        let sc = &mut self.scratch;
        let mut out = rec
            .reallocation
            .take()
            .or_else(|| sc.spare.take())
            .unwrap_or_default();
        out.trigger = trigger;
        out.reason.clear();
        reason(&mut out.reason, p);
        out.allocation.truncate(n - at);
        for (k, j) in (at..n).enumerate() {
            let (a, ia) = (
                &p.activities[j].name,
                &p.activities[j].ias[self.choice[j]].name,
            );
            match out.allocation.get_mut(k) {
                Some(e) => {
                    e.0.clone_from(a);
                    e.1.clone_from(ia);
                }
                None => out.allocation.push((a.clone(), ia.clone())),
            }
        }
        panorama::margins_into(p, &self.choice, &sc.m, &mut sc.alt);
        named_into(&p.goals, &sc.alt.margin, &mut out.margins_after);
        rec.reallocation = Some(out);
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

    /// Index of the alternative in force for `activity` ([`Guarantee::allocated`]'s).
    pub fn allocated_index(&self, activity: usize) -> Option<usize> {
        let i = *self.choice.get(activity)?;
        self.spec
            .problem
            .activities
            .get(activity)?
            .ias
            .get(i)
            .map(|_| i)
    }

    /// Every RAS computed so far, pre-flight first.
    pub fn ras_rows(&self) -> &[RasRow] {
        &self.rows
    }

    /// The pack the energy goal is reckoned from this cycle, and the energy counted as used.
    ///
    /// With the autopilot's capacity (mAh > 0) and a cell count (its parameter, else counted
    /// from the first pack voltage, `ceil(V / 4.25)`), the pack's energy is
    /// `C = capacity_mAh x 3.6 x cells x 3.7 V` (J), the goal's bound is `C x (1 - k)` with `k`
    /// the fraction params' `[battery]` keeps back (never drawn, and the reserve), and the energy
    /// left is `pct / 100 x C`, or `(capacity - consumed mAh) x 3.6 x cells x 3.7 V`, the smaller
    /// when both are reported. Counted as used: `C - left`, so the margin is
    /// `left - k x C - remainder`: a vehicle that starts at 12 % starts with 12 % of its pack.
    /// Otherwise the params' `[battery]` as before ([`Guarantee::energy_used`]).
    fn energy_pack(&mut self, p: &Progress) -> (Option<f64>, EnergySource, Option<PackRecord>) {
        let pk = &p.pack;
        if self.cells_seen.is_none() {
            self.cells_seen = pk
                .voltage_v
                .filter(|v| v.is_finite() && *v > 0.0)
                .map(|v| (v / MAX_CELL_V).ceil());
        }
        let cells = match pk.cells.filter(|c| *c >= 1.0) {
            Some(c) => Some((c, CellsSource::Autopilot)),
            None => self.cells_seen.map(|c| (c, CellsSource::FirstVoltage)),
        };
        let kept = self.spec.battery_kept_back;
        let ap = pk
            .capacity_mah
            .filter(|c| *c > 0.0)
            .zip(cells)
            .zip(kept.zip(self.energy_goal));
        let Some(((cap_mah, (cells, cells_source)), (kept, (e, _)))) = ap else {
            // The params' pack: the goal's bound as compiled.
            if let Some((e, bound)) = self.energy_goal {
                self.spec.problem.goals[e].bound = bound;
            }
            let (used, source) = self.energy_used(p);
            let said = pk.capacity_mah.is_some() || pk.voltage_v.is_some();
            let rec = self.spec.battery_capacity_j.filter(|_| said).map(|cap| {
                let kept_back_j = kept.unwrap_or(0.0) * cap;
                let left_j = p
                    .battery_remaining_pct
                    .map(|pct| pct.clamp(0.0, 100.0) / 100.0 * cap);
                PackRecord {
                    capacity_source: CapacitySource::Params,
                    capacity_mah: pk.capacity_mah,
                    capacity_j: cap,
                    nominal_v: None,
                    cells: cells.map(|c| c.0),
                    cells_source: cells.map(|c| c.1),
                    left_j,
                    kept_back_j,
                    spendable_j: left_j.map(|l| l - kept_back_j),
                }
            });
            return (used, source, rec);
        };
        let nominal_v = cells * NOMINAL_CELL_V;
        let cap_j = cap_mah * 3.6 * nominal_v;
        let kept_back_j = kept * cap_j;
        self.spec.problem.goals[e].bound = cap_j - kept_back_j;
        let from_pct = p
            .battery_remaining_pct
            .map(|pct| pct.clamp(0.0, 100.0) / 100.0 * cap_j);
        let from_mah = pk
            .consumed_mah
            .filter(|c| c.is_finite())
            .map(|c| (cap_mah - c).clamp(0.0, cap_mah) * 3.6 * nominal_v);
        let (left, source) = match (from_pct, from_mah) {
            (Some(a), Some(b)) if b < a => (Some(b), EnergySource::CurrentConsumed),
            (Some(a), _) => (Some(a), EnergySource::BatteryRemaining),
            (None, Some(b)) => (Some(b), EnergySource::CurrentConsumed),
            (None, None) => (None, EnergySource::Estimate),
        };
        let rec = PackRecord {
            capacity_source: CapacitySource::Autopilot,
            capacity_mah: Some(cap_mah),
            capacity_j: cap_j,
            nominal_v: Some(nominal_v),
            cells: Some(cells),
            cells_source: Some(cells_source),
            left_j: left,
            kept_back_j,
            spendable_j: left.map(|l| l - kept_back_j),
        };
        (left.map(|l| (cap_j - l).max(0.0)), source, Some(rec))
    }

    /// Predicted against measured power of activity `at` (index into the problem) at `now`, and
    /// the energy factor learned from it. `None` when the autopilot reports neither power nor
    /// consumed energy (`simulate`).
    fn power(&mut self, at: usize, p: &Progress) -> Option<PowerRecord> {
        let measured_w = p
            .pack
            .voltage_v
            .zip(p.pack.current_a)
            .map(|(v, i)| v * i)
            .filter(|w| w.is_finite());
        let consumed = p.energy_used_j.filter(|e| e.is_finite());
        if measured_w.is_none() && consumed.is_none() {
            return None;
        }
        let now = p.pack.vehicle_time_s.unwrap_or(p.elapsed_s);
        let st = &mut self.power;
        if p.pack.armed == Some(false) {
            *st = PowerState::default();
            return Some(PowerRecord {
                predicted_w: self.predicted_power(at),
                measured_w,
                energy_scale: self.energy_scale,
                ..Default::default()
            });
        }
        if st.activity.map(|a| a.0) != Some(at) {
            st.activity = Some((at, now, consumed));
            st.integrated_j = 0.0;
            st.last = None;
            st.drift_said = false;
        }
        if let (Some((t0, w0)), Some(w)) = (st.last, measured_w) {
            st.integrated_j += 0.5 * (w0 + w) * (now - t0).max(0.0);
        }
        if let Some(w) = measured_w {
            st.last = Some((now, w));
        }
        let (_, began, consumed0) = st.activity.unwrap_or((at, now, None));
        let activity_s = (now - began).max(0.0);
        let measured_j = match (consumed, consumed0) {
            (Some(c), Some(c0)) => Some((c - c0).max(0.0)),
            _ => measured_w.map(|_| st.integrated_j),
        };
        let predicted_w = self.predicted_power(at);
        let predicted_j = predicted_w * activity_s;
        let ratio = measured_j
            .filter(|_| activity_s >= self.spec.tuning.power_drift_min_s && predicted_j > 0.0)
            .map(|m| m / predicted_j);
        let tolerance = self.spec.tuning.power_drift_tolerance;
        let drift = ratio.is_some_and(|r| (r - 1.0).abs() > tolerance);
        let drift_began = drift && !self.power.drift_said;
        if drift {
            self.power.drift_said = true;
            let (lo, hi) = self.spec.tuning.energy_scale_bounds;
            let w = self.spec.tuning.prior_weight_s;
            let r = ratio.unwrap_or(1.0);
            let k = (w + activity_s * r) / (w + activity_s);
            self.set_energy_scale(at, k.clamp(lo, hi));
        }
        Some(PowerRecord {
            predicted_w,
            measured_w,
            activity_s,
            predicted_j,
            measured_j,
            ratio,
            drift,
            drift_began,
            energy_scale: self.energy_scale,
        })
    }

    /// The power the allocation in force predicts for activity `at` (W): its energy estimate
    /// over its duration estimate, as compiled (the learned factor not applied).
    fn predicted_power(&self, at: usize) -> f64 {
        let (e, d) = self.planned(at);
        if d > 0.0 { e / d } else { 0.0 }
    }

    /// The allocation in force's estimates for activity `at`, energy (J) and duration (s), as
    /// compiled (the learned factor not applied); zeros without an energy and a duration goal.
    fn planned(&self, at: usize) -> (f64, f64) {
        let p = &self.spec.problem;
        let d = p.goals.iter().position(|g| g.name == DURATION);
        let (Some(_), Some(d)) = (self.energy_goal, d) else {
            return (0.0, 0.0);
        };
        let Some(ia) = p
            .activities
            .get(at)
            .and_then(|a| a.ias.get(self.choice[at]))
        else {
            return (0.0, 0.0);
        };
        (self.base_energy[at][self.choice[at]], ia.cost[d])
    }

    /// Scale the energy estimates of activities `at..` by `k` (those before are flown, measured).
    fn set_energy_scale(&mut self, at: usize, k: f64) {
        let Some((e, _)) = self.energy_goal else {
            return;
        };
        self.energy_scale = k;
        for (j, a) in self.spec.problem.activities.iter_mut().enumerate().skip(at) {
            for (i, ia) in a.ias.iter_mut().enumerate() {
                ia.cost[e] = self.base_energy[j][i] * k;
            }
        }
    }

    /// Energy counted as used against the energy goal with params' `[battery]` (the fallback,
    /// and `simulate`), and where it came from.
    ///
    /// The goal's bound is the pack's usable energy above the reserve, for a full pack. What the
    /// mission may still spend is what the pack holds now: `pct` % of the capacity, less the
    /// part that is never drawn (`1 - usable_fraction`) and the reserve. Counted as used is the
    /// bound minus that, `(1 - pct / 100) x capacity`, so a vehicle that starts at 12 % starts
    /// with 12 % (not "full at the first reading"). The autopilot's consumed energy counts from
    /// its boot (a full pack assumed); when both are reported the larger use counts (the
    /// conservative reading). Neither: `None`, the plan's estimate is used.
    fn energy_used(&self, p: &Progress) -> (Option<f64>, EnergySource) {
        let from_pct = p.battery_remaining_pct.and_then(|pct| {
            let cap = self.spec.battery_capacity_j?;
            // Written as the drop from 100 % so that a pack starting full gives, bit for bit,
            // what the old "drop since the first reading" gave.
            Some(((100.0 - pct.clamp(0.0, 100.0)) / 100.0 * cap).max(0.0))
        });
        match (from_pct, p.energy_used_j.filter(|e| e.is_finite())) {
            (Some(a), Some(b)) if b > a => (Some(b), EnergySource::EnergyConsumed),
            (Some(a), _) => (Some(a), EnergySource::BatteryRemaining),
            (None, Some(b)) => (Some(b), EnergySource::EnergyConsumed),
            (None, None) => (None, EnergySource::Estimate),
        }
    }

    /// PANORAMA P3, one cycle: margins and drift for the RAS in force; a new RAS for the reduced
    /// mission when a margin is negative or a failed resource is used from now on; `infeasible`
    /// set (with the goal and excess in `infeasible_reason`) when no RAS remains.
    pub fn watch(&mut self, progress: Progress) -> GuaranteeRecord {
        let mut rec = GuaranteeRecord::default();
        self.watch_into(progress, &mut rec);
        rec
    }

    /// Add the resources reported failed, then write the failed list the allocation avoids
    /// (`scratch.failed`): those resources and the tile slots lost to failed tiles (a failed tile
    /// removes the highest slot still available), over the reused strings.
    fn note_failed(&mut self, failed_resources: &[String]) {
        for r in failed_resources {
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
    }

    /// As [`Guarantee::watch`], overwriting a reused record. A cycle that keeps the RAS in force
    /// (no negative margin, no failed resource in the plan) allocates nothing once the record
    /// and the internal buffers have their shape; a re-allocation builds its strings as before.
    pub fn watch_into(&mut self, progress: Progress, rec: &mut GuaranteeRecord) {
        let (energy, energy_source, pack) = self.energy_pack(&progress);
        rec.energy_source = energy_source;
        rec.pack = pack;
        self.note_failed(progress.failed_resources);
        let n = self.spec.problem.activities.len();
        let at = progress.activity_index.min(n.saturating_sub(1));
        rec.power = self.power(at, &progress);
        (rec.planned_j, rec.planned_s) = self.planned(at);
        let p = &self.spec.problem;
        let fraction = if progress.activity_index >= n {
            1.0
        } else {
            progress.activity_fraction.clamp(0.0, 1.0)
        };
        let sc = &mut self.scratch;
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
        if let Some(r) = rec.reallocation.take() {
            sc.spare = Some(r);
        }
        rec.infeasible = false;
        if let Some(r) = rec.infeasible_reason.take() {
            sc.spare_reason = r;
        }
        rec.failed_resources.clone_from(&self.failed);
        rec.verdict = None;
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
        let mut reason = std::mem::take(&mut sc.reason);
        reason::reallocation_reason_into(p, &self.choice, at, failed, &report.margin, &mut reason);
        let found = sc
            .reallocator
            .reallocate_or_exact(
                p,
                &self.choice,
                &sc.m,
                &sc.failed,
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
                self.choice = c;
                let trigger = if any_failed {
                    ReallocationTrigger::Failure
                } else {
                    ReallocationTrigger::Margin
                };
                self.push_row(at, &reason);
                self.write_reallocation(at, trigger, rec, |out, _| out.push_str(&reason));
                self.reallocations += 1;
            }
            Err(e) => {
                rec.infeasible = true;
                let mut out = std::mem::take(&mut sc.spare_reason);
                out.clear();
                use std::fmt::Write;
                // Writing into a String cannot fail.
                let _ = write!(
                    out,
                    "{reason}: no allocation of the remaining activities: {e}"
                );
                rec.infeasible_reason = Some(out);
                // Before the flight (on the ground, the first activity): what the start refusal
                // tells the operator, from what the pack holds and the time spent.
                if at == 0 && progress.pack.armed != Some(true) {
                    rec.verdict = Some(judge(
                        &self.spec,
                        &self.scratch.m.so_far,
                        progress.battery_remaining_pct,
                    ));
                }
            }
        }
        self.scratch.reason = reason;
    }
}

/// The application alternatives an IA name carries, as (version, implementation): `V4.F` and
/// `zone_t.F` in `gps_vision fusion V4.F`; tokens without an implementation are skipped.
pub fn ia_variants(ia: &str) -> impl Iterator<Item = (&str, &str)> {
    ia.split_whitespace()
        .filter_map(|token| token.split_once('.'))
}

/// Node budget of the exact fallback: bounded work per cycle.
const EXACT_FALLBACK_NODES: u64 = 200_000;
