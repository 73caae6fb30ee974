//! Bad command-line input is refused with a clear message and a non-zero exit: never a panic,
//! an abort or a hang. Each case runs the real binary with a time limit.

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Run the binary with `args` (and `COMPANION_PARAMS` unset), killing it after 60 s: a hang fails
/// the test instead of stalling the suite.
fn companion(args: &[&str], cwd: &Path) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_companion"))
        .args(args)
        .current_dir(cwd)
        .env_remove("COMPANION_PARAMS")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "companion {args:?} hung; stderr: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Exit code not 0, no panic, and stderr contains every piece of `want`.
fn refused(args: &[&str], cwd: &Path, want: &[&str]) -> String {
    let out = companion(args, cwd);
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(!out.status.success(), "{args:?} succeeded: {err}");
    assert!(!err.contains("panicked at"), "{args:?} panicked: {err}");
    // A Rust abort (allocation failure) is a signal, not an exit code.
    assert!(
        out.status.code().is_some(),
        "{args:?} died by a signal: {err}"
    );
    for w in want {
        assert!(err.contains(w), "{args:?}: {w:?} not in: {err}");
    }
    err
}

fn mkfifo(path: &Path) -> bool {
    Command::new("mkfifo")
        .arg(path)
        .status()
        .is_ok_and(|s| s.success())
}

/// Never opened: every case is refused before the link starts.
const CONNECT: &str = "tcp:127.0.0.1:1";

#[test]
fn link_timeout_beyond_a_day_is_refused() {
    let d = tempfile::tempdir().unwrap();
    for v in ["1e30s", "86401s", "nan", "0s"] {
        refused(
            &["fly", "--connect", CONNECT, "--link-timeout", v],
            d.path(),
            &["--link-timeout"],
        );
    }
}

#[test]
fn fly_duration_huge_is_refused() {
    let d = tempfile::tempdir().unwrap();
    for v in ["1e30", "18446744073709551616", "inf"] {
        refused(
            &["fly", "--connect", CONNECT, "--duration", v],
            d.path(),
            &["--duration"],
        );
    }
}

#[test]
fn simulate_runs_and_steps_out_of_range_are_refused() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &["simulate", "--no-log", "--runs", "4294967295"],
        d.path(),
        &["--runs", "10000"],
    );
    refused(
        &["simulate", "--no-log", "--runs", "0"],
        d.path(),
        &["--runs"],
    );
    refused(
        &["simulate", "--no-log", "--steps", "4294967295"],
        d.path(),
        &["--steps"],
    );
}

#[test]
fn a_fifo_as_signing_key_is_refused_not_read() {
    let d = tempfile::tempdir().unwrap();
    let key = d.path().join("key");
    if !mkfifo(&key) {
        return eprintln!("mkfifo unavailable: skipped");
    }
    refused(
        &[
            "fly",
            "--connect",
            CONNECT,
            "--auto-start",
            "--signing-key",
            key.to_str().unwrap(),
            "--log-dir",
            d.path().join("runs").to_str().unwrap(),
        ],
        d.path(),
        &["signing-key", "not a regular file"],
    );
}

#[test]
fn a_fifo_as_mission_route_is_refused_before_a_run_folder() {
    let d = tempfile::tempdir().unwrap();
    let route = d.path().join("route.toml");
    if !mkfifo(&route) {
        return eprintln!("mkfifo unavailable: skipped");
    }
    let runs = d.path().join("runs");
    refused(
        &[
            "fly",
            "--connect",
            CONNECT,
            "--mission",
            route.to_str().unwrap(),
            "--log-dir",
            runs.to_str().unwrap(),
        ],
        d.path(),
        &["route.toml", "not a regular file"],
    );
    assert!(!runs.exists(), "no run folder for a refused start");
}

#[test]
fn a_fifo_as_review_target_is_refused_not_read() {
    let d = tempfile::tempdir().unwrap();
    let log = d.path().join("decisions.jsonl");
    if !mkfifo(&log) {
        return eprintln!("mkfifo unavailable: skipped");
    }
    refused(
        &["review", log.to_str().unwrap(), "--summary"],
        d.path(),
        &["decisions.jsonl", "not a regular file"],
    );
    // The same FIFO as a run folder's log.
    let run = d.path().join("run");
    std::fs::create_dir(&run).unwrap();
    assert!(mkfifo(&run.join("decisions.jsonl")));
    refused(
        &["review", run.to_str().unwrap(), "--summary"],
        d.path(),
        &["not a regular file"],
    );
}

fn params_copy(to: &Path) {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                copy(&p, &to.join(e.file_name()));
            } else {
                std::fs::copy(&p, to.join(e.file_name())).unwrap();
            }
        }
    }
    copy(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../params"), to);
}

#[test]
fn check_refuses_a_commands_toml_syntax_error_naming_the_file() {
    let d = tempfile::tempdir().unwrap();
    let params = d.path().join("params");
    params_copy(&params);
    let f = params.join("commands.toml");
    let text = std::fs::read_to_string(&f).unwrap();
    std::fs::write(&f, text.replacen("[take_off]", "[take_off", 1)).unwrap();
    let p = params.to_str().unwrap();
    refused(
        &["check", "--params", p],
        d.path(),
        &["commands.toml", "line"],
    );
    // simulate and fly refuse it the same way, fly before any run folder.
    refused(
        &["simulate", "--no-log", "--params", p],
        d.path(),
        &["commands.toml", "line"],
    );
    let runs = d.path().join("runs");
    refused(
        &[
            "fly",
            "--connect",
            CONNECT,
            "--params",
            p,
            "--log-dir",
            runs.to_str().unwrap(),
        ],
        d.path(),
        &["commands.toml", "line"],
    );
    assert!(!runs.exists(), "no run folder for a refused start");
}

#[test]
fn check_refuses_a_broken_route_file_given_with_route() {
    let d = tempfile::tempdir().unwrap();
    let route = d.path().join("route.toml");
    std::fs::write(
        &route,
        "altitude_m = 1e300\n[[waypoint]]\nnorth_m = 1\neast_m = 1\n",
    )
    .unwrap();
    refused(
        &["check", "--route", route.to_str().unwrap()],
        d.path(),
        &["route.toml", "altitude_m", "out of range"],
    );
}

#[test]
fn a_scenario_of_a_billion_steps_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let real = Path::new(env!("CARGO_MANIFEST_DIR")).join("../params/scenarios/complete-1.toml");
    let text = std::fs::read_to_string(real).unwrap();
    let scenario = d.path().join("long.toml");
    std::fs::write(
        &scenario,
        text.replacen("steps = 100", "steps = 1000000000", 1),
    )
    .unwrap();
    refused(
        &[
            "simulate",
            "--no-log",
            "--scenario",
            scenario.to_str().unwrap(),
        ],
        d.path(),
        &["long.toml", "steps", "out of range"],
    );
}

/// `--policy` takes the names params/policies.toml declares: another name is refused before
/// any run folder or socket, naming the flag and the declared policies.
#[test]
fn a_policy_params_do_not_declare_is_refused_naming_the_known_ones() {
    let d = tempfile::tempdir().unwrap();
    refused(
        &["simulate", "--policy", "yolo", "--runs-dir", "runs"],
        d.path(),
        &[
            "--policy",
            "unknown policy `yolo`",
            "policies.toml",
            "safety",
        ],
    );
    refused(
        &[
            "fly",
            "--connect",
            CONNECT,
            "--policy",
            "yolo",
            "--log-dir",
            "runs",
        ],
        d.path(),
        &["--policy", "unknown policy `yolo`", "mission"],
    );
    assert!(!d.path().join("runs").exists(), "a run folder was started");
}

/// The test helpers are the testkit's own binaries: the shipped one has no hidden subcommands.
#[test]
fn the_binary_has_no_hidden_test_subcommands() {
    for hidden in ["__log-stress", "__tlog-sample"] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_companion"))
            .arg(hidden)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{hidden} is accepted");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("unrecognized subcommand"),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// A bad `check --evidence` value is refused with one line naming the observation and the value,
/// and no backtrace even when RUST_BACKTRACE asks for one (issue 24 item 6).
#[test]
fn check_evidence_bad_value_is_one_line_without_backtrace() {
    let d = tempfile::tempdir().unwrap();
    for (arg, want) in [
        ("cpu_load=medium", ["cpu_load", "medium"]),
        ("A_cpu_load=huge", ["A_cpu_load", "huge"]),
        ("no_such_node=1", ["no_such_node", "node"]),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args(["check", "--evidence", arg])
            .current_dir(d.path())
            .env_remove("COMPANION_PARAMS")
            .env("RUST_BACKTRACE", "1")
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{arg}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{arg}: {err}");
        assert!(!err.contains("backtrace"), "{arg}: {err}");
        for w in want {
            assert!(err.contains(w), "{arg}: {w:?} not in {err}");
        }
    }
}
