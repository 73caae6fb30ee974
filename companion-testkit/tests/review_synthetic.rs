//! Review of the synthetic 100-cycle mission against counts worked out by hand from its phase
//! boundaries (synthetic.rs): base 0; wp1 1–7; wpi 8–15; wpf 16–21; target 22–25; v3 26–92
//! with the obstacle detour at 40–45 and V3 -> V1 from 60; landing 93–99.

use companion::decision_log::LogItem;
use companion::decision_log::LossReason;
use companion::decision_log::{Header, LogEvent, ReadIssue};
use companion::review::outcomes::Category;
use companion::review::*;
use companion_core::record::DecisionRecord;
use companion_core::record::{CommandRecord, Conflict, Event, LinkEvent, MdpProposal};
use companion_testkit::synthetic;
use std::time::UNIX_EPOCH;

fn header() -> Header {
    let mut h = Header::new("companion simulate --policy safety --seed 1", UNIX_EPOCH);
    h.step_s = Some(1.0);
    h
}

fn items(records: Vec<DecisionRecord>) -> Vec<LogItem> {
    let mut v = vec![LogItem::Header(Box::new(header()))];
    v.extend(
        records
            .into_iter()
            .map(|r| LogItem::Record(Box::new(r), Vec::new())),
    );
    v.push(LogItem::End);
    v
}

fn review(records: Vec<DecisionRecord>) -> Review {
    Review::from_items(items(records), None)
}

#[test]
fn summary_counts_match_hand_count() {
    let rev = review(synthetic::mission(100));
    let s = &rev.summary;
    assert_eq!(s.records, 100);
    assert_eq!(s.policy.as_deref(), Some("safety"));
    // Tracking steps (companion_core::tracking): v3 cycles 26–59 choose track_v3 and stay in v3 = 34.
    // target 22–25 chooses track_v0 but never reaches v0; 60–92 choose track_v1 in state v3.
    assert_eq!(s.tracking_steps, 34);
    assert!((s.tracking_s - 34.0).abs() < 1e-9);
    assert_eq!(s.conflicts, 6); // one per obstacle cycle 40..=45
    assert_eq!(s.degradations, 1); // V3 -> V1 at cycle 60
    assert_eq!(s.reallocations, 1); // on "obstacle detected" at cycle 40
    assert_eq!(s.commands, 3); // take-off; SET_MODE LAND (timeout) + NAV_LAND
    assert_eq!(s.failed_commands, 0);
    assert_eq!(s.outcomes.get(Category::TimedOut), 1);
    assert_eq!(s.outcomes.get(Category::Accepted), 2);
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

fn command(result: &str) -> CommandRecord {
    CommandRecord {
        action: "take_off".into(),
        command: "X".into(),
        result: companion::decision_log::migration::outcome(result),
        attempts: 1,
        latency_ms: None,
    }
}

/// A flight where every command was accepted: the steps sent and then accepted, modes already
/// set, a verified upload and a skipped zone step are no failures.
#[test]
fn all_accepted_flight_shows_failed_0() {
    let mut recs = synthetic::mission(20);
    for r in &mut recs {
        r.commands.clear();
    }
    recs[1].commands = vec![
        command("SENT"),
        command("ACCEPTED"),
        command("ALREADY"),
        command("SENT"),
        command("ACCEPTED (verified 5 items)"),
    ];
    recs[2].commands = vec![
        command("SKIPPED (no zone reported; landing here)"),
        command("SENT"),
        command("ACCEPTED"),
        command("ALREADY"),
    ];
    let rev = review(recs);
    let s = &rev.summary;
    assert_eq!(s.commands, 9);
    assert_eq!(s.failed_commands, 0);
    assert_eq!(s.outcomes.get(Category::Accepted), 3);
    // Each SENT is followed by the outcome of the same step: none is unresolved at the end, so
    // none is "in progress" (issue 22: "7 in progress" for commands that all completed).
    assert_eq!(s.outcomes.get(Category::InProgress), 0);
    assert_eq!(s.outcomes.get(Category::Already), 2);
    assert_eq!(s.outcomes.get(Category::Skipped), 1);
    let html = render_html(&rev);
    assert!(html.contains(r#"data-failed-commands="0""#));
    assert!(!html.contains(r#"class="card bad" id="sum-failed-commands""#));
    assert!(html.contains("0 of 9"));
    assert_eq!(html.matches(r#"class="command-row failed""#).count(), 0);
    let term = render_terminal(&rev, false);
    assert!(term.contains("failed commands          0 of 9"), "{term}");
}

#[test]
fn phases_follow_table_4_shape() {
    let rev = review(synthetic::mission(100));
    let p = &rev.phases;
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
    let labels: Vec<String> = p[3].events.iter().map(|i| rev.spans[*i].label()).collect();
    assert_eq!(labels, vec!["target detected"]);
    assert_eq!(p[3].resources, vec!["5 + 394 + 10 ms"]);
    assert!(p[8].marks.iter().any(|m| matches!(m, Mark::Degraded(_))));
    assert!(
        p[9].marks
            .iter()
            .any(|m| matches!(m, Mark::Mode(t) if t == "mode GUIDED → LAND"))
    );
}

#[test]
fn repeated_event_folds_into_one_span() {
    let mut recs = synthetic::mission(40);
    for r in &mut recs[12..=23] {
        r.events.push(Event::Other("battery low".into()));
    }
    recs[30].events.push(Event::Other("battery low".into()));
    let rev = review(recs);
    let spans: Vec<&Span> = rev
        .spans
        .iter()
        .filter(|s| s.text == "battery low")
        .collect();
    assert_eq!(spans.len(), 2);
    assert_eq!(spans[0].label(), "cycles 12–23: battery low (×12)");
    assert_eq!(spans[1].label(), "battery low");
    let html = render_html(&rev);
    assert_eq!(html.matches("battery low (×12)").count(), 3); // phase table, cycle table, events
    assert_eq!(html.matches("battery low").count(), 6); // + the lone one at 30, as often
    let term = render_terminal(&rev, false);
    assert!(term.contains("cycles 12-23: battery low (x12)") || term.contains("battery low (×12)"));
}

fn r_has(rev: &Review, row: usize, text: &str) -> bool {
    rev.rows[row]
        .events
        .iter()
        .any(|i| rev.spans[*i].text == text)
}

#[test]
fn failsafe_events_and_losses_are_marked() {
    let mut recs = synthetic::mission(30);
    recs[10]
        .link_events
        .push(LinkEvent::Other("FAILSAFE: radio".into()));
    let mut it = items(recs);
    // An event line after record 12, and a loss line before record 20 (index 21 with header).
    it.insert(
        14,
        LogItem::Event(LogEvent {
            cycle: 12,
            time_s: 12.0,
            event: "battery failsafe".into(),
        }),
    );
    it.insert(22, LogItem::Loss(7, LossReason::QueueFull));
    // An event line for cycle 5 written after later records.
    it.insert(
        25,
        LogItem::Event(LogEvent {
            cycle: 5,
            time_s: 5.0,
            event: "late failsafe".into(),
        }),
    );
    let rev = Review::from_items(it, None);
    assert!(r_has(&rev, 5, "late failsafe"));
    assert!(
        rev.rows[5]
            .marks
            .iter()
            .any(|m| matches!(m, Mark::Failsafe(_)))
    );
    let r = &rev.rows;
    assert!(
        r[10]
            .marks
            .iter()
            .any(|m| matches!(m, Mark::Failsafe(t) if t == "FAILSAFE: radio"))
    );
    assert!(!r[10].marks.iter().any(|m| matches!(m, Mark::Link(_))));
    assert!(
        r[12]
            .events
            .iter()
            .any(|i| rev.spans[*i].text == "battery failsafe")
    );
    assert!(r[12].marks.iter().any(|m| matches!(m, Mark::Failsafe(_))));
    assert_eq!(
        r[20]
            .marks
            .iter()
            .filter(|m| matches!(m, Mark::Loss(7, _)))
            .count(),
        1
    );
    assert_eq!(rev.summary.dropped, 7);
}

#[test]
fn html_has_one_row_per_record_and_plots_with_points() {
    let rev = review(synthetic::mission(100));
    let html = render_html(&rev);
    assert_eq!(html.matches("class=\"timeline-row").count(), 100);
    assert_eq!(html.matches("class=\"phase-row").count(), 10);
    assert_eq!(html.matches("class=\"why\" id=\"why-cycle-").count(), 100);
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
fn twenty_probability_lines_have_distinct_colour_and_dash() {
    let mut recs = synthetic::mission(10);
    for r in &mut recs {
        for k in 0..20 {
            r.probabilities.insert(format!("P_{k:02}"), 0.5);
        }
    }
    let html = render_html(&review(recs));
    let at = html.find(r#"id="plot-probabilities""#).unwrap();
    let fig = &html[at..at + html[at..].find("</figure>").unwrap()];
    let mut styles = std::collections::BTreeSet::new();
    let mut n = 0;
    for part in fig.split("<polyline").skip(1) {
        let attr = |k: &str| {
            let a = part.find(&format!("{k}=\"")).unwrap() + k.len() + 2;
            part[a..a + part[a..].find('"').unwrap()].to_string()
        };
        styles.insert((attr("data-color"), attr("data-dash")));
        n += 1;
    }
    assert!(n >= 20);
    assert_eq!(styles.len(), n, "{styles:?}");
}

#[test]
fn why_of_a_cycle_has_the_proposals_action_and_value() {
    let mut recs = synthetic::mission(30);
    recs[17].proposals = vec![
        MdpProposal {
            mdp: "navigation".into(),
            state: "wpf".into(),
            action: "continue_route".into(),
            actions: ["follow_trajectory"].into_iter().collect(),
            value: 12.345,
            iterations: 3,
            ..Default::default()
        },
        MdpProposal {
            mdp: "tracking".into(),
            action: "detect".into(),
            value: -0.5,
            ..Default::default()
        },
    ];
    recs[17].conflicts = vec![Conflict {
        kept: ["avoid_obstacle"].into_iter().collect(),
        dropped: ["follow_trajectory"].into_iter().collect(),
        rule: "safety first".into(),
    }];
    let mut it = items(recs);
    // Proposal 0 recorded the probabilities it read.
    if let LogItem::Record(_, inputs) = &mut it[18] {
        *inputs = vec![Some(serde_json::json!({"P_nav_ok": 0.93})), None];
    }
    let rev = Review::from_items(it, Some(17));
    let w = rev.asked_why.as_ref().expect("cycle 17 kept");
    let text = render_why(w, false);
    assert!(text.contains("continue_route"), "{text}");
    assert!(text.contains("value 12.345"), "{text}");
    assert!(text.contains("P_nav_ok = 0.930"), "{text}");
    assert!(text.contains("kept avoid_obstacle, gave way: follow_trajectory (rule safety first)"));
    assert!(text.contains("guarantee"), "{text}");
    let html = render_html(&rev);
    let at = html.find(r#"id="why-cycle-17""#).unwrap();
    let sec = &html[at..at + html[at..].find("</details>").unwrap()];
    assert!(
        sec.contains(r#"data-action="continue_route" data-value="12.345""#),
        "{sec}"
    );
    assert!(sec.contains("P_nav_ok = 0.930"));
}

#[test]
fn html_escapes_log_text() {
    let mut recs = synthetic::mission(20);
    recs[3]
        .events
        .push(Event::Other("<script>alert(1)</script>".into()));
    let html = render_html(&review(recs));
    assert!(!html.contains("<script>"));
    assert!(html.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
}

/// Keys and values that end up in attributes (margin keys in ids, MDP names in data-*, mark
/// classes) as well as in text: no raw `<script>`, no quote that closes an attribute.
#[test]
fn crafted_keys_and_values_are_escaped_everywhere_attributes_included() {
    let evil = r#"x"><script>alert('1')</script><b class='y"#;
    let mut recs = synthetic::mission(20);
    for r in &mut recs {
        if let Some(g) = &mut r.guarantee {
            g.margins.insert(evil.into(), 1.0);
            g.goals.insert(evil.into(), 2.0);
        }
        r.probabilities.insert(evil.into(), 0.5);
        r.vehicle.insert("mode".into(), serde_json::json!(evil));
    }
    recs[5].proposals.push(MdpProposal {
        mdp: evil.into(),
        action: evil.into(),
        ..Default::default()
    });
    recs[6].state = evil.into();
    recs[7].commands.push(command(evil));
    let mut it = items(recs);
    it.push(LogItem::Corrupted(ReadIssue {
        file: evil.into(),
        line: 1,
        reason: evil.into(),
    }));
    it.push(LogItem::Note(evil.into()));
    let mut h = header();
    h.command = evil.into();
    h.params.insert(evil.into(), evil.into());
    it[0] = LogItem::Header(Box::new(h));
    let html = render_html(&Review::from_items(it, None));
    assert!(!html.contains("<script"), "raw script tag");
    assert!(!html.contains(r#"x">"#), "a quote closed an attribute");
    assert!(!html.contains("'1'"), "raw single quotes");
    assert!(html.contains("x&quot;&gt;&lt;script&gt;alert(&#39;1&#39;)"));
}

#[test]
fn terminal_summary_strips_control_characters() {
    let mut recs = synthetic::mission(20);
    recs[4].events.push(Event::Other(
        "EKF\x1b[2J\x1b]0;pwned\x07 variance\x08".into(),
    ));
    recs[5].state = "v\x1b[31m3".into();
    recs[6].link_events.push(LinkEvent::Other(
        "STATUSTEXT: \x1b[1;31mPreArm\x1b[0m\r\n".into(),
    ));
    let rev = review(recs);
    let out = render_terminal(&rev, false);
    assert!(!out.chars().any(|c| c.is_control() && c != '\n'), "{out:?}");
    assert!(out.contains("EKF variance"), "{out}");
    let coloured = render_terminal(&rev, true);
    // Only our own SGR colour codes remain.
    for esc_seq in coloured.split('\x1b').skip(1) {
        assert!(
            esc_seq.starts_with("[1m")
                || esc_seq.starts_with("[0m")
                || esc_seq.starts_with("[31m")
                || esc_seq.starts_with("[33m"),
            "{esc_seq:?}"
        );
    }
    assert!(!coloured.contains("pwned\x07"));
}

#[test]
fn ticks_are_nice() {
    assert_eq!(plot::ticks(0.0, 1.0, 5), vec![0.0, 0.2, 0.4, 0.6, 0.8, 1.0]);
    assert_eq!(
        plot::ticks(0.0, 100.0, 10),
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

/// The review holds bounded aggregates, not the log: after 20,000 records the rows, plot
/// points and spans it keeps are capped, and the counts still cover every record.
#[test]
fn review_of_a_long_log_keeps_bounded_state() {
    let one = synthetic::mission(100);
    let mut rev = Review::new();
    rev.push(LogItem::Header(Box::new(header())));
    let n = 20_000u64;
    for i in 0..n {
        let mut r = one[(i % 100) as usize].clone();
        r.cycle = i;
        r.time_s = i as f64;
        r.events.push(Event::Other(format!("distinct event {i}")));
        rev.push(LogItem::Record(Box::new(r), Vec::new()));
    }
    rev.finish();
    assert_eq!(rev.summary.records, n as usize);
    assert_eq!(rev.rows.len(), MAX_ROWS);
    assert_eq!(rev.rows_omitted, n as usize - MAX_ROWS);
    assert!(rev.spans.len() <= MAX_SPANS);
    assert!(rev.phases.len() <= MAX_PHASES);
    for d in rev.plots.probabilities.values() {
        assert!(d.points().len() <= plot::MAX_POINTS + 1);
    }
    let html = render_html(&rev);
    assert!(html.contains(r#"id="rows-omitted""#));
}

#[test]
fn full_disk_is_told_from_a_killed_process() {
    // The writer's loss line after a failed write, and no end line: the disk filled.
    let mut full = items(synthetic::mission(20));
    full.pop(); // no end line
    full.push(LogItem::Loss(35, LossReason::WriteFailed));
    let rev = Review::from_items(full, None);
    assert_eq!(rev.summary.lost_write_failed, 35);
    assert!(
        rev.summary.outcome.contains("failed writes"),
        "{}",
        rev.summary.outcome
    );
    assert!(!rev.summary.outcome.contains("process stopped"));
    let html = render_html(&rev);
    assert!(html.contains("records lost to failed writes"));
    assert!(!html.contains("killed or still running"));

    // Same records, no loss line, no end line: killed.
    let mut killed = items(synthetic::mission(20));
    killed.pop();
    let rev = Review::from_items(killed, None);
    assert_eq!(rev.summary.lost_write_failed, 0);
    assert!(
        rev.summary.outcome.contains("process stopped"),
        "{}",
        rev.summary.outcome
    );
}
