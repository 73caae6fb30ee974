//! With the memos off (`Core::set_caches(false)`: every cycle re-solves every MDP and re-runs
//! the resource scheduler), a warm decision cycle still makes no heap allocation: the scheduler
//! works in its reusable workspace and writes into the one memo slot in place. The stream flips
//! the vibration evidence every cycle (bench_cycle's "worst" case). Counting allocator, own
//! binary.

use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Plan};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
#[path = "support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

const WARM: u64 = 50;
const COUNTED: u64 = 400;

#[test]
fn memos_off_cycle_allocates_nothing_once_warm() {
    let params = default_params_dir();
    let model = std::sync::Arc::new(companion::params::load_model(&params).unwrap());
    let base = tracking_snapshot(&model, &params, "complete-1");
    for policy in model.policies.iter().map(|p| model.policy(p).unwrap()) {
        let stream = StreamGen::new(&model, base.clone(), Stream::Changing);
        let mut core = Core::new(std::sync::Arc::clone(&model), ModelKind::Bfm, policy);
        core.set_caches(false);
        let mut obs = base.clone();
        let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
        let set =
            |obs: &mut companion_core::observations::Observations, k: u64| stream.advance(obs, k);
        for k in 0..WARM {
            set(&mut obs, k);
            core.step_into(&obs, &mut plan, &mut rec);
        }
        let runs_before = core.work_done().scheduler_runs;
        let mut allocs = 0;
        for k in WARM..WARM + COUNTED {
            set(&mut obs, k);
            allocs += allocations(|| core.step_into(&obs, &mut plan, &mut rec));
            assert!(rec.resources.is_some(), "the resources stage ran");
        }
        let runs = core.work_done().scheduler_runs - runs_before;
        assert_eq!(
            runs, COUNTED,
            "{policy:?}: the scheduler must run every cycle"
        );
        assert_eq!(
            allocs, 0,
            "{policy:?}: {allocs} allocations in {COUNTED} memo-less cycles"
        );
    }
}
