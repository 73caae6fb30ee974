//! `companion fly` says connection failures aloud: the real binary, spawned with a deadline,
//! against a refused TCP port, a missing serial device, an unknown URL scheme, a silent `udpin`
//! port with `--connect-timeout`, and a `udpin://` (MAVSDK form) port that hears a heartbeat.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

fn companion(args: &[&str], log_dir: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_companion"))
        .arg("fly")
        .args(args)
        .arg("--log-dir")
        .arg(log_dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawning the companion binary")
}

/// Lines of a child's stream as they come.
fn lines(r: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for l in BufReader::new(r).lines().map_while(Result::ok) {
            if tx.send(l).is_err() {
                return;
            }
        }
    });
    rx
}

/// The first stderr line matching `pred` within `within`; the lines seen, on failure.
fn wait_line(
    rx: &mpsc::Receiver<String>,
    within: Duration,
    pred: impl Fn(&str) -> bool,
) -> Result<String, Vec<String>> {
    let end = Instant::now() + within;
    let mut seen = Vec::new();
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        match rx.recv_timeout(left) {
            Ok(l) if pred(&l) => return Ok(l),
            Ok(l) => seen.push(l),
            Err(_) => break,
        }
    }
    Err(seen)
}

/// Wait for the child to exit within `within`, else kill it and fail.
fn wait_exit(child: &mut Child, within: Duration) -> ExitStatus {
    let end = Instant::now() + within;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() >= end {
            let _ = child.kill();
            let _ = child.wait();
            panic!("companion fly did not exit within {within:?}");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn refused_tcp_endpoint_is_said_on_stderr_within_10s() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = companion(&["--connect", "tcp:127.0.0.1:1"], dir.path());
    let err = lines(child.stderr.take().unwrap());
    let got = wait_line(&err, Duration::from_secs(10), |l| {
        l.contains("127.0.0.1:1") && l.to_lowercase().contains("refused")
    });
    let _ = child.kill();
    let _ = child.wait();
    let line = got.unwrap_or_else(|seen| panic!("no line naming the endpoint: {seen:?}"));
    assert!(line.contains("retrying"), "{line}");
}

#[test]
fn missing_serial_device_is_said_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let mut child = companion(
        &["--connect", "serial:///dev/ttyNOSUCHDEVICE7:57600"],
        dir.path(),
    );
    let err = lines(child.stderr.take().unwrap());
    let got = wait_line(&err, Duration::from_secs(10), |l| {
        l.contains("/dev/ttyNOSUCHDEVICE7")
    });
    let _ = child.kill();
    let _ = child.wait();
    got.unwrap_or_else(|seen| panic!("no line naming the device: {seen:?}"));
}

#[test]
fn unknown_url_scheme_is_a_cli_error() {
    let dir = tempfile::tempdir().unwrap();
    for url in ["udp://0.0.0.0:14550", "http://127.0.0.1:80", "14550"] {
        let out = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args(["fly", "--connect", url, "--log-dir"])
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(!out.status.success(), "{url}: exit 0");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("unknown scheme") || err.contains("expected SCHEME"),
            "{url}: {err}"
        );
        assert!(err.contains(url), "{url}: the error names the URL: {err}");
    }
}

#[test]
fn connect_timeout_without_a_heartbeat_exits_non_zero_naming_the_endpoint() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port();
    let url = format!("udpin://127.0.0.1:{port}");
    let mut child = companion(
        &["--connect", &url, "--connect-timeout", "2s", "--auto-start"],
        dir.path(),
    );
    let err = lines(child.stderr.take().unwrap());
    let status = wait_exit(&mut child, Duration::from_secs(30));
    assert!(!status.success(), "exit 0 without any autopilot");
    let line = wait_line(&err, Duration::from_secs(2), |l| {
        l.contains("no autopilot HEARTBEAT")
    })
    .unwrap_or_else(|seen| panic!("no timeout line: {seen:?}"));
    assert!(line.contains(&format!("udpin:127.0.0.1:{port}")), "{line}");
}

#[test]
fn udpin_mavsdk_url_hears_a_heartbeat() {
    use companion_link::dialect::*;
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port();
    let url = format!("udpin://127.0.0.1:{port}");
    let mut child = companion(
        &[
            "--connect",
            &url,
            "--connect-timeout",
            "20s",
            "--duration",
            "6s",
            "--auto-start",
        ],
        dir.path(),
    );
    let out = lines(child.stdout.take().unwrap());
    let _err = lines(child.stderr.take().unwrap());
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let sender = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            });
            let mut seq = 0u8;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let mut buf = Vec::new();
                let h = mavlink::MavHeader {
                    system_id: 1,
                    component_id: 1,
                    sequence: seq,
                };
                seq = seq.wrapping_add(1);
                mavlink::write_v2_msg(&mut buf, h, &hb).unwrap();
                let _ = s.send_to(&buf, ("127.0.0.1", port));
                std::thread::sleep(Duration::from_millis(200));
            }
        })
    };
    let status = wait_exit(&mut child, Duration::from_secs(60));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    sender.join().unwrap();
    assert!(status.success(), "fly failed: {status}");
    let run = wait_line(&out, Duration::from_secs(2), |l| {
        l.starts_with("run folder: ")
    })
    .expect("the run folder is printed");
    let log = std::fs::read_to_string(
        Path::new(run.trim_start_matches("run folder: ")).join("decisions.jsonl"),
    )
    .unwrap();
    // Decision cycles run only once an autopilot is chosen: its heartbeat was heard.
    let cycles = log.lines().filter(|l| l.contains("\"cycle\":")).count();
    assert!(
        cycles >= 2,
        "no decision cycle: the heartbeat was not heard\n{log}"
    );
}

#[test]
fn autopilot_sysid_zero_and_bad_connect_timeout_are_cli_errors() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, value) in [
        ("--autopilot-sysid", "0"),
        ("--autopilot-sysid", "256"),
        ("--connect-timeout", "0s"),
        ("--connect-timeout", "soon"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_companion"))
            .args([
                "fly",
                "--connect",
                "tcp:127.0.0.1:1",
                flag,
                value,
                "--log-dir",
            ])
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(!out.status.success(), "{flag} {value}: exit 0");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(flag), "{flag} {value}: {err}");
    }
}

/// A link existed (an ArduPilot heartbeat over TCP), then the autopilot's end closed and every
/// reconnect is refused: stderr (the journal) says the failures at most once per 10 s, each
/// once, not once per 1 s retry and not twice, although decision cycles run every second.
#[test]
fn refused_reconnects_after_a_link_are_said_once_per_10s() {
    use companion_link::dialect::*;
    use std::io::Write as _;
    let dir = tempfile::tempdir().unwrap();
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let url = format!("tcp:127.0.0.1:{port}");
    let mut child = companion(&["--connect", &url, "--duration", "14s"], dir.path());
    let err = lines(child.stderr.take().unwrap());
    let (mut conn, _) = listener.accept().unwrap();
    // Nothing listens on the port from now on: every reconnect is refused.
    drop(listener);
    let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    for seq in 0..8u8 {
        let mut buf = Vec::new();
        let h = mavlink::MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: seq,
        };
        mavlink::write_v2_msg(&mut buf, h, &hb).unwrap();
        conn.write_all(&buf).unwrap();
        std::thread::sleep(Duration::from_millis(250));
    }
    drop(conn);
    let status = wait_exit(&mut child, Duration::from_secs(60));
    assert!(status.success(), "fly failed: {status}");
    let seen: Vec<String> = err.try_iter().collect();
    assert!(
        seen.iter().any(|l| l.contains("autopilot chosen")),
        "the heartbeat was not heard: {seen:#?}"
    );
    let failures: Vec<&String> = seen
        .iter()
        .filter(|l| {
            l.contains(&format!("127.0.0.1:{port}"))
                && (l.contains("refused") || l.contains("closed"))
        })
        .collect();
    // About 12 s of 1 s retries after the close: the close at once, the refusals once 10 s on.
    assert!(
        !failures.is_empty() && failures.len() <= 2,
        "{} failure lines: {failures:#?}",
        failures.len()
    );
}
