//! The PANORAMA patrolling mission (Tables 1, 3, 4, 5) against the paper's published figures, and
//! its in-flight re-allocations in the shape of Table 7.

use companion_core::guarantee::*;
use companion_core::report::guarantee::*;
use std::path::Path;

fn params() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../params"))
}

fn files() -> companion_core::spec::ParamsFiles {
    companion::params::read_params_dir(params()).unwrap()
}

fn spec() -> MissionSpec {
    load_mission(&files(), "patrolling").unwrap()
}

#[test]
fn nga_matches_the_paper_exactly() {
    // Section 7.2.1: NGA ~ 7.7e14; Table 5 n_IA row: 21 12 4 3 2 3 12 21 21 4 3 2 3 21 21 12 21.
    let s = spec();
    let counts: Vec<usize> = s.problem.activities.iter().map(|a| a.ias.len()).collect();
    assert_eq!(
        counts,
        vec![21, 12, 4, 3, 2, 3, 12, 21, 21, 4, 3, 2, 3, 21, 21, 12, 21]
    );
    assert_eq!(panorama::nga(&s.problem), Some(768_288_795_144_192));
    let j = check_json(&files(), "patrolling").unwrap();
    assert_eq!(j["guarantee"]["nga"].as_u64(), Some(768_288_795_144_192));
}

#[test]
fn ras0_is_table_6() {
    let s = spec();
    let r = Guarantee::pre_flight(&s).unwrap();
    let names: Vec<&str> = r
        .choice
        .iter()
        .enumerate()
        .map(|(j, &i)| s.problem.activities[j].ias[i].name.as_str())
        .collect();
    // PANORAMA Table 6, RAS0 row.
    let table6 = [
        "M5 L2", "M5 L2", "M5 L2", "T1 L2", "D2", "T1 L2", "M5 L2", "M5 L2", "M5 L2", "M5 L2",
        "T1 L2", "D2", "T1 L2", "M5 L2", "M5 L2", "M5 L2", "M3 L1",
    ];
    assert_eq!(names, table6);
    // Table 6's speed row: 0.41 .33 .33 - - - .33 .41 .41 .41 - - - .41 .41 .33 .41.
    let v: Vec<Option<f64>> = s
        .activities
        .iter()
        .zip(&r.choice)
        .map(|(a, &i)| a.ia_speed[i])
        .collect();
    let want = [
        0.41, 0.33, 0.33, 0.0, 0.0, 0.0, 0.33, 0.41, 0.41, 0.41, 0.0, 0.0, 0.0, 0.41, 0.41, 0.33,
        0.41,
    ];
    for (got, w) in v.iter().zip(want) {
        assert_eq!(got.unwrap_or(0.0), w);
    }
    // Duration does not reduce the IAs (section 7.2.3) and both margins are non-negative.
    assert!(r.margins["duration_s"] >= 0.0 && r.margins["energy_j"] >= 0.0);
    let text = check_text(&files(), "patrolling").unwrap();
    assert!(text.contains("768288795144192"), "{text}");
}

#[test]
fn energy_drift_then_laser_fault_table_7() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    let p = &s.problem;
    let e = p.goals.iter().position(|x| x.name == "energy_j").unwrap();
    // Plan's energy up to the end of A8 (index 7).
    let est: f64 = (0..8)
        .map(|j| p.activities[j].ias[g.choice()[j]].cost[e])
        .sum();
    let est_t: f64 = (0..8)
        .map(|j| p.activities[j].ias[g.choice()[j]].cost[1 - e])
        .sum();
    // TRAS1: at the end of A8 the robot has used 400 J more than planned (odometry drift,
    // obstacles, model error).
    let rec = g.watch(Progress {
        activity_index: 7,
        activity_fraction: 1.0,
        energy_used_j: Some(est + 400.0),
        battery_remaining_pct: None,
        elapsed_s: est_t,
        failed_resources: &[],
        pack: Default::default(),
    });
    assert!((rec.drift["energy_j"] - 400.0).abs() < 1e-6);
    assert!(rec.margins["energy_j"] < 0.0, "{rec:?}");
    let re = rec.reallocation.expect("re-allocated");
    assert!(!rec.infeasible);
    assert!(re.margins_after["energy_j"] >= 0.0);
    assert!(re.margins_after["duration_s"] >= 0.0);
    // Like the paper's RAS1: the cuts fall on the last activities (dichotomy from the end).
    let row1 = &g.ras_rows()[1];
    assert_eq!(row1.label, "RAS1");
    // With a 400 J overrun the row is exactly Table 7's RAS1 (A8..A17): the sonar-only M1 replaces
    // M5/M3 in A16 and A17.
    let table7_ras1 = [
        "M5 L2", "M5 L2", "M5 L2", "T1 L2", "D2", "T1 L2", "M5 L2", "M5 L2", "M1 L2", "M1 L1",
    ];
    let got: Vec<&str> = row1.cells[7..]
        .iter()
        .map(|c| c.as_deref().unwrap())
        .collect();
    assert_eq!(got, table7_ras1);
    assert!(row1.cells[..7].iter().all(|c| c.is_none()));

    // TRAS2: laser2 fails during A14 (index 13).
    let est: f64 = (0..13)
        .map(|j| p.activities[j].ias[g.choice()[j]].cost[e])
        .sum();
    let failed = vec!["laser2".to_string()];
    let rec = g.watch(Progress {
        activity_index: 13,
        activity_fraction: 0.5,
        energy_used_j: Some(est + 400.0 + 0.5 * p.activities[13].ias[g.choice()[13]].cost[e]),
        battery_remaining_pct: None,
        elapsed_s: 400.0,
        failed_resources: &failed,
        pack: Default::default(),
    });
    let re = rec.reallocation.expect("re-allocated after the fault");
    assert!(re.reason.contains("laser2"), "{}", re.reason);
    assert!(re.margins_after.values().all(|m| *m >= 0.0));
    for j in 13..17 {
        let ia = &p.activities[j].ias[g.choice()[j]];
        assert!(
            !ia.resources.contains(&"laser2".to_string()),
            "{} still uses laser2",
            ia.name
        );
    }
    // Table 7 RAS2 starts with M3 L2 in A14 (M5 -> M3: one laser instead of two).
    assert_eq!(g.ras_rows()[2].cells[13].as_deref(), Some("M3 L2"));

    // TRAS3 (the paper's x = 170 m): during the last activity the energy margin is negative
    // again; the same strategy (sonar instead of laser) finishes the mission: A17 runs M1.
    let a17 = p.activities[16].ias[g.choice()[16]].cost[e];
    let before = p.activities[16].ias[g.choice()[16]].name.clone();
    assert!(!before.starts_with("M1"), "{before}");
    let rec = g.watch(Progress {
        activity_index: 16,
        activity_fraction: 0.5,
        // Used so far: the goal minus half of A17's estimate, plus 50 J: margin -50 J.
        energy_used_j: Some(p.goals[e].bound - 0.5 * a17 + 50.0),
        battery_remaining_pct: None,
        elapsed_s: 500.0,
        failed_resources: &failed,
        pack: Default::default(),
    });
    let re = rec.reallocation.expect("TRAS3: re-allocated in A17");
    assert!(re.reason.contains("energy_j"), "{}", re.reason);
    assert_eq!(g.ras_rows()[3].label, "RAS3");
    let a17_after = g.ras_rows()[3].cells[16].as_deref().unwrap();
    assert!(
        a17_after.starts_with("M1 "),
        "RAS3 A17 {a17_after}, was {before}"
    );
    let table = render_ras_table(&s, g.ras_rows());
    println!("{table}");
    assert!(table.contains("RAS2"));
}

/// The optimality gap of RAS0 on the paper's own mission: branch-and-bound maximises the summed
/// energy (the paper's capability proxy) under both goals. RAS0 can only be at or below it.
#[test]
fn ras0_gap_on_the_patrolling_mission() {
    let s = spec();
    let r = Guarantee::pre_flight(&s).unwrap();
    let e = s
        .problem
        .goals
        .iter()
        .position(|g| g.name == ENERGY)
        .unwrap();
    // The energy objective is subset-sum-like: the search is capped and may end with its best so far.
    match panorama::exact(&s.problem, s.selection, 300_000) {
        panorama::Exact::Optimal(o) => {
            let ras0 = r.totals[ENERGY];
            assert!(o.totals[e] >= ras0 - 1e-6);
            assert!(s.problem.feasible(&o.choice));
            println!(
                "patrolling: RAS0 energy {ras0:.1} J, optimum {:.1} J, gap {:.3} %",
                o.totals[e],
                100.0 * (o.totals[e] - ras0) / o.totals[e]
            );
        }
        panorama::Exact::Aborted(Some(b)) => {
            assert!(s.problem.feasible(&b.choice));
            println!(
                "patrolling: search capped; RAS0 energy {:.1} J, best found {:.1} J",
                r.totals[ENERGY], b.totals[e]
            );
        }
        other => panic!("RAS0 exists, so a feasible allocation does: {other:?}"),
    }
}
