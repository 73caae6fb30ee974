//! `companion fly` under systemd (deploy/companion.service, `Type=notify`, `WatchdogSec=`): the real
//! binary with a fake `NOTIFY_SOCKET` (a unix datagram socket this test binds) and
//! `WATCHDOG_USEC` gets READY=1 once its loop runs, WATCHDOG=1 from the loop while it runs, and
//! STOPPING=1 when it stops; without `NOTIFY_SOCKET` it runs as before (the other fly tests).

use std::os::unix::net::UnixDatagram;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[test]
fn fly_tells_systemd_ready_watchdog_and_stopping() {
    let dir = tempfile::tempdir().unwrap();
    let sock_path = dir.path().join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let logs = dir.path().join("runs");
    // No autopilot (a refused port): the loop still turns, retrying the link, for 4 s.
    let mut child = Command::new(env!("CARGO_BIN_EXE_companion"))
        .args(["fly", "--connect", "tcp:127.0.0.1:1", "--duration", "4s"])
        .arg("--log-dir")
        .arg(&logs)
        .env("NOTIFY_SOCKET", &sock_path)
        // A 1 s watchdog: a ping at least every 0.5 s.
        .env("WATCHDOG_USEC", "1000000")
        .env_remove("WATCHDOG_PID")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawning the companion binary");
    let mut got: Vec<(Instant, String)> = Vec::new();
    let end = Instant::now() + Duration::from_secs(20);
    let mut buf = [0u8; 512];
    while Instant::now() < end {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push((
                Instant::now(),
                String::from_utf8_lossy(&buf[..n]).into_owned(),
            ));
        }
        if child.try_wait().unwrap().is_some() {
            while let Ok(n) = sock.recv(&mut buf) {
                got.push((
                    Instant::now(),
                    String::from_utf8_lossy(&buf[..n]).into_owned(),
                ));
            }
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    let lines: Vec<&str> = got.iter().flat_map(|(_, m)| m.lines()).collect();
    assert_eq!(lines.first(), Some(&"READY=1"), "{lines:?}");
    let pings = lines.iter().filter(|l| **l == "WATCHDOG=1").count();
    // 4 s of loop at one ping per 0.5 s: about 8; a loop that never pinged would be killed.
    assert!(pings >= 4, "{pings} WATCHDOG=1 in 4 s: {lines:?}");
    assert_eq!(lines.last(), Some(&"STOPPING=1"), "{lines:?}");
}
