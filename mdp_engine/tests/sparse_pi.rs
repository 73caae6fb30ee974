//! Policy iteration's sparse evaluation (above `Config::dense_eval_max_states`) against its dense
//! exact one and against nalgebra's LU evaluation of the returned policy: the same policy and the
//! same values (1e-9 relative) on random models on both sides of the default threshold, with and
//! without terminal states, with slowly mixing chains, and with gamma = 1 (proper and improper
//! policies: the singular case must still be reported, at the same iteration).

use mdp_engine::{Config, DENSE_EVAL_MAX_STATES, Mdp, MdpBuilder, SolveError, Workspace};
use nalgebra::{DMatrix, DVector};

mod support;
use support::Lcg;

/// `n` states, `m` actions (each admissible w.p. ~0.7, action 0 always), up to `k` successors.
/// The last `terminals` states have no action. With `ring`, successors are near neighbours on a
/// ring (a slowly mixing chain); with `dag`, successors are higher-numbered states only, so every
/// policy reaches a terminal state.
fn model(n: usize, m: usize, k: usize, terminals: usize, seed: u64, ring: bool, dag: bool) -> Mdp {
    let mut rng = Lcg(seed);
    let mut b = MdpBuilder::new(n, m);
    for s in 0..n - terminals {
        for a in 0..m {
            if a > 0 && rng.f() < 0.3 {
                continue;
            }
            let mut tr: Vec<(usize, f64)> = Vec::new();
            for _ in 0..k {
                let j = if dag {
                    s + 1 + rng.below(n - s - 1)
                } else if ring {
                    (s + rng.below(3) + n - 1) % n
                } else {
                    rng.below(n)
                };
                if !tr.iter().any(|t| t.0 == j) {
                    tr.push((j, rng.f() + 0.01));
                }
            }
            let total: f64 = tr.iter().map(|t| t.1).sum();
            tr.iter_mut().for_each(|t| t.1 /= total);
            b.choice(s, a, rng.f() * 10.0 - 5.0, &tr);
        }
    }
    b.build().expect("valid model")
}

/// Values of `policy` by nalgebra's LU on `(I - gamma P) v = r` (terminal rows v = 0).
fn lu_values(m: &Mdp, policy: &[Option<usize>], gamma: f64) -> DVector<f64> {
    let n = m.n_states();
    let mut a = DMatrix::<f64>::identity(n, n);
    let mut r = DVector::<f64>::zeros(n);
    for s in 0..n {
        if let Some(act) = policy[s] {
            let c = m.choices(s).find(|c| c.action == act).expect("admissible");
            r[s] = c.reward;
            for (j, p) in c.next.iter().zip(c.prob) {
                a[(s, *j as usize)] -= gamma * p;
            }
        }
    }
    a.lu().solve(&r).expect("nonsingular")
}

fn cfg(gamma: f64, dense_eval_max_states: usize) -> Config {
    Config {
        gamma,
        dense_eval_max_states,
        ..Config::default()
    }
}

/// Sparse and dense PI agree with each other and with nalgebra's evaluation of the policy.
fn check_agree(m: &Mdp, gamma: f64) {
    let mut ws = Workspace::new();
    let dense = ws.policy_iteration(m, &cfg(gamma, usize::MAX)).unwrap();
    let (dv, dp, dit) = (
        dense.values().to_vec(),
        dense.policy(),
        dense.stats.iterations,
    );
    let sparse = ws.policy_iteration(m, &cfg(gamma, 0)).unwrap();
    let (sv, sp) = (sparse.values().to_vec(), sparse.policy());
    assert!(sparse.stats.converged);
    assert_eq!(
        sp,
        dp,
        "policies differ (n = {}, gamma = {gamma})",
        m.n_states()
    );
    let exact = lu_values(m, &dp, gamma);
    let scale = exact.amax().max(1.0);
    for s in 0..m.n_states() {
        assert!(
            (sv[s] - exact[s]).abs() <= 1e-9 * scale,
            "s={s} {} vs {}",
            sv[s],
            exact[s]
        );
        assert!((dv[s] - exact[s]).abs() <= 1e-9 * scale);
    }
    // The default threshold picks one of the two and gives the same answer.
    let def = ws
        .policy_iteration(m, &cfg(gamma, DENSE_EVAL_MAX_STATES))
        .unwrap();
    assert_eq!(def.policy(), dp);
    assert!(def.stats.iterations <= dit + 2);
}

#[test]
fn sparse_equals_dense_on_random_models_both_sides_of_threshold() {
    for (i, n) in [30usize, 49, 51, 210].into_iter().enumerate() {
        for (j, gamma) in [0.5, 0.95, 0.99].into_iter().enumerate() {
            let seed = 1000 + i as u64 * 17 + j as u64;
            if (i + j) % 2 == 0 {
                check_agree(&model(n, 5, 5, 0, seed, false, false), gamma);
            } else {
                check_agree(&model(n, 4, 3, n / 10, seed, false, false), gamma);
            }
        }
    }
}

#[test]
fn sparse_equals_dense_on_slowly_mixing_rings() {
    check_agree(&model(100, 3, 3, 0, 7, true, false), 0.999);
    check_agree(&model(100, 3, 3, 5, 8, true, false), 0.99);
}

#[test]
fn gamma_one_proper_models_agree() {
    for seed in 0..2 {
        let m = model(210, 4, 4, 3, 50 + seed, false, true);
        check_agree(&m, 1.0);
    }
}

#[test]
fn gamma_one_improper_policy_is_singular_on_both_paths() {
    // 300 states; every state's action 0 is a rewarding cycle to the next state (no terminal
    // reachable), action 1 pays less and goes to the terminal state 299. The first policy (greedy
    // for immediate reward) takes action 0 everywhere: improper, singular at iteration 1.
    let n = 300;
    let mut b = MdpBuilder::new(n, 2);
    for s in 0..n - 1 {
        b.choice(s, 0, 1.0, &[((s + 1) % (n - 1), 1.0)])
            .choice(s, 1, 0.5, &[(n - 1, 1.0)]);
    }
    let m = b.build().unwrap();
    let mut ws = Workspace::new();
    for threshold in [usize::MAX, 0] {
        assert_eq!(
            ws.policy_iteration(&m, &cfg(1.0, threshold)).unwrap_err(),
            SolveError::Singular { iteration: 1 }
        );
    }
    // A single state stuck in a cycle of two among otherwise proper states is enough.
    let mut b = MdpBuilder::new(n, 1);
    for s in 0..n - 1 {
        let next = match s {
            10 => 11,
            11 => 10,
            _ => n - 1,
        };
        b.choice(s, 0, 1.0, &[(next, 1.0)]);
    }
    let m = b.build().unwrap();
    for threshold in [usize::MAX, 0] {
        assert_eq!(
            ws.policy_iteration(&m, &cfg(1.0, threshold)).unwrap_err(),
            SolveError::Singular { iteration: 1 }
        );
    }
    // ... and a zero-probability entry is not a way out: s0 -> {s0: 1, terminal: 0}.
    let mut b = MdpBuilder::new(n, 1);
    b.choice(0, 0, 1.0, &[(0, 1.0), (n - 1, 0.0)]);
    for s in 1..n - 1 {
        b.choice(s, 0, 1.0, &[(n - 1, 1.0)]);
    }
    let m = b.build().unwrap();
    for threshold in [usize::MAX, 0] {
        assert!(matches!(
            ws.policy_iteration(&m, &cfg(1.0, threshold)),
            Err(SolveError::Singular { .. })
        ));
    }
}
