//! Properties over random requests and platform states, checked with sums computed here from
//! the catalogue (not by the scheduler's own bookkeeping).

mod common;
use common::params;
use fpga_model::*;
use proptest::prelude::*;
use std::collections::BTreeSet;

const APPS: [&str; 5] = [
    "tracking",
    "landing_search",
    "obstacle_detection",
    "obstacle_avoidance",
    "path_planning",
];

#[derive(Debug, Clone)]
struct Case {
    requests: Vec<Request>,
    failed: u8,
    cores: u8,
    external: f64,
    bitstreams: Vec<Option<usize>>,
    safety: bool,
}

fn arb_case() -> impl Strategy<Value = Case> {
    let req = prop::option::of((0usize..6, -1.6f64..2.4));
    (
        prop::collection::vec(req, 5),
        Just(APPS.to_vec()).prop_shuffle(),
        0u8..16,
        0u8..=2,
        prop_oneof![Just(0.0), 0.0f64..1.0],
        prop::collection::vec(prop::option::of(0usize..64), 4),
        any::<bool>(),
    )
        .prop_map(
            |(reqs, order, failed, cores, external, bitstreams, safety)| {
                let p = params();
                let mut requests = Vec::new();
                for (app, r) in order.iter().zip(reqs) {
                    if let Some((vi, e)) = r {
                        let versions = p.catalogue.versions(app);
                        requests.push(Request::new(
                            app,
                            versions[vi % versions.len()],
                            10f64.powf(e),
                        ));
                    }
                }
                Case {
                    requests,
                    failed,
                    cores,
                    external,
                    bitstreams,
                    safety,
                }
            },
        )
}

fn state_of(p: &common::Params, c: &Case) -> PlatformState {
    let mut st = PlatformState::new(&p.platform);
    let keys: Vec<String> = p
        .catalogue
        .variants()
        .iter()
        .filter(|v| v.tiles > 0)
        .flat_map(|v| (0..v.tiles).map(move |k| format!("{}#{k}", v.key())))
        .collect();
    for (t, b) in c.bitstreams.iter().enumerate() {
        st.tiles[t].bitstream = b.map(|i| keys[i % keys.len()].clone());
        st.tiles[t].failed = c.failed & (1 << t) != 0;
    }
    st.cores_online = c.cores;
    st.external_cpu_load = c.external;
    st
}

fn variant_of<'a>(p: &'a common::Params, pl: &Placement) -> &'a Variant {
    p.catalogue
        .variants()
        .iter()
        .find(|v| {
            v.app == pl.app && v.version == pl.version && v.implementation == pl.implementation
        })
        .unwrap()
}

fn healthy(st: &PlatformState) -> usize {
    st.tiles.iter().filter(|t| !t.failed).count()
}

fn cpu_cap(p: &common::Params, st: &PlatformState) -> f64 {
    p.platform.cpu_budget * f64::from(st.cores_online) / f64::from(p.platform.cpu_cores)
        - st.external_cpu_load
}

proptest! {
    #[test]
    fn placement_never_exceeds_tiles_or_cpu_budget(c in arb_case()) {
        let p = params();
        let st = state_of(p, &c);
        let policy = if c.safety { &p.safety } else { &p.mission };
        let (s, after) = schedule(&p.platform, &p.catalogue, policy, &st, &c.requests);
        let mut used = BTreeSet::new();
        let mut cpu = 0.0;
        for pl in &s.placements {
            let v = variant_of(p, pl);
            prop_assert_eq!(pl.tiles.len(), usize::from(v.tiles));
            prop_assert!(v.meets(pl.required_fps));
            for &t in &pl.tiles {
                prop_assert!(t < 4);
                prop_assert!(!st.tiles[usize::from(t)].failed, "placed on failed tile {}", t);
                prop_assert!(used.insert(t), "tile {} used twice", t);
                let part_tag = after.tiles[usize::from(t)].bitstream.clone().unwrap();
                prop_assert!(part_tag.starts_with(&v.key()));
            }
            cpu += v.sw_ms() * pl.required_fps / 1000.0 / 2.0;
        }
        prop_assert!(used.len() <= healthy(&st));
        prop_assert_eq!(usize::from(s.tiles_used), used.len());
        if cpu > 0.0 {
            prop_assert!(cpu <= cpu_cap(p, &st) + 1e-9, "cpu {} over cap {}", cpu, cpu_cap(p, &st));
        }
        // Every request is either placed or reported dropped.
        prop_assert_eq!(s.placements.len() + s.dropped.len(), c.requests.len());
    }

    #[test]
    fn just_enough_never_picks_faster_when_a_slower_one_fits(c in arb_case()) {
        let p = params();
        let st = state_of(p, &c);
        let policy = if c.safety { &p.safety } else { &p.mission };
        let (s, _) = schedule(&p.platform, &p.catalogue, policy, &st, &c.requests);
        let share = |v: &Variant, fps: f64| v.sw_ms() * fps / 1000.0 / 2.0;
        let tiles: usize = s.placements.iter().map(|pl| usize::from(variant_of(p, pl).tiles)).sum();
        let cpu: f64 = s.placements.iter().map(|pl| share(variant_of(p, pl), pl.required_fps)).sum();
        for pl in &s.placements {
            let chosen = variant_of(p, pl);
            for alt in p.catalogue.implementations(&pl.app, &pl.version) {
                if alt.ms_per_frame() <= chosen.ms_per_frame() || !alt.meets(pl.required_fps) {
                    continue;
                }
                // The slower alternative with everything else unchanged must not fit.
                let t = tiles - usize::from(chosen.tiles) + usize::from(alt.tiles);
                let sh = share(alt, pl.required_fps);
                let all_cpu = cpu - share(chosen, pl.required_fps) + sh;
                let any_sw = all_cpu > 0.0;
                let fits = t <= healthy(&st) && (!any_sw || all_cpu <= cpu_cap(p, &st) - 1e-9);
                prop_assert!(!fits, "{} {}: slower {} would fit instead of {}", pl.app, pl.version, alt.implementation, chosen.implementation);
            }
        }
    }

    #[test]
    fn removing_a_fault_never_makes_a_feasible_set_infeasible(c in arb_case(), which in 0u8..6) {
        let p = params();
        let st = state_of(p, &c);
        let policy = if c.safety { &p.safety } else { &p.mission };
        let (s, _) = schedule(&p.platform, &p.catalogue, policy, &st, &c.requests);
        prop_assume!(s.dropped.is_empty() && s.degraded.is_empty());
        let mut better = st.clone();
        match which {
            0..=3 => better.repair_tile(which),
            4 => better.cores_online = p.platform.cpu_cores,
            _ => better.external_cpu_load = 0.0,
        }
        let (s2, _) = schedule(&p.platform, &p.catalogue, policy, &better, &c.requests);
        prop_assert!(s2.dropped.is_empty(), "{:?}", s2.dropped);
        prop_assert!(s2.degraded.is_empty(), "{:?}", s2.degraded);
    }
}
