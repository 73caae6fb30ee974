//! The same tolerant reading as [`read_log`](super::read_log), one line at a time: what the
//! reader holds is one line and the caller's state, whatever the log's size. `review` and
//! `export` read through this.

use super::reader::{LogEvent, ReadError, ReadIssue, log_files};
use super::{Header, SCHEMA_VERSION};
use companion_core::record::DecisionRecord;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// A line longer than this is skipped as corrupted instead of being held whole.
pub const MAX_LINE_BYTES: usize = 64 * 1024 * 1024;

/// One thing read from a log, in file order.
#[derive(Debug)]
pub enum LogItem {
    /// The first part's header.
    Header(Box<Header>),
    /// A decision record and the raw `proposals[].inputs` of each proposal (the probabilities
    /// it read, when the writer recorded them; `None` per proposal otherwise).
    Record(Box<DecisionRecord>, Vec<Option<serde_json::Value>>),
    Event(LogEvent),
    /// `dropped` records/events lost just before the next record, and why.
    Loss(u64, LossReason),
    /// The writer's end line.
    End,
    Corrupted(ReadIssue),
    /// The last line of the last part was cut off.
    Truncated(ReadIssue),
    /// A remark for the report (unknown kind, no header).
    Note(String),
    /// A header of a schema newer than this build reads.
    NewerSchema(u32),
}

/// Why a loss line's records are missing (its `reason`, as the writer wrote it).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum LossReason {
    /// The writer thread fell behind (also loss lines written before reasons were).
    #[default]
    QueueFull,
    /// A write failed: disk full or an I/O error.
    WriteFailed,
    /// The log reached its size cap.
    Cap,
    /// One record was over the line-size limit.
    TooLarge,
    /// Frames of the run's `flight.tlog` past its cap (not records).
    TlogCap,
}

impl LossReason {
    fn from_line(reason: Option<&str>) -> Self {
        match reason {
            Some("write_failed") => Self::WriteFailed,
            Some("cap") => Self::Cap,
            Some("too_large") => Self::TooLarge,
            Some("tlog_cap") => Self::TlogCap,
            _ => Self::QueueFull,
        }
    }

    /// Why, in a few words, for the report.
    pub fn text(self) -> &'static str {
        match self {
            Self::QueueFull => "log writer behind",
            Self::WriteFailed => "write failed: disk full or I/O error",
            Self::Cap => "log size cap reached",
            Self::TooLarge => "record over the line-size limit",
            Self::TlogCap => "flight.tlog size cap reached: telemetry frames not written",
        }
    }
}

/// Iterator over a run folder's or a log file's items; see [`stream_log`].
pub struct LogStream {
    files: Vec<PathBuf>,
    next_file: usize,
    cur: Option<Part>,
    nonblank_bytes: u64,
    path: PathBuf,
    done: bool,
    queued: Option<LogItem>,
}

struct Part {
    file: PathBuf,
    reader: BufReader<File>,
    line: usize,
    first: bool,
    last: bool,
    saw_header: bool,
    lines_read: usize,
    /// The schema of this part's lines, from its header (schema 1: sentences, migrated).
    schema: Option<u32>,
}

/// Open a run folder or `.jsonl` file for streaming. The parts are listed as `read_log` lists
/// them; an empty log yields `Err(ReadError::Empty)` as its last item.
pub fn stream_log(path: &Path) -> Result<LogStream, ReadError> {
    let files = log_files(path)?;
    // Opening a FIFO would wait for a writer forever: regular files only.
    for f in &files {
        let meta = std::fs::metadata(f).map_err(|source| ReadError::Io {
            path: f.clone(),
            source,
        })?;
        if !meta.is_file() {
            return Err(ReadError::Io {
                path: f.clone(),
                source: std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    "not a regular file (a FIFO, device or socket): a decision log is a file",
                ),
            });
        }
    }
    Ok(LogStream {
        files,
        next_file: 0,
        cur: None,
        nonblank_bytes: 0,
        path: path.to_path_buf(),
        done: false,
        queued: None,
    })
}

impl LogStream {
    /// The parts this stream reads, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

/// Read one line (without its `\n`) into `buf`, holding at most [`MAX_LINE_BYTES`]. Returns
/// (bytes consumed, ended with newline, too long).
fn read_line_bounded(
    r: &mut impl BufRead,
    buf: &mut Vec<u8>,
) -> std::io::Result<(usize, bool, bool)> {
    buf.clear();
    let mut consumed = 0usize;
    let mut too_long = false;
    loop {
        let avail = r.fill_buf()?;
        if avail.is_empty() {
            return Ok((consumed, false, too_long));
        }
        let (take, found) = match avail.iter().position(|b| *b == b'\n') {
            Some(i) => (i + 1, true),
            None => (avail.len(), false),
        };
        let body = if found {
            &avail[..take - 1]
        } else {
            &avail[..take]
        };
        if buf.len() + body.len() > MAX_LINE_BYTES {
            too_long = true;
            buf.clear();
        } else if !too_long {
            buf.extend_from_slice(body);
        }
        consumed += take;
        r.consume(take);
        if found {
            return Ok((consumed, true, too_long));
        }
    }
}

impl LogStream {
    /// Opens the next part file as the current one; `Err(what next returns)` when there is none
    /// left (the end, or an empty log) or it cannot be opened.
    #[allow(clippy::type_complexity)]
    fn open_next_part(&mut self) -> Result<(), Option<Result<LogItem, ReadError>>> {
        if self.next_file == self.files.len() {
            self.done = true;
            if self.nonblank_bytes == 0 {
                return Err(Some(Err(ReadError::Empty {
                    path: self.path.clone(),
                })));
            }
            return Err(None);
        }
        let i = self.next_file;
        self.next_file += 1;
        let file = self.files[i].clone();
        match File::open(&file) {
            Ok(f) => {
                self.cur = Some(Part {
                    reader: BufReader::with_capacity(256 * 1024, f),
                    file,
                    line: 0,
                    first: i == 0,
                    last: i + 1 == self.files.len(),
                    saw_header: false,
                    lines_read: 0,
                    schema: None,
                })
            }
            Err(source) => {
                self.done = true;
                return Err(Some(Err(ReadError::Io { path: file, source })));
            }
        }
        Ok(())
    }
}

/// A decision record line, its proposals' `inputs` taken out (kept as read, in order); a
/// schema-1 line (`schema`, from its part's header) is migrated first.
fn record_item(
    mut value: serde_json::Value,
    schema: Option<u32>,
    issue: impl Fn(String) -> ReadIssue,
) -> LogItem {
    if super::migration::needs_migration(schema) {
        super::migration::record_v1(&mut value);
    }
    let inputs: Vec<Option<serde_json::Value>> = value
        .get_mut("proposals")
        .and_then(|p| p.as_array_mut())
        .map(|ps| {
            ps.iter_mut()
                .map(|p| p.as_object_mut().and_then(|o| o.remove("inputs")))
                .collect()
        })
        .unwrap_or_default();
    match serde_json::from_value::<DecisionRecord>(value) {
        Ok(r) => LogItem::Record(Box::new(r), inputs),
        Err(e) => LogItem::Corrupted(issue(format!("not a decision record: {e}"))),
    }
}

impl Iterator for LogStream {
    type Item = Result<LogItem, ReadError>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(q) = self.queued.take() {
            return Some(Ok(q));
        }
        let mut buf = Vec::new();
        loop {
            if self.done {
                return None;
            }
            if self.cur.is_none()
                && let Err(end) = self.open_next_part()
            {
                return end;
            }
            let part = self.cur.as_mut().expect("opened above");
            let (n, newline, too_long) = match read_line_bounded(&mut part.reader, &mut buf) {
                Ok(x) => x,
                Err(source) => {
                    self.done = true;
                    return Some(Err(ReadError::Io {
                        path: part.file.clone(),
                        source,
                    }));
                }
            };
            if n == 0 {
                let p = self.cur.take().expect("current part");
                if !p.saw_header && p.lines_read > 0 {
                    return Some(Ok(LogItem::Note(format!(
                        "{}: no header line; schema {SCHEMA_VERSION} assumed",
                        p.file.display()
                    ))));
                }
                continue;
            }
            part.line += 1;
            part.lines_read += 1;
            let lineno = part.line;
            let issue = |reason: String| ReadIssue {
                file: part.file.clone(),
                line: lineno,
                reason,
            };
            if too_long {
                self.nonblank_bytes += 1;
                return Some(Ok(LogItem::Corrupted(issue(format!(
                    "line longer than {MAX_LINE_BYTES} bytes: skipped unread"
                )))));
            }
            let nonblank = buf.iter().filter(|b| !b.is_ascii_whitespace()).count();
            if nonblank == 0 {
                continue;
            }
            self.nonblank_bytes += nonblank as u64;
            let parsed = std::str::from_utf8(&buf)
                .map_err(|e| format!("not UTF-8: {e}"))
                .and_then(|s| {
                    serde_json::from_str::<serde_json::Value>(s)
                        .map_err(|e| format!("not JSON: {e}"))
                });
            let value = match parsed {
                Ok(v) => v,
                Err(reason) => {
                    // Cut off: the very last line of the last part, without its newline.
                    let at_end = !newline && part.last;
                    return Some(Ok(if at_end {
                        LogItem::Truncated(issue(format!(
                            "last line cut off ({} bytes, no newline): the process was killed \
                             while writing it",
                            buf.len()
                        )))
                    } else {
                        LogItem::Corrupted(issue(reason))
                    }));
                }
            };
            let kind = value
                .get("kind")
                .and_then(|k| k.as_str())
                .map(str::to_string);
            let item = match kind.as_deref() {
                Some("header") => {
                    part.saw_header = true;
                    let schema = value.get("schema").and_then(|s| s.as_u64()).unwrap_or(0);
                    let schema = u32::try_from(schema).unwrap_or(u32::MAX);
                    part.schema = Some(schema);
                    if schema > SCHEMA_VERSION {
                        if !part.first {
                            return Some(Ok(LogItem::NewerSchema(schema)));
                        }
                        self.queued = Some(LogItem::NewerSchema(schema));
                    }
                    if !part.first {
                        continue;
                    }
                    match serde_json::from_value::<Header>(value) {
                        Ok(h) => LogItem::Header(Box::new(h)),
                        Err(e) => LogItem::Corrupted(issue(format!("unreadable header: {e}"))),
                    }
                }
                Some("loss") => LogItem::Loss(
                    value.get("dropped").and_then(|d| d.as_u64()).unwrap_or(0),
                    LossReason::from_line(value.get("reason").and_then(|r| r.as_str())),
                ),
                Some("event") => match serde_json::from_value::<LogEvent>(value) {
                    Ok(e) => LogItem::Event(e),
                    Err(e) => LogItem::Corrupted(issue(format!("unreadable event: {e}"))),
                },
                Some("end") => LogItem::End,
                None | Some("record") => record_item(value, part.schema, issue),
                Some(other) => LogItem::Note(format!(
                    "{}:{lineno}: line of unknown kind {other:?} skipped",
                    part.file.display()
                )),
            };
            return Some(Ok(item));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decision_log::read_log;

    /// Streaming and `read_log` agree on records, events, losses, corruption and truncation.
    #[test]
    fn stream_reads_what_read_log_reads() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.jsonl");
        let mut text = String::from("{\"kind\":\"header\",\"schema\":1,\"command\":\"c\"}\n");
        for i in 0..5 {
            text.push_str(&format!(
                "{{\"cycle\":{i},\"time_s\":{i},\"state\":\"s\",\"proposals\":[{{\"mdp\":\"m\",\"inputs\":{{\"P_a\":0.5}}}}]}}\n"
            ));
            if i == 2 {
                text.push_str("not json\n{\"kind\":\"loss\",\"dropped\":3}\n");
                text.push_str("{\"kind\":\"event\",\"cycle\":2,\"time_s\":2,\"event\":\"e\"}\n");
            }
        }
        text.push_str("{\"cycle\":9,\"ti");
        std::fs::write(&p, &text).unwrap();
        let whole = read_log(&p).unwrap();
        let (mut recs, mut events, mut lost, mut bad, mut cut, mut inputs) = (0, 0, 0, 0, 0, 0);
        for item in stream_log(&p).unwrap() {
            match item.unwrap() {
                LogItem::Record(_, i) => {
                    recs += 1;
                    inputs += i.iter().flatten().count();
                }
                LogItem::Event(_) => events += 1,
                LogItem::Loss(n, _) => lost += n,
                LogItem::Corrupted(_) => bad += 1,
                LogItem::Truncated(_) => cut += 1,
                _ => {}
            }
        }
        assert_eq!(recs, whole.records.len());
        assert_eq!(events, whole.events.len());
        assert_eq!(lost, whole.dropped());
        assert_eq!(bad, whole.corrupted.len());
        assert_eq!(cut, usize::from(whole.truncated.is_some()));
        assert_eq!(inputs, 5);
    }

    #[test]
    fn fifo_is_refused_without_waiting_for_a_writer() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("decisions.jsonl");
        let ok = std::process::Command::new("mkfifo").arg(&p).status();
        if !ok.is_ok_and(|s| s.success()) {
            return; // no mkfifo on this system
        }
        let err = stream_log(&p).err().expect("a FIFO is refused");
        assert!(err.to_string().contains("not a regular file"), "{err}");
        let err = stream_log(dir.path())
            .err()
            .expect("a run folder whose log is a FIFO");
        assert!(err.to_string().contains("not a regular file"), "{err}");
    }

    #[test]
    fn empty_log_is_an_error_at_the_end() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.jsonl");
        std::fs::write(&p, "\n\n").unwrap();
        let items: Vec<_> = stream_log(&p).unwrap().collect();
        assert!(matches!(items.last(), Some(Err(ReadError::Empty { .. }))));
    }

    #[test]
    fn overlong_line_is_skipped_without_holding_it() {
        let mut r = std::io::Cursor::new(vec![b'x'; MAX_LINE_BYTES + 10]);
        let mut buf = Vec::new();
        let (n, nl, too_long) = read_line_bounded(&mut r, &mut buf).unwrap();
        assert_eq!((n, nl, too_long), (MAX_LINE_BYTES + 10, false, true));
        assert!(buf.len() <= MAX_LINE_BYTES);
    }
}
