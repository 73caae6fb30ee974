//! Post-flight review of a decision log: a summary, a timeline shaped like the BFM paper's
//! Tables 4–7 (state, set of actions, events, resources), the why of every cycle, plots over
//! time, a map of the flown track, the commands by outcome.
//! `companion review RUN_OR_LOG [--out report.html] [--summary] [--cycle N]`; see
//! docs/decision-log.md.
//!
//! The log is streamed: records are read one at a time into bounded aggregates ([`Review`]), so
//! the memory a review needs does not grow with the log (plots are decimated, per-cycle rows
//! and lists capped with the omission said in the report).

mod html;
pub mod outcomes;
pub mod plot;
mod records;
mod terminal;
// The text helpers live on the ground floor (`crate::text`); kept here by their old path.
pub use crate::text;
pub mod why;

use crate::decision_log::migration::mission_states_of;
pub use html::render_html;
pub use records::{distance_m, policy_from_command};
use records::{is_failsafe, mode, position, vehicle_f64};
pub use terminal::{render_terminal, render_why};

use crate::decision_log::{Header, LogItem, LossReason, ReadError, ReadIssue, stream_log};
use companion_core::mission::{ActionRole, RouteRole};
use companion_core::record::{CommandRecord, DecisionRecord, Event, LinkEvent, OperatorEvent};
use companion_core::tracking::TrackingCounter;
use outcomes::{Category, OutcomeCounts, categorize};
use plot::Decimator;
use std::collections::{BTreeMap, HashMap};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use why::Why;

/// Per-cycle rows (timeline table and why) kept in the report; later cycles are summarised.
pub const MAX_ROWS: usize = 3000;
pub const MAX_PHASES: usize = 2000;
pub const MAX_SPANS: usize = 5000;
pub const MAX_COMMANDS: usize = 5000;
pub const MAX_ISSUES: usize = 200;
/// Probability lines drawn (the first names in order); more are counted, not drawn.
pub const MAX_SERIES: usize = 48;
const MAX_MARKS: usize = 2000;
const MAX_PENDING_EVENT_CYCLES: usize = 1000;

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
    #[error("cycle {cycle} is not in this log (cycles {first}..={last})")]
    NoSuchCycle { cycle: u64, first: u64, last: u64 },
    /// The report's file is refused or cannot be written (`output_file`); escaped already.
    #[error("report not written: {reason}")]
    Refused { reason: String },
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
    /// The paper's Table 8 "tracking time (nbr steps)", by [`companion_core::tracking`]: the same
    /// definition `simulate` counts with.
    pub tracking_steps: usize,
    pub tracking_s: f64,
    /// Goal name (`energy_j`, `duration_s`) -> margin in the last record that had a guarantee.
    pub final_margins: BTreeMap<String, FinalMargin>,
    pub conflicts: usize,
    pub degradations: usize,
    pub reallocations: usize,
    pub commands: usize,
    /// Commands whose result is a failure (category `failed` only).
    pub failed_commands: usize,
    pub outcomes: OutcomeCounts,
    pub mode_changes: usize,
    pub link_events: usize,
    pub dropped: u64,
    pub corrupted_lines: usize,
    pub truncated: bool,
    pub ended_cleanly: bool,
    /// Records lost to failed writes (a full disk) and to the log's size cap: with either, a
    /// log without its end line ran out of room rather than being killed.
    pub lost_write_failed: u64,
    pub lost_capped: u64,
    /// Telemetry frames `flight.tlog` did not write because it reached its size cap.
    pub tlog_capped: u64,
    /// `--live` runs: messages the live viewers lost, as the last record counts them.
    pub live_dropped: Option<u64>,
}

/// Something to flag on a cycle.
#[derive(Debug, Clone, PartialEq)]
pub enum Mark {
    Mode(String),
    Failsafe(String),
    Link(String),
    Degraded(String),
    Reallocated(String),
    Loss(u64, LossReason),
}

impl Mark {
    pub fn class(&self) -> &'static str {
        match self {
            Mark::Mode(_) => "mode-change",
            Mark::Failsafe(_) => "failsafe",
            Mark::Link(_) => "link-event",
            Mark::Degraded(_) => "degraded",
            Mark::Reallocated(_) => "reallocated",
            Mark::Loss(..) => "loss",
        }
    }
    pub fn text(&self) -> String {
        match self {
            Mark::Mode(t) | Mark::Failsafe(t) | Mark::Link(t) | Mark::Degraded(t) => t.clone(),
            Mark::Reallocated(t) => format!("re-allocated: {t}"),
            Mark::Loss(n, why) => format!("{n} records lost ({})", why.text()),
        }
    }
}

/// An event sentence over consecutive cycles: "cycles 12–23: <sentence> (×12)".
#[derive(Debug, Clone, PartialEq)]
pub struct Span {
    pub text: String,
    pub first_cycle: u64,
    pub last_cycle: u64,
    pub count: usize,
}

impl Span {
    pub fn label(&self) -> String {
        if self.count > 1 {
            format!(
                "cycles {}–{}: {} (×{})",
                self.first_cycle, self.last_cycle, self.text, self.count
            )
        } else {
            self.text.clone()
        }
    }
}

/// One row of the Tables 4–7 shaped timeline: consecutive records with the same state and
/// action set.
#[derive(Debug, Clone, PartialEq)]
pub struct Phase {
    pub state: String,
    pub actions: Vec<String>,
    /// Event spans starting in this phase (indices into [`Review::spans`]).
    pub events: Vec<usize>,
    /// Distinct resource summaries in order ("5 + 394 ms").
    pub resources: Vec<String>,
    pub first_cycle: u64,
    pub last_cycle: u64,
    pub start_s: f64,
    pub records: usize,
    pub marks: Vec<Mark>,
}

/// One decision cycle as the per-cycle table and the why section show it.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    pub cycle: u64,
    pub time_s: f64,
    pub state: String,
    pub actions: Vec<String>,
    /// Event spans starting at this cycle (indices into [`Review::spans`]).
    pub events: Vec<usize>,
    /// Distinct event sentences of this cycle, folded or not.
    pub event_count: usize,
    pub resources: Option<String>,
    pub marks: Vec<Mark>,
    pub why: Why,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CommandRow {
    pub cycle: u64,
    pub time_s: f64,
    pub command: CommandRecord,
    pub category: Category,
}

/// Plot data, decimated to a bounded number of points per line.
#[derive(Debug, Default)]
pub struct Plots {
    pub probabilities: BTreeMap<String, Decimator>,
    pub probability_names_not_drawn: usize,
    /// goal -> (predicted total, goal, margin).
    pub margins: BTreeMap<String, (Decimator, Decimator, Decimator)>,
    pub cpu_load: Decimator,
    pub tiles_used: Decimator,
    pub altitude: Decimator,
    pub battery: Decimator,
    /// (longitude, latitude) in degrees.
    pub track: Decimator,
    pub marks: Vec<(f64, Mark)>,
}

/// Everything a report shows, built from the log one item at a time.
#[derive(Debug, Default)]
pub struct Review {
    pub files: Vec<PathBuf>,
    pub header: Option<Header>,
    pub summary: Summary,
    pub phases: Vec<Phase>,
    pub phases_omitted: usize,
    pub rows: Vec<Row>,
    pub rows_omitted: usize,
    pub spans: Vec<Span>,
    pub spans_omitted: usize,
    pub commands: Vec<CommandRow>,
    pub commands_omitted: usize,
    pub plots: Plots,
    pub corrupted: Vec<ReadIssue>,
    pub truncated: Option<ReadIssue>,
    pub notes: Vec<String>,
    /// (record index the loss precedes, records lost).
    pub losses: Vec<(usize, u64)>,
    pub newer_schema: Option<u32>,
    /// The why of the cycle asked for with `--cycle`.
    pub asked_why: Option<Why>,

    // Streaming state.
    asked_cycle: Option<u64>,
    pending: Option<(Box<DecisionRecord>, Vec<Option<serde_json::Value>>)>,
    pending_events: BTreeMap<u64, Vec<Event>>,
    pending_loss: (u64, LossReason),
    open_spans: HashMap<String, usize>,
    prev_cycle: Option<u64>,
    prev_mode: Option<String>,
    tracking: TrackingCounter,
    last_gap: Option<f64>,
    first_time: Option<f64>,
    last_time: f64,
    crash: Option<(String, u64)>,
    last: Option<LastRecord>,
    /// Where the vehicle took off from: the first position before it armed (fly logs).
    home: Option<(f64, f64)>,
    /// Some record said the vehicle was armed.
    ever_armed: bool,
    /// The last start refusal of the log, in the operator's words (the gate's event, with the
    /// guarantee's verdict when the refused cycle has one).
    refused: Option<String>,
    /// Started next to a flight in progress: handed off (why) or resumed (fly/restart.rs).
    restart: Option<String>,
    /// The previous record's `vehicle.armed`.
    prev_armed: Option<bool>,
    /// (action, command) -> in-progress results not yet followed by an outcome.
    open_in_progress: HashMap<(String, String), usize>,
}

#[derive(Debug, Default)]
struct LastRecord {
    state: String,
    cycle: u64,
    landing: bool,
    returning: bool,
    altitude: Option<f64>,
    armed: Option<bool>,
    mode: Option<String>,
    /// `vehicle.operator`: `waiting`, `started`, `taken_over`.
    operator: Option<String>,
    /// (longitude, latitude).
    position: Option<(f64, f64)>,
}

impl Review {
    pub fn new() -> Self {
        Self::default()
    }

    /// Also keep the why of `cycle` (`review --cycle N`), wherever it is in the log.
    pub fn with_cycle(mut self, cycle: Option<u64>) -> Self {
        self.asked_cycle = cycle;
        self
    }

    /// Feed one item of the log.
    pub fn push(&mut self, item: LogItem) {
        match item {
            LogItem::Header(h) => {
                if self.header.is_none() {
                    self.tracking = TrackingCounter::new(mission_states_of(&h));
                    self.header = Some(*h);
                }
            }
            LogItem::Record(r, inputs) => {
                if let Some((prev, prev_inputs)) = self.pending.take() {
                    self.finalize(*prev, &prev_inputs);
                }
                let mut r = r;
                if let Some(extra) = self.pending_events.remove(&r.cycle) {
                    r.events.extend(extra);
                }
                self.pending = Some((r, inputs));
            }
            LogItem::Event(e) => match &mut self.pending {
                Some((r, _)) if r.cycle == e.cycle => r.events.push(Event::Other(e.event)),
                Some((r, _)) if e.cycle < r.cycle => self.attach_late_event(e.cycle, e.event),
                _ => {
                    if self.pending_events.len() < MAX_PENDING_EVENT_CYCLES
                        || self.pending_events.contains_key(&e.cycle)
                    {
                        let v = self.pending_events.entry(e.cycle).or_default();
                        if v.len() < MAX_ISSUES {
                            v.push(Event::Other(e.event));
                        }
                    }
                }
            },
            // Telemetry frames, not records: said in the summary, not as a gap in the records.
            LogItem::Loss(n, LossReason::TlogCap) => self.summary.tlog_capped += n,
            LogItem::Loss(n, why) => {
                if let Some((prev, prev_inputs)) = self.pending.take() {
                    self.finalize(*prev, &prev_inputs);
                }
                match why {
                    LossReason::WriteFailed => self.summary.lost_write_failed += n,
                    LossReason::Cap => self.summary.lost_capped += n,
                    LossReason::QueueFull | LossReason::TooLarge | LossReason::TlogCap => {}
                }
                self.pending_loss = (self.pending_loss.0 + n, why);
                self.summary.dropped += n;
                if self.losses.len() < MAX_ISSUES {
                    self.losses.push((self.summary.records, n));
                }
            }
            LogItem::End => self.summary.ended_cleanly = true,
            LogItem::Corrupted(i) => {
                self.summary.corrupted_lines += 1;
                if self.corrupted.len() < MAX_ISSUES {
                    self.corrupted.push(i);
                }
            }
            LogItem::Truncated(i) => {
                self.summary.truncated = true;
                self.truncated = Some(i);
            }
            LogItem::Note(n) => {
                if self.notes.len() < MAX_ISSUES {
                    self.notes.push(n);
                }
            }
            LogItem::NewerSchema(v) => {
                self.newer_schema = Some(self.newer_schema.unwrap_or(0).max(v));
            }
        }
    }

    /// An event line for a cycle already reviewed (written after later records): onto its row
    /// and phase as a span of its own.
    fn attach_late_event(&mut self, cycle: u64, text: String) {
        let at = self.rows.partition_point(|r| r.cycle < cycle);
        let Some(row) = self.rows.get_mut(at).filter(|r| r.cycle == cycle) else {
            return;
        };
        if self.spans.len() >= MAX_SPANS {
            self.spans_omitted += 1;
            return;
        }
        let id = self.spans.len();
        self.spans.push(Span {
            text: text.clone(),
            first_cycle: cycle,
            last_cycle: cycle,
            count: 1,
        });
        row.events.push(id);
        row.event_count += 1;
        let mark = is_failsafe(&text).then_some(Mark::Failsafe(text));
        if let Some(m) = &mark {
            row.marks.push(m.clone());
        }
        if let Some(p) = self
            .phases
            .iter_mut()
            .rev()
            .find(|p| p.first_cycle <= cycle && cycle <= p.last_cycle)
        {
            p.events.push(id);
            if let Some(m) = mark {
                p.marks.push(m);
            }
        }
    }

    fn finalize(&mut self, r: DecisionRecord, inputs: &[Option<serde_json::Value>]) {
        let armed = self.count(&r);
        self.summary.live_dropped = r.live_dropped.max(self.summary.live_dropped);
        self.count_commands(&r);
        let marks = self.marks(&r);
        let (started, n_texts) = self.spans(&r);
        let res = r.resources.as_ref().map(|x| x.summary.clone());
        self.phase(&r, res.as_ref(), &started, &marks);
        self.plot(&r, &marks);
        self.outcome_inputs(&r, armed);
        // Rows and why.
        if self.asked_cycle == Some(r.cycle) && self.asked_why.is_none() {
            self.asked_why = Some(Why::of(&r, inputs));
        }
        if self.rows.len() < MAX_ROWS {
            self.rows.push(Row {
                cycle: r.cycle,
                time_s: r.time_s,
                state: r.state.clone(),
                actions: r.actions.to_names(),
                events: started,
                event_count: n_texts,
                resources: res,
                marks,
                why: Why::of(&r, inputs),
            });
        } else {
            self.rows_omitted += 1;
        }
    }

    /// The summary's counts, the flight's bounds, home and final margins; the record's `armed`.
    fn count(&mut self, r: &DecisionRecord) -> Option<bool> {
        let s = &mut self.summary;
        s.records += 1;
        s.first_cycle.get_or_insert(r.cycle);
        s.last_cycle = Some(r.cycle);
        if let Some(t0) = self.first_time {
            self.last_gap = Some((r.time_s - self.last_time).max(0.0));
            s.duration_s = r.time_s - t0;
        } else {
            self.first_time = Some(r.time_s);
        }
        self.last_time = r.time_s;
        self.tracking.push(r);
        s.conflicts += r.conflicts.len();
        if let Some(res) = &r.resources {
            s.degradations += res.degraded.len();
        }
        // Flights in the log (fly): a flight is over when the vehicle disarms; the records after
        // it (the next flight's, its fresh guarantee) do not replace its margins until the
        // vehicle arms again. Logs without `armed` (simulate) are one flight.
        let armed = r.vehicle.get("armed").and_then(|v| v.as_bool());
        let flight_over = self.ever_armed && armed == Some(false);
        let first_disarm = flight_over && self.prev_armed == Some(true);
        if armed == Some(true) {
            self.ever_armed = true;
        }
        if !self.ever_armed
            && let Some(p) = position(r)
        {
            // The newest position on the ground before the first arming.
            self.home = Some(p);
        }
        if self.home.is_none() {
            self.home = position(r);
        }
        self.prev_armed = armed.or(self.prev_armed);
        if r.guarantee
            .as_ref()
            .is_some_and(|g| g.reallocation.is_some())
        {
            s.reallocations += 1;
        }
        if let Some(g) = r
            .guarantee
            .as_ref()
            .filter(|_| !flight_over || first_disarm)
        {
            s.final_margins = g
                .margins
                .iter()
                .take(MAX_SERIES)
                .map(|(k, m)| {
                    let goal = g.goals.get(k).copied();
                    (k.clone(), FinalMargin { margin: *m, goal })
                })
                .collect();
        }
        armed
    }

    /// The commands' outcomes and rows.
    fn count_commands(&mut self, r: &DecisionRecord) {
        for c in &r.commands {
            let cat = categorize(&c.result);
            // "In progress" is what is still unresolved at the end of the log: a step sent and
            // awaiting its answer is counted by the outcome that follows it, if one does.
            let key = (c.action.clone(), c.command.clone());
            if cat == Category::InProgress {
                *self.open_in_progress.entry(key).or_default() += 1;
            } else {
                self.open_in_progress.remove(&key);
                self.summary.outcomes.add(cat);
            }
            self.summary.commands += 1;
            if cat == Category::Failed {
                self.summary.failed_commands += 1;
            }
            if self.commands.len() < MAX_COMMANDS {
                self.commands.push(CommandRow {
                    cycle: r.cycle,
                    time_s: r.time_s,
                    command: c.clone(),
                    category: cat,
                });
            } else {
                self.commands_omitted += 1;
            }
        }
        self.summary.link_events += r.link_events.len();
    }

    /// The record's marks: losses, mode changes, failsafes, link events, degradations,
    /// re-allocations.
    fn marks(&mut self, r: &DecisionRecord) -> Vec<Mark> {
        // Marks.
        let mut marks = Vec::new();
        if self.pending_loss.0 > 0 {
            marks.push(Mark::Loss(self.pending_loss.0, self.pending_loss.1));
            self.pending_loss.0 = 0;
        }
        let m = mode(r);
        if let (Some(now), Some(before)) = (&m, &self.prev_mode)
            && now != before
        {
            self.summary.mode_changes += 1;
            marks.push(Mark::Mode(format!("mode {before} → {now}")));
        }
        if m.is_some() {
            self.prev_mode = m;
        }
        let event_texts = r.events.iter().map(Event::to_string);
        let link_texts: Vec<String> = r.link_events.iter().map(LinkEvent::to_string).collect();
        for e in event_texts.chain(link_texts.iter().cloned()) {
            if is_failsafe(&e) {
                marks.push(Mark::Failsafe(e));
            }
        }
        for l in link_texts {
            if !is_failsafe(&l) {
                marks.push(Mark::Link(l));
            }
        }
        if let Some(res) = &r.resources {
            marks.extend(res.degraded.iter().map(|d| Mark::Degraded(d.to_string())));
        }
        if let Some(re) = r.guarantee.as_ref().and_then(|g| g.reallocation.as_ref()) {
            marks.push(Mark::Reallocated(re.reason.clone()));
        }

        marks
    }

    /// The event spans the record extends or starts; the spans started and the number of
    /// distinct sentences.
    fn spans(&mut self, r: &DecisionRecord) -> (Vec<usize>, usize) {
        // Event spans: a sentence also present in the previous cycle extends its span.
        let consecutive = self
            .prev_cycle
            .is_some_and(|p| r.cycle == p + 1 || r.cycle == p);
        // Distinct sentences in first-seen order, through a set: a flood of events stays
        // linear (a list lookup per event was quadratic: 34 s for 100,000 events).
        let mut texts: Vec<String> = Vec::new();
        let mut seen_texts = std::collections::HashSet::new();
        for e in &r.events {
            let e = e.to_string();
            if seen_texts.insert(e.clone()) {
                texts.push(e);
            }
        }
        let mut started = Vec::new();
        let mut still_open = HashMap::new();
        for t in &texts {
            match self.open_spans.get(t) {
                Some(&id) if consecutive => {
                    let sp = &mut self.spans[id];
                    sp.last_cycle = r.cycle;
                    sp.count += 1;
                    still_open.insert((*t).clone(), id);
                }
                _ => {
                    if self.spans.len() < MAX_SPANS {
                        let id = self.spans.len();
                        self.spans.push(Span {
                            text: (*t).clone(),
                            first_cycle: r.cycle,
                            last_cycle: r.cycle,
                            count: 1,
                        });
                        started.push(id);
                        still_open.insert((*t).clone(), id);
                    } else {
                        self.spans_omitted += 1;
                    }
                }
            }
        }
        self.open_spans = still_open;
        self.prev_cycle = Some(r.cycle);

        (started, texts.len())
    }

    /// The phase (state and actions) the record extends or starts.
    fn phase(
        &mut self,
        r: &DecisionRecord,
        res: Option<&String>,
        started: &[usize],
        marks: &[Mark],
    ) {
        // Phases.
        let same = self
            .phases
            .last()
            .is_some_and(|p| p.state == r.state && r.actions == p.actions[..])
            && self.phases_omitted == 0;
        if !same {
            if self.phases.len() < MAX_PHASES {
                self.phases.push(Phase {
                    state: r.state.clone(),
                    actions: r.actions.to_names(),
                    events: Vec::new(),
                    resources: Vec::new(),
                    first_cycle: r.cycle,
                    last_cycle: r.cycle,
                    start_s: r.time_s,
                    records: 0,
                    marks: Vec::new(),
                });
            } else {
                self.phases_omitted += 1;
            }
        }
        if self.phases_omitted == 0
            && let Some(p) = self.phases.last_mut()
        {
            p.last_cycle = r.cycle;
            p.records += 1;
            p.events.extend(started.iter().copied());
            if let Some(x) = res
                && !x.is_empty()
                && !p.resources.contains(x)
                && p.resources.len() < 16
            {
                p.resources.push(x.clone());
            }
            for m in marks {
                if p.marks.len() < 64 && !p.marks.contains(m) {
                    p.marks.push(m.clone());
                }
            }
        }
    }

    /// The plotted series.
    fn plot(&mut self, r: &DecisionRecord, marks: &[Mark]) {
        // Plots.
        let t = r.time_s;
        for (name, p) in &r.probabilities {
            let room = self.plots.probabilities.len() < MAX_SERIES;
            match self.plots.probabilities.get_mut(name) {
                Some(d) => d.push(t, *p),
                None if room => {
                    let mut d = Decimator::default();
                    d.push(t, *p);
                    self.plots.probabilities.insert(name.clone(), d);
                }
                None => self.plots.probability_names_not_drawn += 1,
            }
        }
        if let Some(g) = &r.guarantee {
            for (goal, m) in g.margins.iter().take(8) {
                let e = self.plots.margins.entry(goal.clone()).or_default();
                e.2.push(t, *m);
                if let Some(gv) = g.goals.get(goal) {
                    e.0.push(t, gv - m);
                    e.1.push(t, *gv);
                }
            }
        }
        if let Some(x) = &r.resources {
            self.plots.cpu_load.push(t, x.cpu_load);
            self.plots.tiles_used.push(t, f64::from(x.tiles_used));
        }
        if let Some(a) = vehicle_f64(r, "altitude_m") {
            self.plots.altitude.push(t, a);
        }
        if let Some(b) = vehicle_f64(r, "battery_pct") {
            self.plots.battery.push(t, b);
        }
        if let Some((lon, lat)) = position(r) {
            self.plots.track.push(lon, lat);
        }
        for m in marks {
            if self.plots.marks.len() < MAX_MARKS {
                self.plots.marks.push((t, m.clone()));
            }
        }
    }

    /// What the outcome is judged from: a crash, and the last record.
    fn outcome_inputs(&mut self, r: &DecisionRecord, armed: Option<bool>) {
        // The gate's refusal event (fly/gate.rs), and the guarantee's typed verdict when the
        // models refused on energy.
        for e in &r.events {
            self.restart = outcomes::restart_words(e).or(self.restart.take());
            if let Event::Operator(OperatorEvent::StartRefused { why, .. }) = e {
                let why = why.trim();
                let verdict = (r.guarantee.as_ref())
                    .and_then(|g| g.verdict.as_ref())
                    .filter(|v| !v.fits)
                    .map(|v| format!(" ({})", v.words().join("; ")));
                self.refused = Some(format!("{why}{}", verdict.unwrap_or_default()));
            }
        }
        // Outcome inputs.
        if self.crash.is_none() && (r.state == "crash" || r.state == "collision") {
            self.crash = Some((r.state.clone(), r.cycle));
        }
        // The run's own params say which state lands and which actions do (their roles).
        let states = self.tracking.states();
        let roles = states.actions();
        self.last = Some(LastRecord {
            state: r.state.clone(),
            cycle: r.cycle,
            landing: states.is_route(RouteRole::Landing, &r.state)
                || r.state == "zone_ok"
                || roles.any(&r.actions, ActionRole::Land)
                || roles.any(&r.actions, ActionRole::ReplanAndLand),
            returning: roles.any(&r.actions, ActionRole::ReturnToBase),
            altitude: vehicle_f64(r, "altitude_m"),
            armed,
            mode: mode(r),
            operator: r
                .vehicle
                .get("operator")
                .and_then(|v| v.as_str())
                .map(str::to_string),
            position: position(r),
        });
    }

    /// Close the stream: judge the last record and word the outcome.
    pub fn finish(&mut self) {
        if let Some((prev, prev_inputs)) = self.pending.take() {
            self.finalize(*prev, &prev_inputs);
        }
        let h = self.header.as_ref();
        let last_step = h.and_then(|h| h.step_s).or(self.last_gap).unwrap_or(0.0);
        let (steps, secs) = self.tracking.finish(last_step);
        let s = &mut self.summary;
        for n in self.open_in_progress.values() {
            for _ in 0..*n {
                s.outcomes.add(Category::InProgress);
            }
        }
        s.tracking_steps = steps;
        s.tracking_s = secs;
        s.policy = h.and_then(|h| h.policy.clone().or_else(|| policy_from_command(&h.command)));
        s.scenario = h.and_then(|h| h.scenario.clone());
        let home = self.home;
        let ever_armed = self.ever_armed;
        let mut out = match (&self.crash, &self.last) {
            (_, None) => "no decision records".to_string(),
            (Some((state, cycle)), _) => format!("crashed ({state} at cycle {cycle})"),
            // Fly logs say whether the vehicle is armed: the end is told from that.
            (None, Some(l)) if l.armed.is_some() => {
                flight_end(l, home, ever_armed, self.refused.as_deref())
            }
            (None, Some(l)) if l.landing => match l.altitude {
                Some(a) if a > 0.5 => format!("landing (log ends at {a:.1} m)"),
                _ => "landed".into(),
            },
            (None, Some(l)) if l.returning => "returning to base".into(),
            (None, Some(l)) => format!("log ends in state {} at cycle {}", l.state, l.cycle),
        };
        if self.last.is_some() {
            if s.truncated {
                out.push_str("; log truncated");
            } else if s.lost_write_failed > 0 {
                out.push_str(&format!(
                    "; {} records lost to failed writes (disk full?)",
                    s.lost_write_failed
                ));
            } else if s.lost_capped > 0 {
                out.push_str(&format!(
                    "; {} records over the log's size cap",
                    s.lost_capped
                ));
            } else if !s.ended_cleanly {
                out.push_str("; no end line (process stopped?)");
            }
        }
        if let Some(r) = &self.restart {
            out = format!("started in flight, {r}; {out}");
        }
        s.outcome = out;
        if let Some(v) = self.newer_schema {
            self.notes.insert(
                0,
                format!(
                    "this log has schema {v}, newer than this companion reads ({}): fields it \
                     does not know are ignored; upgrade companion for a full review",
                    companion_core::record::SCHEMA_VERSION
                ),
            );
        }
    }

    /// Review a whole stream of items (tests and callers with records in hand).
    pub fn from_items(items: impl IntoIterator<Item = LogItem>, cycle: Option<u64>) -> Review {
        let mut r = Review::new().with_cycle(cycle);
        for i in items {
            r.push(i);
        }
        r.finish();
        r
    }
}

/// How a fly log ends, from its last record: taken over (by which mode), landed and disarmed
/// (where, how far from home) or still armed (altitude, mode).
fn flight_end(
    l: &LastRecord,
    home: Option<(f64, f64)>,
    ever_armed: bool,
    refused: Option<&str>,
) -> String {
    let mode = l.mode.as_deref().unwrap_or("unknown");
    let taken = if l.operator.as_deref() == Some("taken_over") {
        format!("taken over by the pilot (mode {mode}); ")
    } else {
        String::new()
    };
    let at = match l.position {
        Some((lon, lat)) => {
            let from_home = home
                .map(|h| format!(", {:.0} m from home", distance_m(h, (lon, lat))))
                .unwrap_or_else(|| ", home unknown".into());
            format!(" at {lat:.6}, {lon:.6}{from_home}")
        }
        None => " (no position in the log)".into(),
    };
    let alt = l
        .altitude
        .map(|a| format!(" at {a:.1} m"))
        .unwrap_or_else(|| " (altitude unknown)".into());
    match l.armed {
        Some(true) => format!("{taken}log ended with the vehicle armed{alt} in {mode}{at}"),
        _ if ever_armed => format!("{taken}landed and disarmed{at}"),
        _ => match refused {
            Some(why) => format!("{taken}never armed: start refused: {why}"),
            None => format!(
                "{taken}never armed: log ends on the ground in state {}",
                l.state
            ),
        },
    }
}

/// Read and review a run folder or log file, one line at a time.
pub fn review_path(input: &Path, cycle: Option<u64>) -> Result<Review, ReviewError> {
    let stream = stream_log(input)?;
    let mut rev = Review::new().with_cycle(cycle);
    rev.files = stream.files().to_vec();
    for item in stream {
        rev.push(item?);
    }
    rev.finish();
    Ok(rev)
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
    run_with_cycle(input, out, summary, None)
}

/// `companion review` with `--cycle N`: the why of cycle N in the terminal (and the report
/// only when `--out` is given).
pub fn run_with_cycle(
    input: &Path,
    out: Option<&Path>,
    summary: bool,
    cycle: Option<u64>,
) -> Result<Option<PathBuf>, ReviewError> {
    let rev = review_path(input, cycle)?;
    for note in &rev.notes {
        eprintln!("note: {}", text::clean(note));
    }
    for c in &rev.corrupted {
        eprintln!(
            "skipped {}:{}: {}",
            text::clean(&c.file.display().to_string()),
            c.line,
            text::clean(&c.reason)
        );
    }
    if let Some(t) = &rev.truncated {
        eprintln!(
            "truncated {}:{}: {}",
            text::clean(&t.file.display().to_string()),
            t.line,
            text::clean(&t.reason)
        );
    }
    let color = std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    if summary {
        print!("{}", render_terminal(&rev, color));
    }
    if let Some(c) = cycle {
        match &rev.asked_why {
            Some(w) => print!("{}", render_why(w, color)),
            None => {
                return Err(ReviewError::NoSuchCycle {
                    cycle: c,
                    first: rev.summary.first_cycle.unwrap_or(0),
                    last: rev.summary.last_cycle.unwrap_or(0),
                });
            }
        }
    }
    if (summary || cycle.is_some()) && out.is_none() {
        return Ok(None);
    }
    let path = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| default_report_path(input));
    // The log (every part) and the tlog are inputs the report may not replace.
    let mut inputs = crate::decision_log::log_files(input).unwrap_or_default();
    inputs.push(if input.is_dir() {
        input.join("flight.tlog")
    } else {
        input.with_file_name("flight.tlog")
    });
    let html = render_html(&rev);
    crate::output_file::write(&path, &inputs, "review", html.as_bytes(), 0o644).map_err(|e| {
        ReviewError::Refused {
            reason: e.to_string(),
        }
    })?;
    println!("report: {}", text::clean(&path.display().to_string()));
    Ok(Some(path))
}
