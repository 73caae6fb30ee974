//! No output over an input, no waiting on a pipe (issue 40): every command that writes
//! (`calibrate --out`, `export --out`, `review --out`, `signing-setup --key`) refuses an output
//! that is one of its inputs (by name, symlink or hard link), a FIFO, or a name with control
//! characters: non-zero exit, the reason, every input byte-identical, nothing blocks.

#![cfg(unix)]

mod common;
use common::text;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The binary under test (named here: scripts/arm.sh skips tests that start it under qemu).
const BIN: &str = env!("CARGO_BIN_EXE_companion");

/// Run the companion, killed (and the test failed) if it has not ended within a minute: a
/// FIFO opened for writing without a reader would block it for ever.
fn companion(args: &[&std::ffi::OsStr]) -> Output {
    let mut child = Command::new(BIN)
        .args(args)
        .env_remove("COMPANION_PARAMS")
        .env_remove("RUST_BACKTRACE")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("companion runs");
    let deadline = Instant::now() + Duration::from_secs(60);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("companion {args:?} still running after 60 s (blocked on a FIFO?)");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn os<S: AsRef<std::ffi::OsStr> + ?Sized>(s: &S) -> &std::ffi::OsStr {
    s.as_ref()
}

/// A run folder with a few `simulate` records and a tlog.
fn run_folder(root: &Path) -> PathBuf {
    let runs = root.join("runs");
    let o = companion(&[
        os("simulate"),
        os("--steps"),
        os("5"),
        os("--runs-dir"),
        os(&runs),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let run = std::fs::read_dir(&runs)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    // A tlog (one frame's worth of bytes is enough to be an input).
    std::fs::write(run.join("flight.tlog"), [0u8; 8]).unwrap();
    run
}

/// The bytes of every file in `files`.
fn snapshot(files: &[PathBuf]) -> Vec<Vec<u8>> {
    files.iter().map(|f| std::fs::read(f).unwrap()).collect()
}

/// `args` exit non-zero with `why` in the output, and `inputs` are byte-identical.
fn refused(args: &[&std::ffi::OsStr], inputs: &[PathBuf], why: &str) {
    let before = snapshot(inputs);
    let o = companion(args);
    let t = text(&o);
    assert!(!o.status.success(), "accepted {args:?}: {t}");
    assert!(t.contains(why), "expected {why:?} from {args:?} in: {t}");
    assert!(!t.contains('\x1b') && !t.contains('\x07'), "{t:?}");
    assert_eq!(snapshot(inputs), before, "{args:?} changed an input");
}

/// The outputs every command must refuse, given its inputs: each input itself, a symlink and
/// a hard link to the first, a FIFO, a name with a newline and escape sequence; with the
/// reason each is refused for.
fn bad_outputs(dir: &Path, inputs: &[PathBuf]) -> Vec<(PathBuf, &'static str)> {
    let mut out: Vec<(PathBuf, &'static str)> = inputs
        .iter()
        .map(|i| (i.clone(), "an input of this"))
        .collect();
    let sym = dir.join("sym.out");
    let _ = std::fs::remove_file(&sym);
    std::os::unix::fs::symlink(&inputs[0], &sym).unwrap();
    out.push((sym, "an input of this"));
    let hard = dir.join("hard.out");
    let _ = std::fs::remove_file(&hard);
    std::fs::hard_link(&inputs[0], &hard).unwrap();
    out.push((hard, "an input of this"));
    let fifo = dir.join("fifo.out");
    if !fifo.exists() {
        let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(made.success());
    }
    out.push((fifo, "not a regular file"));
    out.push((
        dir.join("x\n[flight]\nhandoff = \"none\"\n\x1b]0;owned\x07.toml"),
        "control characters",
    ));
    out
}

#[test]
fn calibrate_never_writes_over_its_runs_or_params() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path());
    // A base overlay given with --params is an input too.
    let base = d.path().join("base.toml");
    std::fs::write(
        &base,
        format!(
            "[calibration]\nparams = {:?}\n",
            companion::params::default_params_dir()
                .display()
                .to_string()
        ),
    )
    .unwrap();
    let inputs = vec![
        run.join("decisions.jsonl"),
        run.join("flight.tlog"),
        base.clone(),
    ];
    for (out, why) in bad_outputs(d.path(), &inputs) {
        refused(
            &[
                os("calibrate"),
                os(&run),
                os("--params"),
                os(&base),
                os("--out"),
                os(&out),
            ],
            &inputs,
            why,
        );
    }
    // A shipped params file, given through the default params directory, is an input as well.
    let mission = companion::params::default_params_dir().join("missions/tracking.toml");
    refused(
        &[os("calibrate"), os(&run), os("--out"), os(&mission)],
        std::slice::from_ref(&mission),
        "an input of this",
    );
    // Nothing left behind but the files made here.
    let names: Vec<String> = std::fs::read_dir(d.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.ends_with(".tmp")), "{names:?}");
}

#[test]
fn review_never_writes_over_its_log() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path());
    let inputs = vec![run.join("decisions.jsonl"), run.join("flight.tlog")];
    for (out, why) in bad_outputs(d.path(), &inputs) {
        refused(
            &[os("review"), os(&run), os("--out"), os(&out)],
            &inputs,
            why,
        );
    }
}

#[test]
fn export_refuses_a_name_with_control_characters() {
    let d = tempfile::tempdir().unwrap();
    let run = run_folder(d.path());
    let inputs = vec![run.join("decisions.jsonl"), run.join("flight.tlog")];
    for (out, why) in bad_outputs(d.path(), &inputs) {
        for format in ["csv", "mcap"] {
            refused(
                &[
                    os("export"),
                    os(&run),
                    os("--format"),
                    os(format),
                    os("--out"),
                    os(&out),
                ],
                &inputs,
                why,
            );
        }
    }
}

#[test]
fn signing_setup_refuses_a_fifo_or_a_control_name_for_its_key() {
    let d = tempfile::tempdir().unwrap();
    let fifo = d.path().join("key.fifo");
    assert!(
        Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let bad = d.path().join("key\n\x1b[2J");
    for (key, why) in [(&fifo, "not a regular file"), (&bad, "control characters")] {
        for force in [false, true] {
            let mut args = vec![
                os("signing-setup"),
                os("--connect"),
                // Never reached: the key is refused before the link opens.
                os("udpin:127.0.0.1:14598"),
                os("--timeout"),
                os("1s"),
                // Pinned (an unpinned set-up is refused before its key is looked at).
                os("--autopilot-sysid"),
                os("1"),
                os("--autopilot-compid"),
                os("1"),
                os("--key"),
                os(key),
            ];
            if force {
                args.push(os("--force"));
            }
            refused(&args, &[], why);
        }
    }
    assert!(!bad.exists());
}
