//! The guarantee stage of the cycle (PANORAMA): the plan bound to what runs, the activity
//! watched against its allocation, re-allocation, and what is said of a drift. Its share of
//! `Core`'s fields is the guarantee's (`guarantee`, `capped_versions`, `guarantee_infeasible`, ...).

use super::*;
use crate::record::Event;

impl Core {
    /// One configuration: the plan follows what runs (guarantee/binding.rs), and the versions
    /// no feasible alternative carries are capped from the next cycle, with an event when that
    /// set changes.
    pub(super) fn bind_plan(&mut self, activity_index: usize, rec: &mut DecisionRecord) {
        let model = Arc::clone(&self.model);
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

    pub(super) fn watch_guarantee(
        &mut self,
        sc: &mut Scratch,
        obs: &Observations,
        rec: &mut DecisionRecord,
    ) {
        let Some(g) = self.guarantee.as_mut() else {
            rec.guarantee = None;
            return;
        };
        let coupling = &self.model.mission.guarantee;
        let n = g.spec.problem.activities.len();
        let (slots, r) = (&self.read_slots, &self.readings);
        let Some(activity_index) = read_slots::activity_index(&self.model, slots, r, &obs.state, n)
        else {
            rec.guarantee = None;
            return;
        };
        for (resource, slot) in &self.read_slots.failures {
            if self.readings.get(*slot).is_some_and(|v| v > 0.5)
                && !self.failed_resources.contains(resource)
            {
                self.failed_resources.push(resource.clone());
            }
        }
        let failed_tiles = (self.readings)
            .get(self.read_slots.failed_tiles)
            .unwrap_or(0.0)
            .max(0.0) as usize;
        let n_tiles = self.platform.tiles.len();
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
        let vehicle_now = self.read_slots.pack(&self.readings).vehicle_time_s;
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
                energy_used_j: self.readings.get(self.read_slots.energy_consumed_j),
                battery_remaining_pct: self.readings.get(self.read_slots.battery_pct),
                elapsed_s: obs.time_s,
                failed_resources: failed,
                pack: self.read_slots.pack(&self.readings),
            },
            record,
        );
        if let Some(drift) =
            watch::drift_event(record, self.model.guarantee.tuning.power_drift_tolerance)
        {
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
                    let actions = &self.model.actions;
                    let proposal = rec.proposals.iter().rev().find(|pr| {
                        pr.actions
                            .iter()
                            .any(|a| actions.get(a).and_then(|x| x.app.as_deref()) == Some(app))
                    });
                    if p.version != version
                        && let Some(pr) = proposal
                    {
                        let _ = write!(line, ": the {} MDP chose {}", pr.mdp, pr.action);
                        let mut sep = " reading ";
                        // A version's probabilities are the ones its activation node publishes
                        // (the list the health layer builds from params/variants.toml).
                        let activations = &self.model.health.activations;
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
            self.bind_plan(activity_index, rec);
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

pub(super) fn drift_event(
    record: &crate::record::GuaranteeRecord,
    tolerance: f64,
) -> Option<Event> {
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
