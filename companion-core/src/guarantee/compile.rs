//! A mission file checked against the variant catalogue and compiled to PANORAMA's problem:
//! goals, tasks and constraint classes validated, each activity's implementation alternatives
//! costed.

use super::schema::{ActivityFile, GoalFile, MissionFile, TaskFile, TioFile};
use super::{ActivityInfo, DURATION, ENERGY, MissionSpec};
use crate::spec::SpecError;
use panorama::{Activity, CoreConstraint, Goal, Ia, Problem, Selection, Task, Tio};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Every TIO naming a `variant` (`app/version/implementation`) must occupy what
/// params/variants.toml says: its tiles, and as `cpu_load` its SW milliseconds per frame / 1000
/// (cores' worth at one frame per second).
pub(super) fn check_against_catalogue(
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

fn tile_slot(k: usize) -> String {
    format!("tile_slot:{k}")
}

/// The tasks by name, each compiled to PANORAMA's task with its file entry kept for costing.
type Tasks<'f> = BTreeMap<&'f str, (Task, &'f TaskFile)>;

/// One implementation alternative of an activity: the generic IA, its TIO names, its speed,
/// and the energy a second more of hold costs (J/s).
type CostedIa = (Ia, Vec<String>, Option<f64>, f64);

/// A mission file being compiled; `path` names it in errors.
struct Compiler<'f> {
    path: &'f Path,
    f: &'f MissionFile,
    /// Tiles of the platform (`[compute]`), 0 without one.
    tiles_total: usize,
}

/// Check and compile a parsed mission: goals, powers, tasks, constraint classes, then each
/// activity's implementation alternatives costed in energy and duration.
pub(super) fn compile(path: &Path, f: MissionFile) -> Result<MissionSpec, SpecError> {
    let c = Compiler {
        path,
        f: &f,
        tiles_total: f.compute.as_ref().map_or(0, |c| c.tile_names.len()),
    };
    let goals = c.goals()?;
    let selection = c.selection(&goals)?;
    c.check_powers()?;
    let power_bounds = f.power_bounds.as_ref().map(|b| b.check(path)).transpose()?;
    let fastest_mps = super::power_bounds::fastest(&f);
    super::power_bounds::check_power_curve(
        power_bounds.as_ref(),
        |v| f.propulsion.power(v),
        f.base.power_w,
        fastest_mps,
    )
    .map_err(|u| c.err(u.entry, u.reason))?;
    let tasks = c.tasks()?;
    c.check_constraints(&tasks)?;
    if f.activities.is_empty() {
        return Err(c.err("activities", "a mission needs at least one activity"));
    }
    let mut acts = Vec::new();
    let mut infos = Vec::new();
    for j in 0..f.activities.len() {
        let (act, info) = c.activity(j, &goals, &tasks)?;
        acts.push(act);
        infos.push(info);
    }
    let mut names = BTreeSet::new();
    for (j, a) in f.activities.iter().enumerate() {
        if !names.insert(a.name.as_str()) {
            return Err(c.err(
                format!("activities[{j}].name"),
                format!("duplicate activity `{}`", a.name),
            ));
        }
    }
    let battery_capacity_j = f.battery.as_ref().map(|b| b.capacity_wh * 3600.0);
    // What the energy goal keeps back of a full pack, as a fraction of it: applied to a pack
    // the autopilot describes (`Guarantee::watch`).
    let battery_kept_back = f
        .battery
        .as_ref()
        .filter(|b| b.capacity_wh > 0.0)
        .map(|b| (1.0 - b.usable_fraction) + b.reserve_wh / b.capacity_wh);
    let tuning = c.tuning()?;
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
        battery_kept_back,
        tile_names: f.compute.map(|c| c.tile_names).unwrap_or_default(),
        tuning,
        power_bounds,
        fastest_mps,
    })
}

impl<'f> Compiler<'f> {
    /// `[guarantee]`, range-checked (issue 23: the drift tuning is the mission's, not the code's).
    fn tuning(&self) -> Result<super::Tuning, SpecError> {
        let Some(t) = &self.f.guarantee else {
            return Ok(super::Tuning::default());
        };
        let check = |entry: &str, x: f64, lo: f64, hi: f64| {
            if x.is_finite() && (lo..=hi).contains(&x) {
                Ok(())
            } else {
                Err(self.err(
                    format!("guarantee.{entry}"),
                    format!("{x} is outside [{lo}, {hi}]"),
                ))
            }
        };
        check("power_drift_tolerance", t.power_drift_tolerance, 0.01, 10.0)?;
        check("power_drift_min_s", t.power_drift_min_s, 0.0, 3600.0)?;
        check("prior_weight_s", t.prior_weight_s, 0.0, 86_400.0)?;
        let [lo, hi] = t.energy_scale_bounds;
        check("energy_scale_bounds[0]", lo, 0.01, 1.0)?;
        check("energy_scale_bounds[1]", hi, 1.0, 100.0)?;
        check("fit_headroom", t.fit_headroom, 0.0, 0.5)?;
        Ok(super::Tuning {
            power_drift_tolerance: t.power_drift_tolerance,
            power_drift_min_s: t.power_drift_min_s,
            prior_weight_s: t.prior_weight_s,
            energy_scale_bounds: (lo, hi),
            fit_headroom: t.fit_headroom,
        })
    }

    fn err(&self, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
        SpecError::new(self.path, entry, reason)
    }

    fn finite_nonneg(&self, entry: String, x: f64, what: &str) -> Result<(), SpecError> {
        if !x.is_finite() || x < 0.0 {
            Err(self.err(
                entry,
                format!("{what} must be a finite non-negative number, got {x}"),
            ))
        } else {
            Ok(())
        }
    }

    /// Goals, in the user's order; each listed once, each with a bound.
    fn goals(&self) -> Result<Vec<Goal>, SpecError> {
        let f = self.f;
        if f.mission.goal_order.is_empty() {
            return Err(self.err(
                "mission.goal_order",
                "at least one end-oriented goal is required",
            ));
        }
        let mut goals = Vec::new();
        let mut seen = BTreeSet::new();
        for (k, name) in f.mission.goal_order.iter().enumerate() {
            let entry = format!("mission.goal_order[{k}]");
            let g = f.goals.get(name).ok_or_else(|| {
                self.err(
                    entry.clone(),
                    format!(
                        "unknown goal `{name}` (defined: {})",
                        f.goals.keys().cloned().collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
            if !seen.insert(name.clone()) {
                return Err(self.err(entry, format!("goal `{name}` listed twice")));
            }
            if name != ENERGY && name != DURATION {
                return Err(self.err(
                    format!("goals.{name}"),
                    format!("no model for indicator `{name}` (known: {ENERGY}, {DURATION})"),
                ));
            }
            let bound = self.goal_bound(name, g)?;
            self.finite_nonneg(
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
                return Err(self.err(
                    format!("goals.{name}"),
                    "goal not listed in mission.goal_order",
                ));
            }
        }
        Ok(goals)
    }

    /// A goal's bound: given, or (energy) the battery's usable energy above the reserve.
    fn goal_bound(&self, name: &str, g: &GoalFile) -> Result<f64, SpecError> {
        match (g.bound, g.from_battery, &self.f.battery) {
            (Some(b), false, _) => Ok(b),
            (None, true, Some(b)) if name == ENERGY => {
                for (k, x) in [("capacity_wh", b.capacity_wh), ("reserve_wh", b.reserve_wh)] {
                    self.finite_nonneg(format!("battery.{k}"), x, "energy")?;
                }
                if !(0.0..=1.0).contains(&b.usable_fraction) {
                    return Err(self.err("battery.usable_fraction", "must be within [0, 1]"));
                }
                Ok((b.capacity_wh * b.usable_fraction - b.reserve_wh) * 3600.0)
            }
            (None, true, None) => {
                Err(self.err(format!("goals.{name}.from_battery"), "no [battery] table"))
            }
            _ => Err(self.err(
                format!("goals.{name}"),
                "give exactly one of `bound` or `from_battery = true` (energy only)",
            )),
        }
    }

    fn selection(&self, goals: &[Goal]) -> Result<Selection, SpecError> {
        let m = &self.f.mission;
        match (m.selection.as_str(), &m.selection_goal) {
            ("most_capable", None) => Ok(Selection::MostCapable),
            ("highest_cost", Some(g)) => Ok(Selection::HighestCost(
                goals.iter().position(|x| &x.name == g).ok_or_else(|| {
                    self.err("mission.selection_goal", format!("unknown goal `{g}`"))
                })?,
            )),
            (s, _) => Err(self.err(
                "mission.selection",
                format!("`{s}`: expected `most_capable`, or `highest_cost` with `selection_goal`"),
            )),
        }
    }

    /// Powers and the compute table are finite and non-negative.
    fn check_powers(&self) -> Result<(), SpecError> {
        let f = self.f;
        self.finite_nonneg(
            "base.power_w".into(),
            f.base.power_w,
            "power (negative energy)",
        )?;
        for (name, r) in &f.resources {
            self.finite_nonneg(
                format!("resources.{name}.power_w"),
                r.power_w,
                "power (negative energy)",
            )?;
        }
        if let Some(c) = &f.compute {
            self.finite_nonneg(
                "compute.cpu_w_per_core".into(),
                c.cpu_w_per_core,
                "power (negative energy)",
            )?;
            self.finite_nonneg("compute.tile_w".into(), c.tile_w, "power (negative energy)")?;
            self.finite_nonneg("compute.cores".into(), c.cores, "core count")?;
        }
        Ok(())
    }

    /// Tasks and their TIOs, checked against the resources and the platform.
    fn tasks(&self) -> Result<Tasks<'f>, SpecError> {
        let f = self.f;
        let mut tasks: Tasks<'f> = BTreeMap::new();
        for (tname, t) in &f.tasks {
            if t.tios.is_empty() {
                return Err(self.err(
                    format!("tasks.{tname}.tios"),
                    "a task needs at least one TIO",
                ));
            }
            let mut names = BTreeSet::new();
            for (k, tio) in t.tios.iter().enumerate() {
                let e = format!("tasks.{tname}.tios[{k}]");
                if !names.insert(tio.name.as_str()) {
                    return Err(self.err(e, format!("duplicate TIO `{}`", tio.name)));
                }
                self.check_tio(e, tio)?;
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
        Ok(tasks)
    }

    fn check_tio(&self, e: String, tio: &TioFile) -> Result<(), SpecError> {
        let f = self.f;
        let tiles_total = self.tiles_total;
        for r in &tio.resources {
            if !f.resources.contains_key(r) {
                return Err(self.err(
                    format!("{e}.resources"),
                    format!("unknown resource `{r}` (not in [resources])"),
                ));
            }
        }
        self.finite_nonneg(format!("{e}.time_s"), tio.time_s, "time")?;
        self.finite_nonneg(format!("{e}.cpu_load"), tio.cpu_load, "CPU load")?;
        if let Some(v) = tio.v_max_mps
            && !(v.is_finite() && v > 0.0)
        {
            return Err(self.err(format!("{e}.v_max_mps"), format!("must be > 0, got {v}")));
        }
        if (tio.tiles > 0 || tio.cpu_load > 0.0) && f.compute.is_none() {
            return Err(self.err(
                e,
                "uses CPU or tiles but the mission has no [compute] table",
            ));
        }
        if tio.tiles as usize > tiles_total && f.compute.is_some() {
            return Err(self.err(
                format!("{e}.tiles"),
                format!("{} tiles > {tiles_total} on the platform", tio.tiles),
            ));
        }
        Ok(())
    }

    /// Constraint classes: every rule names a known task, TIO and resource.
    fn check_constraints(&self, tasks: &Tasks) -> Result<(), SpecError> {
        let f = self.f;
        for (cname, c) in &f.constraints {
            for (k, rule) in c.rules.iter().enumerate() {
                let e = format!("constraints.{cname}.rules[{k}]");
                let (task, _) = tasks.get(rule.task()).ok_or_else(|| {
                    self.err(
                        format!("{e}.task"),
                        format!("unknown task `{}`", rule.task()),
                    )
                })?;
                match rule {
                    CoreConstraint::Require { resource, .. }
                    | CoreConstraint::Forbid { resource, .. } => {
                        if !f.resources.contains_key(resource) {
                            return Err(self.err(
                                format!("{e}.resource"),
                                format!("unknown resource `{resource}`"),
                            ));
                        }
                    }
                    CoreConstraint::Only { tios, .. } => {
                        for t in tios {
                            if !task.tios.iter().any(|x| &x.name == t) {
                                return Err(self.err(
                                    format!("{e}.tios"),
                                    format!("unknown TIO `{t}` for task `{}`", task.name),
                                ));
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Activity `j`: its IAs (the TIO combinations its constraints leave) costed, those that
    /// never fit the platform left out.
    fn activity(
        &self,
        j: usize,
        goals: &[Goal],
        tasks: &Tasks<'f>,
    ) -> Result<(Activity, ActivityInfo), SpecError> {
        let f = self.f;
        let a = &f.activities[j];
        let e = format!("activities[{j}]");
        if a.tasks.is_empty() {
            return Err(self.err(format!("{e}.tasks"), "an activity needs at least one task"));
        }
        let mut ts = Vec::new();
        let mut tfs = Vec::new();
        for (k, t) in a.tasks.iter().enumerate() {
            let (task, tf) = tasks.get(t.as_str()).ok_or_else(|| {
                self.err(format!("{e}.tasks[{k}]"), format!("unknown task `{t}`"))
            })?;
            ts.push(task.clone());
            tfs.push(*tf);
        }
        let mut rules = Vec::new();
        for (k, c) in a.constraints.iter().enumerate() {
            let class = f.constraints.get(c).ok_or_else(|| {
                self.err(
                    format!("{e}.constraints[{k}]"),
                    format!("unknown constraint class `{c}`"),
                )
            })?;
            rules.extend(class.rules.iter().cloned());
        }
        self.finite_nonneg(format!("{e}.length_m"), a.length_m, "length")?;
        self.finite_nonneg(format!("{e}.hold_s"), a.hold_s, "time")?;
        self.finite_nonneg(format!("{e}.hold_speed_mps"), a.hold_speed_mps, "speed")?;
        let n_all: usize = ts.iter().map(|t| t.tios.len()).product();
        let combos = panorama::combine(&ts, &rules);
        if combos.is_empty() {
            return Err(self.err(
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
        let mut ia_hold_w = Vec::new();
        for combo in combos {
            let tios: Vec<&TioFile> = combo
                .iter()
                .enumerate()
                .map(|(k, &i)| &tfs[k].tios[i])
                .collect();
            if let Some((ia, names, speed, hold_w)) = self.ia(&e, a, &tios, goals)? {
                ias.push(ia);
                ia_tios.push(names);
                ia_speed.push(speed);
                ia_hold_w.push(hold_w);
            }
        }
        if ias.is_empty() {
            return Err(self.err(
                e.to_string(),
                format!(
                    "activity `{}`: no alternative fits the platform's CPU and tiles",
                    a.name
                ),
            ));
        }
        let _ = (a.x_start_m, a.x_end_m);
        Ok((
            Activity {
                name: a.name.clone(),
                ias,
            },
            ActivityInfo {
                name: a.name.clone(),
                objective: a.objective.clone(),
                env: a.env.clone(),
                tasks: a.tasks.clone(),
                constraints: a.constraints.clone(),
                ia_tios,
                ia_speed,
                n_ia_unconstrained: n_all,
                hold_s: a.hold_s,
                hold_kind: a.hold_kind,
                ia_hold_w,
            },
        ))
    }

    /// One IA (a TIO per task) costed: speed (the activity's cap and the TIOs'), duration,
    /// energy (propulsion, payload, compute). `None` when it never fits the platform.
    fn ia(
        &self,
        e: &str,
        a: &ActivityFile,
        tios: &[&TioFile],
        goals: &[Goal],
    ) -> Result<Option<CostedIa>, SpecError> {
        let f = self.f;
        let mut resources: BTreeSet<String> = tios
            .iter()
            .flat_map(|t| t.resources.iter().cloned())
            .collect();
        let speed = if a.length_m > 0.0 {
            // A commanded speed is what the vehicle flies whichever IA runs (no IA commands its
            // own); otherwise the slowest TIO caps it.
            let cap = if a.speed_commanded {
                f64::INFINITY
            } else {
                tios.iter()
                    .filter_map(|t| t.v_max_mps)
                    .fold(f64::INFINITY, f64::min)
            };
            let v = a.v_max_mps.unwrap_or(f64::INFINITY).min(cap);
            if !(v.is_finite() && v > 0.0) {
                return Err(self.err(
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
            return Err(self.err(
                e.to_string(),
                format!(
                    "IA `{name}` has negative or non-finite energy {energy} J (check the propulsion model)"
                ),
            ));
        }
        if let Some(c) = &f.compute
            && (cpu > c.cores + 1e-9 || tiles as usize > self.tiles_total)
        {
            return Ok(None); // never placeable on the platform: not an alternative
        }
        for k in 1..=tiles as usize {
            resources.insert(tile_slot(k));
        }
        let mut cost = vec![0.0; goals.len()];
        if let Some(i) = goals.iter().position(|g| g.name == ENERGY) {
            cost[i] = energy;
        }
        if let Some(i) = goals.iter().position(|g| g.name == DURATION) {
            cost[i] = duration;
        }
        let ia = Ia {
            name: name.clone(),
            cost,
            capability: tios.iter().map(|t| t.capability).sum(),
            resources: resources.into_iter().collect(),
        };
        // d(energy)/d(hold_s): the hold's propulsion and the payload over the longer duration.
        let hold_w = f.propulsion.power(a.hold_speed_mps) + payload_w;
        Ok(Some((
            ia,
            tios.iter().map(|t| t.name.clone()).collect(),
            speed,
            hold_w,
        )))
    }
}
