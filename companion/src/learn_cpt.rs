//! In-flight learning of the health BN's CPT rows (`companion fly|simulate --learn-cpt`,
//! docs/calibrate.md; issue 23 item 4): the rows `companion calibrate` counts, counted as the
//! run goes, each record's trials updating the core's row from the next cycle on.
//!
//! The trials are `calibrate::cpt::CptCounts::trials` (the same rows, the same rule); the
//! learned value is `calibrate::cpt::dirichlet_mean` with the row as loaded for prior (worth
//! `PRIOR_PSEUDO_COUNTS` = 10 trials), held within `max_change` of it (params/learning.toml).
//! Each update is logged in the record (`cpt_learned`) and `companion replay` re-derives it
//! from the logged records. Rows are learned per run: a new core starts from the loaded rows.

use crate::calibrate::cpt::{self, CptCounts, Row, ShippedRows, Trial};
use companion_core::decision::Core;
use companion_core::record::{CptUpdate, DecisionRecord, Event};
use companion_core::spec::{ParamsFiles, SpecError};
use std::collections::BTreeMap;

// learning.toml is read with the params (`crate::learning_params`, floor 1); kept here by its
// old path.
pub use crate::learning_params::{DEFAULT_MAX_CHANGE, LEARNING_FILE, LearningParams};

/// One row's counts this run.
struct RowTally {
    /// P(success) of the row as loaded: the prior's mean and the bound's centre.
    prior: f64,
    successes: u64,
    trials: u64,
    /// The value in force.
    value: f64,
}

/// The online learner of one run.
pub struct OnlineCpt {
    params: LearningParams,
    shipped: ShippedRows,
    parents_of: BTreeMap<String, Vec<String>>,
    /// The run's memory of what was found (which trials still count); its tallies are unused.
    counts: CptCounts,
    rows: BTreeMap<(String, Row), RowTally>,
    /// `fly`: the last record, whose outcome the next cycle's observed events give.
    pending: Option<DecisionRecord>,
}

impl OnlineCpt {
    pub fn new(files: &ParamsFiles, params: LearningParams) -> Result<Self, SpecError> {
        let shipped = ShippedRows::load(files)?;
        Ok(OnlineCpt {
            params,
            parents_of: shipped.parents(),
            shipped,
            counts: CptCounts::default(),
            rows: BTreeMap::new(),
            pending: None,
        })
    }

    /// The learner `--learn-cpt` asks for (`None` without the flag), from the loaded params.
    pub fn when(
        flag: bool,
        files: &ParamsFiles,
        learning: LearningParams,
    ) -> anyhow::Result<Option<Self>> {
        use anyhow::Context;
        flag.then(|| Self::new(files, learning).context("--learn-cpt"))
            .transpose()
    }

    /// A new run (a fresh core, its rows as loaded): forget the counts.
    pub fn start_run(&mut self) {
        self.counts.start_run();
        self.rows.clear();
        self.pending = None;
    }

    /// `simulate`: the record holds its outcome (`vehicle.world_events_after` and the state
    /// after); its trials update `core`'s rows. Returns the updates, for the record.
    pub fn learn_simulated(&mut self, core: &mut Core, r: &DecisionRecord) -> Vec<CptUpdate> {
        let Some((events, state_after)) = cpt::simulated_outcome(r) else {
            return Vec::new();
        };
        let trials = self.counts.trials(
            r,
            &events,
            state_after,
            &core.model.states,
            &self.shipped,
            &self.parents_of,
        );
        self.apply(core, trials)
    }

    /// `fly`: record `r` has been stepped on observations whose events (`observed`) are the
    /// outcome of the previous cycle (the onboard tracker's `target_detected` telemetry: target
    /// found, target lost). Its trials update `core`'s rows; `r` waits for the next cycle's.
    pub fn learn_flown(
        &mut self,
        core: &mut Core,
        r: &DecisionRecord,
        observed: &[Event],
    ) -> Vec<CptUpdate> {
        let updates = match self.pending.take() {
            Some(prev) => {
                let trials = self.counts.trials(
                    &prev,
                    observed,
                    // Kept is "no `target lost`": fly's states do not say more.
                    None,
                    &core.model.states,
                    &self.shipped,
                    &self.parents_of,
                );
                self.apply(core, trials)
            }
            None => Vec::new(),
        };
        self.pending = Some(r.clone());
        updates
    }

    fn apply(&mut self, core: &mut Core, trials: Vec<Trial>) -> Vec<CptUpdate> {
        let mut out = Vec::new();
        for t in trials {
            let key = (t.node.clone(), t.when.clone());
            if !self.rows.contains_key(&key) {
                // A row this model does not have (or not of two states) is not learned.
                let Some(row) = core.cpt_row(&t.node, &t.when).filter(|r| r.len() == 2) else {
                    continue;
                };
                let p = row[t.success_index];
                self.rows.insert(
                    key.clone(),
                    RowTally {
                        prior: p,
                        successes: 0,
                        trials: 0,
                        value: p,
                    },
                );
            }
            let tally = self.rows.get_mut(&key).expect("inserted above");
            tally.successes += u64::from(t.success);
            tally.trials += 1;
            let mean = cpt::dirichlet_mean(tally.prior, tally.successes, tally.trials);
            let m = self.params.max_change;
            let new = mean.clamp(tally.prior - m, tally.prior + m).clamp(0.0, 1.0);
            let old = tally.value;
            tally.value = new;
            let mut p = [1.0 - new, 1.0 - new];
            p[t.success_index] = new;
            if core.set_cpt_row(&t.node, &t.when, &p).is_err() {
                continue; // the row was read from this model just above
            }
            out.push(CptUpdate {
                node: t.node,
                when: t.when.into_iter().collect(),
                success_state: t.success_state.to_string(),
                successes: tally.successes,
                trials: tally.trials,
                prior: tally.prior,
                old,
                new,
                bounded: new != mean,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{Params, default_params_dir};
    use companion_core::decision::ModelKind;

    /// A `fly` record tracking with V3 under the given vibration evidence.
    fn tracking_v3(vibration: &str) -> DecisionRecord {
        DecisionRecord {
            state: "v3".into(),
            actions: ["track_v3"].into_iter().collect(),
            evidence: [("A_vibration".to_string(), vibration.into())]
                .into_iter()
                .collect(),
            ..Default::default()
        }
    }

    fn row() -> Vec<(String, String)> {
        vec![
            ("U_vibration".into(), "present".into()),
            ("U_point_lost".into(), "absent".into()),
            ("U_motion_lost".into(), "absent".into()),
        ]
    }

    #[test]
    fn in_flight_a_tracking_step_is_kept_unless_the_next_cycle_observes_target_lost() {
        let p = Params::load(&default_params_dir(), None).unwrap();
        let policy = p.model.policy("safety").unwrap();
        let mut l = OnlineCpt::new(&p.files, p.learning).unwrap();
        let mut core = Core::new(std::sync::Arc::new(p.model), ModelKind::Bfm, policy);
        let shipped = core.cpt_row("C_V3", &row()).unwrap()[1];
        assert!((shipped - 0.9982).abs() < 1e-12, "{shipped}");

        // The first record's outcome is the next cycle's.
        assert!(
            l.learn_flown(&mut core, &tracking_v3("high"), &[])
                .is_empty()
        );
        let u = l.learn_flown(&mut core, &tracking_v3("high"), &[Event::TargetLost]);
        assert_eq!(u.len(), 1, "{u:?}");
        assert_eq!(
            (u[0].node.as_str(), u[0].successes, u[0].trials),
            ("C_V3", 0, 1)
        );
        assert_eq!(u[0].when["U_vibration"], "present");
        let lost_once = 10.0 * shipped / 11.0;
        assert!((u[0].new - lost_once).abs() < 1e-12, "{u:?}");
        assert_eq!(core.cpt_row("C_V3", &row()).unwrap()[1], u[0].new);

        let u = l.learn_flown(&mut core, &tracking_v3("high"), &[]);
        assert_eq!((u[0].successes, u[0].trials), (1, 2), "kept: {u:?}");
        assert_eq!(u[0].old, lost_once);

        // A new flight starts again from the loaded rows' counts.
        l.start_run();
        assert!(
            l.learn_flown(&mut core, &tracking_v3("high"), &[])
                .is_empty()
        );
    }
}
