//! One full decision cycle (observations to plan: all health managers, the three concurrent MDPs
//! at horizon 100, behaviour and resource arbitration, the PANORAMA guarantee), and the monolithic
//! model's cycle for the concurrent/monolithic ratio (BFM paper Table 9's point).

use companion::decision::{Core, Model, ModelKind, Policy};
use companion::observations::Observations;
use companion::sim::{Scenario, World, WorldSpec};
use companion::spec::default_params_dir;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

/// An observation snapshot in the tracking phase under vibrations, taken from the simulated world.
fn tracking_snapshot(model: &Model) -> Observations {
    let params = default_params_dir();
    let spec = WorldSpec::load(&params).unwrap();
    let scenario = Scenario::load(&params, "complete-1").unwrap();
    let mut world = World::new(&spec, &scenario, 1);
    let mut core = Core::new(model, ModelKind::Bfm, Policy::Safety);
    loop {
        let obs = world.observe();
        if obs.state.starts_with('v') {
            return obs;
        }
        let (plan, rec) = core.step(&obs);
        world.advance(&plan, &rec);
    }
}

fn cycle(c: &mut Criterion) {
    let model = Model::load(&default_params_dir()).unwrap();
    let obs = tracking_snapshot(&model);
    for (name, kind) in [
        ("cycle_concurrent", ModelKind::Bfm),
        ("cycle_monolithic", ModelKind::Monolithic),
    ] {
        let mut core = Core::new(&model, kind, Policy::Safety);
        c.bench_function(name, |b| b.iter(|| black_box(core.step(black_box(&obs)))));
    }
}

criterion_group!(benches, cycle);
criterion_main!(benches);
