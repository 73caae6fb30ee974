//! The mission's MDPs as data (`params/mdp/*.toml`) and the behaviour-conflict rules
//! (`params/policies.toml`), loaded, validated and compiled once; then re-instantiated in place
//! with each cycle's named probabilities. Format: docs/params/mdp.md.

pub mod expr;
mod load;
mod schema;

use crate::record::MdpProposal;
use crate::spec::{ParamsFiles, SpecError, read_toml};
use expr::Expr;
pub use load::load_mdp;
use mdp_engine::{Mdp, MdpError, Workspace};
use schema::IndexFile;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Number of pseudo-random probability points (besides the all-0 and all-1 corners and the
/// index's check point) at which every row must sum to 1.
pub const RANDOM_CHECK_POINTS: usize = 64;
/// Tolerance of the load-time row-sum check.
pub const LOAD_SUM_TOLERANCE: f64 = 1e-9;

// ---------------------------------------------------------------- compiled model

/// Why an MDP could not be instantiated with the given probabilities.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InstantiateError {
    /// A probability the MDP reads was not given.
    #[error("probability {0} not provided")]
    MissingProbability(String),
    /// A probability given is outside [0, 1] (or not a number).
    #[error("probability {name} = {value} not in [0, 1]")]
    BadProbability {
        /// Probability name.
        name: String,
        /// The value given.
        value: f64,
    },
    /// The policy named has no rewards in this MDP.
    #[error("unknown policy '{0}'")]
    UnknownPolicy(String),
    /// The filled-in model is not a valid MDP (a transition row not summing to 1, say).
    #[error("mdp '{mdp}': {err}")]
    Invalid {
        /// MDP name from params.
        mdp: String,
        /// The engine's validation error.
        err: MdpError,
    },
}

/// A stage-0 decision: the MDP action index (see [`MissionMdp::action_name`],
/// [`MissionMdp::primitives`]) and the optimal expected total reward from the current state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// Index of the chosen MDP action.
    pub action: usize,
    /// Optimal expected total reward from the current state, in the policy's reward units.
    pub value: f64,
    /// Stages the solver computed (the early stop extrapolates the rest of the horizon).
    pub iterations: u32,
}

/// One MDP from params, compiled: the engine model plus the expressions that fill it.
#[derive(Debug, Clone)]
pub struct MissionMdp {
    name: String,
    file: PathBuf,
    states: Vec<String>,
    initial: usize,
    actions: Vec<String>,
    does: Vec<Vec<String>>,
    /// Probability names used by this MDP; slot `k` of every expression is `vars[k]`.
    vars: Vec<String>,
    /// Indices into `vars` in name order (the order of the name-keyed maps the cycle reads and
    /// writes), so they are matched in one ordered walk instead of a lookup each.
    by_name: Vec<usize>,
    /// `vars` in name order, shared by every proposal's `inputs` (their names, written only
    /// when a record is).
    input_names: crate::named_slots::SortedNames,
    values: Vec<f64>,
    /// Expression per engine transition index.
    trans_expr: Vec<Expr>,
    policies: Vec<String>,
    /// Per policy: action reward expression per engine choice index.
    choice_reward: Vec<Vec<Expr>>,
    /// Per policy: enter reward per state (`None` = 0).
    enter_reward: Vec<Vec<Option<Expr>>>,
    /// Scratch for `fill`: each state's enter reward at the current values, evaluated once per
    /// fill instead of once per incoming transition.
    enter_value: Vec<f64>,
    mdp: Mdp,
    /// The last solve's stage-0 answer for every state, keyed on its exact inputs.
    solved: Solved,
}

/// How many recent finite-horizon solves each MDP remembers. The probabilities come from BNs
/// over discrete evidence, so they take few distinct values: evidence flapping across one
/// threshold (vibration on/off) alternates between two input points, a second flapping reading
/// makes four.
const SOLVE_MEMO: usize = 4;

/// Memo of recent finite-horizon solves. A solve is a pure function of the probability values
/// (which fix every transition probability and reward), the policy and the horizon, so when all
/// three are bit-identical to a remembered solve's, its stage-0 decisions and values are exactly
/// what a new solve would give. `decide` then skips instantiate + solve.
#[derive(Debug, Clone, Default)]
struct Solved {
    enabled: bool,
    /// Up to [`SOLVE_MEMO`] solves; a miss replaces them in turn (`next`), their buffers kept.
    entries: Vec<SolvedEntry>,
    next: usize,
    /// The entry `decide` answered from last.
    current: usize,
    /// Solves actually run (memo misses), for benchmarks and tests.
    solves: u64,
}

#[derive(Debug, Clone, Default)]
struct SolvedEntry {
    values: Vec<f64>,
    policy: usize,
    horizon: usize,
    /// Stages the solve computed.
    iterations: u32,
    /// Stage-0 action per state (`u32::MAX`: terminal / none) and stage-0 value per state.
    decision: Vec<u32>,
    value: Vec<f64>,
}

impl SolvedEntry {
    fn is(&self, values: &[f64], policy: usize, horizon: usize) -> bool {
        self.policy == policy
            && self.horizon == horizon
            && self.values.len() == values.len()
            && self
                .values
                .iter()
                .zip(values)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }
}

impl Solved {
    /// A memo with its [`SOLVE_MEMO`] slots allocated for a model of `n_states` states reading
    /// `n_vars` probabilities (so filling them allocates nothing), holding no solve.
    pub(crate) fn new(n_states: usize, n_vars: usize) -> Self {
        // Built one by one: a clone would not keep the capacity.
        let empty = || SolvedEntry {
            values: Vec::with_capacity(n_vars.max(1)),
            decision: Vec::with_capacity(n_states),
            value: Vec::with_capacity(n_states),
            ..SolvedEntry::default()
        };
        let mut memo = Solved {
            enabled: true,
            entries: (0..SOLVE_MEMO).map(|_| empty()).collect(),
            ..Solved::default()
        };
        memo.forget();
        memo
    }

    /// Hold no solve (every slot's values set to a point no input can be: NaN).
    fn forget(&mut self) {
        for e in &mut self.entries {
            e.values.clear();
            e.values.push(f64::NAN);
        }
        self.next = 0;
        self.current = 0;
    }

    /// The remembered solve of exactly these inputs (the last answered checked first).
    fn hit(&self, values: &[f64], policy: usize, horizon: usize) -> Option<usize> {
        if !self.enabled {
            return None;
        }
        let n = self.entries.len();
        (0..n)
            .map(|k| (self.current + k) % n)
            .find(|&i| self.entries[i].is(values, policy, horizon))
    }

    /// The slot a new solve goes into: the only one with the memo off, else the next in turn.
    fn slot(&mut self) -> usize {
        let slots = if self.enabled { SOLVE_MEMO } else { 1 };
        if self.entries.len() < slots {
            self.entries.push(SolvedEntry::default());
            return self.entries.len() - 1;
        }
        let i = self.next % self.entries.len();
        self.next = (i + 1) % slots;
        i
    }
}

impl MissionMdp {
    /// MDP name from params.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// File it was read from.
    pub fn file(&self) -> &Path {
        &self.file
    }
    /// Number of states.
    pub fn n_states(&self) -> usize {
        self.states.len()
    }
    /// Number of MDP actions.
    pub fn n_actions(&self) -> usize {
        self.actions.len()
    }
    /// Index of the state named `name`.
    pub fn state_index(&self, name: &str) -> Option<usize> {
        self.states.iter().position(|s| s == name)
    }
    /// Name of state `s` (panics when out of range).
    pub fn state_name(&self, s: usize) -> &str {
        &self.states[s]
    }
    /// State names, in index order.
    pub fn states(&self) -> &[String] {
        &self.states
    }
    /// Index of the state the MDP starts in.
    pub fn initial_state(&self) -> usize {
        self.initial
    }
    /// Index of the MDP action named `name` (`"A2+A11"`).
    pub fn action_index(&self, name: &str) -> Option<usize> {
        self.actions.iter().position(|a| a == name)
    }
    /// The MDP action's name as in params (`"A2+A11"`).
    pub fn action_name(&self, a: usize) -> &str {
        &self.actions[a]
    }
    /// MDP action names, in index order.
    pub fn action_names(&self) -> &[String] {
        &self.actions
    }
    /// The primitive actions an MDP action stands for (`["follow_trajectory", "detect_obstacles_lidar"]`).
    pub fn primitives(&self, a: usize) -> &[String] {
        &self.does[a]
    }
    /// Probability names this MDP reads.
    pub fn probability_names(&self) -> &[String] {
        &self.vars
    }
    /// Policies this MDP has rewards for (params/policies.toml names).
    pub fn policies(&self) -> &[String] {
        &self.policies
    }
    /// The engine model as last instantiated (at load: the first check point, first policy).
    pub fn mdp(&self) -> &Mdp {
        &self.mdp
    }

    /// Turn the decision memo on or off (on by default; off re-solves every cycle, for tests
    /// and the worst-case benchmark).
    pub fn set_solve_cache(&mut self, on: bool) {
        self.solved.enabled = on;
        self.solved.forget();
    }

    /// Finite-horizon solves `decide` has actually run (the rest came from the memo).
    pub fn solves(&self) -> u64 {
        self.solved.solves
    }

    /// Where `policy`'s rewards sit in this MDP: resolved once per core, then handed to
    /// [`MissionMdp::decide_slots`] every cycle.
    pub fn policy_index(&self, policy: &str) -> Result<usize, InstantiateError> {
        self.policies
            .iter()
            .position(|p| p == policy)
            .ok_or_else(|| InstantiateError::UnknownPolicy(policy.to_string()))
    }

    /// Read every probability this MDP uses into `self.values` by name, checking range.
    fn load_values(
        &mut self,
        lookup: impl Fn(&str) -> Option<f64>,
    ) -> Result<(), InstantiateError> {
        for (k, name) in self.vars.iter().enumerate() {
            let v =
                lookup(name).ok_or_else(|| InstantiateError::MissingProbability(name.clone()))?;
            if !(0.0..=1.0).contains(&v) {
                return Err(InstantiateError::BadProbability {
                    name: name.clone(),
                    value: v,
                });
            }
            self.values[k] = v;
        }
        Ok(())
    }

    /// Fill transition probabilities and rewards in place from named probabilities for `policy`.
    /// Allocation-free. Fails when a probability is missing or outside `[0, 1]`, or the result
    /// is not a stochastic model.
    pub fn instantiate(
        &mut self,
        probs: &BTreeMap<String, f64>,
        policy: &str,
    ) -> Result<&Mdp, InstantiateError> {
        self.instantiate_with(|n| probs.get(n).copied(), policy)
    }

    /// Like [`MissionMdp::instantiate`] with any lookup from probability name to value.
    pub fn instantiate_with(
        &mut self,
        lookup: impl Fn(&str) -> Option<f64>,
        policy: &str,
    ) -> Result<&Mdp, InstantiateError> {
        let pi = self.policy_index(policy)?;
        self.load_values(lookup)?;
        self.fill_checked(pi)?;
        Ok(&self.mdp)
    }

    /// Fill the engine model from `self.values` for policy `pi` and check it is stochastic.
    fn fill_checked(&mut self, pi: usize) -> Result<(), InstantiateError> {
        self.fill(pi);
        self.mdp
            .validate()
            .map_err(|err| InstantiateError::Invalid {
                mdp: self.name.clone(),
                err,
            })
    }

    /// One decision cycle for this MDP: instantiate with `probs` under `policy`, solve the
    /// finite horizon (`horizon` steps, the paper uses 100) in `ws`, and return the stage-0
    /// action at `state` with its value. `Ok(None)` when `state` is terminal. Allocation-free
    /// once `ws` has seen this model size and horizon. When the probabilities, policy and
    /// horizon are bit-identical to the last solve's, the memoised answer is returned instead
    /// (see [`MissionMdp::set_solve_cache`]).
    pub fn decide(
        &mut self,
        ws: &mut Workspace,
        state: usize,
        probs: &BTreeMap<String, f64>,
        policy: &str,
        horizon: usize,
    ) -> Result<Option<Decision>, InstantiateError> {
        let pi = self.policy_index(policy)?;
        self.load_values(|n| probs.get(n).copied())?;
        self.decide_loaded(ws, state, pi, horizon)
    }

    /// The slot of each probability this MDP reads in `slot_names` (sorted names; None: not
    /// there), for [`MissionMdp::decide_slots`].
    pub fn slots_in(&self, slot_names: &[String]) -> Vec<Option<usize>> {
        self.vars
            .iter()
            .map(|v| slot_names.binary_search(v).ok())
            .collect()
    }

    /// [`MissionMdp::decide`] with the probabilities read by slot (the decision cycle's only
    /// path): `values` the cycle's probabilities by slot (`HealthModel::slot_names` order;
    /// `None`: not published this cycle), `slots` where each of this MDP's probabilities sits
    /// there ([`MissionMdp::slots_in`]), `pi` the policy's rewards ([`MissionMdp::policy_index`]).
    /// A probability missing or outside `[0, 1]` is the error [`MissionMdp::decide`] gives: the
    /// first in file order, by name.
    pub fn decide_slots(
        &mut self,
        ws: &mut Workspace,
        state: usize,
        values: &[Option<f64>],
        slots: &[Option<usize>],
        pi: usize,
        horizon: usize,
    ) -> Result<Option<Decision>, InstantiateError> {
        for (k, name) in self.vars.iter().enumerate() {
            let v = slots
                .get(k)
                .copied()
                .flatten()
                .and_then(|s| values.get(s).copied().flatten())
                .ok_or_else(|| InstantiateError::MissingProbability(name.clone()))?;
            if !(0.0..=1.0).contains(&v) {
                return Err(InstantiateError::BadProbability {
                    name: name.clone(),
                    value: v,
                });
            }
            self.values[k] = v;
        }
        self.decide_loaded(ws, state, pi, horizon)
    }

    /// The decision with `self.values` loaded: the memo, else a solve.
    fn decide_loaded(
        &mut self,
        ws: &mut Workspace,
        state: usize,
        pi: usize,
        horizon: usize,
    ) -> Result<Option<Decision>, InstantiateError> {
        let i = match self.solved.hit(&self.values, pi, horizon) {
            Some(i) => i,
            None => {
                let i = self.solved.slot();
                // Invalid until filled (a failed fill leaves it matching nothing).
                self.solved.entries[i].values.clear();
                self.solved.entries[i].values.push(f64::NAN);
                self.fill_checked(pi)?;
                let fh = ws.finite_horizon(&self.mdp, horizon);
                let n = self.states.len();
                let memo = &mut self.solved.entries[i];
                memo.decision.clear();
                memo.value.clear();
                for s in 0..n {
                    memo.decision
                        .push(fh.decision(s).map_or(u32::MAX, |a| a as u32));
                    memo.value.push(fh.value(0, s));
                }
                memo.values.clear();
                memo.values.extend_from_slice(&self.values);
                memo.policy = pi;
                memo.horizon = horizon;
                memo.iterations = fh.stats().iterations;
                self.solved.solves += 1;
                i
            }
        };
        self.solved.current = i;
        let memo = &self.solved.entries[i];
        let a = memo.decision[state];
        Ok((a != u32::MAX).then(|| Decision {
            action: a as usize,
            value: memo.value[state],
            iterations: memo.iterations,
        }))
    }

    /// The decision as a decision-log entry (allocates the strings).
    pub fn proposal(&self, state: usize, d: &Decision, horizon: usize) -> MdpProposal {
        MdpProposal {
            mdp: self.name.clone(),
            state: self.states[state].clone(),
            action: self.actions[d.action].clone(),
            actions: crate::action_id::ActionIds::from_names(&self.does[d.action]),
            value: d.value,
            iterations: d.iterations,
            horizon: horizon as u32,
            inputs: self
                .vars
                .iter()
                .cloned()
                .zip(self.values.iter().copied())
                .collect(),
            reason: String::new(),
        }
    }

    /// As [`MissionMdp::proposal`], into a reused entry (its strings keep their capacity); its
    /// `actions` are left to the caller, who holds the catalogue their ids index.
    pub fn proposal_into(&self, state: usize, d: &Decision, horizon: usize, out: &mut MdpProposal) {
        out.mdp.clone_from(&self.name);
        out.state.clone_from(&self.states[state]);
        out.action.clone_from(&self.actions[d.action]);
        out.value = d.value;
        out.iterations = d.iterations;
        out.horizon = horizon as u32;
        // Provenance: the probabilities this solve read, at the values it read, by slot over
        // the MDP's variables in name order (named when the record is written).
        out.inputs.reset_over(&self.input_names);
        for (slot, &k) in self.by_name.iter().enumerate() {
            out.inputs.set(slot, self.values[k]);
        }
        out.reason.clear();
    }

    /// Evaluate every expression at `self.values` into the engine model.
    fn fill(&mut self, policy: usize) {
        let vals = &self.values;
        for (p, e) in self.mdp.probs_mut().iter_mut().zip(&self.trans_expr) {
            *p = e.eval(vals);
        }
        for (x, e) in self.enter_value.iter_mut().zip(&self.enter_reward[policy]) {
            *x = e.as_ref().map_or(0.0, |e| e.eval(vals));
        }
        for c in 0..self.mdp.n_choices() {
            let mut r = self.choice_reward[policy][c].eval(vals);
            let range = self.mdp.transition_range(c);
            for t in range {
                let next = self.mdp.next_states()[t] as usize;
                // `None` adds nothing (not `+ p * 0.0`): keeps the sum bit-identical to the
                // per-transition evaluation this replaces.
                if self.enter_reward[policy][next].is_some() {
                    r += self.mdp.probs()[t] * self.enter_value[next];
                }
            }
            self.mdp.rewards_mut()[c] = r;
        }
    }
}

/// All MDPs listed in `params/mdp/index.toml`.
#[derive(Debug, Clone)]
pub struct MissionMdps {
    mdps: Vec<MissionMdp>,
    concurrent: Vec<String>,
    monolithic: Option<String>,
    reference: Option<String>,
    check_point: BTreeMap<String, f64>,
}

impl MissionMdps {
    /// Load `params_dir/mdp/index.toml` and every MDP it lists. `known_probability_names` are the
    /// names the health BNs publish; any other name in an expression is an error.
    pub fn load(params: &ParamsFiles, known_probability_names: &[&str]) -> Result<Self, SpecError> {
        let dir = params.dir().join("mdp");
        let index_path = dir.join("index.toml");
        let index: IndexFile = read_toml(params, &index_path)?;
        if index.concurrent.is_empty() {
            return Err(SpecError::new(
                &index_path,
                "concurrent",
                "no MDPs: the decision layer needs at least one concurrent MDP",
            ));
        }
        for (k, v) in &index.check_point {
            if !known_probability_names.contains(&k.as_str()) {
                return Err(SpecError::new(
                    &index_path,
                    format!("check_point.{k}"),
                    "unknown probability name",
                ));
            }
            if !(0.0..=1.0).contains(v) {
                return Err(SpecError::new(
                    &index_path,
                    format!("check_point.{k}"),
                    "not in [0, 1]",
                ));
            }
        }
        let mut names: Vec<String> = index.concurrent.clone();
        names.extend(index.monolithic.iter().cloned());
        names.extend(index.reference.iter().cloned());
        let mut seen = BTreeSet::new();
        let mut mdps = Vec::new();
        for n in &names {
            if !seen.insert(n.clone()) {
                return Err(SpecError::new(
                    &index_path,
                    "concurrent",
                    format!("MDP '{n}' listed twice"),
                ));
            }
            let path = dir.join(format!("{n}.toml"));
            let m = load_mdp(params, &path, known_probability_names, &index.check_point)?;
            if m.name != *n {
                return Err(SpecError::new(
                    &path,
                    "name",
                    format!("is '{}', expected '{n}' (file name)", m.name),
                ));
            }
            if let Some(first) = mdps.first() {
                let first: &MissionMdp = first;
                if first.policies != m.policies {
                    return Err(SpecError::new(
                        &path,
                        "reward",
                        format!(
                            "policies {:?} differ from {:?} in {}",
                            m.policies,
                            first.policies,
                            first.file.display()
                        ),
                    ));
                }
            }
            mdps.push(m);
        }
        Ok(Self {
            mdps,
            concurrent: index.concurrent,
            monolithic: index.monolithic,
            reference: index.reference,
            check_point: index.check_point,
        })
    }

    /// The MDP named `name`.
    pub fn get(&self, name: &str) -> Option<&MissionMdp> {
        self.mdps.iter().find(|m| m.name == name)
    }
    /// The MDP named `name`, mutable.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut MissionMdp> {
        self.mdps.iter_mut().find(|m| m.name == name)
    }
    /// Every loaded MDP.
    pub fn all(&self) -> &[MissionMdp] {
        &self.mdps
    }
    /// Solves run by every MDP's `decide` so far.
    pub fn solves(&self) -> u64 {
        self.mdps.iter().map(MissionMdp::solves).sum()
    }
    /// Turn every MDP's decision memo on or off ([`MissionMdp::set_solve_cache`]).
    pub fn set_solve_cache(&mut self, on: bool) {
        self.mdps.iter_mut().for_each(|m| m.set_solve_cache(on));
    }
    /// Names of the concurrent MDPs, in index order.
    pub fn concurrent(&self) -> &[String] {
        &self.concurrent
    }
    /// Name of the MDP solving the whole mission at once, if the index names one.
    pub fn monolithic(&self) -> Option<&str> {
        self.monolithic.as_deref()
    }
    /// Name of the reference tracking MDP (paper Figure 1), if the index names one.
    pub fn reference(&self) -> Option<&str> {
        self.reference.as_deref()
    }
    /// The index's check point (paper section 7.1 values plus stated assumptions).
    pub fn check_point(&self) -> &BTreeMap<String, f64> {
        &self.check_point
    }
    /// Policy names (identical in every MDP).
    pub fn policies(&self) -> &[String] {
        self.mdps
            .first()
            .map(|m| m.policies.as_slice())
            .unwrap_or(&[])
    }
    /// Union of the primitive actions of every MDP (sorted).
    pub fn primitive_actions(&self) -> Vec<String> {
        let set: BTreeSet<&String> = self
            .mdps
            .iter()
            .flat_map(|m| m.does.iter().flatten())
            .collect();
        set.into_iter().cloned().collect()
    }
}

fn err(path: &Path, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(path, entry, reason)
}

/// Most states of one MDP (the shipped monolithic MDP has 20).
pub const MAX_STATES: usize = 256;
/// Most actions of one MDP (the shipped monolithic MDP has under 30).
pub const MAX_ACTIONS: usize = 128;

#[cfg(test)]
mod tests;
