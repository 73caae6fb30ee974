//! One full decision cycle (observations to plan: all health managers, the three concurrent MDPs
//! at horizon 100, behaviour and resource arbitration, the PANORAMA guarantee), and the monolithic
//! model's cycle for the concurrent/monolithic ratio (BFM paper Table 9's point).
//!
//! `cycle_concurrent`: a steady tracking-phase stream (time and battery move, evidence does not).
//! `cycle_concurrent_changing`: the vibration evidence flips every cycle, so the health
//! probabilities and every MDP's inputs change and the solve memos miss.
//! `cycle_concurrent_worst`: the changing stream with the memos off (every MDP re-solved, the
//! scheduler re-run, every cycle). `cycle_monolithic`: section 5's single MDP, memos off, so the
//! ratio to `cycle_concurrent_worst` compares solve work like for like.

use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Plan};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn cycle(c: &mut Criterion) {
    let params = default_params_dir();
    let model = std::sync::Arc::new(companion::params::load_model(&params).unwrap());
    let base = tracking_snapshot(&model, &params, "complete-1");
    for (name, kind, stream, caches) in [
        ("cycle_concurrent", ModelKind::Bfm, Stream::Steady, true),
        (
            "cycle_concurrent_changing",
            ModelKind::Bfm,
            Stream::Changing,
            true,
        ),
        (
            "cycle_concurrent_worst",
            ModelKind::Bfm,
            Stream::Changing,
            false,
        ),
        (
            "cycle_monolithic",
            ModelKind::Monolithic,
            Stream::Changing,
            false,
        ),
    ] {
        let stream_gen = StreamGen::new(&model, base.clone(), stream);
        let mut core = Core::new(
            std::sync::Arc::clone(&model),
            kind,
            model.policy("safety").unwrap(),
        );
        core.set_caches(caches);
        let mut obs = base.clone();
        let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
        let mut k = 0;
        c.bench_function(name, |b| {
            b.iter(|| {
                stream_gen.advance(&mut obs, k);
                k += 1;
                core.step_into(black_box(&obs), &mut plan, &mut rec);
                black_box(&rec);
            })
        });
    }
}

criterion_group!(benches, cycle);
criterion_main!(benches);
