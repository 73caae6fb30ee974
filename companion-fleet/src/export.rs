//! A run folder as Parquet tables (docs/fleet.md "Schema"): `runs` (one row), `records` (one row
//! per cycle, typed columns), `proposals`, `events`, `commands` and `telemetry` (the tlog).
//!
//! The log is read twice through the companion's own streaming reader (old schemas, rotation
//! parts, a cut-off last line): the first pass finds the columns a run's maps give
//! (observations, probabilities, evidence, vehicle, goals), the second writes the rows in
//! batches. Neither holds more than one record and one batch.

use crate::table::{Cell, Kind, TableWriter};
use anyhow::Context;
use companion::decision_log::{LogItem, stream_log};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The fleet dataset's schema version (docs/fleet.md): bumped on an incompatible change.
/// 2: `events` and `commands` read the decision log's typed events and outcomes (record schema
/// 2): `kind` and `text` columns replace the sentence columns `event` and `result`.
/// 3: `events` holds the operator gate's events' fields (`operator`, `start_by`, `why`), which
/// the report counts refused starts by; a schema-2 dataset lacks them (its refusals would read
/// as none), so it is re-ingested.
/// 4: the table `stretches` (the activity durations calibrate sums, written at ingest); a
/// schema-3 dataset has none, so it is re-ingested.
pub const FLEET_SCHEMA: i64 = 4;

/// The tables of a run, in the order they are written.
pub const TABLES: [&str; 10] = [
    "runs",
    "records",
    "proposals",
    "events",
    "commands",
    "telemetry",
    "samples",
    "legs",
    "bn_trials",
    "stretches",
];

/// Who a run is: its content id, vehicle, date and route.
#[derive(Debug, Clone)]
pub struct RunKey {
    /// `sha256:<hex>` of the run's contents (`companion calibrate` counts runs by the same id).
    pub run_id: String,
    pub vehicle: String,
    /// `YYYY-MM-DD` of the run's start (UTC), `unknown` without a header.
    pub date: String,
    pub route: String,
}

fn s(v: &Value) -> Cell {
    match v {
        Value::String(t) => Cell::Str(t.clone()),
        Value::Null => Cell::Null,
        other => Cell::Str(other.to_string()),
    }
}

fn f(v: &Value) -> Cell {
    v.as_f64().map_or(Cell::Null, Cell::F64)
}

fn i(v: &Value) -> Cell {
    v.as_i64()
        .or_else(|| v.as_u64().map(|u| i64::try_from(u).unwrap_or(i64::MAX)))
        .map_or(Cell::Null, Cell::I64)
}

fn b(v: &Value) -> Cell {
    v.as_bool().map_or(Cell::Null, Cell::Bool)
}

/// A typed event, link event or command outcome (record schema 2: an object tagged by `kind`
/// with its fields and its sentence as `text`): its kind, its sentence and its other fields as
/// one JSON object (null when it has none). A plain string (a note line) is an `other`.
fn typed(v: &Value) -> (Cell, Cell, Cell) {
    let Some(o) = v.as_object() else {
        return ("other".into(), s(v), Cell::Null);
    };
    let fields: serde_json::Map<String, Value> = o
        .iter()
        .filter(|(k, _)| *k != "kind" && *k != "text")
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let fields = if fields.is_empty() {
        Cell::Null
    } else {
        Value::Object(fields).to_string().into()
    };
    (s(&v["kind"]), s(&v["text"]), fields)
}

/// A list of typed events as their sentences.
fn texts(v: &Value) -> Cell {
    Cell::StrList(
        v.as_array()
            .map(|a| {
                a.iter()
                    .map(|x| match x {
                        Value::String(t) => t.clone(),
                        x => x["text"].as_str().unwrap_or_default().to_string(),
                    })
                    .collect()
            })
            .unwrap_or_default(),
    )
}

fn strs(v: &Value) -> Cell {
    Cell::StrList(
        v.as_array()
            .map(|a| {
                a.iter()
                    .map(|x| x.as_str().map_or_else(|| x.to_string(), str::to_string))
                    .collect()
            })
            .unwrap_or_default(),
    )
}

/// The header's facts, as JSON (fields the header type does not know are kept).
fn header_of(dir: &Path) -> anyhow::Result<Value> {
    let mut stream = stream_log(dir).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
    match stream.next() {
        Some(Ok(LogItem::Header(h))) => Ok(serde_json::to_value(&*h)?),
        _ => Ok(Value::Null),
    }
}

/// The vehicle a run flew: `--vehicle` when given, else `sysid<N>` of the autopilot `fly` was
/// pinned to, else `sim` for `simulate` runs, else `unknown`.
fn vehicle_of(dir: &Path, header: &Value, given: Option<&str>) -> String {
    if let Some(v) = given {
        return v.to_string();
    }
    if let Some((sys, _)) = companion::calibrate::runs::fly_pin(dir) {
        return format!("sysid{sys}");
    }
    let command = header["command"].as_str().unwrap_or("");
    if command.split_whitespace().any(|w| w == "simulate") {
        return "sim".into();
    }
    "unknown".into()
}

/// The route a run judged: the plan's route file's name (the folder it was read from differs
/// between machines), else its mission, else the scenario.
fn route_of(header: &Value) -> String {
    let plan = &header["plan"];
    if let Some(f) = plan["route_file"].as_str().filter(|t| !t.is_empty()) {
        let name = f.rsplit(['/', '\\']).next().unwrap_or(f);
        return name.to_string();
    }
    for v in [&plan["mission"], &header["scenario"]] {
        if let Some(t) = v.as_str().filter(|t| !t.is_empty()) {
            return t.to_string();
        }
    }
    "unknown".into()
}

/// A partition value safe in a folder name: `/`, `=`, `\` and control characters become `_`,
/// and a leading dot (a reader skips dot folders) too.
pub fn partition_value(v: &str) -> String {
    let mut out: String = v
        .chars()
        .map(|c| {
            if c == '/' || c == '\\' || c == '=' || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if out.starts_with('.') || out.is_empty() {
        out.insert(0, '_');
    }
    out
}

/// The key of the run in `dir`.
pub fn run_key(dir: &Path, vehicle: Option<&str>) -> anyhow::Result<RunKey> {
    let run_id = companion::calibrate::runs::content_id(dir)?;
    let header = header_of(dir)?;
    let date = header["started_utc"]
        .as_str()
        .and_then(|t| t.get(..10))
        .filter(|d| d.bytes().all(|c| c.is_ascii_digit() || c == b'-'))
        .unwrap_or("unknown")
        .to_string();
    Ok(RunKey {
        run_id,
        vehicle: vehicle_of(dir, &header, vehicle),
        date,
        route: route_of(&header),
    })
}

/// Columns a run's maps give, found by the first pass, with their types.
#[derive(Default)]
struct Dynamic {
    obs: BTreeMap<String, ()>,
    probs: BTreeMap<String, ()>,
    evidence: BTreeMap<String, ()>,
    goals: BTreeMap<String, ()>,
    /// Vehicle keys: numeric while every value seen is a number.
    vehicle: BTreeMap<String, Kind>,
}

impl Dynamic {
    fn add(&mut self, r: &Value) {
        for (map, field) in [
            (&mut self.obs, "observations"),
            (&mut self.probs, "probabilities"),
            (&mut self.evidence, "evidence"),
        ] {
            if let Some(o) = r[field].as_object() {
                map.extend(o.keys().map(|k| (k.clone(), ())));
            }
        }
        let g = &r["guarantee"];
        for field in ["margins", "goals", "drift"] {
            if let Some(o) = g[field].as_object() {
                self.goals.extend(o.keys().map(|k| (k.clone(), ())));
            }
        }
        if let Some(o) = r["vehicle"].as_object() {
            for (k, v) in o {
                let kind = if v.is_number() { Kind::F64 } else { Kind::Str };
                let e = self.vehicle.entry(k.clone()).or_insert(kind);
                if *e != kind {
                    *e = Kind::Str;
                }
            }
        }
    }
}

/// The fixed leading columns of `records` (docs/fleet.md).
const RECORD_FIXED: [(&str, Kind); 26] = [
    ("run_id", Kind::Str),
    ("vehicle", Kind::Str),
    ("route", Kind::Str),
    ("cycle", Kind::I64),
    ("time_s", Kind::F64),
    ("record_idx", Kind::I64),
    ("utc_us", Kind::I64),
    ("state", Kind::Str),
    ("actions", Kind::StrList),
    ("events", Kind::StrList),
    ("link_events", Kind::StrList),
    ("absent_evidence", Kind::StrList),
    ("resources_cpu_load", Kind::F64),
    ("resources_tiles_used", Kind::I64),
    ("resources_summary", Kind::Str),
    ("guarantee_activity", Kind::I64),
    ("guarantee_activity_name", Kind::Str),
    ("guarantee_infeasible", Kind::Bool),
    ("guarantee_infeasible_reason", Kind::Str),
    ("guarantee_reallocation_trigger", Kind::Str),
    ("guarantee_energy_source", Kind::Str),
    ("guarantee_planned_j", Kind::F64),
    ("guarantee_planned_s", Kind::F64),
    ("power_measured_j", Kind::F64),
    ("power_drift_began", Kind::Bool),
    ("verdict_fits", Kind::Bool),
];

fn record_columns(d: &Dynamic) -> Vec<(String, Kind)> {
    let mut c: Vec<(String, Kind)> = RECORD_FIXED
        .iter()
        .map(|(n, k)| (n.to_string(), *k))
        .collect();
    c.extend(d.obs.keys().map(|k| (format!("obs_{k}"), Kind::F64)));
    c.extend(d.probs.keys().map(|k| (format!("p_{k}"), Kind::F64)));
    c.extend(d.evidence.keys().map(|k| (format!("ev_{k}"), Kind::Str)));
    for prefix in ["margin", "goal", "drift"] {
        c.extend(d.goals.keys().map(|k| (format!("{prefix}_{k}"), Kind::F64)));
    }
    c.extend(d.vehicle.iter().map(|(k, t)| (format!("veh_{k}"), *t)));
    c
}

fn record_row(key: &RunKey, d: &Dynamic, r: &Value, idx: u64) -> Vec<Cell> {
    let g = &r["guarantee"];
    let res = &r["resources"];
    let mut row = vec![
        key.run_id.as_str().into(),
        key.vehicle.as_str().into(),
        key.route.as_str().into(),
        i(&r["cycle"]),
        f(&r["time_s"]),
        idx.into(),
        i(&r["utc_us"]),
        s(&r["state"]),
        strs(&r["actions"]),
        texts(&r["events"]),
        texts(&r["link_events"]),
        strs(&r["absent_evidence"]),
        f(&res["cpu_load"]),
        i(&res["tiles_used"]),
        s(&res["summary"]),
        i(&g["activity"]),
        s(&g["activity_name"]),
        b(&g["infeasible"]),
        s(&g["infeasible_reason"]),
        s(&g["reallocation"]["trigger"]),
        s(&g["energy_source"]),
        f(&g["planned_j"]),
        f(&g["planned_s"]),
        f(&g["power"]["measured_j"]),
        b(&g["power"]["drift_began"]),
        b(&g["verdict"]["fits"]),
    ];
    row.extend(d.obs.keys().map(|k| f(&r["observations"][k])));
    row.extend(d.probs.keys().map(|k| f(&r["probabilities"][k])));
    row.extend(d.evidence.keys().map(|k| s(&r["evidence"][k])));
    for field in ["margins", "goals", "drift"] {
        row.extend(d.goals.keys().map(|k| f(&g[field][k])));
    }
    for (k, t) in &d.vehicle {
        let v = &r["vehicle"][k];
        row.push(if *t == Kind::F64 { f(v) } else { s(v) });
    }
    row
}

fn cols(spec: &[(&str, Kind)]) -> Vec<(String, Kind)> {
    spec.iter().map(|(n, k)| (n.to_string(), *k)).collect()
}

const KEY: [(&str, Kind); 4] = [
    ("run_id", Kind::Str),
    ("vehicle", Kind::Str),
    ("cycle", Kind::I64),
    ("time_s", Kind::F64),
];

fn keyed(rest: &[(&str, Kind)]) -> Vec<(String, Kind)> {
    let mut c = cols(&KEY);
    c.extend(cols(rest));
    c
}

fn key_cells(key: &RunKey, cycle: Cell, time_s: Cell) -> Vec<Cell> {
    vec![
        key.run_id.as_str().into(),
        key.vehicle.as_str().into(),
        cycle,
        time_s,
    ]
}

/// An `events` row after its key and source: kind, text, the nested link event's kind (a `link`
/// event), the nested operator event's kind and how its start came about (an `operator` event),
/// the reason (the event's `why`, else its nested operator or link event's), the command's
/// action, the command's or stream's outcome kind, the other fields.
fn event_cells(e: &Value) -> [Cell; 9] {
    let (kind, text, fields) = typed(e);
    let outcome = match &e["outcome"] {
        Value::Null => Cell::Null,
        o => s(&o["kind"]),
    };
    let why = [&e["why"], &e["operator"]["why"], &e["link"]["why"]]
        .into_iter()
        .find(|w| !w.is_null())
        .unwrap_or(&Value::Null);
    [
        kind,
        text,
        s(&e["link"]["kind"]),
        s(&e["operator"]["kind"]),
        s(&e["operator"]["by"]),
        s(why),
        s(&e["action"]),
        outcome,
        fields,
    ]
}

/// The run's other tables, written beside `records`.
struct Side {
    proposals: TableWriter,
    events: TableWriter,
    commands: TableWriter,
}

impl Side {
    fn create(out: &Path) -> anyhow::Result<Self> {
        Ok(Side {
            proposals: TableWriter::create(
                &out.join("proposals.parquet"),
                &keyed(&[
                    ("idx", Kind::I64),
                    ("mdp", Kind::Str),
                    ("state", Kind::Str),
                    ("action", Kind::Str),
                    ("actions", Kind::StrList),
                    ("value", Kind::F64),
                    ("iterations", Kind::I64),
                    ("horizon", Kind::I64),
                    ("reason", Kind::Str),
                    ("inputs", Kind::Str),
                ]),
            )?,
            events: TableWriter::create(
                &out.join("events.parquet"),
                &keyed(&[
                    ("source", Kind::Str),
                    ("kind", Kind::Str),
                    ("text", Kind::Str),
                    ("link", Kind::Str),
                    ("operator", Kind::Str),
                    ("start_by", Kind::Str),
                    ("why", Kind::Str),
                    ("action", Kind::Str),
                    ("outcome", Kind::Str),
                    ("fields", Kind::Str),
                ]),
            )?,
            commands: TableWriter::create(
                &out.join("commands.parquet"),
                &keyed(&[
                    ("idx", Kind::I64),
                    ("action", Kind::Str),
                    ("command", Kind::Str),
                    ("kind", Kind::Str),
                    ("text", Kind::Str),
                    ("why", Kind::Str),
                    ("attempts", Kind::I64),
                    ("latency_ms", Kind::F64),
                ]),
            )?,
        })
    }

    fn add(&mut self, key: &RunKey, r: &Value) -> anyhow::Result<()> {
        let k = || key_cells(key, i(&r["cycle"]), f(&r["time_s"]));
        for (n, p) in r["proposals"].as_array().into_iter().flatten().enumerate() {
            let mut row = k();
            row.extend([
                (n as i64).into(),
                s(&p["mdp"]),
                s(&p["state"]),
                s(&p["action"]),
                strs(&p["actions"]),
                f(&p["value"]),
                i(&p["iterations"]),
                i(&p["horizon"]),
                s(&p["reason"]),
                if p["inputs"].is_null() {
                    Cell::Null
                } else {
                    p["inputs"].to_string().into()
                },
            ]);
            self.proposals.push(row)?;
        }
        for (source, field) in [("record", "events"), ("link", "link_events")] {
            for e in r[field].as_array().into_iter().flatten() {
                let mut row = k();
                row.push(source.into());
                row.extend(event_cells(e));
                self.events.push(row)?;
            }
        }
        for (n, c) in r["commands"].as_array().into_iter().flatten().enumerate() {
            let mut row = k();
            let (kind, text, _) = typed(&c["result"]);
            let res = &c["result"];
            let why = if res["why"].is_null() {
                &res["at"]
            } else {
                &res["why"]
            };
            row.extend([
                (n as i64).into(),
                s(&c["action"]),
                s(&c["command"]),
                kind,
                text,
                s(why),
                i(&c["attempts"]),
                f(&c["latency_ms"]),
            ]);
            self.commands.push(row)?;
        }
        Ok(())
    }
}

/// What reading a run's log found besides records.
#[derive(Default, Debug)]
pub struct LogCounts {
    pub records: u64,
    pub log_events: u64,
    pub dropped: u64,
    pub corrupted: u64,
    pub truncated: bool,
    pub newer_schema: Option<u32>,
}

/// Write the run in `dir` as Parquet files into `out` (an existing folder).
pub fn export_run(dir: &Path, out: &Path, key: &RunKey) -> anyhow::Result<LogCounts> {
    let shown = dir.display();
    // The report's energy and duration columns are there in every run, null when unknown.
    let mut dynamic = Dynamic::default();
    dynamic.goals.insert("energy_j".into(), ());
    dynamic.goals.insert("duration_s".into(), ());
    let stream = stream_log(dir).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
    for item in stream {
        if let Ok(LogItem::Record(r, _)) = item {
            dynamic.add(&serde_json::to_value(&*r)?);
        }
    }
    let mut records = TableWriter::create(&out.join("records.parquet"), &record_columns(&dynamic))?;
    let mut side = Side::create(out)?;
    let mut trials = crate::bn_rows::TrialWriter::create(&out.join("bn_trials.parquet"))?;
    let mut stretches = crate::durations::StretchWriter::create(&out.join("stretches.parquet"))?;
    let mut counts = LogCounts::default();
    let mut header = Value::Null;
    let stream = stream_log(dir).map_err(|e| anyhow::anyhow!("{shown}: {e}"))?;
    for item in stream {
        match item.map_err(|e| anyhow::anyhow!("{shown}: {e}"))? {
            LogItem::Header(h) => header = serde_json::to_value(&*h)?,
            LogItem::Record(r, _) => {
                let v = serde_json::to_value(&*r)?;
                records.push(record_row(key, &dynamic, &v, counts.records))?;
                side.add(key, &v)?;
                trials.add(key, &r, counts.records)?;
                stretches.add(key, &r)?;
                counts.records += 1;
            }
            LogItem::Event(e) => {
                let mut row = key_cells(key, e.cycle.into(), e.time_s.into());
                row.push("log".into());
                row.extend(event_cells(&Value::String(e.event)));
                side.events.push(row)?;
                counts.log_events += 1;
            }
            LogItem::Loss(n, _) => counts.dropped += n,
            LogItem::Corrupted(c) => {
                counts.corrupted += 1;
                trials.fail(format!("line {}: {}", c.line, c.reason));
            }
            LogItem::Truncated(_) => counts.truncated = true,
            LogItem::NewerSchema(v) => counts.newer_schema = Some(v),
            LogItem::End | LogItem::Note(_) => {}
        }
    }
    records.finish()?;
    side.proposals.finish()?;
    side.events.finish()?;
    side.commands.finish()?;
    stretches.finish()?;
    let frames = crate::telemetry::export_tlog(dir, &out.join("telemetry.parquet"), key)?;
    let samples = crate::samples::export_samples(dir, &out.join("samples.parquet"), key)?;
    let legs = crate::legs::export_legs(dir, &out.join("legs.parquet"), key)?;
    let trials = trials.finish()?;
    write_runs_row(
        out,
        key,
        &header,
        &counts,
        (frames, samples, legs, trials),
        dir,
    )?;
    Ok(counts)
}

fn write_runs_row(
    out: &Path,
    key: &RunKey,
    h: &Value,
    c: &LogCounts,
    (tlog_frames, samples, legs, trials): (u64, Result<u64, String>, u64, Result<u64, String>),
    dir: &Path,
) -> anyhow::Result<()> {
    let mut w = TableWriter::create(
        &out.join("runs.parquet"),
        &cols(&[
            ("run_id", Kind::Str),
            ("vehicle", Kind::Str),
            ("date", Kind::Str),
            ("route", Kind::Str),
            ("fleet_schema", Kind::I64),
            ("log_schema", Kind::I64),
            ("started_utc", Kind::Str),
            ("git_revision", Kind::Str),
            ("command", Kind::Str),
            ("scenario", Kind::Str),
            ("policy", Kind::Str),
            ("model", Kind::Str),
            ("seed", Kind::I64),
            ("step_s", Kind::F64),
            ("planned_energy_j", Kind::F64),
            ("planned_duration_s", Kind::F64),
            ("records", Kind::I64),
            ("log_events", Kind::I64),
            ("dropped", Kind::I64),
            ("corrupted_lines", Kind::I64),
            ("truncated", Kind::Bool),
            ("tlog_frames", Kind::I64),
            ("samples", Kind::I64),
            ("samples_error", Kind::Str),
            ("legs", Kind::I64),
            ("bn_trials", Kind::I64),
            ("trials_error", Kind::Str),
            ("source", Kind::Str),
        ]),
    )?;
    let source = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    w.push(vec![
        key.run_id.as_str().into(),
        key.vehicle.as_str().into(),
        key.date.as_str().into(),
        key.route.as_str().into(),
        FLEET_SCHEMA.into(),
        c.newer_schema
            .map_or_else(|| i(&h["schema"]), |v| i64::from(v).into()),
        s(&h["started_utc"]),
        s(&h["git_revision"]),
        s(&h["command"]),
        s(&h["scenario"]),
        s(&h["policy"]),
        s(&h["model"]),
        i(&h["seed"]),
        f(&h["step_s"]),
        f(&h["plan"]["planned_energy_j"]),
        f(&h["plan"]["planned_duration_s"]),
        c.records.into(),
        c.log_events.into(),
        c.dropped.into(),
        c.corrupted.into(),
        c.truncated.into(),
        tlog_frames.into(),
        samples.as_ref().map_or(Cell::Null, |n| (*n).into()),
        samples.err().into(),
        legs.into(),
        trials.as_ref().map_or(Cell::Null, |n| (*n).into()),
        trials.err().into(),
        source.into(),
    ])?;
    w.finish().context("runs.parquet")?;
    Ok(())
}
