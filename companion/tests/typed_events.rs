//! The typed events, link events and command outcomes of real runs are written as objects tagged
//! by `kind` (schema 2, their sentence in `text`) and read back as the same values: every `simulate` scenario under both policies and the three
//! models (the fly loop's records are checked the same way in link_loopback.rs).

use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Event};
use std::collections::BTreeSet;

/// A record written to JSON reads back with equal events, link events and command results,
/// each written as an object with its `kind` and, for people, the sentence its `Display` gives.
pub fn assert_reads_back(r: &DecisionRecord) {
    let json = serde_json::to_value(r).unwrap();
    let back: DecisionRecord = serde_json::from_value(json.clone()).unwrap();
    assert_eq!(back.events, r.events, "cycle {}", r.cycle);
    assert_eq!(back.link_events, r.link_events, "cycle {}", r.cycle);
    assert_eq!(back.commands, r.commands, "cycle {}", r.cycle);
    let written: Vec<serde_json::Value> = r
        .events
        .iter()
        .map(|e| serde_json::json!(e.to_string()))
        .collect();
    let said: Vec<serde_json::Value> = json["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            assert!(e["kind"].is_string(), "{e}");
            e["text"].clone()
        })
        .collect();
    assert_eq!(said, written);
}

#[test]
fn every_simulated_event_reads_back_as_the_variant_written() {
    let dir = companion::params::default_params_dir();
    let files = companion::params::read_params_dir(&dir).unwrap();
    let model = std::sync::Arc::new(companion::params::load_model(&dir).unwrap());
    let world = WorldSpec::load(&files).unwrap();
    let mut scenarios: Vec<String> = std::fs::read_dir(dir.join("scenarios"))
        .unwrap()
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(str::to_string))?
        })
        .collect();
    scenarios.sort();
    assert!(scenarios.len() >= 9, "{scenarios:?}");
    let mut kinds = BTreeSet::new();
    let mut others = BTreeSet::new();
    for name in &scenarios {
        let scenario = Scenario::load(&files, name).unwrap();
        for policy in [
            model.policy("safety").unwrap(),
            model.policy("mission").unwrap(),
        ] {
            for kind in [ModelKind::Bfm, ModelKind::Reference, ModelKind::Monolithic] {
                let mut core = Core::new(std::sync::Arc::clone(&model), kind, policy);
                let run = sim::run(&world, &scenario, 1, |obs| core.step(obs));
                for r in &run.records {
                    assert_reads_back(r);
                    // The world's own happenings after the step, written beside the record.
                    let after = &r.vehicle["world_events_after"];
                    let world: Vec<Event> = serde_json::from_value(after.clone()).unwrap();
                    assert_eq!(&serde_json::to_value(&world).unwrap(), after);
                    for e in r.events.iter().chain(&world) {
                        match e {
                            Event::Other(text) => {
                                others.insert(text.clone());
                            }
                            e => {
                                let d = format!("{e:?}");
                                kinds.insert(d.split(['(', ' ']).next().unwrap().to_string());
                            }
                        }
                    }
                }
            }
        }
    }
    // The world's and the core's happenings are typed: these show up across the scenarios.
    for kind in [
        "TargetDetected",
        "TargetLost",
        "ObstacleDetected",
        "ObstacleAvoided",
        "Landing",
        "Reallocation",
        "GuaranteeInfeasible",
    ] {
        assert!(kinds.contains(kind), "no {kind} in any run: {kinds:?}");
    }
    // Free text is only what has no fixed spelling: the scenarios' hazards and the resource
    // degradations.
    for t in &others {
        assert!(
            !t.starts_with("command ") && !t.starts_with("mode ") && !t.starts_with("health: "),
            "a typed sentence read as free text: {t}"
        );
    }
}
