//! Review of the synthetic 100-cycle mission against counts worked out by hand from its phase
//! boundaries (synthetic.rs): base 0; wp1 1–7; wpi 8–15; wpf 16–21; target 22–25; v3 26–92
//! with the obstacle detour at 40–45 and V3 -> V1 from 60; landing 93–99.

use super::*;
use crate::decision_log::{Header, LogEvent, LogRead, LossMark, synthetic};
use std::time::UNIX_EPOCH;

fn log_of(records: Vec<DecisionRecord>) -> LogRead {
    let mut h = Header::new("companion simulate --policy safety --seed 1", UNIX_EPOCH);
    h.step_s = Some(1.0);
    LogRead {
        header: Some(h),
        records,
        ended_cleanly: true,
        ..Default::default()
    }
}

#[test]
fn summary_counts_match_hand_count() {
    let log = log_of(synthetic::mission(100));
    let s = summarize(&log);
    assert_eq!(s.records, 100);
    assert_eq!(s.policy.as_deref(), Some("safety"));
    // target 22–25 (track_v0) + v3 26–92 (track_v3 / track_v1) = 4 + 67.
    assert_eq!(s.tracking_steps, 71);
    assert!((s.tracking_s - 71.0).abs() < 1e-9);
    assert_eq!(s.conflicts, 6); // one per obstacle cycle 40..=45
    assert_eq!(s.degradations, 1); // V3 -> V1 at cycle 60
    assert_eq!(s.reallocations, 1); // on "obstacle detected" at cycle 40
    assert_eq!(s.commands, 3); // take-off; SET_MODE LAND (timeout) + NAV_LAND
    assert_eq!(s.failed_commands, 1);
    assert_eq!(s.mode_changes, 1); // GUIDED -> LAND at 93
    assert_eq!(s.link_events, 2); // cycles 50, 51
    assert_eq!(s.outcome, "landed");
    // Last record (i = 99): energy predicted 42000 + 60*99 + 4000 = 51940 -> margin 8060 J.
    let e = &s.final_margins["energy_j"];
    assert!((e.margin - 8060.0).abs() < 1e-9);
    assert_eq!(e.goal, Some(60_000.0));
    // duration predicted 700 + 49.5 + 100 = 849.5 -> margin 50.5 s.
    assert!((s.final_margins["duration_s"].margin - 50.5).abs() < 1e-9);
}

#[test]
fn phases_follow_table_4_shape() {
    let log = log_of(synthetic::mission(100));
    let r = rows(&log);
    let p = phases(&log, &r);
    let got: Vec<(&str, u64, u64)> = p
        .iter()
        .map(|p| (p.state.as_str(), p.first_cycle, p.last_cycle))
        .collect();
    assert_eq!(
        got,
        vec![
            ("base", 0, 0),
            ("wp1", 1, 7),
            ("wpi", 8, 15),
            ("wpf", 16, 21),
            ("target", 22, 25),
            ("v3", 26, 39),
            ("v3", 40, 45),
            ("v3", 46, 59),
            ("v3", 60, 92),
            ("landing", 93, 99),
        ]
    );
    assert_eq!(p[3].events, vec!["target detected"]);
    assert_eq!(p[3].resources, vec!["5 + 394 + 10 ms"]);
    assert!(p[8].marks.iter().any(|m| matches!(m, Mark::Degraded(_))));
    assert!(
        p[9].marks
            .iter()
            .any(|m| matches!(m, Mark::Mode(t) if t == "mode GUIDED → LAND"))
    );
}

#[test]
fn failsafe_events_and_losses_are_marked() {
    let mut recs = synthetic::mission(30);
    recs[10].link_events.push("FAILSAFE: radio".into());
    let mut log = log_of(recs);
    log.events.push(LogEvent {
        cycle: 12,
        time_s: 12.0,
        event: "battery failsafe".into(),
    });
    log.losses.push(LossMark {
        before_record: 20,
        dropped: 7,
    });
    let r = rows(&log);
    assert!(
        r[10]
            .marks
            .iter()
            .any(|m| matches!(m, Mark::Failsafe(t) if t == "FAILSAFE: radio"))
    );
    assert!(!r[10].marks.iter().any(|m| matches!(m, Mark::Link(_))));
    assert!(r[12].events.contains(&"battery failsafe".to_string()));
    assert!(r[12].marks.iter().any(|m| matches!(m, Mark::Failsafe(_))));
    assert_eq!(
        r[20]
            .marks
            .iter()
            .filter(|m| matches!(m, Mark::Loss(7)))
            .count(),
        1
    );
    let s = summarize(&log);
    assert_eq!(s.dropped, 7);
}

#[test]
fn html_has_one_row_per_record_and_plots_with_points() {
    let log = log_of(synthetic::mission(100));
    let s = summarize(&log);
    let r = rows(&log);
    let p = phases(&log, &r);
    let html = render_html(&log, &s, &r, &p);
    assert_eq!(html.matches("class=\"timeline-row").count(), 100);
    assert_eq!(html.matches("class=\"phase-row").count(), 10);
    for id in [
        "plot-probabilities",
        "plot-margin-energy_j",
        "plot-margin-duration_s",
        "plot-cpu-load",
        "plot-fpga-tiles",
        "plot-altitude",
        "plot-battery",
    ] {
        let at = html
            .find(&format!("id=\"{id}\""))
            .unwrap_or_else(|| panic!("{id} missing"));
        let tail = &html[at..];
        let end = tail.find("</figure>").unwrap();
        assert!(tail[..end].contains("<polyline"), "{id} has no polyline");
    }
    // 9 named probabilities in the synthetic records, 100 points each.
    assert!(html.contains(r#"id="plot-probabilities" data-series="9" data-points="900""#));
    assert_eq!(html.matches("class=\"command-row").count(), 3);
    assert!(
        !html.contains("http://")
            || html.matches("http://").count()
                == html.matches("xmlns=\"http://www.w3.org/2000/svg\"").count()
    );
    assert!(!html.contains("<script"));
}

#[test]
fn html_escapes_log_text() {
    let mut recs = synthetic::mission(20);
    recs[3].events.push("<script>alert(1)</script>".into());
    let log = log_of(recs);
    let s = summarize(&log);
    let r = rows(&log);
    let html = render_html(&log, &s, &r, &phases(&log, &r));
    assert!(!html.contains("<script>"));
    assert!(html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
}

#[test]
fn ticks_are_nice() {
    assert_eq!(html::ticks(0.0, 1.0, 5), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
    assert_eq!(
        html::ticks(0.0, 100.0, 10),
        (0..=10).map(|k| k as f64 * 10.0).collect::<Vec<_>>()
    );
}

#[test]
fn policy_parsed_from_command_line() {
    assert_eq!(
        policy_from_command("companion simulate --policy mission"),
        Some("mission".into())
    );
    assert_eq!(
        policy_from_command("companion simulate --policy=safety"),
        Some("safety".into())
    );
    assert_eq!(policy_from_command("companion fly --connect x"), None);
}
