//! The log writer thread: bounded channel in, one flushed line per record out, size rotation.

use super::{Header, part_path};
use crate::record::DecisionRecord;
use serde::Serialize;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// How the writer buffers and rotates.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    /// Records (and events) the channel holds before the producer starts dropping.
    pub capacity: usize,
    /// Start a new part when the current one would grow past this many bytes (a part always
    /// holds at least its header and one line, so a single huge record is never split).
    pub rotate_bytes: u64,
    /// Test hook: the writer takes this lock before writing each line, so a test can stall it.
    #[doc(hidden)]
    pub stall: Option<Arc<Mutex<()>>>,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            capacity: 1024,
            rotate_bytes: 64 * 1024 * 1024,
            stall: None,
        }
    }
}

/// What the writer did, returned by [`DecisionLog::close`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriterStats {
    pub records: u64,
    pub events: u64,
    /// Records and events dropped because the channel was full (all reported in loss lines).
    pub dropped: u64,
    /// Parts written (1 = only `decisions.jsonl`).
    pub parts: u32,
    /// Lines that failed to reach the file (disk full, ...) and the last such error.
    pub write_errors: u64,
    pub last_error: Option<String>,
}

enum Payload {
    Record(Box<DecisionRecord>),
    Event {
        cycle: u64,
        time_s: f64,
        text: String,
    },
}

struct Msg {
    /// Drops that happened between the previous accepted message and this one: the writer puts
    /// the loss line exactly where the lost records belong.
    lost_before: u64,
    payload: Payload,
}

#[derive(Serialize)]
struct LossLine {
    kind: &'static str,
    dropped: u64,
}

#[derive(Serialize)]
struct EventLine<'a> {
    kind: &'static str,
    cycle: u64,
    time_s: f64,
    event: &'a str,
}

#[derive(Serialize)]
struct EndLine {
    kind: &'static str,
    records: u64,
    events: u64,
    dropped: u64,
}

/// Handle to a running decision log. Cheap to call from the decision loop: [`Self::record`]
/// never blocks and never touches the disk.
pub struct DecisionLog {
    tx: Option<SyncSender<Msg>>,
    pending_lost: Arc<AtomicU64>,
    dropped_total: Arc<AtomicU64>,
    handle: Option<JoinHandle<WriterStats>>,
    dir: PathBuf,
}

impl DecisionLog {
    /// Write the header of `decisions.jsonl` in `dir` now (so a bad folder fails here, not
    /// silently later) and start the writer thread.
    pub fn start(dir: &Path, header: Header, opts: WriterOptions) -> io::Result<Self> {
        let mut part = Part::open(dir, &header, 0)?;
        part.sync()?;
        let (tx, rx) = sync_channel::<Msg>(opts.capacity.max(1));
        let pending_lost = Arc::new(AtomicU64::new(0));
        let dropped_total = Arc::new(AtomicU64::new(0));
        let thread = WriterThread {
            dir: dir.to_path_buf(),
            header,
            opts,
            part,
            stats: WriterStats {
                parts: 1,
                ..Default::default()
            },
            pending_lost: pending_lost.clone(),
        };
        let handle = std::thread::Builder::new()
            .name("decision-log".into())
            .spawn(move || thread.run(rx))?;
        Ok(DecisionLog {
            tx: Some(tx),
            pending_lost,
            dropped_total,
            handle: Some(handle),
            dir: dir.to_path_buf(),
        })
    }

    /// The run folder this log writes into.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Queue one record. Returns false when it was dropped (channel full); the drop is counted
    /// and reported in the file by a loss line.
    pub fn record(&self, record: DecisionRecord) -> bool {
        self.send(Payload::Record(Box::new(record)))
    }

    /// Queue one event line (`failsafe`, `link lost`, `mode RTL`, ...) outside the records.
    pub fn event(&self, cycle: u64, time_s: f64, text: impl Into<String>) -> bool {
        self.send(Payload::Event {
            cycle,
            time_s,
            text: text.into(),
        })
    }

    /// Records and events dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped_total.load(Ordering::Relaxed)
    }

    fn send(&self, payload: Payload) -> bool {
        let Some(tx) = &self.tx else { return false };
        let lost_before = self.pending_lost.swap(0, Ordering::AcqRel);
        match tx.try_send(Msg {
            lost_before,
            payload,
        }) {
            Ok(()) => true,
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                // Give the earlier count back and add this drop: nothing is ever lost silently.
                self.pending_lost
                    .fetch_add(lost_before + 1, Ordering::AcqRel);
                self.dropped_total.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Drain the queue, write the final loss line (if any) and the end line, sync, and return
    /// what was written. Blocks until the writer thread is done: from async code call it in
    /// `tokio::task::spawn_blocking`.
    pub fn close(mut self) -> WriterStats {
        self.shutdown()
    }

    fn shutdown(&mut self) -> WriterStats {
        drop(self.tx.take());
        match self.handle.take() {
            Some(h) => h.join().unwrap_or_else(|_| WriterStats {
                last_error: Some("decision-log writer thread panicked".into()),
                ..Default::default()
            }),
            None => WriterStats::default(),
        }
    }
}

impl Drop for DecisionLog {
    fn drop(&mut self) {
        if self.handle.is_some() {
            let _ = self.shutdown();
        }
    }
}

/// One open part file.
struct Part {
    file: File,
    bytes: u64,
    lines_after_header: u64,
    index: u32,
}

impl Part {
    fn open(dir: &Path, header: &Header, index: u32) -> io::Result<Part> {
        let path = part_path(dir, index);
        let mut file = OpenOptions::new()
            .create_new(true)
            .write(true)
            .open(&path)?;
        let mut h = header.clone();
        h.part = index;
        let mut line = serde_json::to_string(&h).map_err(io::Error::other)?;
        line.push('\n');
        file.write_all(line.as_bytes())?;
        file.flush()?;
        Ok(Part {
            file,
            bytes: line.len() as u64,
            lines_after_header: 0,
            index,
        })
    }

    fn sync(&mut self) -> io::Result<()> {
        self.file.sync_data()
    }
}

struct WriterThread {
    dir: PathBuf,
    header: Header,
    opts: WriterOptions,
    part: Part,
    stats: WriterStats,
    pending_lost: Arc<AtomicU64>,
}

impl WriterThread {
    fn run(mut self, rx: Receiver<Msg>) -> WriterStats {
        while let Ok(msg) = rx.recv() {
            if msg.lost_before > 0 {
                self.write_loss(msg.lost_before);
            }
            match msg.payload {
                Payload::Record(r) => {
                    if self.write_json(&*r) {
                        self.stats.records += 1;
                    }
                }
                Payload::Event {
                    cycle,
                    time_s,
                    text,
                } => {
                    let line = EventLine {
                        kind: "event",
                        cycle,
                        time_s,
                        event: &text,
                    };
                    if self.write_json(&line) {
                        self.stats.events += 1;
                    }
                }
            }
        }
        // Channel closed: drops after the last accepted message are still owed a loss line.
        let rest = self.pending_lost.swap(0, Ordering::AcqRel);
        if rest > 0 {
            self.write_loss(rest);
        }
        let end = EndLine {
            kind: "end",
            records: self.stats.records,
            events: self.stats.events,
            dropped: self.stats.dropped,
        };
        self.write_json(&end);
        if let Err(e) = self.part.sync() {
            self.stats.last_error = Some(e.to_string());
        }
        self.stats
    }

    fn write_loss(&mut self, n: u64) {
        self.stats.dropped += n;
        self.write_json(&LossLine {
            kind: "loss",
            dropped: n,
        });
    }

    /// Serialise, rotate if needed, write the whole line in one call and flush. True on success.
    fn write_json<T: Serialize>(&mut self, value: &T) -> bool {
        let stall = self.opts.stall.clone();
        let _stalled = stall.as_ref().map(|m| m.lock());
        let mut line = match serde_json::to_string(value) {
            Ok(l) => l,
            Err(e) => return self.fail(e.to_string()),
        };
        line.push('\n');
        let n = line.len() as u64;
        if self.part.lines_after_header > 0 && self.part.bytes + n > self.opts.rotate_bytes {
            let _ = self.part.sync();
            match Part::open(&self.dir, &self.header, self.part.index + 1) {
                Ok(p) => {
                    self.part = p;
                    self.stats.parts += 1;
                }
                Err(e) => {
                    // Keep writing into the oversized part rather than losing records.
                    self.stats.last_error = Some(format!("rotation failed: {e}"));
                }
            }
        }
        match self
            .part
            .file
            .write_all(line.as_bytes())
            .and_then(|_| self.part.file.flush())
        {
            Ok(()) => {
                self.part.bytes += n;
                self.part.lines_after_header += 1;
                true
            }
            Err(e) => self.fail(e.to_string()),
        }
    }

    fn fail(&mut self, e: String) -> bool {
        self.stats.write_errors += 1;
        self.stats.last_error = Some(e);
        false
    }
}
