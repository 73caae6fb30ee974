//! Trust on the autopilot link, end to end through `fly`'s loop on 127.0.0.1: a `udpin` port
//! answers only the chosen autopilot (junk and impostors get nothing back), the autopilot can be
//! named with `--autopilot-sysid`, and a TCP link that only reconnects is declared lost.

use companion::fly::{FlyArgs, run_with};
use companion_core::record::DecisionRecord;
use companion_core::record::{Event, LinkEvent};
use companion_link::dialect::*;
use companion_testkit::scripted::ScriptedDecider;
use mavlink::{MavHeader, MavlinkReader};
use std::net::SocketAddr;
use std::time::Duration;
use tokio::net::UdpSocket;

type Msg = MavMessage;

fn encode(sys: u8, comp: u8, seq: &mut u8, msg: &Msg) -> Vec<u8> {
    let mut buf = Vec::new();
    let h = MavHeader {
        system_id: sys as u32,
        component_id: comp,
        sequence: *seq,
    };
    *seq = seq.wrapping_add(1);
    mavlink::write_v2_msg(&mut buf, h, msg).unwrap();
    buf
}

fn heartbeat(mode: u32) -> Msg {
    Msg::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: mode,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    })
}

fn position() -> Msg {
    Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
        lat: -353_632_610,
        lon: 1_491_652_300,
        ..GLOBAL_POSITION_INT_DATA::DEFAULT
    })
}

fn args(connect: &str, duration_s: f64) -> FlyArgs {
    let mut args = FlyArgs::from_cli(["--connect", connect, "--auto-start"]).unwrap();
    args.duration = Some(Duration::from_secs_f64(duration_s));
    args
}

fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Every frame in the datagrams a socket received: (system, component, message).
fn frames(datagrams: &[Vec<u8>]) -> Vec<(u8, u8, Msg)> {
    let mut out = Vec::new();
    for d in datagrams {
        let mut r = MavlinkReader::new(&d[..]);
        while let Ok(raw) = r.read_any_raw_message::<Msg>() {
            if let Ok(m) =
                <Msg as mavlink::Message>::parse(raw.version(), raw.message_id(), raw.payload())
            {
                out.push((raw.system_id().min(255) as u8, raw.component_id(), m));
            }
        }
    }
    out
}

/// Send `each` every `period` until `until`, collecting every datagram that comes back.
async fn talk(
    sock: UdpSocket,
    to: SocketAddr,
    period: Duration,
    until: tokio::time::Instant,
    mut each: impl FnMut(u32) -> Vec<u8>,
) -> Vec<Vec<u8>> {
    let mut got = Vec::new();
    let mut buf = vec![0u8; 4096];
    let mut tick = tokio::time::interval(period);
    let mut n = 0;
    loop {
        tokio::select! {
            _ = tick.tick() => {
                if tokio::time::Instant::now() >= until { break; }
                let bytes = each(n);
                n += 1;
                if !bytes.is_empty() {
                    let _ = sock.send_to(&bytes, to).await;
                }
            }
            r = sock.recv_from(&mut buf) => if let Ok((k, _)) = r { got.push(buf[..k].to_vec()) },
        }
    }
    // Late replies still count against the junk senders.
    while let Ok(Ok((k, _))) =
        tokio::time::timeout(Duration::from_millis(300), sock.recv_from(&mut buf)).await
    {
        got.push(buf[..k].to_vec());
    }
    got
}

/// Junk datagrams at ~200/s (one byte, frame headers that never complete, noise) and an
/// impostor autopilot
/// (sysid 7) heard before the real one: neither gets a single byte back; the real autopilot,
/// named with `--autopilot-sysid 1`, gets the companion's heartbeats and stream requests, and
/// every command is addressed to it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn udpin_junk_senders_get_nothing_and_the_autopilot_keeps_the_traffic() {
    let port = free_udp_port();
    let to: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let until = tokio::time::Instant::now() + Duration::from_millis(3500);
    let junk = tokio::spawn(talk(
        UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        to,
        Duration::from_millis(5),
        until,
        |n| match n % 3 {
            0 => vec![0x42],
            // A MAVLink 2 start byte claiming a long payload: a parser shared across datagrams
            // would complete it with the autopilot's next datagram, then, after the CRC
            // failure, find the autopilot's frames while handling a later junk datagram.
            1 => vec![0xFD, 250, 0, 0, 0x99],
            _ => (0..(n % 97) as u8 + 1)
                .map(|b| b.wrapping_mul(31))
                .collect(),
        },
    ));
    let impostor = tokio::spawn(talk(
        UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        to,
        Duration::from_millis(100),
        until,
        {
            let mut seq = 0;
            move |_| encode(7, 1, &mut seq, &heartbeat(4))
        },
    ));
    // The real autopilot starts a little later, so the impostor is heard first.
    let autopilot = tokio::spawn(async move {
        tokio::time::sleep(Duration::from_millis(400)).await;
        let mut seq = 0;
        talk(
            UdpSocket::bind("127.0.0.1:0").await.unwrap(),
            to,
            Duration::from_millis(100),
            until,
            move |_| {
                let mut b = encode(1, 1, &mut seq, &heartbeat(0));
                b.extend(encode(1, 1, &mut seq, &position()));
                b
            },
        )
        .await
    });
    let mut a = args(&format!("udpin:127.0.0.1:{port}"), 3.5);
    a.autopilot_sysid = Some(1);
    let mut records: Vec<DecisionRecord> = Vec::new();
    let report = run_with(a, ScriptedDecider::new(20.0, 6, "safety"), &mut records)
        .await
        .unwrap();
    let junk_got = junk.await.unwrap();
    let impostor_got = impostor.await.unwrap();
    let autopilot_got = frames(&autopilot.await.unwrap());

    assert_eq!(
        junk_got.iter().map(Vec::len).sum::<usize>(),
        0,
        "junk senders got bytes back"
    );
    assert_eq!(
        impostor_got.iter().map(Vec::len).sum::<usize>(),
        0,
        "the impostor autopilot got bytes back"
    );
    let ours = |m: &dyn Fn(&Msg) -> bool| {
        autopilot_got
            .iter()
            .filter(|(s, c, msg)| *s == 1 && *c == 191 && m(msg))
            .count()
    };
    assert!(
        ours(&|m| matches!(m, Msg::HEARTBEAT(_))) >= 2,
        "the autopilot hears our heartbeats"
    );
    assert!(
        ours(
            &|m| matches!(m, Msg::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL)
        ) >= 1,
        "the autopilot gets our stream requests"
    );
    let targets: Vec<u8> = autopilot_got
        .iter()
        .filter_map(|(_, _, m)| match m {
            Msg::COMMAND_LONG(c) => Some(c.target_system),
            _ => None,
        })
        .collect();
    assert!(
        targets.iter().all(|t| *t == 1),
        "commands addressed to another system: {targets:?}"
    );
    assert!(report.ingest.bytes_unframed() > 0, "the junk was counted");
    let events: Vec<String> = records
        .iter()
        .flat_map(|r| r.link_events.iter().map(LinkEvent::to_string))
        .collect();
    assert!(
        events
            .iter()
            .any(|e| e.starts_with("udpin peer") && e.contains("learned from autopilot 1/1")),
        "{events:?}"
    );
    assert!(
        events
            .iter()
            .any(|e| e.contains("another autopilot 7/1 heard, ignored")),
        "{events:?}"
    );
}

/// The autopilot's address changes (a new source port, as after its restart): the companion's
/// traffic follows it, the change is a link event, and the old address hears nothing more.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn udpin_peer_follows_the_same_autopilot_to_a_new_address() {
    let port = free_udp_port();
    let to: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let start = tokio::time::Instant::now();
    let switch_at = start + Duration::from_millis(1500);
    let mk = |sys| {
        let mut seq = 0;
        move |_| encode(sys, 1, &mut seq, &heartbeat(0))
    };
    let first = tokio::spawn(talk(
        UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        to,
        Duration::from_millis(100),
        switch_at,
        mk(1),
    ));
    let second = tokio::spawn(async move {
        tokio::time::sleep_until(switch_at).await;
        talk(
            UdpSocket::bind("127.0.0.1:0").await.unwrap(),
            to,
            Duration::from_millis(100),
            start + Duration::from_millis(3500),
            mk(1),
        )
        .await
    });
    let mut records: Vec<DecisionRecord> = Vec::new();
    run_with(
        args(&format!("udpin:127.0.0.1:{port}"), 3.5),
        ScriptedDecider::new(20.0, 6, "safety"),
        &mut records,
    )
    .await
    .unwrap();
    let first_got = frames(&first.await.unwrap());
    let second_got = frames(&second.await.unwrap());
    let hb = |got: &[(u8, u8, Msg)]| {
        got.iter()
            .filter(|(_, c, m)| *c == 191 && matches!(m, Msg::HEARTBEAT(_)))
            .count()
    };
    assert!(hb(&first_got) >= 1, "the first address was answered");
    assert!(hb(&second_got) >= 1, "the traffic followed the autopilot");
    let events: Vec<String> = records
        .iter()
        .flat_map(|r| r.link_events.iter().map(LinkEvent::to_string))
        .collect();
    assert!(
        events.iter().any(|e| e.starts_with("udpin peer changed")),
        "{events:?}"
    );
}

/// A TCP server that accepts and hangs up at once, over and over, after one burst of
/// heartbeats: the link is declared lost (reconnects are not messages from the autopilot).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_link_that_only_reconnects_is_declared_lost() {
    use tokio::io::AsyncWriteExt;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    let server = tokio::spawn(async move {
        let mut first = true;
        while let Ok((mut s, _)) = listener.accept().await {
            if first {
                first = false;
                let mut seq = 0;
                for _ in 0..5 {
                    let _ = s.write_all(&encode(1, 1, &mut seq, &heartbeat(0))).await;
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            }
            drop(s);
        }
    });
    let mut a = args(&format!("tcp:127.0.0.1:{port}"), 6.0);
    a.link_timeout = Duration::from_secs(2);
    let mut records: Vec<DecisionRecord> = Vec::new();
    let report = run_with(a, ScriptedDecider::new(20.0, 6, "safety"), &mut records)
        .await
        .unwrap();
    server.abort();
    let reconnects = records
        .iter()
        .flat_map(|r| r.link_events.iter())
        .filter(|e| matches!(e, LinkEvent::TransportConnected(n) if n.starts_with("tcp:")))
        .count();
    assert!(reconnects >= 3, "the server kept accepting: {reconnects}");
    assert!(report.link_losses >= 1, "never declared lost");
    assert!(
        records
            .iter()
            .any(|r| r.events.contains(&Event::Link(LinkEvent::Lost))),
        "no link lost event"
    );
    assert_eq!(
        records.last().unwrap().vehicle.get("link_alive"),
        Some(&serde_json::Value::from(false))
    );
}
