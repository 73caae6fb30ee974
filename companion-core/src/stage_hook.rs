//! An optional observer of the decision cycle's stage boundaries, for `bench_cycle`'s
//! breakdown of where a cycle's time goes.
//!
//! The core has no clock: the hook, a plain function a benchmark installs once per process,
//! reads its own. Each [`Stage`] passed to it says that stage just ended, so the time since the
//! previous call belongs to it ([`Stage::CycleStart`] opens a cycle). Not installed (every
//! flight, every test), a boundary costs one atomic load and a branch not taken; the hook never
//! sees or changes what the core decides.

use std::sync::OnceLock;

/// A stage of [`crate::decision::Core::step_into`] that just ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage<'a> {
    /// A cycle begins: the time before it belongs to no stage.
    CycleStart,
    /// Observations to evidence (platform room, thresholds, absent nodes, resolving the
    /// evidence to network states).
    Evidence,
    /// One health manager's inference (import priors, exact query or its memo, publishing).
    HealthManager(&'a str),
    /// The dynamic managers' carried beliefs set for the next cycle.
    HealthCarry,
    /// One MDP's decision: read its probabilities, then instantiate and solve or reuse a memo,
    /// and write its proposal.
    Mdp(&'a str),
    /// Behaviour arbitration and resource arbitration except the scheduler.
    Arbitration,
    /// The platform scheduler (a run or its memo).
    Scheduler,
    /// A resource conflict's re-evaluation and re-solve.
    Resolve,
    /// The PANORAMA guarantee stage.
    Guarantee,
    /// Copying inputs into the record and writing the plan.
    Record,
}

/// A function told of every stage boundary.
pub type StageHook = fn(Stage<'_>);

static HOOK: OnceLock<StageHook> = OnceLock::new();

/// Install the process's stage hook (benchmarks only). False when one was installed already.
pub fn set_stage_hook(hook: StageHook) -> bool {
    HOOK.set(hook).is_ok()
}

/// Tell the hook, if any, that `stage` just ended.
#[inline(always)]
pub(crate) fn mark(stage: Stage<'_>) {
    if let Some(hook) = HOOK.get() {
        hook(stage);
    }
}
