//! The health and decision stage of the cycle: the evidence by observation, the health
//! managers' probabilities, and every MDP of the model solved at its projected state. Its share
//! of the core's state: the health model, the MDPs, their solver workspace and what was
//! resolved of them when the core started (rewards, probability slots, primitives by id).

use super::read_slots::{self, ReadSlots};
use super::{Model, ModelKind, Policy};
use crate::evidence::{EvidenceStates, ObservationId};
use crate::health::HealthModel;
use crate::mission_mdp::MissionMdps;
use crate::readings::Readings;
use crate::record::{DecisionRecord, Event, MdpProposal};
use crate::scratch::Scratch;
use crate::stage_hook::{Stage, mark};
use crate::vocabulary::ActionId;
use mdp_engine::Workspace;

/// Distinct recent queries each health manager's engine answers from memory: evidence flapping
/// across a threshold alternates between two, with the resource re-evaluation a few more.
const BN_QUERY_MEMO: usize = 4;

/// The health managers and the MDPs, with what the cycle resolved of them once.
pub(super) struct HealthMdpStage {
    mdp_names: Vec<String>,
    /// Per MDP of `mdp_names`: where the policy's rewards sit in it, resolved in `new` (`None`:
    /// the MDP has no rewards for the policy, an error each cycle as the name lookup gave).
    mdp_policy: Vec<Option<usize>>,
    /// Per MDP of `mdp_names`, the slot of each probability it reads among the published ones
    /// (`HealthModel::slot_names`): every MDP and the re-solve read the record's probabilities
    /// by these slots.
    mdp_slots: Vec<Vec<Option<usize>>>,
    /// Per MDP of `mdp_names`, per MDP action: the catalogue ids of its primitives (`does`),
    /// resolved in `new` so the cycle merges proposals without looking names up.
    mdp_primitives: Vec<Vec<Vec<ActionId>>>,
    pub(super) health: HealthModel,
    mdps: MissionMdps,
    workspace: Workspace,
    /// The health manager the resource conflict re-evaluates (the first activation's).
    assessed_manager: Option<usize>,
    /// The cycle's evidence by observation (its state index), kept between cycles.
    evidence_states: EvidenceStates,
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

impl HealthMdpStage {
    /// Fresh copies of the model's health managers and MDPs, the MDPs of `kind` resolved for
    /// `policy`.
    pub(super) fn new(model: &Model, kind: ModelKind, policy: Policy) -> Self {
        HealthMdpStage {
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
            mdp_primitives: model
                .mdp_names(kind)
                .iter()
                .map(|name| primitive_ids(model, name))
                .collect(),
            health: {
                let mut h = model.health.clone();
                h.set_query_memo(BN_QUERY_MEMO);
                h
            },
            mdps: model.mdps.clone(),
            workspace: Workspace::new(),
            assessed_manager: (model.health.activations.first())
                .and_then(|a| model.health.manager_position(&a.manager)),
            evidence_states: Default::default(),
        }
    }

    /// MDP solves actually run (memo hits not counted).
    pub(super) fn solves(&self) -> u64 {
        self.mdps.solves()
    }

    /// The MDP solve memo and the health query memo on or off ([`super::Core::set_caches`]).
    pub(super) fn set_caches(&mut self, on: bool) {
        self.mdps.set_solve_cache(on);
        self.health
            .set_query_memo(if on { BN_QUERY_MEMO } else { 0 });
    }

    /// The cycle's evidence into the record: the snapshot's values and the core's own (`extra`:
    /// the platform's room, the fit checks) by observation, and the nodes left without evidence.
    pub(super) fn record_evidence(
        &mut self,
        readings: &Readings,
        extra: &[(ObservationId, f64)],
        rec: &mut DecisionRecord,
    ) {
        self.evidence_states_into(readings, extra, rec);
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
    }

    /// The evidence from this cycle's readings and the core's own values (`extra`): by
    /// observation into `evidence_states`, by node into the record.
    fn evidence_states_into(
        &mut self,
        readings: &Readings,
        extra: &[(ObservationId, f64)],
        rec: &mut DecisionRecord,
    ) {
        self.health.observations.evidence_states_from_into(
            readings.values(),
            extra,
            &mut self.evidence_states,
            &mut rec.evidence,
        );
    }

    /// The health managers on the evidence just written, by observation: the probabilities by
    /// slot.
    pub(super) fn write_probabilities(&mut self, rec: &mut DecisionRecord) {
        if let Err(e) = self
            .health
            .evaluate_states_into(&self.evidence_states, &mut rec.probabilities)
        {
            rec.probabilities.reset_over(self.health.slot_names());
            rec.events.push(Event::HealthError(e.to_string()));
        }
    }

    /// Every MDP of the model solved at its projected state: its proposal into the record, its
    /// primitives merged into `sc.merged`, (MDP, action) into `sc.proposed`.
    pub(super) fn propose(
        &mut self,
        model: &Model,
        policy: Policy,
        (read_slots, readings): (&ReadSlots, &Readings),
        state: &str,
        sc: &mut Scratch,
        rec: &mut DecisionRecord,
    ) {
        sc.merged.clear();
        sc.proposed.clear();
        let mut n_proposals = 0;
        for (j, name) in self.mdp_names.iter().enumerate() {
            let local =
                read_slots::project(model, name, &read_slots.projection[j], readings, state);
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
                (rec.probabilities.slots(), &self.mdp_slots[j]),
                self.mdp_policy[j],
                model,
                policy,
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
                    let p = &mut rec.proposals[n_proposals];
                    mdp.proposal_into(s, &d, model.mission.horizon, p);
                    self.primitives_into(model, (j, d.action), p);
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
    }

    /// Each live proposal's primitives into `sc.merged`, by the ids resolved when the core
    /// started (the proposal's `actions` are the same ids, named when the record is written).
    pub(super) fn merge_live(&self, sc: &mut Scratch) {
        sc.merged.clear();
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
    }

    /// The primitives of action `a` of MDP `j` into proposal `p`, by id over the catalogue.
    fn primitives_into(&self, model: &Model, (j, a): (usize, usize), p: &mut MdpProposal) {
        (p.actions).set(
            model.actions.names(),
            self.mdp_primitives[j][a].iter().copied(),
        );
    }

    /// The last proposal (not superseded) whose action starts application `app`, by its ids.
    pub(super) fn last_starting(&self, model: &Model, app: &str, sc: &Scratch) -> Option<usize> {
        let starts_app = |&(j, d): &(usize, usize)| {
            self.mdp_primitives[j][d]
                .iter()
                .any(|&id| model.actions.by_id(id).app.as_deref() == Some(app))
        };
        (0..sc.proposed.len())
            .rev()
            .find(|&k| !sc.superseded.contains(&k) && starts_app(&sc.proposed[k]))
    }

    /// Proposal `k` solved again on the assessed application's manager re-evaluated on the
    /// cycle's readings and the core's own values `extra` (the room beside what was placed),
    /// by observation: its new proposal recorded with `why`, and `k` superseded. False when the
    /// MDP's choice does not change.
    pub(super) fn resolve(
        &mut self,
        (model, policy): (&Model, Policy),
        (readings, extra): (&Readings, &[(ObservationId, f64)]),
        (k, why): (usize, &impl std::fmt::Display),
        sc: &mut Scratch,
        rec: &mut DecisionRecord,
    ) -> bool {
        self.evidence_states_into(readings, extra, rec);
        let Some(manager) = self.assessed_manager else {
            return false;
        };
        if let Err(e) = self.health.reevaluate_manager_states_into(
            manager,
            &self.evidence_states,
            &mut rec.probabilities,
        ) {
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
        let decided = decide(
            mdp,
            &mut self.workspace,
            s,
            (rec.probabilities.slots(), &self.mdp_slots[j]),
            pi,
            model,
            policy,
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
        let mut p = MdpProposal::default();
        mdp.proposal_into(s, &d, model.mission.horizon, &mut p);
        self.primitives_into(model, (j, d.action), &mut p);
        if p.action == rec.proposals[k].action {
            return false;
        }
        p.reason = format!("re-solved: {why}");
        rec.proposals.push(p);
        sc.proposed.push((j, d.action));
        sc.superseded.push(k);
        true
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
