//! Solvers against independent brute force on small random MDPs:
//! * infinite horizon (discounted): enumerate every deterministic stationary policy, evaluate
//!   each with nalgebra's own LU (not the engine's solver), take the componentwise maximum;
//! * finite horizon: enumerate every deterministic Markov policy (one decision rule per stage) and
//!   evaluate it by pushing the state distribution *forward* (not by backward induction);
//! * the solvers (VI, PI, MPI) against each other, and gamma = 1 on acyclic (proper) models.

use mdp_engine::{Config, Mdp, MdpBuilder, Workspace};
use nalgebra::{DMatrix, DVector};
use proptest::prelude::*;

/// Raw random model: per (state, action): admissible?, reward, unnormalised weights per next.
#[derive(Debug, Clone)]
struct Raw {
    n: usize,
    m: usize,
    cells: Vec<(bool, f64, Vec<f64>)>,
}

fn raw(max_s: usize, max_a: usize) -> impl Strategy<Value = Raw> {
    (1..=max_s, 1..=max_a).prop_flat_map(|(n, m)| {
        let cell = (
            any::<bool>(),
            -10.0..10.0f64,
            prop::collection::vec(prop_oneof![Just(0.0), 0.0..1.0f64], n),
        );
        prop::collection::vec(cell, n * m).prop_map(move |cells| Raw { n, m, cells })
    })
}

/// Build: every state gets at least its first action (so no terminals unless `terminals`),
/// zero-weight rows become a self loop. With `dag`, transitions only go to higher states and the
/// last state is terminal (so every policy is proper and gamma = 1 is fine).
fn build(r: &Raw, dag: bool) -> Mdp {
    let mut b = MdpBuilder::new(r.n, r.m);
    for s in 0..r.n {
        if dag && s == r.n - 1 {
            continue;
        }
        for a in 0..r.m {
            let (adm, rew, w) = &r.cells[s * r.m + a];
            if !adm && a != 0 {
                continue;
            }
            let lo = if dag { s + 1 } else { 0 };
            let total: f64 = w[lo..].iter().sum();
            let tr: Vec<(usize, f64)> = if total <= 0.0 {
                vec![(if dag { r.n - 1 } else { s }, 1.0)]
            } else {
                (lo..r.n)
                    .filter(|&j| w[j] > 0.0)
                    .map(|j| (j, w[j] / total))
                    .collect()
            };
            b.choice(s, a, *rew, &tr);
        }
    }
    b.build().expect("valid random model")
}

fn admissible(m: &Mdp, s: usize) -> Vec<usize> {
    m.choices(s).map(|c| c.action).collect()
}

/// Exact value of a stationary policy by nalgebra LU on (I - gamma P) v = r.
fn eval_lu(m: &Mdp, pol: &[usize], gamma: f64) -> Option<DVector<f64>> {
    let n = m.n_states();
    let mut a = DMatrix::<f64>::identity(n, n);
    let mut b = DVector::<f64>::zeros(n);
    for s in 0..n {
        if let Some(c) = m.choices(s).find(|c| c.action == pol[s]) {
            b[s] = c.reward;
            for (j, p) in c.next.iter().zip(c.prob) {
                a[(s, *j as usize)] -= gamma * p;
            }
        }
    }
    a.lu().solve(&b)
}

/// All deterministic stationary policies (terminal states get a dummy 0).
fn all_policies(m: &Mdp) -> Vec<Vec<usize>> {
    let mut out = vec![vec![]];
    for s in 0..m.n_states() {
        let acts = admissible(m, s);
        let acts = if acts.is_empty() { vec![0] } else { acts };
        out = out
            .into_iter()
            .flat_map(|p| {
                acts.iter().map(move |a| {
                    let mut q = p.clone();
                    q.push(*a);
                    q
                })
            })
            .collect();
    }
    out
}

/// Componentwise max over all stationary policies (an optimal policy attains it everywhere).
fn brute_optimal(m: &Mdp, gamma: f64) -> Vec<f64> {
    let mut best = vec![f64::NEG_INFINITY; m.n_states()];
    for p in all_policies(m) {
        let v = eval_lu(m, &p, gamma).expect("nonsingular for gamma < 1 or proper policies");
        for s in 0..m.n_states() {
            best[s] = best[s].max(v[s]);
        }
    }
    best
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| (x - y).abs() <= tol * (1.0 + y.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn discounted_solvers_match_exhaustive_policy_search(r in raw(4, 3), gamma in 0.1..0.95f64) {
        let m = build(&r, false);
        let best = brute_optimal(&m, gamma);
        let cfg = Config { gamma, tolerance: 1e-11, max_iterations: 100_000, eval_sweeps: 5, ..Config::default() };
        // Oversized workspace: the dense evaluation runs on the top-left block of a 10x10 matrix.
        let mut ws = Workspace::with_capacity(10, 0, true);
        let mut policies = vec![];
        for which in 0..3 {
            let sol = match which {
                0 => ws.value_iteration(&m, &cfg),
                1 => ws.policy_iteration(&m, &cfg),
                _ => ws.modified_policy_iteration(&m, &cfg),
            }.unwrap();
            prop_assert!(sol.stats.converged);
            prop_assert!(close(sol.values(), &best, 1e-7), "solver {} {:?} vs {:?}", which, sol.values(), best);
            prop_assert!(sol.stats.residual < 1e-7);
            let pol: Vec<usize> = sol.policy().iter().map(|a| a.unwrap_or(0)).collect();
            // The returned policy itself is optimal (evaluated independently).
            let v = eval_lu(&m, &pol, gamma).unwrap();
            prop_assert!(close(v.as_slice(), &best, 1e-7));
            policies.push(pol);
        }
        // PI's exact values give the tie-broken greedy policy; VI/MPI may only differ where two
        // actions are within their tolerance of each other, and then both are optimal (checked).
        let _ = policies;
    }

    #[test]
    fn undiscounted_proper_models_match_exhaustive_search(r in raw(5, 3)) {
        let m = build(&r, true);
        let best = brute_optimal(&m, 1.0);
        let cfg = Config { gamma: 1.0, tolerance: 1e-12, max_iterations: 10_000, eval_sweeps: 3, ..Config::default() };
        let mut ws = Workspace::new();
        let pi = ws.policy_iteration(&m, &cfg).unwrap();
        prop_assert!(close(pi.values(), &best, 1e-9));
        let vi = ws.value_iteration(&m, &cfg).unwrap();
        prop_assert!(vi.stats.converged);
        prop_assert!(close(vi.values(), &best, 1e-9));
        let mpi = ws.modified_policy_iteration(&m, &cfg).unwrap();
        prop_assert!(close(mpi.values(), &best, 1e-9));
    }

    #[test]
    fn finite_horizon_matches_all_markov_policies(r in raw(3, 2), horizon in 1usize..4) {
        let m = build(&r, false);
        let n = m.n_states();
        // Decision rules: one stationary rule per stage; a Markov policy is a sequence of them.
        let rules = all_policies(&m);
        let mut best = vec![f64::NEG_INFINITY; n];
        let mut idx = vec![0usize; horizon];
        loop {
            for s0 in 0..n {
                // Forward: distribution over states, accumulate expected reward.
                let mut mu = vec![0.0; n];
                mu[s0] = 1.0;
                let mut total = 0.0;
                for &k in idx.iter() {
                    let rule = &rules[k];
                    let mut next = vec![0.0; n];
                    for s in 0..n {
                        if mu[s] == 0.0 { continue; }
                        if let Some(c) = m.choices(s).find(|c| c.action == rule[s]) {
                            total += mu[s] * c.reward;
                            for (j, p) in c.next.iter().zip(c.prob) {
                                next[*j as usize] += mu[s] * p;
                            }
                        }
                    }
                    mu = next;
                }
                best[s0] = best[s0].max(total);
            }
            // Next Markov policy (odometer over stages).
            let mut t = 0;
            while t < horizon {
                idx[t] += 1;
                if idx[t] < rules.len() { break; }
                idx[t] = 0;
                t += 1;
            }
            if t == horizon { break; }
        }
        let mut ws = Workspace::new();
        let fh = ws.finite_horizon(&m, horizon);
        prop_assert!(close(fh.values_at(0), &best, 1e-9), "{:?} vs {:?}", fh.values_at(0), best);
        prop_assert!(fh.values_at(horizon).iter().all(|v| *v == 0.0));
    }

    #[test]
    fn finite_horizon_decision_is_optimal_first_step(r in raw(4, 3), horizon in 1usize..6) {
        // The stage-0 decision attains the stage-0 value: Q(s, decision) == V_0(s), and no
        // admissible action does better.
        let m = build(&r, false);
        let mut ws = Workspace::new();
        let fh = ws.finite_horizon(&m, horizon);
        let v1 = fh.values_at(1).to_vec();
        for s in 0..m.n_states() {
            let qs: Vec<(usize, f64)> = m.choices(s).map(|c| {
                (c.action, c.reward + c.next.iter().zip(c.prob).map(|(j, p)| p * v1[*j as usize]).sum::<f64>())
            }).collect();
            let d = fh.decision(s).unwrap();
            let qd = qs.iter().find(|x| x.0 == d).unwrap().1;
            prop_assert!((qd - fh.value(0, s)).abs() < 1e-12);
            // lowest-index tie-breaking: every lower action is strictly worse
            for (a, q) in &qs {
                prop_assert!(*q <= qd + 1e-9);
                if *a < d { prop_assert!(*q < qd); }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// Too big for brute force: the three solvers agree with each other, and the policy each
    /// returns is optimal when evaluated exactly.
    #[test]
    fn solvers_agree_on_larger_models(r in raw(25, 4), gamma in 0.5..0.97f64) {
        let m = build(&r, false);
        let cfg = Config { gamma, tolerance: 1e-10, max_iterations: 100_000, eval_sweeps: 10, ..Config::default() };
        let mut ws = Workspace::new();
        let pi = ws.policy_iteration(&m, &cfg).unwrap().values().to_vec();
        let vi = ws.value_iteration(&m, &cfg).unwrap();
        prop_assert!(vi.stats.converged);
        let vi_pol: Vec<usize> = vi.policy().iter().map(|a| a.unwrap_or(0)).collect();
        prop_assert!(close(vi.values(), &pi, 1e-7));
        let mpi = ws.modified_policy_iteration(&m, &cfg).unwrap();
        prop_assert!(close(mpi.values(), &pi, 1e-7));
        let v = eval_lu(&m, &vi_pol, gamma).unwrap();
        prop_assert!(close(v.as_slice(), &pi, 1e-6));
    }
}

#[test]
fn workspace_reuse_gives_identical_answers() {
    let r = Raw {
        n: 3,
        m: 2,
        cells: vec![
            (true, 1.0, vec![0.2, 0.8, 0.0]),
            (true, 0.5, vec![0.0, 0.0, 1.0]),
            (true, 2.0, vec![0.5, 0.5, 0.0]),
            (false, 0.0, vec![1.0, 0.0, 0.0]),
            (true, -1.0, vec![0.0, 0.3, 0.7]),
            (true, 3.0, vec![1.0, 0.0, 0.0]),
        ],
    };
    let m = build(&r, false);
    let cfg = Config {
        gamma: 0.9,
        ..Config::default()
    };
    let mut ws = Workspace::new();
    let first = ws.policy_iteration(&m, &cfg).unwrap().values().to_vec();
    let _ = ws.finite_horizon(&m, 50);
    let _ = ws.value_iteration(&m, &cfg).unwrap();
    let again = ws.policy_iteration(&m, &cfg).unwrap().values().to_vec();
    assert_eq!(first, again);
    assert!(close(&first, &brute_optimal(&m, 0.9), 1e-9));
}
