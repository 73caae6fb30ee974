//! Decision log writer and reader: loss accounting under a stalled writer, rotation,
//! flush-per-record, tolerant reading, and a SIGKILL of a process in the middle of writing.

use companion::decision_log::{
    DecisionLog, Header, ReadError, SCHEMA_VERSION, WriterOptions, part_path, read_log,
};
use companion_core::record::DecisionRecord;
use companion_testkit::synthetic;
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, UNIX_EPOCH};

fn header() -> Header {
    Header::new("companion simulate --policy safety", UNIX_EPOCH)
}

fn rec(i: u64) -> DecisionRecord {
    let mut r = synthetic::record(i % 100, 100);
    r.cycle = i;
    r.time_s = i as f64;
    r
}

/// Lines of a file, by a plain split (independent of the reader under test).
fn raw_lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// Wait (bounded) until `cond` holds; a correctness wait, not a speed assertion.
fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120); // generous: a loaded CI machine
    while !cond() {
        assert!(Instant::now() < deadline, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn records_round_trip_bit_exact_with_header_first() {
    let dir = tempfile::tempdir().unwrap();
    let recs = synthetic::mission(100);
    let log = DecisionLog::start(dir.path(), header(), WriterOptions::default()).unwrap();
    for r in &recs {
        assert!(log.record(r.clone()));
    }
    assert!(log.event(50, 50.0, "mode RTL"));
    let stats = log.close();
    assert_eq!(
        (stats.records, stats.events, stats.dropped, stats.parts),
        (100, 1, 0, 1)
    );

    let lines = raw_lines(&part_path(dir.path(), 0));
    // header + 100 records + 1 event + end line
    assert_eq!(lines.len(), 103);
    let h: serde_json::Value = serde_json::from_str(&lines[0]).unwrap();
    assert_eq!(h["schema"], SCHEMA_VERSION);
    assert_eq!(h["kind"], "header");
    for key in ["started_utc", "git_revision", "command", "params"] {
        assert!(h.get(key).is_some(), "header lacks {key}");
    }
    assert_eq!(h["started_utc"], "1970-01-01T00:00:00Z");
    let end: serde_json::Value = serde_json::from_str(lines.last().unwrap()).unwrap();
    assert_eq!(end["kind"], "end");
    assert_eq!(end["records"], 100);

    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.records, recs);
    assert_eq!(read.events.len(), 1);
    assert_eq!(read.events[0].event, "mode RTL");
    assert!(read.ended_cleanly && read.corrupted.is_empty() && read.truncated.is_none());
    assert_eq!(
        read.header.unwrap().command,
        "companion simulate --policy safety"
    );
}

#[test]
fn stalled_writer_drops_are_counted_and_logged() {
    let dir = tempfile::tempdir().unwrap();
    let stall = Arc::new(Mutex::new(()));
    let guard = stall.lock().unwrap();
    let capacity = 4;
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            capacity,
            stall: Some(stall.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let sent = 20u64;
    let results: Vec<bool> = (0..sent).map(|i| log.record(rec(i))).collect();
    let accepted = results.iter().filter(|&&ok| ok).count() as u64;
    // The channel holds `capacity`; the writer takes at most one more off it before it blocks
    // on the stall. Which one it takes, and so which sends succeed, depends on when the writer
    // thread runs: the expected file is built from what `record` actually answered.
    assert!(
        accepted == capacity as u64 || accepted == capacity as u64 + 1,
        "{accepted}"
    );
    assert_eq!(log.dropped(), sent - accepted);
    drop(guard);
    // Let the writer drain, then send fewer than `capacity` more: these must all get through.
    let path = part_path(dir.path(), 0);
    // A record line has no top-level "kind" (loss and end lines do); a half-written line is not one.
    let is_record = |l: &String| {
        serde_json::from_str::<serde_json::Value>(l).is_ok_and(|v| v.get("kind").is_none())
    };
    wait_until("the accepted records on disk", || {
        raw_lines(&path)
            .iter()
            .skip(1)
            .filter(|l| is_record(l))
            .count() as u64
            >= accepted
    });
    for i in 100..103 {
        assert!(log.record(rec(i)));
    }
    let stats = log.close();
    assert_eq!(stats.dropped, sent - accepted);

    // Expected: each run of drops reported by one loss line right before the next record that
    // got through (built from the send results, not from the writer).
    #[derive(Debug, PartialEq)]
    enum Line {
        Record(u64),
        Loss(u64),
    }
    let mut expected = Vec::new();
    let mut pending = 0u64;
    let sends = results
        .iter()
        .copied()
        .zip(0..sent)
        .chain((100..103).map(|i| (true, i)));
    for (ok, i) in sends {
        if !ok {
            pending += 1;
            continue;
        }
        if pending > 0 {
            expected.push(Line::Loss(pending));
            pending = 0;
        }
        expected.push(Line::Record(i));
    }
    let lines = raw_lines(&path);
    let got: Vec<Line> = lines[1..]
        .iter()
        .filter_map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            match v.get("kind").and_then(|k| k.as_str()) {
                None => Some(Line::Record(v["cycle"].as_u64().unwrap())),
                Some("loss") => Some(Line::Loss(v["dropped"].as_u64().unwrap())),
                Some(_) => None, // the end line
            }
        })
        .collect();
    assert_eq!(got, expected);
    assert!(
        got.iter().any(|l| matches!(l, Line::Loss(_))),
        "a loss line"
    );

    let read = read_log(dir.path()).unwrap();
    let cycles: Vec<u64> = read.records.iter().map(|r| r.cycle).collect();
    let want: Vec<u64> = expected
        .iter()
        .filter_map(|l| match l {
            Line::Record(c) => Some(*c),
            Line::Loss(_) => None,
        })
        .collect();
    assert_eq!(cycles, want);
    assert_eq!(read.dropped(), sent - accepted);
}

#[test]
fn drops_after_the_last_accepted_record_are_logged_at_close() {
    let dir = tempfile::tempdir().unwrap();
    let stall = Arc::new(Mutex::new(()));
    let guard = stall.lock().unwrap();
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            capacity: 2,
            stall: Some(stall.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let accepted = (0..10).filter(|&i| log.record(rec(i))).count() as u64;
    drop(guard);
    log.close();
    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.records.len() as u64, accepted);
    assert_eq!(read.dropped(), 10 - accepted);
    assert_eq!(read.records.len() as u64 + read.dropped(), 10);
}

#[test]
fn rotation_splits_by_size_and_reads_back_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let one_line = serde_json::to_string(&rec(30)).unwrap().len() as u64 + 1;
    let rotate = 5 * one_line; // a handful of records per part
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            rotate_bytes: rotate,
            ..Default::default()
        },
    )
    .unwrap();
    for i in 0..60 {
        assert!(log.record(rec(i)));
    }
    let stats = log.close();
    assert!(stats.parts >= 5, "{stats:?}");

    let mut total_records = 0;
    for k in 0..stats.parts {
        let p = part_path(dir.path(), k);
        let name = p.file_name().unwrap().to_str().unwrap().to_string();
        assert_eq!(
            name,
            if k == 0 {
                "decisions.jsonl".to_string()
            } else {
                format!("decisions.{k}.jsonl")
            }
        );
        let lines = raw_lines(&p);
        let h: serde_json::Value = serde_json::from_str(&lines[0]).unwrap();
        assert_eq!(
            (h["kind"].as_str(), h["part"].as_u64()),
            (Some("header"), Some(k as u64))
        );
        let size = std::fs::metadata(&p).unwrap().len();
        let body = size - lines[0].len() as u64 - 1;
        // Each part stays within the limit, unless it holds a single line.
        assert!(
            size <= rotate || lines.len() <= 2,
            "part {k}: {size} > {rotate}"
        );
        assert!(body > 0);
        // A record has no top-level `kind` (its events have theirs, nested).
        let is_record =
            |l: &&String| serde_json::from_str::<serde_json::Value>(l).unwrap()["kind"].is_null();
        total_records += lines.iter().filter(is_record).count();
    }
    assert!(!part_path(dir.path(), stats.parts).exists());
    assert_eq!(total_records, 60);

    for input in [dir.path().to_path_buf(), part_path(dir.path(), 0)] {
        let read = read_log(&input).unwrap();
        assert_eq!(read.files.len() as u32, stats.parts);
        let cycles: Vec<u64> = read.records.iter().map(|r| r.cycle).collect();
        assert_eq!(cycles, (0..60).collect::<Vec<_>>());
        assert!(read.ended_cleanly);
    }
}

#[test]
fn each_record_is_on_disk_before_close() {
    let dir = tempfile::tempdir().unwrap();
    let log = DecisionLog::start(dir.path(), header(), WriterOptions::default()).unwrap();
    let path = part_path(dir.path(), 0);
    for i in 0..3 {
        assert!(log.record(rec(i)));
        // Without a flush per record this would not appear until close.
        wait_until("record on disk", || raw_lines(&path).len() as u64 == 2 + i);
    }
    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.records.len(), 3);
    assert!(!read.ended_cleanly); // still open
    log.close();
}

fn write(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
}

fn record_line(i: u64) -> String {
    serde_json::to_string(&rec(i)).unwrap()
}

#[test]
fn newer_schema_is_reviewed_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    let newer = SCHEMA_VERSION + 1;
    // A future record: an extra field, and a future kind of line.
    let mut future: serde_json::Value = serde_json::from_str(&record_line(1)).unwrap();
    future["wind_field"] = serde_json::json!({"u": 1.0});
    write(
        &p,
        &format!(
            "{{\"schema\":{newer},\"kind\":\"header\",\"started_utc\":\"2030-01-01T00:00:00Z\",\"git_revision\":\"abc\",\"command\":\"companion simulate\",\"params\":{{}},\"new_header_field\":true}}\n{}\n{}\n{{\"kind\":\"hologram\",\"x\":1}}\n",
            record_line(0),
            future
        ),
    );
    let read = read_log(&p).unwrap();
    assert_eq!(read.newer_schema, Some(newer));
    assert_eq!(read.records.len(), 2);
    assert_eq!(read.records[1].cycle, 1);
    assert!(
        read.notes[0].contains(&format!("schema {newer}")),
        "{:?}",
        read.notes
    );
    assert!(read.notes[0].contains("newer"));
    assert!(
        read.notes
            .iter()
            .any(|n| n.contains("hologram") && n.contains(":4"))
    );
}

#[test]
fn corrupted_lines_are_skipped_and_reported_with_line_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    let h = serde_json::to_string(&header()).unwrap();
    write(
        &p,
        &format!(
            "{h}\n{}\n{{\"cycle\": 1, \"state\": \"wp1\", GARBAGE\n{}\n[1,2,3]\n{{\"cycle\":\"three\"}}\n\u{0}\u{1}binary\n{}\n",
            record_line(0),
            record_line(2),
            record_line(4),
        ),
    );
    let read = read_log(&p).unwrap();
    let cycles: Vec<u64> = read.records.iter().map(|r| r.cycle).collect();
    assert_eq!(cycles, vec![0, 2, 4]);
    let lines: Vec<usize> = read.corrupted.iter().map(|c| c.line).collect();
    assert_eq!(lines, vec![3, 5, 6, 7]);
    assert!(read.corrupted[0].reason.starts_with("not JSON"));
    assert!(
        read.corrupted[1]
            .reason
            .starts_with("not a decision record")
    );
    assert!(read.truncated.is_none());
}

#[test]
fn invalid_utf8_line_is_corrupted_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    let mut bytes = format!("{}\n", record_line(0)).into_bytes();
    bytes.extend_from_slice(b"\xff\xfe{}\n");
    bytes.extend_from_slice(format!("{}\n", record_line(1)).as_bytes());
    std::fs::write(&p, bytes).unwrap();
    let read = read_log(&p).unwrap();
    assert_eq!(read.records.len(), 2);
    assert_eq!(read.corrupted.len(), 1);
    assert_eq!(read.corrupted[0].line, 2);
    assert!(read.corrupted[0].reason.contains("UTF-8"));
    assert!(read.notes.iter().any(|n| n.contains("no header")));
}

#[test]
fn empty_and_missing_logs_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    write(&p, "");
    let e = read_log(&p).unwrap_err();
    assert!(matches!(e, ReadError::Empty { .. }));
    assert!(e.to_string().contains("empty"), "{e}");
    write(&p, "\n\n  \n");
    assert!(matches!(read_log(&p).unwrap_err(), ReadError::Empty { .. }));
    assert!(matches!(
        read_log(dir.path()).unwrap_err(),
        ReadError::Empty { .. }
    ));

    let empty_dir = tempfile::tempdir().unwrap();
    let e = read_log(empty_dir.path()).unwrap_err();
    assert!(matches!(e, ReadError::NoLog { .. }), "{e}");
    let e = read_log(&empty_dir.path().join("nope.jsonl")).unwrap_err();
    assert!(matches!(e, ReadError::NotFound { .. }), "{e}");
}

#[test]
fn truncated_last_line_is_reviewed_up_to_it() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    let h = serde_json::to_string(&header()).unwrap();
    let last = record_line(3);
    write(
        &p,
        &format!(
            "{h}\n{}\n{}\n{}\n{}",
            record_line(0),
            record_line(1),
            record_line(2),
            &last[..last.len() / 2]
        ),
    );
    let read = read_log(&p).unwrap();
    assert_eq!(read.records.len(), 3);
    let t = read.truncated.expect("marked truncated");
    assert_eq!(t.line, 5);
    assert!(read.corrupted.is_empty());
    assert!(!read.ended_cleanly);
}

#[test]
fn process_killed_with_sigkill_leaves_a_readable_log() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_companion-log-stress"))
        .arg(dir.path())
        .args(["--rotate-bytes", "40000"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill it while it writes: after it has rotated at least twice.
    let third = part_path(dir.path(), 2);
    wait_until("two rotations", || third.exists());
    child.kill().unwrap(); // SIGKILL on Unix
    child.wait().unwrap();

    let read = read_log(dir.path()).unwrap();
    assert!(read.files.len() >= 3);
    assert!(read.corrupted.is_empty(), "{:?}", read.corrupted);
    assert!(!read.ended_cleanly);
    assert!(read.records.len() > 10);
    // Every complete line on disk was read: count newline-terminated non-header lines by hand.
    let mut complete = 0usize;
    for f in &read.files {
        let text = std::fs::read(f).unwrap();
        for line in text
            .split(|b| *b == b'\n')
            .collect::<Vec<_>>()
            .split_last()
            .unwrap()
            .1
        {
            let l = String::from_utf8_lossy(line);
            if !l.contains("\"kind\":\"header\"") && !l.contains("\"kind\":\"loss\"") {
                complete += 1;
            }
        }
    }
    assert_eq!(read.records.len(), complete);
    // Cycles only increase; every gap is matched by loss lines just before it.
    for (k, w) in read.records.windows(2).enumerate() {
        let gap = w[1].cycle - w[0].cycle - 1;
        let lost: u64 = read
            .losses
            .iter()
            .filter(|l| l.before_record == k + 1)
            .map(|l| l.dropped)
            .sum();
        assert_eq!(
            gap, lost,
            "between cycles {} and {}",
            w[0].cycle, w[1].cycle
        );
    }
}

#[test]
fn review_of_a_damaged_newer_log_still_reports_everything_readable() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("decisions.jsonl");
    let mut h = serde_json::to_value(header()).unwrap();
    h["schema"] = serde_json::json!(SCHEMA_VERSION + 1);
    let last = record_line(5);
    write(
        &p,
        &format!(
            "{h}\n{}\n{}\nnot json at all\n{}\n{{\"kind\":\"loss\",\"dropped\":3}}\n{}\n{}",
            record_line(0),
            record_line(1),
            record_line(2),
            record_line(6),
            &last[..10]
        ),
    );
    let out = dir.path().join("r.html");
    let written = companion::review::run(&p, Some(&out), false).unwrap();
    assert_eq!(written.as_deref(), Some(out.as_path()));
    let html = std::fs::read_to_string(&out).unwrap();
    assert_eq!(html.matches("class=\"timeline-row").count(), 4); // cycles 0, 1, 2, 6
    assert!(html.contains("data-corrupted=\"1\" data-truncated=\"true\""));
    assert!(html.contains(&format!("data-newer-schema=\"{}\"", SCHEMA_VERSION + 1)));
    assert!(html.contains("data-line=\"4\"")); // the non-JSON line
    assert!(html.contains("data-line=\"8\"")); // the cut-off last line
    assert!(html.contains("data-losses=\"1\" data-dropped=\"3\""));
    assert!(html.contains("log truncated"));
}
