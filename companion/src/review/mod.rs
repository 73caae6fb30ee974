//! Post-flight review of a decision log: a summary, a timeline shaped like the BFM paper's
//! Tables 4–7 (state, set of actions, events, resources), plots over time, the commands.
//! `companion review RUN_OR_LOG [--out report.html] [--summary]`; see docs/decision-log.md.

mod html;
mod terminal;

pub use html::render_html;
pub use terminal::render_terminal;

use crate::decision_log::{LogRead, ReadError, read_log};
use crate::record::DecisionRecord;
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum ReviewError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error("{path}: cannot write the report: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// Final margin of one PANORAMA goal.
#[derive(Debug, Clone, PartialEq)]
pub struct FinalMargin {
    pub margin: f64,
    pub goal: Option<f64>,
}

/// The numbers at the top of a review.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Summary {
    pub outcome: String,
    pub policy: Option<String>,
    pub scenario: Option<String>,
    pub records: usize,
    pub first_cycle: Option<u64>,
    pub last_cycle: Option<u64>,
    /// time_s of the last record minus that of the first.
    pub duration_s: f64,
    /// Cycles whose final action set holds a tracking action (`track_v0`..`track_v5`): the
    /// paper's Table 8 "tracking time (nbr steps)".
    pub tracking_steps: usize,
    pub tracking_s: f64,
    /// Goal name (`energy_j`, `duration_s`) -> margin in the last record that had a guarantee.
    pub final_margins: BTreeMap<String, FinalMargin>,
    pub conflicts: usize,
    pub degradations: usize,
    pub reallocations: usize,
    pub commands: usize,
    pub failed_commands: usize,
    pub mode_changes: usize,
    pub link_events: usize,
    pub dropped: u64,
    pub corrupted_lines: usize,
    pub truncated: bool,
    pub ended_cleanly: bool,
}

/// Command results that are not failures; anything else (DENIED, FAILED, TIMEOUT, ...) is.
pub const OK_RESULTS: [&str; 4] = ["ACCEPTED", "SIMULATED", "PENDING", "IN_PROGRESS"];

pub fn is_tracking(r: &DecisionRecord) -> bool {
    r.actions.iter().any(|a| a.starts_with("track_"))
}

/// Seconds each record stands for: the gap to the next record; the last one gets the header's
/// step length or the median gap.
pub fn record_durations(log: &LogRead) -> Vec<f64> {
    let t: Vec<f64> = log.records.iter().map(|r| r.time_s).collect();
    let mut gaps: Vec<f64> = t.windows(2).map(|w| (w[1] - w[0]).max(0.0)).collect();
    let last = log
        .header
        .as_ref()
        .and_then(|h| h.step_s)
        .unwrap_or_else(|| {
            let mut g = gaps.clone();
            g.sort_by(f64::total_cmp);
            g.get(g.len() / 2).copied().unwrap_or(0.0)
        });
    if !t.is_empty() {
        gaps.push(last);
    }
    gaps
}

fn mode(r: &DecisionRecord) -> Option<String> {
    r.vehicle.get("mode").map(|m| match m.as_str() {
        Some(s) => s.to_string(),
        None => m.to_string(),
    })
}

fn vehicle_f64(r: &DecisionRecord, key: &str) -> Option<f64> {
    r.vehicle.get(key).and_then(|v| v.as_f64())
}

fn policy_from_command(cmd: &str) -> Option<String> {
    let mut it = cmd.split_whitespace();
    while let Some(w) = it.next() {
        if w == "--policy" {
            return it.next().map(str::to_string);
        }
        if let Some(p) = w.strip_prefix("--policy=") {
            return Some(p.to_string());
        }
    }
    None
}

pub fn summarize(log: &LogRead) -> Summary {
    let recs = &log.records;
    let durations = record_durations(log);
    let mut s = Summary {
        records: recs.len(),
        first_cycle: recs.first().map(|r| r.cycle),
        last_cycle: recs.last().map(|r| r.cycle),
        duration_s: match (recs.first(), recs.last()) {
            (Some(a), Some(b)) => b.time_s - a.time_s,
            _ => 0.0,
        },
        policy: log
            .header
            .as_ref()
            .and_then(|h| h.policy.clone().or_else(|| policy_from_command(&h.command))),
        scenario: log.header.as_ref().and_then(|h| h.scenario.clone()),
        dropped: log.dropped(),
        corrupted_lines: log.corrupted.len(),
        truncated: log.truncated.is_some(),
        ended_cleanly: log.ended_cleanly,
        ..Default::default()
    };
    let mut prev_mode: Option<String> = None;
    for (r, d) in recs.iter().zip(&durations) {
        if is_tracking(r) {
            s.tracking_steps += 1;
            s.tracking_s += d;
        }
        s.conflicts += r.conflicts.len();
        if let Some(res) = &r.resources {
            s.degradations += res.degraded.len();
        }
        if let Some(g) = &r.guarantee {
            if g.reallocation.is_some() {
                s.reallocations += 1;
            }
            s.final_margins = g
                .margins
                .iter()
                .map(|(k, m)| {
                    (
                        k.clone(),
                        FinalMargin {
                            margin: *m,
                            goal: g.goals.get(k).copied(),
                        },
                    )
                })
                .collect();
        }
        s.commands += r.commands.len();
        s.failed_commands += r
            .commands
            .iter()
            .filter(|c| !OK_RESULTS.contains(&c.result.as_str()))
            .count();
        s.link_events += r.link_events.len();
        let m = mode(r);
        if m.is_some() && prev_mode.is_some() && m != prev_mode {
            s.mode_changes += 1;
        }
        if m.is_some() {
            prev_mode = m;
        }
    }
    s.outcome = outcome(log);
    s
}

/// Mission outcome in words, from the states and actions of the log (shared mission vocabulary).
fn outcome(log: &LogRead) -> String {
    let recs = &log.records;
    let Some(last) = recs.last() else {
        return "no decision records".into();
    };
    let mut out = if let Some(r) = recs
        .iter()
        .find(|r| r.state == "crash" || r.state == "collision")
    {
        format!("crashed ({} at cycle {})", r.state, r.cycle)
    } else {
        let landing = last.state == "landing"
            || last.state == "zone_ok"
            || last
                .actions
                .iter()
                .any(|a| a == "land" || a == "replan_and_land");
        let alt = vehicle_f64(last, "altitude_m");
        if landing {
            match alt {
                Some(a) if a > 0.5 => format!("landing (log ends at {a:.1} m)"),
                _ => "landed".into(),
            }
        } else if last.actions.iter().any(|a| a == "return_to_base") {
            "returning to base".into()
        } else {
            format!("log ends in state {} at cycle {}", last.state, last.cycle)
        }
    };
    if log.truncated.is_some() {
        out.push_str("; log truncated");
    } else if !log.ended_cleanly {
        out.push_str("; no end line (process stopped?)");
    }
    out
}

/// One row of the Tables 4–7 shaped timeline: consecutive records with the same state and
/// action set.
#[derive(Debug, Clone, PartialEq)]
pub struct Phase {
    pub state: String,
    pub actions: Vec<String>,
    pub events: Vec<String>,
    /// Distinct resource summaries in order ("5 + 394 ms").
    pub resources: Vec<String>,
    pub first_cycle: u64,
    pub last_cycle: u64,
    pub start_s: f64,
    pub records: usize,
    /// Something to flag: mode change, failsafe or link event, degradation.
    pub marks: Vec<Mark>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Mark {
    Mode(String),
    Failsafe(String),
    Link(String),
    Degraded(String),
    Reallocated(String),
    Loss(u64),
}

impl Mark {
    pub fn class(&self) -> &'static str {
        match self {
            Mark::Mode(_) => "mode-change",
            Mark::Failsafe(_) => "failsafe",
            Mark::Link(_) => "link-event",
            Mark::Degraded(_) => "degraded",
            Mark::Reallocated(_) => "reallocated",
            Mark::Loss(_) => "loss",
        }
    }
    pub fn text(&self) -> String {
        match self {
            Mark::Mode(t) | Mark::Failsafe(t) | Mark::Link(t) | Mark::Degraded(t) => t.clone(),
            Mark::Reallocated(t) => format!("re-allocated: {t}"),
            Mark::Loss(n) => format!("{n} records lost (log writer behind)"),
        }
    }
}

/// One row per record: everything the timeline shows about that cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub index: usize,
    pub events: Vec<String>,
    pub marks: Vec<Mark>,
}

fn is_failsafe(text: &str) -> bool {
    text.to_ascii_lowercase().contains("failsafe")
}

/// Per-record rows: the record's events, event lines of that cycle, and marks.
pub fn rows(log: &LogRead) -> Vec<Row> {
    let mut by_cycle: BTreeMap<u64, Vec<&str>> = BTreeMap::new();
    for e in &log.events {
        by_cycle.entry(e.cycle).or_default().push(&e.event);
    }
    let mut prev_mode: Option<String> = None;
    let mut out = Vec::with_capacity(log.records.len());
    for (i, r) in log.records.iter().enumerate() {
        let mut events: Vec<String> = r.events.clone();
        if let Some(extra) = by_cycle.remove(&r.cycle) {
            events.extend(extra.into_iter().map(str::to_string));
        }
        let mut marks = Vec::new();
        for l in log.losses.iter().filter(|l| l.before_record == i) {
            marks.push(Mark::Loss(l.dropped));
        }
        let m = mode(r);
        if let (Some(now), Some(before)) = (&m, &prev_mode)
            && now != before
        {
            marks.push(Mark::Mode(format!("mode {before} → {now}")));
        }
        if m.is_some() {
            prev_mode = m;
        }
        for e in events.iter().chain(&r.link_events) {
            if is_failsafe(e) {
                marks.push(Mark::Failsafe(e.clone()));
            }
        }
        for l in &r.link_events {
            if !is_failsafe(l) {
                marks.push(Mark::Link(l.clone()));
            }
        }
        if let Some(res) = &r.resources {
            marks.extend(res.degraded.iter().cloned().map(Mark::Degraded));
        }
        if let Some(re) = r.guarantee.as_ref().and_then(|g| g.reallocation.as_ref()) {
            marks.push(Mark::Reallocated(re.reason.clone()));
        }
        out.push(Row {
            index: i,
            events,
            marks,
        });
    }
    out
}

/// Group rows into Tables 4–7 shaped phases.
pub fn phases(log: &LogRead, rows: &[Row]) -> Vec<Phase> {
    let mut out: Vec<Phase> = Vec::new();
    for row in rows {
        let r = &log.records[row.index];
        let res = r
            .resources
            .as_ref()
            .map(|x| x.summary.clone())
            .unwrap_or_default();
        let same = out
            .last()
            .is_some_and(|p| p.state == r.state && p.actions == r.actions);
        if !same {
            out.push(Phase {
                state: r.state.clone(),
                actions: r.actions.clone(),
                events: Vec::new(),
                resources: Vec::new(),
                first_cycle: r.cycle,
                last_cycle: r.cycle,
                start_s: r.time_s,
                records: 0,
                marks: Vec::new(),
            });
        }
        let p = out.last_mut().expect("pushed above");
        p.last_cycle = r.cycle;
        p.records += 1;
        for e in &row.events {
            if !p.events.contains(e) {
                p.events.push(e.clone());
            }
        }
        if !res.is_empty() && !p.resources.contains(&res) {
            p.resources.push(res);
        }
        p.marks.extend(row.marks.iter().cloned());
    }
    out
}

/// Where the HTML goes when `--out` is not given: `report.html` in a run folder, or the log's
/// name with `.html` beside a log file.
pub fn default_report_path(input: &Path) -> PathBuf {
    if input.is_dir() {
        input.join("report.html")
    } else {
        input.with_extension("html")
    }
}

/// The `companion review` command. Returns the report path when one was written.
pub fn run(
    input: &Path,
    out: Option<&Path>,
    summary: bool,
) -> Result<Option<PathBuf>, ReviewError> {
    let log = read_log(input)?;
    let sum = summarize(&log);
    let rows = rows(&log);
    let phases = phases(&log, &rows);
    for note in &log.notes {
        eprintln!("note: {note}");
    }
    for c in &log.corrupted {
        eprintln!("skipped {}:{}: {}", c.file.display(), c.line, c.reason);
    }
    if let Some(t) = &log.truncated {
        eprintln!("truncated {}:{}: {}", t.file.display(), t.line, t.reason);
    }
    if summary {
        let color = std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none();
        print!("{}", render_terminal(&log, &sum, &phases, color));
        if out.is_none() {
            return Ok(None);
        }
    }
    let path = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| default_report_path(input));
    let html = render_html(&log, &sum, &rows, &phases);
    std::fs::write(&path, html).map_err(|source| ReviewError::Write {
        path: path.clone(),
        source,
    })?;
    println!("report: {}", path.display());
    Ok(Some(path))
}

#[cfg(test)]
mod tests;
