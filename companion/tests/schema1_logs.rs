//! Logs written by a schema-1 build (kept in tests/fixtures/schema1, never regenerated) still
//! read, review and replay: their sentences come back as the typed values, and the review of a
//! kept log equals the review of the same log rewritten at schema 2.

use companion::decision_log::{SCHEMA_VERSION, read_log};
use companion_core::record::{CommandOutcome, Event, LinkEvent};
use std::path::{Path, PathBuf};
use std::process::Command;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/schema1")
        .join(name)
}

const FIXTURES: [&str; 4] = [
    "simulate-complete-1",
    "simulate-lidar-failure",
    "simulate-emergency-landing",
    "fly-standin",
];

fn companion(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_companion"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn kept_schema_1_logs_read_as_typed_values() {
    assert_eq!(SCHEMA_VERSION, 2);
    for name in FIXTURES {
        let log = read_log(&fixture(name)).unwrap();
        let h = log.header.as_ref().unwrap();
        assert_eq!(h.schema, 1, "{name}");
        assert!(log.corrupted.is_empty(), "{name}: {:?}", log.corrupted);
        assert!(log.records.len() > 10, "{name}");
    }
    let fly = read_log(&fixture("fly-standin")).unwrap();
    let events: Vec<&Event> = fly.records.iter().flat_map(|r| &r.events).collect();
    assert!(
        events.contains(&&Event::Mode("GUIDED".into())),
        "{events:?}"
    );
    assert!(events.iter().any(|e| matches!(
        e,
        Event::Command {
            outcome: CommandOutcome::Accepted,
            ..
        }
    )));
    let links: Vec<&LinkEvent> = fly.records.iter().flat_map(|r| &r.link_events).collect();
    assert!(links.iter().any(|l| matches!(
        l,
        LinkEvent::Stream {
            outcome: CommandOutcome::Accepted,
            ..
        }
    )));
    assert!(links.contains(&&LinkEvent::MissionUploaded { items: 8 }));
    let results: Vec<&CommandOutcome> = fly
        .records
        .iter()
        .flat_map(|r| r.commands.iter().map(|c| &c.result))
        .collect();
    assert!(results.contains(&&CommandOutcome::AcceptedVerified { items: 8 }));
    assert!(
        results
            .iter()
            .any(|o| matches!(o, CommandOutcome::WaitingReady(_)))
    );
    assert!(
        !results
            .iter()
            .any(|o| matches!(o, CommandOutcome::Other(_)))
    );
    let sim = read_log(&fixture("simulate-lidar-failure")).unwrap();
    let events: Vec<&Event> = sim.records.iter().flat_map(|r| &r.events).collect();
    assert!(
        events.iter().any(|e| matches!(e, Event::Reallocation(_))),
        "{events:?}"
    );
}

#[test]
fn kept_schema_1_logs_replay_equal() {
    for name in FIXTURES {
        let dir = fixture(name);
        let out = companion(&["replay", dir.to_str().unwrap()]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{name}: {stdout}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(stdout.contains("cycles equal"), "{name}: {stdout}");
    }
}

/// The log rewritten at schema 2 from its records as read: the header's schema raised, each
/// record written again from its typed value.
fn rewritten_at_schema_2(name: &str, dir: &Path) -> PathBuf {
    let log = read_log(&fixture(name)).unwrap();
    let mut header = log.header.clone().unwrap();
    header.schema = SCHEMA_VERSION;
    let mut text = serde_json::to_string(&header).unwrap() + "\n";
    for r in &log.records {
        let line = serde_json::to_string(r).unwrap();
        assert!(!line.contains("\"events\":[\""), "a sentence left: {line}");
        text += &line;
        text.push('\n');
    }
    text += "{\"kind\":\"end\",\"records\":0,\"events\":0,\"dropped\":0}\n";
    let out = dir.join(name);
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("decisions.jsonl"), text).unwrap();
    out
}

#[test]
fn review_and_replay_read_schema_1_and_its_schema_2_rewrite_alike() {
    let tmp = tempfile::tempdir().unwrap();
    for name in FIXTURES {
        let v2 = rewritten_at_schema_2(name, tmp.path());
        let kept = fixture(name);
        let review = |p: &Path| {
            let out = companion(&["review", p.to_str().unwrap(), "--summary"]);
            assert!(out.status.success(), "{name}");
            String::from_utf8(out.stdout).unwrap()
        };
        let (old, new) = (review(&kept), review(&v2));
        assert!(old.contains("Summary"), "{old}");
        assert_eq!(old, new, "{name}: the review differs between the schemas");
        let replay = companion(&["replay", v2.to_str().unwrap()]);
        assert!(
            replay.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&replay.stdout)
        );
    }
}
