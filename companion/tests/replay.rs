//! `companion replay` against real `companion simulate` run folders: every cycle of a fresh run
//! replays equal; an edited record is named with its cycle and field (exit 1); a log whose
//! params or header are missing is refused naming the file and line (exit 2).

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn companion() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_companion"));
    c.env("COMPANION_PARAMS", companion::params::default_params_dir());
    c
}

/// `companion simulate` into a fresh runs dir under `base`; the run folder it made.
fn simulate(base: &Path, name: &str, args: &[&str]) -> PathBuf {
    let runs = base.join(name);
    let out = companion()
        .arg("simulate")
        .args(args)
        .arg("--runs-dir")
        .arg(&runs)
        .output()
        .unwrap();
    assert!(out.status.success(), "simulate {args:?}: {}", text(&out));
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&runs)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    dirs.pop().unwrap()
}

fn replay(run: &Path) -> Output {
    companion().arg("replay").arg(run).output().unwrap()
}

fn text(out: &Output) -> String {
    format!(
        "exit {:?}\n--- stdout\n{}--- stderr\n{}",
        out.status.code(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn log_lines(run: &Path) -> Vec<String> {
    std::fs::read_to_string(run.join("decisions.jsonl"))
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

fn write_lines(run: &Path, lines: &[String]) {
    std::fs::write(run.join("decisions.jsonl"), lines.join("\n") + "\n").unwrap();
}

fn n_records(run: &Path) -> usize {
    log_lines(run)
        .iter()
        .filter(|l| {
            serde_json::from_str::<Value>(l)
                .unwrap()
                .get("kind")
                .is_none()
        })
        .count()
}

/// A copy of `run` to edit.
fn copy_run(run: &Path, to: &Path) -> PathBuf {
    std::fs::create_dir_all(to).unwrap();
    std::fs::copy(run.join("decisions.jsonl"), to.join("decisions.jsonl")).unwrap();
    to.to_path_buf()
}

#[test]
fn fresh_simulate_runs_replay_equal_in_every_cycle() {
    let tmp = tempfile::tempdir().unwrap();
    for scenario in ["complete-1", "lidar-failure"] {
        for policy in ["safety", "mission"] {
            let run = simulate(
                tmp.path(),
                &format!("{scenario}-{policy}"),
                &["--scenario", scenario, "--policy", policy],
            );
            let out = replay(&run);
            assert_eq!(
                out.status.code(),
                Some(0),
                "{scenario} {policy}: {}",
                text(&out)
            );
            let n = n_records(&run);
            assert!(n > 10, "{scenario} {policy}: {n} records");
            let said = String::from_utf8_lossy(&out.stdout);
            assert!(
                said.contains(&format!("all {n} cycles equal")),
                "{scenario} {policy}: {said}"
            );
        }
    }
}

/// `simulate --model reference,bfm` logs the first run of the first model, and its header says
/// which (`model`): replay must build that model, so a header naming another one makes the
/// records differ. A header without `model` (an older build's log) falls back to the command.
#[test]
fn replay_builds_the_model_the_header_names() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(
        tmp.path(),
        "reference",
        &["--scenario", "complete-1", "--model", "reference,bfm"],
    );
    let out = replay(&run);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    let header: Value = serde_json::from_str(&log_lines(&run)[0]).unwrap();
    assert_eq!(header["model"], "reference");

    let edit = |name: &str, f: &dyn Fn(&mut Value)| {
        let edited = copy_run(&run, &tmp.path().join(name));
        let mut lines = log_lines(&edited);
        let mut header: Value = serde_json::from_str(&lines[0]).unwrap();
        f(&mut header);
        lines[0] = header.to_string();
        write_lines(&edited, &lines);
        replay(&edited)
    };
    let differs = |out: &Output| {
        assert_eq!(out.status.code(), Some(1), "{}", text(out));
        assert!(
            String::from_utf8_lossy(&out.stdout).contains("cycle 0 differs"),
            "{}",
            text(out)
        );
    };
    differs(&edit("as-bfm", &|h| h["model"] = Value::from("bfm")));
    let old_log = edit("old-log", &|h| {
        h.as_object_mut().unwrap().remove("model");
    });
    assert_eq!(old_log.status.code(), Some(0), "{}", text(&old_log));
    differs(&edit("old-log-as-bfm", &|h| {
        h.as_object_mut().unwrap().remove("model");
        let command = h["command"]
            .as_str()
            .unwrap()
            .replace("reference,bfm", "bfm");
        h["command"] = Value::from(command);
    }));
    let bad = edit("unknown-model", &|h| h["model"] = Value::from("oracle"));
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad));
    assert!(text(&bad).contains("header model"), "{}", text(&bad));
}

#[test]
fn an_edited_probability_is_reported_with_its_cycle_field_and_both_values() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(tmp.path(), "run", &["--scenario", "complete-1"]);
    let edited = copy_run(&run, &tmp.path().join("edited"));
    let mut lines = log_lines(&edited);
    // Line 13 is the record of cycle 11 (line 1 is the header).
    let mut rec: Value = serde_json::from_str(&lines[12]).unwrap();
    assert_eq!(rec["cycle"], 11);
    let (name, was) = {
        let (k, v) = rec["probabilities"]
            .as_object()
            .unwrap()
            .iter()
            .next()
            .unwrap();
        (k.clone(), v.as_f64().unwrap())
    };
    let now = if was > 0.5 { was - 0.125 } else { was + 0.125 };
    rec["probabilities"][&name] = Value::from(now);
    lines[12] = rec.to_string();
    write_lines(&edited, &lines);

    let out = replay(&edited);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("cycle 11 differs"), "{said}");
    assert!(said.contains("decisions.jsonl:13"), "{said}");
    assert!(said.contains(&format!("probabilities.{name}")), "{said}");
    assert!(
        said.contains(&format!("logged {}", Value::from(now)))
            && said.contains(&format!("replayed {}", Value::from(was))),
        "{said}"
    );
    assert!(said.contains("11 cycles before it equal"), "{said}");

    // An edited input changes what the core decides from there on.
    let inputs = copy_run(&run, &tmp.path().join("inputs"));
    let mut lines = log_lines(&inputs);
    let mut rec: Value = serde_json::from_str(&lines[5]).unwrap();
    rec["observations"]["battery_pct"] = Value::from(3.0);
    lines[5] = rec.to_string();
    write_lines(&inputs, &lines);
    let out = replay(&inputs);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("cycle 4 differs"),
        "{}",
        text(&out)
    );
}

#[test]
fn a_log_without_the_params_text_or_header_is_refused_naming_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(tmp.path(), "run", &["--scenario", "complete-1"]);

    // A params file the model needs, logged only by its hash.
    let hashed = copy_run(&run, &tmp.path().join("hashed"));
    let mut lines = log_lines(&hashed);
    let mut header: Value = serde_json::from_str(&lines[0]).unwrap();
    header["params"]["mission.toml"] = Value::from("fnv1a64:0123456789abcdef (2000000 bytes)");
    lines[0] = header.to_string();
    write_lines(&hashed, &lines);
    let out = replay(&hashed);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("decisions.jsonl:1"), "{said}");
    assert!(
        said.contains("mission.toml") && said.contains("hash"),
        "{said}"
    );

    // No params at all.
    let empty = copy_run(&run, &tmp.path().join("no-params"));
    let mut lines = log_lines(&empty);
    let mut header: Value = serde_json::from_str(&lines[0]).unwrap();
    header["params"] = serde_json::json!({});
    lines[0] = header.to_string();
    write_lines(&empty, &lines);
    let out = replay(&empty);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("decisions.jsonl:1: the header holds no params"),
        "{}",
        text(&out)
    );

    // The header line gone: the first line is a record.
    let headless = copy_run(&run, &tmp.path().join("headless"));
    let lines = log_lines(&headless);
    write_lines(&headless, &lines[1..]);
    let out = replay(&headless);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("decisions.jsonl:1") && said.contains("before any header"),
        "{said}"
    );

    // Records lost mid-log: the core's state after them is unknown.
    let lossy = copy_run(&run, &tmp.path().join("loss"));
    let mut lines = log_lines(&lossy);
    lines[4] = r#"{"kind":"loss","dropped":1,"reason":"queue_full"}"#.into();
    write_lines(&lossy, &lines);
    let out = replay(&lossy);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("decisions.jsonl:5: records were lost"),
        "{}",
        text(&out)
    );

    // A record whose observation is not a number.
    let bad = copy_run(&run, &tmp.path().join("bad"));
    let mut lines = log_lines(&bad);
    let mut rec: Value = serde_json::from_str(&lines[3]).unwrap();
    rec["observations"]["battery_pct"] = Value::Null;
    lines[3] = rec.to_string();
    write_lines(&bad, &lines);
    let out = replay(&bad);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("decisions.jsonl:4"),
        "{}",
        text(&out)
    );
}

/// The events the core appends (a re-allocation when PANORAMA makes one) come after the
/// observed ones; an event after them in a simulate log is not the core's.
#[test]
fn an_event_after_the_core_added_ones_is_reported_on_events() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(
        tmp.path(),
        "run",
        &["--scenario", "lidar-failure", "--policy", "mission"],
    );
    let mut lines = log_lines(&run);
    // The first record with a re-allocation: the core said so in its events, last.
    let (i, mut rec) = lines
        .iter()
        .enumerate()
        .map(|(i, l)| (i, serde_json::from_str::<Value>(l).unwrap()))
        .find(|(_, v)| v.get("kind").is_none() && !v["guarantee"]["reallocation"].is_null())
        .expect("the lidar failure makes PANORAMA re-allocate");
    let reason = rec["guarantee"]["reallocation"]["reason"]
        .as_str()
        .unwrap()
        .to_string();
    let last = rec["events"].as_array().unwrap().last().unwrap()["text"]
        .as_str()
        .unwrap();
    assert!(last.contains(&reason), "{rec}");
    let cycle = rec["cycle"].as_u64().unwrap();
    rec["events"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::to_value(companion_core::record::Event::Mode("LAND".into())).unwrap());
    lines[i] = rec.to_string();
    let edited = tmp.path().join("edited");
    std::fs::create_dir_all(&edited).unwrap();
    write_lines(&edited, &lines);
    let out = replay(&edited);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.contains(&format!("cycle {cycle} differs")) && said.contains("events"),
        "{said}"
    );
}

/// A log rotated into parts (each starting with a copy of the header) replays as one; a last
/// line cut off by a kill is named and not replayed.
#[test]
fn rotated_parts_replay_as_one_log_and_a_cut_off_last_line_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(tmp.path(), "run", &["--scenario", "complete-1"]);
    let lines = log_lines(&run);
    let n = n_records(&run);
    let rotated = tmp.path().join("rotated");
    std::fs::create_dir_all(&rotated).unwrap();
    let mut header: Value = serde_json::from_str(&lines[0]).unwrap();
    let half = lines.len() / 2;
    write_lines(&rotated, &lines[..half]);
    header["part"] = Value::from(1);
    let mut part1 = vec![header.to_string()];
    part1.extend_from_slice(&lines[half..]);
    std::fs::write(rotated.join("decisions.1.jsonl"), part1.join("\n") + "\n").unwrap();
    let out = replay(&rotated);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&format!("all {n} cycles equal")),
        "{}",
        text(&out)
    );

    // Killed while writing the last record: no end line, the record cut in half.
    let killed = tmp.path().join("killed");
    std::fs::create_dir_all(&killed).unwrap();
    let last = lines.len() - 2; // the last record (the end line follows it)
    let mut body = lines[..last].join("\n") + "\n";
    body.push_str(&lines[last][..lines[last].len() / 2]);
    std::fs::write(killed.join("decisions.jsonl"), body).unwrap();
    let out = replay(&killed);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(&format!("all {} cycles equal", n - 1)),
        "{}",
        text(&out)
    );
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains(&format!("decisions.jsonl:{}: last line cut off", last + 1)),
        "{}",
        text(&out)
    );
}

/// A `fly` log holding two flights: the second starts at the record carrying the new-flight
/// event (written as the sentence fly has always written), where fly started a fresh core, and
/// replay restarts its own core there; without the event the second flight replays against the
/// first flight's core and differs.
#[test]
fn a_fly_log_restarts_the_core_at_the_new_flight_event() {
    let tmp = tempfile::tempdir().unwrap();
    let run = simulate(
        tmp.path(),
        "run",
        &["--scenario", "complete-1", "--policy", "safety"],
    );
    let lines = log_lines(&run);
    let mut header: Value = serde_json::from_str(&lines[0]).unwrap();
    let command = header["command"]
        .as_str()
        .unwrap()
        .replace(" simulate ", " fly ");
    assert!(command.contains(" fly "), "{command}");
    header["command"] = Value::from(command);
    let flight: Vec<Value> = lines[1..]
        .iter()
        .map(|l| serde_json::from_str::<Value>(l).unwrap())
        .filter(|v| v.get("kind").is_none())
        .take(20)
        .collect();
    assert_eq!(flight.len(), 20);
    let two_flights = |event: Option<Value>| {
        let mut second = flight.clone();
        if let Some(e) = event {
            // Observed before the cycle: the head of the record's events.
            second[0]["events"]
                .as_array_mut()
                .unwrap()
                .insert(0, e.clone());
        }
        let mut out = vec![header.to_string()];
        out.extend(flight.iter().chain(&second).map(Value::to_string));
        out
    };
    let dir = tmp.path().join("two");
    std::fs::create_dir_all(&dir).unwrap();
    write_lines(
        &dir,
        &two_flights(Some(
            serde_json::to_value(companion_core::record::Event::NewFlight).unwrap(),
        )),
    );
    let out = replay(&dir);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));
    write_lines(&dir, &two_flights(None));
    let out = replay(&dir);
    assert_eq!(out.status.code(), Some(1), "{}", text(&out));
}
