//! Time the full decision cycle (observations to plan: evidence, every health BN, the MDPs,
//! behaviour and resource arbitration, the PANORAMA guarantee) in-process and count its heap
//! allocations, for bench/compare's "decision cycle" case (target: 50 us median).
//!
//! Prints one JSON object `{"cases":[{"name","median_us","p99_us","max_us","cycles",
//! "allocations_per_cycle","mdp_solves_per_cycle","scheduler_runs_per_cycle"}]}`. Each case warms
//! a core up for 100 cycles on its stream, then times `Core::step_into` alone, once per cycle
//! (`Instant` around the call), over `cycles` cycles (first argument, default 2000).
//!
//! Cases: `steady` (time and battery move, evidence does not), `changing` (vibration evidence
//! flips every cycle: health probabilities and every MDP's inputs change), `worst` (the changing
//! stream with the memos off: every MDP re-solved and the scheduler re-run every cycle), and
//! `monolithic` (section 5's single MDP on the changing stream).
//!
//! Run: `cargo run --release -p companion --example bench_cycle -- 2000 [CASE,CASE...]` (the
//! optional second argument keeps only the named cases, e.g. `changing` for a profile).
use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Plan};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
use serde_json::json;
use std::hint::black_box;
use std::time::{Duration, Instant};

// The same counting allocator as the no-allocation tests (counts this thread's allocations).
#[path = "../tests/support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

fn main() {
    let cycles: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("cycles: a number"))
        .unwrap_or(2000);
    let only: Vec<String> = std::env::args()
        .nth(2)
        .map(|a| a.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    let params = default_params_dir();
    let model = companion::params::load_model(&params).expect("params load");
    let base = tracking_snapshot(&model, &params, "complete-1");
    let mut out = Vec::new();
    for (name, kind, stream, caches) in [
        ("steady", ModelKind::Bfm, Stream::Steady, true),
        ("changing", ModelKind::Bfm, Stream::Changing, true),
        ("worst", ModelKind::Bfm, Stream::Changing, false),
        ("monolithic", ModelKind::Monolithic, Stream::Changing, true),
    ] {
        if !only.is_empty() && !only.iter().any(|o| o == name) {
            continue;
        }
        let stream_gen = StreamGen::new(&model, base.clone(), stream);
        let mut core = Core::new(&model, kind, model.policy("safety").unwrap());
        core.set_caches(caches);
        let mut obs = base.clone();
        let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
        for k in 0..100 {
            stream_gen.advance(&mut obs, k);
            core.step_into(&obs, &mut plan, &mut rec);
        }
        let work0 = core.work_done();
        let mut times = Vec::with_capacity(cycles as usize);
        let mut allocs = 0;
        for k in 100..100 + cycles {
            stream_gen.advance(&mut obs, k);
            let mut dt = Duration::ZERO;
            allocs += allocations(|| {
                let t0 = Instant::now();
                core.step_into(black_box(&obs), &mut plan, &mut rec);
                dt = t0.elapsed();
            });
            black_box(&rec);
            times.push(dt.as_secs_f64() * 1e6);
        }
        let work = core.work_done();
        times.sort_by(f64::total_cmp);
        let per = |x: u64| x as f64 / cycles as f64;
        out.push(json!({
            "name": name,
            "median_us": percentile(&times, 0.5),
            "p99_us": percentile(&times, 0.99),
            "max_us": times[times.len() - 1],
            "cycles": cycles,
            "allocations_per_cycle": allocs as f64 / cycles as f64,
            "mdp_solves_per_cycle": per(work.mdp_solves - work0.mdp_solves),
            "scheduler_runs_per_cycle": per(work.scheduler_runs - work0.scheduler_runs),
        }));
    }
    println!("{}", json!({ "cases": out }));
}
