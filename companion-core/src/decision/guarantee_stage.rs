//! The guarantee stage of the cycle (PANORAMA): the plan bound to what runs, the activity
//! watched against its allocation, re-allocation, and what is said of a drift. It owns the
//! guarantee in force and what the cycle keeps of it: the versions capped, the activity flown,
//! the resources failed, the implementations each allocation names.

use super::read_slots::{self, ReadSlots};
use super::{Model, Observations};
use crate::arbitration::{PlannedVariant, planned_variants};
use crate::guarantee::{Guarantee, MissionSpec, Progress};
use crate::readings::Readings;
use crate::record::{DecisionRecord, Event};
use crate::scratch::Scratch;

/// The guarantee in force and the cycle's memory of it.
pub(super) struct GuaranteeStage {
    guarantee: Option<Guarantee>,
    /// Set when the guarantee stage found no allocation meeting the goals.
    guarantee_infeasible: bool,
    /// The slot of the probability the guarantee caps when infeasible (`None`: not published).
    capped_slot: Option<usize>,
    /// Probabilities (`P_V3`) of the versions no feasible alternative of the activity being
    /// flown carries, capped from the next cycle (guarantee/binding.rs).
    capped_versions: Vec<String>,
    /// The versions (`V3`) whose probabilities are in `capped_versions`.
    capped_for: Vec<String>,
    /// Scratch: the versions without a feasible alternative, as the guarantee names them.
    versions_scratch: Vec<String>,
    /// The last cycle's re-allocation event text, kept to be rewritten (a version flipping
    /// every cycle is a plan-follow every cycle: no allocation for its event once warm).
    reallocation_event: String,
    failed_resources: Vec<String>,
    /// The activity being flown, when it started (s) and on which clock (true: the autopilot's
    /// `vehicle_time_s`, false: the observation time).
    activity_started: Option<(usize, f64, bool)>,
    /// Per activity of the guarantee's mission, per alternative: the implementations it names.
    planned: Vec<Vec<Vec<PlannedVariant>>>,
}

/// Per activity of the guarantee's mission, per alternative: the implementations it names.
fn planned_of(guarantee: Option<&Guarantee>, model: &Model) -> Vec<Vec<Vec<PlannedVariant>>> {
    guarantee.map_or_else(Vec::new, |g| {
        let cat = &model.resources.catalogue;
        (g.spec.problem.activities.iter())
            .map(|a| {
                a.ias
                    .iter()
                    .map(|ia| planned_variants(&ia.name, cat))
                    .collect()
            })
            .collect()
    })
}

/// `names` into `into`, reusing its strings (the cycle allocates nothing once warm).
fn refill<'a>(into: &mut Vec<String>, names: impl Iterator<Item = &'a str>) {
    let mut len = 0;
    for name in names {
        if len == into.len() {
            into.push(String::new());
        }
        into[len].clear();
        into[len].push_str(name);
        len += 1;
    }
    into.truncate(len);
}

impl GuaranteeStage {
    /// The model's mission allocated before flight ([`Guarantee::start_or_unbounded`]).
    pub(super) fn new(model: &Model) -> Self {
        let guarantee = Guarantee::start_or_unbounded(model.guarantee.clone());
        GuaranteeStage {
            planned: planned_of(guarantee.as_ref(), model),
            guarantee,
            guarantee_infeasible: false,
            capped_slot: (model.health.slot_names())
                .binary_search(&model.mission.guarantee.capped_probability)
                .ok(),
            capped_versions: Vec::new(),
            capped_for: Vec::new(),
            versions_scratch: Vec::new(),
            reallocation_event: String::new(),
            failed_resources: Vec::new(),
            activity_started: None,
        }
    }

    /// [`super::Core::replace_mission`].
    pub(super) fn replace_mission(&mut self, model: &Model, spec: MissionSpec) -> bool {
        self.guarantee = Guarantee::start_or_unbounded(spec);
        self.mission_changed(model);
        self.guarantee.is_some()
    }

    /// What the guarantee in force planned, after it changed; the activity flown forgotten.
    fn mission_changed(&mut self, model: &Model) {
        self.planned = planned_of(self.guarantee.as_ref(), model);
        self.guarantee_infeasible = false;
        self.capped_versions.clear();
        self.capped_for.clear();
        self.activity_started = None;
    }

    /// [`super::Core::replan_from`].
    pub(super) fn replan_from(&mut self, model: &Model, spec: MissionSpec, flown: usize) -> bool {
        let Some(g) = self.guarantee.as_ref() else {
            return self.replace_mission(model, spec);
        };
        let Some(next) = g.replan_from(spec.clone(), flown) else {
            return self.replace_mission(model, spec);
        };
        self.guarantee = Some(next);
        self.mission_changed(model);
        true
    }

    /// The guarantee in force (`None`: off, pre-flight infeasible).
    pub(super) fn in_force(&self) -> Option<&Guarantee> {
        self.guarantee.as_ref()
    }

    /// Keep a re-allocation event's text of the record being overwritten, to be rewritten.
    pub(super) fn keep_event_text(&mut self, text: String) {
        self.reallocation_event = text;
    }

    /// PANORAMA -> BFM: when no allocation meets the goals the capped probability is held at
    /// most the infeasible cap, and a version no feasible alternative carries is improbable, so
    /// no MDP proposes it (docs/guarantee.md "One configuration").
    pub(super) fn cap_probabilities(&self, model: &Model, rec: &mut DecisionRecord) {
        let cap = model.mission.guarantee.infeasible_p_battery;
        if self.guarantee_infeasible
            && let Some(p) = self.capped_slot.and_then(|k| rec.probabilities.slot_mut(k))
        {
            *p = p.min(cap);
        }
        for name in &self.capped_versions {
            if let Some(p) = rec.probabilities.get_mut(name) {
                *p = p.min(cap);
            }
        }
    }

    /// The implementations the allocation in force names for the activity being flown
    /// (PANORAMA's plan, `gps_vision fusion V4.F`), when the plan binds.
    pub(super) fn planned_now(
        &self,
        model: &Model,
        (slots, r): (&ReadSlots, &Readings),
        state: &str,
    ) -> Option<&[PlannedVariant]> {
        let g = self
            .guarantee
            .as_ref()
            .filter(|_| model.mission.guarantee.binds)?;
        let n = g.spec.problem.activities.len();
        let activity = read_slots::activity_index(model, slots, r, state, n)?;
        let ia = g.allocated_index(activity)?;
        self.planned.get(activity)?.get(ia).map(Vec::as_slice)
    }

    /// One configuration: the plan follows what runs (guarantee/binding.rs), and the versions
    /// no feasible alternative carries are capped from the next cycle, with an event when that
    /// set changes.
    fn bind_plan(&mut self, model: &Model, activity_index: usize, rec: &mut DecisionRecord) {
        let (Some(g), Some(record)) = (self.guarantee.as_mut(), rec.guarantee.as_mut()) else {
            return;
        };
        if let Some(res) = &rec.resources {
            g.follow(activity_index, &res.placements, record);
        }
        let mut versions = std::mem::take(&mut self.versions_scratch);
        g.versions_without_alternative(activity_index, &mut versions);
        // The versions capped last time, compared as the guarantee names them; their
        // probabilities are the ones their activation nodes publish (the list the health layer
        // builds from params/variants.toml), not a name made from the version's.
        if versions != self.capped_for {
            self.capped_for.clone_from(&versions);
            self.capped_versions.clear();
            for a in &model.health.activations {
                if versions.contains(&a.version) {
                    self.capped_versions.extend(a.published.iter().cloned());
                }
            }
            if !self.capped_versions.is_empty() {
                rec.events.push(Event::VersionsCapped {
                    versions: versions.clone(),
                    capped: self.capped_versions.clone(),
                    at: model.mission.guarantee.infeasible_p_battery,
                });
            }
        }
        self.versions_scratch = versions;
    }

    /// The activity being flown watched against its allocation: margins, drift, re-allocation,
    /// what runs against what was planned, and the plan bound to what runs. `n_tiles`: the
    /// platform's tiles, the last failed ones named as the guarantee's resources.
    pub(super) fn watch(
        &mut self,
        model: &Model,
        (read_slots, readings): (&ReadSlots, &Readings),
        n_tiles: usize,
        sc: &mut Scratch,
        obs: &Observations,
        rec: &mut DecisionRecord,
    ) {
        let Some(g) = self.guarantee.as_mut() else {
            rec.guarantee = None;
            return;
        };
        let coupling = &model.mission.guarantee;
        let n = g.spec.problem.activities.len();
        let (slots, r) = (read_slots, readings);
        let Some(activity_index) = read_slots::activity_index(model, slots, r, &obs.state, n)
        else {
            rec.guarantee = None;
            return;
        };
        for (resource, slot) in &read_slots.failures {
            if readings.get(*slot).is_some_and(|v| v > 0.5)
                && !self.failed_resources.contains(resource)
            {
                self.failed_resources.push(resource.clone());
            }
        }
        let failed_tiles = readings
            .get(read_slots.failed_tiles)
            .unwrap_or(0.0)
            .max(0.0) as usize;
        let tile_names = (0..failed_tiles.min(n_tiles)).map(|k| {
            g.spec
                .tile_names
                .get(n_tiles - 1 - k)
                .map_or("", String::as_str)
        });
        let failed = &mut sc.failed;
        refill(
            failed,
            self.failed_resources
                .iter()
                .map(String::as_str)
                .chain(tile_names),
        );
        // How far into the activity: time spent in it over its estimated duration (capped below
        // 1 so an overrunning activity still counts its remainder as not yet flown). The time is
        // the autopilot's when it reports it, as the plan's durations are the vehicle's (a SITL
        // faster than real time flies an activity in a third of the wall clock's seconds).
        let vehicle_now = read_slots.pack(readings).vehicle_time_s;
        let (now, on_vehicle) = vehicle_now.map_or((obs.time_s, false), |t| (t, true));
        let started = match self.activity_started {
            Some((a, t, v)) if a == activity_index && v == on_vehicle => t,
            _ => {
                self.activity_started = Some((activity_index, now, on_vehicle));
                now
            }
        };
        let fraction = g
            .estimated(activity_index, &coupling.progress_goal)
            .filter(|d| *d > 0.0)
            .map_or(0.0, |d| ((now - started) / d).clamp(0.0, 0.95));
        let record = rec.guarantee.get_or_insert_with(Default::default);
        g.watch_into(
            Progress {
                activity_index,
                activity_fraction: fraction,
                energy_used_j: readings.get(read_slots.energy_consumed_j),
                battery_remaining_pct: readings.get(read_slots.battery_pct),
                elapsed_s: obs.time_s,
                failed_resources: failed,
                pack: read_slots.pack(readings),
            },
            record,
        );
        if let Some(drift) = drift_event(record, model.guarantee.tuning.power_drift_tolerance) {
            rec.events.push(drift);
        }
        // The allocation's application alternatives (`V4.F`, `zone_t.F`) against what was placed.
        let mut n_differs = 0;
        let cell = g.allocated_index(activity_index);
        let planned = cell.and_then(|i| self.planned.get(activity_index)?.get(i));
        if let (Some(planned), Some(res)) = (planned, &rec.resources) {
            for pv in planned {
                let (version, imp) = (pv.version.as_str(), pv.implementation.as_str());
                let Some(app) = pv.app.as_deref() else {
                    continue;
                };
                let Some(p) = res.placements.iter().find(|p| p.app == app) else {
                    continue;
                };
                if p.version != version || p.implementation != imp {
                    use std::fmt::Write;
                    // Strings reused between cycles (the cycle allocates nothing once warm).
                    if n_differs == record.plan_differs.len() {
                        record.plan_differs.push(String::new());
                    }
                    let line = &mut record.plan_differs[n_differs];
                    line.clear();
                    let _ = write!(
                        line,
                        "{app}: allocation plans {version}.{imp}, {} {} runs",
                        p.version, p.implementation
                    );
                    // Why: the proposal that started this application, and what it read of the
                    // planned and the running version (the allocation is only an estimate).
                    let actions = &model.actions;
                    let proposal = rec.proposals.iter().rev().find(|pr| {
                        (actions.actions_of(&pr.actions)).any(|x| x.app.as_deref() == Some(app))
                    });
                    if p.version != version
                        && let Some(pr) = proposal
                    {
                        let _ = write!(line, ": the {} MDP chose {}", pr.mdp, pr.action);
                        let mut sep = " reading ";
                        // A version's probabilities are the ones its activation node publishes
                        // (the list the health layer builds from params/variants.toml).
                        let activations = &model.health.activations;
                        let publishes = |v: &str, name: &str| {
                            activations.iter().any(|a| {
                                a.app == app
                                    && a.version == v
                                    && a.published.iter().any(|n| n == name)
                            })
                        };
                        for (name, value) in &pr.inputs {
                            if publishes(version, name) || publishes(&p.version, name) {
                                let _ = write!(line, "{sep}{name} = {value:.3}");
                                sep = ", ";
                            }
                        }
                    } else {
                        let _ = write!(
                            line,
                            ": the planned implementation does not fit beside what runs or is too slow for the rate, so the just-enough one runs"
                        );
                    }
                    let _ = write!(
                        line,
                        " (the allocation's alternative is its energy and duration estimate)"
                    );
                    n_differs += 1;
                }
            }
        }
        record.plan_differs.truncate(n_differs);
        // One configuration (after `plan_differs`, which compares what ran with the plan this
        // cycle requested).
        if coupling.binds {
            self.bind_plan(model, activity_index, rec);
        }
        let Some(record) = rec.guarantee.as_ref() else {
            return;
        };
        if let Some(r) = &record.reallocation {
            let mut text = std::mem::take(&mut self.reallocation_event);
            text.clone_from(&r.reason);
            rec.events.push(Event::Reallocation(text));
        }
        if record.infeasible && !self.guarantee_infeasible {
            rec.events.push(Event::GuaranteeInfeasible);
        }
        self.guarantee_infeasible = record.infeasible;
    }
}

fn drift_event(record: &crate::record::GuaranteeRecord, tolerance: f64) -> Option<Event> {
    let pw = record.power.as_ref().filter(|pw| pw.drift_began)?;
    Some(Event::PerformanceDrift {
        activity: record.activity_name.clone(),
        measured_j: pw.measured_j.unwrap_or(0.0),
        predicted_j: pw.predicted_j,
        activity_s: pw.activity_s,
        ratio: pw.ratio.unwrap_or(1.0),
        tolerance_pct: tolerance * 100.0,
        energy_scale: pw.energy_scale,
    })
}
