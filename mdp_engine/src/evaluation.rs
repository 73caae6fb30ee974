//! Policy evaluation for policy iteration: the exact dense solve over the non-terminal states and
//! the sparse iterative one with its properness check.

use crate::linalg::lu_solve;
use crate::model::{ActionId, Mdp, NONE};
use crate::workspace::{Workspace, resize};

/// Sparse policy evaluation stops when its certified error (`gamma < 1`) or its last change
/// (`gamma = 1`) is at most this relative to `max(1, |v|_inf)`.
pub const SPARSE_EVAL_TOLERANCE: f64 = 1e-13;
/// Sparse policy evaluation (`gamma < 1`) also stops when its bracket has not halved in this many
/// sweeps (rounding floor), returning the midpoint.
pub const SPARSE_EVAL_STALL_SWEEPS: u32 = 2000;
/// Cap on the sweeps of one sparse policy evaluation.
pub const SPARSE_EVAL_MAX_SWEEPS: u32 = 1_000_000;

impl Workspace {
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
    pub(crate) fn evaluate_exact(&mut self, mdp: &Mdp, gamma: f64) -> bool {
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
    pub(crate) fn evaluate_sparse(&mut self, mdp: &Mdp, gamma: f64) -> bool {
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
}
