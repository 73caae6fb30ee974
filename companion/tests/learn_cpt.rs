//! In-flight CPT learning (`simulate --learn-cpt`, docs/calibrate.md): on a params copy whose
//! world loses the target with V3 under vibrations in 70 % of the steps (the shipped BN row
//! `C_V3[U_vibration present, others absent]` says 0.9982 kept), the row learned during the run
//! moves toward the truth within params/learning.toml's bound, changes the decision it should,
//! and `companion replay` re-derives every update; off, records carry nothing new.

mod common;
use common::copy_dir;
use common::text;
use companion::params::default_params_dir;
use serde_json::Value;
use std::path::Path;

/// The binary under test (named here: scripts/arm.sh skips tests that start it under qemu).
const BIN: &str = env!("CARGO_BIN_EXE_companion");

fn companion(args: &[&str]) -> std::process::Output {
    common::run_companion(BIN, args)
}

const TRUE_ROW: f64 = 0.30;
const SHIPPED_ROW: f64 = 0.9982;

/// A params copy whose world keeps the target with V3 under vibrations in 30 % of the steps,
/// with a scenario shaking the drone from the start of tracking.
fn world_unlike_the_bn(dir: &Path) {
    std::fs::create_dir_all(dir).unwrap();
    copy_dir(&default_params_dir(), dir);
    let world = dir.join("world.toml");
    let w = std::fs::read_to_string(&world).unwrap();
    let at = w.find("[truth.qos.vibrations]").unwrap();
    let v3 = at + w[at..].find("V3 = 0.90").unwrap();
    std::fs::write(&world, format!("{}V3 = 0.30{}", &w[..v3], &w[v3 + 9..])).unwrap();
    std::fs::write(
        dir.join("scenarios/shaky.toml"),
        "name = \"shaky\"\ndescription = \"vibrations from the start of tracking\"\nsteps = 200\n\
         [[hazard]]\nevent = \"vibrations\"\ntrigger = { phase = \"tracking\", after = 0 }\n\
         set = { vibration_mps2 = 25.0 }\n",
    )
    .unwrap();
}

fn decisions(params: &Path, extra: &[&str]) -> Vec<Value> {
    let mut args = vec![
        "simulate",
        "--params",
        params.to_str().unwrap(),
        "--scenario",
        "shaky",
        "--seed",
        "1",
        "--no-log",
        "--json",
    ];
    args.extend_from_slice(extra);
    let o = companion(&args);
    assert!(o.status.success(), "{}", text(&o));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    v["decisions"].as_array().unwrap().clone()
}

/// The V3 vibration row's updates, in order.
fn v3_updates(records: &[Value]) -> Vec<Value> {
    records
        .iter()
        .flat_map(|r| r["cpt_learned"].as_array().cloned().unwrap_or_default())
        .filter(|u| {
            u["node"] == "C_V3"
                && u["when"]["U_vibration"] == "present"
                && u["when"]["U_point_lost"] == "absent"
                && u["when"]["U_motion_lost"] == "absent"
        })
        .collect()
}

fn has_track_v3(r: &Value) -> bool {
    r["actions"]
        .as_array()
        .unwrap()
        .iter()
        .any(|a| a == "track_v3")
}

#[test]
fn the_row_learned_in_flight_moves_to_the_truth_within_its_bound_and_changes_the_decision() {
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("params");
    world_unlike_the_bn(&params);

    let fixed = decisions(&params, &[]);
    let learning = decisions(&params, &["--learn-cpt"]);
    assert!(
        fixed.iter().all(|r| r.get("cpt_learned").is_none()),
        "off, no record carries learned rows"
    );

    let ups = v3_updates(&learning);
    assert!(ups.len() >= 10, "V3 tracked under vibrations: {ups:?}");
    let first = &ups[0];
    assert!(
        (first["prior"].as_f64().unwrap() - SHIPPED_ROW).abs() < 1e-9,
        "{first}"
    );
    for (i, u) in ups.iter().enumerate() {
        let (old, new) = (u["old"].as_f64().unwrap(), u["new"].as_f64().unwrap());
        assert_eq!(u["trials"].as_u64(), Some(i as u64 + 1), "{u}");
        // The default bound (params/learning.toml): within 0.6 of the row as loaded.
        assert!(SHIPPED_ROW - new <= 0.6 + 1e-12, "{u}");
        if i > 0 {
            assert_eq!(old, ups[i - 1]["new"].as_f64().unwrap(), "{u}");
        }
    }
    let last = ups.last().unwrap()["new"].as_f64().unwrap();
    assert!(
        last < 0.55 && last > TRUE_ROW,
        "the row moves from {SHIPPED_ROW} toward {TRUE_ROW}: {last}"
    );

    // Without learning the drone tracks with V3 whenever it does; with it, once the row has
    // fallen, the same cycle decides otherwise (the first cycle where the runs differ).
    let first_diff = fixed
        .iter()
        .zip(&learning)
        .position(|(a, b)| a["actions"] != b["actions"])
        .expect("learning the row changes a decision");
    let (a, b) = (&fixed[first_diff], &learning[first_diff]);
    assert!(has_track_v3(a) && !has_track_v3(b), "{a}\n{b}");
    let p = |r: &Value| r["probabilities"]["P_V3"].as_f64().unwrap();
    assert!(p(b) < p(a) - 0.3, "P_V3 learned {} vs {}", p(b), p(a));
}

#[test]
fn a_learning_run_replays_without_a_mismatch() {
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("params");
    world_unlike_the_bn(&params);
    let runs = tmp.path().join("runs");
    let o = companion(&[
        "simulate",
        "--params",
        params.to_str().unwrap(),
        "--scenario",
        "shaky",
        "--seed",
        "1",
        "--learn-cpt",
        "--runs-dir",
        runs.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let run = std::fs::read_dir(&runs)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let log = std::fs::read_to_string(run.join("decisions.jsonl")).unwrap();
    assert!(
        log.contains("\"cpt_learned\""),
        "the log holds the learned rows"
    );
    let o = companion(&["replay", run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));

    // A logged update that the records do not give is found.
    let tampered = log.replacen("\"successes\":0", "\"successes\":1", 1);
    assert_ne!(tampered, log);
    std::fs::write(run.join("decisions.jsonl"), tampered).unwrap();
    let o = companion(&["replay", run.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("cpt_learned"), "{}", text(&o));
}

#[test]
fn a_tighter_bound_holds_the_row_and_the_decision() {
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("params");
    world_unlike_the_bn(&params);
    std::fs::write(params.join("learning.toml"), "[cpt]\nmax_change = 0.2\n").unwrap();
    let ups = v3_updates(&decisions(&params, &["--learn-cpt"]));
    assert!(!ups.is_empty());
    for u in &ups {
        assert!(
            SHIPPED_ROW - u["new"].as_f64().unwrap() <= 0.2 + 1e-12,
            "{u}"
        );
    }
    let last = ups.last().unwrap();
    assert_eq!(
        last["bounded"], true,
        "the Dirichlet mean went past the bound: {last}"
    );
}

#[test]
fn a_malformed_learning_setting_is_refused_with_file_entry_and_reason() {
    let tmp = tempfile::tempdir().unwrap();
    let params = tmp.path().join("params");
    std::fs::create_dir_all(&params).unwrap();
    copy_dir(&default_params_dir(), &params);
    for (body, entry, reason) in [
        (
            "[cpt]\nmax_change = 1.5\n",
            "cpt.max_change",
            "not a probability change in (0, 1]",
        ),
        (
            "[cpt]\nmax_change = 0.0\n",
            "cpt.max_change",
            "not a probability change in (0, 1]",
        ),
        (
            "[cpt]\nmax_chnage = 0.5\n",
            "cpt.max_chnage",
            "unknown entry",
        ),
        (
            "[cpt]\nmax_change = \"half\"\n",
            "cpt.max_change",
            "is not a number",
        ),
        ("[cpt\n", "learning.toml", "not TOML"),
    ] {
        std::fs::write(params.join("learning.toml"), body).unwrap();
        for cmd in ["check", "simulate"] {
            let o = companion(
                &[cmd, "--params", params.to_str().unwrap(), "--no-log"]
                    [..if cmd == "check" { 3 } else { 4 }],
            );
            let t = text(&o);
            assert!(!o.status.success(), "{cmd} {body}: {t}");
            assert!(t.contains("learning.toml"), "{cmd} {body}: {t}");
            assert!(t.contains(entry) && t.contains(reason), "{cmd} {body}: {t}");
        }
    }
}
