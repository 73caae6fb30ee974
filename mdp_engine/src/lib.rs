//! Sparse finite MDPs and their solvers.
//!
//! * [`Mdp`]: per state, the admissible actions only (an action not admissible in a state is
//!   simply absent), each with a reward `R(s,a)` and a sparse list of `(next_state, probability)`.
//!   A state with no admissible action is *terminal*: its value is 0 and it has no decision.
//!   The structure is fixed at build time; probabilities and rewards can be overwritten in place
//!   ([`Mdp::probs_mut`], [`Mdp::rewards_mut`]) so re-instantiating with new probabilities costs
//!   no allocation.
//! * [`Workspace`]: preallocated solver buffers, reused across solves. After the first solve of a
//!   given size (and horizon), re-solving allocates nothing.
//! * Solvers (methods on [`Workspace`]): finite-horizon undiscounted backward induction (the BFM
//!   paper's eq. 1–3; stops early once a certified bound shows the remaining stages are the
//!   computed ones plus a constant gain per stage, to within [`FH_STOP_TOLERANCE`]), value
//!   iteration (stopped on the MacQueen–Porteus bracket), policy iteration (eq. 4–5, policy
//!   evaluation by a dense in-place linear solve over the non-terminal states up to
//!   [`Config::dense_eval_max_states`] states, above by warm-started sparse sweeps with a
//!   certified stop) and modified policy iteration.
//!
//! **Tie-breaking** is deterministic everywhere: a later action (higher action index) replaces the
//! current best only if its Q-value is larger by more than [`TIE_TOLERANCE`] relative to the best
//! (`q > best + TIE_TOLERANCE * max(1, |best|)`). So among (numerically) equal Q-values the lowest
//! action index wins. The infinite-horizon solvers all finish with one greedy extraction from their
//! final values using this rule, so they return comparable policies.
//!
//! **Discounting.** `gamma` must be in `(0, 1]`. With `gamma < 1` every solver converges. With
//! `gamma = 1` (total reward) the policy-evaluation system `(I - P_pi) v = r_pi` (terminal states
//! fixed at 0) is nonsingular exactly when every non-terminal state reaches a terminal state with
//! probability 1 under `pi` (a *proper* policy); policy iteration returns
//! [`SolveError::Singular`] otherwise, and value iteration / modified policy iteration may stop at
//! `max_iterations` with `converged = false`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::ops::Range;

pub type StateId = usize;
pub type ActionId = usize;

/// Relative margin by which a Q-value must beat the current best to replace it (see crate docs).
pub const TIE_TOLERANCE: f64 = 1e-12;
/// Tolerance on `sum_s' p(s'|s,a) = 1` used by [`Mdp::validate`].
pub const ROW_SUM_TOLERANCE: f64 = 1e-9;
/// A pivot smaller than this (relative to the largest matrix entry) makes the evaluation singular.
pub const SINGULAR_TOLERANCE: f64 = 1e-12;

const NONE: u32 = u32::MAX;

/// Why an MDP could not be built or is not a valid stochastic model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MdpError {
    #[error("state {state} out of range (n_states = {n_states})")]
    StateOutOfRange { state: usize, n_states: usize },
    #[error("action {action} out of range (n_actions = {n_actions})")]
    ActionOutOfRange { action: usize, n_actions: usize },
    #[error("action {action} given twice for state {state}")]
    DuplicateChoice { state: usize, action: usize },
    #[error("state {state}, action {action}: no transition")]
    NoTransition { state: usize, action: usize },
    #[error("state {state}, action {action}: next state {next} given twice")]
    DuplicateNext {
        state: usize,
        action: usize,
        next: usize,
    },
    #[error("state {state}, action {action}: probability {prob} to {next} not in [0, 1]")]
    BadProbability {
        state: usize,
        action: usize,
        next: usize,
        prob: f64,
    },
    #[error("state {state}, action {action}: probabilities sum to {sum}, not 1")]
    RowSum {
        state: usize,
        action: usize,
        sum: f64,
    },
    #[error("state {state}, action {action}: reward {reward} is not finite")]
    BadReward {
        state: usize,
        action: usize,
        reward: f64,
    },
    #[error("too many states, actions or transitions for 32-bit indices")]
    TooLarge,
}

/// Why a solve failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    #[error("discount factor {0} not in (0, 1]")]
    BadGamma(f64),
    #[error(
        "policy evaluation singular at iteration {iteration} (improper policy with gamma = 1?)"
    )]
    Singular { iteration: u32 },
}

/// A sparse MDP in compressed (CSR-like) storage: states -> choices (admissible actions, sorted by
/// action index) -> transitions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MdpRaw")]
pub struct Mdp {
    n_actions: usize,
    /// `state_start[s]..state_start[s+1]` are the choices of state `s`.
    state_start: Vec<u32>,
    choice_action: Vec<u32>,
    choice_reward: Vec<f64>,
    /// `choice_start[c]..choice_start[c+1]` are the transitions of choice `c`.
    choice_start: Vec<u32>,
    next: Vec<u32>,
    prob: Vec<f64>,
    /// `k` when every choice has exactly `k` transitions (1..=[`MAX_UNIFORM_SUCCESSORS`]), else 0:
    /// the solvers then use a kernel with the count fixed at compile time (derived from
    /// `choice_start`, which never changes after build).
    #[serde(skip_serializing)]
    uniform_successors: u32,
}

/// Largest per-choice successor count with its own solver kernel (see `Mdp::uniform_successors`).
const MAX_UNIFORM_SUCCESSORS: u32 = 5;

/// `k` if every choice `choice_start[c]..choice_start[c + 1]` has exactly `k` transitions and `k`
/// is at most [`MAX_UNIFORM_SUCCESSORS`], else 0.
fn uniform_successors(choice_start: &[u32]) -> u32 {
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
    pub action: ActionId,
    pub reward: f64,
    pub next: &'a [u32],
    pub prob: &'a [f64],
}

/// (state, action, reward, transitions) as given to [`MdpBuilder::choice`].
type PendingChoice = (usize, usize, f64, Vec<(usize, f64)>);

/// Collects choices in any order, then builds an [`Mdp`].
#[derive(Debug, Clone)]
pub struct MdpBuilder {
    n_states: usize,
    n_actions: usize,
    choices: Vec<PendingChoice>,
}

impl MdpBuilder {
    pub fn new(n_states: usize, n_actions: usize) -> Self {
        Self {
            n_states,
            n_actions,
            choices: Vec::new(),
        }
    }

    /// Make `action` admissible in `state` with reward `reward` and transitions `(next, p)`.
    /// Transitions keep the given order (callers may rely on it to overwrite probabilities).
    pub fn choice(
        &mut self,
        state: StateId,
        action: ActionId,
        reward: f64,
        transitions: &[(StateId, f64)],
    ) -> &mut Self {
        self.choices
            .push((state, action, reward, transitions.to_vec()));
        self
    }

    /// Check indices and duplicates, lay out the storage and [`Mdp::validate`] it.
    pub fn build(self) -> Result<Mdp, MdpError> {
        let mdp = self.build_unchecked()?;
        mdp.validate()?;
        Ok(mdp)
    }

    /// Like [`MdpBuilder::build`] but without checking probabilities and rewards, for callers that
    /// fill them in afterwards (then call [`Mdp::validate`]).
    pub fn build_unchecked(mut self) -> Result<Mdp, MdpError> {
        let n_states = self.n_states;
        let n_actions = self.n_actions;
        let total: usize = self.choices.iter().map(|c| c.3.len()).sum();
        if n_states >= NONE as usize
            || n_actions >= NONE as usize
            || self.choices.len() >= NONE as usize
            || total >= NONE as usize
        {
            return Err(MdpError::TooLarge);
        }
        for (s, a, _, tr) in &self.choices {
            if *s >= n_states {
                return Err(MdpError::StateOutOfRange {
                    state: *s,
                    n_states,
                });
            }
            if *a >= n_actions {
                return Err(MdpError::ActionOutOfRange {
                    action: *a,
                    n_actions,
                });
            }
            if tr.is_empty() {
                return Err(MdpError::NoTransition {
                    state: *s,
                    action: *a,
                });
            }
            for (i, (n, _)) in tr.iter().enumerate() {
                if *n >= n_states {
                    return Err(MdpError::StateOutOfRange {
                        state: *n,
                        n_states,
                    });
                }
                if tr[..i].iter().any(|(m, _)| m == n) {
                    return Err(MdpError::DuplicateNext {
                        state: *s,
                        action: *a,
                        next: *n,
                    });
                }
            }
        }
        self.choices.sort_by_key(|c| (c.0, c.1));
        for w in self.choices.windows(2) {
            if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
                return Err(MdpError::DuplicateChoice {
                    state: w[0].0,
                    action: w[0].1,
                });
            }
        }
        let mut mdp = Mdp {
            n_actions,
            state_start: Vec::with_capacity(n_states + 1),
            choice_action: Vec::with_capacity(self.choices.len()),
            choice_reward: Vec::with_capacity(self.choices.len()),
            choice_start: Vec::with_capacity(self.choices.len() + 1),
            next: Vec::with_capacity(total),
            prob: Vec::with_capacity(total),
            uniform_successors: 0,
        };
        let mut c = 0;
        for s in 0..n_states {
            mdp.state_start.push(mdp.choice_action.len() as u32);
            while c < self.choices.len() && self.choices[c].0 == s {
                let (_, a, r, tr) = &self.choices[c];
                mdp.choice_action.push(*a as u32);
                mdp.choice_reward.push(*r);
                mdp.choice_start.push(mdp.next.len() as u32);
                for (n, p) in tr {
                    mdp.next.push(*n as u32);
                    mdp.prob.push(*p);
                }
                c += 1;
            }
        }
        mdp.state_start.push(mdp.choice_action.len() as u32);
        mdp.choice_start.push(mdp.next.len() as u32);
        mdp.uniform_successors = uniform_successors(&mdp.choice_start);
        Ok(mdp)
    }
}

impl Mdp {
    pub fn n_states(&self) -> usize {
        self.state_start.len() - 1
    }
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
    pub fn next_states(&self) -> &[u32] {
        &self.next
    }
    pub fn probs(&self) -> &[f64] {
        &self.prob
    }
    pub fn probs_mut(&mut self) -> &mut [f64] {
        &mut self.prob
    }
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
    fn q(&self, c: usize, gamma: f64, v: &[f64]) -> f64 {
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
    fn greedy(&self, s: StateId, gamma: f64, v: &[f64]) -> Option<(usize, f64)> {
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
fn beats(q: f64, best: f64) -> bool {
    q > best + TIE_TOLERANCE * best.abs().max(1.0)
}

/// Default [`Config::dense_eval_max_states`]. Measured on the benches' random models (|A| = 10,
/// 5 successors, gamma 0.95): at 100 states sparse PI took 258 us against 451 us dense, at 1000
/// states 6.7 ms against 560 ms. Small models stay dense: on the paper's models (<= 20 states,
/// absorbing terminal states, where the bracket converges only at rate gamma) one dense solve is
/// a few thousand flops.
pub const DENSE_EVAL_MAX_STATES: usize = 50;
/// Sparse policy evaluation stops when its certified error (`gamma < 1`) or its last change
/// (`gamma = 1`) is at most this relative to `max(1, |v|_inf)`.
pub const SPARSE_EVAL_TOLERANCE: f64 = 1e-13;
/// Sparse policy evaluation (`gamma < 1`) also stops when its bracket has not halved in this many
/// sweeps (rounding floor), returning the midpoint.
pub const SPARSE_EVAL_STALL_SWEEPS: u32 = 2000;
/// Cap on the sweeps of one sparse policy evaluation.
pub const SPARSE_EVAL_MAX_SWEEPS: u32 = 1_000_000;

/// Relative bound for the finite-horizon early stop: the extrapolated stages may differ from full
/// backward induction by at most this times `max(1, |V_0|)` in value, and a kept action may be
/// worse than the best by at most as much beyond the [`TIE_TOLERANCE`] (see
/// [`Workspace::finite_horizon`]). Full backward induction's own rounding is of order
/// `H * 1e-16 * |V_0|`, a hundred times smaller at the paper's horizon.
pub const FH_STOP_TOLERANCE: f64 = 1e-12;

/// What one certified backup (stage `b - 1` from `V_b`, `V_{b+1}`) measures about `g = V_b -
/// V_{b+1}`, to bound the remaining stages without computing them.
///
/// With `T` the Bellman operator (monotone; `T(V + c) = TV + c` at non-terminal states for a
/// constant `c`, terminal states fixed at 0), for every `k >= 1`:
/// * span bound: `min g <= d <= max g` propagates to every earlier difference, so
///   `|V_{b-k} - (V_b + k g)| <= k * span(g)`;
/// * componentwise bound (multichain models, where terminal states keep `g = 0` and the others
///   earn a positive gain, so the span never shrinks): with `eps_up = max_{s,a} (P_a g)(s) -
///   g(s)` and `eps_lo = max_s g(s) - (P_{pi_b} g)(s)`, induction on `T(V + w) <= TV + max_a P_a
///   w` and `T(V + w) >= T_{pi_b}(V + w)` gives `V_b + k g - k(k+1)/2 eps_lo <= V_{b-k} <= V_b +
///   k g + k(k+1)/2 eps_up`.
///
/// Actions: at an earlier stage, `Q(s,a) = qb(s,a) + k (P_a g)(s) + (P_a err)(s)` with `qb` the
/// Q-values of stage `b - 1`, so the stage `b - 1` choice `a*` loses to another action at most
/// `2 E + k ((P_a g)(s) - (P_a* g)(s))`, and that gain difference is at most `eps_up + eps_star`
/// (`eps_star = max_s g(s) - (P_{a*} g)(s)`) or `span(g)`.
#[derive(Debug, Clone, Copy)]
struct FhCertificate {
    eps_up: f64,
    eps_lo: f64,
    eps_star: f64,
    span: f64,
    vmax: f64,
    gmax: f64,
}

/// The bounds of [`FhCertificate`] over `k` remaining stages.
#[derive(Debug, Clone, Copy)]
struct FhBound {
    /// On every extrapolated value.
    value: f64,
    /// On how much a kept action's Q-value may fall below the best (beyond the tie tolerance).
    action: f64,
}

impl FhCertificate {
    fn stop_bound(&self, k: usize) -> Option<FhBound> {
        let k = k as f64;
        let value = (k * self.span).min(k * (k + 1.0) * 0.5 * self.eps_up.max(self.eps_lo));
        let eta = (self.eps_up + self.eps_star).min(self.span);
        let action = 2.0 * value + k * eta;
        action.is_finite().then_some(FhBound { value, action })
    }

    /// An upper bound on `max(1, |V_0|)` when `V_0 ~ V_b + k g`.
    fn scale(&self, k: usize) -> f64 {
        (self.vmax + k as f64 * self.gmax).max(1.0)
    }
}

/// `sum_t p[t] * v[next[t]]` over the transitions `t..end` of one choice, in transition order.
///
/// With `K > 0` the choice has exactly `K` transitions (`end = t + K`): unrolled, no loop
/// control, which is most of the cost when choices have a few successors. With `K = 0` a plain
/// loop (unrolling it by two measured 6-8 % more ARMv7 instructions on navigation/monolithic).
///
/// # Safety
/// `t <= end <= pr.len() == nx.len()` and every `nx[t..end]` is `< v.len()`.
#[inline(always)]
unsafe fn dot_choice<const K: usize>(
    pr: &[f64],
    nx: &[u32],
    v: &[f64],
    mut t: usize,
    end: usize,
) -> f64 {
    // SAFETY: by the caller's contract.
    unsafe {
        let mut acc = 0.0;
        if K > 0 {
            for i in 0..K {
                acc +=
                    *pr.get_unchecked(t + i) * *v.get_unchecked(*nx.get_unchecked(t + i) as usize);
            }
            return acc;
        }
        while t < end {
            acc += *pr.get_unchecked(t) * *v.get_unchecked(*nx.get_unchecked(t) as usize);
            t += 1;
        }
        acc
    }
}

/// One plain Bellman backup with gamma = 1: `cur = T next`, `pol` the greedy actions. When
/// `next2` (`V_{t+2}`, one stage after `next`) is given, also returns the early-stop screen of
/// [`Workspace::finite_horizon`] for the next stage, `(max_s |cur - 2 next + next2|, max(1, max_s
/// |cur|))`, fused here so the screen costs two loads per state instead of a separate pass.
///
/// The hot loop of the finite-horizon solve: it walks the CSR arrays with running choice and
/// transition cursors (choices of consecutive states and transitions of consecutive choices are
/// contiguous, `state_start[0] = choice_start[0] = 0`) and reads them unchecked. Every index is in
/// range by the layout invariants that [`MdpBuilder::build_unchecked`] and deserialization check
/// before an [`Mdp`] exists (offsets start at 0, are monotone and end at the array lengths; every
/// `next` is `< n_states`) and that nothing can change afterwards ([`Mdp::probs_mut`] and
/// [`Mdp::rewards_mut`] only change values); the debug assertions recheck them. Summation order
/// is the plain one (`acc += p * v` in transition order, then `reward + acc`), so values are
/// bit-identical to the straightforward loop.
#[inline(always)]
fn backup_stage_impl<const SCREEN: bool, const K: usize>(
    mdp: &Mdp,
    next: &[f64],
    next2: &[f64],
    cur: &mut [f64],
    pol: &mut [u32],
) -> (f64, f64) {
    let n = cur.len();
    assert!(next.len() == n && pol.len() == n && mdp.state_start.len() == n + 1);
    if SCREEN {
        assert!(next2.len() == n);
    }
    let (ss, cs, nx, pr) = (&mdp.state_start, &mdp.choice_start, &mdp.next, &mdp.prob);
    let (rw, ca) = (&mdp.choice_reward, &mdp.choice_action);
    debug_assert!(ss[0] == 0 && cs[0] == 0 && ss[n] as usize == rw.len());
    debug_assert!(cs.len() == rw.len() + 1 && ca.len() == rw.len());
    debug_assert!(cs[rw.len()] as usize == nx.len() && pr.len() == nx.len());
    debug_assert!(nx.iter().all(|&j| (j as usize) < n));
    let (mut delta, mut scale) = (0.0f64, 1.0f64);
    let mut c = 0usize;
    let mut t = 0usize;
    for s in 0..n {
        // SAFETY: see the function docs; s < n, c < hi <= n_choices, t < choice_start[c + 1]
        // <= n_transitions, next[t] < n.
        unsafe {
            let hi = *ss.get_unchecked(s + 1) as usize;
            let (best, act) = if c == hi {
                (0.0, NONE)
            } else {
                let end = choice_end::<K>(cs, c, t);
                let acc = dot_choice::<K>(pr, nx, next, t, end);
                t = end;
                let mut best = *rw.get_unchecked(c) + acc;
                let mut best_c = c;
                let mut bar = beat_bar(best);
                c += 1;
                while c < hi {
                    let end = choice_end::<K>(cs, c, t);
                    let acc = dot_choice::<K>(pr, nx, next, t, end);
                    t = end;
                    let q = *rw.get_unchecked(c) + acc;
                    if q > bar {
                        best = q;
                        best_c = c;
                        bar = beat_bar(best);
                    }
                    c += 1;
                }
                (best, *ca.get_unchecked(best_c))
            };
            *cur.get_unchecked_mut(s) = best;
            *pol.get_unchecked_mut(s) = act;
            if SCREEN {
                let d = best - 2.0 * *next.get_unchecked(s) + *next2.get_unchecked(s);
                delta = delta.max(d.abs());
                scale = scale.max(best.abs());
            }
        }
    }
    (delta, scale)
}

/// The end of choice `c`'s transitions, which start at `t`: `t + K` for a uniform model (no
/// load), else from `choice_start`.
///
/// # Safety
/// `c + 1 < cs.len()`.
#[inline(always)]
unsafe fn choice_end<const K: usize>(cs: &[u32], c: usize, t: usize) -> usize {
    if K > 0 {
        debug_assert!(cs[c + 1] as usize == t + K);
        t + K
    } else {
        // SAFETY: by the caller's contract.
        unsafe { *cs.get_unchecked(c + 1) as usize }
    }
}

/// Calls `$f::<.., K>` with `K` the model's uniform successor count (0: mixed counts).
macro_rules! by_successors {
    ($mdp:expr, $f:ident $(::<$($g:tt),*>)?, ($($arg:expr),*)) => {
        match $mdp.uniform_successors {
            1 => $f::<$($($g,)*)? 1>($($arg),*),
            2 => $f::<$($($g,)*)? 2>($($arg),*),
            3 => $f::<$($($g,)*)? 3>($($arg),*),
            4 => $f::<$($($g,)*)? 4>($($arg),*),
            5 => $f::<$($($g,)*)? 5>($($arg),*),
            _ => $f::<$($($g,)*)? 0>($($arg),*),
        }
    };
}

/// [`backup_stage_impl`] without the screen.
fn backup_stage(mdp: &Mdp, next: &[f64], cur: &mut [f64], pol: &mut [u32]) {
    by_successors!(mdp, backup_stage_impl::<false>, (mdp, next, &[], cur, pol));
}

/// [`backup_stage_impl`] with the screen from `next2`.
fn backup_stage_screened(
    mdp: &Mdp,
    next: &[f64],
    next2: &[f64],
    cur: &mut [f64],
    pol: &mut [u32],
) -> (f64, f64) {
    by_successors!(mdp, backup_stage_impl::<true>, (mdp, next, next2, cur, pol))
}

/// One value-iteration sweep `nxt = T cur` (terminal states 0), returning `(min d, max d)` of `d =
/// nxt - cur` (infinities when there is no state). The same cursor walk and unchecked reads as
/// [`backup_stage_impl`] (same invariants), with `q = R + gamma * (sum p v)` in transition order.
fn vi_sweep(mdp: &Mdp, gamma: f64, cur: &[f64], nxt: &mut [f64]) -> (f64, f64) {
    by_successors!(mdp, vi_sweep_impl, (mdp, gamma, cur, nxt))
}

/// [`vi_sweep`] for models whose choices all have `K` transitions (`K = 0`: any count).
#[inline(always)]
fn vi_sweep_impl<const K: usize>(
    mdp: &Mdp,
    gamma: f64,
    cur: &[f64],
    nxt: &mut [f64],
) -> (f64, f64) {
    let n = cur.len();
    assert!(nxt.len() == n && mdp.state_start.len() == n + 1);
    let (ss, cs, nx, pr, rw) = (
        &mdp.state_start,
        &mdp.choice_start,
        &mdp.next,
        &mdp.prob,
        &mdp.choice_reward,
    );
    debug_assert!(ss[0] == 0 && cs[0] == 0 && ss[n] as usize == rw.len());
    debug_assert!(cs.len() == rw.len() + 1 && cs[rw.len()] as usize == nx.len());
    debug_assert!(pr.len() == nx.len() && nx.iter().all(|&j| (j as usize) < n));
    let (mut dmin, mut dmax) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut c, mut t) = (0usize, 0usize);
    for s in 0..n {
        // SAFETY: as in backup_stage_impl.
        unsafe {
            let hi = *ss.get_unchecked(s + 1) as usize;
            let mut best = f64::NEG_INFINITY;
            let terminal = c == hi;
            while c < hi {
                let end = choice_end::<K>(cs, c, t);
                let acc = dot_choice::<K>(pr, nx, cur, t, end);
                t = end;
                let q = *rw.get_unchecked(c) + gamma * acc;
                // A plain select (one maxsd), not f64::max's NaN handling: values are finite.
                best = if q > best { q } else { best };
                c += 1;
            }
            let q = if terminal { 0.0 } else { best };
            let d = q - *cur.get_unchecked(s);
            dmin = dmin.min(d);
            dmax = dmax.max(d);
            *nxt.get_unchecked_mut(s) = q;
        }
    }
    (dmin, dmax)
}

/// The early-stop screen `(max_s |vb - 2 vb1 + vb2|, max(1, max_s |vb|))` as a separate pass.
fn screen(vb: &[f64], vb1: &[f64], vb2: &[f64]) -> (f64, f64) {
    let (mut delta, mut scale) = (0.0f64, 1.0f64);
    for ((a, b), c) in vb.iter().zip(vb1).zip(vb2) {
        delta = delta.max((a - 2.0 * b + c).abs());
        scale = scale.max(a.abs());
    }
    (delta, scale)
}

/// [`backup_stage`] from `vb` (`V_b`) that also measures the [`FhCertificate`] of `g = vb -
/// vb1`, with `pol_b` the decision rule of stage `b`.
fn backup_certified(
    mdp: &Mdp,
    vb: &[f64],
    vb1: &[f64],
    pol_b: &[u32],
    cur: &mut [f64],
    pol: &mut [u32],
) -> FhCertificate {
    let ss = &mdp.state_start;
    let mut cert = FhCertificate {
        eps_up: 0.0,
        eps_lo: 0.0,
        eps_star: 0.0,
        span: 0.0,
        vmax: 0.0,
        gmax: 0.0,
    };
    let (mut gmin, mut gmaxs) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in 0..cur.len() {
        let gs = vb[s] - vb1[s];
        gmin = gmin.min(gs);
        gmaxs = gmaxs.max(gs);
        cert.gmax = cert.gmax.max(gs.abs());
        cert.vmax = cert.vmax.max(vb[s].abs());
        let lo = ss[s] as usize;
        let hi = ss[s + 1] as usize;
        if lo == hi {
            cur[s] = 0.0;
            pol[s] = NONE;
            continue;
        }
        let mut best_c = lo;
        let mut best = f64::NEG_INFINITY;
        let mut bar = f64::NEG_INFINITY;
        let mut best_pg = 0.0;
        for c in lo..hi {
            let t = mdp.transition_range(c);
            let (mut q, mut pg) = (0.0, 0.0);
            for (n, p) in mdp.next[t.clone()].iter().zip(&mdp.prob[t]) {
                let n = *n as usize;
                q += p * vb[n];
                pg += p * (vb[n] - vb1[n]);
            }
            let q = mdp.choice_reward[c] + q;
            cert.eps_up = cert.eps_up.max(pg - gs);
            if mdp.choice_action[c] == pol_b[s] {
                cert.eps_lo = cert.eps_lo.max(gs - pg);
            }
            if c == lo || q > bar {
                best = q;
                best_c = c;
                bar = beat_bar(best);
                best_pg = pg;
            }
        }
        cert.eps_star = cert.eps_star.max(gs - best_pg);
        cur[s] = best;
        pol[s] = mdp.choice_action[best_c];
    }
    cert.span = if gmaxs >= gmin { gmaxs - gmin } else { 0.0 };
    cert
}

/// Fill stages `0..t` by the certified extrapolation from base `b = t + 1`: `V_{t'} = V_b + (b -
/// t') g` and the decision rule of stage `t`.
fn fill_extrapolated(vals: &mut [f64], pol: &mut [u32], n: usize, t: usize, b: usize) {
    if n == 0 {
        return;
    }
    let (lo, hi) = vals.split_at_mut(b * n);
    let (vb, vb1) = hi[..2 * n].split_at(n);
    for (tp, out) in lo[..t * n].chunks_exact_mut(n).enumerate() {
        let k = (b - tp) as f64;
        for ((o, v), v1) in out.iter_mut().zip(vb).zip(vb1) {
            *o = v + k * (v - v1);
        }
    }
    let (head, row) = pol.split_at_mut(t * n);
    let row = &row[..n];
    for out in head.chunks_exact_mut(n) {
        out.copy_from_slice(row);
    }
}

/// The value a later Q must exceed to replace `best` (see [`beats`]).
#[inline(always)]
fn beat_bar(best: f64) -> f64 {
    best + TIE_TOLERANCE * best.abs().max(1.0)
}

/// Settings for the infinite-horizon solvers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    /// Discount factor in `(0, 1]`.
    pub gamma: f64,
    /// Value iteration: stop once the returned values are within `gamma / (1 - gamma) *
    /// tolerance` of `V*` (MacQueen–Porteus bracket, see [`Workspace::value_iteration`]; with
    /// `gamma = 1`, once the sup-norm change is below this). Modified policy iteration: stop when
    /// the Bellman residual is below this.
    pub tolerance: f64,
    /// Upper bound on iterations (sweeps for VI, improvements for PI/MPI).
    pub max_iterations: u32,
    /// Modified policy iteration: partial evaluation sweeps per improvement.
    pub eval_sweeps: u32,
    /// Policy iteration: models with at most this many states evaluate each policy by the dense
    /// exact solve; larger ones by the sparse iterative one (see
    /// [`Workspace::policy_iteration`]).
    pub dense_eval_max_states: usize,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            gamma: 0.95,
            tolerance: 1e-9,
            max_iterations: 100_000,
            eval_sweeps: 20,
            dense_eval_max_states: DENSE_EVAL_MAX_STATES,
        }
    }
}

/// How a solve went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stats {
    /// Finite horizon: stages computed (at most the horizon, see the early stop of
    /// [`Workspace::finite_horizon`]). VI: sweeps. PI: policy evaluations (the paper's Table 9
    /// count). MPI: improvement steps.
    pub iterations: u32,
    /// `max_s |max_a Q(s,a) - v(s)|` at the returned values (finite horizon: the certified bound
    /// on the extrapolated stages, 0 when every stage was computed).
    pub residual: f64,
    pub converged: bool,
}

/// Preallocated solver buffers. Create once, solve many times; buffers grow to the largest model
/// (and horizon) seen and are then reused without allocation.
#[derive(Debug, Clone)]
pub struct Workspace {
    n: usize,
    v: Vec<f64>,
    v2: Vec<f64>,
    policy: Vec<u32>,
    /// Chosen choice index per state (internal to PI/MPI).
    pchoice: Vec<u32>,
    horizon: usize,
    /// `(horizon + 1) * n` values, stage-major; stage `horizon` is the zero terminal value.
    fh_values: Vec<f64>,
    /// `horizon * n` actions, stage-major.
    fh_policy: Vec<u32>,
    /// Dense policy evaluation: the system over the non-terminal states, row-major `m x m`
    /// (`mat`), its right-hand side (`rhs`) and each state's row (`dense_row`, `NONE` if terminal).
    mat: Vec<f64>,
    rhs: Vec<f64>,
    dense_row: Vec<u32>,
    /// Sparse policy evaluation: the policy's reverse graph (CSR) and a BFS queue, for the
    /// structural properness check with `gamma = 1`.
    rev_start: Vec<u32>,
    rev: Vec<u32>,
    queue: Vec<u32>,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    pub fn new() -> Self {
        Self {
            n: 0,
            v: Vec::new(),
            v2: Vec::new(),
            policy: Vec::new(),
            pchoice: Vec::new(),
            horizon: 0,
            fh_values: Vec::new(),
            fh_policy: Vec::new(),
            mat: Vec::new(),
            rhs: Vec::new(),
            dense_row: Vec::new(),
            rev_start: Vec::new(),
            rev: Vec::new(),
            queue: Vec::new(),
        }
    }

    /// Preallocate for `n_states` states, a finite horizon up to `horizon`, and (when
    /// `dense_solve`) the `n_states x n_states` policy-evaluation matrix.
    pub fn with_capacity(n_states: usize, horizon: usize, dense_solve: bool) -> Self {
        let mut ws = Self::new();
        ws.reserve(n_states, horizon, dense_solve);
        ws
    }

    /// Grow buffers (never shrinks); no allocation when already large enough.
    pub fn reserve(&mut self, n: usize, horizon: usize, dense_solve: bool) {
        self.n = n;
        resize(&mut self.v, n, 0.0);
        resize(&mut self.v2, n, 0.0);
        resize(&mut self.policy, n, NONE);
        resize(&mut self.pchoice, n, NONE);
        if horizon > 0 {
            self.horizon = horizon;
            resize(&mut self.fh_values, (horizon + 1) * n, 0.0);
            resize(&mut self.fh_policy, horizon * n, NONE);
        }
        // The dense buffers only grow; smaller systems use a prefix, so alternating between
        // models of different sizes does not reallocate.
        if dense_solve {
            resize(&mut self.mat, n * n, 0.0);
            resize(&mut self.rhs, n, 0.0);
            resize(&mut self.dense_row, n, NONE);
        }
    }

    /// Finite-horizon undiscounted backward induction (paper eq. 1–3): `V_H = 0` and
    /// `V_t(s) = max_a R(s,a) + sum_s' p(s'|s,a) V_{t+1}(s')` for `t = H-1 .. 0`. Stage `t` is the
    /// decision taken with `H - t` steps to go; `t = 0` is the decision to execute now.
    ///
    /// **Early stop with a certified bound.** Once the stage differences `g = V_b - V_{b+1}` have
    /// settled, the remaining stages are `V_{b-k} = V_b + k g` up to a bound proved from the
    /// monotonicity of the Bellman operator (see the private `FhCertificate`); when that bound, propagated
    /// over the remaining stages, is below [`FH_STOP_TOLERANCE`] relative to the values, the
    /// earlier stages are filled by that extrapolation (values) and by the last computed decision
    /// rule (actions), and [`FiniteHorizonSolution::stats`] reports the stages actually computed
    /// and the bound (`residual`). Models whose stage differences never settle (periodic ones) are
    /// solved in full.
    pub fn finite_horizon(&mut self, mdp: &Mdp, horizon: usize) -> FiniteHorizonSolution<'_> {
        let n = mdp.n_states();
        self.reserve(n, horizon, false);
        self.horizon = horizon;
        let (vals, pol) = (&mut self.fh_values, &mut self.fh_policy);
        vals[horizon * n..(horizon + 1) * n].fill(0.0);
        let mut computed = 0u32;
        let mut bound = 0.0;
        // The second difference at which the last certificate attempt failed: retry only once it
        // has at least halved, so a model that never settles costs no more than a few attempts.
        let mut retry_below = f64::INFINITY;
        // Screen for the stage about to be computed (from the three stages after it), filled
        // by the previous backup.
        let mut screen_next: Option<(f64, f64)> = None;
        let mut t = horizon;
        while t > 0 {
            t -= 1;
            computed += 1;
            // Candidate for a certificate at base b = t + 1: needs V_{b+1} (so b + 1 <= H) and
            // the decision rule pi_b (b <= H - 1), and a cheap sign that g has settled:
            // delta = max |d_b - d_{b+1}| (needs V_{b+2}).
            let b = t + 1;
            if let Some((delta, scale)) = screen_next.take() {
                let kk = b as f64;
                let tol = FH_STOP_TOLERANCE * scale;
                if delta < retry_below && kk * (kk + 1.0) * 0.5 * delta <= 16.0 * tol {
                    let (cur, rest) = vals[t * n..(t + 3) * n].split_at_mut(n);
                    let (vb, vb1) = rest.split_at(n);
                    let (pol_t, pol_b) = pol[t * n..(t + 2) * n].split_at_mut(n);
                    let cert = backup_certified(mdp, vb, vb1, pol_b, cur, pol_t);
                    match cert.stop_bound(b) {
                        Some(e) if e.action <= FH_STOP_TOLERANCE * cert.scale(b) => {
                            bound = e.value;
                            fill_extrapolated(vals, pol, n, t, b);
                            break;
                        }
                        _ => retry_below = delta * 0.5,
                    }
                    if t > 0 {
                        let (cur, rest) = vals[t * n..(t + 3) * n].split_at(n);
                        let (vb, vb1) = rest.split_at(n);
                        screen_next = Some(screen(cur, vb, vb1));
                    }
                    continue;
                }
            }
            // The stage after this one (t - 1, base t) is a certificate candidate when t + 2 <= H.
            if t > 0 && t + 2 <= horizon {
                let (cur, rest) = vals[t * n..(t + 3) * n].split_at_mut(n);
                let (next, next2) = rest.split_at(n);
                screen_next = Some(backup_stage_screened(
                    mdp,
                    next,
                    next2,
                    cur,
                    &mut pol[t * n..(t + 1) * n],
                ));
            } else {
                let (cur, next) = vals[t * n..(t + 2) * n].split_at_mut(n);
                backup_stage(mdp, next, cur, &mut pol[t * n..(t + 1) * n]);
            }
        }
        FiniteHorizonSolution {
            ws: self,
            n,
            horizon,
            computed,
            bound,
        }
    }

    /// Value iteration from `v = 0`: `v <- T v`, `d = T v - v`.
    ///
    /// With `gamma < 1` it stops on the MacQueen–Porteus bounds: `V*` lies in `[Tv + gamma/(1 -
    /// gamma) min d, Tv + gamma/(1 - gamma) max d]` (min/max over all states; terminal states, fixed
    /// at 0, count with `d = 0`), so once `span(d) <= 2 * tolerance` the bracket's midpoint is
    /// returned for the non-terminal states: `|v - V*| <= gamma/(1 - gamma) * tolerance`, the
    /// guarantee today's sup-norm rule (`max |d| < tolerance`, which implies this one) gave, in
    /// far fewer sweeps where the differences settle to a common gain (unichain models; with
    /// terminal states, `span(d) >= max |d|` and the two rules coincide). With `gamma = 1` it stops
    /// when `max |d| < tolerance` (no bracket). At most `cfg.max_iterations` sweeps.
    pub fn value_iteration(&mut self, mdp: &Mdp, cfg: &Config) -> Result<Solution<'_>, SolveError> {
        check_gamma(cfg.gamma)?;
        let n = mdp.n_states();
        let gamma = cfg.gamma;
        self.reserve(n, 0, false);
        self.v[..n].fill(0.0);
        let mut iterations = 0;
        let mut converged = false;
        while iterations < cfg.max_iterations {
            // Terminal states take part with d = 0 (their value stays 0).
            let (mut dmin, mut dmax) = if n == 0 {
                (0.0f64, 0.0f64)
            } else {
                (f64::INFINITY, f64::NEG_INFINITY)
            };
            let (lo_d, hi_d) = vi_sweep(mdp, gamma, &self.v[..n], &mut self.v2[..n]);
            dmin = dmin.min(lo_d);
            dmax = dmax.max(hi_d);
            std::mem::swap(&mut self.v, &mut self.v2);
            iterations += 1;
            let (span, sup) = (dmax - dmin, dmax.max(-dmin));
            if !span.is_finite() {
                break;
            }
            if gamma < 1.0 && span <= 2.0 * cfg.tolerance {
                let shift = gamma / (1.0 - gamma) * 0.5 * (dmin + dmax);
                for s in 0..n {
                    if !mdp.is_terminal(s) {
                        self.v[s] += shift;
                    }
                }
                converged = true;
                break;
            }
            if sup < cfg.tolerance {
                converged = true;
                break;
            }
        }
        Ok(self.finish(mdp, cfg.gamma, iterations, converged))
    }

    /// Policy iteration (paper eq. 4–5). Starts from the greedy policy for immediate rewards;
    /// evaluates each policy exactly by solving `(I - gamma P_pi) v = r_pi` over the non-terminal
    /// states (terminal states fixed at `v = 0`) with Gaussian elimination with partial pivoting
    /// in a preallocated row-major buffer; improves by switching a state's action only when
    /// another is strictly better (so it cannot cycle); stops when the policy is stable.
    /// `Stats::iterations` counts evaluations.
    ///
    /// Evaluation is dense up to `cfg.dense_eval_max_states` states (O(|S|^2) memory, O(|S|^3)
    /// time). Above, it is sparse (sweeps of the policy's operator): O(transitions) per sweep,
    /// warm-started from the previous policy's values. With `gamma < 1` it stops on the
    /// MacQueen–Porteus bracket once the certified error is below `max(`[`SPARSE_EVAL_TOLERANCE`]`,
    /// 8 eps gamma/(1-gamma))` relative to the values. With `gamma = 1` an improper policy (some
    /// non-terminal state cannot reach a terminal one along positive transitions) is reported as
    /// [`SolveError::Singular`] from the policy's graph, and a proper one is solved by
    /// Gauss–Seidel to a relative change below [`SPARSE_EVAL_TOLERANCE`] (not a certified bound).
    pub fn policy_iteration(
        &mut self,
        mdp: &Mdp,
        cfg: &Config,
    ) -> Result<Solution<'_>, SolveError> {
        check_gamma(cfg.gamma)?;
        let n = mdp.n_states();
        let dense = n <= cfg.dense_eval_max_states;
        self.reserve(n, 0, dense);
        self.v[..n].fill(0.0);
        for s in 0..n {
            self.pchoice[s] = mdp
                .greedy(s, cfg.gamma, &self.v[..n])
                .map_or(NONE, |b| b.0 as u32);
        }
        let mut iterations = 0;
        let mut converged = false;
        while iterations < cfg.max_iterations {
            iterations += 1;
            let ok = if dense {
                self.evaluate_exact(mdp, cfg.gamma)
            } else {
                self.evaluate_sparse(mdp, cfg.gamma)
            };
            if !ok {
                return Err(SolveError::Singular {
                    iteration: iterations,
                });
            }
            if !self.improve(mdp, cfg.gamma) {
                converged = true;
                break;
            }
        }
        Ok(self.finish(mdp, cfg.gamma, iterations, converged))
    }

    /// Modified policy iteration (Puterman 6.5): from `v0 = min(0, min R) / (1 - gamma)` (or 0 when
    /// `gamma = 1`), repeat: greedy policy for `v`; stop if the Bellman residual is below
    /// `cfg.tolerance`; else apply that policy's operator `cfg.eval_sweeps` times.
    pub fn modified_policy_iteration(
        &mut self,
        mdp: &Mdp,
        cfg: &Config,
    ) -> Result<Solution<'_>, SolveError> {
        check_gamma(cfg.gamma)?;
        let n = mdp.n_states();
        self.reserve(n, 0, false);
        let v0 = if cfg.gamma < 1.0 {
            let rmin = mdp.choice_reward.iter().copied().fold(0.0, f64::min);
            rmin / (1.0 - cfg.gamma)
        } else {
            0.0
        };
        for s in 0..n {
            self.v[s] = if mdp.is_terminal(s) { 0.0 } else { v0 };
        }
        let mut iterations = 0;
        let mut converged = false;
        while iterations < cfg.max_iterations {
            iterations += 1;
            let mut residual: f64 = 0.0;
            for s in 0..n {
                let (c, q) = match mdp.greedy(s, cfg.gamma, &self.v[..n]) {
                    Some(b) => (b.0 as u32, b.1),
                    None => (NONE, 0.0),
                };
                self.pchoice[s] = c;
                residual = residual.max((q - self.v[s]).abs());
                self.v2[s] = q;
            }
            std::mem::swap(&mut self.v, &mut self.v2);
            if residual < cfg.tolerance || !residual.is_finite() {
                converged = residual.is_finite();
                break;
            }
            for _ in 1..cfg.eval_sweeps.max(1) {
                for s in 0..n {
                    let c = self.pchoice[s];
                    self.v2[s] = if c == NONE {
                        0.0
                    } else {
                        mdp.q(c as usize, cfg.gamma, &self.v[..n])
                    };
                }
                std::mem::swap(&mut self.v, &mut self.v2);
            }
        }
        Ok(self.finish(mdp, cfg.gamma, iterations, converged))
    }

    /// Evaluate the stationary policy `policy[s]` (an action admissible in `s`, or anything for a
    /// terminal state) exactly. Returns the values, or `None` when the system is singular or an
    /// action is not admissible.
    pub fn evaluate_policy(
        &mut self,
        mdp: &Mdp,
        policy: &[ActionId],
        gamma: f64,
    ) -> Option<&[f64]> {
        let n = mdp.n_states();
        self.reserve(n, 0, true);
        for s in 0..n {
            self.pchoice[s] = if mdp.is_terminal(s) {
                NONE
            } else {
                mdp.choice_index(s, *policy.get(s)?)? as u32
            };
        }
        if self.evaluate_exact(mdp, gamma) {
            Some(&self.v[..n])
        } else {
            None
        }
    }

    /// Solve `(I - gamma P_pi) v = r_pi` for the policy in `pchoice` into `v`. False if singular.
    fn evaluate_exact(&mut self, mdp: &Mdp, gamma: f64) -> bool {
        // Terminal states are fixed at 0: their rows (identity, right-hand side 0) and columns
        // drop out, so the system is over the m non-terminal states only.
        let n = mdp.n_states();
        let mut m = 0usize;
        for s in 0..n {
            self.dense_row[s] = if self.pchoice[s] == NONE {
                NONE
            } else {
                m += 1;
                (m - 1) as u32
            };
        }
        let a = &mut self.mat[..m * m];
        let b = &mut self.rhs[..m];
        a.fill(0.0);
        for s in 0..n {
            let (i, c) = (self.dense_row[s], self.pchoice[s]);
            if i == NONE {
                continue;
            }
            let (i, c) = (i as usize, c as usize);
            a[i * m + i] = 1.0;
            b[i] = mdp.choice_reward[c];
            for t in mdp.transition_range(c) {
                let j = self.dense_row[mdp.next[t] as usize];
                if j != NONE {
                    a[i * m + j as usize] -= gamma * mdp.prob[t];
                }
            }
        }
        if !lu_solve(a, b, m) {
            return false;
        }
        for s in 0..n {
            let i = self.dense_row[s];
            self.v[s] = if i == NONE { 0.0 } else { b[i as usize] };
        }
        true
    }

    /// Sparse iterative evaluation of the policy in `pchoice`, warm-started from `v` (the previous
    /// policy's values). False if singular.
    ///
    /// `gamma < 1`: sweeps `v <- r_pi + gamma P_pi v` (the policy's own value-iteration operator)
    /// and, with `d` its change, stops on the MacQueen–Porteus bracket (`v_pi` lies within
    /// `gamma/(1-gamma) * [min d, max d]` of the swept values; terminal states count with `d = 0`)
    /// once its half-width is at most `max(`[`SPARSE_EVAL_TOLERANCE`]`, 8 eps gamma/(1-gamma)) *
    /// max(1, |v|_inf)` (the second term: one sweep's rounding, amplified as the bracket amplifies
    /// it), returning the midpoint. The constant shift is taken out by the bracket, so the error left shrinks by
    /// `gamma` times the policy chain's second eigenvalue per sweep, not by `gamma`: a few dozen
    /// sweeps on the random models of the benches. It also stops, returning the midpoint, if the
    /// bracket has not halved in [`SPARSE_EVAL_STALL_SWEEPS`] sweeps (a rounding floor) or after
    /// [`SPARSE_EVAL_MAX_SWEEPS`].
    ///
    /// `gamma = 1`: `(I - P_pi) v = r_pi` is singular exactly when some non-terminal state cannot
    /// reach a terminal one along `P_pi`'s positive entries (then `P_pi` restricted to the
    /// non-terminal states has a closed class and spectral radius 1); checked on the graph. If
    /// proper, Gauss–Seidel sweeps (they converge for this M-matrix) until the largest change is
    /// at most [`SPARSE_EVAL_TOLERANCE`] `* max(1, |v|_inf)` (a residual, not a certified error:
    /// the error may be larger by the expected time to absorption).
    fn evaluate_sparse(&mut self, mdp: &Mdp, gamma: f64) -> bool {
        let n = mdp.n_states();
        if gamma >= 1.0 {
            if !self.policy_is_proper(mdp) {
                return false;
            }
            let v = &mut self.v[..n];
            for _ in 0..SPARSE_EVAL_MAX_SWEEPS {
                let (mut change, mut scale) = (0.0f64, 1.0f64);
                for s in 0..n {
                    let c = self.pchoice[s];
                    let x = if c == NONE {
                        0.0
                    } else {
                        mdp.q(c as usize, 1.0, v)
                    };
                    change = change.max((x - v[s]).abs());
                    scale = scale.max(x.abs());
                    v[s] = x;
                }
                if !change.is_finite() {
                    return false;
                }
                if change <= SPARSE_EVAL_TOLERANCE * scale {
                    break;
                }
            }
            return true;
        }
        let k = gamma / (1.0 - gamma);
        // Rounding of one sweep (~eps * |v|) is amplified by k in the bracket: ask no less.
        let tol = SPARSE_EVAL_TOLERANCE.max(8.0 * k * f64::EPSILON);
        let has_terminal = self.n_nonterminal(mdp) < n;
        let mut sweeps = 0u32;
        // Stagnation guard: the best half-width and when it last halved.
        let (mut best_half, mut best_at) = (f64::INFINITY, 0u32);
        loop {
            let (cur, nxt) = (&self.v[..n], &mut self.v2[..n]);
            let (mut dmin, mut dmax, mut scale) = (0.0f64, 0.0f64, 1.0f64);
            let mut any = false;
            for s in 0..n {
                let c = self.pchoice[s];
                if c == NONE {
                    nxt[s] = 0.0;
                    continue;
                }
                let x = mdp.q(c as usize, gamma, cur);
                let d = x - cur[s];
                if any {
                    dmin = dmin.min(d);
                    dmax = dmax.max(d);
                } else {
                    (dmin, dmax, any) = (d, d, true);
                }
                scale = scale.max(x.abs());
                nxt[s] = x;
            }
            if any && has_terminal {
                // Terminal states take part with d = 0.
                dmin = dmin.min(0.0);
                dmax = dmax.max(0.0);
            }
            std::mem::swap(&mut self.v, &mut self.v2);
            sweeps += 1;
            let half = 0.5 * k * (dmax - dmin);
            if !half.is_finite() {
                return false;
            }
            if half < 0.5 * best_half {
                (best_half, best_at) = (half, sweeps);
            }
            if half <= tol * scale
                || sweeps >= SPARSE_EVAL_MAX_SWEEPS
                || sweeps - best_at > SPARSE_EVAL_STALL_SWEEPS
            {
                let shift = 0.5 * k * (dmin + dmax);
                for s in 0..n {
                    if self.pchoice[s] != NONE {
                        self.v[s] += shift;
                    }
                }
                return true;
            }
        }
    }

    /// Number of non-terminal states (those with a choice in `pchoice`).
    fn n_nonterminal(&self, mdp: &Mdp) -> usize {
        self.pchoice[..mdp.n_states()]
            .iter()
            .filter(|c| **c != NONE)
            .count()
    }

    /// True when every non-terminal state reaches a terminal state along positive-probability
    /// transitions of the policy in `pchoice` (breadth-first search back from the terminal states
    /// on the policy's reverse graph, built in workspace buffers).
    fn policy_is_proper(&mut self, mdp: &Mdp) -> bool {
        let n = mdp.n_states();
        resize(&mut self.rev_start, n + 2, 0);
        self.rev_start[..n + 2].fill(0);
        let mut m = 0usize;
        for s in 0..n {
            let c = self.pchoice[s];
            if c == NONE {
                continue;
            }
            for t in mdp.transition_range(c as usize) {
                if mdp.prob[t] > 0.0 {
                    self.rev_start[mdp.next[t] as usize + 2] += 1;
                    m += 1;
                }
            }
        }
        for j in 2..n + 2 {
            self.rev_start[j] += self.rev_start[j - 1];
        }
        resize(&mut self.rev, m, 0);
        for s in 0..n {
            let c = self.pchoice[s];
            if c == NONE {
                continue;
            }
            for t in mdp.transition_range(c as usize) {
                if mdp.prob[t] > 0.0 {
                    let j = mdp.next[t] as usize + 1;
                    self.rev[self.rev_start[j] as usize] = s as u32;
                    self.rev_start[j] += 1;
                }
            }
        }
        // Now rev_start[j]..rev_start[j + 1] are the predecessors of j. Reached states are marked
        // in `policy` (scratch here; `finish` rewrites it).
        let seen = &mut self.policy[..n];
        resize(&mut self.queue, n, 0);
        let mut tail = 0;
        for (s, (seen_s, c)) in seen.iter_mut().zip(&self.pchoice[..n]).enumerate() {
            let terminal = *c == NONE;
            *seen_s = terminal as u32;
            if terminal {
                self.queue[tail] = s as u32;
                tail += 1;
            }
        }
        let mut head = 0;
        while head < tail {
            let j = self.queue[head] as usize;
            head += 1;
            for i in self.rev_start[j]..self.rev_start[j + 1] {
                let p = self.rev[i as usize] as usize;
                if seen[p] == 0 {
                    seen[p] = 1;
                    self.queue[tail] = p as u32;
                    tail += 1;
                }
            }
        }
        tail == n
    }

    /// Policy improvement on `pchoice` given `v`. Returns true if any state changed.
    fn improve(&mut self, mdp: &Mdp, gamma: f64) -> bool {
        let n = mdp.n_states();
        let mut changed = false;
        for s in 0..n {
            let cur = self.pchoice[s];
            if cur == NONE {
                continue;
            }
            let (best_c, best_q) = mdp.greedy(s, gamma, &self.v[..n]).expect("non-terminal");
            let cur_q = mdp.q(cur as usize, gamma, &self.v[..n]);
            if best_c != cur as usize && beats(best_q, cur_q) {
                self.pchoice[s] = best_c as u32;
                changed = true;
            }
        }
        changed
    }

    /// Greedy extraction (lowest-index tie-breaking) and Bellman residual at the final values.
    fn finish(&mut self, mdp: &Mdp, gamma: f64, iterations: u32, converged: bool) -> Solution<'_> {
        let n = mdp.n_states();
        let mut residual: f64 = 0.0;
        for s in 0..n {
            match mdp.greedy(s, gamma, &self.v[..n]) {
                Some((c, q)) => {
                    self.policy[s] = mdp.choice_action[c];
                    residual = residual.max((q - self.v[s]).abs());
                }
                None => self.policy[s] = NONE,
            }
        }
        Solution {
            values: &self.v[..n],
            policy: &self.policy[..n],
            stats: Stats {
                iterations,
                residual,
                converged,
            },
        }
    }
}

fn resize<T: Copy>(v: &mut Vec<T>, n: usize, fill: T) {
    if v.len() < n {
        v.resize(n, fill);
    }
}

fn check_gamma(g: f64) -> Result<(), SolveError> {
    if g > 0.0 && g <= 1.0 {
        Ok(())
    } else {
        Err(SolveError::BadGamma(g))
    }
}

/// Solves `a x = b` for a square `a` (left as given: a row-major copy is factored), `x` written
/// into `b`, by `lu_solve`. Returns `false` if the matrix is singular.
pub fn solve_dense(a: &DMatrix<f64>, b: &mut DVector<f64>) -> bool {
    let m = a.nrows();
    assert!(a.ncols() == m && b.len() == m);
    let mut rows: Vec<f64> = a.transpose().as_slice().to_vec();
    lu_solve(&mut rows, b.as_mut_slice(), m)
}

/// Gaussian elimination with partial pivoting on a row-major `m x m` matrix `a` (overwritten by
/// its factors), `x` written into `b`. `false` if a pivot is NaN or at most
/// [`SINGULAR_TOLERANCE`] times `max(1, max |a|)`. Row-major so row swaps and the elimination's
/// row updates are contiguous; tested against nalgebra's LU.
fn lu_solve(a: &mut [f64], b: &mut [f64], m: usize) -> bool {
    assert!(a.len() == m * m && b.len() == m);
    let scale = a.iter().fold(1.0f64, |s, x| s.max(x.abs()));
    for k in 0..m {
        let mut p = k;
        let mut best = a[k * m + k].abs();
        for i in k + 1..m {
            let x = a[i * m + k].abs();
            if x > best {
                best = x;
                p = i;
            }
        }
        if best.is_nan() || best <= SINGULAR_TOLERANCE * scale {
            return false;
        }
        if p != k {
            let (top, bottom) = a.split_at_mut(p * m);
            top[k * m..k * m + m].swap_with_slice(&mut bottom[..m]);
            b.swap(k, p);
        }
        let (top, bottom) = a.split_at_mut((k + 1) * m);
        let pivot_row = &top[k * m..k * m + m];
        let pivot = pivot_row[k];
        let bk = b[k];
        for (r, row) in bottom.chunks_exact_mut(m).enumerate() {
            let l = row[k] / pivot;
            row[k] = l;
            b[k + 1 + r] -= l * bk;
            if l != 0.0 {
                for (x, u) in row[k + 1..].iter_mut().zip(&pivot_row[k + 1..]) {
                    *x -= l * u;
                }
            }
        }
    }
    for k in (0..m).rev() {
        let row = &a[k * m..k * m + m];
        let mut x = b[k];
        for (u, bj) in row[k + 1..].iter().zip(&b[k + 1..]) {
            x -= u * bj;
        }
        b[k] = x / row[k];
    }
    true
}

/// Result of [`Workspace::finite_horizon`], borrowing the workspace.
#[derive(Debug)]
pub struct FiniteHorizonSolution<'a> {
    ws: &'a Workspace,
    n: usize,
    horizon: usize,
    /// Stages computed by backward induction (the rest were extrapolated).
    computed: u32,
    /// Certified bound on the extrapolated values (0 when every stage was computed).
    bound: f64,
}

impl FiniteHorizonSolution<'_> {
    pub fn horizon(&self) -> usize {
        self.horizon
    }
    /// Optimal expected total reward from `s` with `horizon - t` steps to go.
    pub fn value(&self, t: usize, s: StateId) -> f64 {
        self.ws.fh_values[t * self.n + s]
    }
    /// Values at stage `t` (`t = horizon` is all zeros).
    pub fn values_at(&self, t: usize) -> &[f64] {
        &self.ws.fh_values[t * self.n..(t + 1) * self.n]
    }
    /// Optimal action at stage `t < horizon` in `s`, `None` for a terminal state.
    pub fn action(&self, t: usize, s: StateId) -> Option<ActionId> {
        let a = self.ws.fh_policy[t * self.n + s];
        (a != NONE).then_some(a as usize)
    }
    /// The decision to execute now (stage 0); `None` for terminal states or horizon 0.
    pub fn decision(&self, s: StateId) -> Option<ActionId> {
        if self.horizon == 0 {
            None
        } else {
            self.action(0, s)
        }
    }
    /// `iterations`: stages computed by backward induction (the horizon unless the early stop
    /// certified the rest); `residual`: the certified bound on the extrapolated values (0 when
    /// every stage was computed).
    pub fn stats(&self) -> Stats {
        Stats {
            iterations: self.computed,
            residual: self.bound,
            converged: true,
        }
    }
}

/// Result of an infinite-horizon solve, borrowing the workspace.
#[derive(Debug)]
pub struct Solution<'a> {
    values: &'a [f64],
    policy: &'a [u32],
    pub stats: Stats,
}

impl Solution<'_> {
    pub fn values(&self) -> &[f64] {
        self.values
    }
    pub fn value(&self, s: StateId) -> f64 {
        self.values[s]
    }
    /// Greedy action in `s` (lowest index among ties), `None` for a terminal state.
    pub fn action(&self, s: StateId) -> Option<ActionId> {
        let a = self.policy[s];
        (a != NONE).then_some(a as usize)
    }
    /// The policy as action indices, `None` for terminal states (allocates; for tests/tools).
    pub fn policy(&self) -> Vec<Option<ActionId>> {
        (0..self.policy.len()).map(|s| self.action(s)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two-state chain by hand: s0 --a0 (r=1)--> s1 (terminal) or s0 --a1 (r=0)--> s0 w.p. 1/2,
    /// s1 w.p. 1/2. With gamma = 1/2: Q(a1) = 0 + 0.5 * 0.5 * v0; v0 = max(1, 0.25 v0) = 1.
    #[test]
    fn hand_computed_two_states() {
        let mut b = MdpBuilder::new(2, 2);
        b.choice(0, 0, 1.0, &[(1, 1.0)])
            .choice(0, 1, 0.0, &[(0, 0.5), (1, 0.5)]);
        let m = b.build().unwrap();
        let cfg = Config {
            gamma: 0.5,
            ..Config::default()
        };
        let mut ws = Workspace::new();
        let s = ws.policy_iteration(&m, &cfg).unwrap();
        assert!((s.value(0) - 1.0).abs() < 1e-12);
        assert_eq!(s.action(0), Some(0));
        assert_eq!(s.action(1), None);
        assert_eq!(s.value(1), 0.0);
    }

    /// Seeded xorshift64 uniform in [0, 1): the random models and systems of the tests below.
    fn xorshift_unit(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    #[test]
    fn fixed_successor_kernels_match_the_general_one_bit_for_bit() {
        // Models where every choice has k successors take the kernels with k fixed at compile
        // time; clearing the marker sends the same model through the general kernel, which must
        // give identical bits (same summation order) for every k with a kernel, and more.
        let mut rnd = xorshift_unit(0x9e37_79b9_7f4a_7c15);
        for k in 1..=MAX_UNIFORM_SUCCESSORS as usize + 1 {
            let (n, m) = (12, 4);
            let mut b = MdpBuilder::new(n, m);
            for s in 1..n {
                for a in 0..m {
                    if a > 0 && rnd() < 0.3 {
                        continue; // not every action admissible
                    }
                    let mut next: Vec<usize> = Vec::new();
                    while next.len() < k {
                        let j = (rnd() * n as f64) as usize % n;
                        if !next.contains(&j) {
                            next.push(j);
                        }
                    }
                    let w: Vec<f64> = (0..k).map(|_| 0.1 + rnd()).collect();
                    let sum: f64 = w.iter().sum();
                    let tr: Vec<(usize, f64)> =
                        next.iter().zip(&w).map(|(&j, &x)| (j, x / sum)).collect();
                    b.choice(s, a, rnd() * 10.0 - 3.0, &tr);
                }
            }
            // state 0 is terminal: the choices' counts stay uniform
            let uniform = b.build().unwrap();
            let expected = if k <= MAX_UNIFORM_SUCCESSORS as usize {
                k as u32
            } else {
                0
            };
            assert_eq!(uniform.uniform_successors, expected, "k={k}");
            let mut general = uniform.clone();
            general.uniform_successors = 0;
            let (mut w1, mut w2) = (Workspace::new(), Workspace::new());
            let (f1, f2) = (
                w1.finite_horizon(&uniform, 60),
                w2.finite_horizon(&general, 60),
            );
            assert_eq!(f1.stats().iterations, f2.stats().iterations, "k={k}");
            for t in 0..60 {
                for s in 0..n {
                    assert_eq!(
                        f1.value(t, s).to_bits(),
                        f2.value(t, s).to_bits(),
                        "k={k} t={t}"
                    );
                    assert_eq!(f1.action(t, s), f2.action(t, s), "k={k} t={t} s={s}");
                }
            }
            let cfg = Config::default();
            let v1 = w1.value_iteration(&uniform, &cfg).unwrap();
            let (vals1, pol1, it1) = (v1.values().to_vec(), v1.policy(), v1.stats.iterations);
            let v2 = w2.value_iteration(&general, &cfg).unwrap();
            assert_eq!(it1, v2.stats.iterations, "k={k}");
            assert_eq!(pol1, v2.policy(), "k={k}");
            for (a, b) in vals1.iter().zip(v2.values()) {
                assert_eq!(a.to_bits(), b.to_bits(), "k={k}");
            }
        }
    }

    #[test]
    fn lu_solve_matches_nalgebra_on_random_systems_and_detects_singular_ones() {
        // uniform in [-1, 1)
        let mut unit = xorshift_unit(0x2545_f491_4f6c_dd1d);
        let mut rnd = move || unit() * 2.0 - 1.0;
        for m in 1..=12 {
            for _ in 0..20 {
                let a0 = DMatrix::from_fn(m, m, |_, _| if rnd() > 0.0 { rnd() } else { 0.0 });
                let b0 = DVector::from_fn(m, |_, _| rnd());
                let Some(expect) = a0.clone().lu().solve(&b0) else {
                    continue;
                };
                if a0.clone().lu().determinant().abs() < 1e-6 {
                    continue; // ill-conditioned: the two eliminations may differ a lot
                }
                let mut b = b0.clone();
                assert!(solve_dense(&a0, &mut b), "m={m}");
                let err = (&b - &expect).amax() / expect.amax().max(1.0);
                assert!(err < 1e-9, "m={m}: {err}");
                // residual of our own answer
                assert!((&a0 * &b - &b0).amax() < 1e-9, "m={m}");
            }
            if m >= 2 {
                // two equal rows: singular, reported, never a division by ~0
                let mut a = DMatrix::from_fn(m, m, |_, _| rnd());
                let r0 = a.row(0).clone_owned();
                a.set_row(m - 1, &r0);
                let mut b = DVector::from_fn(m, |_, _| rnd());
                assert!(!solve_dense(&a, &mut b), "m={m}");
            }
        }
    }

    /// Finite horizon by hand: "wait" (action 0, reward 1, self loop) versus "cash" (action 1,
    /// reward 5, to a terminal state). With h steps to go V_h = max(1 + V_{h-1}, 5): V_1 = 5
    /// (cash), then V_h = h + 4 (wait). With a wait reward of 0 instead, V_h = 5 for all h and
    /// from h = 2 on both actions tie, so the lowest index (wait) must be chosen.
    #[test]
    fn finite_horizon_by_hand() {
        for wait_reward in [1.0, 0.0] {
            let mut b = MdpBuilder::new(2, 2);
            b.choice(0, 0, wait_reward, &[(0, 1.0)])
                .choice(0, 1, 5.0, &[(1, 1.0)]);
            let m = b.build().unwrap();
            let mut ws = Workspace::new();
            for h in 1..10usize {
                let fh = ws.finite_horizon(&m, h);
                let expected = if wait_reward == 1.0 {
                    h as f64 + 4.0
                } else {
                    5.0
                };
                assert_eq!(fh.value(0, 0), expected, "h={h}");
                assert_eq!(fh.decision(0), Some(if h == 1 { 1 } else { 0 }), "h={h}");
                // The last stage always cashes in.
                assert_eq!(fh.action(h - 1, 0), Some(1));
                assert_eq!(fh.decision(1), None);
            }
        }
    }

    #[test]
    fn builder_rejects_bad_input() {
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(1, 0.5)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::RowSum {
                state: 0,
                action: 0,
                ..
            })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(2, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::StateOutOfRange { state: 2, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 1, 0.0, &[(1, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::ActionOutOfRange { action: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(1, 1.0)])
            .choice(0, 0, 0.0, &[(1, 1.0)]);
        assert!(matches!(b.build(), Err(MdpError::DuplicateChoice { .. })));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[]);
        assert!(matches!(b.build(), Err(MdpError::NoTransition { .. })));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, 0.0, &[(0, 1.5), (1, -0.5)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::BadProbability { state: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, f64::NAN, &[(0, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::BadReward { state: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, 0.0, &[(0, 0.5), (0, 0.5)]);
        assert!(matches!(b.build(), Err(MdpError::DuplicateNext { .. })));
    }

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
    fn improper_policy_with_gamma_one_is_singular() {
        // Only action: self loop with reward 1 -> infinite total reward.
        let mut b = MdpBuilder::new(1, 1);
        b.choice(0, 0, 1.0, &[(0, 1.0)]);
        let m = b.build().unwrap();
        let cfg = Config {
            gamma: 1.0,
            ..Config::default()
        };
        let mut ws = Workspace::new();
        assert_eq!(
            ws.policy_iteration(&m, &cfg).unwrap_err(),
            SolveError::Singular { iteration: 1 }
        );
        assert!(matches!(
            ws.policy_iteration(&m, &Config { gamma: 0.0, ..cfg }),
            Err(SolveError::BadGamma(_))
        ));
        let vi = ws
            .value_iteration(
                &m,
                &Config {
                    max_iterations: 50,
                    ..cfg
                },
            )
            .unwrap();
        assert!(!vi.stats.converged);
        assert_eq!(vi.stats.iterations, 50);
    }

    #[test]
    fn solve_dense_matches_nalgebra_lu() {
        let a0 = DMatrix::from_row_slice(3, 3, &[0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 4.0]);
        let b0 = DVector::from_row_slice(&[1.0, 2.0, 3.0]);
        let expect = a0.clone().lu().solve(&b0).unwrap();
        let mut b = b0;
        assert!(solve_dense(&a0, &mut b));
        assert!((b - expect).amax() < 1e-12);
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
