//! The tolerant reader: whatever is readable gets reviewed, and whatever is not is named.

use super::{Header, LOG_STEM, SCHEMA_VERSION, part_path};
use companion_core::record::DecisionRecord;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Why a log could not be read at all (partial problems are [`ReadIssue`]s instead).
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: no such file or folder")]
    NotFound { path: PathBuf },
    #[error("{path}: no decision log here (expected {LOG_STEM}.jsonl in the run folder)")]
    NoLog { path: PathBuf },
    #[error("{path}: the log is empty (no header, no records): the run wrote nothing")]
    Empty { path: PathBuf },
    #[error("{path}: {reason}")]
    NotAFile { path: PathBuf, reason: String },
}

/// How a log ended, judged from its last lines: the end line (written at close) and the loss
/// lines' reasons.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogEnd {
    /// The writer closed the log (end line present) and nothing was lost to the disk or a cap.
    Clean,
    /// No end line and no write-failure or cap loss line: the process stopped without closing
    /// its log (killed, crashed, power lost).
    Killed,
    /// A write failed (disk full, I/O error); `lost` records and events are not in the log.
    /// With `closed` false the end line could not be written either, and `lost` is a lower bound.
    WriteFailed { lost: u64, closed: bool },
    /// The log reached its size cap; `lost` records and events were counted, not written.
    Capped { lost: u64, closed: bool },
}

/// A line that could not be used, with where it is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ReadIssue {
    pub file: PathBuf,
    /// 1-based line number within `file`.
    pub line: usize,
    pub reason: String,
}

/// An event line (`{"kind":"event",...}`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LogEvent {
    pub cycle: u64,
    pub time_s: f64,
    pub event: String,
}

/// A loss line: `dropped` records/events were lost just before record index `before_record`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LossMark {
    pub before_record: usize,
    pub dropped: u64,
}

/// Everything readable in a log, plus what was not.
#[derive(Debug, Clone, Default)]
pub struct LogRead {
    /// Parts read, in order.
    pub files: Vec<PathBuf>,
    /// The first part's header, if it had one.
    pub header: Option<Header>,
    pub records: Vec<DecisionRecord>,
    pub events: Vec<LogEvent>,
    pub losses: Vec<LossMark>,
    /// Lines skipped because they are not valid JSON or not a record.
    pub corrupted: Vec<ReadIssue>,
    /// The last line was cut off (a killed process): reviewed up to the line before it.
    pub truncated: Option<ReadIssue>,
    /// Set when the header's schema is newer than [`SCHEMA_VERSION`].
    pub newer_schema: Option<u32>,
    /// The writer's end line was found: the run closed its log normally.
    pub ended_cleanly: bool,
    /// Human-readable remarks for the report (newer schema, missing header, unknown kinds).
    pub notes: Vec<String>,
    /// Lost because the writer fell behind (loss lines with reason `queue_full`, or none).
    pub lost_queue_full: u64,
    /// Lost to failed writes (loss lines with reason `write_failed`).
    pub lost_write_failed: u64,
    /// Not written because the log reached its size cap (reason `cap`).
    pub lost_capped: u64,
    /// Not written because the record was over the line-size limit (reason `too_large`).
    pub lost_too_large: u64,
    /// Frames of the run's `flight.tlog` not written because it reached its cap (reason
    /// `tlog_cap`): not records, so neither in `losses` nor in `dropped()`.
    pub tlog_capped: u64,
}

impl LogRead {
    /// Total records and events reported lost by loss lines, whatever the reason.
    pub fn dropped(&self) -> u64 {
        self.losses.iter().map(|l| l.dropped).sum()
    }

    /// How the log ended: a full disk or a cap is told from a killed process by the loss
    /// lines the writer leaves (docs/decision-log.md, "How a log ends").
    pub fn end(&self) -> LogEnd {
        let closed = self.ended_cleanly;
        if self.lost_write_failed > 0 {
            LogEnd::WriteFailed {
                lost: self.lost_write_failed,
                closed,
            }
        } else if self.lost_capped > 0 {
            LogEnd::Capped {
                lost: self.lost_capped,
                closed,
            }
        } else if closed {
            LogEnd::Clean
        } else {
            LogEnd::Killed
        }
    }
}

/// Read a run folder or one `.jsonl` file. Rotated parts (`decisions.1.jsonl`, ...) are read in
/// order after `decisions.jsonl`.
pub fn read_log(path: &Path) -> Result<LogRead, ReadError> {
    let files = log_files(path)?;
    let mut out = LogRead {
        files: files.clone(),
        ..Default::default()
    };
    let mut total_bytes = 0usize;
    for (i, file) in files.iter().enumerate() {
        let bytes = std::fs::read(file).map_err(|source| ReadError::Io {
            path: file.clone(),
            source,
        })?;
        total_bytes += bytes.iter().filter(|b| !b.is_ascii_whitespace()).count();
        read_part(&mut out, file, &bytes, i == 0, i + 1 == files.len());
    }
    if total_bytes == 0 {
        return Err(ReadError::Empty {
            path: path.to_path_buf(),
        });
    }
    if let Some(v) = out.newer_schema {
        out.notes.insert(
            0,
            format!(
                "this log has schema {v}, newer than this companion reads ({SCHEMA_VERSION}): \
                 fields it does not know are ignored; upgrade companion for a full review"
            ),
        );
    }
    Ok(out)
}

/// The log parts of a run folder or `.jsonl` file, in order (regular files only).
pub(crate) fn log_files(path: &Path) -> Result<Vec<PathBuf>, ReadError> {
    if !path.exists() {
        return Err(ReadError::NotFound {
            path: path.to_path_buf(),
        });
    }
    let not_a_file = |p: &Path, reason: String| ReadError::NotAFile {
        path: p.to_path_buf(),
        reason,
    };
    if path.is_dir() {
        let first = part_path(path, 0);
        if first.exists() {
            crate::params::regular_file(&first).map_err(|r| not_a_file(&first, r))?;
        }
        if !first.exists() {
            return Err(ReadError::NoLog {
                path: path.to_path_buf(),
            });
        }
        return Ok(parts_from(path, &first, LOG_STEM));
    }
    // Reading a FIFO or a device would block or never end.
    crate::params::regular_file(path).map_err(|r| not_a_file(path, r))?;
    // A file: if it is part 0 of a rotation set (`stem.jsonl`), its parts follow it.
    let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if let Some(stem) = name.strip_suffix(".jsonl")
        && !stem.contains('.')
    {
        let dir = path.parent().unwrap_or(Path::new("."));
        return Ok(parts_from(dir, path, stem));
    }
    Ok(vec![path.to_path_buf()])
}

/// `first`, then `stem.1.jsonl`, `stem.2.jsonl`, ... while they exist.
fn parts_from(dir: &Path, first: &Path, stem: &str) -> Vec<PathBuf> {
    let mut files = vec![first.to_path_buf()];
    for k in 1.. {
        let p = dir.join(format!("{stem}.{k}.jsonl"));
        if !p.is_file() {
            break;
        }
        files.push(p);
    }
    files
}

fn read_part(out: &mut LogRead, file: &Path, bytes: &[u8], first_part: bool, last_part: bool) {
    let ends_with_newline = bytes.last() == Some(&b'\n');
    let lines: Vec<&[u8]> = bytes.split(|b| *b == b'\n').collect();
    // split yields a trailing empty slice after a final '\n'.
    let n = if ends_with_newline {
        lines.len() - 1
    } else {
        lines.len()
    };
    let mut saw_header = false;
    // The schema of this part's lines, from its header (schema 1: sentences, migrated).
    let mut schema = None;
    for (idx, raw) in lines.iter().take(n).enumerate() {
        let lineno = idx + 1;
        let is_last = idx + 1 == n;
        let issue = |reason: String| ReadIssue {
            file: file.to_path_buf(),
            line: lineno,
            reason,
        };
        if raw.iter().all(|b| b.is_ascii_whitespace()) {
            continue;
        }
        let parsed = std::str::from_utf8(raw)
            .map_err(|e| format!("not UTF-8: {e}"))
            .and_then(|s| {
                serde_json::from_str::<serde_json::Value>(s).map_err(|e| format!("not JSON: {e}"))
            });
        let mut value = match parsed {
            Ok(v) => v,
            Err(reason) => {
                if is_last && !ends_with_newline && last_part {
                    out.truncated = Some(issue(format!(
                        "last line cut off ({} bytes, no newline): the process was killed \
                         while writing it",
                        raw.len()
                    )));
                } else {
                    out.corrupted.push(issue(reason));
                }
                continue;
            }
        };
        let kind = value
            .get("kind")
            .and_then(|k| k.as_str())
            .map(str::to_string);
        match kind.as_deref() {
            Some("header") => {
                saw_header = true;
                let v = value.get("schema").and_then(|s| s.as_u64()).unwrap_or(0) as u32;
                if v > SCHEMA_VERSION {
                    out.newer_schema = Some(out.newer_schema.unwrap_or(0).max(v));
                }
                schema = Some(v);
                if first_part && out.header.is_none() {
                    match serde_json::from_value::<Header>(value) {
                        Ok(h) => out.header = Some(h),
                        Err(e) => out.corrupted.push(issue(format!("unreadable header: {e}"))),
                    }
                }
            }
            Some("loss") => {
                let dropped = value.get("dropped").and_then(|d| d.as_u64()).unwrap_or(0);
                if value.get("reason").and_then(|r| r.as_str()) == Some("tlog_cap") {
                    out.tlog_capped += dropped;
                    continue;
                }
                // Loss lines from before reasons were written are all queue drops.
                match value.get("reason").and_then(|r| r.as_str()) {
                    Some("write_failed") => out.lost_write_failed += dropped,
                    Some("cap") => out.lost_capped += dropped,
                    Some("too_large") => out.lost_too_large += dropped,
                    _ => out.lost_queue_full += dropped,
                }
                out.losses.push(LossMark {
                    before_record: out.records.len(),
                    dropped,
                });
            }
            Some("event") => match serde_json::from_value::<LogEvent>(value) {
                Ok(e) => out.events.push(e),
                Err(e) => out.corrupted.push(issue(format!("unreadable event: {e}"))),
            },
            Some("end") => out.ended_cleanly = true,
            None | Some("record") => match {
                if super::migration::needs_migration(schema) {
                    super::migration::record_v1(&mut value);
                }
                serde_json::from_value::<DecisionRecord>(value)
            } {
                Ok(r) => out.records.push(r),
                Err(e) => out
                    .corrupted
                    .push(issue(format!("not a decision record: {e}"))),
            },
            Some(other) => out.notes.push(format!(
                "{}:{lineno}: line of unknown kind {other:?} skipped",
                file.display()
            )),
        }
    }
    if !saw_header && n > 0 {
        out.notes.push(format!(
            "{}: no header line; schema {SCHEMA_VERSION} assumed",
            file.display()
        ));
    }
}
