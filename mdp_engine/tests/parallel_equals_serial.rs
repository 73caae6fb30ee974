//! The sweeps split across threads (`Workspace::set_parallel_min_transitions(0)`) against one
//! thread (`usize::MAX`) on the same random models: finite horizon (every stage's values bit for
//! bit, every stage's action, the stages computed and the early stop's bound) and value
//! iteration (values bit for bit, policy, sweeps), the split in a pool of two threads. Models of
//! 2 to 300 states, so the threads' range edges fall everywhere, with terminal states and mixed successor counts (the general kernel) or a
//! fixed count (the unrolled ones).

use mdp_engine::{Config, Mdp, MdpBuilder, Workspace};
use proptest::prelude::*;
mod support;
use support::Lcg;

fn model(n: usize, m: usize, k_fixed: Option<usize>, terminals: usize, seed: u64) -> Mdp {
    let mut lcg = Lcg(seed ^ 0x9e37_79b9_7f4a_7c15);
    let mut b = MdpBuilder::new(n, m);
    for s in 0..n {
        if lcg.below(n) < terminals {
            continue; // terminal: no choice
        }
        for a in 0..m {
            if a > 0 && lcg.f() < 0.3 {
                continue;
            }
            let k = k_fixed.unwrap_or_else(|| 1 + lcg.below(6)).min(n);
            let mut tr: Vec<(usize, f64)> = Vec::new();
            while tr.len() < k {
                let j = lcg.below(n);
                if !tr.iter().any(|t| t.0 == j) {
                    tr.push((j, 0.05 + lcg.f()));
                }
            }
            let tot: f64 = tr.iter().map(|t| t.1).sum();
            tr.iter_mut().for_each(|t| t.1 /= tot);
            b.choice(s, a, lcg.f() * 10.0 - 4.0, &tr);
        }
    }
    b.build().expect("valid")
}

/// The split runs as a team of a pool's threads: two of them, whatever the machine's cores.
fn two_threads() -> &'static rayon::ThreadPool {
    static POOL: std::sync::OnceLock<rayon::ThreadPool> = std::sync::OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("thread pool")
    })
}

fn workspaces() -> (Workspace, Workspace) {
    let (mut one, mut split) = (Workspace::new(), Workspace::new());
    one.set_parallel_min_transitions(usize::MAX);
    split.set_parallel_min_transitions(0);
    (one, split)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    #[test]
    fn split_sweeps_equal_one_thread_bit_for_bit(
        n in 2usize..300, m in 1usize..5, fixed in prop::option::of(1usize..6),
        terminals in 0usize..3, seed in any::<u64>(), h in 1usize..80,
        gamma in prop_oneof![Just(0.95), Just(0.5), Just(0.99)],
    ) {
        let mdp = model(n, m, fixed, terminals, seed);
        let (mut one, mut split) = workspaces();
        let a = one.finite_horizon(&mdp, h);
        let b = two_threads().install(|| split.finite_horizon(&mdp, h));
        prop_assert_eq!(a.stats().iterations, b.stats().iterations);
        prop_assert_eq!(a.stats().residual.to_bits(), b.stats().residual.to_bits());
        for t in 0..h {
            for s in 0..n {
                prop_assert_eq!(a.value(t, s).to_bits(), b.value(t, s).to_bits(), "t={} s={}", t, s);
                prop_assert_eq!(a.action(t, s), b.action(t, s), "t={} s={}", t, s);
            }
        }
        let cfg = Config { gamma, tolerance: 1e-9, ..Config::default() };
        let va = one.value_iteration(&mdp, &cfg).unwrap();
        let (vals, pol, it) = (va.values().to_vec(), va.policy(), va.stats.iterations);
        let vb = two_threads().install(|| split.value_iteration(&mdp, &cfg)).unwrap();
        prop_assert_eq!(it, vb.stats.iterations);
        prop_assert_eq!(pol, vb.policy());
        for (x, y) in vals.iter().zip(vb.values()) {
            prop_assert_eq!(x.to_bits(), y.to_bits());
        }
    }
}

/// The default threshold keeps the paper's models (tens of transitions) on one thread and splits
/// a 10,000-state model; both give the one-thread answer.
#[test]
fn default_threshold_splits_only_big_models() {
    let big = model(10_000, 10, Some(5), 0, 7);
    assert!(big.n_transitions() >= mdp_engine::PARALLEL_MIN_TRANSITIONS);
    let (mut one, mut dflt) = (Workspace::new(), Workspace::new());
    one.set_parallel_min_transitions(usize::MAX);
    let (a, b) = (one.finite_horizon(&big, 20), dflt.finite_horizon(&big, 20));
    for s in 0..big.n_states() {
        assert_eq!(a.value(0, s).to_bits(), b.value(0, s).to_bits());
        assert_eq!(a.decision(s), b.decision(s));
    }
}
