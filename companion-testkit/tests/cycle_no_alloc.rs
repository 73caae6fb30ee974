//! The steady-state decision cycle makes no heap allocation: after a warm-up, `Core::step_into`
//! over a stream of changing observations (time, battery, and in the `Changing` stream the
//! vibration evidence flipping every cycle, so every MDP is re-instantiated and re-solved)
//! allocates nothing in 1000 cycles. Counting global allocator, test thread only, own binary.

use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
#[path = "support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

const WARM: u64 = 50;
const COUNTED_CYCLES: u64 = 1000;

/// A core on the default params, its stream of `stream` observations from the tracking
/// snapshot of `complete-1`, and that snapshot to advance.
fn tracking_core(kind: ModelKind, policy: &str, stream: Stream) -> (Core, StreamGen, Observations) {
    let params = default_params_dir();
    let model = std::sync::Arc::new(companion::params::load_model(&params).unwrap());
    let base = tracking_snapshot(&model, &params, "complete-1");
    // Written over the run's vocabulary, as the shells write it: every name by slot.
    assert!(
        base.values.overflow().is_empty(),
        "{:?}",
        base.values.overflow()
    );
    assert!(base.values.names().len() > 20);
    let stream_gen = StreamGen::new(&model, base.clone(), stream);
    let core = Core::new(
        std::sync::Arc::clone(&model),
        kind,
        model.policy(policy).unwrap(),
    );
    (core, stream_gen, base)
}

/// Allocations over `COUNTED_CYCLES` cycles after `WARM` warm-up cycles, and the evidence
/// changes and MDP solves seen while counting (to show the stream really moved).
fn run(kind: ModelKind, policy: &str, stream: Stream, memos: bool) -> (usize, usize, u64) {
    let (mut core, stream_gen, mut obs) = tracking_core(kind, policy, stream);
    core.set_caches(memos);
    let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
    for k in 0..WARM {
        stream_gen.advance(&mut obs, k);
        core.step_into(&obs, &mut plan, &mut rec);
    }
    let solves_before = core.work_done().mdp_solves;
    let mut allocs = 0;
    let mut evidence_changes = 0;
    let mut last = rec.evidence.clone();
    for k in WARM..WARM + COUNTED_CYCLES {
        stream_gen.advance(&mut obs, k);
        allocs += allocations(|| core.step_into(&obs, &mut plan, &mut rec));
        if rec.evidence != last {
            evidence_changes += 1;
            last.clone_from(&rec.evidence);
        }
        assert!(rec.state.starts_with('v'), "left tracking: {}", rec.state);
        assert!(!rec.actions.is_empty());
    }
    let solves = core.work_done().mdp_solves - solves_before;
    (allocs, evidence_changes, solves)
}

#[test]
fn steady_stream_allocates_nothing() {
    for policy in ["safety", "mission"] {
        let (allocs, _, _) = run(ModelKind::Bfm, policy, Stream::Steady, true);
        assert_eq!(
            allocs, 0,
            "{policy:?}: {allocs} allocations in {COUNTED_CYCLES} cycles"
        );
    }
}

#[test]
fn evidence_flipping_every_cycle_allocates_nothing_and_resolves_every_cycle() {
    for policy in ["safety", "mission"] {
        // Memos off: three concurrent MDPs re-solved and every BN query run each cycle.
        let (allocs, changes, solves) = run(ModelKind::Bfm, policy, Stream::Changing, false);
        assert_eq!(
            changes as u64, COUNTED_CYCLES,
            "{policy:?}: evidence must flip every cycle"
        );
        assert!(solves >= COUNTED_CYCLES, "{policy:?}: only {solves} solves");
        assert_eq!(
            allocs, 0,
            "{policy:?}: {allocs} allocations in {COUNTED_CYCLES} cycles"
        );
        // Memos on: both evidence points answered from memory, nothing allocated either.
        let (allocs, _, _) = run(ModelKind::Bfm, policy, Stream::Changing, true);
        assert_eq!(allocs, 0, "{policy:?} with memos: {allocs} allocations");
    }
}

#[test]
fn monolithic_model_allocates_nothing_either() {
    let (allocs, _, _) = run(ModelKind::Monolithic, "safety", Stream::Changing, true);
    assert_eq!(allocs, 0);
}

/// Past the duration goal (the tracking hold outlasting it, 2,000 s of cycles at 0.1 s), the
/// guarantee cannot re-allocate and says so every cycle, searching again each time: the
/// reduced mission, both searches and the reason text reuse their buffers, so that allocates
/// nothing either (18 allocations per cycle before).
#[test]
fn a_guarantee_that_cannot_be_met_says_so_every_cycle_allocating_nothing() {
    let (mut core, stream_gen, mut obs) = tracking_core(ModelKind::Bfm, "safety", Stream::Steady);
    let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
    let first = 25_000;
    for k in first..first + WARM {
        stream_gen.advance(&mut obs, k);
        core.step_into(&obs, &mut plan, &mut rec);
    }
    let mut allocs = 0;
    for k in first + WARM..first + WARM + COUNTED_CYCLES {
        stream_gen.advance(&mut obs, k);
        allocs += allocations(|| core.step_into(&obs, &mut plan, &mut rec));
        let g = rec.guarantee.as_ref().expect("a guarantee record");
        assert!(g.infeasible, "cycle {k}: the guarantee is met again");
        let reason = g.infeasible_reason.as_deref().unwrap_or_default();
        assert!(
            reason.contains("margin") && reason.contains("no allocation"),
            "cycle {k}: {reason}"
        );
    }
    assert_eq!(allocs, 0, "{allocs} allocations in {COUNTED_CYCLES} cycles");
}

/// A version flipping every cycle makes the plan follow it every cycle (issue 24's binding): each
/// cycle's record says so, with its typed trigger, but the RAS history only holds the distinct
/// allocations (it grew by a row per cycle before, without bound on a long flight).
#[test]
fn a_flipping_version_reallocates_every_cycle_but_the_history_stays_bounded() {
    let (mut core, stream_gen, mut obs) = tracking_core(ModelKind::Bfm, "safety", Stream::Changing);
    let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
    let mut follows = 0;
    for k in 0..400 {
        stream_gen.advance(&mut obs, k);
        core.step_into(&obs, &mut plan, &mut rec);
        let re = rec.guarantee.as_ref().and_then(|g| g.reallocation.as_ref());
        if re.is_some_and(|r| r.trigger.is_follow()) {
            follows += 1;
        }
    }
    assert!(
        follows > 300,
        "the plan followed {follows} times in 400 cycles"
    );
    assert!(core.reallocations() >= follows, "{}", core.reallocations());
    let table = core.allocation_table().unwrap();
    let rows = table
        .lines()
        .filter(|l| l.starts_with("RAS") && l.contains('|'))
        .count();
    assert!((2..=4).contains(&rows), "{rows} RAS rows:\n{table}");
}
