//! `fly --live` / `simulate --live ws://HOST:PORT`: the decision channels served live with the
//! Foxglove WebSocket protocol (v1, subprotocol `foxglove.websocket.v1`), the same channels and
//! schemas as `export --format mcap` ([`crate::decision_channels`]).
//!
//! The cycle never waits for a viewer: [`LiveSink`] writes the record first (to the log, as
//! without `--live`), then hands it to the [`Hub`], which only appends it to each subscribed
//! viewer's bounded queue ([`LiveArgs::live_queue`] records). A viewer that does not keep up loses
//! its oldest queued records; the messages lost are counted ([`Hub::dropped`]) and the count so
//! far is the record's `live_dropped`. Serialising and sending happen on the server's own thread
//! ([`server`]). A viewer that subscribes mid-flight first gets the latest record's message on
//! each channel it subscribes to.
//!
//! Read-only: client messages other than `subscribe`/`unsubscribe` are ignored and counted.

pub mod server;

use crate::decision_log::LetGo;
use companion_core::record::DecisionRecord;
use std::collections::{BTreeMap, VecDeque};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

pub use server::LiveServer;

/// Records queued per viewer at most before the oldest is dropped (`--live-queue`).
pub const DEFAULT_QUEUE: usize = 64;

/// The `--live` options `fly` and `simulate` share.
#[derive(Debug, Clone, clap::Args)]
pub struct LiveArgs {
    /// Serve the decision channels live to Foxglove (WebSocket protocol) at ws://HOST:PORT (or
    /// HOST:PORT, or PORT for 127.0.0.1:PORT; port 0 picks a free one). The address served is said
    /// on stderr at start. Use a non-loopback HOST only to serve other machines.
    #[arg(long, value_name = "ws://HOST:PORT", value_parser = parse_addr)]
    pub live: Option<SocketAddr>,
    /// Records queued per live viewer; a viewer further behind loses its oldest (counted in the
    /// record's `live_dropped`).
    #[arg(long, default_value_t = DEFAULT_QUEUE, requires = "live", value_parser = queue_size)]
    pub live_queue: usize,
}

fn queue_size(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=100_000).contains(&n) => Ok(n),
        _ => Err(format!("`{s}`: a number of records from 1 to 100000")),
    }
}

/// `ws://HOST:PORT`, `HOST:PORT` or `PORT` (loopback) -> the address to listen on.
pub fn parse_addr(s: &str) -> Result<SocketAddr, String> {
    use std::net::ToSocketAddrs;
    let rest = match s.split_once("://") {
        Some(("ws", rest)) => rest,
        Some((scheme, _)) => {
            return Err(format!(
                "`{s}`: scheme {scheme}:// is not served (ws://HOST:PORT, no TLS)"
            ));
        }
        None => s,
    };
    let rest = rest.strip_suffix('/').unwrap_or(rest);
    if rest.contains('/') {
        return Err(format!("`{s}`: no path is served (ws://HOST:PORT)"));
    }
    if let Ok(port) = rest.parse::<u16>() {
        return Ok(SocketAddr::from(([127, 0, 0, 1], port)));
    }
    let mut addrs = rest
        .to_socket_addrs()
        .map_err(|e| format!("`{s}`: not HOST:PORT ({e})"))?;
    addrs
        .next()
        .ok_or_else(|| format!("`{s}`: the host has no address"))
}

/// How long the end of a run waits for the viewers to get what is queued.
pub const DRAIN: Duration = Duration::from_secs(3);

/// Start the server when `--live` is given; the address served is said on stderr.
pub fn start(args: &LiveArgs, start_ns: u64) -> anyhow::Result<Option<LiveServer>> {
    let Some(addr) = args.live else {
        return Ok(None);
    };
    let hub = Arc::new(Hub::new(args.live_queue, start_ns));
    let server = LiveServer::start(addr, hub)?;
    let loopback = if server.addr.ip().is_loopback() {
        "this machine only"
    } else {
        "OTHER MACHINES TOO: the address is not loopback"
    };
    eprintln!(
        "live: Foxglove WebSocket at ws://{} ({loopback}; {} records queued per viewer)",
        server.addr, args.live_queue
    );
    tracing::info!("live: Foxglove WebSocket at ws://{}", server.addr);
    Ok(Some(server))
}

/// End the server (the viewers get what is queued, at most [`DRAIN`]); the end-of-run words:
/// ` live_dropped N live_ignored M` (empty without `--live`).
pub fn finish(server: Option<LiveServer>) -> String {
    let Some(server) = server else {
        return String::new();
    };
    let hub = server.hub();
    server.finish(DRAIN);
    format!(
        " live_dropped {} live_ignored {}",
        hub.dropped(),
        hub.ignored()
    )
}

/// One viewer's queue: records (with their publish sequence) not yet handed to its sender.
#[derive(Debug)]
struct Viewer {
    queue: VecDeque<(u64, Arc<DecisionRecord>)>,
    /// Channels subscribed: each queued record is that many messages.
    channels: usize,
    wake: Arc<tokio::sync::Notify>,
    /// `simulate`'s pacing gave up on this viewer (it did not take within the wait).
    waited_out: bool,
}

#[derive(Debug, Default)]
struct HubState {
    seq: u64,
    latest: Option<(u64, Arc<DecisionRecord>)>,
    viewers: BTreeMap<u64, Viewer>,
    next_viewer: u64,
    subscribed_ever: bool,
    closed: bool,
    /// Records the hub let go of (the previous latest, a full queue's oldest): handed back by
    /// [`Hub::publish`] two at a time, to be freed on the log's thread; more than that (several
    /// viewers) wait here for the server's thread ([`Hub::bury`]), beyond [`GRAVEYARD_MAX`] freed at once.
    graveyard: Vec<Arc<DecisionRecord>>,
}

/// Records let go of at most, waiting for the server's thread to free them (beyond: freed at
/// once, on the cycle).
const GRAVEYARD_MAX: usize = 4096;
/// Records let go of before the server's thread is woken to free them.
const GRAVEYARD_BATCH: usize = 32;

/// What the cycle hands records to and the viewers take them from (see the module's text).
#[derive(Debug)]
pub struct Hub {
    state: Mutex<HubState>,
    /// A viewer took records or subscribed (`simulate`'s waits).
    changed: Condvar,
    capacity: usize,
    dropped: AtomicU64,
    ignored: AtomicU64,
    /// Wakes the server's thread to free what the hub let go of.
    pub(crate) janitor: tokio::sync::Notify,
    /// The run's start (ns since the epoch): message time = start + `time_s`, as the export.
    pub start_ns: u64,
}

/// A viewer's handle on the hub, from [`Hub::connect`].
pub(crate) struct ViewerId(u64);

impl Hub {
    /// `capacity` records per viewer.
    pub fn new(capacity: usize, start_ns: u64) -> Self {
        Self {
            state: Mutex::new(HubState::default()),
            changed: Condvar::new(),
            capacity: capacity.max(1),
            dropped: AtomicU64::new(0),
            ignored: AtomicU64::new(0),
            janitor: tokio::sync::Notify::new(),
            start_ns,
        }
    }

    fn lock(&self) -> MutexGuard<'_, HubState> {
        // A viewer task that panicked holding the lock leaves consistent queues: keep going.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Hand one record to every subscribed viewer; never waits. A full queue loses its oldest
    /// record (its messages counted in [`Hub::dropped`]). Returns up to two records the hub let
    /// go of, for the caller to free off the cycle (the log's thread: [`LetGo`]).
    pub fn publish(&self, rec: Arc<DecisionRecord>) -> LetGo {
        let mut s = self.lock();
        s.seq += 1;
        let seq = s.seq;
        let HubState {
            latest,
            viewers,
            graveyard,
            ..
        } = &mut *s;
        graveyard.extend(latest.replace((seq, Arc::clone(&rec))).map(|(_, r)| r));
        let mut lost = 0u64;
        for v in viewers.values_mut().filter(|v| v.channels > 0) {
            if v.queue.len() >= self.capacity {
                graveyard.extend(v.queue.pop_front().map(|(_, r)| r));
                lost += v.channels as u64;
            }
            v.queue.push_back((seq, Arc::clone(&rec)));
            v.wake.notify_one();
        }
        let let_go = [graveyard.pop(), graveyard.pop()];
        let buried = graveyard.len();
        let overflow = if buried > GRAVEYARD_MAX {
            std::mem::take(graveyard)
        } else {
            Vec::new()
        };
        drop(s);
        drop(overflow);
        if lost > 0 {
            self.dropped.fetch_add(lost, Ordering::Relaxed);
        }
        // Waking the server's thread is a system call: once per batch, not per record.
        if buried >= GRAVEYARD_BATCH {
            self.janitor.notify_one();
        }
        let_go
    }

    /// Free the records the hub let go of (the server's thread).
    pub(crate) fn bury(&self) {
        let dead = std::mem::take(&mut self.lock().graveyard);
        drop(dead);
    }

    /// Messages the viewers lost so far (summed over viewers).
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Client messages ignored so far (anything but subscribe/unsubscribe, or malformed).
    pub fn ignored(&self) -> u64 {
        self.ignored.load(Ordering::Relaxed)
    }

    pub(crate) fn count_ignored(&self) {
        self.ignored.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn connect(&self) -> (ViewerId, Arc<tokio::sync::Notify>) {
        let mut s = self.lock();
        let id = s.next_viewer;
        s.next_viewer += 1;
        let wake = Arc::new(tokio::sync::Notify::new());
        s.viewers.insert(
            id,
            Viewer {
                queue: VecDeque::new(),
                channels: 0,
                wake: Arc::clone(&wake),
                waited_out: false,
            },
        );
        (ViewerId(id), wake)
    }

    pub(crate) fn disconnect(&self, id: &ViewerId) {
        self.lock().viewers.remove(&id.0);
        self.changed.notify_all();
    }

    /// The viewer now has `channels` subscriptions; returns the latest record (what a viewer
    /// subscribing mid-run gets first).
    pub(crate) fn subscribed(
        &self,
        id: &ViewerId,
        channels: usize,
    ) -> Option<(u64, Arc<DecisionRecord>)> {
        let mut s = self.lock();
        if let Some(v) = s.viewers.get_mut(&id.0) {
            v.channels = channels;
            if channels == 0 {
                v.queue.clear();
            }
        }
        if channels > 0 {
            s.subscribed_ever = true;
        }
        let latest = s.latest.clone();
        drop(s);
        self.changed.notify_all();
        latest
    }

    /// The viewer's queued records, oldest first, and whether the hub is closed.
    pub(crate) fn take(&self, id: &ViewerId) -> (Vec<(u64, Arc<DecisionRecord>)>, bool) {
        let mut s = self.lock();
        let closed = s.closed;
        let batch = match s.viewers.get_mut(&id.0) {
            Some(v) => {
                v.waited_out = false;
                v.queue.drain(..).collect()
            }
            None => Vec::new(),
        };
        drop(s);
        self.changed.notify_all();
        (batch, closed)
    }

    /// No more records: each viewer sends what it has queued, then closes.
    pub fn close(&self) {
        let mut s = self.lock();
        s.closed = true;
        for v in s.viewers.values() {
            v.wake.notify_one();
        }
    }

    /// Blocks until some viewer has subscribed to a channel, at most `wait`; true if one has.
    pub fn wait_for_subscriber(&self, wait: Duration) -> bool {
        let s = self.lock();
        let (s, _) = self
            .changed
            .wait_timeout_while(s, wait, |s| !s.subscribed_ever)
            .unwrap_or_else(|p| p.into_inner());
        s.subscribed_ever
    }

    /// `simulate`'s pacing: blocks until every subscribed viewer's queue has room, at most
    /// `wait`; viewers still full then are not waited for again until they take.
    pub fn wait_for_room(&self, wait: Duration) {
        let cap = self.capacity;
        let full = |s: &HubState| {
            s.viewers
                .values()
                .any(|v| v.channels > 0 && !v.waited_out && v.queue.len() >= cap)
        };
        let deadline = Instant::now() + wait;
        let mut s = self.lock();
        while full(&s) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                for v in s.viewers.values_mut() {
                    if v.channels > 0 && v.queue.len() >= cap {
                        v.waited_out = true;
                    }
                }
                return;
            }
            s = self
                .changed
                .wait_timeout(s, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

/// A record sink (`fly::RecordSink`) that also serves the records live: the record is written to `inner` with the
/// drop count so far (`live_dropped`), then handed to the hub. Without a hub, `inner` alone.
pub struct LiveSink<S> {
    pub inner: S,
    hub: Option<Arc<Hub>>,
}

impl<S> LiveSink<S> {
    pub fn new(inner: S, hub: Option<Arc<Hub>>) -> Self {
        Self { inner, hub }
    }
}

impl<S> LiveSink<S> {
    /// With a hub: the record to write and serve, stamped with the losses so far (its
    /// `RecordSink` impl, in `fly`, writes it to `inner` first, then [`LiveSink::publish`]es it).
    pub fn stamp(&self, rec: &DecisionRecord) -> Option<Arc<DecisionRecord>> {
        let hub = self.hub.as_ref()?;
        let mut rec = rec.clone();
        rec.live_dropped = Some(hub.dropped());
        Some(Arc::new(rec))
    }

    /// Hand a record to the viewers; what the hub let go of comes back ([`Hub::publish`]).
    pub fn publish(&self, rec: Arc<DecisionRecord>) -> LetGo {
        match &self.hub {
            Some(hub) => hub.publish(rec),
            None => LetGo::default(),
        }
    }
}

#[cfg(test)]
mod tests;
