//! One decision cycle: observations -> evidence -> health -> concurrent MDPs -> behaviour
//! arbitration -> resource arbitration (fpga_model) -> guarantee (PANORAMA) -> plan + record.
//!
//! `Core::step` is pure: everything it needs comes in as the loaded [`Model`], the state the
//! core carries between cycles (its own fields) and one [`Observations`] snapshot. No clock, file,
//! socket or randomness.

use crate::action_id::ActionIds;
use crate::mission::ActionKind;
pub use crate::mission::Policy;
pub use crate::model::{Model, ModelKind};
use crate::observations::Observations;
use crate::readings::Readings;
use crate::record::{DecisionRecord, Event, Plan};
use crate::scratch::Scratch;
use crate::stage_hook::{Stage, mark};
use std::sync::Arc;

/// A decision core bound to a model, a model kind and a policy; `step` once per cycle. Each
/// stage of the cycle owns its state; the core keeps what they all read (the model, the
/// snapshot's readings) and runs them in order.
pub struct Core {
    /// The loaded params this core decides with (shared, never changed: cores of several runs
    /// may hold the same one).
    pub model: Arc<Model>,
    /// Which MDPs decide (concurrent, reference or monolithic).
    pub kind: ModelKind,
    /// Decision policy whose rewards and priorities apply.
    pub policy: Policy,
    cycle: u64,
    /// The snapshot's values this cycle by slot, and the slots each stage reads.
    readings: Readings,
    read_slots: ReadSlots,
    /// Evidence, health managers and MDPs.
    health_mdp: HealthMdpStage,
    /// The platform model, its room and the resource arbitration.
    platform: PlatformStage,
    /// PANORAMA: the allocation in force, watched.
    guarantee: GuaranteeStage,
    scratch: Scratch,
}

/// How much work the cycles so far really did (the rest came from the memos).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WorkDone {
    /// Decision cycles stepped.
    pub cycles: u64,
    /// MDP solves actually run (memo hits not counted).
    pub mdp_solves: u64,
    /// Platform scheduler runs actually made (memo hits not counted).
    pub scheduler_runs: u64,
}

/// At most this many re-solves per cycle (one per version the MDP may turn to is plenty).
const MAX_RESOLVES: usize = 3;

impl Core {
    /// A core at cycle 0 with fresh copies of the model's stateful parts.
    pub fn new(model: Arc<Model>, kind: ModelKind, policy: Policy) -> Self {
        let (readings, read_slots) = ReadSlots::resolve(&model, &model.mdp_names(kind));
        Core {
            kind,
            policy,
            cycle: 0,
            readings,
            read_slots,
            health_mdp: HealthMdpStage::new(&model, kind, policy),
            platform: PlatformStage::new(&model),
            guarantee: GuaranteeStage::new(&model),
            scratch: Scratch::default(),
            model,
        }
    }

    /// Plan `spec` from now on in place of the mission the guarantee watched (the autopilot's
    /// mission, downloaded again after a ground station changed it): its pre-flight allocation
    /// is made afresh and the activity being flown forgotten; the health and decision state stay.
    /// `false` when the new mission has no allocation at all (no implementation alternative: the
    /// guarantee stage is then off); one whose goals cannot be met is allocated with their bounds
    /// lifted and its margins, negative, refuse the launch, as at start
    /// ([`Guarantee::start_or_unbounded`]).
    pub fn replace_mission(&mut self, spec: crate::guarantee::MissionSpec) -> bool {
        self.guarantee.replace_mission(&self.model, spec)
    }

    /// A mission changed in flight, planned from the point reached ([`Guarantee::replan_from`];
    /// without a guarantee in force, as [`Core::replace_mission`]).
    pub fn replan_from(&mut self, spec: crate::guarantee::MissionSpec, flown: usize) -> bool {
        self.guarantee.replan_from(&self.model, spec, flown)
    }

    /// Work done by the cycles stepped so far.
    pub fn work_done(&self) -> WorkDone {
        WorkDone {
            cycles: self.cycle,
            mdp_solves: self.health_mdp.solves(),
            scheduler_runs: self.platform.scheduler_runs(),
        }
    }

    /// Turn the memos (MDP solves, health queries, resource schedules) on or off. Off, every
    /// cycle re-solves every MDP, re-runs the scheduler and runs every BN query whose inputs
    /// changed since its last: the worst case, and the reference the memos are
    /// tested against. Outputs are identical either way.
    pub fn set_caches(&mut self, on: bool) {
        self.health_mdp.set_caches(on);
        self.platform.set_caches(on);
    }

    /// The PANORAMA allocations in force so far (RAS0 then each re-allocation), in the shape of
    /// PANORAMA's Table 7; `None` when the guarantee stage is off (pre-flight infeasible).
    pub fn allocation_table(&self) -> Option<String> {
        let g = self.guarantee.in_force()?;
        Some(crate::report::guarantee::render_ras_table(
            &g.spec,
            g.ras_rows(),
        ))
    }

    /// Number of re-allocations so far (RAS0 not counted).
    pub fn reallocations(&self) -> usize {
        (self.guarantee.in_force()).map_or(0, |g| g.reallocations())
    }

    /// A CPT row of this core's health model (docs/calibrate.md, in-flight learning: the shell
    /// reads and sets the rows between cycles; the cycle itself stays pure).
    pub fn cpt_row(&self, node: &str, when: &[(String, String)]) -> Option<Vec<f64>> {
        self.health_mdp.health.cpt_row(node, when)
    }

    /// Set a CPT row of this core's health model, in force from the next cycle (`--learn-cpt`).
    pub fn set_cpt_row(
        &mut self,
        node: &str,
        when: &[(String, String)],
        p: &[f64],
    ) -> Result<(), crate::health::HealthError> {
        self.health_mdp.health.set_cpt_row(node, when, p)
    }

    /// One decision cycle.
    pub fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        let mut plan = Plan::default();
        let mut rec = DecisionRecord::default();
        self.step_into(obs, &mut plan, &mut rec);
        (plan, rec)
    }

    /// The record's inputs copied in (strings and maps reused), the cycle counted.
    fn begin_record(&mut self, obs: &Observations, rec: &mut DecisionRecord) {
        rec.cycle = self.cycle;
        rec.time_s = obs.time_s;
        rec.state.clone_from(&obs.state);
        if let Some(Event::Reallocation(s)) = rec
            .events
            .iter_mut()
            .skip(obs.events.len())
            .find(|e| matches!(e, Event::Reallocation(_)))
        {
            self.guarantee.keep_event_text(std::mem::take(s));
        }
        rec.events.clone_from(&obs.events);
        rec.observations.clone_from(&obs.values);
        rec.commands.clear();
        rec.link_events.clear();
        rec.vehicle.clear();
        self.cycle += 1;
    }

    /// One decision cycle into the caller's buffers: `plan` and `rec` are overwritten (the result
    /// equals [`Core::step`]'s whatever they held) and keep their capacity, so a steady stream of
    /// observations of the same shape allocates nothing once warm (tests/cycle_no_alloc.rs).
    pub fn step_into(&mut self, obs: &Observations, plan: &mut Plan, rec: &mut DecisionRecord) {
        mark(Stage::CycleStart);
        let model = Arc::clone(&self.model);
        let model = &*model;
        self.begin_record(obs, rec);
        self.readings.read(obs);
        mark(Stage::Record);

        // evidence -> health (the platform's room comes from the core's own platform model)
        let at = (&self.read_slots, &self.readings);
        self.platform.update(at);
        let extra = self.platform.room_evidence(model, at);
        self.health_mdp.record_evidence(&self.readings, extra, rec);
        mark(Stage::Evidence);
        self.health_mdp.write_probabilities(rec);
        self.guarantee.cap_probabilities(model, rec);

        // decision: every MDP of the model, solved at its projected state
        let mut sc = std::mem::take(&mut self.scratch);
        let at = (&self.read_slots, &self.readings);
        (self.health_mdp).propose(model, self.policy, at, &obs.state, &mut sc, rec);

        // behaviour arbitration, then resource arbitration: application actions become variant
        // requests on the platform
        sc.superseded.clear();
        self.arbitrate(&mut sc, obs, rec);
        // A resource conflict the policy resolved against the assessed application (tracking):
        // the resource manager sees the room this cycle's placements leave, the MDP that chose
        // the application is solved again, and its new proposal is what runs.
        for _ in 0..MAX_RESOLVES {
            let resolved = self.resolve_conflict(&mut sc, rec);
            mark(Stage::Resolve);
            if !resolved {
                break;
            }
            self.arbitrate(&mut sc, obs, rec);
        }
        self.record_resource_conflicts(&sc, rec);
        self.platform.note_others(model, self.policy, rec);
        // By id over the catalogue's names: named only when the record is written.
        rec.actions
            .set(model.actions.names(), sc.actions.iter().copied());
        mark(Stage::Arbitration);

        // guarantee: PANORAMA margins on the activity being flown
        let at = (&self.read_slots, &self.readings);
        let n_tiles = self.platform.tiles();
        (self.guarantee).watch(model, at, n_tiles, &mut sc, obs, rec);
        mark(Stage::Guarantee);

        // plan
        plan.vehicle_actions.clear();
        plan.vehicle_actions.extend(
            sc.actions
                .iter()
                .copied()
                .filter(|&a| model.actions.by_id(a).kind == ActionKind::Vehicle),
        );
        self.scratch = sc;
        match &rec.resources {
            Some(r) => plan.applications.clone_from(&r.placements),
            None => plan.applications.clear(),
        }
        mark(Stage::Record);
    }

    /// Behaviour arbitration over the live proposals, then resource arbitration.
    fn arbitrate(&mut self, sc: &mut Scratch, obs: &Observations, rec: &mut DecisionRecord) {
        let model = Arc::clone(&self.model);
        let model = &*model;
        self.health_mdp.merge_live(sc);
        if let Err(e) = model.conflicts.resolve_by(
            &sc.merged,
            model.actions.names(),
            // Model::policies lists the policies in the conflicts' order: the index is theirs.
            self.policy.index(),
            &mut sc.kept,
            &mut rec.conflicts,
        ) {
            rec.conflicts.clear();
            rec.events.push(Event::ArbitrationError(e.to_string()));
            sc.kept.clone_from(&sc.merged);
        }
        // The IA in force for the activity being flown (PANORAMA's plan, `gps_vision fusion
        // V4.F`): its implementations are requested for the versions the MDPs chose.
        let at = (&self.read_slots, &self.readings);
        let plan = self.guarantee.planned_now(model, at, &obs.state);
        (self.platform).arbitrate(model, self.policy, sc, at, plan, rec);
    }

    /// When the assessed application was requested but not placed: re-evaluate the resource
    /// manager on the room this cycle's placements leave, solve the MDP that chose the
    /// application again and record its new proposal. False when there is nothing to do or the
    /// MDP's choice does not change.
    fn resolve_conflict(&mut self, sc: &mut Scratch, rec: &mut DecisionRecord) -> bool {
        let model = Arc::clone(&self.model);
        let model = &*model;
        let Some(app) = platform_stage::assessed_app(model) else {
            return false;
        };
        let Some(res) = &rec.resources else {
            return false;
        };
        let requested = sc
            .key
            .iter()
            .any(|k| model.actions.by_id(k.0).app.as_deref() == Some(app));
        if !requested || res.placements.iter().any(|p| p.app == app) {
            return false;
        }
        let why = res
            .dropped
            .iter()
            .find(|d| d.app == app)
            .cloned()
            .unwrap_or_default();
        let Some(k) = self.health_mdp.last_starting(model, app, sc) else {
            return false;
        };
        // The room beside what was placed this cycle.
        self.platform.note_others(model, self.policy, rec);
        let at = (&self.read_slots, &self.readings);
        let extra = self.platform.room_evidence(model, at);
        let at = (&self.readings, extra);
        (self.health_mdp).resolve((model, self.policy), at, (k, &why), sc, rec)
    }

    /// Each application the resource policy left out becomes a conflict entry: the rule (policy
    /// rank and reason) and the action that gave way. A re-solve is one too: the earlier
    /// proposal's action gave way to the new one.
    fn record_resource_conflicts(&self, sc: &Scratch, rec: &mut DecisionRecord) {
        let model = &*self.model;
        let policy = model.policy_name(self.policy);
        for &k in &sc.superseded {
            let old = &rec.proposals[k];
            let new = rec.proposals[k + 1..]
                .iter()
                .rfind(|p| p.mdp == old.mdp)
                .map_or_else(ActionIds::default, |p| p.actions.clone());
            rec.conflicts.push(crate::record::Conflict {
                kept: new,
                dropped: old.actions.clone(),
                rule: format!("resource policy {policy}: {} re-solved", old.mdp),
            });
        }
        let Some(res) = &rec.resources else {
            return;
        };
        for d in &res.dropped {
            let app = d.app.as_str();
            let mut gave_way = ActionIds::over(model.actions.names());
            (sc.kept.iter())
                .filter(|&&a| model.actions.by_id(a).app.as_deref() == Some(app))
                .for_each(|&a| gave_way.push(a));
            if gave_way.is_empty() {
                continue;
            }
            rec.conflicts.push(crate::record::Conflict {
                kept: ActionIds::default(),
                dropped: gave_way,
                rule: format!("resource policy {policy}: {d}"),
            });
        }
    }
}

/// Evidence, the health managers and the MDPs: the health and decision stage.
mod health_mdp_stage;
use health_mdp_stage::HealthMdpStage;
/// The platform model, the room it leaves beside the other applications (what the resource
/// evidence reads) and the resource arbitration.
mod platform_stage;
use platform_stage::PlatformStage;
/// The guarantee stage (PANORAMA): the plan bound to what runs, the activity watched, drift.
mod guarantee_stage;
use guarantee_stage::GuaranteeStage;
mod read_slots;
use read_slots::ReadSlots;
/// The decision table (the paper's Tables 4 to 7) from a run's records.
mod table;
pub use table::table;

#[cfg(test)]
mod fit_tests;

#[cfg(test)]
mod tests;
