//! `companion export` never destroys its inputs (issue 26 item 6), run as the operator runs it:
//! the binary, on a run folder. An `--out` naming the log, the tlog or a link to either exits
//! non-zero and leaves them byte-identical; a FIFO or a directory is refused without blocking;
//! unreadable lines are counted and named, and an input with no readable record fails.

use companion_core::record::DecisionRecord;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_companion")
}

/// A run folder `dir/name` with a header, `n` records and an end line, and a small tlog.
fn run_folder(dir: &Path, name: &str, n: u64) -> PathBuf {
    let run = dir.join(name);
    std::fs::create_dir_all(&run).unwrap();
    let mut text = String::from(
        "{\"kind\":\"header\",\"schema\":1,\"started_utc\":\"2025-06-01T12:00:00Z\",\"command\":\"companion fly\"}\n",
    );
    for i in 0..n {
        let r = DecisionRecord {
            cycle: i,
            time_s: i as f64,
            state: "wpi".into(),
            ..Default::default()
        };
        text.push_str(&serde_json::to_string(&r).unwrap());
        text.push('\n');
    }
    text.push_str("{\"kind\":\"end\"}\n");
    std::fs::write(run.join("decisions.jsonl"), text).unwrap();
    // One 8-byte timestamp and a 12-byte MAVLink v2 frame header stand-in: only its bytes matter.
    std::fs::write(run.join("flight.tlog"), [7u8; 40]).unwrap();
    run
}

/// Run the binary; a child still running after 60 s is killed (a hang fails the test rather than
/// the test run: the assertion is on the exit status, not on time).
fn export(args: &[&std::ffi::OsStr]) -> Output {
    let mut child = Command::new(bin())
        .arg("export")
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().unwrap();
            panic!("export did not finish: it blocked");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn os<S: AsRef<std::ffi::OsStr> + ?Sized>(s: &S) -> &std::ffi::OsStr {
    s.as_ref()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit non-zero, the message naming why, and every input byte-identical.
fn refused(run: &Path, format: &str, out: &Path, why: &str) {
    let log = std::fs::read(run.join("decisions.jsonl")).unwrap();
    let tlog = std::fs::read(run.join("flight.tlog")).unwrap();
    let o = export(&[os(run), os("--format"), os(format), os("--out"), os(out)]);
    assert!(!o.status.success(), "{format} --out {out:?} was accepted");
    assert!(
        stderr(&o).contains(why),
        "expected {why:?} in: {}",
        stderr(&o)
    );
    assert_eq!(std::fs::read(run.join("decisions.jsonl")).unwrap(), log);
    assert_eq!(std::fs::read(run.join("flight.tlog")).unwrap(), tlog);
}

#[test]
fn export_out_naming_its_input_log_fails_and_leaves_it_byte_identical() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 50);
    refused(
        &run,
        "csv",
        &run.join("decisions.jsonl"),
        "input of this export",
    );
    refused(
        &run,
        "mcap",
        &run.join("decisions.jsonl"),
        "input of this export",
    );
    // Given as the log file rather than the folder, through `..` as well.
    let log = run.join("decisions.jsonl");
    let o = export(&[
        os(&log),
        os("--format"),
        os("csv"),
        os("--out"),
        os(&run.join("..").join("run").join("decisions.jsonl")),
    ]);
    assert!(!o.status.success());
}

#[test]
fn export_out_naming_the_tlog_or_another_run_file_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 5);
    refused(
        &run,
        "mcap",
        &run.join("flight.tlog"),
        "input of this export",
    );
    std::fs::write(run.join("report.html"), "<html>").unwrap();
    refused(
        &run,
        "csv",
        &run.join("report.html"),
        "file of the run folder",
    );
    assert_eq!(std::fs::read(run.join("report.html")).unwrap(), b"<html>");
}

#[cfg(unix)]
#[test]
fn links_to_the_input_are_seen_through() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 5);
    let sym = d.path().join("sym.csv");
    std::os::unix::fs::symlink(run.join("decisions.jsonl"), &sym).unwrap();
    refused(&run, "csv", &sym, "input of this export");
    let hard = d.path().join("hard.mcap");
    std::fs::hard_link(run.join("flight.tlog"), &hard).unwrap();
    refused(&run, "mcap", &hard, "input of this export");
}

#[cfg(unix)]
#[test]
fn a_fifo_or_a_directory_as_out_is_refused_without_blocking() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 5);
    let fifo = d.path().join("out.csv");
    let made = Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        refused(&run, "csv", &fifo, "not a regular file");
        refused(&run, "mcap", &fifo, "not a regular file");
    }
    refused(&run, "csv", d.path(), "a directory");
}

#[test]
fn an_export_replaces_its_earlier_export_and_leaves_no_temporary_file() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 5);
    for _ in 0..2 {
        let o = export(&[os(&run), os("--format"), os("csv")]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let csv = std::fs::read_to_string(run.join("export.csv")).unwrap();
    assert_eq!(csv.lines().count(), 6, "header and 5 rows: {csv}");
    let names: Vec<String> = std::fs::read_dir(&run)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names.iter().any(|n| n.contains(".tmp")),
        "temporary file left: {names:?}"
    );
}

#[test]
fn unreadable_lines_are_counted_and_named() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run", 3);
    let mut text = std::fs::read_to_string(run.join("decisions.jsonl")).unwrap();
    text.push_str("not json\n{\"cycle\":\"seven\"}\n");
    std::fs::write(run.join("decisions.jsonl"), text).unwrap();
    let o = export(&[os(&run), os("--format"), os("csv")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    // Header + 3 records + end = lines 1..5; the bad ones are lines 6 and 7.
    assert!(err.contains("decisions.jsonl:6: not JSON"), "{err}");
    assert!(
        err.contains("decisions.jsonl:7: not a decision record"),
        "{err}"
    );
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("3 records") && out.contains("2 unreadable lines skipped"),
        "{out}"
    );
}

#[test]
fn an_input_without_one_readable_record_fails() {
    let d = tempfile::tempdir().unwrap();
    let run = d.path().join("junk");
    std::fs::create_dir(&run).unwrap();
    // Bytes that are no log at all (what `random_1MB` was), without a newline in them.
    let junk: Vec<u8> = (0..100_000u32)
        .map(|i| (i * 7 % 251) as u8 | 0x80)
        .collect();
    std::fs::write(run.join("decisions.jsonl"), &junk).unwrap();
    for format in ["csv", "mcap"] {
        let o = export(&[os(&run), os("--format"), os(format)]);
        assert!(
            !o.status.success(),
            "{format}: exported nothing with exit 0"
        );
        assert!(stderr(&o).contains("no decision record"), "{}", stderr(&o));
        assert!(!run.join(format!("export.{format}")).exists());
    }
}

#[cfg(unix)]
#[test]
fn a_folder_name_with_escape_sequences_is_printed_escaped() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path(), "run\x1b]0;owned\x07\x1b[2J", 2);
    let o = export(&[os(&run), os("--format"), os("csv")]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!out.contains('\x1b') && !out.contains('\x07'), "{out:?}");
    assert!(out.contains("run\\u{1b}]0;owned"), "{out}");
    // The refusal's message too.
    let o = export(&[
        os(&run),
        os("--format"),
        os("csv"),
        os("--out"),
        os(&run.join("decisions.jsonl")),
    ]);
    assert!(!o.status.success());
    assert!(!stderr(&o).contains('\x1b'), "{:?}", stderr(&o));
}

#[test]
fn csv_formula_guard_covers_tab_and_cr() {
    use companion::export::csv_field;
    assert_eq!(csv_field("\t=1+2"), "'\t=1+2");
    assert_eq!(csv_field("\r=1+2"), "\"'\r=1+2\"");
    assert_eq!(csv_field("=1+2"), "'=1+2");
    assert_eq!(csv_field("-3.5"), "-3.5");
}
