use super::*;
use crate::arbitration::BehaviourConflicts;
use crate::record::Conflict;
use mdp_engine::Workspace;

/// The probability names the shipped health managers publish: what `Model::load` hands the MDPs,
/// read from params/health/ rather than copied here.
pub(super) static KNOWN: std::sync::LazyLock<Vec<&'static str>> = std::sync::LazyLock::new(|| {
    crate::health::HealthModel::load(&crate::shipped::params())
        .expect("params/health loads")
        .publishes()
        .into_iter()
        .map(|n| &*n.leak())
        .collect()
});

fn params() -> ParamsFiles {
    crate::shipped::params()
}

fn load_all() -> MissionMdps {
    MissionMdps::load(&params(), &KNOWN).expect("params/mdp loads")
}

/// Section 7.1 values (vibration context), written out here independently of index.toml; the
/// names 7.1 does not give are the health managers' own values in that context (P_V0, P_track,
/// P_crash, P_fusion: companion/tests/health_paper.rs).
fn paper_point() -> BTreeMap<String, f64> {
    [
        ("P_sys", 0.9),
        ("P_obs", 0.5),
        ("P_SI", 0.6),
        ("P_SF", 0.4),
        ("P_battery", 0.8),
        ("P_appT", 0.5),
        ("P_appZ", 0.4),
        ("P_detect", 0.8),
        ("P_V1", 0.37),
        ("P_V2", 0.05),
        ("P_V3", 0.96),
        ("P_V4", 0.31),
        ("P_V5", 0.47),
        ("P_V0", 0.096),
        ("P_track", 0.113),
        ("P_crash", 0.063),
        ("P_fusion", 0.98),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// Stage-0 decision (horizon 100, as in section 7) of MDP `name` in `state`, as its action name.
fn decide(
    all: &mut MissionMdps,
    name: &str,
    state: &str,
    probs: &BTreeMap<String, f64>,
    policy: &str,
) -> String {
    let m = all.get_mut(name).unwrap();
    let s = m
        .state_index(state)
        .unwrap_or_else(|| panic!("{name} has no state {state}"));
    let mdp = m.instantiate(probs, policy).unwrap();
    let mut ws = Workspace::new();
    let a = ws
        .finite_horizon(mdp, 100)
        .decision(s)
        .expect("non-terminal");
    m.action_name(a).to_string()
}

fn primitives_of(all: &MissionMdps, name: &str, action: &str) -> Vec<String> {
    let m = all.get(name).unwrap();
    m.primitives(m.action_index(action).unwrap()).to_vec()
}

#[test]
fn sizes_match_table_9() {
    let all = load_all();
    let size = |n: &str| {
        let m = all.get(n).unwrap();
        (m.n_states(), m.n_actions())
    };
    // Table 9, plus A0 (stay on the ground), an addition (docs/params/mdp.md).
    // section 5 / Table 9 (20 x 21) plus A0 and the concurrent models' action sets (issue 24 item 5)
    assert_eq!(size("monolithic"), (27, 49));
    assert_eq!(size("navigation"), (9, 9));
    assert_eq!(size("tracking"), (12, 10));
    // Table 9 says 9 states; the prose names 10 (documented deviation), 6 actions as in Table 9.
    assert_eq!(size("landing"), (10, 6));
    assert_eq!(size("reference"), (6, 5)); // Figure 1: S1..S6, A1..A5
    assert_eq!(all.concurrent(), ["navigation", "landing", "tracking"]);
    // The concurrent MDPs share the departure, waypoint and final states (section 6.1).
    for n in all.concurrent() {
        for s in ["base", "wp1", "wpi", "wpf", "landing"] {
            assert!(
                all.get(n).unwrap().state_index(s).is_some(),
                "{n} lacks {s}"
            );
        }
        assert_eq!(
            all.get(n)
                .unwrap()
                .state_name(all.get(n).unwrap().initial_state()),
            "base"
        );
    }
}

/// Tables 4-7 (both policies, vibration point of section 7.1): the action sets per mission state.
#[test]
fn decisions_follow_tables_4_to_7() {
    let mut all = load_all();
    let p = paper_point();
    for pol in ["safety", "mission"] {
        // Base: take-off, in every MDP.
        for n in ["navigation", "landing", "tracking", "monolithic"] {
            assert_eq!(decide(&mut all, n, "base", &p, pol), "A1", "{n} {pol}");
        }
        assert_eq!(decide(&mut all, "reference", "S1", &p, pol), "A1");
        // WayPoint 1: follow trajectory / obstacle detection (5 ms: LIDAR), no zone search yet.
        assert_eq!(
            decide(&mut all, "navigation", "wp1", &p, pol),
            "A2+A11",
            "{pol}"
        );
        assert_eq!(decide(&mut all, "landing", "wp1", &p, pol), "A2", "{pol}");
        assert_eq!(
            decide(&mut all, "monolithic", "wp1", &p, pol),
            "A2+A11",
            "{pol}"
        );
        // Intermediate waypoint: ... and search 'T' zone.
        assert_eq!(
            decide(&mut all, "navigation", "wpi", &p, pol),
            "A2+A11",
            "{pol}"
        );
        // After a lidar failure (P_obs 0.15, the BN's value) both turn to fusion on the way, from
        // a full battery to P_battery 0.7 (docs/params/mdp.md "Which detector").
        for pb in [0.7, 0.8, 0.99] {
            let mut failed = p.clone();
            failed.insert("P_obs".into(), 0.15);
            failed.insert("P_battery".into(), pb);
            assert_eq!(
                decide(&mut all, "navigation", "wpi", &failed, pol),
                "A2+A4",
                "{pol} {pb}"
            );
            assert_eq!(
                decide(&mut all, "monolithic", "wpi", &failed, pol),
                "A2+A4+A5",
                "{pol} {pb}"
            );
        }
        assert_eq!(decide(&mut all, "landing", "wpi", &p, pol), "A5", "{pol}");
        assert_eq!(decide(&mut all, "tracking", "wpi", &p, pol), "A2", "{pol}");
        assert_eq!(
            decide(&mut all, "monolithic", "wpi", &p, pol),
            "A2+A11+A5",
            "{pol}"
        );
        // Final waypoint: follow trajectory / obstacle detection, 'T' zone search, target detection.
        let mut union: Vec<String> = ["navigation", "landing", "tracking"]
            .iter()
            .flat_map(|n| {
                let a = decide(&mut all, n, "wpf", &p, pol);
                primitives_of(&all, n, &a)
            })
            .collect();
        union.sort();
        let mut expect = vec![
            "detect_obstacles_lidar",
            "detect_target",
            "follow_trajectory",
            "search_zone_t",
        ];
        expect.sort();
        assert_eq!(union, expect, "{pol}");
        let mono = decide(&mut all, "monolithic", "wpf", &p, pol);
        let mut mono_prims = primitives_of(&all, "monolithic", &mono);
        mono_prims.sort();
        assert_eq!(
            mono_prims, expect,
            "{pol}: the monolithic MDP takes the same decision"
        );
        // Tracking phase, vibrations: V3 (P_V3 = 0.96 is the best version), from the detection
        // state and from any running version (switch), with obstacle detection and T zone search.
        for s in ["target", "v0", "v1", "v3", "v5"] {
            let a = decide(&mut all, "tracking", s, &p, pol);
            assert_eq!(
                primitives_of(&all, "tracking", &a),
                ["track_v3"],
                "{s} {pol}"
            );
            let a = decide(&mut all, "monolithic", s, &p, pol);
            assert_eq!(
                primitives_of(&all, "monolithic", &a),
                ["track_v3", "detect_obstacles_lidar", "search_zone_t"],
                "{s} {pol}"
            );
        }
        // Obstacle detected: avoidance (both policies in Tables 4-7); the monolithic MDP keeps the
        // T zone search going ("V3 and obstacle avoidance and search T zone").
        assert_eq!(
            decide(&mut all, "navigation", "obstacle_detected", &p, pol),
            "A3",
            "{pol}"
        );
        assert_eq!(
            decide(&mut all, "monolithic", "obstacle_detected", &p, pol),
            "A3+A5",
            "{pol}"
        );
        // T zone not found: emergency area search (Table 4 tracking phase 2).
        assert_eq!(
            decide(&mut all, "landing", "zone_t_nok", &p, pol),
            "A6",
            "{pol}"
        );
    }
}

/// Tables 6-7 (high-speed target): the appropriate version is V2 (R.O.I. resizing). The BN values
/// for that context are not printed in the paper; any point where P_V2 is clearly the best will
/// do (assumption: V2 0.9, the stabilised versions poor without vibrations).
#[test]
fn high_speed_target_picks_v2() {
    let mut all = load_all();
    let mut p = paper_point();
    for (k, v) in [
        ("P_V0", 0.3),
        ("P_V1", 0.3),
        ("P_V2", 0.9),
        ("P_V3", 0.2),
        ("P_V4", 0.2),
        ("P_V5", 0.6),
    ] {
        p.insert(k.into(), v);
    }
    for pol in ["safety", "mission"] {
        for s in ["target", "v0", "v3"] {
            let a = decide(&mut all, "tracking", s, &p, pol);
            assert_eq!(
                primitives_of(&all, "tracking", &a),
                ["track_v2"],
                "{s} {pol}"
            );
        }
    }
}

/// Table 3 / section 7.2: with vibrations the reference (V0 only, P_track low) aborts while BFM
/// keeps tracking by switching version; in the nominal case the reference tracks too.
#[test]
fn reference_aborts_where_bfm_switches_version() {
    let mut all = load_all();
    let mut p = paper_point();
    p.insert("P_track".into(), 0.05);
    p.insert("P_V0".into(), 0.05);
    for pol in ["safety", "mission"] {
        assert_eq!(
            decide(&mut all, "reference", "S5", &p, pol),
            "A5",
            "{pol}: reference returns to base"
        );
        let a = decide(&mut all, "tracking", "v0", &p, pol);
        assert_eq!(
            primitives_of(&all, "tracking", &a),
            ["track_v3"],
            "{pol}: BFM switches V0 -> V3"
        );
    }
    // At the 7.1 point itself (P_track = P_V0 = 0.2, assumed) both policies already give up.
    for pol in ["safety", "mission"] {
        assert_eq!(
            decide(&mut all, "reference", "S5", &paper_point(), pol),
            "A5",
            "{pol}"
        );
    }
    let mut nominal = paper_point();
    nominal.insert("P_track".into(), 0.9);
    for pol in ["safety", "mission"] {
        assert_eq!(
            decide(&mut all, "reference", "S5", &nominal, pol),
            "A4",
            "{pol}: nominal reference tracks"
        );
        assert_eq!(
            decide(&mut all, "reference", "S4", &nominal, pol),
            "A3",
            "{pol}"
        );
    }
}

/// Table 8: the mission policy tracks at least as long as the safety policy. Over a grid of
/// battery levels and tracking qualities, whenever safety-first keeps tracking, so does
/// mission-first, in the tracking, monolithic and reference MDPs.
#[test]
fn mission_policy_tracks_whenever_safety_does() {
    let mut all = load_all();
    let mut safety_tracks = 0;
    let mut mission_only = 0;
    for b in 0..=10 {
        for q in 0..=10 {
            let mut p = paper_point();
            let (pb, pv) = (b as f64 / 10.0, q as f64 / 10.0);
            p.insert("P_battery".into(), pb);
            p.insert("P_sys".into(), 0.5 + 0.5 * pb);
            for v in ["P_V0", "P_V1", "P_V2", "P_V4", "P_V5"] {
                p.insert(v.into(), 0.0);
            }
            p.insert("P_V3".into(), pv);
            p.insert("P_track".into(), pv);
            for (mdp, state) in [
                ("tracking", "v3"),
                ("monolithic", "v3"),
                ("reference", "S5"),
            ] {
                let tracks = |all: &mut MissionMdps, pol: &str| {
                    let a = decide(all, mdp, state, &p, pol);
                    primitives_of(all, mdp, &a)
                        .iter()
                        .any(|x| x.starts_with("track_v"))
                };
                let s = tracks(&mut all, "safety");
                let m = tracks(&mut all, "mission");
                assert!(
                    !s || m,
                    "{mdp} P_battery={pb} P_V={pv}: safety tracks, mission does not"
                );
                safety_tracks += s as u32;
                mission_only += (m && !s) as u32;
            }
        }
    }
    // Not vacuous: both policies track somewhere, and mission tracks strictly more somewhere.
    assert!(
        safety_tracks > 0 && mission_only > 0,
        "{safety_tracks} {mission_only}"
    );
}

/// Safety-first heads home earlier as the battery drains: navigation returns to base from the
/// tracking area at a battery level (0.5) where mission-first still stays.
#[test]
fn low_battery_sends_safety_home_first() {
    let mut all = load_all();
    let mut p = paper_point();
    p.insert("P_battery".into(), 0.5);
    assert_eq!(decide(&mut all, "navigation", "wpf", &p, "safety"), "A10");
    assert_eq!(decide(&mut all, "navigation", "wpf", &p, "mission"), "A11");
    p.insert("P_battery".into(), 0.2);
    assert_eq!(decide(&mut all, "navigation", "wpf", &p, "mission"), "A10");
    // Mission-first lets tracking beat return_to_base in arbitration, so the tracking MDP itself
    // must give up with a nearly empty battery, even with the best version.
    p.insert("P_battery".into(), 0.05);
    for pol in ["safety", "mission"] {
        assert_eq!(decide(&mut all, "tracking", "v3", &p, pol), "A10", "{pol}");
        let a = decide(&mut all, "monolithic", "v3", &p, pol);
        assert_eq!(
            primitives_of(&all, "monolithic", &a),
            ["return_to_base"],
            "{pol}"
        );
    }
}

/// The models' honest way to stay on the ground (A0, an addition to the paper): a healthy vehicle
/// takes off, a battery belief near 0 (the guarantee's cap is 0.05) or a failing system stays.
#[test]
fn base_stays_on_the_ground_when_battery_or_system_is_failing() {
    let mut all = load_all();
    for pol in ["safety", "mission"] {
        for n in ["navigation", "monolithic"] {
            let mut p = paper_point();
            // A healthy start as the simulated world sees it at base.
            p.insert("P_battery".into(), 0.99);
            p.insert("P_sys".into(), 0.98);
            assert_eq!(
                decide(&mut all, n, "base", &p, pol),
                "A1",
                "{n} {pol} healthy"
            );
            for pb in [0.0, 0.05, 0.2] {
                p.insert("P_battery".into(), pb);
                assert_eq!(
                    decide(&mut all, n, "base", &p, pol),
                    "A0",
                    "{n} {pol} P_battery {pb}"
                );
            }
            p.insert("P_battery".into(), 0.99);
            for ps in [0.0, 0.05] {
                p.insert("P_sys".into(), ps);
                assert_eq!(
                    decide(&mut all, n, "base", &p, pol),
                    "A0",
                    "{n} {pol} P_sys {ps}"
                );
            }
        }
        assert_eq!(
            primitives_of(&all, "navigation", "A0"),
            ["stay_on_ground"],
            "{pol}"
        );
    }
}

/// Expected total reward over `horizon` steps from every state of the stationary policy `pi`
/// (one action index per state; terminal states ignored), by plain backward summation.
fn evaluate_stationary(mdp: &mdp_engine::Mdp, pi: &[Option<u32>], horizon: usize) -> Vec<f64> {
    let n = mdp.n_states();
    let mut v = vec![0.0; n];
    for _ in 0..horizon {
        let mut next = vec![0.0; n];
        for s in 0..n {
            let Some(a) = pi[s] else { continue };
            let c = mdp
                .choices(s as _)
                .find(|c| c.action as u32 == a)
                .expect("policy action available");
            next[s] = c.reward
                + c.next
                    .iter()
                    .zip(c.prob)
                    .map(|(t, p)| p * v[*t as usize])
                    .sum::<f64>();
        }
        v = next;
    }
    v
}

/// Exhaustive search over every stationary deterministic policy of `mdp`, each evaluated over the
/// 100-step horizon by direct summation from `start`: (best value, the best policy's action in
/// `start`, number of policies searched).
fn best_stationary(mdp: &mdp_engine::Mdp, start: usize) -> (f64, u32, usize) {
    let options: Vec<Vec<u32>> = (0..mdp.n_states())
        .map(|s| mdp.choices(s as _).map(|c| c.action as u32).collect())
        .collect();
    let mut pi: Vec<Option<u32>> = options.iter().map(|o| o.first().copied()).collect();
    let mut idx = vec![0usize; options.len()];
    let (mut best, mut best_first, mut count) = (f64::NEG_INFINITY, 0u32, 0);
    loop {
        count += 1;
        let v = evaluate_stationary(mdp, &pi, 100)[start];
        if v > best {
            best = v;
            best_first = pi[start].unwrap();
        }
        // Next policy: odometer over every state's available actions.
        let mut s = 0;
        loop {
            if s == options.len() {
                break;
            }
            if options[s].is_empty() {
                s += 1;
                continue;
            }
            idx[s] += 1;
            if idx[s] < options[s].len() {
                pi[s] = Some(options[s][idx[s]]);
                break;
            }
            idx[s] = 0;
            pi[s] = Some(options[s][0]);
            s += 1;
        }
        if s == options.len() {
            break;
        }
    }
    (best, best_first, count)
}

/// Independent answer for the base decision: exhaustive search over every stationary
/// deterministic policy of the navigation MDP (2,160 of them), each evaluated over the 100-step
/// horizon by direct summation. At a low battery the best policy stays on the ground, at a high
/// one it takes off, and the engine's finite-horizon decision agrees; its stage-0 value is at
/// least the best stationary one (a time-dependent policy can only do better: near the end of
/// the horizon a short hop home pays more than staying).
#[test]
fn base_decision_matches_exhaustive_policy_search() {
    let mut all = load_all();
    for pol in ["safety", "mission"] {
        for (pb, want) in [(0.02, "A0"), (0.3, "A0"), (0.95, "A1")] {
            let mut p = paper_point();
            p.insert("P_battery".into(), pb);
            p.insert("P_sys".into(), 0.98);
            let m = all.get_mut("navigation").unwrap();
            let base = m.state_index("base").unwrap();
            let mdp = m.instantiate(&p, pol).unwrap().clone();
            let (best, best_first, count) = best_stationary(&mdp, base);
            assert_eq!(count, 2160, "every stationary policy searched");
            assert_eq!(
                m.action_name(best_first as usize),
                want,
                "{pol} P_battery {pb}"
            );
            let mut ws = Workspace::new();
            let fh = ws.finite_horizon(&mdp, 100);
            assert_eq!(
                m.action_name(fh.decision(base as _).unwrap()),
                want,
                "{pol} P_battery {pb}: engine"
            );
            let engine = fh.value(0, base as _);
            assert!(engine >= best - 1e-9, "{pol} {pb}: {engine} < {best}");
        }
    }
}

/// The detectors' health turns the vehicle (issue 24 item 2), checked by brute force: with the
/// sensors BN's values for a failed lidar (P_obs 0.145, P_fusion 0.98, as the lidar-failure run
/// records them) the best of all 2,160 stationary navigation policies detects obstacles by fusion
/// between the waypoints and over the area, and with a healthy lidar (P_obs 0.79) by lidar; the
/// engine's decision agrees in each case. No projection is involved: the MDP is asked in its
/// route states.
#[test]
fn detector_health_picks_the_detector_by_exhaustive_policy_search() {
    let mut all = load_all();
    for pol in ["safety", "mission"] {
        for (p_obs, wpi_want, wpf_want) in [(0.145, "A2+A4", "A4"), (0.79, "A2+A11", "A11")] {
            let mut p = paper_point();
            p.insert("P_battery".into(), 0.99);
            p.insert("P_sys".into(), 0.98);
            p.insert("P_obs".into(), p_obs);
            let m = all.get_mut("navigation").unwrap();
            let mdp = m.instantiate(&p, pol).unwrap().clone();
            for (state, want) in [("wpi", wpi_want), ("wpf", wpf_want)] {
                let s = m.state_index(state).unwrap();
                let (_, best_first, _) = best_stationary(&mdp, s);
                assert_eq!(
                    m.action_name(best_first as usize),
                    want,
                    "{pol} P_obs {p_obs} {state}: exhaustive"
                );
                let mut ws = Workspace::new();
                let fh = ws.finite_horizon(&mdp, 100);
                assert_eq!(
                    m.action_name(fh.decision(s as _).unwrap()),
                    want,
                    "{pol} P_obs {p_obs} {state}: engine"
                );
            }
        }
    }
}

/// In-place instantiation against hand computation, including the folded enter rewards.
#[test]
fn instantiate_fills_probabilities_and_rewards() {
    let mut all = load_all();
    let p = paper_point();
    let m = all.get_mut("navigation").unwrap();
    let (od, a11, coll, avoid) = (
        m.state_index("obstacle_detected").unwrap(),
        m.action_index("A11").unwrap(),
        m.state_index("collision").unwrap(),
        m.state_index("wp_avoid").unwrap(),
    );
    let mdp = m.instantiate(&p, "safety").unwrap();
    let c = mdp.choices(od).find(|c| c.action == a11).unwrap();
    let prob_of = |s: usize| {
        c.next
            .iter()
            .position(|n| *n as usize == s)
            .map(|i| c.prob[i])
            .unwrap()
    };
    assert_eq!(prob_of(coll), 0.5);
    assert_eq!(prob_of(avoid), 0.5);
    // R = (2 - 5 * (1 - 0.8)) + 0.5 * (-100)
    assert!(
        (c.reward - (2.0 - 5.0 * 0.2 - 50.0)).abs() < 1e-12,
        "{}",
        c.reward
    );
    // Re-instantiate with other values: same storage, new numbers.
    let mut q = p.clone();
    q.insert("P_obs".into(), 0.9);
    let mdp = m.instantiate(&q, "mission").unwrap();
    let c = mdp.choices(od).find(|c| c.action == a11).unwrap();
    assert!((c.reward - (2.0 - 3.0 * 0.2 - 90.0)).abs() < 1e-12);
    let wpi = m.state_index("wpi").unwrap();
    let (wpf, act) = (
        m.state_index("wpf").unwrap(),
        m.action_index("A2+A11").unwrap(),
    );
    let mdp = m.mdp();
    let c = mdp.choices(wpi).find(|c| c.action == act).unwrap();
    let i = c.next.iter().position(|n| *n as usize == wpf).unwrap();
    // Lidar flight at P_obs 0.9: 0.1 * 0.9 detected, 0.015 * 0.1 missed and hit, the rest flies on.
    assert!((c.prob[i] - (1.0 - 0.1 * 0.9 - 0.015 * 0.1) * 0.8 * 0.9 * 0.4).abs() < 1e-12);
}

#[test]
fn decide_and_proposal() {
    let mut all = load_all();
    let p = paper_point();
    let m = all.get_mut("navigation").unwrap();
    let mut ws = Workspace::new();
    let wpi = m.state_index("wpi").unwrap();
    let d = m.decide(&mut ws, wpi, &p, "safety", 100).unwrap().unwrap();
    let rec = m.proposal(wpi, &d, 100);
    assert_eq!(rec.mdp, "navigation");
    assert_eq!(rec.state, "wpi");
    assert_eq!(rec.action, "A2+A11");
    assert_eq!(rec.actions, ["follow_trajectory", "detect_obstacles_lidar"]);
    // The horizon solved for, and the stages the solver computed (issue 24 item 6: Table 9
    // compares iteration counts), as an independent solve of the same instance reports them.
    assert_eq!(rec.horizon, 100);
    let mdp = m.instantiate(&p, "safety").unwrap().clone();
    let mut ws2 = Workspace::new();
    let stages = ws2.finite_horizon(&mdp, 100).stats().iterations;
    assert_eq!(rec.iterations, stages);
    assert!(rec.iterations >= 1 && rec.iterations <= 100);
    assert!(rec.value > 0.0);
    let landing = m.state_index("landing").unwrap();
    assert_eq!(m.decide(&mut ws, landing, &p, "safety", 100).unwrap(), None);
}

#[test]
fn instantiate_rejects_bad_probabilities() {
    let mut all = load_all();
    let m = all.get_mut("tracking").unwrap();
    let mut p = paper_point();
    assert_eq!(
        m.instantiate(&p, "reckless").unwrap_err(),
        InstantiateError::UnknownPolicy("reckless".into())
    );
    p.insert("P_V3".into(), 1.5);
    assert!(matches!(
        m.instantiate(&p, "safety"),
        Err(InstantiateError::BadProbability { .. })
    ));
    p.insert("P_V3".into(), f64::NAN);
    assert!(matches!(
        m.instantiate(&p, "safety"),
        Err(InstantiateError::BadProbability { .. })
    ));
    p.remove("P_V3");
    assert_eq!(
        m.instantiate(&p, "safety").unwrap_err(),
        InstantiateError::MissingProbability("P_V3".into())
    );
}

// ------------------------------------------------------------------ loader errors

const GOOD: &str = r#"
name = "tiny"
initial = "base"
states = ["base", "wp1", "landing"]
[[action]]
name = "A1"
does = ["take_off"]
[[action]]
name = "A10"
does = ["return_to_base"]
[transitions.base]
A1 = { wp1 = "P_sys", base = "1 - P_sys" }
[transitions.wp1]
A10 = { landing = "P_sys", wp1 = "1 - P_sys" }
[reward.safety.action]
A1 = 1
A10 = "2 * P_sys"
[reward.safety.enter]
landing = 5
"#;

/// Write an index listing `tiny` plus the given file text; load; return the error.
fn load_text(text: &str) -> Result<MissionMdps, SpecError> {
    let mut dir = ParamsFiles::new("t");
    dir.insert(
        dir.dir().join("mdp/index.toml"),
        "concurrent = [\"tiny\"]\n[check_point]\nP_sys = 0.9\n",
    );
    dir.insert(dir.dir().join("mdp/tiny.toml"), text);
    MissionMdps::load(&dir, &KNOWN)
}

fn load_err(text: &str) -> SpecError {
    let e = load_text(text).expect_err("should be rejected");
    assert!(e.file.ends_with("tiny.toml"), "{e}");
    e
}

#[test]
fn good_tiny_file_loads() {
    let mut all = load_text(GOOD).unwrap();
    let m = all.get_mut("tiny").unwrap();
    assert_eq!(m.probability_names(), ["P_sys"]);
    let p: BTreeMap<String, f64> = [("P_sys".to_string(), 0.5)].into();
    let mdp = m.instantiate(&p, "safety").unwrap();
    // R(wp1, A10) = 2 * 0.5 + 0.5 * 5
    let c = mdp.choices(1).next().unwrap();
    assert_eq!(c.reward, 3.5);
}

#[test]
fn rejects_row_not_summing_to_one() {
    // Sums to 1 at P_sys = 0.5 only: caught at the all-0 corner.
    let e = load_err(&GOOD.replace(r#"base = "1 - P_sys""#, r#"base = "0.5""#));
    assert_eq!(e.entry, "transitions.base.\"A1\"");
    assert!(e.reason.contains("sum to"), "{e}");
    // Sums to 1 at both corners but not in between: caught at a random point.
    let e = load_err(
        &GOOD
            .replace(r#"base = "1 - P_sys""#, r#"base = "1 - P_sys * P_sys""#)
            .replace(r#"wp1 = "P_sys""#, r#"wp1 = "P_sys * P_sys * P_sys""#),
    );
    assert!(
        e.reason.contains("sum to") && !e.reason.contains("all probabilities"),
        "{e}"
    );
}

#[test]
fn rejects_probability_outside_unit_interval() {
    let e = load_err(&GOOD.replace(
        r#"{ wp1 = "P_sys", base = "1 - P_sys" }"#,
        r#"{ wp1 = "2 * P_sys", base = "1 - 2 * P_sys" }"#,
    ));
    assert!(e.entry.starts_with("transitions.base.\"A1\"."), "{e}");
    assert!(e.reason.contains("outside [0, 1]"), "{e}");
}

#[test]
fn rejects_unknown_probability_name() {
    let e = load_err(&GOOD.replace(r#"wp1 = "P_sys""#, r#"wp1 = "P_sis""#));
    assert_eq!(e.entry, "transitions.base.\"A1\".wp1");
    assert!(e.reason.contains("P_sis"), "{e}");
    let e = load_err(&GOOD.replace(r#"A10 = "2 * P_sys""#, r#"A10 = "2 * P_fuel""#));
    assert_eq!(e.entry, "reward.safety.action.\"A10\"");
}

#[test]
fn rejects_unknown_state_and_action_names() {
    let e = load_err(&GOOD.replace(r#"{ landing = "P_sys""#, r#"{ landed = "P_sys""#));
    assert_eq!(e.entry, "transitions.wp1.\"A10\".landed");
    let e = load_err(&GOOD.replace("[transitions.wp1]", "[transitions.wp9]"));
    assert_eq!(e.entry, "transitions.wp9");
    let e = load_err(&GOOD.replace("[transitions.wp1]\nA10", "[transitions.wp1]\nA11"));
    assert_eq!(e.entry, "transitions.wp1.\"A11\"");
    let e = load_err(&GOOD.replace(r#"initial = "base""#, r#"initial = "home""#));
    assert_eq!(e.entry, "initial");
    let e = load_err(&GOOD.replace(
        "[reward.safety.enter]\nlanding",
        "[reward.safety.enter]\nlanded",
    ));
    assert_eq!(e.entry, "reward.safety.enter.landed");
}

#[test]
fn rejects_unreachable_state() {
    let e = load_err(&GOOD.replace(
        r#"states = ["base", "wp1", "landing"]"#,
        r#"states = ["base", "wp1", "landing", "island"]"#,
    ));
    assert_eq!(e.entry, "states[3]");
    assert!(e.reason.contains("unreachable"), "{e}");
}

#[test]
fn rejects_action_without_transition() {
    let e = load_err(&GOOD.replace(
        r#"A10 = { landing = "P_sys", wp1 = "1 - P_sys" }"#,
        "A10 = {}",
    ));
    assert_eq!(e.entry, "transitions.wp1.\"A10\"");
    assert!(e.reason.contains("no transition"), "{e}");
}

#[test]
fn rejects_bad_rewards_and_actions() {
    let e = load_err(&GOOD.replace("A10 = \"2 * P_sys\"\n", ""));
    assert_eq!(e.entry, "reward.safety.action");
    assert!(e.reason.contains("A10"), "{e}");
    let e = load_err(&GOOD.replace("A1 = 1\n", "A1 = 1\nA7 = 0\n"));
    assert_eq!(e.entry, "reward.safety.action.\"A7\"");
    let e = load_err(&GOOD.replace(r#"does = ["take_off"]"#, "does = []"));
    assert_eq!(e.entry, "action[0].does");
    let e = load_err(&GOOD.replace(r#"name = "A10""#, r#"name = "A1""#));
    assert_eq!(e.entry, "action[1].name");
    let e = load_err(&GOOD.replace(
        r#"states = ["base", "wp1", "landing"]"#,
        r#"states = ["base", "wp1", "landing", "wp1"]"#,
    ));
    assert_eq!(e.entry, "states[3]");
    let e = load_err(&GOOD.replace(r#"A1 = { wp1 = "P_sys""#, r#"A1 = { wp1 = "P_sys *""#));
    assert_eq!(e.entry, "transitions.base.\"A1\".wp1");
    let e = load_err(&GOOD.replace(r#"name = "tiny""#, r#"name = "small""#));
    assert_eq!(e.entry, "name");
    let e = load_err(&GOOD.replace("[[action]]\nname = \"A1\"", "[[action]]\nnmae = \"A1\""));
    assert!(e.entry.starts_with("line"), "{e}");
}

#[test]
fn rejects_policy_sets_that_differ_between_mdps() {
    let mut dir = ParamsFiles::new("t");
    dir.insert(
        dir.dir().join("mdp/index.toml"),
        "concurrent = [\"tiny\", \"other\"]\n",
    );
    dir.insert(dir.dir().join("mdp/tiny.toml"), GOOD);
    dir.insert(
        dir.dir().join("mdp/other.toml"),
        GOOD.replace(r#"name = "tiny""#, r#"name = "other""#)
            .replace("reward.safety", "reward.mission"),
    );
    let e = MissionMdps::load(&dir, &KNOWN).unwrap_err();
    assert!(e.file.ends_with("other.toml") && e.entry == "reward", "{e}");
    let e = MissionMdps::load(&ParamsFiles::new("/nonexistent"), &KNOWN).unwrap_err();
    assert!(e.reason.contains("cannot read"), "{e}");
}

#[test]
fn rejects_bad_check_point() {
    let mut dir = ParamsFiles::new("t");
    dir.insert(dir.dir().join("mdp/tiny.toml"), GOOD);
    dir.insert(
        dir.dir().join("mdp/index.toml"),
        "concurrent = [\"tiny\"]\n[check_point]\nP_nope = 0.5\n",
    );
    assert_eq!(
        MissionMdps::load(&dir, &KNOWN).unwrap_err().entry,
        "check_point.P_nope"
    );
    dir.insert(
        dir.dir().join("mdp/index.toml"),
        "concurrent = [\"tiny\"]\n[check_point]\nP_sys = 1.5\n",
    );
    assert_eq!(
        MissionMdps::load(&dir, &KNOWN).unwrap_err().entry,
        "check_point.P_sys"
    );
}

// ------------------------------------------------------------------ behaviour conflicts

fn conflicts() -> BehaviourConflicts {
    let all = load_all();
    let prims = all.primitive_actions();
    let known: Vec<&str> = prims.iter().map(String::as_str).collect();
    let p = params();
    BehaviourConflicts::load(&p, &p.dir().join("policies.toml"), &known)
        .expect("policies.toml loads")
}

#[test]
fn section_6_2_conflicts_by_policy() {
    let c = conflicts();
    // Table 4 tracking phase 1 -> 2 (safety): avoidance wins, V3 deactivated.
    let proposed = [
        "track_v3",
        "detect_obstacles_lidar",
        "avoid_obstacle",
        "search_zone_t",
    ];
    let (kept, why) = c.resolve(&proposed, "safety").unwrap();
    assert_eq!(
        kept,
        ["detect_obstacles_lidar", "avoid_obstacle", "search_zone_t"]
    );
    assert_eq!(
        why,
        [Conflict {
            kept: ["avoid_obstacle"].into_iter().collect(),
            dropped: ["track_v3"].into_iter().collect(),
            rule: "avoidance_vs_tracking".into()
        }]
    );
    // Tables 5 and 7 (mission): avoidance still wins.
    let (kept, _) = c.resolve(&proposed, "mission").unwrap();
    assert!(!kept.contains(&"track_v3".to_string()));
    // Return to base versus tracking: safety returns, mission keeps tracking.
    let (kept, _) = c
        .resolve(&["track_v2", "return_to_base"], "safety")
        .unwrap();
    assert_eq!(kept, ["return_to_base"]);
    let (kept, why) = c
        .resolve(&["track_v2", "return_to_base"], "mission")
        .unwrap();
    assert_eq!(kept, ["track_v2"]);
    assert_eq!(why[0].rule, "return_vs_tracking");
    assert_eq!(why[0].dropped, ["return_to_base"]);
    // Landing versus tracking, and versus returning home.
    let (kept, _) = c.resolve(&["land", "track_v3"], "safety").unwrap();
    assert_eq!(kept, ["land"]);
    let (kept, _) = c
        .resolve(&["replan_and_land", "track_v3"], "mission")
        .unwrap();
    assert_eq!(kept, ["track_v3"]);
    for pol in ["safety", "mission"] {
        let (kept, why) = c.resolve(&["return_to_base", "land"], pol).unwrap();
        assert_eq!(kept, ["land"], "{pol}");
        assert_eq!(why.len(), 1);
        // No antagonism, nothing changes.
        let quiet = [
            "follow_trajectory",
            "detect_obstacles_lidar",
            "search_zone_t",
            "detect_target",
        ];
        let (kept, why) = c.resolve(&quiet, pol).unwrap();
        assert_eq!(kept, quiet);
        assert!(why.is_empty());
    }
    // Staying on the ground (an addition) beats another MDP's take-off under every policy.
    for pol in ["safety", "mission"] {
        let (kept, why) = c.resolve(&["stay_on_ground", "take_off"], pol).unwrap();
        assert_eq!(kept, ["stay_on_ground"], "{pol}");
        assert_eq!(why[0].rule, "ground_vs_take_off");
    }
    assert!(c.resolve(&["land"], "reckless").is_err());
}

fn policies_err(text: &str) -> SpecError {
    let mut dir = ParamsFiles::new("t");
    let path = dir.dir().join("policies.toml");
    dir.insert(&path, text);
    let known = [
        "avoid_obstacle",
        "track_v0",
        "track_v1",
        "land",
        "return_to_base",
    ];
    BehaviourConflicts::load(&dir, &path, &known).expect_err("should be rejected")
}

const GOOD_POLICIES: &str = r#"
[[antagonistic]]
name = "avoidance_vs_tracking"
a = ["avoid_obstacle"]
b = ["track_v*"]
[priority]
safety = ["avoid_obstacle", "track_v*"]
mission = ["track_v*", "avoid_obstacle"]
"#;

#[test]
fn policies_loader_rejects_bad_rules() {
    let mut dir = ParamsFiles::new("t");
    let path = dir.dir().join("policies.toml");
    dir.insert(&path, GOOD_POLICIES);
    let c = BehaviourConflicts::load(&dir, &path, &["avoid_obstacle", "track_v0"]).unwrap();
    let (kept, _) = c
        .resolve(&["track_v0", "avoid_obstacle"], "mission")
        .unwrap();
    assert_eq!(kept, ["track_v0"]);

    let e = policies_err(&GOOD_POLICIES.replace(r#"b = ["track_v*"]"#, r#"b = ["track_x*"]"#));
    assert_eq!(e.entry, "antagonistic[0].b[0]");
    let e = policies_err(&GOOD_POLICIES.replace(
        r#"mission = ["track_v*", "avoid_obstacle"]"#,
        r#"mission = ["track_v*"]"#,
    ));
    assert_eq!(e.entry, "priority.mission");
    let e = policies_err(&GOOD_POLICIES.replace(r#"a = ["avoid_obstacle"]"#, "a = []"));
    assert_eq!(e.entry, "antagonistic[0].a");
    let e =
        policies_err(&GOOD_POLICIES.replace(r#"a = ["avoid_obstacle"]"#, r#"a = ["track_v*"]"#));
    assert_eq!(e.entry, "antagonistic[0]");
    let e = policies_err(&format!(
        "{}\n{}",
        GOOD_POLICIES.split("[priority]").next().unwrap(),
        GOOD_POLICIES
    ));
    assert_eq!(e.entry, "antagonistic[1].name");
    let e = policies_err(&GOOD_POLICIES.replace(
        r#"safety = ["avoid_obstacle", "track_v*"]"#,
        r#"safety = ["avoid_obstacle", "track_v*", "land", "land"]"#,
    ));
    assert_eq!(e.entry, "priority.safety[3]");
    let e = policies_err(&GOOD_POLICIES.replace(
        r#"safety = ["avoid_obstacle", "track_v*"]"#,
        r#"safety = ["avoid_obstacle", "track_v*", "fly"]"#,
    ));
    assert_eq!(e.entry, "priority.safety[2]");
}

// ---------------------------------------------------------------- fast-cycle equivalences

mod fast_cycle {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// `resolve_into` into buffers left over from an earlier call gives exactly what the
        /// original list-building resolution gives, for any subset of the primitive actions.
        #[test]
        fn resolve_into_equals_reference(
            picks in proptest::collection::vec(proptest::collection::vec(any::<bool>(), 32), 1..6),
        ) {
            let c = conflicts();
            let all = load_all().primitive_actions();
            let (mut kept, mut why) = (Vec::new(), Vec::new());
            for pick in &picks {
                let acts: Vec<&str> = all
                    .iter()
                    .zip(pick)
                    .filter(|(_, p)| **p)
                    .map(|(a, _)| a.as_str())
                    .collect();
                for pol in ["safety", "mission"] {
                    let (want_kept, want_why) = c.resolve_reference(&acts, pol).unwrap();
                    c.resolve_into(&acts, pol, &mut kept, &mut why).unwrap();
                    prop_assert_eq!(&kept, &want_kept);
                    prop_assert_eq!(&why, &want_why);
                }
            }
        }

        /// The decision memo returns exactly what a fresh instantiate + solve returns, for a
        /// sequence of probability points with repeats (hits) and changes (misses), every MDP,
        /// both policies, every state.
        #[test]
        fn memoised_decide_equals_fresh_solve(
            points in proptest::collection::vec((0usize..3, proptest::collection::vec(0.0f64..=1.0, KNOWN.len())), 1..6),
        ) {
            let mut memo = load_all();
            let mut fresh = load_all();
            let (mut ws, mut ws2) = (Workspace::new(), Workspace::new());
            let pts: Vec<BTreeMap<String, f64>> = points
                .iter()
                .map(|(_, v)| KNOWN.iter().zip(v).map(|(k, x)| (k.to_string(), *x)).collect())
                .collect();
            let names: Vec<String> = memo.all().iter().map(|m| m.name().to_string()).collect();
            for (i, (repeat, _)) in points.iter().enumerate() {
                // Revisit an earlier point now and then: the memo must only hit on exact inputs.
                let p = &pts[i.saturating_sub(*repeat)];
                for n in &names {
                    for pol in ["safety", "mission"] {
                        let b = fresh.get_mut(n).unwrap();
                        let fh = ws2.finite_horizon(b.instantiate(p, pol).unwrap(), 100);
                        let a = memo.get_mut(n).unwrap();
                        for s in 0..a.n_states() {
                            let got = a.decide(&mut ws, s, p, pol, 100).unwrap();
                            let want = fh.decision(s).map(|action| Decision {
                                action,
                                value: fh.value(0, s),
                                iterations: fh.stats().iterations,
                            });
                            prop_assert_eq!(got.map(|d| d.action), want.map(|d| d.action));
                            prop_assert_eq!(
                                got.map(|d| d.value.to_bits()),
                                want.map(|d| d.value.to_bits())
                            );
                        }
                    }
                }
            }
        }
    }

    /// A repeated input is served by the memo (no new solve); any change re-solves.
    #[test]
    fn memo_hits_only_on_identical_inputs() {
        let mut all = load_all();
        let mut ws = Workspace::new();
        let mut p = paper_point();
        let m = all.get_mut("tracking").unwrap();
        let s = m.state_index("v3").unwrap();
        let first = m.decide(&mut ws, s, &p, "safety", 100).unwrap();
        assert_eq!(m.solves(), 1);
        // Another state of the same model, same inputs: still the same solve.
        m.decide(&mut ws, 0, &p, "safety", 100).unwrap();
        assert_eq!(m.solves(), 1);
        assert_eq!(m.decide(&mut ws, s, &p, "safety", 100).unwrap(), first);
        assert_eq!(m.solves(), 1);
        m.decide(&mut ws, s, &p, "mission", 100).unwrap();
        assert_eq!(m.solves(), 2, "policy change re-solves");
        m.decide(&mut ws, s, &p, "mission", 99).unwrap();
        assert_eq!(m.solves(), 3, "horizon change re-solves");
        let v3 = p.get_mut("P_V3").unwrap();
        *v3 = f64::from_bits(v3.to_bits() + 1); // one ulp
        m.decide(&mut ws, s, &p, "mission", 99).unwrap();
        assert_eq!(m.solves(), 4, "a one-ulp change re-solves");
    }

    /// Inputs flapping between a few points (evidence across a threshold) are solved once each,
    /// and every answer is the one a fresh solve gives; a fifth point evicts the oldest.
    #[test]
    fn memo_remembers_recent_input_points() {
        let mut all = load_all();
        let mut fresh = load_all();
        fresh.set_solve_cache(false);
        let mut ws = Workspace::new();
        let base = paper_point();
        let point = |k: u64| {
            let mut p = base.clone();
            let v3 = p.get_mut("P_V3").unwrap();
            *v3 = f64::from_bits(v3.to_bits() - k); // k ulps below
            p
        };
        let m = all.get_mut("tracking").unwrap();
        let f = fresh.get_mut("tracking").unwrap();
        let s = m.state_index("v3").unwrap();
        for round in 0..3 {
            for k in 0..4 {
                let p = point(k);
                let got = m.decide(&mut ws, s, &p, "safety", 100).unwrap();
                let want = f.decide(&mut ws, s, &p, "safety", 100).unwrap();
                assert_eq!(
                    got.map(|d| (d.action, d.value.to_bits())),
                    want.map(|d| (d.action, d.value.to_bits()))
                );
                assert_eq!(
                    m.solves(),
                    4.min(round * 4 + k + 1),
                    "round {round} point {k}"
                );
            }
        }
        m.decide(&mut ws, s, &point(4), "safety", 100).unwrap();
        assert_eq!(m.solves(), 5, "a fifth point is solved");
        m.decide(&mut ws, s, &point(0), "safety", 100).unwrap();
        assert_eq!(m.solves(), 6, "the oldest point was evicted");
        m.decide(&mut ws, s, &point(4), "safety", 100).unwrap();
        assert_eq!(m.solves(), 6);
    }
}

/// Proposals record the stages the solver computed beside the horizon: where the certified
/// early stop settles before the horizon (the landing and tracking MDPs in flight), the two differ.
#[test]
fn proposal_records_solver_stages_beside_the_horizon() {
    let mut all = load_all();
    let mut p = paper_point();
    p.insert("P_battery".into(), 0.99);
    p.insert("P_sys".into(), 0.98);
    let mut ws = Workspace::new();
    let mut fewer = 0;
    for name in ["landing", "tracking"] {
        let m = all.get_mut(name).unwrap();
        let s = m.state_index("wp1").unwrap();
        let d = m.decide(&mut ws, s, &p, "safety", 100).unwrap().unwrap();
        let rec = m.proposal(s, &d, 100);
        assert_eq!(rec.horizon, 100, "{name}");
        let mdp = m.instantiate(&p, "safety").unwrap().clone();
        let mut ws2 = Workspace::new();
        assert_eq!(
            rec.iterations,
            ws2.finite_horizon(&mdp, 100).stats().iterations,
            "{name}"
        );
        if rec.iterations < rec.horizon {
            fewer += 1;
        }
    }
    assert!(fewer > 0, "no MDP stopped before the horizon");
}

/// Reading the probabilities by slot (the cycle's only path) decides as the by-name edge the
/// paper tests use: the same decision, value and iterations in every state of every concurrent
/// MDP and the monolithic one, over random probabilities; and the same error, naming the
/// probability, when one is missing or out of range.
#[test]
fn decide_by_slot_equals_decide_by_name() {
    let mut by_name = load_all();
    let mut by_slot = load_all();
    let mut names: Vec<String> = KNOWN.iter().map(|s| s.to_string()).collect();
    names.sort();
    let mut seed: u64 = 7;
    let mut next = move || {
        seed = seed
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mdps: Vec<String> = by_name
        .concurrent()
        .iter()
        .cloned()
        .chain(by_name.monolithic().map(str::to_string))
        .collect();
    assert!(mdps.len() >= 4, "{mdps:?}");
    let (mut ws_a, mut ws_b) = (Workspace::new(), Workspace::new());
    for round in 0..30 {
        let mut probs: BTreeMap<String, f64> = names.iter().map(|n| (n.clone(), next())).collect();
        // Now and then a probability missing or out of range: both paths must refuse alike.
        let broken = match round % 10 {
            3 => probs.remove(&names[round % names.len()]).map(|_| ()),
            7 => probs
                .insert(names[round % names.len()].clone(), 1.5)
                .map(|_| ()),
            _ => None,
        };
        let values: Vec<Option<f64>> = names.iter().map(|n| probs.get(n).copied()).collect();
        for name in &mdps {
            let a = by_name.get_mut(name).unwrap();
            let b = by_slot.get_mut(name).unwrap();
            let pi = a.policy_index("safety").unwrap();
            let slots = b.slots_in(&names);
            for s in 0..a.states().len() {
                let want = a.decide(&mut ws_a, s, &probs, "safety", 100);
                let got = b.decide_slots(&mut ws_b, s, &values, &slots, pi, 100);
                assert_eq!(
                    got, want,
                    "round {round} {name} state {s} (broken: {broken:?})"
                );
            }
        }
    }
}
