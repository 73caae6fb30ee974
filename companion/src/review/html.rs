//! The self-contained HTML report: inline CSS, inline SVG plots and map drawn here, no script,
//! no network. Every value from the log goes through [`esc`], in text and in attributes alike.
//! Elements carry stable ids/classes and data attributes (counts) for tests.

use super::outcomes::Category;
use super::plot::{Series, VMark, num, svg_map, svg_plot};
use super::text::esc;
use super::why::Why;
use super::{Mark, Review, Span};
use std::collections::BTreeSet;
use std::fmt::Write;

/// Times: up to two decimals, trailing zeros trimmed (`6`, `7.5`, `0.25`).
fn t(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

const CSS: &str = r#"
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1d232a;background:#f5f6f8}
header{background:#1d2b3a;color:#fff;padding:14px 24px}
header h1{margin:0;font-size:20px} header p{margin:4px 0 0;color:#c8d3de;font-size:12px}
main{padding:16px 24px;max-width:1280px}
section{background:#fff;border:1px solid #dde1e6;border-radius:6px;padding:12px 16px;margin:0 0 16px}
h2{font-size:16px;margin:0 0 10px}
.cards{display:flex;flex-wrap:wrap;gap:8px}
.card{border:1px solid #e3e6ea;border-radius:5px;padding:6px 10px;min-width:130px;background:#fafbfc}
.card .k{font-size:11px;color:#5b6570;text-transform:uppercase;letter-spacing:.03em}
.card .v{font-size:17px;font-weight:600}
.card.bad .v{color:#b3261e} .card.good .v{color:#1e7b34}
table{border-collapse:collapse;width:100%;font-size:13px}
th,td{border-bottom:1px solid #e6e8eb;padding:4px 6px;text-align:left;vertical-align:top}
th{background:#f0f2f4;position:sticky;top:0}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.state{font-weight:600;white-space:nowrap}
.act{display:inline-block;background:#eef3fb;border:1px solid #d3def0;border-radius:3px;padding:0 4px;margin:1px;font-family:ui-monospace,monospace;font-size:12px}
.ev{color:#8a5a00}
.mark{display:inline-block;border-radius:3px;padding:0 4px;margin:1px;font-size:12px}
.mark.mode-change{background:#e0f2f7;color:#0b5b6e}
.mark.failsafe{background:#fde2e0;color:#a1160a;font-weight:600}
.mark.link-event{background:#fdeede;color:#8a4300}
.mark.degraded{background:#f3e8fb;color:#5e2a84}
.mark.reallocated{background:#e6f4e6;color:#1e6b2b}
.mark.loss{background:#fde2e0;color:#a1160a}
tr.failsafe td{background:#fff4f3} tr.mode-change td:first-child{border-left:3px solid #0b8aa8}
.plots{display:grid;grid-template-columns:repeat(auto-fit,minmax(560px,1fr));gap:12px}
figure.plot{margin:0;border:1px solid #e6e8eb;border-radius:5px;padding:6px 8px;background:#fff}
figure.plot figcaption{font-weight:600;font-size:13px;margin-bottom:2px}
figure.plot svg{width:100%;height:auto;display:block}
.grid{stroke:#eceef1;stroke-width:1} .tick{font-size:11px;fill:#6b747d} .axis-label{font-size:11px;fill:#6b747d}
.vmark{stroke-width:1;stroke-dasharray:2 3} .vmark.mode-change{stroke:#0b8aa8} .vmark.failsafe{stroke:#d62728;stroke-dasharray:none}
.vmark.link-event{stroke:#ff7f0e} .vmark.degraded{stroke:#9467bd} .vmark.reallocated{stroke:#2ca02c} .vmark.loss{stroke:#d62728}
.legend{font-size:12px;display:flex;flex-wrap:wrap;gap:4px 12px}
figure.plot .legend svg.swatch{width:26px;height:8px;display:inline-block;vertical-align:middle;margin-right:4px}
.why{border-top:1px solid #eceef1;padding:2px 0} .why ul{margin:2px 0 4px 18px;padding:0} .why .inputs{color:#5b6570;font-size:12px}
.map svg{max-width:520px;height:auto;border:1px solid #e6e8eb} .map-note{font-size:12px;color:#5b6570}
td.accepted,td.already{color:#1e7b34} td.in-progress,td.skipped{color:#5b6570} td.denied,td.failed,td.timed-out{color:#b3261e;font-weight:600}
.no-data{color:#8a939c;font-style:italic}
.ok{color:#1e7b34} .failed{color:#b3261e;font-weight:600}
.issues li{margin:2px 0} .issues .bad{color:#b3261e}
details summary{cursor:pointer;font-weight:600;margin:4px 0}
pre{white-space:pre-wrap;font-size:12px;background:#f6f8fa;padding:6px;border-radius:4px;max-height:300px;overflow:auto}
"#;

fn card(o: &mut String, key: &str, id: &str, value: &str, class: &str) {
    let _ = write!(
        o,
        r#"<div class="card {}" id="{}"><div class="k">{}</div><div class="v">{}</div></div>"#,
        esc(class),
        esc(id),
        esc(key),
        esc(value)
    );
}

fn marks_html(marks: &[Mark]) -> String {
    marks
        .iter()
        .map(|m| {
            format!(
                r#"<span class="mark {}">{}</span>"#,
                esc(m.class()),
                esc(&m.text())
            )
        })
        .collect()
}

fn actions_html(actions: &[String]) -> String {
    if actions.is_empty() {
        return "–".into();
    }
    actions
        .iter()
        .map(|a| format!(r#"<span class="act">{}</span>"#, esc(a)))
        .collect()
}

fn events_html(spans: &[Span], ids: &[usize]) -> String {
    if ids.is_empty() {
        return r#"<span class="ev none">No event</span>"#.into();
    }
    ids.iter()
        .filter_map(|i| spans.get(*i))
        .map(|s| {
            format!(
                r#"<span class="ev" data-count="{}">{}</span>"#,
                s.count,
                esc(&s.label())
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

fn row_classes(marks: &[Mark]) -> String {
    let set: BTreeSet<&str> = marks.iter().map(|m| m.class()).collect();
    esc(&set.into_iter().collect::<Vec<_>>().join(" "))
}

fn why_html(w: &Why) -> String {
    let mut o = String::new();
    let _ = write!(
        o,
        r#"<details class="why" id="why-cycle-{}" data-cycle="{}" data-proposals="{}" data-conflicts="{}"><summary>cycle {} · t {} s · {} · {}</summary><ul>"#,
        w.cycle,
        w.cycle,
        w.proposals.len(),
        w.conflicts.len(),
        w.cycle,
        t(w.time_s),
        esc(&w.state),
        esc(&w.actions.join(", "))
    );
    if !w.shell_actions.is_empty() {
        let _ = write!(
            o,
            "<li>shell (safety rule, not a model): {}</li>",
            esc(&w.shell_actions.join(", "))
        );
    }
    if w.proposals.is_empty() {
        o.push_str("<li class=\"no-data\">no proposals recorded</li>");
    }
    for p in &w.proposals {
        let _ = write!(
            o,
            r#"<li class="proposal" data-mdp="{}" data-action="{}" data-value="{}">MDP <b>{}</b> in state {}: <code>{}</code> → {} (value {})"#,
            esc(&p.mdp),
            esc(&p.action),
            p.value,
            esc(&p.mdp),
            esc(&p.state),
            esc(&p.action),
            actions_html(&p.actions),
            esc(&num(p.value))
        );
        if !p.inputs.is_empty() {
            let read: Vec<String> = p
                .inputs
                .iter()
                .map(|(k, v)| format!("{} = {}", esc(k), esc(v)))
                .collect();
            let _ = write!(o, r#"<div class="inputs">read: {}</div>"#, read.join(", "));
        }
        o.push_str("</li>");
    }
    if !w.probabilities.is_empty() && w.proposals.iter().all(|p| p.inputs.is_empty()) {
        let ps: Vec<String> = w
            .probabilities
            .iter()
            .map(|(k, v)| format!("{} = {}", esc(k), esc(&num(*v))))
            .collect();
        let _ = write!(
            o,
            r#"<li class="inputs">probabilities this cycle: {}</li>"#,
            ps.join(", ")
        );
    }
    for c in &w.conflicts {
        let _ = write!(
            o,
            r#"<li class="conflict">conflict: kept <code>{}</code>, gave way: {} (rule {})</li>"#,
            esc(&c.kept),
            actions_html(&c.dropped),
            esc(&c.rule)
        );
    }
    for d in &w.degraded {
        let _ = write!(
            o,
            r#"<li class="degraded">degraded: {}</li>"#,
            esc(&d.to_string())
        );
    }
    for d in &w.dropped {
        let _ = write!(
            o,
            r#"<li class="degraded">dropped for resources: {}</li>"#,
            esc(&d.to_string())
        );
    }
    if let Some(g) = &w.guarantee {
        let ms: Vec<String> = g
            .margins
            .iter()
            .map(|m| match m.target {
                Some(tg) => format!(
                    "{} {} of goal {}",
                    esc(&m.goal),
                    esc(&num(m.margin)),
                    esc(&num(tg))
                ),
                None => format!("{} {}", esc(&m.goal), esc(&num(m.margin))),
            })
            .collect();
        let _ = write!(
            o,
            r#"<li class="guarantee" data-infeasible="{}">guarantee ({}): margins {}"#,
            g.infeasible,
            esc(&g.activity),
            if ms.is_empty() {
                "none".into()
            } else {
                ms.join("; ")
            }
        );
        if g.infeasible {
            let _ = write!(
                o,
                " · <span class=\"failed\">cannot: {}</span>",
                esc(g
                    .infeasible_reason
                    .as_deref()
                    .unwrap_or("no allocation meets every goal"))
            );
        }
        if let Some(re) = &g.reallocation {
            let _ = write!(o, " · re-allocated: {}", esc(re));
        }
        o.push_str("</li>");
    }
    if w.omitted > 0 {
        let _ = write!(
            o,
            "<li class=\"note\">{} more entries not shown</li>",
            w.omitted
        );
    }
    o.push_str("</ul></details>");
    o
}

/// The whole report.
pub fn render_html(rev: &Review) -> String {
    let mut o = String::new();
    page_head(&mut o, rev);
    summary_section(&mut o, rev);
    read_issues_section(&mut o, rev);
    timeline_section(&mut o, rev);
    events_section(&mut o, rev);
    plots_section(&mut o, rev);
    map_section(&mut o, rev);
    commands_section(&mut o, rev);
    why_section(&mut o, rev);
    params_section(&mut o, rev);
    o.push_str("</main></body></html>\n");
    o
}

/// The document head and the run's header line.
fn page_head(o: &mut String, rev: &Review) {
    let title = match &rev.header {
        Some(h) => format!("companion review — run started {}", h.started_utc),
        None => "companion review".to_string(),
    };
    let _ = write!(
        o,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{CSS}</style></head><body>",
        esc(&title)
    );
    let _ = write!(o, "<header><h1>{}</h1><p>", esc(&title));
    if let Some(h) = &rev.header {
        let _ = write!(
            o,
            "command: <code>{}</code> · git {} · schema {}",
            esc(&h.command),
            esc(&h.git_revision),
            h.schema
        );
    }
    let files = match rev.files.as_slice() {
        [] => String::new(),
        [one] => one.display().to_string(),
        [first, .., last] => format!(
            "{} parts: {} … {}",
            rev.files.len(),
            first.display(),
            last.file_name().unwrap_or_default().to_string_lossy()
        ),
    };
    let _ = write!(o, " · {}</p></header><main>", esc(&files));
}

/// The summary cards, with their counts as data attributes.
fn summary_section(o: &mut String, rev: &Review) {
    let s = &rev.summary;
    let _ = write!(
        o,
        r#"<section id="summary" data-records="{}" data-tracking-steps="{}" data-conflicts="{}" data-degradations="{}" data-reallocations="{}" data-commands="{}" data-failed-commands="{}""#,
        s.records,
        s.tracking_steps,
        s.conflicts,
        s.degradations,
        s.reallocations,
        s.commands,
        s.failed_commands,
    );
    for c in Category::ALL {
        let _ = write!(o, r#" data-commands-{}="{}""#, c.class(), s.outcomes.get(c));
    }
    let _ = write!(
        o,
        r#" data-dropped="{}" data-corrupted="{}" data-truncated="{}"><h2>Summary</h2><div class="cards">"#,
        s.dropped, s.corrupted_lines, s.truncated
    );
    let bad_outcome = s.outcome.contains("crash") || s.truncated;
    card(
        o,
        "mission outcome",
        "sum-outcome",
        &s.outcome,
        if bad_outcome { "bad" } else { "" },
    );
    card(
        o,
        "policy",
        "sum-policy",
        s.policy.as_deref().unwrap_or("unknown"),
        "",
    );
    if let Some(sc) = &s.scenario {
        card(o, "scenario", "sum-scenario", sc, "");
    }
    card(
        o,
        "tracking time",
        "sum-tracking",
        &format!("{} steps / {} s", s.tracking_steps, num(s.tracking_s)),
        "",
    );
    card(
        o,
        "records / duration",
        "sum-records",
        &format!("{} / {} s", s.records, num(s.duration_s)),
        "",
    );
    for (goal, m) in &s.final_margins {
        let v = match m.goal {
            Some(g) if g != 0.0 => format!(
                "{} of {} ({:.0} %)",
                num(m.margin),
                num(g),
                100.0 * m.margin / g
            ),
            _ => num(m.margin),
        };
        card(
            o,
            &format!("final margin {goal}"),
            &format!("sum-margin-{goal}"),
            &v,
            if m.margin < 0.0 { "bad" } else { "good" },
        );
    }
    card(
        o,
        "behaviour conflicts",
        "sum-conflicts",
        &s.conflicts.to_string(),
        "",
    );
    card(
        o,
        "degradations",
        "sum-degradations",
        &s.degradations.to_string(),
        "",
    );
    card(
        o,
        "re-allocations",
        "sum-reallocations",
        &s.reallocations.to_string(),
        "",
    );
    card(
        o,
        "commands",
        "sum-commands",
        &format!("{}: {}", s.commands, s.outcomes.describe()),
        "",
    );
    card(
        o,
        "failed commands",
        "sum-failed-commands",
        &format!("{} of {}", s.failed_commands, s.commands),
        if s.failed_commands > 0 { "bad" } else { "" },
    );
    for c in [Category::Denied, Category::TimedOut] {
        let n = s.outcomes.get(c);
        if n > 0 {
            card(
                o,
                &format!("{} commands", c.label()),
                &format!("sum-{}-commands", c.class()),
                &n.to_string(),
                "bad",
            );
        }
    }
    card(
        o,
        "mode changes",
        "sum-mode-changes",
        &s.mode_changes.to_string(),
        "",
    );
    card(
        o,
        "link events",
        "sum-link-events",
        &s.link_events.to_string(),
        "",
    );
    card(
        o,
        "records lost",
        "sum-dropped",
        &s.dropped.to_string(),
        if s.dropped > 0 { "bad" } else { "" },
    );
    o.push_str("</div></section>");
}

/// How the log read: skipped and truncated lines, losses, how it ended.
fn read_issues_section(o: &mut String, rev: &Review) {
    let s = &rev.summary;
    let n_issues = s.corrupted_lines
        + usize::from(rev.truncated.is_some())
        + rev.notes.len()
        + rev.losses.len()
        + usize::from(!s.ended_cleanly);
    let _ = write!(
        o,
        r#"<section id="read-issues" data-corrupted="{}" data-truncated="{}" data-newer-schema="{}"><h2>Reading the log</h2><ul class="issues">"#,
        s.corrupted_lines,
        rev.truncated.is_some(),
        rev.newer_schema.map(|v| v.to_string()).unwrap_or_default()
    );
    if n_issues == 0 {
        o.push_str(
            "<li class=\"ok\">read whole: every line valid, closed normally, nothing lost</li>",
        );
    }
    for n in &rev.notes {
        let _ = write!(o, "<li class=\"note\">{}</li>", esc(n));
    }
    for c in &rev.corrupted {
        let _ = write!(
            o,
            r#"<li class="bad corrupted" data-line="{}">skipped {}:{}: {}</li>"#,
            c.line,
            esc(&c.file.display().to_string()),
            c.line,
            esc(&c.reason)
        );
    }
    if s.corrupted_lines > rev.corrupted.len() {
        let _ = write!(
            o,
            "<li class=\"bad\">{} more skipped lines not listed</li>",
            s.corrupted_lines - rev.corrupted.len()
        );
    }
    if let Some(tr) = &rev.truncated {
        let _ = write!(
            o,
            r#"<li class="bad truncated" data-line="{}">truncated at {}:{}: {}</li>"#,
            tr.line,
            esc(&tr.file.display().to_string()),
            tr.line,
            esc(&tr.reason)
        );
    }
    if !rev.losses.is_empty() {
        let _ = write!(
            o,
            r#"<li class="bad loss" data-losses="{}" data-dropped="{}">{} records/events lost in {} place(s): the log writer fell behind<details><summary>where</summary><ul>"#,
            rev.losses.len(),
            s.dropped,
            s.dropped,
            rev.losses.len()
        );
        for (before, n) in &rev.losses {
            let _ = write!(o, "<li>{n} lost before record {before}</li>");
        }
        o.push_str("</ul></details></li>");
    }
    if s.lost_write_failed > 0 {
        let _ = write!(
            o,
            "<li class=\"note\">{} records lost to failed writes: the disk filled or failed (not a killed process)</li>",
            s.lost_write_failed
        );
    } else if s.lost_capped > 0 {
        let _ = write!(
            o,
            "<li class=\"note\">{} records not written: the log reached its size cap</li>",
            s.lost_capped
        );
    } else if !s.ended_cleanly && rev.truncated.is_none() {
        o.push_str("<li class=\"note\">no end line: the run did not close its log (killed or still running)</li>");
    }
    o.push_str("</ul></section>");
}

/// The timeline in the shape of the BFM paper's Tables 4–7: phases, then every cycle.
fn timeline_section(o: &mut String, rev: &Review) {
    let _ = write!(
        o,
        r#"<section id="timeline" data-phases="{}" data-rows="{}"><h2>Timeline (as the BFM paper's Tables 4–7)</h2><table id="phase-table"><thead><tr><th>cycles</th><th>t (s)</th><th>State</th><th>Set of actions</th><th>Events</th><th>Resources</th><th>marks</th></tr></thead><tbody>"#,
        rev.phases.len(),
        rev.rows.len()
    );
    for p in &rev.phases {
        let cycles = if p.first_cycle == p.last_cycle {
            p.first_cycle.to_string()
        } else {
            format!("{}–{}", p.first_cycle, p.last_cycle)
        };
        let _ = write!(
            o,
            r##"<tr class="phase-row {}" data-first-cycle="{}" data-last-cycle="{}" data-records="{}"><td class="num"><a href="#why-cycle-{}">{}</a></td><td class="num">{}</td><td class="state">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"##,
            row_classes(&p.marks),
            p.first_cycle,
            p.last_cycle,
            p.records,
            p.first_cycle,
            cycles,
            t(p.start_s),
            esc(&p.state),
            actions_html(&p.actions),
            events_html(&rev.spans, &p.events),
            esc(&if p.resources.is_empty() {
                "–".to_string()
            } else {
                p.resources.join(" → ")
            }),
            marks_html(&p.marks)
        );
    }
    o.push_str("</tbody></table>");
    if rev.phases_omitted > 0 {
        let _ = write!(
            o,
            "<p class=\"note\">{} more phases not listed</p>",
            rev.phases_omitted
        );
    }
    let _ = write!(
        o,
        r#"<details id="cycles"><summary>every cycle ({} records)</summary><table id="timeline-table"><thead><tr><th>cycle</th><th>t (s)</th><th>State</th><th>Set of actions</th><th>Events</th><th>Resources</th><th>marks</th></tr></thead><tbody>"#,
        rev.rows.len()
    );
    for r in &rev.rows {
        let _ = write!(
            o,
            r##"<tr class="timeline-row {}" data-cycle="{}" data-state="{}" data-actions="{}" data-events="{}"><td class="num"><a href="#why-cycle-{}">{}</a></td><td class="num">{}</td><td class="state">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"##,
            row_classes(&r.marks),
            r.cycle,
            esc(&r.state),
            r.actions.len(),
            r.event_count,
            r.cycle,
            r.cycle,
            t(r.time_s),
            esc(&r.state),
            actions_html(&r.actions),
            events_html(&rev.spans, &r.events),
            esc(r.resources.as_deref().unwrap_or("–")),
            marks_html(&r.marks)
        );
    }
    o.push_str("</tbody></table></details>");
    if rev.rows_omitted > 0 {
        let _ = write!(
            o,
            "<p class=\"note\" id=\"rows-omitted\">{} later cycles not listed (the report keeps the first {}); <code>companion review RUN --cycle N</code> prints any cycle's why</p>",
            rev.rows_omitted,
            super::MAX_ROWS
        );
    }
    o.push_str("</section>");
}

/// Events folded into spans.
fn events_section(o: &mut String, rev: &Review) {
    let _ = write!(
        o,
        r#"<section id="events" data-spans="{}"><h2>Events</h2>"#,
        rev.spans.len()
    );
    if rev.spans.is_empty() {
        o.push_str("<p class=\"no-data\">no events in this log</p>");
    } else {
        o.push_str("<ul>");
        for sp in &rev.spans {
            let _ = write!(
                o,
                r#"<li class="span" data-first-cycle="{}" data-last-cycle="{}" data-count="{}">{}</li>"#,
                sp.first_cycle,
                sp.last_cycle,
                sp.count,
                esc(&sp.label())
            );
        }
        o.push_str("</ul>");
    }
    o.push_str("</section>");
}

/// Plots over time: probabilities, margins, CPU, tiles, altitude, battery.
fn plots_section(o: &mut String, rev: &Review) {
    let s = &rev.summary;
    let marks: Vec<VMark> = rev
        .plots
        .marks
        .iter()
        .map(|(tm, m)| VMark {
            t: *tm,
            class: m.class(),
            text: m.text(),
        })
        .collect();
    o.push_str(r#"<section id="plots"><h2>Over time</h2><div class="plots">"#);
    let plots = &rev.plots;
    let prob: Vec<Series> = plots
        .probabilities
        .iter()
        .map(|(n, d)| Series {
            name: n.clone(),
            points: d.points(),
            dashed: false,
        })
        .collect();
    let mut prob_title = "Named probabilities (health BNs)".to_string();
    if plots.probability_names_not_drawn > 0 {
        prob_title.push_str(&format!(
            "; {} values of further names not drawn",
            plots.probability_names_not_drawn
        ));
    }
    o.push_str(&svg_plot(
        "plot-probabilities",
        &prob_title,
        "P",
        &prob,
        Some((0.0, 1.0)),
        &marks,
    ));
    if plots.margins.is_empty() {
        o.push_str(&svg_plot(
            "plot-margins",
            "PANORAMA margins",
            "",
            &[],
            None,
            &[],
        ));
    }
    for (goal, (predicted, goal_line, margin)) in &plots.margins {
        let (series, label) = if goal_line.is_empty() {
            (
                vec![Series {
                    name: format!("{goal} margin"),
                    points: margin.points(),
                    dashed: false,
                }],
                "margin",
            )
        } else {
            (
                vec![
                    Series {
                        name: "predicted total (measured + estimated remainder)".into(),
                        points: predicted.points(),
                        dashed: false,
                    },
                    Series {
                        name: "goal".into(),
                        points: goal_line.points(),
                        dashed: true,
                    },
                ],
                "predicted vs goal",
            )
        };
        let final_m = s
            .final_margins
            .get(goal)
            .map(|m| num(m.margin))
            .unwrap_or_default();
        o.push_str(&svg_plot(
            &format!("plot-margin-{goal}"),
            &format!("PANORAMA {goal}: {label} (final margin {final_m})"),
            goal.rsplit('_').next().unwrap_or(""),
            &series,
            None,
            &marks,
        ));
    }
    let one = |name: &str, d: &super::plot::Decimator| {
        vec![Series {
            name: name.into(),
            points: d.points(),
            dashed: false,
        }]
    };
    o.push_str(&svg_plot(
        "plot-cpu-load",
        "CPU load (share of the CPU budget)",
        "load",
        &one("cpu_load", &plots.cpu_load),
        Some((0.0, 1.0)),
        &marks,
    ));
    o.push_str(&svg_plot(
        "plot-fpga-tiles",
        "FPGA tiles used",
        "tiles",
        &one("tiles_used", &plots.tiles_used),
        Some((0.0, 1.0)),
        &marks,
    ));
    o.push_str(&svg_plot(
        "plot-altitude",
        "Altitude",
        "m",
        &one("altitude_m", &plots.altitude),
        Some((0.0, 1.0)),
        &marks,
    ));
    o.push_str(&svg_plot(
        "plot-battery",
        "Battery",
        "%",
        &one("battery_pct", &plots.battery),
        Some((0.0, 100.0)),
        &marks,
    ));
    o.push_str("</div></section>");
}

/// The flown track.
fn map_section(o: &mut String, rev: &Review) {
    let plots = &rev.plots;
    o.push_str(r#"<section id="map-section"><h2>Map</h2>"#);
    o.push_str(&svg_map(&plots.track.points()));
    o.push_str("</section>");
}

/// Every vehicle command with its outcome.
fn commands_section(o: &mut String, rev: &Review) {
    let s = &rev.summary;
    let _ = write!(
        o,
        r#"<section id="commands" data-commands="{}" data-failed="{}"><h2>Commands</h2>"#,
        s.commands, s.failed_commands
    );
    if s.commands == 0 {
        o.push_str("<p class=\"no-data\">no vehicle commands in this log</p>");
    } else {
        let _ = write!(
            o,
            "<p>{} commands: {}</p>",
            s.commands,
            esc(&s.outcomes.describe())
        );
        o.push_str("<table><thead><tr><th>cycle</th><th>t (s)</th><th>action</th><th>command</th><th>outcome</th><th>result</th><th>attempts</th><th>latency (ms)</th></tr></thead><tbody>");
        for c in &rev.commands {
            let class = c.category.class();
            let _ = write!(
                o,
                r#"<tr class="command-row {}" data-category="{}"><td class="num">{}</td><td class="num">{}</td><td>{}</td><td><code>{}</code></td><td class="{}">{}</td><td>{}</td><td class="num">{}</td><td class="num">{}</td></tr>"#,
                class,
                class,
                c.cycle,
                t(c.time_s),
                esc(&c.command.action),
                esc(&c.command.command),
                class,
                esc(c.category.label()),
                esc(&c.command.result.to_string()),
                c.command.attempts,
                c.command.latency_ms.map(num).unwrap_or_else(|| "–".into())
            );
        }
        o.push_str("</tbody></table>");
        if rev.commands_omitted > 0 {
            let _ = write!(
                o,
                "<p class=\"note\">{} more commands not listed</p>",
                rev.commands_omitted
            );
        }
    }
    o.push_str("</section>");
}

/// Why, per cycle.
fn why_section(o: &mut String, rev: &Review) {
    let _ = write!(
        o,
        r#"<section id="why" data-cycles="{}"><h2>Why, cycle by cycle</h2><p class="note">What each MDP proposed and the probabilities it read, the conflicts and what gave way, the resources, the guarantee margins.</p>"#,
        rev.rows.len()
    );
    for r in &rev.rows {
        o.push_str(&why_html(&r.why));
    }
    o.push_str("</section>");
}

/// The params files the log header carries.
fn params_section(o: &mut String, rev: &Review) {
    if let Some(h) = &rev.header
        && !h.params.is_empty()
    {
        let _ = write!(
            o,
            r#"<section id="params"><h2>Params ({} files, from the log header)</h2>"#,
            h.params.len()
        );
        for (name, text) in &h.params {
            let _ = write!(
                o,
                "<details><summary>{}</summary><pre>{}</pre></details>",
                esc(name),
                esc(text)
            );
        }
        o.push_str("</section>");
    }
}
