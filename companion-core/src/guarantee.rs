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

mod compile;
mod schema;

use crate::record::{EnergySource, GuaranteeRecord, Reallocation};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use compile::{check_against_catalogue, compile};
use panorama::{Goal, Infeasible, MarginReport, Measured, Problem, Selection};
use schema::MissionFile;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

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
}

/// The guarantee stage's state across cycles: the mission, the RAS in force and its history.
#[derive(Debug, Clone)]
pub struct Guarantee {
    /// The mission being flown.
    pub spec: MissionSpec,
    choice: Vec<usize>,
    failed: Vec<String>,
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

    /// Every RAS computed so far, pre-flight first.
    pub fn ras_rows(&self) -> &[RasRow] {
        &self.rows
    }

    /// Energy counted as used against the energy goal, and where it came from.
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
        let (energy, energy_source) = self.energy_used(&progress);
        rec.energy_source = energy_source;
        self.note_failed(progress.failed_resources);
        let p = &self.spec.problem;
        let n = p.activities.len();
        let at = progress.activity_index.min(n.saturating_sub(1));
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
        let mut reason = reallocation_reason(p, &self.choice, at, failed, &report.margin);
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

/// Why the allocation in force must change from activity `at`: its negative margins and the
/// failed resources its remaining IAs use (`FPGA tile` for a lost tile slot).
fn reallocation_reason(
    p: &panorama::Problem,
    choice: &[usize],
    at: usize,
    failed: &[String],
    margin: &[f64],
) -> String {
    let n = p.activities.len();
    let uses_failed: Vec<String> = (at..n)
        .flat_map(|j| p.activities[j].ias[choice[j]].resources.iter())
        .filter(|r| failed.contains(r))
        .cloned()
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    let negative: Vec<String> = p
        .goals
        .iter()
        .zip(margin)
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
    why.join("; ")
}

/// The application alternatives an IA name carries, as (version, implementation): `V4.F` and
/// `zone_t.F` in `gps_vision fusion V4.F`; tokens without an implementation are skipped.
pub fn ia_variants(ia: &str) -> impl Iterator<Item = (&str, &str)> {
    ia.split_whitespace()
        .filter_map(|token| token.split_once('.'))
}

/// Node budget of the exact fallback: bounded work per cycle.
const EXACT_FALLBACK_NODES: u64 = 200_000;
