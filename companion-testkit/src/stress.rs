//! The bodies of the testkit binaries `companion-log-stress` and `companion-tlog-sample`: a log writer that never stops (killed
//! with SIGKILL by the crash-safety test) and a `.tlog` sample for the pymavlink readback test.

use crate::synthetic;
use companion::decision_log::{DecisionLog, Header, TlogWriter, WriterOptions};
use std::io;
use std::path::Path;
use std::time::SystemTime;

/// Write synthetic records into `dir` (created if missing) as fast as the producer can, forever.
/// Cycle numbers count every attempt, so a dropped record shows as a gap in `cycle` matched by
/// a loss line. `rotate_bytes` small makes the kill land across rotations too.
pub fn log_stress(dir: &Path, rotate_bytes: u64) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let header = Header::new("companion-log-stress", SystemTime::now());
    let log = DecisionLog::start(
        dir,
        header,
        WriterOptions {
            capacity: 64,
            rotate_bytes,
            ..WriterOptions::default()
        },
    )?;
    println!("writing to {}", dir.display());
    for i in 0u64.. {
        let mut r = synthetic::record(i % 100, 100);
        r.cycle = i;
        r.time_s = i as f64;
        log.record(r);
        std::thread::yield_now();
    }
    Ok(())
}

/// Write `n` MAVLink frames to a `.tlog` at `path`: HEARTBEATs (v2, custom_mode = k) at even k
/// and SYS_STATUS (v1, battery_remaining = k) at odd k, at t = 1.7e15 us + k * 0.1 s.
pub fn tlog_sample(path: &Path, n: u32) -> io::Result<()> {
    use mavlink::MavHeader;
    use mavlink::dialects::ardupilotmega::{self as apm, MavMessage};
    let mut w = TlogWriter::create(path)?;
    for k in 0..n {
        let hdr = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: k as u8,
        };
        let mut frame = Vec::new();
        if k % 2 == 0 {
            let msg = MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
                custom_mode: k,
                mavtype: apm::MavType::MAV_TYPE_QUADROTOR,
                autopilot: apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: apm::MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            });
            mavlink::write_v2_msg(&mut frame, hdr, &msg).map_err(io::Error::other)?;
        } else {
            let msg = MavMessage::SYS_STATUS(apm::SYS_STATUS_DATA {
                battery_remaining: k as i8,
                voltage_battery: 12_000,
                ..Default::default()
            });
            mavlink::write_v1_msg(&mut frame, hdr, &msg).map_err(io::Error::other)?;
        }
        w.write(1_700_000_000_000_000 + u64::from(k) * 100_000, &frame)?;
    }
    println!("wrote {} frames to {}", w.frames(), path.display());
    Ok(())
}
