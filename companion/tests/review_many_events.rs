//! `review` stays linear in a record's events (issue 26 item 6): one record with 100,000 events
//! took 34 s when each event was looked up in a list of the ones before it. This checks the
//! output of a review of such a record (the distinct sentences counted once, the span cap said);
//! the times measured are in docs/performance.md (no timed assertion here).

use companion::decision_log::LogItem;
use companion::review::{MAX_SPANS, Review, render_html, render_terminal};
use companion_core::record::{DecisionRecord, Event};

fn record_with_events(cycle: u64, n: usize) -> DecisionRecord {
    let mut r = DecisionRecord {
        cycle,
        time_s: cycle as f64,
        state: "wpi".into(),
        ..Default::default()
    };
    // Every sentence twice: the second of each is a repeat and must not count again.
    for i in 0..n {
        r.events.push(Event::Other(format!("autopilot: flood {i}")));
    }
    for i in 0..n {
        r.events.push(Event::Other(format!("autopilot: flood {i}")));
    }
    r
}

fn review_of(records: Vec<DecisionRecord>) -> Review {
    Review::from_items(
        records
            .into_iter()
            .map(|r| LogItem::Record(Box::new(r), Vec::new())),
        None,
    )
}

#[test]
fn a_record_with_many_events_is_reviewed_whole() {
    let n = 20_000;
    let rev = review_of(vec![record_with_events(0, n), record_with_events(1, 3)]);
    assert_eq!(rev.summary.records, 2);
    assert_eq!(rev.rows[0].event_count, n, "distinct sentences of cycle 0");
    assert_eq!(rev.rows[1].event_count, 3);
    // Spans are capped; the rest are counted, not lost silently.
    assert_eq!(rev.spans.len(), MAX_SPANS);
    assert_eq!(rev.spans_omitted, n - MAX_SPANS + 3 - 3);
    // Cycle 1 repeats three sentences of cycle 0: their spans run over both cycles.
    for i in 0..3 {
        let s = &rev.spans[i];
        assert_eq!(s.text, format!("autopilot: flood {i}"));
        assert_eq!((s.first_cycle, s.last_cycle, s.count), (0, 1, 2));
    }
    let html = render_html(&rev);
    assert!(html.contains("autopilot: flood 4999"));
    assert!(!html.contains("autopilot: flood 5000<"));
    let text = render_terminal(&rev, false);
    assert!(text.contains("Timeline"));
}

/// Measurement aid for docs/performance.md (not run by default; prints, asserts nothing timed):
/// `REVIEW_EVENTS=100000 cargo test -p companion --test review_many_events -- --ignored --nocapture`
#[test]
#[ignore]
fn measure_review_of_one_record_with_many_events() {
    let n: usize = std::env::var("REVIEW_EVENTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000);
    let rec = record_with_events(0, n / 2);
    let t = std::time::Instant::now();
    let rev = review_of(vec![rec]);
    let reviewed = t.elapsed();
    let html = render_html(&rev);
    println!(
        "{n} events: review {:.2} s, html {:.2} s ({} bytes)",
        reviewed.as_secs_f64(),
        (t.elapsed() - reviewed).as_secs_f64(),
        html.len()
    );
}
