//! The one decision core behind every driver: `fly` (through `fly::Decider`), `simulate` (through
//! [`crate::sim::Cycle`]), the soak and the fuzz targets. It owns the core and what outlives a
//! flight: the model and policy to start the next flight's core from, the mission planned in
//! place of the model's (`fly --mission autopilot`), and the in-flight learner (`--learn-cpt`),
//! which learns within a flight and starts again from the loaded rows at the next.

use crate::learn_cpt::OnlineCpt;
use companion_core::decision::{Core, Model, ModelKind, Policy};
use companion_core::guarantee::MissionSpec;
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};
use std::sync::Arc;

/// The decision core with what it keeps between flights.
pub struct CoreDecider {
    core: Core,
    model: Arc<Model>,
    kind: ModelKind,
    policy: Policy,
    /// `--learn-cpt`: the rows learned this flight.
    learner: Option<OnlineCpt>,
    /// The mission planned in place of the model's (`fly --mission autopilot`), for every flight.
    mission: Option<MissionSpec>,
}

impl CoreDecider {
    /// A core of `kind` deciding by `policy`, learning its rows as it flies when `learner` is
    /// given.
    pub fn new(
        model: Arc<Model>,
        kind: ModelKind,
        policy: Policy,
        learner: Option<OnlineCpt>,
    ) -> Self {
        Self {
            core: Core::new(Arc::clone(&model), kind, policy),
            model,
            kind,
            policy,
            learner,
            mission: None,
        }
    }

    /// The core of this flight.
    pub fn core(&self) -> &Core {
        &self.core
    }

    /// The model every flight's core is built from.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }

    /// One cycle in flight: the plan and its record, with what the learner learned from the
    /// previous cycle's outcome (read from this cycle's events).
    pub fn step_flown(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        let (plan, mut rec) = self.core.step(obs);
        if let Some(learner) = self.learner.as_mut() {
            rec.cpt_learned = learner.learn_flown(&mut self.core, &rec, &obs.events);
        }
        (plan, rec)
    }

    /// A new flight begins (the last one ended landed and disarmed, or the next simulated run):
    /// a fresh core, the mission planned in place of the model's again, the learner from the
    /// loaded rows.
    pub fn new_flight(&mut self) {
        self.new_flight_of(self.kind);
    }

    /// [`CoreDecider::new_flight`] with a core of `kind` (`simulate --model` runs each kind).
    pub fn new_flight_of(&mut self, kind: ModelKind) {
        self.kind = kind;
        self.core = Core::new(Arc::clone(&self.model), kind, self.policy);
        if let Some(spec) = &self.mission {
            self.core.replace_mission(spec.clone());
        }
        if let Some(learner) = self.learner.as_mut() {
            learner.start_run();
        }
    }

    /// Guarantee `spec` from now on, this flight and the next ones; `false` when it has no
    /// allocation at all.
    pub fn replace_mission(&mut self, spec: MissionSpec) -> bool {
        self.mission = Some(spec.clone());
        self.core.replace_mission(spec)
    }

    /// A mission changed in flight: `spliced` (its first `flown` activities flown) guaranteed
    /// from the point reached, `whole` (the new mission from home) for the next flights.
    pub fn replan_from(&mut self, whole: MissionSpec, spliced: MissionSpec, flown: usize) -> bool {
        self.mission = Some(whole);
        self.core.replan_from(spliced, flown)
    }
}

/// Simulated: the learner learns from the world's outcome of each cycle.
impl crate::sim::Cycle for &mut CoreDecider {
    fn decide(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        self.core.step(obs)
    }

    fn outcome(&mut self, record: &mut DecisionRecord) {
        if let Some(learner) = self.learner.as_mut() {
            record.cpt_learned = learner.learn_simulated(&mut self.core, record);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{Params, default_params_dir};
    use crate::sim::{Scenario, run_cycle};

    fn records_json(r: &crate::sim::RunResult) -> Vec<String> {
        r.records
            .iter()
            .map(|r| serde_json::to_string(r).unwrap())
            .collect()
    }

    /// A second flight after `new_flight` decides as the first did (fly's, simulate's, the
    /// soak's and the fuzzers' decider alike); without it, the core of the first flight goes on
    /// and decides otherwise (the check below that the reset matters).
    #[test]
    fn a_new_flight_starts_from_a_fresh_core() {
        let p = Params::load(&default_params_dir(), None).unwrap();
        let mut scenario = Scenario::load(&p.files, "complete-1").unwrap();
        scenario.steps = scenario.steps.min(40);
        let policy = p.model.policy("safety").unwrap();
        let mut d = CoreDecider::new(Arc::new(p.model), ModelKind::Bfm, policy, None);
        let first = records_json(&run_cycle(&p.world, &scenario, 1, &mut d));
        let carried_on = records_json(&run_cycle(&p.world, &scenario, 1, &mut d));
        assert_ne!(first, carried_on, "the core keeps state across runs");
        d.new_flight();
        let again = records_json(&run_cycle(&p.world, &scenario, 1, &mut d));
        assert_eq!(first, again);
    }
}
