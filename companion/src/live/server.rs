//! The Foxglove WebSocket server (ws-protocol v1) on its own thread and runtime: the decision
//! loop only touches the [`Hub`]. Per viewer: `serverInfo` and `advertise` (the decision
//! channels) on connect; `subscribe`/`unsubscribe` handled; each subscribed channel's message
//! for each record as binary `messageData` (opcode 1, subscription id u32 LE, log time u64 LE
//! ns, the JSON message). Frames are tokio-tungstenite's.

use super::Hub;
use crate::decision_channels::{self as channels, GROUPS};
use companion_core::record::DecisionRecord;
use futures_util::{SinkExt, StreamExt};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};

/// The WebSocket subprotocol of the Foxglove WebSocket protocol.
pub const SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// `messageData`'s opcode.
const MESSAGE_DATA: u8 = 0x01;

/// The running server: its address and the thread that serves.
pub struct LiveServer {
    pub addr: SocketAddr,
    hub: Arc<Hub>,
    done: std::sync::mpsc::Receiver<()>,
    stop: Arc<tokio::sync::Notify>,
}

impl LiveServer {
    /// Listen on `addr` (errors here, before the run starts) and serve on a thread of its own.
    pub fn start(addr: SocketAddr, hub: Arc<Hub>) -> anyhow::Result<Self> {
        use anyhow::Context;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .context("--live: starting its runtime")?;
        let listener = rt
            .block_on(async { listen(addr) })
            .with_context(|| format!("--live {addr}: cannot listen"))?;
        let addr = listener.local_addr()?;
        let (tx, done) = std::sync::mpsc::channel();
        let stop = Arc::new(tokio::sync::Notify::new());
        let (h, s) = (Arc::clone(&hub), Arc::clone(&stop));
        std::thread::Builder::new()
            .name("live".into())
            .spawn(move || {
                rt.block_on(serve(listener, h, s));
                let _ = tx.send(());
            })
            .context("--live: starting its thread")?;
        Ok(Self {
            addr,
            hub,
            done,
            stop,
        })
    }

    pub fn hub(&self) -> Arc<Hub> {
        Arc::clone(&self.hub)
    }

    /// No more records: viewers get what is queued, then the connections close; waits at most
    /// `drain` (a stalled viewer is left behind).
    pub fn finish(self, drain: Duration) {
        self.hub.close();
        self.stop.notify_one();
        let _ = self.done.recv_timeout(drain);
    }
}

/// Viewers' sockets keep at most this much unsent (SO_SNDBUF, inherited from the listener):
/// without it the kernel's buffer grows to megabytes on loopback, and a stalled viewer would
/// hold that much instead of losing messages from its bounded queue.
const SEND_BUFFER: u32 = 64 * 1024;

fn listen(addr: SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    let socket = if addr.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    socket.set_reuseaddr(true)?;
    socket.set_send_buffer_size(SEND_BUFFER)?;
    socket.bind(addr)?;
    socket.listen(64)
}

async fn serve(listener: tokio::net::TcpListener, hub: Arc<Hub>, stop: Arc<tokio::sync::Notify>) {
    let mut viewers = tokio::task::JoinSet::new();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    let _ = stream.set_nodelay(true);
                    viewers.spawn(viewer(stream, peer, Arc::clone(&hub)));
                }
                Err(e) => tracing::warn!("--live: accept failed: {e}"),
            },
            () = hub.janitor.notified() => hub.bury(),
            () = stop.notified() => break,
        }
    }
    while viewers.join_next().await.is_some() {}
}

/// Offer the Foxglove subprotocol when the client asks for it.
#[allow(clippy::result_large_err)] // the signature tungstenite's handshake callback takes
fn choose_subprotocol(req: &Request, mut resp: Response) -> Result<Response, ErrorResponse> {
    let offered = req
        .headers()
        .get_all("sec-websocket-protocol")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|p| p.trim() == SUBPROTOCOL);
    if offered {
        resp.headers_mut().insert(
            "sec-websocket-protocol",
            SUBPROTOCOL.parse().expect("ASCII"),
        );
    }
    Ok(resp)
}

fn server_info(hub: &Hub) -> String {
    serde_json::json!({
        "op": "serverInfo",
        "name": "companion",
        "capabilities": [],
        "supportedEncodings": [],
        "metadata": {},
        "sessionId": hub.start_ns.to_string(),
    })
    .to_string()
}

/// Channel ids are 1 + the group's index in [`GROUPS`].
fn advertise() -> String {
    let chans: Vec<serde_json::Value> = GROUPS
        .iter()
        .enumerate()
        .map(|(i, g)| {
            serde_json::json!({
                "id": i + 1,
                "topic": channels::topic(g),
                "encoding": channels::MESSAGE_ENCODING,
                "schemaName": channels::schema_name(g),
                "schema": channels::schema(g),
                "schemaEncoding": channels::SCHEMA_ENCODING,
            })
        })
        .collect();
    serde_json::json!({"op": "advertise", "channels": chans}).to_string()
}

/// One viewer's subscriptions and what each channel has been sent up to.
#[derive(Default)]
pub(crate) struct Subscriptions {
    /// Subscription id -> group index.
    subs: BTreeMap<u32, usize>,
    /// Per group, the sequence of the last record sent on it.
    sent: [u64; GROUPS.len()],
}

impl Subscriptions {
    /// A client text message: Some(groups newly subscribed) for subscribe/unsubscribe, None
    /// for anything else (ignored).
    pub(crate) fn on_text(&mut self, text: &str) -> Option<Vec<usize>> {
        let v: serde_json::Value = serde_json::from_str(text).ok()?;
        match v.get("op")?.as_str()? {
            "subscribe" => {
                let mut new = Vec::new();
                for s in v.get("subscriptions")?.as_array()? {
                    let id = s.get("id").and_then(|x| x.as_u64());
                    let ch = s.get("channelId").and_then(|x| x.as_u64());
                    if let (Some(id), Some(ch)) = (id, ch)
                        && let Ok(id) = u32::try_from(id)
                        && (1..=GROUPS.len() as u64).contains(&ch)
                        && !self.subs.contains_key(&id)
                    {
                        self.subs.insert(id, ch as usize - 1);
                        new.push(ch as usize - 1);
                    }
                }
                Some(new)
            }
            "unsubscribe" => {
                for id in v.get("subscriptionIds")?.as_array()? {
                    if let Some(id) = id.as_u64().and_then(|i| u32::try_from(i).ok()) {
                        self.subs.remove(&id);
                    }
                }
                Some(Vec::new())
            }
            _ => None,
        }
    }

    pub(crate) fn channels(&self) -> usize {
        self.subs.len()
    }

    /// The `messageData` frames of one record: each subscription whose channel has not had this
    /// record (or a later one) yet; `only` limits it to those groups.
    pub(crate) fn frames(
        &mut self,
        seq: u64,
        rec: &DecisionRecord,
        start_ns: u64,
        only: Option<&[usize]>,
    ) -> Vec<Vec<u8>> {
        let due: Vec<(u32, usize)> = (self.subs.iter())
            .filter(|(_, g)| self.sent[**g] < seq && only.is_none_or(|o| o.contains(g)))
            .map(|(id, g)| (*id, *g))
            .collect();
        if due.is_empty() {
            return Vec::new();
        }
        let v = channels::record_value(rec);
        let t = channels::log_time_ns(start_ns, rec);
        let mut out = Vec::with_capacity(due.len());
        for (id, g) in &due {
            let payload =
                serde_json::to_vec(&channels::message(&v, GROUPS[*g])).unwrap_or_default();
            let mut f = Vec::with_capacity(13 + payload.len());
            f.push(MESSAGE_DATA);
            f.extend_from_slice(&id.to_le_bytes());
            f.extend_from_slice(&t.to_le_bytes());
            f.extend_from_slice(&payload);
            out.push(f);
        }
        for (_, g) in due {
            self.sent[g] = seq;
        }
        out
    }
}

async fn viewer(stream: tokio::net::TcpStream, peer: SocketAddr, hub: Arc<Hub>) {
    let ws = match tokio_tungstenite::accept_hdr_async(stream, choose_subprotocol).await {
        Ok(ws) => ws,
        Err(e) => {
            tracing::info!("--live: {peer}: not a WebSocket client ({e})");
            hub.count_ignored();
            return;
        }
    };
    tracing::info!("--live: viewer {peer} connected");
    let (id, wake) = hub.connect();
    let (mut tx, mut rx) = ws.split();
    let mut subs = Subscriptions::default();
    let hello = [server_info(&hub), advertise()];
    let mut ok = true;
    for text in hello {
        ok &= tx.send(Message::text(text)).await.is_ok();
    }
    while ok {
        let mut frames = Vec::new();
        tokio::select! {
            msg = rx.next() => match msg {
                Some(Ok(Message::Text(t))) => match subs.on_text(t.as_str()) {
                    Some(new) => {
                        let latest = hub.subscribed(&id, subs.channels());
                        if let Some((seq, rec)) = latest.filter(|_| !new.is_empty()) {
                            frames = subs.frames(seq, &rec, hub.start_ns, Some(&new));
                        }
                    }
                    None => hub.count_ignored(),
                },
                Some(Ok(Message::Binary(_))) => hub.count_ignored(),
                Some(Ok(Message::Close(_))) | None => break,
                Some(Err(e)) => {
                    tracing::info!("--live: viewer {peer}: {e}");
                    break;
                }
                Some(Ok(_)) => {} // ping/pong: answered by tungstenite
            },
            () = wake.notified() => {
                let (batch, closed) = hub.take(&id);
                for (seq, rec) in &batch {
                    frames.extend(subs.frames(*seq, rec, hub.start_ns, None));
                }
                if closed {
                    for f in frames.drain(..) {
                        if tx.feed(Message::binary(f)).await.is_err() {
                            break;
                        }
                    }
                    let _ = tx.send(Message::Close(None)).await;
                    break;
                }
            }
        }
        for f in frames {
            ok &= tx.feed(Message::binary(f)).await.is_ok();
        }
        if let Err(e) = tx.flush().await {
            tracing::info!("--live: viewer {peer}: {e}");
            ok = false;
        }
    }
    hub.disconnect(&id);
    tracing::info!("--live: viewer {peer} left");
}
