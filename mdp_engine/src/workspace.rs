//! [`Workspace`]: the preallocated solver buffers every solver writes into.

use crate::model::NONE;

/// Preallocated solver buffers. Create once, solve many times; buffers grow to the largest model
/// (and horizon) seen and are then reused without allocation.
#[derive(Debug, Clone)]
pub struct Workspace {
    pub(crate) n: usize,
    pub(crate) v: Vec<f64>,
    pub(crate) v2: Vec<f64>,
    pub(crate) policy: Vec<u32>,
    /// Chosen choice index per state (internal to PI/MPI).
    pub(crate) pchoice: Vec<u32>,
    pub(crate) horizon: usize,
    /// `(horizon + 1) * n` values, stage-major; stage `horizon` is the zero terminal value.
    pub(crate) fh_values: Vec<f64>,
    /// `horizon * n` actions, stage-major.
    pub(crate) fh_policy: Vec<u32>,
    /// Dense policy evaluation: the system over the non-terminal states, row-major `m x m`
    /// (`mat`), its right-hand side (`rhs`) and each state's row (`dense_row`, `NONE` if terminal).
    pub(crate) mat: Vec<f64>,
    pub(crate) rhs: Vec<f64>,
    pub(crate) dense_row: Vec<u32>,
    /// Sparse policy evaluation: the policy's reverse graph (CSR) and a BFS queue, for the
    /// structural properness check with `gamma = 1`.
    pub(crate) rev_start: Vec<u32>,
    pub(crate) rev: Vec<u32>,
    pub(crate) queue: Vec<u32>,
    /// Sweeps of models with at least this many transitions are split across threads.
    pub(crate) par_min_transitions: usize,
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    /// An empty workspace; the first solve allocates.
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
            par_min_transitions: crate::kernels::PARALLEL_MIN_TRANSITIONS,
        }
    }

    /// Split the finite-horizon and value-iteration solves of models with at least
    /// `min_transitions` transitions across the current rayon pool's threads, as a team in
    /// lockstep (default [`PARALLEL_MIN_TRANSITIONS`]; `usize::MAX`: always one thread; 0:
    /// split every model of two states or more). The values and decisions are bit-identical
    /// either way: every state's backup is the same sum in the same order, and the sweep's
    /// reductions are minima and maxima. Without the `parallel` feature, and on 32-bit ARM, one
    /// thread whatever this says.
    ///
    /// [`PARALLEL_MIN_TRANSITIONS`]: crate::PARALLEL_MIN_TRANSITIONS
    pub fn set_parallel_min_transitions(&mut self, min_transitions: usize) {
        self.par_min_transitions = min_transitions;
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
}

pub(crate) fn resize<T: Copy>(v: &mut Vec<T>, n: usize, fill: T) {
    if v.len() < n {
        v.resize(n, fill);
    }
}
