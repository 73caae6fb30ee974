//! Solve time of the BFM paper's MDPs (finite horizon 100 as in section 7, policy iteration as in
//! Table 9) and a scaling series of random sparse MDPs.
//!
//! The paper MDPs are instantiated at the section 7.1 point (safety policy) and exported to
//! `benches/models/*.json` by the companion test `mission_mdp::tests::bench_models_are_current`
//! (regenerate with `UPDATE_BENCH_MODELS=1 cargo test -p companion-testkit --test bench_models`).

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use mdp_engine::{Config, Mdp, MdpBuilder, Workspace};
use std::hint::black_box;

fn paper_models() -> Vec<(String, Mdp)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/models");
    [
        "reference",
        "navigation",
        "landing",
        "tracking",
        "monolithic",
    ]
    .iter()
    .map(|n| {
        let text = std::fs::read_to_string(dir.join(format!("{n}.json"))).expect("exported model");
        (
            n.to_string(),
            serde_json::from_str(&text).expect("valid model json"),
        )
    })
    .collect()
}

/// Random sparse MDP: every action admissible everywhere, `k` successors per (state, action),
/// a fixed LCG (reproducible, no extra dependency).
fn random_mdp(n: usize, m: usize, k: usize, seed: u64) -> Mdp {
    let mut x = seed;
    let mut next = move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (x >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut b = MdpBuilder::new(n, m);
    let mut tr = Vec::with_capacity(k);
    for s in 0..n {
        for a in 0..m {
            tr.clear();
            let mut total = 0.0;
            while tr.len() < k.min(n) {
                let j = (next() * n as f64) as usize % n;
                if tr.iter().any(|(t, _)| *t == j) {
                    continue;
                }
                let w = next() + 0.01;
                total += w;
                tr.push((j, w));
            }
            for t in tr.iter_mut() {
                t.1 /= total;
            }
            b.choice(s, a, next() * 10.0 - 5.0, &tr);
        }
    }
    b.build().expect("valid")
}

fn paper(c: &mut Criterion) {
    let cfg = Config {
        gamma: 0.95,
        ..Config::default()
    };
    let mut g = c.benchmark_group("paper");
    for (name, mdp) in paper_models() {
        let mut ws = Workspace::with_capacity(mdp.n_states(), 100, true);
        g.bench_function(BenchmarkId::new("finite_horizon_100", &name), |b| {
            b.iter(|| black_box(ws.finite_horizon(black_box(&mdp), 100).decision(0)))
        });
        g.bench_function(BenchmarkId::new("policy_iteration", &name), |b| {
            b.iter(|| {
                black_box(
                    ws.policy_iteration(black_box(&mdp), &cfg)
                        .unwrap()
                        .stats
                        .iterations,
                )
            })
        });
        g.bench_function(BenchmarkId::new("value_iteration", &name), |b| {
            b.iter(|| {
                black_box(
                    ws.value_iteration(black_box(&mdp), &cfg)
                        .unwrap()
                        .stats
                        .iterations,
                )
            })
        });
    }
    g.finish();
}

fn scaling(c: &mut Criterion) {
    let cfg = Config {
        gamma: 0.95,
        tolerance: 1e-6,
        eval_sweeps: 20,
        ..Config::default()
    };
    let mut g = c.benchmark_group("scaling");
    g.sample_size(10);
    for n in [10usize, 100, 1000, 10000] {
        let mdp = random_mdp(n, 10, 5, n as u64);
        let mut ws = Workspace::with_capacity(n, 100, n <= mdp_engine::DENSE_EVAL_MAX_STATES);
        g.bench_function(BenchmarkId::new("finite_horizon_100", n), |b| {
            b.iter(|| black_box(ws.finite_horizon(&mdp, 100).decision(0)))
        });
        g.bench_function(BenchmarkId::new("modified_policy_iteration", n), |b| {
            b.iter(|| {
                black_box(
                    ws.modified_policy_iteration(&mdp, &cfg)
                        .unwrap()
                        .stats
                        .iterations,
                )
            })
        });
        // Above Config::dense_eval_max_states the evaluation is sparse, so 10000 states is fine.
        g.bench_function(BenchmarkId::new("policy_iteration", n), |b| {
            b.iter(|| black_box(ws.policy_iteration(&mdp, &cfg).unwrap().stats.iterations))
        });
    }
    g.finish();
}

criterion_group!(benches, paper, scaling);
criterion_main!(benches);
