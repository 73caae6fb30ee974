//! One warmed-up decision cycle of the concurrent MDPs (instantiate from named probabilities +
//! finite-horizon solve) allocates nothing (counting global allocator, own test binary).

use companion_core::mission_mdp::MissionMdps;
use mdp_engine::Workspace;
use std::collections::BTreeMap;

#[path = "support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

const KNOWN: &[&str] = &[
    "P_sys",
    "P_battery",
    "P_obs",
    "P_fusion",
    "P_SI",
    "P_SF",
    "P_appT",
    "P_appZ",
    "P_crash",
    "P_detect",
    "P_track",
    "P_V0",
    "P_V1",
    "P_V2",
    "P_V3",
    "P_V4",
    "P_V5",
];

#[test]
fn warm_decision_cycle_does_not_allocate() {
    let mut all = MissionMdps::load(
        &companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap(),
        KNOWN,
    )
    .unwrap();
    let mut probs: BTreeMap<String, f64> = all.check_point().clone();
    let names: Vec<String> = all.concurrent().to_vec();
    let mut ws = Workspace::with_capacity(12, 100, false);
    let cycle = |all: &mut MissionMdps, probs: &BTreeMap<String, f64>, ws: &mut Workspace| {
        let mut total = 0.0;
        for n in &names {
            let m = all.get_mut(n).unwrap();
            let s = m.state_index("wpf").unwrap();
            for pol in ["safety", "mission"] {
                let d = m.decide(ws, s, probs, pol, 100).unwrap().unwrap();
                total += d.value + d.action as f64;
            }
        }
        total
    };
    cycle(&mut all, &probs, &mut ws);
    for k in 0..5 {
        *probs.get_mut("P_battery").unwrap() = 0.5 + 0.1 * k as f64;
        let n = allocations(|| {
            std::hint::black_box(cycle(&mut all, &probs, &mut ws));
        });
        assert_eq!(n, 0, "cycle {k} allocated");
    }
}
