//! Value iteration's MacQueen–Porteus stop against exact policy-evaluation values (nalgebra's
//! LU on the optimal policy found by exhaustive search is too slow here, so: the engine's exact
//! policy iteration, itself checked against exhaustive search in brute_force.rs), and against a
//! plain sup-norm value iteration written here: the returned values are within
//! gamma / (1 - gamma) * tolerance of V*, and never take more sweeps than the sup-norm rule.

use mdp_engine::{Config, Mdp, MdpBuilder, Workspace};
use proptest::prelude::*;
mod support;
use support::Lcg;

fn model(n: usize, m: usize, terminals: usize, seed: u64) -> Mdp {
    model_with(n, m, terminals, seed, false)
}

/// With `recurrent_0`, every choice also goes to state 0 (so one recurrent class: unichain).
fn model_with(n: usize, m: usize, terminals: usize, seed: u64, recurrent_0: bool) -> Mdp {
    let mut lcg = Lcg(seed.wrapping_mul(0x9E3779B97F4A7C15).wrapping_add(7));
    let mut rnd = move || lcg.f();
    let mut b = MdpBuilder::new(n, m);
    for s in 0..n - terminals.min(n - 1) {
        for a in 0..m {
            if a > 0 && rnd() < 0.3 {
                continue;
            }
            let mut tr: Vec<(usize, f64)> = vec![];
            for _ in 0..1 + (rnd() * 4.0) as usize {
                let j = ((rnd() * n as f64) as usize).min(n - 1);
                if !tr.iter().any(|t| t.0 == j) {
                    tr.push((j, rnd() + 0.05));
                }
            }
            if recurrent_0 && !tr.iter().any(|t| t.0 == 0) {
                tr.push((0, 0.3));
            }
            let tot: f64 = tr.iter().map(|t| t.1).sum();
            tr.iter_mut().for_each(|t| t.1 /= tot);
            b.choice(s, a, rnd() * 10.0 - 5.0, &tr);
        }
    }
    b.build().unwrap()
}

/// Plain value iteration with the old sup-norm stop; returns the number of sweeps.
fn sup_norm_sweeps(m: &Mdp, gamma: f64, tol: f64) -> u32 {
    let n = m.n_states();
    let mut v = vec![0.0; n];
    for it in 1..1_000_000 {
        let w: Vec<f64> = (0..n)
            .map(|s| {
                m.choices(s)
                    .map(|c| {
                        c.reward
                            + gamma
                                * c.next
                                    .iter()
                                    .zip(c.prob)
                                    .map(|(j, p)| p * v[*j as usize])
                                    .sum::<f64>()
                    })
                    .fold(None, |a: Option<f64>, q| Some(a.map_or(q, |a| a.max(q))))
                    .unwrap_or(0.0)
            })
            .collect();
        let diff = w
            .iter()
            .zip(&v)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        v = w;
        if diff < tol {
            return it;
        }
    }
    unreachable!()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]
    #[test]
    fn vi_within_its_bound_of_exact_values(
        n in 2usize..30, m in 1usize..4, terminals in 0usize..3, seed in any::<u64>(),
        gamma in 0.5..0.99f64, tol_exp in 4i32..11,
    ) {
        let mdp = model(n, m, terminals, seed);
        let tol = 10f64.powi(-tol_exp);
        let cfg = Config { gamma, tolerance: tol, ..Config::default() };
        let mut ws = Workspace::new();
        let exact = ws.policy_iteration(&mdp, &cfg).unwrap().values().to_vec();
        let vi = ws.value_iteration(&mdp, &cfg).unwrap();
        prop_assert!(vi.stats.converged);
        let bound = gamma / (1.0 - gamma) * tol;
        let scale = exact.iter().fold(1.0f64, |a, v| a.max(v.abs()));
        for (s, (a, b)) in vi.values().iter().zip(&exact).enumerate() {
            prop_assert!((a - b).abs() <= bound + 1e-12 * scale, "s={} {} vs {} bound {}", s, a, b, bound);
            if mdp.is_terminal(s) {
                prop_assert_eq!(*a, 0.0);
            }
        }
        prop_assert!(vi.stats.iterations <= sup_norm_sweeps(&mdp, gamma, tol));
    }
}

/// On a unichain model (every state reaches every other) the bracket closes at the mixing rate,
/// not at gamma: far fewer sweeps than the sup-norm rule.
#[test]
fn unichain_stops_much_earlier_than_sup_norm() {
    let mdp = model_with(40, 3, 0, 1, true);
    let cfg = Config {
        gamma: 0.95,
        tolerance: 1e-10,
        ..Config::default()
    };
    let mut ws = Workspace::new();
    let its = ws.value_iteration(&mdp, &cfg).unwrap().stats.iterations;
    let sup = sup_norm_sweeps(&mdp, 0.95, 1e-10);
    eprintln!("MacQueen {its} sweeps, sup-norm {sup}");
    assert!(its * 3 < sup, "{its} vs {sup}");
}
