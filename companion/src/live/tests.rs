use super::server::Subscriptions;
use super::*;

fn rec(cycle: u64) -> Arc<DecisionRecord> {
    Arc::new(DecisionRecord {
        cycle,
        time_s: cycle as f64,
        ..Default::default()
    })
}

fn cycles(batch: &[(u64, Arc<DecisionRecord>)]) -> Vec<u64> {
    batch.iter().map(|(_, r)| r.cycle).collect()
}

#[test]
fn a_full_queue_keeps_the_newest_records_and_counts_each_lost_message() {
    let hub = Hub::new(3, 0);
    let (v, _wake) = hub.connect();
    hub.subscribed(&v, 2);
    for c in 1..=5 {
        hub.publish(rec(c));
    }
    // Bounded: 3 kept, the 2 oldest lost, 2 channels each.
    let (batch, closed) = hub.take(&v);
    assert_eq!(cycles(&batch), [3, 4, 5]);
    assert!(!closed);
    assert_eq!(hub.dropped(), 4);
    // Taken: room again, nothing more lost.
    hub.publish(rec(6));
    assert_eq!(cycles(&hub.take(&v).0), [6]);
    assert_eq!(hub.dropped(), 4);
}

/// Issue 37: what a stalled viewer's queue lets go of comes back to the caller (to be freed on the
/// log's thread, as without `--live`), never piled up for the server's thread to free in bursts.
#[test]
fn a_stalled_viewer_s_lost_records_come_back_to_the_caller_not_the_server() {
    let hub = Hub::new(2, 0);
    let (v, _wake) = hub.connect();
    hub.subscribed(&v, 1);
    let cycles_of = |g: LetGo| -> Vec<u64> { g.iter().flatten().map(|r| r.cycle).collect() };
    assert!(cycles_of(hub.publish(rec(1))).is_empty());
    // The previous latest (1) goes; the queue [1, 2] still has room.
    assert_eq!(cycles_of(hub.publish(rec(2))), [1]);
    for c in 3..=100 {
        // Full: the oldest queued (c - 2) and the previous latest (c - 1) both come back.
        let mut got = cycles_of(hub.publish(rec(c)));
        got.sort_unstable();
        assert_eq!(got, [c - 2, c - 1], "publish {c}");
        assert!(
            hub.lock().graveyard.is_empty(),
            "nothing left for the server at {c}"
        );
    }
    assert_eq!(cycles(&hub.take(&v).0), [99, 100]);
    assert_eq!(hub.dropped(), 98);
}

#[test]
fn a_viewer_without_subscriptions_queues_nothing_and_loses_nothing() {
    let hub = Hub::new(1, 0);
    let (v, _wake) = hub.connect();
    for c in 1..=5 {
        hub.publish(rec(c));
    }
    assert!(hub.take(&v).0.is_empty());
    assert_eq!(hub.dropped(), 0);
}

#[test]
fn each_viewer_has_its_own_queue() {
    let hub = Hub::new(2, 0);
    let (slow, _w1) = hub.connect();
    let (fast, _w2) = hub.connect();
    hub.subscribed(&slow, 1);
    hub.subscribed(&fast, 1);
    for c in 1..=4 {
        hub.publish(rec(c));
        assert_eq!(cycles(&hub.take(&fast).0), [c]);
    }
    assert_eq!(cycles(&hub.take(&slow).0), [3, 4]);
    assert_eq!(hub.dropped(), 2);
}

#[test]
fn a_viewer_subscribing_mid_run_gets_the_latest_record_once_per_channel() {
    let hub = Hub::new(8, 1_000);
    for c in 1..=3 {
        hub.publish(rec(c));
    }
    let (v, _wake) = hub.connect();
    let mut subs = Subscriptions::default();
    let new = subs
        .on_text(
            r#"{"op":"subscribe","subscriptions":[{"id":7,"channelId":1},{"id":8,"channelId":4}]}"#,
        )
        .unwrap();
    assert_eq!(new, [0, 3]);
    let (seq, latest) = hub.subscribed(&v, subs.channels()).unwrap();
    assert_eq!(latest.cycle, 3);
    let frames = subs.frames(seq, &latest, hub.start_ns, Some(&new));
    assert_eq!(frames.len(), 2);
    // messageData: opcode 1, subscription id, log time = start + time_s, the channel's JSON.
    let f = &frames[0];
    assert_eq!(f[0], 1);
    assert_eq!(u32::from_le_bytes(f[1..5].try_into().unwrap()), 7);
    assert_eq!(
        u64::from_le_bytes(f[5..13].try_into().unwrap()),
        1_000 + 3_000_000_000
    );
    let msg: serde_json::Value = serde_json::from_slice(&f[13..]).unwrap();
    assert_eq!(msg["cycle"], 3);
    // The same record again (already queued when it subscribed) is not sent twice.
    assert!(subs.frames(seq, &latest, hub.start_ns, None).is_empty());
    hub.publish(rec(4));
    let (batch, _) = hub.take(&v);
    assert_eq!(cycles(&batch), [4]);
    let (s, r) = &batch[0];
    assert_eq!(subs.frames(*s, r, hub.start_ns, None).len(), 2);
}

#[test]
fn client_messages_other_than_subscriptions_are_not_understood() {
    let mut subs = Subscriptions::default();
    for text in [
        "not json",
        r#"{"op":"advertise","channels":[]}"#,
        r#"{"op":"clientPublish"}"#,
        r#"{"op":"setParameters","parameters":[]}"#,
        r#"{"op":"subscribe","subscriptions":"all"}"#,
    ] {
        assert!(subs.on_text(text).is_none(), "{text}");
    }
    // Unknown channels are not subscribed.
    let new = subs
        .on_text(r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":99},{"id":2,"channelId":0}]}"#)
        .unwrap();
    assert!(new.is_empty());
    assert_eq!(subs.channels(), 0);
    subs.on_text(r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":2}]}"#);
    subs.on_text(r#"{"op":"unsubscribe","subscriptionIds":[1]}"#);
    assert_eq!(subs.channels(), 0);
}

#[test]
fn pacing_gives_up_on_a_viewer_that_does_not_take() {
    let hub = Hub::new(1, 0);
    let (v, _wake) = hub.connect();
    hub.subscribed(&v, 1);
    hub.publish(rec(1));
    hub.wait_for_room(Duration::ZERO);
    // Waited out: later waits return at once while it stays behind.
    let start = Instant::now();
    hub.publish(rec(2));
    hub.wait_for_room(Duration::from_secs(60));
    assert!(start.elapsed() < Duration::from_secs(60));
    assert_eq!(hub.dropped(), 1);
}

#[test]
fn live_addresses() {
    let a = |s| parse_addr(s);
    assert_eq!(
        a("ws://127.0.0.1:8765").unwrap().to_string(),
        "127.0.0.1:8765"
    );
    assert_eq!(a("127.0.0.1:8765/").unwrap().to_string(), "127.0.0.1:8765");
    assert_eq!(a("8765").unwrap().to_string(), "127.0.0.1:8765");
    assert_eq!(a("ws://0.0.0.0:0").unwrap().to_string(), "0.0.0.0:0");
    assert!(a("wss://127.0.0.1:1").unwrap_err().contains("wss://"));
    assert!(a("ws://127.0.0.1:1/x").unwrap_err().contains("path"));
    assert!(a("nonsense").is_err());
}
