//! Caps that are told (issue 26 item 5). `COMPANION_LOG_MAX_BYTES` set to anything but a number
//! of bytes stops the start naming the value (it silently became 1 GiB); the tlog's cap is said
//! like the decision log's: a stderr line, a `tlog_cap` loss line in the decision log, the end
//! line's count, and the review.

use companion::decision_log::{
    DecisionLog, Header, TlogWriter, WriterOptions, parse_max_bytes, read_log,
};
use companion::review::{render_terminal, review_path};
use companion_core::record::DecisionRecord;
use std::process::Command;

#[test]
fn log_max_bytes_that_is_no_size_is_an_error_naming_it() {
    for bad in [
        "abc",
        "100KB",
        "-5",
        "",
        "0",
        "1e9",
        "1 000",
        "+7",
        "99999999999999999999999",
    ] {
        let e = parse_max_bytes(bad).expect_err(bad);
        assert_eq!(e.value, bad);
        assert!(e.to_string().contains(&format!("{bad:?}")), "{e}");
    }
    assert_eq!(parse_max_bytes("4096"), Ok(4096));
    assert_eq!(parse_max_bytes(" 1073741824\n"), Ok(1 << 30));
}

#[test]
fn simulate_and_fly_refuse_to_start_with_an_unparsable_cap() {
    let d = tempfile::tempdir().unwrap();
    for bad in ["abc", "100KB", "-5"] {
        let o = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args(["simulate", "--steps", "3", "--runs-dir"])
            .arg(d.path())
            .env("COMPANION_LOG_MAX_BYTES", bad)
            .output()
            .unwrap();
        assert!(!o.status.success(), "simulate started with {bad:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("COMPANION_LOG_MAX_BYTES={bad:?}")),
            "{err}"
        );
        // The fly start fails the same way, before it opens the link or a run folder.
        let o = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args([
                "fly",
                "--connect",
                "udpin:127.0.0.1:14598",
                "--duration",
                "3s",
                "--auto-start",
                "--log-dir",
            ])
            .arg(d.path())
            .env("COMPANION_LOG_MAX_BYTES", bad)
            .output()
            .unwrap();
        assert!(!o.status.success(), "fly started with {bad:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains(&format!("COMPANION_LOG_MAX_BYTES={bad:?}")),
            "{err}"
        );
    }
    assert_eq!(
        std::fs::read_dir(d.path()).unwrap().count(),
        0,
        "no run folder"
    );
}

#[test]
fn a_capped_tlog_is_said_in_the_decision_log_and_its_review() {
    let d = tempfile::tempdir().unwrap();
    let mut log = DecisionLog::start(
        d.path(),
        Header::new("t", std::time::SystemTime::now()),
        WriterOptions::default(),
    )
    .unwrap();
    // Room for two 8 + 20 byte entries.
    let mut tlog = TlogWriter::create(&d.path().join("flight.tlog"))
        .unwrap()
        .with_max_bytes(60);
    log.watch_tlog(tlog.capped_counter());
    let frame = [
        0xFEu8, 12, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
    ];
    let rec = |c: u64| DecisionRecord {
        cycle: c,
        time_s: c as f64,
        state: "wpi".into(),
        ..Default::default()
    };
    for c in 0..5u64 {
        for _ in 0..3 {
            let _ = tlog.write(c, &frame);
        }
        log.record(rec(c));
    }
    // Frames capped after the last record are still said at close.
    let _ = tlog.write(9, &frame);
    assert_eq!(tlog.frames(), 2);
    assert_eq!(tlog.capped(), 14);
    let stats = log.close();
    assert_eq!(stats.tlog_capped, 14);
    assert_eq!(
        (stats.records, stats.dropped),
        (5, 0),
        "records are not what was capped"
    );

    let text = std::fs::read_to_string(d.path().join("decisions.jsonl")).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let losses: Vec<&serde_json::Value> =
        lines.iter().filter(|l| l["reason"] == "tlog_cap").collect();
    // One at once (before the first record after the cap), the rest at close.
    assert_eq!(losses.len(), 2, "{text}");
    assert_eq!(losses[0]["kind"], "loss");
    assert_eq!(
        losses
            .iter()
            .map(|l| l["dropped"].as_u64().unwrap())
            .sum::<u64>(),
        14
    );
    let end = lines.last().unwrap();
    assert_eq!(
        (end["kind"].as_str(), end["tlog_capped"].as_u64()),
        (Some("end"), Some(14))
    );

    let read = read_log(d.path()).unwrap();
    assert_eq!(read.tlog_capped, 14);
    assert_eq!(read.dropped(), 0);
    assert_eq!(read.records.len(), 5);
    let rev = review_path(d.path(), None).unwrap();
    assert_eq!(rev.summary.tlog_capped, 14);
    assert_eq!(rev.summary.dropped, 0);
    let shown = render_terminal(&rev, false);
    assert!(
        shown.contains("flight.tlog capped") && shown.contains("14 telemetry frames"),
        "{shown}"
    );
}
