//! `companion export RUN_OR_LOG --format mcap|csv [--out FILE]`: the decision records (and, for
//! fly runs, the MAVLink telemetry of `flight.tlog`) in formats the field's viewers open.
//!
//! - MCAP (Foxglove, PlotJuggler): JSON messages with a JSON schema, one channel per record
//!   field group (`/decisions/summary`, `/decisions/observations`, `/decisions/probabilities`,
//!   `/decisions/proposals`, ...; one message per record on each) and one per MAVLink message
//!   name (`/mavlink/HEARTBEAT`, ...). Log time: the run's start (header) plus `time_s`; tlog
//!   frames keep their own receive time.
//! - CSV (PlotJuggler, spreadsheets): one row per record, nested fields flattened into dotted
//!   columns (`probabilities.P_sys`, `proposals.0.value`); lists of plain values joined by `;`.
//!
//! Both stream the log (CSV reads it twice: once for the columns, once for the rows).
//!
//! An export never destroys its inputs: `--out` may not be the log, any part of it, the run's
//! tlog or any other file of the run folder but an earlier export of the same format (compared
//! by device and inode, so symlinks and hard links are seen through); an existing `--out` must
//! be a regular file (a FIFO is never opened); the file is written beside the target under a
//! temporary name and renamed over it only when whole. Lines that cannot be read are counted and
//! named (at most [`MAX_SKIPPED_SHOWN`]); an input with no readable record is an error.

use crate::decision_log::{LogItem, ReadError, ReadIssue, log_files, read_tlog, stream_log};
use crate::output_file;
use crate::review::text::escape_controls;
use companion_core::record::DecisionRecord;
use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Columns a CSV export holds at most (a hostile log with endless names is cut here, said on
/// stderr).
pub const MAX_CSV_COLUMNS: usize = 10_000;
const MAX_DEPTH: usize = 6;
/// Skipped lines named one by one in [`ExportStats::skipped_lines`]; the rest are counted.
pub const MAX_SKIPPED_SHOWN: usize = 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    Mcap,
    Csv,
}

#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Read(#[from] ReadError),
    #[error("{path}: cannot write: {source}")]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: MCAP writer: {source}")]
    Mcap {
        path: PathBuf,
        #[source]
        source: mcap::McapError,
    },
    /// `--out` names something the export must not replace.
    #[error("--out {path}: {reason}")]
    Refused { path: PathBuf, reason: String },
    /// Nothing to export: every line that looked like a record was unreadable.
    #[error("{path}: no decision record could be read ({skipped} lines skipped): nothing exported")]
    NoRecords {
        path: PathBuf,
        skipped: usize,
        skipped_lines: Vec<ReadIssue>,
    },
}

pub use crate::decision_channels::GROUPS;
use crate::decision_channels::{self as channels, record_value};

/// `2025-06-01T12:00:00Z` -> nanoseconds since the Unix epoch (None when not in that form).
pub fn rfc3339_ns(s: &str) -> Option<u64> {
    let b = s.as_bytes();
    if b.len() < 20 || b[4] != b'-' || b[7] != b'-' || b[10] != b'T' || b[13] != b':' {
        return None;
    }
    let n = |a: usize, e: usize| s.get(a..e)?.parse::<i64>().ok();
    let (y, mo, d, h, mi, se) = (
        n(0, 4)?,
        n(5, 7)?,
        n(8, 10)?,
        n(11, 13)?,
        n(14, 16)?,
        n(17, 19)?,
    );
    // Days from civil (H. Hinnant).
    let y2 = if mo <= 2 { y - 1 } else { y };
    let era = y2.div_euclid(400);
    let yoe = y2 - era * 400;
    let mp = (mo + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    let secs = days * 86_400 + h * 3600 + mi * 60 + se;
    u64::try_from(secs).ok()?.checked_mul(1_000_000_000)
}

/// Where the export goes without `--out`: `export.mcap`/`export.csv` in a run folder, or beside
/// a log file with the format's extension.
pub fn default_out(input: &Path, format: Format) -> PathBuf {
    let ext = match format {
        Format::Mcap => "mcap",
        Format::Csv => "csv",
    };
    if input.is_dir() {
        input.join(format!("export.{ext}"))
    } else {
        input.with_extension(ext)
    }
}

/// Counts of what an export wrote.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct ExportStats {
    pub records: usize,
    /// MCAP channel topic -> messages written.
    pub messages: BTreeMap<String, usize>,
    pub columns: usize,
    pub columns_dropped: usize,
    pub tlog_frames: usize,
    /// Lines of the log that could not be read (not JSON, not a record, cut off).
    pub skipped: usize,
    /// The first [`MAX_SKIPPED_SHOWN`] of them, with file, line and reason.
    pub skipped_lines: Vec<ReadIssue>,
}

impl ExportStats {
    fn skip(&mut self, issue: ReadIssue) {
        self.skipped += 1;
        if self.skipped_lines.len() < MAX_SKIPPED_SHOWN {
            self.skipped_lines.push(issue);
        }
    }
}

/// The run folder of a run folder or log file (a log file's own folder).
fn run_dir_of(input: &Path) -> PathBuf {
    if input.is_dir() {
        input.to_path_buf()
    } else {
        match input.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }
}

fn tlog_of(input: &Path) -> PathBuf {
    if input.is_dir() {
        input.join("flight.tlog")
    } else {
        input.with_file_name("flight.tlog")
    }
}

/// Refuse an `--out` that is an input or any other file of the run (but an earlier export of
/// this format), or that exists and is not a regular file. Only metadata is read: nothing at
/// `out` is opened.
pub fn check_out(input: &Path, out: &Path, format: Format) -> Result<(), ExportError> {
    let refuse = |reason: String| ExportError::Refused {
        path: out.to_path_buf(),
        reason,
    };
    let mut inputs = log_files(input).unwrap_or_default();
    inputs.push(tlog_of(input));
    let Some(out_meta) =
        output_file::check(out, &inputs, "export").map_err(|e| refuse(e.reason))?
    else {
        return Ok(());
    };
    let ext = match format {
        Format::Mcap => "mcap",
        Format::Csv => "csv",
    };
    let run_dir = run_dir_of(input);
    if let Ok(entries) = std::fs::read_dir(&run_dir) {
        for e in entries.flatten() {
            let p = e.path();
            if output_file::same_file(out, &out_meta, &p) && p.extension().is_none_or(|x| x != ext)
            {
                return Err(refuse(format!(
                    "is {}, a file of the run folder: an export may only replace an earlier \
                     .{ext} export there",
                    escape_controls(&p.display().to_string(), false)
                )));
            }
        }
    }
    Ok(())
}

fn no_records(input: &Path, stats: ExportStats) -> ExportError {
    ExportError::NoRecords {
        path: input.to_path_buf(),
        skipped: stats.skipped,
        skipped_lines: stats.skipped_lines,
    }
}

/// The `companion export` command.
pub fn run(
    input: &Path,
    format: Format,
    out: Option<&Path>,
) -> Result<(PathBuf, ExportStats), ExportError> {
    let path = out
        .map(Path::to_path_buf)
        .unwrap_or_else(|| default_out(input, format));
    let stats = match format {
        Format::Mcap => export_mcap(input, &path)?,
        Format::Csv => export_csv(input, &path)?,
    };
    Ok((path, stats))
}

/// `companion export` as the CLI runs it: the summary on stdout, skipped lines and left-out
/// columns on stderr, every path escaped for the terminal.
pub fn run_cli(input: &Path, format: Format, out: Option<&Path>) -> anyhow::Result<()> {
    let shown = |p: &Path| escape_controls(&p.display().to_string(), false);
    let say_skipped = |skipped: usize, lines: &[ReadIssue]| {
        for i in lines {
            eprintln!(
                "skipped {}:{}: {}",
                shown(&i.file),
                i.line,
                escape_controls(&i.reason, false)
            );
        }
        if skipped > lines.len() {
            eprintln!("skipped {} more lines", skipped - lines.len());
        }
    };
    let (path, stats) = match run(input, format, out) {
        Ok(x) => x,
        Err(e) => {
            if let ExportError::NoRecords {
                skipped,
                skipped_lines,
                ..
            } = &e
            {
                say_skipped(*skipped, skipped_lines);
            }
            anyhow::bail!("export: {}", escape_controls(&e.to_string(), false));
        }
    };
    say_skipped(stats.skipped, &stats.skipped_lines);
    if stats.columns_dropped > 0 {
        eprintln!(
            "warning: {} columns beyond the first {MAX_CSV_COLUMNS} left out",
            stats.columns_dropped,
        );
    }
    let skipped = if stats.skipped > 0 {
        format!(", {} unreadable lines skipped", stats.skipped)
    } else {
        String::new()
    };
    println!(
        "export: {} ({} records, {} telemetry messages{skipped})",
        shown(&path),
        stats.records,
        stats.tlog_frames
    );
    Ok(())
}

/// The proposals' `inputs` as the log holds them (the reader takes them out of the record), so
/// the file's messages are the record's, as the live view's are.
fn restore_inputs(v: &mut serde_json::Value, inputs: Vec<Option<serde_json::Value>>) {
    let Some(ps) = v.get_mut("proposals").and_then(|p| p.as_array_mut()) else {
        return;
    };
    for (p, i) in ps.iter_mut().zip(inputs) {
        if let (Some(o), Some(i)) = (p.as_object_mut(), i) {
            o.insert("inputs".into(), i);
        }
    }
}

pub fn export_mcap(input: &Path, path: &Path) -> Result<ExportStats, ExportError> {
    let werr = |source| ExportError::Write {
        path: path.to_path_buf(),
        source,
    };
    let merr = |source| ExportError::Mcap {
        path: path.to_path_buf(),
        source,
    };
    check_out(input, path, Format::Mcap)?;
    let items = stream_log(input)?;
    let tmp = output_file::temp_beside(path).map_err(werr)?;
    let file = tmp.reopen().map_err(werr)?;
    let mut w = mcap::Writer::new(BufWriter::new(file)).map_err(merr)?;
    let mut stats = ExportStats::default();
    let mut channels: BTreeMap<String, u16> = BTreeMap::new();
    let no_meta = BTreeMap::new();
    let mut start_ns = 0u64;
    let mut seq = 0u32;
    for item in items {
        match item? {
            LogItem::Header(h) => start_ns = rfc3339_ns(&h.started_utc).unwrap_or(0),
            LogItem::Corrupted(i) | LogItem::Truncated(i) => stats.skip(i),
            LogItem::Record(r, inputs) => {
                stats.records += 1;
                let mut v = record_value(&r);
                restore_inputs(&mut v, inputs);
                let t = channels::log_time_ns(start_ns, &r);
                for g in GROUPS {
                    let topic = channels::topic(g);
                    let id = match channels.get(&topic) {
                        Some(id) => *id,
                        None => {
                            let schema = w
                                .add_schema(
                                    &channels::schema_name(g),
                                    channels::SCHEMA_ENCODING,
                                    channels::schema(g).as_bytes(),
                                )
                                .map_err(merr)?;
                            let id = w
                                .add_channel(schema, &topic, channels::MESSAGE_ENCODING, &no_meta)
                                .map_err(merr)?;
                            channels.insert(topic.clone(), id);
                            id
                        }
                    };
                    let data = serde_json::to_vec(&channels::message(&v, g)).unwrap_or_default();
                    seq = seq.wrapping_add(1);
                    w.write_to_known_channel(
                        &mcap::records::MessageHeader {
                            channel_id: id,
                            sequence: seq,
                            log_time: t,
                            publish_time: t,
                        },
                        &data,
                    )
                    .map_err(merr)?;
                    *stats.messages.entry(topic).or_default() += 1;
                }
            }
            _ => {}
        }
    }
    if stats.records == 0 {
        return Err(no_records(input, stats));
    }
    // Telemetry from the run folder's tlog, when there is one.
    let tlog = tlog_of(input);
    if tlog.is_file()
        && let Ok((frames, _)) = read_tlog(&tlog)
    {
        let mut ingest = companion_link::ingest::Ingest::new(None);
        for f in frames {
            let t = f.t_us.saturating_mul(1000);
            let mut msgs = Vec::new();
            ingest.push_each(&f.frame, |fr| {
                let name = mavlink::Message::message_name(fr.msg).to_string();
                let mut v = serde_json::to_value(fr.msg).unwrap_or(serde_json::Value::Null);
                if let Some(o) = v.as_object_mut() {
                    o.insert("sysid".into(), fr.header.system_id.into());
                    o.insert("compid".into(), fr.header.component_id.into());
                }
                msgs.push((name, v));
            });
            for (name, v) in msgs {
                stats.tlog_frames += 1;
                let topic = format!("/mavlink/{name}");
                let id = match channels.get(&topic) {
                    Some(id) => *id,
                    None => {
                        let schema = serde_json::json!({"title": format!("mavlink.{name}"), "type": "object", "additionalProperties": true}).to_string();
                        let sid = w
                            .add_schema(&format!("mavlink.{name}"), "jsonschema", schema.as_bytes())
                            .map_err(merr)?;
                        let id = w.add_channel(sid, &topic, "json", &no_meta).map_err(merr)?;
                        channels.insert(topic.clone(), id);
                        id
                    }
                };
                seq = seq.wrapping_add(1);
                let data = serde_json::to_vec(&v).unwrap_or_default();
                w.write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: id,
                        sequence: seq,
                        log_time: t,
                        publish_time: t,
                    },
                    &data,
                )
                .map_err(merr)?;
                *stats.messages.entry(topic).or_default() += 1;
            }
        }
    }
    w.finish().map_err(merr)?;
    drop(w);
    output_file::persist(tmp, path, 0o644).map_err(werr)?;
    Ok(stats)
}

/// Flatten a JSON value into dotted columns.
fn flatten(prefix: &str, v: &serde_json::Value, depth: usize, out: &mut Vec<(String, String)>) {
    use serde_json::Value as V;
    let key = |k: &str| {
        if prefix.is_empty() {
            k.to_string()
        } else {
            format!("{prefix}.{k}")
        }
    };
    match v {
        V::Object(m) if depth < MAX_DEPTH => {
            for (k, x) in m {
                flatten(&key(k), x, depth + 1, out);
            }
        }
        V::Array(a) if depth < MAX_DEPTH && a.iter().any(|x| x.is_object() || x.is_array()) => {
            for (i, x) in a.iter().enumerate() {
                flatten(&key(&i.to_string()), x, depth + 1, out);
            }
        }
        V::Array(a) => {
            let parts: Vec<String> = a.iter().map(scalar).collect();
            out.push((prefix.to_string(), parts.join(";")));
        }
        other => out.push((prefix.to_string(), scalar(other))),
    }
}

fn scalar(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Null => String::new(),
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// One CSV field: quoted when needed; text that a spreadsheet would run as a formula gets a
/// leading `'` (numbers are left alone).
pub fn csv_field(s: &str) -> String {
    // TAB and CR too: spreadsheets strip them and read what follows as a formula (OWASP CSV
    // injection).
    let formula = matches!(s.chars().next(), Some('=' | '+' | '-' | '@' | '\t' | '\r'))
        && s.parse::<f64>().is_err();
    let s = if formula {
        format!("'{s}")
    } else {
        s.to_string()
    };
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s
    }
}

fn record_columns(r: &DecisionRecord) -> Vec<(String, String)> {
    let mut cols = Vec::new();
    flatten("", &record_value(r), 0, &mut cols);
    cols
}

pub fn export_csv(input: &Path, path: &Path) -> Result<ExportStats, ExportError> {
    let werr = |source| ExportError::Write {
        path: path.to_path_buf(),
        source,
    };
    check_out(input, path, Format::Csv)?;
    let mut stats = ExportStats::default();
    // Pass 1: the columns, in first-seen order with cycle and time_s first.
    let mut order: Vec<String> = vec!["cycle".into(), "time_s".into()];
    let mut seen: BTreeSet<String> = order.iter().cloned().collect();
    let mut readable = 0usize;
    for item in stream_log(input)? {
        let r = match item? {
            LogItem::Record(r, _) => r,
            LogItem::Corrupted(i) | LogItem::Truncated(i) => {
                stats.skip(i);
                continue;
            }
            _ => continue,
        };
        readable += 1;
        for (k, _) in record_columns(&r) {
            if !seen.contains(&k) {
                if order.len() < MAX_CSV_COLUMNS {
                    seen.insert(k.clone());
                    order.push(k);
                } else {
                    stats.columns_dropped += 1;
                }
            }
        }
    }
    if readable == 0 {
        return Err(no_records(input, stats));
    }
    let index: BTreeMap<&str, usize> = order
        .iter()
        .enumerate()
        .map(|(i, k)| (k.as_str(), i))
        .collect();
    let tmp = output_file::temp_beside(path).map_err(werr)?;
    let mut w = BufWriter::new(tmp.reopen().map_err(werr)?);
    let head: Vec<String> = order.iter().map(|c| csv_field(c)).collect();
    writeln!(w, "{}", head.join(",")).map_err(werr)?;
    // Pass 2: the rows.
    let mut row = vec![String::new(); order.len()];
    for item in stream_log(input)? {
        if let LogItem::Record(r, _) = item? {
            row.iter_mut().for_each(String::clear);
            for (k, v) in record_columns(&r) {
                if let Some(i) = index.get(k.as_str()) {
                    row[*i] = csv_field(&v);
                }
            }
            writeln!(w, "{}", row.join(",")).map_err(werr)?;
            stats.records += 1;
        }
    }
    w.flush().map_err(werr)?;
    drop(w);
    output_file::persist(tmp, path, 0o644).map_err(werr)?;
    stats.columns = order.len();
    Ok(stats)
}
