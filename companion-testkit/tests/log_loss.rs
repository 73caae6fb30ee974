//! Loss said truthfully: a full disk, a size cap and an oversized record each lose records that
//! are counted (in the writer's stats, which the exit line prints, and in loss lines with their
//! reason), the log holds only whole lines, and the reader tells a full disk or a cap from a
//! killed process (docs/decision-log.md, "How a log ends").

use companion::decision_log::{
    DecisionLog, Header, LogEnd, RESERVE_BYTES, RESERVE_FILE, WriterOptions, part_path, read_log,
};
use companion_core::record::DecisionRecord;
use companion_testkit::synthetic;
use std::path::Path;
use std::time::{Duration, Instant, UNIX_EPOCH};

fn header() -> Header {
    Header::new("companion fly", UNIX_EPOCH)
}

fn rec(i: u64) -> DecisionRecord {
    let mut r = synthetic::record(i % 100, 100);
    r.cycle = i;
    r.time_s = i as f64;
    r
}

fn line_len(r: &DecisionRecord) -> u64 {
    serde_json::to_string(r).unwrap().len() as u64 + 1
}

/// Bytes of the lines of records `0..n`.
fn lines_len(n: u64) -> u64 {
    (0..n).map(|i| line_len(&rec(i))).sum()
}

fn header_len() -> u64 {
    serde_json::to_string(&header()).unwrap().len() as u64 + 1
}

/// Every line of the file ends with a newline and is JSON; returns the parsed lines.
fn whole_json_lines(path: &Path) -> Vec<serde_json::Value> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes.last(), Some(&b'\n'), "the log ends with a whole line");
    bytes
        .split(|b| *b == b'\n')
        .filter(|l| !l.is_empty())
        .map(|l| {
            serde_json::from_slice(l)
                .unwrap_or_else(|e| panic!("a partial line: {e}: {}", String::from_utf8_lossy(l)))
        })
        .collect()
}

fn losses(lines: &[serde_json::Value], reason: &str) -> u64 {
    lines
        .iter()
        .filter(|v| v["kind"] == "loss" && v["reason"] == reason)
        .map(|v| v["dropped"].as_u64().unwrap())
        .sum()
}

fn wait_until(what: &str, mut cond: impl FnMut() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !cond() {
        assert!(Instant::now() < deadline, "gave up waiting for {what}");
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn full_disk_losses_are_counted_whole_lines_kept_and_judged_write_failed() {
    let dir = tempfile::tempdir().unwrap();
    let sent = 55u64;
    // Room for the header, the reserve and ten and a half records: the eleventh is cut mid-line.
    let disk = header_len() + RESERVE_BYTES + lines_len(10) + line_len(&rec(10)) / 2;
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            disk_bytes: Some(disk),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        dir.path().join(RESERVE_FILE).exists(),
        "the reserve is held"
    );
    for i in 0..sent {
        assert!(log.record(rec(i)), "the queue holds all {sent}");
    }
    let stats = log.close();
    assert_eq!(stats.records, 10, "{stats:?}");
    assert_eq!(stats.write_failed, sent - 10, "{stats:?}");
    assert_eq!(
        stats.dropped,
        sent - 10,
        "the exit line's dropped counts write failures"
    );
    assert_eq!(stats.records + stats.dropped, sent);
    assert!(stats.write_errors >= 1 && stats.last_error.is_some());
    assert!(
        !dir.path().join(RESERVE_FILE).exists(),
        "reserve removed at close"
    );

    let path = part_path(dir.path(), 0);
    let lines = whole_json_lines(&path);
    assert_eq!(losses(&lines, "write_failed"), sent - 10);
    let end = lines.last().unwrap();
    assert_eq!(end["kind"], "end");
    assert_eq!(end["write_failed"], sent - 10);

    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.records.len(), 10);
    assert!(read.truncated.is_none() && read.corrupted.is_empty());
    assert_eq!(read.dropped(), sent - 10);
    assert_eq!(read.lost_write_failed, sent - 10);
    assert_eq!(
        read.end(),
        LogEnd::WriteFailed {
            lost: sent - 10,
            closed: true
        }
    );
}

#[test]
fn a_write_failure_is_in_the_log_at_once_so_a_later_kill_is_not_blamed() {
    let dir = tempfile::tempdir().unwrap();
    let disk = header_len() + RESERVE_BYTES + lines_len(3) + 10;
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            disk_bytes: Some(disk),
            ..Default::default()
        },
    )
    .unwrap();
    for i in 0..5 {
        log.record(rec(i));
    }
    let path = part_path(dir.path(), 0);
    // Before close (as if the process were killed now): the failure is already on disk.
    wait_until("the write_failed loss line", || {
        std::fs::read_to_string(&path).is_ok_and(|t| t.contains("write_failed"))
    });
    let read = read_log(dir.path()).unwrap();
    assert!(matches!(
        read.end(),
        LogEnd::WriteFailed { closed: false, lost } if lost >= 1
    ));
    assert!(read.truncated.is_none(), "no partial line");
    let stats = log.close();
    assert_eq!(stats.records, 3);
    assert_eq!(stats.write_failed, 2);
}

#[test]
fn the_size_cap_stops_growth_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let cap = header_len() + lines_len(5);
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            max_bytes: cap,
            ..Default::default()
        },
    )
    .unwrap();
    for i in 0..20 {
        assert!(log.record(rec(i)));
    }
    let stats = log.close();
    assert_eq!((stats.records, stats.capped, stats.dropped), (5, 15, 15));
    let path = part_path(dir.path(), 0);
    let lines = whole_json_lines(&path);
    assert_eq!(losses(&lines, "cap"), 15);
    // Only the loss and end lines go past the cap.
    let size = std::fs::metadata(&path).unwrap().len();
    assert!(size <= cap + 512, "{size} bytes for a cap of {cap}");
    let read = read_log(dir.path()).unwrap();
    assert_eq!(
        read.end(),
        LogEnd::Capped {
            lost: 15,
            closed: true
        }
    );
    assert_eq!(read.records.len(), 5);
}

#[test]
fn an_oversized_record_is_counted_not_written() {
    let dir = tempfile::tempdir().unwrap();
    let log = DecisionLog::start(
        dir.path(),
        header(),
        WriterOptions {
            max_line_bytes: (0..3).map(|i| line_len(&rec(i))).min().unwrap() - 1,
            ..Default::default()
        },
    )
    .unwrap();
    for i in 0..3 {
        log.record(rec(i));
    }
    log.event(3, 3.0, "short");
    let stats = log.close();
    assert_eq!((stats.records, stats.too_large, stats.events), (0, 3, 1));
    let read = read_log(dir.path()).unwrap();
    assert_eq!(read.lost_too_large, 3);
    assert_eq!(read.dropped(), 3);
    assert_eq!(read.end(), LogEnd::Clean);
}

#[test]
fn a_log_without_end_or_loss_reason_is_judged_killed() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("decisions.jsonl");
    let mut text = serde_json::to_string(&header()).unwrap() + "\n";
    text += &(serde_json::to_string(&rec(0)).unwrap() + "\n");
    // An old-style loss line (no reason) is a queue drop, not a disk failure.
    text += "{\"kind\":\"loss\",\"dropped\":2}\n";
    std::fs::write(&path, &text).unwrap();
    let read = read_log(&path).unwrap();
    assert_eq!(read.end(), LogEnd::Killed);
    assert_eq!(read.lost_queue_full, 2);
    text += "{\"kind\":\"end\",\"records\":1,\"events\":0,\"dropped\":2}\n";
    std::fs::write(&path, &text).unwrap();
    assert_eq!(read_log(&path).unwrap().end(), LogEnd::Clean);
}

#[test]
fn the_tlog_stops_at_its_cap_with_whole_entries_and_counts_the_rest() {
    use companion::decision_log::{TlogWriter, read_tlog};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flight.tlog");
    // A 17-byte MAVLink 1 frame (header 6, payload 9, CRC 2) plus its 8-byte time: 25 bytes.
    let mut frame = vec![0xFE, 9, 0, 1, 1, 0];
    frame.extend([0u8; 9]);
    frame.extend([0, 0]);
    let mut w = TlogWriter::create(&path)
        .unwrap()
        .with_max_bytes(25 * 4 + 10);
    let ok = (0..10).filter(|&i| w.write(i, &frame).is_ok()).count();
    assert_eq!((ok, w.frames(), w.capped()), (4, 4, 6));
    let (frames, cut) = read_tlog(&path).unwrap();
    assert_eq!(frames.len(), 4);
    assert_eq!(cut, None, "whole entries only");
}
