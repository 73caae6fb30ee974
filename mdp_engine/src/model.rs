//! The MDP itself: sparse CSR storage of states, admissible actions (choices) and transitions,
//! its validation, serialization, and the Q-value and tie-breaking rules every solver shares.

use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Index of a state, `0..n_states`.
pub type StateId = usize;
/// Index of an action, `0..n_actions`; a state admits a subset of them.
pub type ActionId = usize;

/// Relative margin by which a Q-value must beat the current best to replace it (see crate docs).
pub const TIE_TOLERANCE: f64 = 1e-12;
/// Tolerance on `sum_s' p(s'|s,a) = 1` used by [`Mdp::validate`].
pub const ROW_SUM_TOLERANCE: f64 = 1e-9;

pub(crate) const NONE: u32 = u32::MAX;

/// Why an MDP could not be built or is not a valid stochastic model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MdpError {
    /// A state index (of a choice or a successor) is not below the state count.
    #[error("state {state} out of range (n_states = {n_states})")]
    StateOutOfRange {
        /// The offending state index.
        state: usize,
        /// The model's state count.
        n_states: usize,
    },
    /// An action index is not below the action count.
    #[error("action {action} out of range (n_actions = {n_actions})")]
    ActionOutOfRange {
        /// The offending action index.
        action: usize,
        /// The model's action count.
        n_actions: usize,
    },
    /// The same (state, action) pair was given twice.
    #[error("action {action} given twice for state {state}")]
    DuplicateChoice {
        /// The state of the repeated choice.
        state: usize,
        /// The repeated action.
        action: usize,
    },
    /// A choice has an empty transition list.
    #[error("state {state}, action {action}: no transition")]
    NoTransition {
        /// The state of the empty choice.
        state: usize,
        /// The action of the empty choice.
        action: usize,
    },
    /// A choice lists the same successor twice.
    #[error("state {state}, action {action}: next state {next} given twice")]
    DuplicateNext {
        /// The state of the choice.
        state: usize,
        /// The action of the choice.
        action: usize,
        /// The repeated successor.
        next: usize,
    },
    /// A transition probability is outside `[0, 1]` (beyond [`ROW_SUM_TOLERANCE`]) or NaN.
    #[error("state {state}, action {action}: probability {prob} to {next} not in [0, 1]")]
    BadProbability {
        /// The state of the choice.
        state: usize,
        /// The action of the choice.
        action: usize,
        /// The successor the probability leads to.
        next: usize,
        /// The rejected probability.
        prob: f64,
    },
    /// A choice's probabilities do not sum to 1 within [`ROW_SUM_TOLERANCE`].
    #[error("state {state}, action {action}: probabilities sum to {sum}, not 1")]
    RowSum {
        /// The state of the choice.
        state: usize,
        /// The action of the choice.
        action: usize,
        /// The actual sum.
        sum: f64,
    },
    /// A reward is NaN or infinite.
    #[error("state {state}, action {action}: reward {reward} is not finite")]
    BadReward {
        /// The state of the choice.
        state: usize,
        /// The action of the choice.
        action: usize,
        /// The rejected reward.
        reward: f64,
    },
    /// A count does not fit the 32-bit indices of the compressed storage.
    #[error("too many states, actions or transitions for 32-bit indices")]
    TooLarge,
}

/// A sparse MDP in compressed (CSR-like) storage: states -> choices (admissible actions, sorted by
/// action index) -> transitions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MdpRaw")]
pub struct Mdp {
    pub(crate) n_actions: usize,
    /// `state_start[s]..state_start[s+1]` are the choices of state `s`.
    pub(crate) state_start: Vec<u32>,
    pub(crate) choice_action: Vec<u32>,
    pub(crate) choice_reward: Vec<f64>,
    /// `choice_start[c]..choice_start[c+1]` are the transitions of choice `c`.
    pub(crate) choice_start: Vec<u32>,
    pub(crate) next: Vec<u32>,
    pub(crate) prob: Vec<f64>,
    /// `k` when every choice has exactly `k` transitions (1..=[`MAX_UNIFORM_SUCCESSORS`]), else 0:
    /// the solvers then use a kernel with the count fixed at compile time (derived from
    /// `choice_start`, which never changes after build).
    #[serde(skip_serializing)]
    pub(crate) uniform_successors: u32,
}

/// Largest per-choice successor count with its own solver kernel (see `Mdp::uniform_successors`).
pub(crate) const MAX_UNIFORM_SUCCESSORS: u32 = 5;

/// `k` if every choice `choice_start[c]..choice_start[c + 1]` has exactly `k` transitions and `k`
/// is at most [`MAX_UNIFORM_SUCCESSORS`], else 0.
pub(crate) fn uniform_successors(choice_start: &[u32]) -> u32 {
    let mut it = choice_start.windows(2).map(|w| w[1] - w[0]);
    match it.next() {
        Some(k) if k <= MAX_UNIFORM_SUCCESSORS && it.all(|x| x == k) => k,
        _ => 0,
    }
}

/// Serialized form of [`Mdp`]; deserialization checks the layout before trusting it, so a
/// malformed file is an error, never a panic in a solver.
#[derive(Deserialize)]
struct MdpRaw {
    n_actions: usize,
    state_start: Vec<u32>,
    choice_action: Vec<u32>,
    choice_reward: Vec<f64>,
    choice_start: Vec<u32>,
    next: Vec<u32>,
    prob: Vec<f64>,
}

impl TryFrom<MdpRaw> for Mdp {
    type Error = String;
    fn try_from(r: MdpRaw) -> Result<Self, String> {
        let offsets_ok = |v: &[u32], end: usize| {
            v.first() == Some(&0)
                && v.windows(2).all(|w| w[0] <= w[1])
                && v.last().map(|x| *x as usize) == Some(end)
        };
        let n_states = r.state_start.len().saturating_sub(1);
        let n_choices = r.choice_action.len();
        if !offsets_ok(&r.state_start, n_choices) {
            return Err("state_start is not a valid offset array".into());
        }
        if r.choice_reward.len() != n_choices || r.choice_start.len() != n_choices + 1 {
            return Err("choice arrays have inconsistent lengths".into());
        }
        if !offsets_ok(&r.choice_start, r.next.len()) || r.prob.len() != r.next.len() {
            return Err("choice_start / next / prob are inconsistent".into());
        }
        if r.next.iter().any(|n| *n as usize >= n_states) {
            return Err("next state out of range".into());
        }
        for s in 0..n_states {
            let acts = &r.choice_action[r.state_start[s] as usize..r.state_start[s + 1] as usize];
            if acts.iter().any(|a| *a as usize >= r.n_actions)
                || acts.windows(2).any(|w| w[0] >= w[1])
            {
                return Err(format!(
                    "state {s}: actions out of range or not strictly increasing"
                ));
            }
        }
        if r.choice_start.windows(2).any(|w| w[0] == w[1]) {
            return Err("a choice has no transition".into());
        }
        let m = Mdp {
            uniform_successors: uniform_successors(&r.choice_start),
            n_actions: r.n_actions,
            state_start: r.state_start,
            choice_action: r.choice_action,
            choice_reward: r.choice_reward,
            choice_start: r.choice_start,
            next: r.next,
            prob: r.prob,
        };
        m.validate().map_err(|e| e.to_string())?;
        Ok(m)
    }
}

/// One admissible (state, action) pair seen through [`Mdp::choices`].
#[derive(Debug, Clone, Copy)]
pub struct Choice<'a> {
    /// Global choice index (for [`Mdp::rewards_mut`] and [`Mdp::transition_range`]).
    pub index: usize,
    /// The admissible action.
    pub action: ActionId,
    /// Immediate reward `R(s, a)`.
    pub reward: f64,
    /// Successor states, in the order given to the builder.
    pub next: &'a [u32],
    /// Transition probabilities, aligned with `next`.
    pub prob: &'a [f64],
}

impl Mdp {
    /// Number of states (terminal ones included).
    pub fn n_states(&self) -> usize {
        self.state_start.len() - 1
    }
    /// Size of the action index space (not every action is admissible everywhere).
    pub fn n_actions(&self) -> usize {
        self.n_actions
    }
    /// Number of admissible (state, action) pairs.
    pub fn n_choices(&self) -> usize {
        self.choice_action.len()
    }
    /// Number of stored (nonzero-pattern) transitions.
    pub fn n_transitions(&self) -> usize {
        self.next.len()
    }
    /// True when the state has no admissible action (value 0, no decision).
    pub fn is_terminal(&self, s: StateId) -> bool {
        self.state_start[s] == self.state_start[s + 1]
    }

    /// The admissible actions of `s`, in increasing action index.
    pub fn choices(&self, s: StateId) -> impl Iterator<Item = Choice<'_>> + '_ {
        let r = self.state_start[s] as usize..self.state_start[s + 1] as usize;
        r.map(move |c| {
            let t = self.transition_range(c);
            Choice {
                index: c,
                action: self.choice_action[c] as usize,
                reward: self.choice_reward[c],
                next: &self.next[t.clone()],
                prob: &self.prob[t],
            }
        })
    }

    /// Global index of choice `(s, a)`, or `None` when `a` is not admissible in `s`.
    pub fn choice_index(&self, s: StateId, a: ActionId) -> Option<usize> {
        let lo = self.state_start[s] as usize;
        let hi = self.state_start[s + 1] as usize;
        self.choice_action[lo..hi]
            .binary_search(&(a as u32))
            .ok()
            .map(|i| lo + i)
    }

    /// Indices into [`Mdp::probs_mut`] / [`Mdp::next_states`] of choice `c`'s transitions.
    pub fn transition_range(&self, c: usize) -> Range<usize> {
        self.choice_start[c] as usize..self.choice_start[c + 1] as usize
    }
    /// Successor state of every transition, indexed by transition (see [`Mdp::transition_range`]).
    pub fn next_states(&self) -> &[u32] {
        &self.next
    }
    /// Probability of every transition, indexed like [`Mdp::next_states`].
    pub fn probs(&self) -> &[f64] {
        &self.prob
    }
    /// The probabilities for overwriting in place (the structure stays fixed); call
    /// [`Mdp::validate`] after.
    pub fn probs_mut(&mut self) -> &mut [f64] {
        &mut self.prob
    }
    /// Rewards indexed by choice index.
    pub fn rewards(&self) -> &[f64] {
        &self.choice_reward
    }
    /// Rewards indexed by choice index.
    pub fn rewards_mut(&mut self) -> &mut [f64] {
        &mut self.choice_reward
    }
    /// The state a choice belongs to (linear in the number of states; for diagnostics).
    fn state_of_choice(&self, c: usize) -> StateId {
        self.state_start.partition_point(|&x| x as usize <= c) - 1
    }

    /// Check every probability is in `[0, 1]`, every row sums to 1 (within
    /// [`ROW_SUM_TOLERANCE`]) and every reward is finite.
    pub fn validate(&self) -> Result<(), MdpError> {
        for c in 0..self.n_choices() {
            let action = self.choice_action[c] as usize;
            let reward = self.choice_reward[c];
            if !reward.is_finite() {
                return Err(MdpError::BadReward {
                    state: self.state_of_choice(c),
                    action,
                    reward,
                });
            }
            let mut sum = 0.0;
            for t in self.transition_range(c) {
                let p = self.prob[t];
                if !(-ROW_SUM_TOLERANCE..=1.0 + ROW_SUM_TOLERANCE).contains(&p) {
                    return Err(MdpError::BadProbability {
                        state: self.state_of_choice(c),
                        action,
                        next: self.next[t] as usize,
                        prob: p,
                    });
                }
                sum += p;
            }
            if (sum - 1.0).abs() > ROW_SUM_TOLERANCE {
                return Err(MdpError::RowSum {
                    state: self.state_of_choice(c),
                    action,
                    sum,
                });
            }
        }
        Ok(())
    }

    /// `R(s,a) + gamma * sum p(s'|s,a) v(s')` for choice `c`.
    #[inline]
    pub(crate) fn q(&self, c: usize, gamma: f64, v: &[f64]) -> f64 {
        let t = self.transition_range(c);
        let mut acc = 0.0;
        for (n, p) in self.next[t.clone()].iter().zip(&self.prob[t]) {
            acc += p * v[*n as usize];
        }
        self.choice_reward[c] + gamma * acc
    }

    /// Best choice of `s` under `v` (lowest action index among ties), its Q-value, or `None` for a
    /// terminal state.
    #[inline]
    pub(crate) fn greedy(&self, s: StateId, gamma: f64, v: &[f64]) -> Option<(usize, f64)> {
        let lo = self.state_start[s] as usize;
        let hi = self.state_start[s + 1] as usize;
        if lo == hi {
            return None;
        }
        let mut best = (lo, self.q(lo, gamma, v));
        for c in lo + 1..hi {
            let q = self.q(c, gamma, v);
            if beats(q, best.1) {
                best = (c, q);
            }
        }
        Some(best)
    }
}

#[inline]
pub(crate) fn beats(q: f64, best: f64) -> bool {
    q > best + TIE_TOLERANCE * best.abs().max(1.0)
}

/// The value a later Q must exceed to replace `best` (see [`beats`]).
#[inline(always)]
pub(crate) fn beat_bar(best: f64) -> f64 {
    best + TIE_TOLERANCE * best.abs().max(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MdpBuilder, Workspace};

    #[test]
    fn deserialization_rejects_inconsistent_layouts() {
        let mut b = MdpBuilder::new(2, 2);
        b.choice(0, 1, 1.0, &[(1, 1.0)])
            .choice(1, 0, 0.0, &[(0, 0.5), (1, 0.5)]);
        let m = b.build().unwrap();
        let json = serde_json::to_string(&m).unwrap();
        assert_eq!(serde_json::from_str::<Mdp>(&json).unwrap(), m);
        for (from, to) in [
            ("\"next\":[1,0,1]", "\"next\":[1,0,2]"), // next state out of range
            ("\"prob\":[1.0,0.5,0.5]", "\"prob\":[1.0,0.5]"), // length mismatch
            ("\"prob\":[1.0,0.5,0.5]", "\"prob\":[1.0,0.5,0.6]"), // row sum
            ("\"n_actions\":2", "\"n_actions\":1"),   // action out of range
            ("\"state_start\":[0,1,2]", "\"state_start\":[0,2,1]"), // offsets not monotone
            ("\"choice_start\":[0,1,3]", "\"choice_start\":[0,1,4]"),
        ] {
            assert!(json.contains(from), "{json}");
            let bad = json.replace(from, to);
            assert!(serde_json::from_str::<Mdp>(&bad).is_err(), "accepted {bad}");
        }
    }

    #[test]
    fn in_place_update_changes_decision() {
        // s0: a0 (reward 0) -> s1 w.p. p, terminal s2 otherwise; a1 (reward 0.3) -> s2.
        // s1: a0 reward 1 -> s2. Horizon 2: a0 is worth p * 1, a1 is worth 0.3.
        let mut b = MdpBuilder::new(3, 2);
        b.choice(0, 0, 0.0, &[(1, 0.5), (2, 0.5)])
            .choice(0, 1, 0.3, &[(2, 1.0)])
            .choice(1, 0, 1.0, &[(2, 1.0)]);
        let mut m = b.build().unwrap();
        let mut ws = Workspace::new();
        assert_eq!(ws.finite_horizon(&m, 2).decision(0), Some(0));
        let c = m.choice_index(0, 0).unwrap();
        let r = m.transition_range(c);
        m.probs_mut()[r.start] = 0.2;
        m.probs_mut()[r.start + 1] = 0.8;
        m.validate().unwrap();
        assert_eq!(ws.finite_horizon(&m, 2).decision(0), Some(1));
        assert_eq!(m.choice_index(1, 1), None);
    }
}
