//! What the solvers return: per-solve statistics and views of the values and policies that
//! borrow the workspace.

use crate::model::{ActionId, NONE, StateId};
use crate::workspace::Workspace;

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
    /// False when the solver stopped before its stopping rule held (`max_iterations` reached, or
    /// the values stopped being finite).
    pub converged: bool,
}

/// Result of [`Workspace::finite_horizon`], borrowing the workspace.
#[derive(Debug)]
pub struct FiniteHorizonSolution<'a> {
    pub(crate) ws: &'a Workspace,
    pub(crate) n: usize,
    pub(crate) horizon: usize,
    /// Stages computed by backward induction (the rest were extrapolated).
    pub(crate) computed: u32,
    /// Certified bound on the extrapolated values (0 when every stage was computed).
    pub(crate) bound: f64,
}

impl FiniteHorizonSolution<'_> {
    /// The horizon solved for (number of decision stages).
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
    pub(crate) values: &'a [f64],
    pub(crate) policy: &'a [u32],
    /// How the solve went.
    pub stats: Stats,
}

impl Solution<'_> {
    /// The values of every state (0 for terminal states).
    pub fn values(&self) -> &[f64] {
        self.values
    }
    /// The value of state `s`.
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
