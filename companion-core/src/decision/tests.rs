use super::*;

/// Absent is not zero: a snapshot without `wind_mps` (the autopilot not estimating) gives
/// no wind evidence and the record lists `A_wind` as absent; a zero reading is calm evidence.
#[test]
fn absent_observation_is_listed_and_gives_no_evidence() {
    let model = Arc::new(Model::load(&crate::shipped::params()).unwrap());
    let mut core = Core::new(
        Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    let mut obs = Observations {
        state: "base".into(),
        ..Default::default()
    };
    obs.set("battery_pct", 100.0);
    let (_, rec) = core.step(&obs);
    assert!(!rec.evidence.contains_key("A_wind"), "{:?}", rec.evidence);
    assert!(
        rec.absent_evidence.iter().any(|n| n == "A_wind"),
        "{:?}",
        rec.absent_evidence
    );
    assert!(!rec.absent_evidence.iter().any(|n| n == "S_battery"));
    // Core-computed evidence is never absent.
    assert!(!rec.absent_evidence.iter().any(|n| n == "A_free_tiles"));
    obs.set("wind_mps", f64::NAN);
    let (_, rec) = core.step(&obs);
    assert!(rec.absent_evidence.iter().any(|n| n == "A_wind"));
    obs.set("wind_mps", 0.0);
    let (_, rec) = core.step(&obs);
    assert_eq!(rec.evidence.get("A_wind").map(|s| s.as_str()), Some("calm"));
    assert!(
        !rec.absent_evidence.iter().any(|n| n == "A_wind"),
        "{:?}",
        rec.absent_evidence
    );
    let json = serde_json::to_value(&rec).unwrap();
    assert!(json["absent_evidence"].is_array(), "{json}");
}

fn guarantee_activity(core: &mut Core, state: &str, route_activity: Option<f64>) -> String {
    let mut obs = Observations {
        state: state.into(),
        ..Default::default()
    };
    obs.set("battery_pct", 100.0);
    if let Some(a) = route_activity {
        obs.set(crate::evidence::ROUTE_ACTIVITY, a);
    }
    let (_, rec) = core.step(&obs);
    rec.guarantee.expect("a guarantee record").activity_name
}

/// The route's progress names the activity the guarantee watches: `route_activity` wins over
/// the state's `activity_of_state`; absent, NaN, fractional or beyond the plan, the state's
/// activity stands (the fallback).
#[test]
fn route_activity_names_the_activity_and_the_state_is_the_fallback() {
    let model = Arc::new(Model::load(&crate::shipped::params()).unwrap());
    let names: Vec<String> = (model.guarantee.problem.activities.iter())
        .map(|a| a.name.clone())
        .collect();
    let of_state = |s: &str| names[model.mission.guarantee.activity_of_state[s]].clone();
    let mut core = Core::new(
        Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    // wp1 is the typed plan's `transit`; the route says the activity is the last one.
    let last = names.len() - 1;
    assert_ne!(of_state("wp1"), names[last]);
    assert_eq!(
        guarantee_activity(&mut core, "wp1", Some(last as f64)),
        names[last]
    );
    assert_eq!(guarantee_activity(&mut core, "wp1", Some(0.0)), names[0]);
    // The fallback.
    assert_eq!(guarantee_activity(&mut core, "wp1", None), of_state("wp1"));
    for bad in [f64::NAN, -1.0, 1.5, names.len() as f64, f64::INFINITY] {
        assert_eq!(
            guarantee_activity(&mut core, "wpf", Some(bad)),
            of_state("wpf"),
            "route_activity {bad}"
        );
    }
}

/// How far into an activity the guarantee counts is the autopilot's time when it reports one
/// (`vehicle_time_s`): a SITL at speedup 3 flies 30 s of a hold in 10 s of the shell's clock, and
/// the remainder planned shrinks by 30 s' worth, not 10 s'. Without it, the observation time.
#[test]
fn activity_progress_runs_on_the_autopilots_clock() {
    let model = Arc::new(Model::load(&crate::shipped::params()).unwrap());
    let hold = (model.guarantee.problem.activities.iter())
        .position(|a| a.name == "tracking_area")
        .expect("the typed plan's tracking hold");
    let duration = model.guarantee.activities[hold].hold_s;
    let mut core = Core::new(
        Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    let mut at = |shell_s: f64, vehicle_s: Option<f64>| {
        let mut obs = Observations {
            state: "wpf".into(),
            time_s: shell_s,
            ..Default::default()
        };
        obs.set("battery_pct", 100.0);
        obs.set(crate::evidence::ROUTE_ACTIVITY, hold as f64);
        if let Some(v) = vehicle_s {
            obs.set("vehicle_time_s", v);
        }
        let g = core.step(&obs).1.guarantee.expect("a guarantee record");
        assert_eq!(g.activity_name, "tracking_area");
        (g.margins["energy_j"], g.planned_j)
    };
    let (m0, planned) = at(100.0, Some(300.0));
    let (m1, _) = at(110.0, Some(330.0));
    let want = 30.0 / duration * planned;
    assert!(
        (m1 - m0 - want).abs() < 1e-6 * planned,
        "margin grew {} J, want {want} J (30 s of {duration} s)",
        m1 - m0
    );
    // No vehicle clock: the observation time counts (the activity restarts on the other clock).
    let (n0, _) = at(200.0, None);
    let (n1, _) = at(210.0, None);
    let want = 10.0 / duration * planned;
    assert!(
        (n1 - n0 - want).abs() < 1e-6 * planned,
        "{} vs {want}",
        n1 - n0
    );
}
