//! The resource manager agrees with the scheduler (issue 24 item 3): P_Vi is driven down by the
//! fit node exactly when the scheduler cannot place Vi beside the applications in force.

use super::*;
use fpga_model::{PlatformState, Request, Schedule};
use proptest::prelude::*;
use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

/// The shipped model, loaded once per test binary and shared (each core holds its `Arc`).
fn model() -> Arc<Model> {
    static MODEL: OnceLock<Arc<Model>> = OnceLock::new();
    Arc::clone(MODEL.get_or_init(|| {
        Arc::new(Model::load(&crate::shipped::params()).expect("shipped params load"))
    }))
}

/// The applications the policy ranks above tracking, as the simulated missions request them.
fn others_of(lidar_fps: f64, search: Option<(&'static str, f64)>, avoid: bool) -> Vec<Request> {
    let mut r = vec![Request::new("obstacle_detection", "lidar", lidar_fps)];
    if avoid {
        r.push(Request::new("obstacle_avoidance", "right_turn", 1.0));
    }
    if let Some((version, fps)) = search {
        r.push(Request::new("landing_search", version, fps));
    }
    r
}

/// What the resource manager publishes for `version` with the core's evidence, and with its fit
/// node set to `no` and `yes` (the core's own evaluation path: the manager re-evaluated on the
/// imported priors the full evaluation left).
struct Published {
    p: f64,
    p_no: f64,
    p_yes: f64,
    fit: String,
}

/// Core at `state` with the others' placements `placed` in force, tracking needing the rate of
/// `speed` m/s: the evidence the core builds and the manager's answer for `version`.
fn published(
    state: &PlatformState,
    placed: &Schedule,
    speed: f64,
    vibration: f64,
    version: &str,
) -> Published {
    let model = model();
    let mut core = Core::new(
        Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    core.platform.platform = state.clone();
    core.platform.others_tiles = placed.placements.iter().map(|p| p.tiles.len() as u32).sum();
    core.platform.others_cpu = placed.placements.iter().map(|p| p.cpu_share).sum();
    let mut obs = Observations {
        state: "v0".into(),
        ..Default::default()
    };
    obs.set("target_speed_rel", speed);
    obs.set("vibration_mps2", vibration);
    obs.set("battery_pct", 90.0);
    let mut evidence = core.health_mdp.health.evidence(&obs);
    core.readings.read(&obs);
    let at = (&core.read_slots, &core.readings);
    (core.platform).platform_evidence(&model, &core.health_mdp.health, at, &mut evidence);
    let mut probs = BTreeMap::new();
    core.health_mdp
        .health
        .evaluate_into(&evidence, &mut probs)
        .expect("the core's evidence is consistent");
    let name = format!("P_{version}");
    let fit_node = format!("F_{version}");
    let p = probs[&name];
    let mut with = |state: &str| {
        let mut ev = evidence.clone();
        ev.insert(fit_node.clone(), state.into());
        let mut out = probs.clone();
        core.health_mdp
            .health
            .reevaluate_manager_into("resources", &ev, &mut out)
            .unwrap();
        out[&name]
    };
    Published {
        p,
        p_no: with("no"),
        p_yes: with("yes"),
        fit: evidence.get(&fit_node).cloned().unwrap_or_default(),
    }
}

fn platform(failed: u8, external: f64, cores_online: u8) -> PlatformState {
    let res = &model().resources;
    let mut state = PlatformState::new(&res.platform);
    for t in 0..failed {
        state.fail_tile(res.platform.tiles - 1 - t);
    }
    state.external_cpu_load = external;
    state.cores_online = cores_online;
    state
}

/// Complete-1 safety at "insufficient resources" (issue 24): three tiles failed, 0.40 external
/// load, 0.14 of the CPU taken by obstacle detection and the landing search, so 0.26 is left;
/// tracking needs 1.7 fps, at which V3 M (1 tile) fits in what is left. The bins saw headroom "0.2" and rate "1.85" and judged V3 unplaceable (P_V3 = 0.048).
#[test]
fn complete_1_shortage_keeps_v3_placeable() {
    let res = &model().resources;
    let state = platform(3, 0.40, 2);
    let speed = 1.7 * 0.25 * 1.155;
    let fps = res
        .required_fps("tracking", [0.0, 0.0], [speed, 0.0])
        .unwrap();
    assert!((fps - 1.7).abs() < 1e-9, "{fps}");
    // Occupy 0.14 of the CPU and no tile beside tracking, as the others did in the run.
    let (others, _) = res
        .schedule(
            "safety",
            &state,
            &others_of(5.0, Some(("emergency", 1.0)), false),
        )
        .unwrap();
    let others_cpu: f64 = others.placements.iter().map(|p| p.cpu_share).sum();
    let others_tiles: usize = others.placements.iter().map(|p| p.tiles.len()).sum();
    assert_eq!(others_tiles, 0, "{:?}", others.placements);
    let headroom = 0.8 - 0.40 - others_cpu;
    assert!((headroom - 0.26).abs() < 1e-9, "{headroom}");
    // The scheduler places V3 beside them.
    let mut reqs = others_of(5.0, Some(("emergency", 1.0)), false);
    reqs.push(Request::new("tracking", "V3", fps));
    let (both, _) = res.schedule("safety", &state, &reqs).unwrap();
    assert!(
        both.placements
            .iter()
            .any(|p| p.app == "tracking" && p.version == "V3"),
        "{both:?}"
    );
    let got = published(&state, &others, speed, 25.0, "V3");
    assert_eq!(got.p, got.p_yes, "P_V3 below its suitability");
    assert!(
        got.p > 10.0 * got.p_no,
        "P_V3 {} vs unplaceable {}",
        got.p,
        got.p_no
    );
    assert_eq!(got.fit, "yes");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(192))]

    /// Whenever the scheduler places Vi beside the other applications as they run (their
    /// placements unchanged), P_Vi is what it is with fit evidence `yes` (the applications
    /// manager's suitability times p_fit); whenever it cannot, P_Vi is the `no` value. So the
    /// fit node drives P_Vi down exactly when the scheduler cannot place Vi.
    #[test]
    fn p_vi_is_driven_down_only_when_the_scheduler_cannot_place_vi(
        failed in 0u8..=4,
        external in 0.0f64..0.8,
        cores_online in 1u8..=2,
        lidar_fps in 5.0f64..40.0,
        search in prop_oneof![
            Just(None),
            (0.5f64..6.0).prop_map(|f| Some(("emergency", f))),
            (0.5f64..6.0).prop_map(|f| Some(("zone_t", f))),
        ],
        avoid in any::<bool>(),
        speed in prop_oneof![0.0f64..2.0, 0.0f64..40.0],
        vibration in prop_oneof![Just(0.0), Just(25.0)],
        vi in 0usize..6,
    ) {
        let res = &model().resources;
        let version = format!("V{vi}");
        let state = platform(failed, external, cores_online);
        let reqs = others_of(lidar_fps, search, avoid);
        let (alone, _) = res.schedule("safety", &state, &reqs).unwrap();
        // The others as they run: all placed (what gave way is not in force).
        prop_assume!(alone.dropped.is_empty() && alone.degraded.is_empty());
        let fps = res.required_fps("tracking", [0.0, 0.0], [speed, 0.0]).unwrap();
        let mut with = reqs.clone();
        with.push(Request::new("tracking", &version, fps));
        let (both, _) = res.schedule("safety", &state, &with).unwrap();
        let same_others = alone.placements.iter().all(|a| {
            both.placements.iter().any(|b| {
                (b.app.as_str(), b.version.as_str(), b.implementation)
                    == (a.app.as_str(), a.version.as_str(), a.implementation)
            })
        });
        let placed = same_others
            && both.placements.iter().any(|p| p.app == "tracking" && p.version == version);
        let got = published(&state, &alone, speed, vibration, &version);
        if placed {
            prop_assert_eq!(got.p, got.p_yes, "P_{} driven down although placed", version);
            prop_assert_eq!(got.fit.as_str(), "yes");
        } else {
            prop_assert_eq!(got.p, got.p_no, "P_{} not driven down although not placed", version);
            prop_assert_eq!(got.fit.as_str(), "no");
        }
        prop_assert!(got.p_no <= got.p_yes);
    }
}
