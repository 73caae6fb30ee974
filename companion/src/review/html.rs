//! The self-contained HTML report: inline CSS, inline SVG plots drawn here, no script, no
//! network. Elements carry stable ids/classes and data attributes (counts) for tests.

use super::{Mark, Phase, Row, Summary};
use crate::decision_log::LogRead;
use std::collections::BTreeSet;
use std::fmt::Write;

pub(crate) fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

fn num(v: f64) -> String {
    if !v.is_finite() {
        return "–".into();
    }
    if v.abs() >= 1000.0 || v == v.trunc() {
        format!("{v:.0}")
    } else if v.abs() >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// Times: up to two decimals, trailing zeros trimmed (`6`, `7.5`, `0.25`).
fn t(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

const PALETTE: [&str; 10] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
    "#7f7f7f", "#bcbd22",
];

/// A line on a plot.
pub(crate) struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub dashed: bool,
}

/// A vertical marker at a time.
pub(crate) struct VMark {
    pub t: f64,
    pub class: &'static str,
    pub text: String,
}

/// "Nice" tick values covering [lo, hi] (steps of 1, 2 or 5 times a power of ten).
pub(crate) fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater)
        || !lo.is_finite()
        || !hi.is_finite()
    {
        return vec![lo];
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let m = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .find(|m| m * mag >= raw)
        .unwrap_or(10.0);
    let step = m * mag;
    // Tick k is k*m*mag; for mag < 1 divide by 1/mag (an integer) so 3 * 0.2 prints as 0.6.
    let at = |k: f64| {
        if mag < 1.0 {
            k * m / (1.0 / mag).round()
        } else {
            k * m * mag
        }
    };
    let mut out = Vec::new();
    let mut k = (lo / step).ceil();
    while at(k) <= hi + step * 1e-9 {
        let v = at(k);
        out.push(if v == 0.0 { 0.0 } else { v });
        k += 1.0;
    }
    out
}

/// An inline SVG line plot inside a `<figure class="plot" id=...>`, with data attributes
/// giving the number of series and points drawn.
pub(crate) fn svg_plot(
    id: &str,
    title: &str,
    unit: &str,
    series: &[Series],
    y_fixed: Option<(f64, f64)>,
    marks: &[VMark],
) -> String {
    let series: Vec<&Series> = series.iter().filter(|s| !s.points.is_empty()).collect();
    let total: usize = series.iter().map(|s| s.points.len()).sum();
    let mut o = String::new();
    let _ = write!(
        o,
        r#"<figure class="plot" id="{}" data-series="{}" data-points="{}"><figcaption>{}</figcaption>"#,
        esc(id),
        series.len(),
        total,
        esc(title)
    );
    if total == 0 {
        o.push_str(r#"<p class="no-data">no data in this log</p></figure>"#);
        return o;
    }
    let (w, h) = (900.0, 240.0);
    let (ml, mr, mt, mb) = (56.0, 12.0, 10.0, 28.0);
    let all = series.iter().flat_map(|s| s.points.iter());
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(x, y) in all {
        if x.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        if y.is_finite() {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if let Some((a, b)) = y_fixed {
        y0 = y0.min(a);
        y1 = y1.max(b);
    } else {
        let pad = if y1 > y0 {
            (y1 - y0) * 0.08
        } else {
            y0.abs().max(1.0) * 0.1
        };
        y0 -= pad;
        y1 += pad;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let sx = |x: f64| ml + (x - x0) / (x1 - x0) * (w - ml - mr);
    let sy = |y: f64| mt + (1.0 - (y - y0) / (y1 - y0)) * (h - mt - mb);
    let _ = write!(
        o,
        r#"<svg viewBox="0 0 {w} {h}" xmlns="http://www.w3.org/2000/svg" role="img" aria-label="{}">"#,
        esc(title)
    );
    // Grid and axes.
    for t in ticks(y0, y1, 5) {
        let y = sy(t);
        let _ = write!(
            o,
            r##"<line class="grid" x1="{ml}" x2="{}" y1="{y:.1}" y2="{y:.1}"/><text class="tick" x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
            w - mr,
            ml - 6.0,
            y + 4.0,
            num(t)
        );
    }
    for t in ticks(x0, x1, 10) {
        let x = sx(t);
        let _ = write!(
            o,
            r##"<line class="grid" x1="{x:.1}" x2="{x:.1}" y1="{mt}" y2="{}"/><text class="tick" x="{x:.1}" y="{}" text-anchor="middle">{}</text>"##,
            h - mb,
            h - mb + 16.0,
            num(t)
        );
    }
    let _ = write!(
        o,
        r#"<text class="axis-label" x="{}" y="{}" text-anchor="end">time (s)</text><text class="axis-label" x="4" y="{}">{}</text>"#,
        w - mr,
        h - 2.0,
        mt + 8.0,
        esc(unit)
    );
    for m in marks {
        if m.t < x0 || m.t > x1 {
            continue;
        }
        let x = sx(m.t);
        let _ = write!(
            o,
            r#"<line class="vmark {}" x1="{x:.1}" x2="{x:.1}" y1="{mt}" y2="{}"><title>{}</title></line>"#,
            m.class,
            h - mb,
            esc(&format!("t = {} s: {}", num(m.t), m.text))
        );
    }
    for (k, s) in series.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        let pts: Vec<String> = s
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|&(x, y)| format!("{:.1},{:.1}", sx(x), sy(y)))
            .collect();
        let last = s.points.last().map(|p| p.1).unwrap_or(f64::NAN);
        let _ = write!(
            o,
            r#"<polyline class="series{}" data-series="{}" data-points="{}" fill="none" stroke="{color}" stroke-width="1.8"{} points="{}"><title>{} (last {})</title></polyline>"#,
            if s.dashed { " dashed" } else { "" },
            esc(&s.name),
            pts.len(),
            if s.dashed {
                r#" stroke-dasharray="6 4""#
            } else {
                ""
            },
            pts.join(" "),
            esc(&s.name),
            num(last)
        );
    }
    o.push_str("</svg><div class=\"legend\">");
    for (k, s) in series.iter().enumerate() {
        let last = s.points.last().map(|p| p.1).unwrap_or(f64::NAN);
        let _ = write!(
            o,
            r#"<span class="key{}"><i style="background:{}"></i>{} <b>{}</b></span>"#,
            if s.dashed { " dashed" } else { "" },
            PALETTE[k % PALETTE.len()],
            esc(&s.name),
            num(last)
        );
    }
    o.push_str("</div></figure>");
    o
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
.legend i{display:inline-block;width:14px;height:3px;margin-right:4px;vertical-align:middle}
.legend .dashed i{background-image:linear-gradient(90deg,#fff 50%,transparent 50%)!important}
.no-data{color:#8a939c;font-style:italic}
.ok{color:#1e7b34} .failed{color:#b3261e;font-weight:600}
.issues li{margin:2px 0} .issues .bad{color:#b3261e}
details summary{cursor:pointer;font-weight:600;margin:4px 0}
pre{white-space:pre-wrap;font-size:12px;background:#f6f8fa;padding:6px;border-radius:4px;max-height:300px;overflow:auto}
"#;

fn card(o: &mut String, key: &str, id: &str, value: &str, class: &str) {
    let _ = write!(
        o,
        r#"<div class="card {class}" id="{id}"><div class="k">{}</div><div class="v">{}</div></div>"#,
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
                m.class(),
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

fn events_html(events: &[String]) -> String {
    if events.is_empty() {
        return r#"<span class="ev none">No event</span>"#.into();
    }
    events
        .iter()
        .map(|e| format!(r#"<span class="ev">{}</span>"#, esc(e)))
        .collect::<Vec<_>>()
        .join("; ")
}

fn row_classes(marks: &[Mark]) -> String {
    let set: BTreeSet<&str> = marks.iter().map(|m| m.class()).collect();
    set.into_iter().collect::<Vec<_>>().join(" ")
}

/// The whole report.
pub fn render_html(log: &LogRead, s: &Summary, rows: &[Row], phases: &[Phase]) -> String {
    let mut o = String::new();
    let title = match &log.header {
        Some(h) => format!("companion review — run started {}", h.started_utc),
        None => "companion review".to_string(),
    };
    let _ = write!(
        o,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{}</title><style>{CSS}</style></head><body>",
        esc(&title)
    );
    let _ = write!(o, "<header><h1>{}</h1><p>", esc(&title));
    if let Some(h) = &log.header {
        let _ = write!(
            o,
            "command: <code>{}</code> · git {} · schema {}",
            esc(&h.command),
            esc(&h.git_revision),
            h.schema
        );
    }
    let files = match log.files.as_slice() {
        [] => String::new(),
        [one] => one.display().to_string(),
        [first, .., last] => format!(
            "{} parts: {} … {}",
            log.files.len(),
            first.display(),
            last.file_name().unwrap_or_default().to_string_lossy()
        ),
    };
    let _ = write!(o, " · {}</p></header><main>", esc(&files));

    // Summary.
    let _ = write!(
        o,
        r#"<section id="summary" data-records="{}" data-tracking-steps="{}" data-conflicts="{}" data-degradations="{}" data-reallocations="{}" data-failed-commands="{}" data-dropped="{}" data-corrupted="{}" data-truncated="{}"><h2>Summary</h2><div class="cards">"#,
        s.records,
        s.tracking_steps,
        s.conflicts,
        s.degradations,
        s.reallocations,
        s.failed_commands,
        s.dropped,
        s.corrupted_lines,
        s.truncated
    );
    let bad_outcome = s.outcome.contains("crash") || s.truncated;
    card(
        &mut o,
        "mission outcome",
        "sum-outcome",
        &s.outcome,
        if bad_outcome { "bad" } else { "" },
    );
    card(
        &mut o,
        "policy",
        "sum-policy",
        s.policy.as_deref().unwrap_or("unknown"),
        "",
    );
    if let Some(sc) = &s.scenario {
        card(&mut o, "scenario", "sum-scenario", sc, "");
    }
    card(
        &mut o,
        "tracking time",
        "sum-tracking",
        &format!("{} steps / {} s", s.tracking_steps, num(s.tracking_s)),
        "",
    );
    card(
        &mut o,
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
            &mut o,
            &format!("final margin {goal}"),
            &format!("sum-margin-{goal}"),
            &v,
            if m.margin < 0.0 { "bad" } else { "good" },
        );
    }
    card(
        &mut o,
        "behaviour conflicts",
        "sum-conflicts",
        &s.conflicts.to_string(),
        "",
    );
    card(
        &mut o,
        "degradations",
        "sum-degradations",
        &s.degradations.to_string(),
        "",
    );
    card(
        &mut o,
        "re-allocations",
        "sum-reallocations",
        &s.reallocations.to_string(),
        "",
    );
    card(
        &mut o,
        "failed commands",
        "sum-failed-commands",
        &format!("{} of {}", s.failed_commands, s.commands),
        if s.failed_commands > 0 { "bad" } else { "" },
    );
    card(
        &mut o,
        "mode changes",
        "sum-mode-changes",
        &s.mode_changes.to_string(),
        "",
    );
    card(
        &mut o,
        "link events",
        "sum-link-events",
        &s.link_events.to_string(),
        "",
    );
    card(
        &mut o,
        "records lost",
        "sum-dropped",
        &s.dropped.to_string(),
        if s.dropped > 0 { "bad" } else { "" },
    );
    o.push_str("</div></section>");

    // Read issues.
    let n_issues = log.corrupted.len()
        + usize::from(log.truncated.is_some())
        + log.notes.len()
        + log.losses.len()
        + usize::from(!log.ended_cleanly);
    let _ = write!(
        o,
        r#"<section id="read-issues" data-corrupted="{}" data-truncated="{}" data-newer-schema="{}"><h2>Reading the log</h2><ul class="issues">"#,
        log.corrupted.len(),
        log.truncated.is_some(),
        log.newer_schema.map(|v| v.to_string()).unwrap_or_default()
    );
    if n_issues == 0 {
        o.push_str(
            "<li class=\"ok\">read whole: every line valid, closed normally, nothing lost</li>",
        );
    }
    for n in &log.notes {
        let _ = write!(o, "<li class=\"note\">{}</li>", esc(n));
    }
    let corrupted_li = |c: &crate::decision_log::ReadIssue| {
        format!(
            r#"<li class="bad corrupted" data-line="{}">skipped {}:{}: {}</li>"#,
            c.line,
            esc(&c.file.display().to_string()),
            c.line,
            esc(&c.reason)
        )
    };
    for c in log.corrupted.iter().take(20) {
        o.push_str(&corrupted_li(c));
    }
    if log.corrupted.len() > 20 {
        let _ = write!(
            o,
            "<li><details><summary>{} more skipped lines</summary><ul>",
            log.corrupted.len() - 20
        );
        for c in &log.corrupted[20..] {
            o.push_str(&corrupted_li(c));
        }
        o.push_str("</ul></details></li>");
    }
    if let Some(t) = &log.truncated {
        let _ = write!(
            o,
            r#"<li class="bad truncated" data-line="{}">truncated at {}:{}: {}</li>"#,
            t.line,
            esc(&t.file.display().to_string()),
            t.line,
            esc(&t.reason)
        );
    }
    if !log.losses.is_empty() {
        let _ = write!(
            o,
            r#"<li class="bad loss" data-losses="{}" data-dropped="{}">{} records/events lost in {} place(s): the log writer fell behind<details><summary>where</summary><ul>"#,
            log.losses.len(),
            log.dropped(),
            log.dropped(),
            log.losses.len()
        );
        for l in &log.losses {
            let _ = write!(
                o,
                "<li>{} lost before record {}</li>",
                l.dropped, l.before_record
            );
        }
        o.push_str("</ul></details></li>");
    }
    if !log.ended_cleanly && log.truncated.is_none() {
        o.push_str("<li class=\"note\">no end line: the run did not close its log (killed or still running)</li>");
    }
    o.push_str("</ul></section>");

    // Timeline, Tables 4–7 shape.
    let _ = write!(
        o,
        r#"<section id="timeline" data-phases="{}" data-rows="{}"><h2>Timeline (as the BFM paper's Tables 4–7)</h2><table id="phase-table"><thead><tr><th>cycles</th><th>t (s)</th><th>State</th><th>Set of actions</th><th>Events</th><th>Resources</th><th>marks</th></tr></thead><tbody>"#,
        phases.len(),
        rows.len()
    );
    for p in phases {
        let cycles = if p.first_cycle == p.last_cycle {
            p.first_cycle.to_string()
        } else {
            format!("{}–{}", p.first_cycle, p.last_cycle)
        };
        let _ = write!(
            o,
            r#"<tr class="phase-row {}" data-first-cycle="{}" data-last-cycle="{}" data-records="{}"><td class="num">{}</td><td class="num">{}</td><td class="state">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"#,
            row_classes(&p.marks),
            p.first_cycle,
            p.last_cycle,
            p.records,
            cycles,
            t(p.start_s),
            esc(&p.state),
            actions_html(&p.actions),
            events_html(&p.events),
            esc(&if p.resources.is_empty() {
                "–".to_string()
            } else {
                p.resources.join(" → ")
            }),
            marks_html(&p.marks)
        );
    }
    o.push_str("</tbody></table>");
    let _ = write!(
        o,
        r#"<details id="cycles"><summary>every cycle ({} records)</summary><table id="timeline-table"><thead><tr><th>cycle</th><th>t (s)</th><th>State</th><th>Set of actions</th><th>Events</th><th>Resources</th><th>marks</th></tr></thead><tbody>"#,
        rows.len()
    );
    for row in rows {
        let r = &log.records[row.index];
        let res = r
            .resources
            .as_ref()
            .map(|x| x.summary.as_str())
            .unwrap_or("–");
        let _ = write!(
            o,
            r#"<tr class="timeline-row {}" data-cycle="{}" data-state="{}" data-actions="{}" data-events="{}"><td class="num">{}</td><td class="num">{}</td><td class="state">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"#,
            row_classes(&row.marks),
            r.cycle,
            esc(&r.state),
            r.actions.len(),
            row.events.len(),
            r.cycle,
            t(r.time_s),
            esc(&r.state),
            actions_html(&r.actions),
            events_html(&row.events),
            esc(res),
            marks_html(&row.marks)
        );
    }
    o.push_str("</tbody></table></details></section>");

    // Plots.
    let marks: Vec<VMark> = rows
        .iter()
        .flat_map(|row| {
            let t = log.records[row.index].time_s;
            row.marks.iter().map(move |m| VMark {
                t,
                class: m.class(),
                text: m.text(),
            })
        })
        .collect();
    o.push_str(r#"<section id="plots"><h2>Over time</h2><div class="plots">"#);
    let recs = &log.records;
    // Probabilities, in name order.
    let names: BTreeSet<&String> = recs.iter().flat_map(|r| r.probabilities.keys()).collect();
    let prob: Vec<Series> = names
        .iter()
        .map(|n| Series {
            name: (*n).clone(),
            points: recs
                .iter()
                .filter_map(|r| r.probabilities.get(*n).map(|p| (r.time_s, *p)))
                .collect(),
            dashed: false,
        })
        .collect();
    o.push_str(&svg_plot(
        "plot-probabilities",
        "Named probabilities (health BNs)",
        "P",
        &prob,
        Some((0.0, 1.0)),
        &marks,
    ));
    // PANORAMA: predicted total (goal - margin) against the goal, per goal.
    let goals: BTreeSet<&String> = recs
        .iter()
        .filter_map(|r| r.guarantee.as_ref())
        .flat_map(|g| g.margins.keys())
        .collect();
    if goals.is_empty() {
        o.push_str(&svg_plot(
            "plot-margins",
            "PANORAMA margins",
            "",
            &[],
            None,
            &[],
        ));
    }
    for goal in goals {
        let mut predicted = Vec::new();
        let mut goal_line = Vec::new();
        let mut margin = Vec::new();
        for r in recs {
            let Some(g) = &r.guarantee else { continue };
            let Some(m) = g.margins.get(goal) else {
                continue;
            };
            margin.push((r.time_s, *m));
            if let Some(gv) = g.goals.get(goal) {
                predicted.push((r.time_s, gv - m));
                goal_line.push((r.time_s, *gv));
            }
        }
        let (series, label) = if goal_line.is_empty() {
            (
                vec![Series {
                    name: format!("{goal} margin"),
                    points: margin,
                    dashed: false,
                }],
                "margin",
            )
        } else {
            (
                vec![
                    Series {
                        name: "predicted total (measured + estimated remainder)".into(),
                        points: predicted,
                        dashed: false,
                    },
                    Series {
                        name: "goal".into(),
                        points: goal_line,
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
    let res_series = |name: &str, f: &dyn Fn(&crate::record::ResourcesRecord) -> f64| Series {
        name: name.into(),
        points: recs
            .iter()
            .filter_map(|r| r.resources.as_ref().map(|x| (r.time_s, f(x))))
            .collect(),
        dashed: false,
    };
    o.push_str(&svg_plot(
        "plot-cpu-load",
        "CPU load (share of the CPU budget)",
        "load",
        &[res_series("cpu_load", &|x| x.cpu_load)],
        Some((0.0, 1.0)),
        &marks,
    ));
    o.push_str(&svg_plot(
        "plot-fpga-tiles",
        "FPGA tiles used",
        "tiles",
        &[res_series("tiles_used", &|x| f64::from(x.tiles_used))],
        Some((0.0, 1.0)),
        &marks,
    ));
    let veh = |key: &str| Series {
        name: key.into(),
        points: recs
            .iter()
            .filter_map(|r| {
                r.vehicle
                    .get(key)
                    .and_then(|v| v.as_f64())
                    .map(|v| (r.time_s, v))
            })
            .collect(),
        dashed: false,
    };
    o.push_str(&svg_plot(
        "plot-altitude",
        "Altitude",
        "m",
        &[veh("altitude_m")],
        Some((0.0, 1.0)),
        &marks,
    ));
    o.push_str(&svg_plot(
        "plot-battery",
        "Battery",
        "%",
        &[veh("battery_pct")],
        Some((0.0, 100.0)),
        &marks,
    ));
    o.push_str("</div></section>");

    // Commands.
    let n_cmd: usize = recs.iter().map(|r| r.commands.len()).sum();
    let _ = write!(
        o,
        r#"<section id="commands" data-commands="{n_cmd}" data-failed="{}"><h2>Commands</h2>"#,
        s.failed_commands
    );
    if n_cmd == 0 {
        o.push_str("<p class=\"no-data\">no vehicle commands in this log</p>");
    } else {
        o.push_str("<table><thead><tr><th>cycle</th><th>t (s)</th><th>action</th><th>command</th><th>result</th><th>attempts</th><th>latency (ms)</th></tr></thead><tbody>");
        for r in recs {
            for c in &r.commands {
                let ok = super::OK_RESULTS.contains(&c.result.as_str());
                let _ = write!(
                    o,
                    r#"<tr class="command-row {}"><td class="num">{}</td><td class="num">{}</td><td>{}</td><td><code>{}</code></td><td class="{}">{}</td><td class="num">{}</td><td class="num">{}</td></tr>"#,
                    if ok { "ok" } else { "failed" },
                    r.cycle,
                    t(r.time_s),
                    esc(&c.action),
                    esc(&c.command),
                    if ok { "ok" } else { "failed" },
                    esc(&c.result),
                    c.attempts,
                    c.latency_ms.map(num).unwrap_or_else(|| "–".into())
                );
            }
        }
        o.push_str("</tbody></table>");
    }
    o.push_str("</section>");

    // Params from the header.
    if let Some(h) = &log.header
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
    o.push_str("</main></body></html>\n");
    o
}
