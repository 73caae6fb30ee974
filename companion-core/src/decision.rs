//! One decision cycle: observations -> evidence -> health -> concurrent MDPs -> behaviour
//! arbitration -> resource arbitration (fpga_model) -> guarantee (PANORAMA) -> plan + record.
//!
//! `Core::step` is pure: everything it needs comes in as the loaded [`Model`], the state the
//! core carries between cycles (its own fields) and one [`Observations`] snapshot. No clock, file,
//! socket or randomness.

use crate::arbitration::{ResourceArbiter, planned_variants};
use crate::guarantee::{Guarantee, Progress};
use crate::health::HealthModel;
use crate::mission::ActionKind;
pub use crate::mission::Policy;
use crate::mission_mdp::MissionMdps;
pub use crate::model::{Model, ModelKind};
use crate::observations::Observations;
use crate::readings::Readings;
use crate::record::{DecisionRecord, Event, Plan};
use crate::scratch::Scratch;
use crate::stage_hook::{Stage, mark};
use crate::vocabulary::ActionId;
use fpga_model::PlatformState;
use mdp_engine::Workspace;
use std::collections::BTreeMap;
use std::sync::Arc;

/// A decision core bound to a model, a model kind and a policy; `step` once per cycle.
pub struct Core {
    /// The loaded params this core decides with (shared, never changed: cores of several runs
    /// may hold the same one).
    pub model: Arc<Model>,
    /// Which MDPs decide (concurrent, reference or monolithic).
    pub kind: ModelKind,
    /// Decision policy whose rewards and priorities apply.
    pub policy: Policy,
    cycle: u64,
    mdp_names: Vec<String>,
    /// Per MDP of `mdp_names`: where the policy's rewards sit in it, resolved in `new` (`None`:
    /// the MDP has no rewards for the policy, an error each cycle as the name lookup gave).
    mdp_policy: Vec<Option<usize>>,
    /// Per MDP of `mdp_names`, the slot of each probability it reads among the published ones
    /// (`HealthModel::slot_names`), and the cycle's probabilities by slot (`None`: not
    /// published this cycle), what every MDP and the re-solve read.
    mdp_slots: Vec<Vec<Option<usize>>>,
    prob_values: Vec<Option<f64>>,
    /// Per MDP of `mdp_names`, per MDP action: the catalogue ids of its primitives (`does`),
    /// resolved in `new` so the cycle merges proposals without looking names up.
    mdp_primitives: Vec<Vec<Vec<ActionId>>>,
    health: HealthModel,
    mdps: MissionMdps,
    workspace: Workspace,
    platform: PlatformState,
    guarantee: Option<Guarantee>,
    /// Set when the guarantee stage found no allocation meeting the goals.
    guarantee_infeasible: bool,
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
    /// What the applications other than the one the resource manager assesses occupied after
    /// the last schedule (tiles, CPU share): the room the resource manager sees before solving.
    others_tiles: u32,
    others_cpu: f64,
    /// Number of names the health managers publish (a reused probability map holds exactly these).
    n_published: usize,
    scratch: Scratch,
    /// The resource arbitration stage's schedules and degradations in force.
    arbiter: ResourceArbiter,
    /// The ids of [`ROOM`]'s observations (`None`: params do not observe it), and their values
    /// this cycle (capacity kept).
    room_ids: [Option<crate::evidence::ObservationId>; 3],
    room_extra: Vec<(crate::evidence::ObservationId, f64)>,
    /// The cycle's evidence by observation (its state index), kept between cycles.
    evidence_states: crate::evidence::EvidenceStates,
    /// The activation nodes' fit observations the core computes with the scheduler's check.
    fit_checks: Vec<FitCheck>,
    /// The snapshot's values this cycle by slot, and the slots each stage reads.
    readings: Readings,
    read_slots: ReadSlots,
    /// Per activity of the guarantee's mission, per alternative: the implementations it names.
    planned: Vec<Vec<Vec<crate::arbitration::PlannedVariant>>>,
}

/// Per activity of the guarantee's mission, per alternative: the implementations it names.
fn planned_of(
    guarantee: Option<&Guarantee>,
    model: &Model,
) -> Vec<Vec<Vec<crate::arbitration::PlannedVariant>>> {
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

/// Per action of MDP `name`, the catalogue ids of the primitives it stands for (every one is in
/// the catalogue: checked at load; one that were not would be left out, as the name lookup did).
fn primitive_ids(model: &Model, name: &str) -> Vec<Vec<ActionId>> {
    let Some(mdp) = model.mdps.get(name) else {
        return Vec::new();
    };
    (0..mdp.action_names().len())
        .map(|a| {
            let does = mdp.primitives(a).iter();
            does.filter_map(|p| model.actions.id(p)).collect()
        })
        .collect()
}

/// One fit observation (`tracking_V3_fits`, node `F_V3`): whether the scheduler admits some
/// implementation of `app version` beside the applications in force.
#[derive(Debug, Clone)]
struct FitCheck {
    id: crate::evidence::ObservationId,
    name: String,
    /// The catalogue's variants of the activation's `app version` (its implementations), by
    /// index.
    variants: Vec<usize>,
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

/// The observations [`Core::platform_room`] gives, in its order.
const ROOM: [&str; 3] = [
    crate::evidence::FREE_TILES,
    crate::evidence::CPU_HEADROOM,
    crate::evidence::TRACKING_FPS,
];

/// Distinct recent queries each health manager's engine answers from memory: evidence flapping
/// across a threshold alternates between two, with the resource re-evaluation a few more.
const BN_QUERY_MEMO: usize = 4;

/// At most this many re-solves per cycle (one per version the MDP may turn to is plenty).
const MAX_RESOLVES: usize = 3;

/// `dst = src` element by element, reusing `dst`'s strings.
fn fill_strings<'a>(dst: &mut Vec<String>, src: impl ExactSizeIterator<Item = &'a str>) {
    dst.truncate(src.len());
    for (i, a) in src.enumerate() {
        match dst.get_mut(i) {
            Some(d) => {
                d.clear();
                d.push_str(a);
            }
            None => dst.push(a.to_string()),
        }
    }
}

impl Core {
    /// A core at cycle 0 with fresh copies of the model's stateful parts.
    pub fn new(model: Arc<Model>, kind: ModelKind, policy: Policy) -> Self {
        let (readings, read_slots) = ReadSlots::resolve(&model, &model.mdp_names(kind));
        let guarantee = Guarantee::start_or_unbounded(model.guarantee.clone());
        let planned = planned_of(guarantee.as_ref(), &model);
        Core {
            kind,
            policy,
            cycle: 0,
            mdp_names: model.mdp_names(kind),
            mdp_policy: model
                .mdp_names(kind)
                .iter()
                .map(|name| {
                    let mdp = model.mdps.get(name)?;
                    mdp.policy_index(model.policy_name(policy)).ok()
                })
                .collect(),
            mdp_slots: model
                .mdp_names(kind)
                .iter()
                .map(|name| {
                    model
                        .mdps
                        .get(name)
                        .map(|m| m.slots_in(model.health.slot_names()))
                        .unwrap_or_default()
                })
                .collect(),
            prob_values: Vec::new(),
            mdp_primitives: model
                .mdp_names(kind)
                .iter()
                .map(|name| primitive_ids(&model, name))
                .collect(),
            health: {
                let mut h = model.health.clone();
                h.set_query_memo(BN_QUERY_MEMO);
                h
            },
            mdps: model.mdps.clone(),
            workspace: Workspace::new(),
            platform: PlatformState::new(&model.resources.platform),
            guarantee,
            guarantee_infeasible: false,
            capped_versions: Vec::new(),
            capped_for: Vec::new(),
            versions_scratch: Vec::new(),
            reallocation_event: String::new(),
            failed_resources: Vec::new(),
            activity_started: None,
            others_tiles: 0,
            others_cpu: 0.0,
            n_published: model.health.publishes().len(),
            scratch: Scratch::default(),
            arbiter: ResourceArbiter::new(),
            room_ids: ROOM.map(|name| model.health.observations.id(name)),
            room_extra: Vec::with_capacity(ROOM.len() + model.health.activations.len()),
            evidence_states: Default::default(),
            fit_checks: model
                .health
                .fit_observations()
                .filter_map(|(name, a)| {
                    Some(FitCheck {
                        id: model.health.observations.id(name)?,
                        name: name.to_string(),
                        variants: (model.resources.catalogue.variants().iter())
                            .enumerate()
                            .filter(|(_, v)| v.app == a.app && v.version == a.version)
                            .map(|(i, _)| i)
                            .collect(),
                    })
                })
                .collect(),
            readings,
            read_slots,
            planned,
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
        self.guarantee = Guarantee::start_or_unbounded(spec);
        self.mission_changed();
        self.guarantee.is_some()
    }

    /// What the guarantee in force planned, after it changed; the activity flown forgotten.
    fn mission_changed(&mut self) {
        self.planned = planned_of(self.guarantee.as_ref(), &self.model);
        self.guarantee_infeasible = false;
        self.capped_versions.clear();
        self.capped_for.clear();
        self.activity_started = None;
    }

    /// A mission changed in flight, planned from the point reached ([`Guarantee::replan_from`];
    /// without a guarantee in force, as [`Core::replace_mission`]).
    pub fn replan_from(&mut self, spec: crate::guarantee::MissionSpec, flown: usize) -> bool {
        let Some(g) = self.guarantee.as_ref() else {
            return self.replace_mission(spec);
        };
        let Some(next) = g.replan_from(spec.clone(), flown) else {
            return self.replace_mission(spec);
        };
        self.guarantee = Some(next);
        self.mission_changed();
        true
    }

    /// Work done by the cycles stepped so far.
    pub fn work_done(&self) -> WorkDone {
        WorkDone {
            cycles: self.cycle,
            mdp_solves: self.mdps.solves(),
            scheduler_runs: self.arbiter.schedules.runs(),
        }
    }

    /// Turn the memos (MDP solves, health queries, resource schedules) on or off. Off, every
    /// cycle re-solves every MDP, re-runs the scheduler and runs every BN query whose inputs
    /// changed since its last: the worst case, and the reference the memos are
    /// tested against. Outputs are identical either way.
    pub fn set_caches(&mut self, on: bool) {
        self.mdps.set_solve_cache(on);
        self.arbiter.schedules.set_enabled(on);
        self.health
            .set_query_memo(if on { BN_QUERY_MEMO } else { 0 });
    }

    /// The PANORAMA allocations in force so far (RAS0 then each re-allocation), in the shape of
    /// PANORAMA's Table 7; `None` when the guarantee stage is off (pre-flight infeasible).
    pub fn allocation_table(&self) -> Option<String> {
        let g = self.guarantee.as_ref()?;
        Some(crate::report::guarantee::render_ras_table(
            &g.spec,
            g.ras_rows(),
        ))
    }

    /// Number of re-allocations so far (RAS0 not counted).
    pub fn reallocations(&self) -> usize {
        self.guarantee.as_ref().map_or(0, |g| g.reallocations())
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
            self.reallocation_event = std::mem::take(s);
        }
        rec.events.clone_from(&obs.events);
        crate::record::map_clone_from(&mut rec.observations, &obs.values);
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
        self.evidence_into(rec);
        // The evidence just written, by observation: no name lookups (same probabilities).
        match self
            .health
            .evaluate_states_into(&self.evidence_states, &mut rec.probabilities)
        {
            Ok(()) => {
                if rec.probabilities.len() != self.n_published {
                    // A reused map held other names: keep exactly what was published.
                    let names = self.health.publishes();
                    rec.probabilities.retain(|k, _| names.contains(k));
                }
            }
            Err(e) => {
                rec.probabilities.clear();
                rec.events.push(Event::HealthError(e.to_string()));
            }
        }
        if self.guarantee_infeasible {
            let cap = model.mission.guarantee.infeasible_p_battery;
            if let Some(p) = rec
                .probabilities
                .get_mut(&model.mission.guarantee.capped_probability)
            {
                *p = p.min(cap);
            }
        }
        self.cap_versions(rec);
        // The probabilities by slot, what every MDP reads.
        by_slot(
            &mut self.prob_values,
            self.health.slot_names(),
            &rec.probabilities,
        );

        // decision: every MDP of the model, solved at its projected state
        let mut sc = std::mem::take(&mut self.scratch);
        sc.merged.clear();
        sc.proposed.clear();
        let mut n_proposals = 0;
        for (j, name) in self.mdp_names.iter().enumerate() {
            let local = read_slots::project(
                model,
                name,
                &self.read_slots.projection[j],
                &self.readings,
                &obs.state,
            );
            let (Some(mdp), Some(_)) = (self.mdps.get_mut(name), model.mdps.get(name)) else {
                continue;
            };
            let Some(s) = mdp.state_index(local) else {
                rec.events.push(Event::MdpStateUnknown {
                    mdp: name.clone(),
                    state: local.to_string(),
                });
                continue;
            };
            let decided = decide(
                mdp,
                &mut self.workspace,
                s,
                (&self.prob_values, &self.mdp_slots[j]),
                self.mdp_policy[j],
                model,
                self.policy,
            );
            match decided {
                Ok(Some(d)) => {
                    for &id in &self.mdp_primitives[j][d.action] {
                        if !sc.merged.contains(&id) {
                            sc.merged.push(id);
                        }
                    }
                    if n_proposals == rec.proposals.len() {
                        rec.proposals.push(Default::default());
                    }
                    sc.proposed.push((j, d.action));
                    mdp.proposal_into(
                        s,
                        &d,
                        model.mission.horizon,
                        &mut rec.proposals[n_proposals],
                    );
                    n_proposals += 1;
                }
                Ok(None) => {}
                Err(e) => rec.events.push(Event::MdpError {
                    mdp: name.to_string(),
                    error: e.to_string(),
                }),
            }
            mark(Stage::Mdp(name));
        }
        rec.proposals.truncate(n_proposals);

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
        self.note_others(rec);
        fill_strings(
            &mut rec.actions,
            sc.actions.iter().map(|&a| model.actions.name(a)),
        );
        mark(Stage::Arbitration);

        // guarantee: PANORAMA margins on the activity being flown
        self.watch_guarantee(&mut sc, obs, rec);
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

    /// The cycle's evidence into the record: the snapshot's and the core's own values (the
    /// platform's room, the fit checks) by observation, and the nodes left without evidence.
    fn evidence_into(&mut self, rec: &mut DecisionRecord) {
        self.update_platform();
        let room = self.platform_room();
        // As `evidence_with_into(obs, &room, ..)`, with the names' ids resolved once in `new`.
        let mut extra = std::mem::take(&mut self.room_extra);
        extra.clear();
        for ((name, v), id) in room.iter().zip(self.room_ids) {
            if let (false, Some(id)) = (name.is_empty(), id) {
                extra.push((id, *v));
            }
        }
        for f in &self.fit_checks {
            extra.push((f.id, self.fits(f, room[2].1)));
        }
        self.health.observations.evidence_states_from_into(
            self.readings.values(),
            &extra,
            &mut self.evidence_states,
            &mut rec.evidence,
        );
        self.room_extra = extra;
        // Absent is not zero: the nodes no observation fed this cycle, listed (strings reused).
        // One observation per node (checked at load): a node is absent when its observation
        // gave no state.
        let mut n_absent = 0;
        let fed = &self.evidence_states.state;
        for (o, fed) in self.health.observations.observations.iter().zip(fed) {
            if fed.is_none() {
                if n_absent == rec.absent_evidence.len() {
                    rec.absent_evidence.push(String::new());
                }
                rec.absent_evidence[n_absent].clone_from(&o.node);
                n_absent += 1;
            }
        }
        rec.absent_evidence.truncate(n_absent);
        mark(Stage::Evidence);
    }

    /// Behaviour arbitration over the live proposals, then resource arbitration.
    fn arbitrate(&mut self, sc: &mut Scratch, obs: &Observations, rec: &mut DecisionRecord) {
        let model = Arc::clone(&self.model);
        let model = &*model;
        sc.merged.clear();
        // Each live proposal's primitives, by the ids resolved when the core started (the
        // proposal's `actions` are the same primitives by name, for the record).
        for (k, &(j, a)) in sc.proposed.iter().enumerate() {
            if sc.superseded.contains(&k) {
                continue;
            }
            for &id in &self.mdp_primitives[j][a] {
                if !sc.merged.contains(&id) {
                    sc.merged.push(id);
                }
            }
        }
        if let Err(e) = model.conflicts.resolve_by(
            &sc.merged,
            |a| model.actions.name(a),
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
        let plan = self
            .guarantee
            .as_ref()
            .filter(|_| model.mission.guarantee.binds)
            .and_then(|g| {
                let n = g.spec.problem.activities.len();
                let (slots, r) = (&self.read_slots, &self.readings);
                let activity = read_slots::activity_index(model, slots, r, &obs.state, n)?;
                let ia = g.allocated_index(activity)?;
                self.planned.get(activity)?.get(ia).map(Vec::as_slice)
            });
        self.arbiter.arbitrate_resources(
            model,
            self.policy,
            &mut self.platform,
            sc,
            (&self.read_slots.rates, &self.readings),
            plan,
            rec,
        );
    }

    /// When the assessed application was requested but not placed: re-evaluate the resource
    /// manager on the room this cycle's placements leave, solve the MDP that chose the
    /// application again and record its new proposal. False when there is nothing to do or the
    /// MDP's choice does not change.
    fn resolve_conflict(&mut self, sc: &mut Scratch, rec: &mut DecisionRecord) -> bool {
        let model = Arc::clone(&self.model);
        let model = &*model;
        let Some(app) = model.health.activations.first().map(|a| a.app.as_str()) else {
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
        // The last proposal (not superseded) whose action starts the application, by its ids.
        let starts_app = |&(j, d): &(usize, usize)| {
            self.mdp_primitives[j][d]
                .iter()
                .any(|&id| model.actions.by_id(id).app.as_deref() == Some(app))
        };
        let Some(k) = (0..sc.proposed.len())
            .rev()
            .find(|&k| !sc.superseded.contains(&k) && starts_app(&sc.proposed[k]))
        else {
            return false;
        };
        // The room beside what was placed this cycle.
        self.note_others(rec);
        self.platform_evidence(&mut rec.evidence);
        let manager = &model.health.activations[0].manager;
        if let Err(e) =
            self.health
                .reevaluate_manager_into(manager, &rec.evidence, &mut rec.probabilities)
        {
            rec.events.push(Event::HealthError(e.to_string()));
            return false;
        }
        let name = rec.proposals[k].mdp.clone();
        let j = sc.proposed[k].0;
        let pi = self.mdp_policy[j];
        let Some(mdp) = self.mdps.get_mut(&name) else {
            return false;
        };
        let Some(s) = mdp.state_index(&rec.proposals[k].state) else {
            return false;
        };
        // The re-evaluated manager's probabilities, by slot as the cycle's MDPs read them.
        by_slot(
            &mut self.prob_values,
            self.health.slot_names(),
            &rec.probabilities,
        );
        let decided = decide(
            mdp,
            &mut self.workspace,
            s,
            (&self.prob_values, &self.mdp_slots[j]),
            pi,
            model,
            self.policy,
        );
        let d = match decided {
            Ok(Some(d)) => d,
            Ok(None) => return false,
            Err(e) => {
                rec.events.push(Event::MdpError {
                    mdp: name.to_string(),
                    error: e.to_string(),
                });
                return false;
            }
        };
        let mut p = crate::record::MdpProposal::default();
        mdp.proposal_into(s, &d, model.mission.horizon, &mut p);
        if p.action == rec.proposals[k].action {
            return false;
        }
        p.reason = format!("re-solved: {why}");
        rec.proposals.push(p);
        sc.proposed.push((j, d.action));
        sc.superseded.push(k);
        true
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
                .map_or(String::new(), |p| p.actions.join("+"));
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
            let gave_way: Vec<String> = sc
                .kept
                .iter()
                .filter(|&&a| model.actions.by_id(a).app.as_deref() == Some(app))
                .map(|&a| model.actions.name(a).to_string())
                .collect();
            if gave_way.is_empty() {
                continue;
            }
            rec.conflicts.push(crate::record::Conflict {
                kept: String::new(),
                dropped: gave_way,
                rule: format!("resource policy {policy}: {d}"),
            });
        }
    }

    /// PANORAMA -> BFM: a version no feasible alternative carries is improbable, so no MDP
    /// proposes it (docs/guarantee.md "One configuration").
    fn cap_versions(&self, rec: &mut DecisionRecord) {
        let cap = self.model.mission.guarantee.infeasible_p_battery;
        for name in &self.capped_versions {
            if let Some(p) = rec.probabilities.get_mut(name) {
                *p = p.min(cap);
            }
        }
    }
}

/// One MDP's decision at state `s` under its reward slot `pi` (resolved at load; `None`: the
/// policy has no slot in this MDP, the error the record names), from `probs`: the cycle's
/// probabilities by slot and where this MDP's sit among them.
fn decide(
    mdp: &mut crate::mission_mdp::MissionMdp,
    ws: &mut Workspace,
    s: usize,
    (values, slots): (&[Option<f64>], &[Option<usize>]),
    pi: Option<usize>,
    model: &Model,
    policy: Policy,
) -> Result<Option<crate::mission_mdp::Decision>, crate::mission_mdp::InstantiateError> {
    match pi {
        Some(pi) => mdp.decide_slots(ws, s, values, slots, pi, model.mission.horizon),
        None => Err(crate::mission_mdp::InstantiateError::UnknownPolicy(
            model.policy_name(policy).to_string(),
        )),
    }
}

/// The published probabilities `probs` (the health layer's map, keyed by `names`, sorted) into
/// `into` by slot (`None`: not in the map). The map holds exactly the published names every
/// cycle the health layer succeeded: then its values in key order are the slots, no name
/// compared; otherwise (a failed or partial evaluation) each slot is looked up.
fn by_slot(into: &mut Vec<Option<f64>>, names: &[String], probs: &BTreeMap<String, f64>) {
    into.clear();
    if probs.len() == names.len() {
        into.extend(probs.values().map(|&v| Some(v)));
    } else {
        into.extend(names.iter().map(|n| probs.get(n).copied()));
    }
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

mod learned_rows;
/// The platform model's room beside the other applications: what the resource evidence reads.
mod platform_room;
mod read_slots;
use read_slots::ReadSlots;
/// The decision table (the paper's Tables 4 to 7) from a run's records.
mod table;
pub use table::table;

/// The guarantee stage (PANORAMA): the plan bound to what runs, the activity watched, drift.
mod watch;

#[cfg(test)]
mod fit_tests;

#[cfg(test)]
mod tests;
