//! The log writer thread: bounded channel in, one flushed line per record out, size rotation.

use super::{Header, part_path};
use companion_core::record::DecisionRecord;
use serde::Serialize;
use std::fs::{File, OpenOptions};
use std::io::{self, Seek, SeekFrom, Write};
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
    /// Most bytes the run's log may take, all parts together. Past it records and events are
    /// counted, not written, and a loss line with reason `cap` says so. Default
    /// [`DEFAULT_MAX_BYTES`], or `$COMPANION_LOG_MAX_BYTES`.
    pub max_bytes: u64,
    /// Longest line a record or event may take; a longer one is counted, not written (loss
    /// reason `too_large`).
    pub max_line_bytes: u64,
    /// Test hook: the writer takes this lock before writing each line, so a test can stall it.
    #[doc(hidden)]
    pub stall: Option<Arc<Mutex<()>>>,
    /// Test hook: a simulated filesystem of this many bytes under the log parts and the reserve
    /// (writes past it fail as on a full disk, after writing what fits).
    #[doc(hidden)]
    pub disk_bytes: Option<u64>,
}

/// Default cap on one run's decision log (all parts): 1 GiB.
pub const DEFAULT_MAX_BYTES: u64 = 1 << 30;
/// Default longest record line: 1 MiB (a normal record is a few KiB).
pub const DEFAULT_MAX_LINE_BYTES: u64 = 1 << 20;
/// Bytes kept free in the run folder (`.log-reserve`) and given back when a write fails, so the
/// loss and end lines can still be written on a full disk.
pub const RESERVE_BYTES: u64 = 16 * 1024;
/// The reserve file's name in the run folder (removed at close).
pub const RESERVE_FILE: &str = ".log-reserve";

impl Default for WriterOptions {
    /// The defaults, whatever the environment ([`WriterOptions::from_env`] reads it).
    fn default() -> Self {
        WriterOptions {
            capacity: 1024,
            rotate_bytes: 64 * 1024 * 1024,
            max_bytes: DEFAULT_MAX_BYTES,
            max_line_bytes: DEFAULT_MAX_LINE_BYTES,
            stall: None,
            disk_bytes: None,
        }
    }
}

/// `COMPANION_LOG_MAX_BYTES` is set to something that is not a number of bytes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "COMPANION_LOG_MAX_BYTES={value:?} is not a size: expected a whole number of bytes of at \
     least 1, digits only (e.g. 1073741824 for 1 GiB; no unit, sign or separator)"
)]
pub struct LogCapError {
    /// The value as set (shown with Rust escapes, so a control character is seen, not sent).
    pub value: String,
}

/// The cap `COMPANION_LOG_MAX_BYTES` sets: `None` when unset; an error naming the value when it
/// is set to anything but digits (surrounding spaces allowed) giving at least 1 byte. `abc`,
/// `100KB`, `-5`, `1e9`, `0` and an empty value are errors, never a silent default.
pub fn max_bytes_from_env() -> Result<Option<u64>, LogCapError> {
    match std::env::var_os("COMPANION_LOG_MAX_BYTES") {
        None => Ok(None),
        Some(v) => parse_max_bytes(&v.to_string_lossy()).map(Some),
    }
}

/// See [`max_bytes_from_env`].
pub fn parse_max_bytes(value: &str) -> Result<u64, LogCapError> {
    let t = value.trim();
    let err = || LogCapError {
        value: value.to_string(),
    };
    if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
        return Err(err());
    }
    match t.parse::<u64>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(err()),
    }
}

impl WriterOptions {
    /// The defaults with the cap from `COMPANION_LOG_MAX_BYTES` when set (what `fly` and
    /// `simulate` start with); an unparsable value is an error, not 1 GiB.
    pub fn from_env() -> Result<Self, LogCapError> {
        let mut o = WriterOptions::default();
        if let Some(b) = max_bytes_from_env()? {
            o.max_bytes = b;
        }
        Ok(o)
    }
}

/// What the writer did, returned by [`DecisionLog::close`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct WriterStats {
    pub records: u64,
    pub events: u64,
    /// Records and events not in the log, for any reason: the sum of the four counts below.
    pub dropped: u64,
    /// Dropped because the channel was full (the writer fell behind).
    pub queue_full: u64,
    /// Lost to a failed write (disk full, I/O error): the one that failed and every later one.
    pub write_failed: u64,
    /// Not written because the log reached [`WriterOptions::max_bytes`].
    pub capped: u64,
    /// Not written because the line exceeded [`WriterOptions::max_line_bytes`].
    pub too_large: u64,
    /// Frames the run's `flight.tlog` did not write because it reached its cap (told to this log
    /// by [`DecisionLog::watch_tlog`]; not records, so not in `dropped`).
    pub tlog_capped: u64,
    /// Parts written (1 = only `decisions.jsonl`).
    pub parts: u32,
    /// Writes that failed (lines of any kind) and the last such error.
    pub write_errors: u64,
    pub last_error: Option<String>,
}

/// Records another reader let go of (`--live`'s hub: its previous latest and a full viewer
/// queue's oldest), handed over with a record to be dropped on the writer's thread after it: their
/// memory is then freed where a log without `--live` frees its records, one at a time, not in
/// bursts on another thread contending with the cycle's allocations (issue 37).
pub type LetGo = [Option<Arc<DecisionRecord>>; 2];

enum Payload {
    // Shared: `--live` serves the same record (crate::live), no second copy on the cycle.
    Record(Arc<DecisionRecord>, LetGo),
    Event {
        cycle: u64,
        time_s: f64,
        text: String,
    },
    /// More tlog frames counted, not written, since the last report.
    TlogCapped(u64),
}

struct Msg {
    /// Drops that happened between the previous accepted message and this one: the writer puts
    /// the loss line exactly where the lost records belong.
    lost_before: u64,
    payload: Payload,
}

/// Why records were lost, as written in a loss line's `reason`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Loss {
    QueueFull,
    WriteFailed,
    Cap,
    TooLarge,
    /// Frames of the run's tlog past its cap (not records: counted apart from `dropped`).
    TlogCap,
}

impl Loss {
    fn reason(self) -> &'static str {
        match self {
            Loss::QueueFull => "queue_full",
            Loss::WriteFailed => "write_failed",
            Loss::Cap => "cap",
            Loss::TooLarge => "too_large",
            Loss::TlogCap => "tlog_cap",
        }
    }
}

#[derive(Serialize)]
struct LossLine {
    kind: &'static str,
    dropped: u64,
    reason: &'static str,
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
    queue_full: u64,
    write_failed: u64,
    capped: u64,
    too_large: u64,
    tlog_capped: u64,
}

/// Handle to a running decision log. Cheap to call from the decision loop: [`Self::record`]
/// never blocks and never touches the disk.
pub struct DecisionLog {
    tx: Option<SyncSender<Msg>>,
    pending_lost: Arc<AtomicU64>,
    dropped_total: Arc<AtomicU64>,
    handle: Option<JoinHandle<WriterStats>>,
    dir: PathBuf,
    /// The tlog's count of capped frames, and how much of it this log has said.
    tlog: Option<(Arc<AtomicU64>, AtomicU64)>,
}

impl DecisionLog {
    /// Write the header of `decisions.jsonl` in `dir` now (so a bad folder fails here, not
    /// silently later) and start the writer thread.
    pub fn start(dir: &Path, header: Header, opts: WriterOptions) -> io::Result<Self> {
        let disk = opts.disk_bytes.map(|b| Arc::new(Mutex::new(b)));
        let mut part = Part::open(dir, &header, 0, disk.clone())?;
        part.sync()?;
        let reserve = Reserve::create(dir, disk.clone());
        let (tx, rx) = sync_channel::<Msg>(opts.capacity.max(1));
        let pending_lost = Arc::new(AtomicU64::new(0));
        let dropped_total = Arc::new(AtomicU64::new(0));
        let thread = WriterThread {
            dir: dir.to_path_buf(),
            header,
            total_bytes: part.bytes,
            opts,
            part,
            stats: WriterStats {
                parts: 1,
                ..Default::default()
            },
            pending_lost: pending_lost.clone(),
            disk,
            reserve,
            unreported: Vec::new(),
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
            tlog: None,
        })
    }

    /// The run folder this log writes into.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Queue one record. Returns false when it was dropped (channel full); the drop is counted
    /// and reported in the file by a loss line.
    pub fn record(&self, record: DecisionRecord) -> bool {
        self.record_shared(Arc::new(record))
    }

    /// [`DecisionLog::record`] of a record shared with other readers.
    pub fn record_shared(&self, record: Arc<DecisionRecord>) -> bool {
        self.send(Payload::Record(record, LetGo::default()))
    }

    /// [`DecisionLog::record_shared`], and records the caller lets go of, dropped on the writer's
    /// thread after this one ([`LetGo`]); when the queue is full they drop here.
    pub fn record_letting_go(&self, record: Arc<DecisionRecord>, let_go: LetGo) -> bool {
        self.send(Payload::Record(record, let_go))
    }

    /// Queue one event line (`failsafe`, `link lost`, `mode RTL`, ...) outside the records.
    pub fn event(&self, cycle: u64, time_s: f64, text: impl Into<String>) -> bool {
        self.send(Payload::Event {
            cycle,
            time_s,
            text: text.into(),
        })
    }

    /// Say in this log when the run's tlog reaches its cap: `capped` is the tlog's counter
    /// ([`TlogWriter::capped_counter`](super::TlogWriter::capped_counter)). The first capped
    /// frames get a loss line (reason `tlog_cap`) with the next record, the rest one at close,
    /// and the end line carries the total.
    pub fn watch_tlog(&mut self, capped: Arc<AtomicU64>) {
        self.tlog = Some((capped, AtomicU64::new(0)));
    }

    /// Tell the writer about tlog frames capped since the last call.
    fn report_tlog(&self, tx: &SyncSender<Msg>, blocking: bool) {
        let Some((counter, said)) = &self.tlog else {
            return;
        };
        let now = counter.load(Ordering::Acquire);
        let before = said.swap(now, Ordering::AcqRel);
        if now <= before {
            said.fetch_max(before, Ordering::AcqRel);
            return;
        }
        let msg = Msg {
            lost_before: 0,
            payload: Payload::TlogCapped(now - before),
        };
        let sent = if blocking {
            tx.send(msg).is_ok()
        } else {
            tx.try_send(msg).is_ok()
        };
        if !sent {
            // Said with a later record or at close.
            said.store(before, Ordering::Release);
        }
    }

    /// Records and events dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped_total.load(Ordering::Relaxed)
    }

    fn send(&self, payload: Payload) -> bool {
        let Some(tx) = &self.tx else { return false };
        self.report_tlog(tx, false);
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
        if let Some(tx) = &self.tx {
            self.report_tlog(tx, true);
        }
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

/// The simulated disk of [`WriterOptions::disk_bytes`]: bytes left.
type Disk = Option<Arc<Mutex<u64>>>;

/// One open part file.
struct Part {
    file: File,
    /// Bytes of whole lines in the file (the length a failed write is cut back to).
    bytes: u64,
    lines_after_header: u64,
    index: u32,
    disk: Disk,
}

impl Part {
    fn open(dir: &Path, header: &Header, index: u32, disk: Disk) -> io::Result<Part> {
        let path = part_path(dir, index);
        let file = OpenOptions::new()
            .create_new(true)
            .write(true)
            .open(&path)?;
        let mut part = Part {
            file,
            bytes: 0,
            lines_after_header: 0,
            index,
            disk,
        };
        let mut h = header.clone();
        h.part = index;
        let mut line = serde_json::to_string(&h).map_err(io::Error::other)?;
        line.push('\n');
        part.append(line.as_bytes())?;
        Ok(part)
    }

    /// Write one whole line, or nothing: on failure the file is cut back to its last whole line.
    fn append(&mut self, line: &[u8]) -> io::Result<()> {
        let (written, r) = self.write_through_disk(line);
        match r.and_then(|_| self.file.flush()) {
            Ok(()) => {
                self.bytes += line.len() as u64;
                Ok(())
            }
            Err(e) => {
                let cut = self
                    .file
                    .set_len(self.bytes)
                    .and_then(|_| self.file.seek(SeekFrom::Start(self.bytes)));
                if let Some(d) = &self.disk {
                    *d.lock().unwrap_or_else(|p| p.into_inner()) += written;
                }
                match cut {
                    Ok(_) => Err(e),
                    Err(c) => Err(io::Error::new(
                        e.kind(),
                        format!("{e}; cutting the partial line failed too: {c}"),
                    )),
                }
            }
        }
    }

    /// One `write_all` of the whole line (through the simulated disk when a test set one):
    /// the bytes that reached the file, and the result.
    fn write_through_disk(&mut self, line: &[u8]) -> (u64, io::Result<()>) {
        let Some(d) = self.disk.clone() else {
            // Unknown how much of a failed write_all landed: the cut to `bytes` covers it.
            return (0, self.file.write_all(line));
        };
        let mut left = d.lock().unwrap_or_else(|p| p.into_inner());
        let n = (*left).min(line.len() as u64) as usize;
        if let Err(e) = self.file.write_all(&line[..n]) {
            return (0, Err(e));
        }
        *left -= n as u64;
        if n < line.len() {
            return (
                n as u64,
                Err(io::Error::new(
                    io::ErrorKind::StorageFull,
                    "No space left on device (simulated)",
                )),
            );
        }
        (n as u64, Ok(()))
    }

    fn sync(&mut self) -> io::Result<()> {
        self.file.sync_data()
    }
}

/// [`RESERVE_BYTES`] held in the run folder until a write fails.
struct Reserve {
    path: PathBuf,
    disk: Disk,
    held: bool,
}

impl Reserve {
    /// Best effort: a folder without room for the reserve still gets a log.
    fn create(dir: &Path, disk: Disk) -> Reserve {
        let path = dir.join(RESERVE_FILE);
        let mut held = false;
        let room = disk.as_ref().is_none_or(|d| {
            let mut left = d.lock().unwrap_or_else(|p| p.into_inner());
            let ok = *left >= RESERVE_BYTES;
            if ok {
                *left -= RESERVE_BYTES;
            }
            ok
        });
        if room {
            let zeros = vec![0u8; RESERVE_BYTES as usize];
            held = File::create(&path)
                .and_then(|mut f| f.write_all(&zeros).and_then(|_| f.sync_data()))
                .is_ok();
            if !held {
                let _ = std::fs::remove_file(&path);
                if let Some(d) = &disk {
                    *d.lock().unwrap_or_else(|p| p.into_inner()) += RESERVE_BYTES;
                }
            }
        }
        Reserve { path, disk, held }
    }

    /// Give the space back (at the first failed write, and at close).
    fn release(&mut self) {
        if self.held && std::fs::remove_file(&self.path).is_ok() {
            self.held = false;
            if let Some(d) = &self.disk {
                *d.lock().unwrap_or_else(|p| p.into_inner()) += RESERVE_BYTES;
            }
        }
    }
}

struct WriterThread {
    dir: PathBuf,
    header: Header,
    opts: WriterOptions,
    part: Part,
    stats: WriterStats,
    pending_lost: Arc<AtomicU64>,
    /// Bytes in all parts so far (against [`WriterOptions::max_bytes`]).
    total_bytes: u64,
    disk: Disk,
    reserve: Reserve,
    /// Losses counted but not yet in a loss line (written at close).
    unreported: Vec<(Loss, u64)>,
}

/// What a line is, for the cap and the failure rules: records and events are what a cap or a
/// failed disk stops; loss and end lines are always attempted.
#[derive(Clone, Copy, PartialEq, Eq)]
enum LineKind {
    Payload,
    Meta,
}

impl WriterThread {
    fn run(mut self, rx: Receiver<Msg>) -> WriterStats {
        while let Ok(msg) = rx.recv() {
            if msg.lost_before > 0 {
                self.write_loss(Loss::QueueFull, msg.lost_before);
            }
            match msg.payload {
                Payload::Record(r, let_go) => {
                    if self.write_json(&*r, LineKind::Payload) {
                        self.stats.records += 1;
                    }
                    drop((r, let_go));
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
                    if self.write_json(&line, LineKind::Payload) {
                        self.stats.events += 1;
                    }
                }
                Payload::TlogCapped(n) => {
                    // The first at once (a killed run still says it), the rest at close.
                    let first = self.stats.tlog_capped == 0;
                    self.count(Loss::TlogCap, n);
                    if first {
                        self.write_loss_line(Loss::TlogCap, n);
                    } else {
                        self.defer(Loss::TlogCap, n);
                    }
                }
            }
        }
        // Channel closed: drops after the last accepted message are still owed a loss line.
        let rest = self.pending_lost.swap(0, Ordering::AcqRel);
        if rest > 0 {
            self.write_loss(Loss::QueueFull, rest);
        }
        // The reserve's space is for these last lines.
        self.reserve.release();
        for (why, n) in std::mem::take(&mut self.unreported) {
            self.write_loss_line(why, n);
        }
        let st = &self.stats;
        let end = EndLine {
            kind: "end",
            records: st.records,
            events: st.events,
            dropped: st.dropped,
            queue_full: st.queue_full,
            write_failed: st.write_failed,
            capped: st.capped,
            too_large: st.too_large,
            tlog_capped: st.tlog_capped,
        };
        self.write_json(&end, LineKind::Meta);
        if let Err(e) = self.part.sync() {
            self.stats.last_error = Some(e.to_string());
        }
        self.stats
    }

    /// Count `n` lost for `why`.
    fn count(&mut self, why: Loss, n: u64) {
        if why == Loss::TlogCap {
            self.stats.tlog_capped += n;
            return;
        }
        self.stats.dropped += n;
        match why {
            Loss::QueueFull => self.stats.queue_full += n,
            Loss::WriteFailed => self.stats.write_failed += n,
            Loss::Cap => self.stats.capped += n,
            Loss::TooLarge => self.stats.too_large += n,
            Loss::TlogCap => {}
        }
    }

    /// Count and say a loss now.
    fn write_loss(&mut self, why: Loss, n: u64) {
        self.count(why, n);
        self.write_loss_line(why, n);
    }

    fn write_loss_line(&mut self, why: Loss, n: u64) {
        let line = LossLine {
            kind: "loss",
            dropped: n,
            reason: why.reason(),
        };
        if !self.write_json(&line, LineKind::Meta) {
            self.defer(why, n);
        }
    }

    /// Remember a counted loss for a loss line at close.
    fn defer(&mut self, why: Loss, n: u64) {
        match self.unreported.iter_mut().find(|(w, _)| *w == why) {
            Some((_, k)) => *k += n,
            None => self.unreported.push((why, n)),
        }
    }

    /// A record or event that will not be written: counted, said at once the first time for
    /// its reason (so a killed process still leaves the reason), later ones said at close.
    fn lose_payload(&mut self, why: Loss) {
        let first = match why {
            Loss::WriteFailed => self.stats.write_failed == 0,
            Loss::Cap => self.stats.capped == 0,
            _ => true,
        };
        self.count(why, 1);
        if first {
            self.write_loss_line(why, 1);
        } else {
            self.defer(why, 1);
        }
    }

    /// Serialise, rotate if needed, write the whole line in one call and flush. True on success.
    fn write_json<T: Serialize>(&mut self, value: &T, kind: LineKind) -> bool {
        let stall = self.opts.stall.clone();
        let _stalled = stall.as_ref().map(|m| m.lock());
        let mut line = match serde_json::to_string(value) {
            Ok(l) => l,
            Err(e) => {
                self.stats.last_error = Some(e.to_string());
                if kind == LineKind::Payload {
                    self.lose_payload(Loss::TooLarge);
                }
                return false;
            }
        };
        line.push('\n');
        let n = line.len() as u64;
        if kind == LineKind::Payload {
            if self.stats.write_failed > 0 {
                // The disk already failed once: keep what is left of it for the loss and end
                // lines rather than retry each record.
                self.lose_payload(Loss::WriteFailed);
                return false;
            }
            if n > self.opts.max_line_bytes {
                self.lose_payload(Loss::TooLarge);
                return false;
            }
            if self.total_bytes + n > self.opts.max_bytes {
                if self.stats.capped == 0 {
                    eprintln!(
                        "warning: decision log {} reached its cap of {} bytes: further \
                         records are counted, not written",
                        crate::text::escape_controls(&self.dir.display().to_string(), false),
                        self.opts.max_bytes
                    );
                }
                self.lose_payload(Loss::Cap);
                return false;
            }
        }
        if kind == LineKind::Payload
            && self.part.lines_after_header > 0
            && self.part.bytes + n > self.opts.rotate_bytes
        {
            let _ = self.part.sync();
            match Part::open(
                &self.dir,
                &self.header,
                self.part.index + 1,
                self.disk.clone(),
            ) {
                Ok(p) => {
                    self.total_bytes += p.bytes;
                    self.part = p;
                    self.stats.parts += 1;
                }
                Err(e) => {
                    // Keep writing into the oversized part rather than losing records. A part
                    // file left without its whole header reads as a damaged part.
                    self.stats.last_error = Some(format!("rotation failed: {e}"));
                }
            }
        }
        match self.part.append(line.as_bytes()) {
            Ok(()) => {
                self.total_bytes += n;
                self.part.lines_after_header += 1;
                true
            }
            Err(e) => {
                self.stats.write_errors += 1;
                self.stats.last_error = Some(e.to_string());
                if kind == LineKind::Payload {
                    eprintln!(
                        "warning: decision log {}: write failed ({e}): this and every later \
                         record are counted as lost",
                        crate::text::escape_controls(&self.dir.display().to_string(), false)
                    );
                    // Space for the loss line that says so.
                    self.reserve.release();
                    self.lose_payload(Loss::WriteFailed);
                }
                false
            }
        }
    }
}
