//! Health evaluation cost: one cycle of every health manager (all published probabilities) under
//! typical evidence, and one junction-tree propagation of the tracking BN alone.

use companion_core::health::HealthModel;
use companion_core::observations::Observations;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;

fn snapshot(vibration: f64) -> Observations {
    let mut o = Observations::default();
    for (k, v) in [
        ("vibration_mps2", vibration),
        ("wind_mps", 3.0),
        ("battery_pct", 45.0),
        ("gps_fix", 3.0),
        ("gps_sats", 10.0),
        ("luminosity_lux", 400.0),
        ("target_speed_rel", 0.5),
        ("drone_speed_mps", 3.0),
        ("cpu_load", 0.2),
        ("free_tiles", 4.0),
        ("temperature_c", 20.0),
        ("waypoints_remaining", 3.0),
    ] {
        o.set(k, v);
    }
    o
}

fn bench(c: &mut Criterion) {
    let params = companion::params::default_params_dir();
    c.bench_function("health_load_and_compile", |b| {
        b.iter(|| {
            let files = companion::params::read_params_dir(black_box(&params)).unwrap();
            HealthModel::load(&files).unwrap()
        })
    });
    let mut model =
        HealthModel::load(&companion::params::read_params_dir(&params).unwrap()).unwrap();
    let ev = model.evidence(&snapshot(25.0));
    let mut out = std::collections::BTreeMap::new();
    c.bench_function("health_evaluate_all_managers", |b| {
        b.iter(|| {
            model.evaluate_into(black_box(&ev), &mut out).unwrap();
            black_box(out.get("P_V3").copied())
        })
    });
    c.bench_function("health_observations_to_evidence", |b| {
        let o = snapshot(25.0);
        b.iter(|| model.evidence(black_box(&o)))
    });
    let apps = model.manager("applications").unwrap();
    let mut engine = apps.engine().clone();
    let net = engine.network().clone();
    let e = net
        .evidence([
            ("A_wind", "strong"),
            ("A_target_speed", "high"),
            ("QoS", "high"),
        ])
        .unwrap();
    c.bench_function("bn_propagate_applications", |b| {
        b.iter(|| engine.propagate(black_box(&e)).unwrap())
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
