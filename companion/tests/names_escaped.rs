//! Names the operator gives (a --vehicle name, a key file, a log folder, a URL) reach the
//! terminal escaped in `fly` and `signing-setup` (issue 40): an ESC or BEL sequence in a name is
//! shown as `\u{1b}`, never sent to the terminal to obey.

use std::process::{Command, Output, Stdio};

const EVIL: &str = "x\u{1b}[2J\u{1b}]0;pwned\u{7}\u{9b}31m";

fn companion(args: &[&str], cwd: &std::path::Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_companion"))
        .args(args)
        .current_dir(cwd)
        .env_remove("COMPANION_PARAMS")
        .env("NO_COLOR", "1")
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

/// A `udpin:` URL on a loopback port free a moment ago.
fn udpin() -> String {
    let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    format!("udpin:127.0.0.1:{}", s.local_addr().unwrap().port())
}

/// Neither stream holds a control character other than a line end; both are returned.
fn no_raw_controls(out: &Output) -> (String, String) {
    let so = String::from_utf8_lossy(&out.stdout).to_string();
    let se = String::from_utf8_lossy(&out.stderr).to_string();
    for (name, text) in [("stdout", &so), ("stderr", &se)] {
        let bad: Vec<char> = text
            .chars()
            .filter(|c| c.is_control() && *c != '\n')
            .collect();
        assert!(bad.is_empty(), "{name} holds {bad:?}: {text:?}");
    }
    (so, se)
}

#[test]
fn fly_escapes_a_vehicle_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = companion(
        &["fly", "--connect", &udpin(), "--vehicle", EVIL],
        dir.path(),
    );
    assert!(!out.status.success());
    let (_, err) = no_raw_controls(&out);
    assert!(
        err.contains("--vehicle x\\u{1b}[2J\\u{1b}]0;pwned\\u{7}"),
        "{err}"
    );
}

#[test]
fn fly_escapes_a_signing_key_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let key = dir.path().join(EVIL);
    let out = companion(
        &[
            "fly",
            "--connect",
            &udpin(),
            "--signing-key",
            key.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(!out.status.success());
    let (_, err) = no_raw_controls(&out);
    assert!(err.contains("x\\u{1b}[2J"), "{err}");
}

#[test]
fn fly_escapes_its_run_folder() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join(EVIL);
    let out = companion(
        &[
            "fly",
            "--connect",
            &udpin(),
            "--duration",
            "1s",
            "--log-dir",
            logs.to_str().unwrap(),
        ],
        dir.path(),
    );
    let (so, _) = no_raw_controls(&out);
    assert!(
        so.contains("run folder: ") && so.contains("x\\u{1b}[2J"),
        "{so}"
    );
}

#[test]
fn signing_setup_escapes_the_key_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let key = dir.path().join(EVIL);
    let out = companion(
        &[
            "signing-setup",
            "--connect",
            "tcp:127.0.0.1:1",
            "--key",
            key.to_str().unwrap(),
            "--autopilot-sysid",
            "1",
            "--autopilot-compid",
            "1",
            "--timeout",
            "1s",
        ],
        dir.path(),
    );
    assert!(!out.status.success());
    // A key file named with control characters is refused before anything is written (the
    // output rules every writing command shares), and the refusal names it escaped.
    let (_, err) = no_raw_controls(&out);
    assert!(
        err.contains("the file name holds control characters") && err.contains("x\\u{1b}[2J"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing written beside the refused key file"
    );
}
