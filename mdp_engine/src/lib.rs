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
//! **Threads.** With the `parallel` feature (default on) the finite-horizon and value-iteration
//! solves of a model with at least [`PARALLEL_MIN_TRANSITIONS`] transitions run as a team of
//! the current rayon pool's threads, each on a fixed range of states, in lockstep stage by
//! stage (sweep by sweep) ([`Workspace::set_parallel_min_transitions`]; one team at a time in
//! the process, a solve that finds one running sweeps alone); each state's backup is the same
//! sum in the same order and the stages' reductions are minima and maxima, so the values,
//! decisions and statistics are bit-identical to one thread. On 32-bit ARM (the A9 build) the
//! split is compiled out whatever the features: the flight build stays one thread.
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
//!
//! # Layout
//!
//! * `model`: [`Mdp`] (CSR storage, validation, serialization), [`Choice`], the index types,
//!   [`MdpError`], and the Q-value and tie-breaking rules the solvers share.
//! * `builder`: [`MdpBuilder`], which collects choices in any order and lays out an [`Mdp`].
//! * `workspace`: [`Workspace`], the preallocated solver buffers.
//! * `kernels`: the hot unchecked sweeps (finite-horizon backup, value-iteration sweep), one
//!   kernel per fixed successor count, over all states or one thread's range.
//! * `lockstep`: a thread alone or a team of a rayon pool's threads sweeping stage by stage, and
//!   the rows they share.
//! * `finite_horizon`: [`Workspace::finite_horizon`], backward induction with the certified early
//!   stop ([`FH_STOP_TOLERANCE`]).
//! * `infinite_horizon`: [`Config`], [`SolveError`], and value, policy and modified policy
//!   iteration on [`Workspace`].
//! * `evaluation`: policy evaluation, dense (via `linalg`) and sparse, and
//!   [`Workspace::evaluate_policy`].
//! * `linalg`: the row-major LU solve with partial pivoting and [`solve_dense`].
//! * `solution`: [`Stats`], [`Solution`] and [`FiniteHorizonSolution`], views borrowing the
//!   workspace.

mod builder;
mod evaluation;
mod finite_horizon;
mod infinite_horizon;
mod kernels;
mod linalg;
mod lockstep;
mod model;
mod solution;
mod workspace;

pub use builder::MdpBuilder;
pub use evaluation::{SPARSE_EVAL_MAX_SWEEPS, SPARSE_EVAL_STALL_SWEEPS, SPARSE_EVAL_TOLERANCE};
pub use finite_horizon::FH_STOP_TOLERANCE;
pub use infinite_horizon::{Config, DENSE_EVAL_MAX_STATES, SolveError};
pub use kernels::PARALLEL_MIN_TRANSITIONS;
pub use linalg::{SINGULAR_TOLERANCE, solve_dense};
pub use model::{ActionId, Choice, Mdp, MdpError, ROW_SUM_TOLERANCE, StateId, TIE_TOLERANCE};
pub use solution::{FiniteHorizonSolution, Solution, Stats};
pub use workspace::Workspace;

#[cfg(test)]
mod testing {
    /// Seeded xorshift64 uniform in [0, 1): the random models and systems of the unit tests.
    pub(crate) fn xorshift_unit(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }
}
