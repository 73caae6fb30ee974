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

/// The learning settings file, relative to the params directory (optional: defaults apply).
pub const LEARNING_FILE: &str = "learning.toml";

/// The default bound: the most a row moves from its loaded value within one run.
pub const DEFAULT_MAX_CHANGE: f64 = 0.6;

/// params/learning.toml.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearningParams {
    /// The most a learned row may differ from the row as loaded (probability, in (0, 1]).
    pub max_change: f64,
}

impl Default for LearningParams {
    fn default() -> Self {
        LearningParams {
            max_change: DEFAULT_MAX_CHANGE,
        }
    }
}

impl LearningParams {
    /// Read `learning.toml` from the params (absent: the defaults); a malformed, unknown or
    /// out-of-range entry is refused naming the file and the entry.
    pub fn load(files: &ParamsFiles) -> Result<Self, SpecError> {
        let file = files.dir().join(LEARNING_FILE);
        if !files.contains(&file) {
            return Ok(Self::default());
        }
        let t: toml::Table = files.text(&file)?.parse().map_err(|e: toml::de::Error| {
            SpecError::new(&file, "-", format!("not TOML: {}", e.message()))
        })?;
        let mut p = Self::default();
        for (k, v) in &t {
            let toml::Value::Table(cpt) = v else {
                return Err(SpecError::new(&file, k, "unknown entry (known: [cpt])"));
            };
            if k != "cpt" {
                return Err(SpecError::new(&file, k, "unknown entry (known: [cpt])"));
            }
            for (ck, cv) in cpt {
                let entry = format!("cpt.{ck}");
                if ck != "max_change" {
                    return Err(SpecError::new(
                        &file,
                        &entry,
                        "unknown entry (known: max_change)",
                    ));
                }
                let x = cv
                    .as_float()
                    .or_else(|| cv.as_integer().map(|i| i as f64))
                    .ok_or_else(|| {
                        SpecError::new(&file, &entry, format!("{cv} is not a number"))
                    })?;
                if !(x > 0.0 && x <= 1.0) {
                    return Err(SpecError::new(
                        &file,
                        &entry,
                        format!("{x} is not a probability change in (0, 1]"),
                    ));
                }
                p.max_change = x;
            }
        }
        Ok(p)
    }
}

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
                let names: Vec<String> = observed.iter().map(|e| e.to_string()).collect();
                let events: Vec<&str> = names.iter().map(String::as_str).collect();
                let trials = self.counts.trials(
                    &prev,
                    &events,
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

/// A core that learns from each simulated cycle's outcome ([`crate::sim::Cycle`]).
pub struct LearningCore<'c, 'm> {
    pub core: &'c mut Core<'m>,
    pub learner: &'c mut OnlineCpt,
}

impl crate::sim::Cycle for LearningCore<'_, '_> {
    fn decide(
        &mut self,
        obs: &companion_core::observations::Observations,
    ) -> (companion_core::record::Plan, DecisionRecord) {
        self.core.step(obs)
    }

    fn outcome(&mut self, record: &mut DecisionRecord) {
        record.cpt_learned = self.learner.learn_simulated(self.core, record);
    }
}
