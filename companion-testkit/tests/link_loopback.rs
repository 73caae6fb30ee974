//! Loopback: `fly` against a tiny in-test autopilot on 127.0.0.1 built from the mavlink crate
//! (its serialiser and async reader). The peer behaves like ArduPilot Copter for the few
//! commands `take_off` needs, injects garbage bytes between frames, and drops the TCP connection
//! once the vehicle is airborne to check reconnect + stream re-request without command replay.

use companion::fly::{FlyArgs, RecordSink, run_until, run_with};
use companion_core::record::DecisionRecord;
use companion_core::record::{Event, LinkEvent};
use companion_link::dialect::*;
use companion_testkit::scripted::ScriptedDecider;
use mavlink::{AsyncMavlinkReader, MavHeader};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::AsyncWriteExt;
use tokio::net::TcpListener;

type Msg = MavMessage;

#[derive(Default)]
struct PeerLog {
    /// (session, command) in arrival order.
    commands: Vec<(u32, MavCmd, u8)>,
    /// Our heartbeats as seen by the autopilot: (component, type, autopilot).
    heartbeats: Vec<(u8, MavType, MavAutopilot)>,
}

#[derive(Clone, Copy)]
struct Vehicle {
    mode: u32,
    armed: bool,
    alt_m: f32,
}

fn frame(seq: &mut u8, msg: &Msg) -> Vec<u8> {
    let mut buf = Vec::new();
    mavlink::write_v2_msg(
        &mut buf,
        MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: *seq,
        },
        msg,
    )
    .unwrap();
    *seq = seq.wrapping_add(1);
    buf
}

fn telemetry(v: Vehicle) -> Vec<Msg> {
    let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
    let base = if v.armed {
        MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    } else {
        MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    };
    vec![
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: v.mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: base,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        }),
        Msg::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: bit,
            onboard_control_sensors_enabled: bit,
            onboard_control_sensors_health: bit,
            battery_remaining: 87,
            ..SYS_STATUS_DATA::DEFAULT
        }),
        Msg::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
            flags: EkfStatusFlags::EKF_ATTITUDE
                | EkfStatusFlags::EKF_VELOCITY_HORIZ
                | EkfStatusFlags::EKF_POS_HORIZ_ABS
                | EkfStatusFlags::EKF_POS_VERT_ABS,
            ..EKF_STATUS_REPORT_DATA::DEFAULT
        }),
        Msg::HOME_POSITION(HOME_POSITION_DATA {
            latitude: -353_632_610,
            longitude: 1_491_652_300,
            altitude: 584_000,
            ..HOME_POSITION_DATA::DEFAULT
        }),
        Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: -353_632_610,
            lon: 1_491_652_300,
            relative_alt: (v.alt_m * 1000.0) as i32,
            hdg: 0,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        }),
    ]
}

/// ArduPilot-like answers: DO_SET_MODE changes mode, ARM needs GUIDED-capable mode, TAKEOFF needs armed.
fn answer(v: &mut Vehicle, c: &COMMAND_LONG_DATA) -> MavResult {
    match c.command {
        MavCmd::MAV_CMD_DO_SET_MODE => {
            v.mode = c.param2 as u32;
            MavResult::MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_COMPONENT_ARM_DISARM => {
            v.armed = c.param1 == 1.0;
            MavResult::MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_NAV_TAKEOFF if v.armed && v.mode == 4 => {
            v.alt_m = c.param7;
            MavResult::MAV_RESULT_ACCEPTED
        }
        MavCmd::MAV_CMD_NAV_TAKEOFF => MavResult::MAV_RESULT_FAILED,
        MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => MavResult::MAV_RESULT_ACCEPTED,
        _ => MavResult::MAV_RESULT_UNSUPPORTED,
    }
}

/// Two sessions: the first ends (we close the socket) once the vehicle has taken off.
async fn autopilot(listener: TcpListener, log: Arc<Mutex<PeerLog>>) {
    let mut v = Vehicle {
        mode: 0,
        armed: false,
        alt_m: 0.0,
    };
    for session in 1..=2u32 {
        let Ok((stream, _)) = listener.accept().await else {
            return;
        };
        let (r, mut w) = stream.into_split();
        let (ack_tx, mut ack_rx) = tokio::sync::mpsc::unbounded_channel::<COMMAND_LONG_DATA>();
        let log_r = log.clone();
        let reader = tokio::spawn(async move {
            let mut reader = AsyncMavlinkReader::new(r);
            while let Ok((h, m)) = reader.read_any_message::<Msg>().await {
                match m {
                    Msg::COMMAND_LONG(c) => {
                        log_r
                            .lock()
                            .unwrap()
                            .commands
                            .push((session, c.command, c.confirmation));
                        let _ = ack_tx.send(c);
                    }
                    Msg::HEARTBEAT(hb) => log_r.lock().unwrap().heartbeats.push((
                        h.component_id,
                        hb.mavtype,
                        hb.autopilot,
                    )),
                    _ => {}
                }
            }
        });
        let mut seq = 0u8;
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        let mut n = 0u32;
        loop {
            tokio::select! {
                Some(c) = ack_rx.recv() => {
                    let result = answer(&mut v, &c);
                    let ack = Msg::COMMAND_ACK(COMMAND_ACK_DATA { command: c.command, result, ..COMMAND_ACK_DATA::DEFAULT });
                    if w.write_all(&frame(&mut seq, &ack)).await.is_err() { break; }
                }
                _ = tick.tick() => {
                    n += 1;
                    let mut bytes = Vec::new();
                    for m in telemetry(v) {
                        bytes.extend(frame(&mut seq, &m));
                        // Line noise between frames (no frame markers, so nothing real is lost).
                        bytes.extend_from_slice(&[0x00, 0x13, 0x37, 0x42, 0x99]);
                    }
                    if w.write_all(&bytes).await.is_err() { break; }
                    if session == 1 && v.alt_m > 0.0 && n > 5 {
                        break; // drop the link
                    }
                }
            }
        }
        reader.abort();
        drop(w);
    }
}

/// The failure bound of the TCP flight: what it checks happens within ~3 s on an idle machine.
const FLIGHT_BOUND: Duration = Duration::from_secs(60);

/// Decision records the test reads while the flight runs.
#[derive(Clone, Default)]
struct SharedRecords(Arc<Mutex<Vec<DecisionRecord>>>);

impl RecordSink for SharedRecords {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        self.0.lock().unwrap().push(rec.clone());
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fly_takes_off_over_tcp_reconnects_and_never_replays() {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let log = Arc::new(Mutex::new(PeerLog::default()));
    let peer = tokio::spawn(autopilot(listener, log.clone()));

    // An onboard monitor (the tracker) on its own UDP link reports a detection.
    let onboard_port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let monitor = tokio::spawn(async move {
        let s = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let mut seq = 0u8;
        // Until the flight ends (the task is aborted then), however long that takes.
        for i in 0u32.. {
            let det = if i < 10 { 0.0 } else { 1.0 };
            let m = Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                time_boot_ms: i * 100,
                value: det,
                name: "tgt_det".into(),
            });
            let _ = s
                .send_to(&frame(&mut seq, &m), ("127.0.0.1", onboard_port))
                .await;
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    });
    let args = FlyArgs::from_cli([
        "--connect".to_string(),
        format!("tcp:127.0.0.1:{port}"),
        "--onboard".into(),
        format!("udpin:127.0.0.1:{onboard_port}"),
        "--auto-start".into(),
    ])
    .unwrap();
    let decider = ScriptedDecider::new(20.0, 6, "safety");
    // The flight ends once everything checked below has happened (taken off, reconnected with
    // the streams asked for again, the detection seen), or after FLIGHT_BOUND, the failure
    // bound: never after a fixed time that a loaded machine may not reach it in.
    let shared = SharedRecords::default();
    let (seen_records, seen_log) = (shared.0.clone(), log.clone());
    let done = async move {
        let happened = || {
            let records = seen_records.lock().unwrap();
            let log = seen_log.lock().unwrap();
            let reconnected = log
                .commands
                .iter()
                .any(|c| c.0 == 2 && c.1 == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL);
            let took_off = records.iter().flat_map(|r| &r.commands).any(|c| {
                c.action == "take_off"
                    && c.command == "MAV_CMD_NAV_TAKEOFF"
                    && c.result == "ACCEPTED"
            });
            let detected = records
                .iter()
                .any(|r| r.events.contains(&Event::TargetDetected));
            reconnected && took_off && detected
        };
        let deadline = tokio::time::Instant::now() + FLIGHT_BOUND;
        while !happened() && tokio::time::Instant::now() < deadline {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    };
    let mut sink = shared.clone();
    let report = run_until(args, decider, &mut sink, done).await.unwrap();
    peer.abort();
    monitor.abort();
    let records = std::mem::take(&mut *shared.0.lock().unwrap());

    let log = log.lock().unwrap();
    // Identity: our heartbeat is an onboard controller, component 191, not an autopilot.
    assert!(!log.heartbeats.is_empty());
    assert!(log.heartbeats.iter().all(|h| *h
        == (
            191,
            MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            MavAutopilot::MAV_AUTOPILOT_INVALID
        )));
    // take_off: GUIDED, arm, takeoff — each exactly once, in order, first transmission.
    let flight: Vec<(u32, MavCmd, u8)> = log
        .commands
        .iter()
        .copied()
        .filter(|c| c.1 != MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL)
        .collect();
    assert_eq!(
        flight,
        vec![
            (1, MavCmd::MAV_CMD_DO_SET_MODE, 0),
            (1, MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 0),
            (1, MavCmd::MAV_CMD_NAV_TAKEOFF, 0),
            // The stop at the end of --duration, the vehicle armed in the air: the hand-off
            // (params/link.toml [flight] handoff = "rtl"), a new command, not a replay.
            (2, MavCmd::MAV_CMD_DO_SET_MODE, 0)
        ],
        "{:?}\ncommand records: {:?}\nactions per cycle: {:?}",
        log.commands,
        records
            .iter()
            .flat_map(|r| &r.commands)
            .map(|c| format!("{} {} {}", c.action, c.command, c.result))
            .collect::<Vec<_>>(),
        records
            .iter()
            .map(|r| format!("{}:{}:{}", r.cycle, r.state, r.actions.join("+")))
            .collect::<Vec<_>>()
    );
    // Streams requested in both sessions: the 15 of params/link.toml less the 3 ArduPilot does
    // not send ([streams_not_sent_by] ardupilot: 230, 330, 253) after connect, again after the
    // reconnect.
    let streams = |s| {
        log.commands
            .iter()
            .filter(|c| c.0 == s && c.1 == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL)
            .count()
    };
    assert_eq!(streams(1), 12);
    assert!(
        streams(2) >= 1,
        "streams re-requested after reconnect: {:?}",
        log.commands
    );
    let said: Vec<String> = records
        .iter()
        .flat_map(|r| r.events.iter().map(|e| e.to_string()))
        .collect();
    assert!(
        said.iter().any(
            |e| e.contains("companion stopping (stop requested by the caller)")
                && e.contains("hand-off RTL")
        ),
        "{said:?}"
    );
    assert_eq!(
        records
            .last()
            .and_then(|r| r.vehicle.get("operator"))
            .and_then(|v| v.as_str()),
        Some("stopping")
    );
    // The garbage was counted, not fatal.
    assert!(report.ingest.bytes_unframed() > 0);
    assert!(report.ingest.frames_ok > 20);
    // Records: the arm command's result with the trigger-to-send latency.
    let cmds: Vec<_> = records.iter().flat_map(|r| r.commands.iter()).collect();
    let arm_sent = cmds
        .iter()
        .find(|c| c.command == "ARM" && c.result == "SENT")
        .expect("ARM sent record");
    assert!(arm_sent.latency_ms.is_some());
    assert!(cmds.iter().any(|c| c.action == "take_off"
        && c.command == "MAV_CMD_NAV_TAKEOFF"
        && c.result == "ACCEPTED"));
    assert!(records.iter().any(|r| {
        r.link_events
            .iter()
            .any(|e| matches!(e, LinkEvent::TransportDisconnected(_)))
    }));
    assert!(records.windows(2).all(|w| w[1].cycle == w[0].cycle + 1));
    // The onboard monitor's detection reached the observations and triggered a cycle.
    assert!(
        records
            .iter()
            .any(|r| r.events.contains(&Event::TargetDetected))
    );
    assert_eq!(
        records.last().unwrap().observations.get("target_detected"),
        Some(&1.0)
    );
    // The fly loop's events, link events and command results read back from the log as the
    // values written (typed, not re-read as free text).
    let mut typed_link_events = 0;
    for r in &records {
        let back: DecisionRecord =
            serde_json::from_str(&serde_json::to_string(r).unwrap()).unwrap();
        assert_eq!(back.events, r.events, "cycle {}", r.cycle);
        assert_eq!(back.link_events, r.link_events, "cycle {}", r.cycle);
        assert_eq!(back.commands, r.commands, "cycle {}", r.cycle);
        typed_link_events += r
            .link_events
            .iter()
            .filter(|e| !matches!(e, LinkEvent::Other(_)))
            .count();
    }
    assert!(typed_link_events > 0);
}

/// UDP + signing: our frames arrive signed with the shared key (checked with the crate's
/// verifier), unsigned commands addressed to us are refused and counted, signed ones pass.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fly_over_udp_signs_frames_and_refuses_unsigned_commands() {
    use mavlink::{MAVLinkMessageRaw, MavlinkReader, SigningConfig, SigningData};
    let key = [0x5au8; 32];
    let dir = tempfile::tempdir().unwrap();
    let key_path = dir.path().join("key.hex");
    std::fs::write(&key_path, "5a".repeat(32)).unwrap();

    let sock = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let port = sock.local_addr().unwrap().port();
    let peer = tokio::spawn(async move {
        let verifier = SigningData::from_config(SigningConfig::new(key, 0, false, false));
        let signer = SigningData::from_config(SigningConfig::new(key, 1, true, false));
        let (mut signed_ok, mut unsigned) = (0u32, 0u32);
        let mut buf = vec![0u8; 2048];
        let mut seq = 0u8;
        let v = Vehicle {
            mode: 4,
            armed: false,
            alt_m: 0.0,
        };
        let cmd = Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_DO_SET_MODE,
            target_system: 1,
            target_component: 191,
            ..COMMAND_LONG_DATA::DEFAULT
        });
        let deadline = tokio::time::Instant::now() + Duration::from_millis(2500);
        let mut from = None;
        while tokio::time::Instant::now() < deadline {
            if let Ok(Ok((n, addr))) =
                tokio::time::timeout(Duration::from_millis(100), sock.recv_from(&mut buf)).await
            {
                from = Some(addr);
                let mut r = MavlinkReader::new(&buf[..n]);
                while let Ok(raw) = r.read_any_raw_message::<Msg>() {
                    match raw {
                        MAVLinkMessageRaw::V2(m)
                            if m.incompatibility_flags() & 1 == 1
                                && verifier.verify_signature(&m) =>
                        {
                            signed_ok += 1
                        }
                        _ => unsigned += 1,
                    }
                }
            }
            if let Some(addr) = from {
                let mut bytes = Vec::new();
                for m in telemetry(v) {
                    // The autopilot holds the key too and signs what it sends.
                    let h = MavHeader {
                        system_id: 1,
                        component_id: 1,
                        sequence: seq,
                    };
                    seq = seq.wrapping_add(1);
                    mavlink::write_v2_msg_signed(&mut bytes, h, &m, Some(&signer)).unwrap();
                }
                bytes.extend(frame(&mut seq, &telemetry(v)[1])); // unsigned telemetry: refused
                bytes.extend(frame(&mut seq, &cmd)); // unsigned command to us: refused
                let h = MavHeader {
                    system_id: 255,
                    component_id: 190,
                    sequence: 0,
                };
                mavlink::write_v2_msg_signed(&mut bytes, h, &cmd, Some(&signer)).unwrap(); // signed: passes
                let _ = sock.send_to(&bytes, addr).await;
            }
        }
        (signed_ok, unsigned)
    });

    let mut args = FlyArgs::from_cli([
        "--connect".to_string(),
        format!("udpout:127.0.0.1:{port}"),
        "--policy".into(),
        "mission".into(),
        "--duration".into(),
        "3s".into(),
        "--auto-start".into(),
    ])
    .unwrap();
    args.signing_key = Some(key_path);
    let mut records: Vec<DecisionRecord> = Vec::new();
    let report = run_with(args, ScriptedDecider::new(20.0, 6, "mission"), &mut records)
        .await
        .unwrap();
    let (signed_ok, unsigned) = peer.await.unwrap();
    assert!(signed_ok >= 2, "our heartbeats arrive signed and verify");
    assert_eq!(unsigned, 0, "nothing we send is unsigned or badly signed");
    assert!(report.ingest.unsigned_commands_refused >= 1);
    assert_eq!(
        report.ingest.unsigned_refused, report.ingest.unsigned_commands_refused,
        "one unsigned SYS_STATUS refused per burst, as many as unsigned commands"
    );
    assert_eq!(report.ingest.bad_signatures, 0);
    // Every unsigned frame was refused; each signed one was accepted alongside the signed telemetry.
    assert!(report.ingest.frames_ok >= 6 * report.ingest.unsigned_commands_refused);
}
