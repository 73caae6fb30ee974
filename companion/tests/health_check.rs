//! `companion check` end to end: human and JSON output, evidence showing the paper's figures.

mod common;

fn check(args: &[&str]) -> (bool, String, String) {
    let (code, out, err) = common::check_run(env!("CARGO_BIN_EXE_companion"), args);
    (code == Some(0), out, err)
}

#[test]
fn json_lists_managers_nodes_and_publishes() {
    let (ok, out, err) = check(&["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let health = v["health"].as_array().unwrap();
    let names: Vec<&str> = health.iter().map(|h| h["name"].as_str().unwrap()).collect();
    for want in ["applications", "sensors", "system", "resources"] {
        assert!(names.contains(&want), "{names:?}");
    }
    for h in health {
        assert!(!h["nodes"].as_array().unwrap().is_empty());
        for n in h["nodes"].as_array().unwrap() {
            assert!(n["name"].is_string() && n["role"].is_string() && n["states"].is_array());
        }
        for p in h["publishes"].as_array().unwrap() {
            let x = p["value"].as_f64().unwrap();
            assert!((0.0..=1.0).contains(&x));
        }
    }
}

#[test]
fn evidence_shows_figure_4() {
    let (ok, out, err) = check(&[
        "--json",
        "--evidence",
        "wind=strong,target_speed=high,qos=high",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let apps = v["health"]
        .as_array()
        .unwrap()
        .iter()
        .find(|h| h["name"] == "applications")
        .unwrap();
    let node = |n: &str| {
        apps["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x["name"] == n)
            .unwrap()
            .clone()
    };
    let stab = node("C_stabilization")["posterior"][1].as_f64().unwrap();
    let roi = node("C_roi_resize")["posterior"][1].as_f64().unwrap();
    assert_eq!((stab * 100.0).round() / 100.0, 0.60);
    assert_eq!((roi * 100.0).round() / 100.0, 0.72);
    assert_eq!(node("QoS")["evidence"], "high");
    // Human output names the evidence.
    let (ok, out, _) = check(&["--evidence", "luminosity=low"]);
    assert!(ok);
    assert!(
        out.contains("A_luminosity") && out.contains("<- evidence low"),
        "{out}"
    );
    assert!(out.contains("publishes P_V3"), "{out}");
}

#[test]
fn bad_input_fails_with_a_reason() {
    let (ok, _, err) = check(&["--evidence", "wind=gale"]);
    assert!(!ok);
    assert!(err.contains("no state `gale`"), "{err}");
    let (ok, _, err) = check(&["--params", "/nonexistent/params"]);
    assert!(!ok);
    assert!(err.contains("/nonexistent/params"), "{err}");
}

/// `check --json`'s `probabilities`: every published name once, with the manager that publishes
/// it and every MDP that reads it among its consumers; nothing published goes unread.
#[test]
fn json_lists_each_probability_with_its_publisher_and_readers() {
    let (ok, out, err) = check(&["--json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let listed = v["probabilities"].as_array().unwrap();
    let mut published = Vec::new();
    for h in v["health"].as_array().unwrap() {
        for p in h["publishes"].as_array().unwrap() {
            let name = p["name"].as_str().unwrap();
            published.push(name);
            let entry: Vec<_> = listed.iter().filter(|x| x["name"] == name).collect();
            assert_eq!(entry.len(), 1, "{name}");
            assert_eq!(entry[0]["publisher"], h["name"], "{name}");
            assert!(
                !entry[0]["consumers"].as_array().unwrap().is_empty(),
                "{name} has no reader"
            );
        }
    }
    assert_eq!(listed.len(), published.len());
    for m in v["mdps"].as_array().unwrap() {
        for p in m["probabilities"].as_array().unwrap() {
            let entry = listed.iter().find(|x| x["name"] == *p).unwrap();
            assert!(
                entry["consumers"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|c| c["kind"] == "mdp" && c["name"] == m["name"]),
                "{p} read by {} but not listed",
                m["name"]
            );
        }
    }
}
