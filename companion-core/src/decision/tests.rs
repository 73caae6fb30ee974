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
    assert_eq!(rec.evidence.get("A_wind").map(String::as_str), Some("calm"));
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
