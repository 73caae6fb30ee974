//! The BFM tracking mission under PANORAMA: pre-flight, (a) energy drift, (b) lidar and tile
//! failures, (c) an impossible goal; and every kind of bad mission file the loader rejects.

use companion_core::guarantee::*;
use companion_core::report::guarantee::*;
use std::path::Path;

fn params() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../params"))
}

fn text() -> String {
    std::fs::read_to_string(params().join("missions/tracking.toml")).unwrap()
}

/// The shipped params plus the mission file again under its absolute path (a mission by path).
fn files() -> companion_core::spec::ParamsFiles {
    let mut f = companion::params::read_params_dir(params()).unwrap();
    let abs = params().join("missions/tracking.toml");
    companion::params::add_file(&mut f, &abs);
    f
}

fn spec() -> MissionSpec {
    load_mission(&files(), "tracking").unwrap()
}

fn ia_name(s: &MissionSpec, g: &Guarantee, j: usize) -> String {
    s.problem.activities[j].ias[g.choice()[j]].name.clone()
}

#[test]
fn loads_by_name_and_by_path() {
    let a = spec();
    let b = load_mission(
        &files(),
        params().join("missions/tracking.toml").to_str().unwrap(),
    )
    .unwrap();
    assert_eq!(a.problem, b.problem);
    // Energy goal from the battery: (74 Wh x 0.85 - 7.4 Wh) x 3600 s/h.
    let e = a.problem.goals.iter().find(|g| g.name == ENERGY).unwrap();
    assert!((e.bound - (74.0 * 0.85 - 7.4) * 3600.0).abs() < 1e-6);
    // IA counts: 2 x 2, GPS-degraded forces vision (1 x 2), tracking 2 x 2 x 18, landing 2 x 2 x 4.
    let counts: Vec<usize> = a.problem.activities.iter().map(|x| x.ias.len()).collect();
    assert_eq!(counts, vec![4, 4, 2, 4, 72, 16]);
    assert_eq!(panorama::nga(&a.problem), Some(4 * 4 * 2 * 4 * 72 * 16));
    let j = check_json(&files(), "tracking").unwrap();
    assert_eq!(j["guarantee"]["nga"].as_u64(), Some(147_456));
    assert!(j["guarantee"]["margins"]["energy_j"].as_f64().unwrap() >= 0.0);
    assert_eq!(j["guarantee"]["activities"].as_array().unwrap().len(), 6);
}

#[test]
fn hover_power_matches_the_model_by_hand() {
    // Take-off IA "gps lidar": 30 m at 2.5 m/s = 12 s. Rotary-wing P(2.5) by hand:
    // blade 60 (1 + 3 x 6.25 / 6400) = 60.17578; r = 6.25 / 39.69 = 0.157470;
    // induced 140 sqrt(sqrt(1 + r^2 / 4) - r / 2) = 140 sqrt(0.924359) = 134.6011 (to 1e-3);
    // parasitic 0.5 x 1.225 x 0.05 x 15.625 = 0.478516. Payload 8 + 0.5 + 3 + 1.5 x 0.025 W.
    let s = spec();
    let a = &s.problem.activities[0];
    let i = a.ias.iter().position(|x| x.name == "gps lidar").unwrap();
    let r: f64 = 6.25 / (6.3 * 6.3);
    let induced = 140.0 * ((1.0 + r * r / 4.0).sqrt() - r / 2.0).sqrt();
    assert!((induced - 134.6011).abs() < 1e-3, "{induced}");
    let p = 60.0 * (1.0 + 3.0 * 6.25 / 6400.0) + induced + 0.5 * 1.225 * 0.05 * 15.625;
    let payload = 8.0 + 0.5 + 3.0 + 1.5 * (0.02 + 0.005);
    let e = s
        .problem
        .goals
        .iter()
        .position(|g| g.name == ENERGY)
        .unwrap();
    assert!(
        (a.ias[i].cost[e] - (p + payload) * 12.0).abs() < 1e-6,
        "{}",
        a.ias[i].cost[e]
    );
    assert!((a.ias[i].cost[1 - e] - 12.0).abs() < 1e-9);
}

/// (a) Energy drift: wind makes the first activities cost more than planned; the margin turns
/// negative at the obstacle-dense zone and a re-allocation of the remaining activities restores it.
#[test]
fn energy_drift_reallocation_restores_margin() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    let p = &s.problem;
    let e = p.goals.iter().position(|x| x.name == ENERGY).unwrap();
    let at = 3; // obstacle_dense
    let est: f64 = (0..at)
        .map(|j| p.activities[j].ias[g.choice()[j]].cost[e])
        .sum();
    let total: f64 = (0..p.activities.len())
        .map(|j| p.activities[j].ias[g.choice()[j]].cost[e])
        .sum();
    let margin0 = p.goals[e].bound - total;
    let overrun = margin0 + 1500.0; // 1.5 kJ more than the whole margin
    let rec = g.watch(Progress {
        activity_index: at,
        activity_fraction: 0.0,
        energy_used_j: Some(est + overrun),
        battery_remaining_pct: None,
        elapsed_s: 130.0,
        failed_resources: &[],
        pack: Default::default(),
    });
    assert!((rec.margins["energy_j"] + 1500.0).abs() < 1e-6, "{rec:?}");
    assert!((rec.drift["energy_j"] - overrun).abs() < 1e-6);
    let re = rec.reallocation.as_ref().expect("re-allocated");
    assert!(!rec.infeasible);
    assert!(re.margins_after["energy_j"] >= 0.0, "{re:?}");
    assert_eq!(re.allocation.len(), 3);
    // The next cycle with the same measurement sees the new plan's non-negative margin.
    let again = g.watch(Progress {
        activity_index: at,
        activity_fraction: 0.0,
        energy_used_j: Some(est + overrun),
        battery_remaining_pct: None,
        elapsed_s: 130.0,
        failed_resources: &[],
        pack: Default::default(),
    });
    assert!(again.reallocation.is_none() && again.margins["energy_j"] >= 0.0);
    println!("{}", render_ras_table(&s, g.ras_rows()));
}

/// Energy from the battery percentage: the energy the reported percentage represents, from the
/// first reading on (a pack that is not full at the first reading is not counted as full).
#[test]
fn battery_percentage_is_converted() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    let mk = |pct: f64, consumed: Option<f64>| Progress {
        activity_index: 1,
        activity_fraction: 0.0,
        energy_used_j: consumed,
        battery_remaining_pct: Some(pct),
        elapsed_s: 12.0,
        failed_resources: &[],
        pack: Default::default(),
    };
    let cap = 74.0 * 3600.0;
    let est0: f64 = s.problem.activities[0].ias[g.choice()[0]].cost[0];
    // 95 % left of 74 Wh: 5 % of it counted as used, already at the first reading.
    let r = g.watch(mk(95.0, None));
    assert!(
        (r.drift["energy_j"] - (0.05 * cap - est0)).abs() < 1e-6,
        "{r:?}"
    );
    assert_eq!(
        r.energy_source,
        companion_core::record::EnergySource::BatteryRemaining
    );
    // The autopilot's consumed energy counts when it says more was used (conservative).
    let r = g.watch(mk(95.0, Some(0.08 * cap)));
    assert!(
        (r.drift["energy_j"] - (0.08 * cap - est0)).abs() < 1e-6,
        "{r:?}"
    );
    assert_eq!(
        r.energy_source,
        companion_core::record::EnergySource::EnergyConsumed
    );
    let r = g.watch(mk(95.0, Some(0.01 * cap)));
    assert_eq!(
        r.energy_source,
        companion_core::record::EnergySource::BatteryRemaining
    );
}

/// A vehicle whose first reading is 12 % has 12 % of the pack: what the mission may still spend
/// is 12 % of 74 Wh less the never-drawn 15 % and the reserve, which is below zero, so the
/// energy margin is negative and no allocation meets the goal. At 100 % the margin is the
/// pre-flight one.
#[test]
fn first_reading_of_12_percent_is_12_percent() {
    let s = spec();
    let bound = s
        .problem
        .goals
        .iter()
        .find(|g| g.name == ENERGY)
        .unwrap()
        .bound;
    let remainder: f64 = (0..s.problem.activities.len())
        .map(|j| {
            let g = Guarantee::start(s.clone()).unwrap();
            s.problem.activities[j].ias[g.choice()[j]].cost[0]
        })
        .sum();
    let at = |pct: f64| {
        let mut g = Guarantee::start(s.clone()).unwrap();
        g.watch(Progress {
            activity_index: 0,
            activity_fraction: 0.0,
            energy_used_j: None,
            battery_remaining_pct: Some(pct),
            elapsed_s: 0.0,
            failed_resources: &[],
            pack: Default::default(),
        })
    };
    let full = at(100.0);
    assert!(
        (full.margins["energy_j"] - (bound - remainder)).abs() < 1e-6,
        "{full:?}"
    );
    assert!(!full.infeasible);
    let low = at(12.0);
    // Left to spend: 0.12 x 74 Wh - (1 - 0.85) x 74 Wh - 7.4 Wh = -9.62 Wh: nothing at all.
    let left_j = (0.12 * 74.0 - 0.15 * 74.0 - 7.4) * 3600.0;
    assert!(low.infeasible, "{low:?}");
    assert!(
        low.infeasible_reason
            .as_deref()
            .unwrap()
            .contains("energy_j"),
        "{low:?}"
    );
    assert!(
        (low.margins["energy_j"] - (left_j - remainder)).abs() < 1e-6,
        "{low:?}"
    );
}

/// (b) Lidar failure during the transit: the remaining activities switch to IR/US fusion and the
/// re-allocation keeps every margin non-negative.
#[test]
fn lidar_failure_reallocation() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    assert!(ia_name(&s, &g, 2).contains("lidar"));
    let failed = vec!["lidar".to_string()];
    let rec = g.watch(Progress {
        activity_index: 1,
        activity_fraction: 0.5,
        energy_used_j: None,
        battery_remaining_pct: None,
        elapsed_s: 40.0,
        failed_resources: &failed,
        pack: Default::default(),
    });
    let re = rec.reallocation.expect("re-allocated");
    assert!(re.reason.contains("lidar"), "{}", re.reason);
    assert!(re.margins_after.values().all(|m| *m >= 0.0), "{re:?}");
    for j in 1..6 {
        assert!(
            ia_name(&s, &g, j).contains("fusion"),
            "{}",
            ia_name(&s, &g, j)
        );
    }
    assert_eq!(rec.failed_resources, failed);
}

/// (b') Three FPGA tiles fail during the tracking: two-tile (F) variants are no longer placeable.
#[test]
fn tile_failure_reallocation() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    assert!(ia_name(&s, &g, 4).ends_with(".F"), "{}", ia_name(&s, &g, 4));
    let failed: Vec<String> = ["tile0", "tile1", "tile2"]
        .iter()
        .map(|x| x.to_string())
        .collect();
    let rec = g.watch(Progress {
        activity_index: 4,
        activity_fraction: 0.2,
        energy_used_j: None,
        battery_remaining_pct: None,
        elapsed_s: 250.0,
        failed_resources: &failed,
        pack: Default::default(),
    });
    let re = rec.reallocation.expect("re-allocated");
    assert!(re.reason.contains("FPGA tile"), "{}", re.reason);
    assert!(re.margins_after.values().all(|m| *m >= 0.0));
    let track = ia_name(&s, &g, 4);
    // Most capable with at most one tile: V4 or V5 in M (capability 4.25).
    assert!(
        track.ends_with("V4.M") || track.ends_with("V5.M"),
        "{track}"
    );
    assert!(!ia_name(&s, &g, 5).ends_with(".F") || ia_name(&s, &g, 5).contains("zone_t.F"));
}

/// (c) An impossible goal is reported with the numbers, before and during the flight.
#[test]
fn impossible_goal_is_infeasible_with_numbers() {
    let t = text().replace("bound = 1500.0", "bound = 500.0");
    let s = parse_mission(Path::new("tracking-500s.toml"), &t).unwrap();
    // Fastest IAs: take-off 12 s, transit 60 s, GPS-degraded 50 s (vision), obstacle-dense
    // 41.67 s, tracking 600 s, landing 25 + 20 + 20 s: 828.67 s > 500 s.
    let fastest = 12.0 + 60.0 + 50.0 + 250.0 / 6.0 + 600.0 + 25.0 + 20.0 + 20.0;
    match Guarantee::pre_flight(&s) {
        Err(panorama::Infeasible::Goal {
            goal,
            minimum,
            bound,
            excess,
        }) => {
            assert_eq!(goal, "duration_s");
            assert!((minimum - fastest).abs() < 1e-6, "{minimum}");
            assert_eq!(bound, 500.0);
            assert!((excess - (fastest - 500.0)).abs() < 1e-6);
        }
        other => panic!("{other:?}"),
    }
    let j = check_json_spec(&s);
    assert_eq!(j["guarantee"]["infeasible"]["constraint"], "duration_s");
    assert!(j["guarantee"]["ras0"].is_null());
    assert!(check_text_spec(&s).contains("INFEASIBLE"));
    // In flight: a huge overrun leaves no allocation; the record says so.
    let mut g = Guarantee::start(spec()).unwrap();
    let rec = g.watch(Progress {
        activity_index: 4,
        activity_fraction: 0.0,
        energy_used_j: Some(199_000.0),
        battery_remaining_pct: None,
        elapsed_s: 200.0,
        failed_resources: &[],
        pack: Default::default(),
    });
    assert!(rec.infeasible && rec.reallocation.is_none());
    let why = rec.infeasible_reason.unwrap();
    assert!(why.contains("energy_j") && why.contains("exceeds"), "{why}");
}

fn rejected(t: &str) -> companion_core::spec::SpecError {
    parse_mission(Path::new("bad.toml"), t).expect_err("must be rejected")
}

#[test]
fn unknown_tio_is_rejected() {
    let t = text()
        + "\n[constraints.odd]\nrules = [{ kind = \"only\", task = \"tracking\", tios = [\"V9.F\"] }]\n";
    let e = rejected(&t);
    assert_eq!(e.file, Path::new("bad.toml"));
    assert_eq!(e.entry, "constraints.odd.rules[0].tios");
    assert!(e.reason.contains("unknown TIO `V9.F`"), "{e}");
}

#[test]
fn unknown_resource_of_a_tio_is_rejected() {
    let t = text().replace(
        "resources = [\"ir\", \"us\"]",
        "resources = [\"ir\", \"sonar\"]",
    );
    let e = rejected(&t);
    assert_eq!(e.entry, "tasks.obstacle_detection.tios[1].resources");
    assert!(e.reason.contains("sonar"));
}

#[test]
fn negative_energy_is_rejected() {
    let e = rejected(&text().replace(
        "[resources.lidar]\npower_w = 3.0",
        "[resources.lidar]\npower_w = -3.0",
    ));
    assert_eq!(e.entry, "resources.lidar.power_w");
    assert!(e.reason.contains("negative"), "{e}");
    let e = rejected(&text().replace("reserve_wh = 7.4", "reserve_wh = 70.0"));
    assert_eq!(e.entry, "goals.energy_j.bound");
    // A propulsion fit that goes negative at the flown speed: no airframe's ([power_bounds]).
    let p = text().replace("blade_profile_w = 60.0", "blade_profile_w = -600.0");
    let e = rejected(&p);
    assert_eq!(e.entry, "propulsion", "{e}");
    assert!(e.reason.contains("hover power -460"), "{e}");
}

#[test]
fn empty_activity_after_core_filter_is_rejected() {
    let t = text()
        + "\n[constraints.no_camera]\nrules = [{ kind = \"forbid\", task = \"localisation\", resource = \"camera\" }]\n";
    let t = t.replace(
        "constraints = [\"gps_degraded\"]",
        "constraints = [\"gps_degraded\", \"no_camera\"]",
    );
    let e = rejected(&t);
    assert_eq!(e.entry, "activities[2]");
    assert!(
        e.reason.contains("transit_gps_degraded")
            && e.reason.contains("no implementation alternative"),
        "{e}"
    );
}

#[test]
fn goal_order_naming_an_unknown_goal_is_rejected() {
    let e = rejected(&text().replace(
        "goal_order = [\"energy_j\", \"duration_s\"]",
        "goal_order = [\"energy_j\", \"time_s\"]",
    ));
    assert_eq!(e.entry, "mission.goal_order[1]");
    assert!(e.reason.contains("unknown goal `time_s`"), "{e}");
    // A defined goal left out of the order is an error too (it would be silently ignored).
    let e = rejected(&text().replace(
        "goal_order = [\"energy_j\", \"duration_s\"]",
        "goal_order = [\"energy_j\"]",
    ));
    assert_eq!(e.entry, "goals.duration_s");
}

#[test]
fn unknown_task_and_constraint_class_and_syntax_are_rejected() {
    let e = rejected(&text().replace(
        "tasks = [\"localisation\", \"obstacle_detection\", \"tracking\"]",
        "tasks = [\"localisation\", \"tracker\"]",
    ));
    assert_eq!(e.entry, "activities[4].tasks[1]");
    let e = rejected(&text().replace(
        "constraints = [\"gps_degraded\"]",
        "constraints = [\"gps_denied\"]",
    ));
    assert_eq!(e.entry, "activities[2].constraints[0]");
    let e = rejected("[mission\nname=");
    assert_eq!(e.file, Path::new("bad.toml"));
    let missing = load_mission(&files(), "no_such_mission").unwrap_err();
    assert!(missing.file.ends_with("missions/no_such_mission.toml"));
}

/// RAS0 against the exact optimum (branch-and-bound, checked by exhaustive search: NGA 147 456).
#[test]
fn ras0_gap_on_the_tracking_mission() {
    let s = spec();
    let r = Guarantee::pre_flight(&s).unwrap();
    let ras0 = s.problem.score(&r.choice, s.selection);
    let brute = panorama::exhaustive(&s.problem, s.selection).unwrap();
    match panorama::exact(&s.problem, s.selection, u64::MAX) {
        panorama::Exact::Optimal(o) => {
            assert!((o.score - brute.score).abs() < 1e-9);
            assert!(o.score >= ras0 - 1e-9);
            println!("tracking: RAS0 capability {ras0}, optimum {}", o.score);
        }
        other => panic!("{other:?}"),
    }
}

/// The energy estimate of the allocation in force, activities `from..`.
fn estimate_from(s: &MissionSpec, g: &Guarantee, from: usize) -> f64 {
    (from..s.problem.activities.len())
        .map(|j| s.problem.activities[j].ias[g.choice()[j]].cost[0])
        .sum()
}

fn pack_at(
    pct: Option<f64>,
    pack: PackReading,
    activity_index: usize,
    elapsed_s: f64,
) -> Progress<'static> {
    Progress {
        activity_index,
        activity_fraction: 0.0,
        energy_used_j: None,
        battery_remaining_pct: pct,
        elapsed_s,
        failed_resources: &[],
        pack,
    }
}

/// The autopilot's pack, not the params': ArduCopter SITL's 3300 mAh at 12.6 V is 3 cells
/// (ceil(12.6 / 4.25) = 3), 11.1 V nominal, C = 3300 x 3.6 x 11.1 = 131,868 J. Params keep back
/// 15 % (never drawn) + 7.4 / 74 = 10 % (reserve) = 25 % = 32,967 J; the bound is 98,901 J. At
/// 12 % the pack holds 15,824.16 J: what the mission may spend is 15,824.16 - 32,967 J.
#[test]
fn the_bound_is_the_autopilot_pack_and_12_percent_is_12_percent_of_it() {
    use companion_core::record::{CapacitySource, CellsSource, EnergySource};
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    let est = estimate_from(&s, &g, 0);
    let ardu = PackReading {
        capacity_mah: Some(3300.0),
        voltage_v: Some(12.6),
        ..Default::default()
    };
    let r = g.watch(pack_at(Some(12.0), ardu, 0, 0.0));
    let p = r.pack.expect("pack recorded");
    assert_eq!(p.capacity_source, CapacitySource::Autopilot);
    assert_eq!(p.cells, Some(3.0));
    assert_eq!(p.cells_source, Some(CellsSource::FirstVoltage));
    assert!((p.capacity_j - 131_868.0).abs() < 1e-6, "{p:?}");
    assert!((p.kept_back_j - 32_967.0).abs() < 1e-6, "{p:?}");
    assert!((p.left_j.unwrap() - 15_824.16).abs() < 1e-6, "{p:?}");
    assert!((r.goals["energy_j"] - 98_901.0).abs() < 1e-6, "{r:?}");
    assert_eq!(r.energy_source, EnergySource::BatteryRemaining);
    assert!(
        (r.margins["energy_j"] - (15_824.16 - 32_967.0 - est)).abs() < 1e-6,
        "{r:?}"
    );
    assert!(r.margins["energy_j"] < 0.0);

    // The consumed charge says less is left (3000 of 3300 mAh: 300 x 3.6 x 11.1 = 11,988 J); the
    // voltage has sagged to 8 V, but the cells stay counted from the first reading.
    let mut g = Guarantee::start(s.clone()).unwrap();
    g.watch(pack_at(Some(12.0), ardu, 0, 0.0));
    let sagged = PackReading {
        voltage_v: Some(8.0),
        consumed_mah: Some(3000.0),
        ..ardu
    };
    let r = g.watch(pack_at(Some(12.0), sagged, 0, 1.0));
    let p = r.pack.unwrap();
    assert_eq!(p.cells, Some(3.0));
    assert_eq!(r.energy_source, EnergySource::CurrentConsumed);
    assert!((p.left_j.unwrap() - 11_988.0).abs() < 1e-6, "{p:?}");

    // PX4 names its cells: 4 x 3.7 V; 5000 mAh x 3.6 x 14.8 = 266,400 J, at 100 %.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let px4 = PackReading {
        capacity_mah: Some(5000.0),
        cells: Some(4.0),
        voltage_v: Some(16.2),
        ..Default::default()
    };
    let r = g.watch(pack_at(Some(100.0), px4, 0, 0.0));
    let p = r.pack.unwrap();
    assert_eq!(p.cells_source, Some(CellsSource::Autopilot));
    assert!((p.capacity_j - 266_400.0).abs() < 1e-6, "{p:?}");
    assert!((r.goals["energy_j"] - 199_800.0).abs() < 1e-6, "{r:?}");

    // PX4 SIH's capacity -1: the params' pack, and the record says so.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let unset = PackReading {
        capacity_mah: Some(-1.0),
        voltage_v: Some(16.2),
        ..Default::default()
    };
    let r = g.watch(pack_at(Some(50.0), unset, 0, 0.0));
    let p = r.pack.unwrap();
    assert_eq!(p.capacity_source, CapacitySource::Params);
    assert_eq!(p.capacity_mah, Some(-1.0));
    assert!((p.capacity_j - 74.0 * 3600.0).abs() < 1e-6);
    assert!((p.left_j.unwrap() - 0.5 * 74.0 * 3600.0).abs() < 1e-6);
    assert!((r.goals["energy_j"] - (74.0 * 0.85 - 7.4) * 3600.0).abs() < 1e-6);

    // Nothing said of the pack (simulate): no pack record, the params' goal.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let r = g.watch(pack_at(Some(50.0), PackReading::default(), 0, 0.0));
    assert!(r.pack.is_none() && r.power.is_none());
}

/// Power measured against predicted: the transit's allocation predicts P = E / T. Measured at
/// exactly 2 P (12 V x 2P/12 A) from t = 100 s: after 10 s in the activity the ratio is 2 (beyond
/// 25 %), a drift; the remaining activities' energy estimates are scaled by the factor with the
/// params' prior worth 60 s: (60 x 1 + 10 x 2) / (60 + 10) = 8/7, bounded to [0.5, 2]. At 1.2 P
/// nothing drifts.
#[test]
fn measured_power_is_confronted_with_the_prediction_and_a_drift_rescales_the_rest() {
    let s = spec();
    let mut g = Guarantee::start(s.clone()).unwrap();
    let ia = &s.problem.activities[1].ias[g.choice()[1]];
    let (e_pred, t_pred) = (ia.cost[0], ia.cost[1]);
    let p_pred = e_pred / t_pred;
    let drawing = |w: f64| PackReading {
        voltage_v: Some(12.0),
        current_a: Some(w / 12.0),
        ..Default::default()
    };
    let r = g.watch(pack_at(Some(90.0), drawing(2.0 * p_pred), 1, 100.0));
    let pw = r.power.unwrap();
    assert!((pw.predicted_w - p_pred).abs() < 1e-9);
    assert!((pw.measured_w.unwrap() - 2.0 * p_pred).abs() < 1e-9);
    assert_eq!(pw.measured_j, Some(0.0));
    assert!(!pw.drift && pw.ratio.is_none());
    let r = g.watch(pack_at(Some(90.0), drawing(2.0 * p_pred), 1, 105.0));
    let pw = r.power.unwrap();
    assert!((pw.measured_j.unwrap() - 2.0 * p_pred * 5.0).abs() < 1e-6);
    assert!((pw.predicted_j - p_pred * 5.0).abs() < 1e-6);
    assert!(!pw.drift, "judged only after 10 s");
    let r = g.watch(pack_at(Some(90.0), drawing(2.0 * p_pred), 1, 110.0));
    let pw = r.power.unwrap();
    assert!((pw.ratio.unwrap() - 2.0).abs() < 1e-9, "{pw:?}");
    assert!(pw.drift && pw.drift_began);
    let k = 8.0 / 7.0;
    assert!((pw.energy_scale - k).abs() < 1e-12, "{pw:?}");
    for j in 1..s.problem.activities.len() {
        for (i, ia) in s.problem.activities[j].ias.iter().enumerate() {
            let c = g.spec.problem.activities[j].ias[i].cost[0];
            assert!((c - k * ia.cost[0]).abs() < 1e-9 * ia.cost[0].max(1.0));
        }
    }
    assert_eq!(
        g.spec.problem.activities[0].ias[0].cost[0], s.problem.activities[0].ias[0].cost[0],
        "flown activities keep their estimate"
    );
    let r = g.watch(pack_at(Some(90.0), drawing(2.0 * p_pred), 1, 111.0));
    let pw = r.power.unwrap();
    assert!(pw.drift && !pw.drift_began, "said once per activity");

    let mut g = Guarantee::start(s.clone()).unwrap();
    for t in [100.0, 105.0, 110.0, 120.0] {
        let pw = g
            .watch(pack_at(Some(90.0), drawing(1.2 * p_pred), 1, t))
            .power
            .unwrap();
        assert!(!pw.drift, "{pw:?}");
        assert_eq!(pw.energy_scale, 1.0);
    }
    // Disarmed on the ground nothing is flown: no judgement however long it waits, and the
    // measurement starts again at the arming.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let idle = PackReading {
        armed: Some(false),
        ..drawing(0.0)
    };
    for t in [0.0, 30.0, 60.0] {
        let pw = g.watch(pack_at(Some(90.0), idle, 0, t)).power.unwrap();
        assert!(
            !pw.drift && pw.ratio.is_none() && pw.activity_s == 0.0,
            "{pw:?}"
        );
    }
    let armed = |w: f64| PackReading {
        armed: Some(true),
        ..drawing(w)
    };
    let p0 = {
        let ia = &s.problem.activities[0].ias[g.choice()[0]];
        ia.cost[0] / ia.cost[1]
    };
    g.watch(pack_at(Some(90.0), armed(p0), 0, 61.0));
    let pw = g
        .watch(pack_at(Some(90.0), armed(p0), 0, 72.0))
        .power
        .unwrap();
    assert_eq!(pw.activity_s, 11.0);
    assert!(
        (pw.ratio.unwrap() - 1.0).abs() < 1e-9 && !pw.drift,
        "{pw:?}"
    );
    // The autopilot's clock counts (a SITL at speedup 3): 15 vehicle seconds in 5 companion seconds.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let clocked = |vt: f64| PackReading {
        vehicle_time_s: Some(vt),
        ..drawing(p_pred)
    };
    g.watch(pack_at(Some(90.0), clocked(30.0), 1, 100.0));
    let pw = g
        .watch(pack_at(Some(90.0), clocked(45.0), 1, 105.0))
        .power
        .unwrap();
    assert_eq!(pw.activity_s, 15.0);
    assert!((pw.ratio.unwrap() - 1.0).abs() < 1e-9, "{pw:?}");
    // The autopilot's consumed energy, when it reports it, is the measured energy of the activity.
    let mut g = Guarantee::start(s.clone()).unwrap();
    let mut at = |t: f64, consumed: f64| {
        g.watch(Progress {
            energy_used_j: Some(consumed),
            ..pack_at(Some(90.0), drawing(p_pred), 1, t)
        })
        .power
        .unwrap()
    };
    at(100.0, 5_000.0);
    let pw = at(112.0, 5_000.0 + 3.0 * p_pred * 12.0);
    assert!((pw.measured_j.unwrap() - 3.0 * p_pred * 12.0).abs() < 1e-6);
    // (60 + 12 x 3) / 72 = 4/3
    assert!((pw.energy_scale - 4.0 / 3.0).abs() < 1e-12, "{pw:?}");
    // sustained: after 1000 s at x3, (60 + 3000) / 1060 = 2.89, bounded to 2
    let pw = at(1100.0, 5_000.0 + 3.0 * p_pred * 1000.0);
    assert_eq!(pw.energy_scale, 2.0, "bounded to 2");
}

/// A mission the params' pack cannot hold (a vehicle profile's power, say) still gets a guarantee:
/// `start` refuses it, `start_or_unbounded` starts from the lifted allocation and its margins say
/// the truth: negative on the params' pack, positive once the autopilot reports a pack that
/// holds the mission (in `fly` the verdict reads those margins: the ArduCopter profile's flight).
#[test]
fn a_mission_the_params_pack_cannot_hold_starts_and_its_margins_follow_the_autopilots_pack() {
    let mut s = spec();
    let e = s
        .problem
        .goals
        .iter()
        .position(|g| g.name == ENERGY)
        .unwrap();
    // the params' pack's usable energy: a bound just below the cheapest allocation's total
    let cheapest: f64 = s
        .problem
        .activities
        .iter()
        .map(|a| {
            a.ias
                .iter()
                .map(|ia| ia.cost[e])
                .fold(f64::INFINITY, f64::min)
        })
        .sum();
    s.problem.goals[e].bound = 0.9 * cheapest;
    assert!(Guarantee::start(s.clone()).is_err());
    let watch = |pack: PackReading| {
        let mut g = Guarantee::start_or_unbounded(s.clone()).expect("a guarantee");
        g.watch(Progress {
            activity_index: 0,
            activity_fraction: 0.0,
            energy_used_j: None,
            battery_remaining_pct: Some(100.0),
            elapsed_s: 0.0,
            failed_resources: &[],
            pack,
        })
    };
    let params_pack = watch(Default::default());
    assert!(params_pack.margins["energy_j"] < 0.0, "{params_pack:?}");
    // a 3S 40 Ah pack reported by the autopilot: 40,000 mAh x 3.6 x 3 x 3.7 V = 1.6 MJ
    let big = watch(PackReading {
        capacity_mah: Some(40_000.0),
        cells: Some(3.0),
        voltage_v: Some(12.6),
        ..Default::default()
    });
    assert!(big.margins["energy_j"] > 0.0, "{big:?}");
    assert!(!big.infeasible, "{big:?}");
}
