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
