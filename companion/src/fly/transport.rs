//! Byte transports on tokio: TCP (client, reconnecting), TCP server (accepts again after the
//! client leaves), UDP in/out, serial (tokio-serial, reopened after an error). A supervisor task
//! owns the connection and reports bytes and (re)connections; framing is the ingest's job.
//!
//! A `udpin` socket never answers whoever sent the last datagram: it replies only to the peer
//! the fly loop sets ([`TransportHandle::peer`]), which it learns from valid MAVLink frames of the
//! chosen autopilot ([`UdpPeer`]). Junk datagrams get nothing back.

use companion_link::url::ConnectUrl;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::{mpsc, watch};

/// A TCP connect that hears nothing (a black-holed address) fails after this long instead of
/// the kernel's two minutes of SYN retries, so the operator hears about it within seconds.
const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// What the transport reports.
#[derive(Debug)]
pub enum Inbound {
    Connected(String),
    Bytes(Vec<u8>),
    /// `udpin` only: one datagram and who sent it (replies go to [`TransportHandle::peer`]).
    Datagram(Vec<u8>, SocketAddr),
    Disconnected(String),
}

/// Handle to a running transport task.
pub struct TransportHandle {
    pub inbound: mpsc::Receiver<Inbound>,
    pub outbound: mpsc::Sender<Vec<u8>>,
    /// `udpin` reply address; `None` (the start) sends nothing. Ignored by other transports.
    pub peer: watch::Sender<Option<SocketAddr>>,
    pub task: tokio::task::JoinHandle<()>,
}

/// Start the supervisor for `url`. `retry` is the pause between reconnection attempts.
pub fn spawn(url: ConnectUrl, retry: Duration) -> TransportHandle {
    let (in_tx, in_rx) = mpsc::channel(256);
    let (out_tx, out_rx) = mpsc::channel(256);
    let (peer_tx, peer_rx) = watch::channel(None);
    let task = tokio::spawn(supervise(url, retry, in_tx, out_rx, peer_rx));
    TransportHandle {
        inbound: in_rx,
        outbound: out_tx,
        peer: peer_tx,
        task,
    }
}

async fn supervise(
    url: ConnectUrl,
    retry: Duration,
    tx: mpsc::Sender<Inbound>,
    mut rx: mpsc::Receiver<Vec<u8>>,
    peer: watch::Receiver<Option<SocketAddr>>,
) {
    let mut listener: Option<TcpListener> = None;
    loop {
        let result = match &url {
            ConnectUrl::TcpOut { peer } => {
                match tokio::time::timeout(TCP_CONNECT_TIMEOUT, TcpStream::connect(peer.as_str()))
                    .await
                {
                    Ok(Ok(s)) => {
                        let _ = s.set_nodelay(true);
                        run_stream(s, &format!("tcp:{peer}"), &tx, &mut rx).await
                    }
                    Ok(Err(e)) => Err(format!("tcp connect {peer}: {e}")),
                    Err(_) => Err(format!(
                        "tcp connect {peer}: no answer within {}s (host unreachable?)",
                        TCP_CONNECT_TIMEOUT.as_secs()
                    )),
                }
            }
            ConnectUrl::TcpIn { bind } => {
                if listener.is_none() {
                    match TcpListener::bind(bind.as_str()).await {
                        Ok(l) => listener = Some(l),
                        Err(e) => {
                            let _ = tx
                                .send(Inbound::Disconnected(format!("tcpin bind {bind}: {e}")))
                                .await;
                            tokio::time::sleep(retry).await;
                            continue;
                        }
                    }
                }
                let l = listener.as_ref().expect("bound above");
                match accept_draining(l, &mut rx).await {
                    Ok((s, peer)) => {
                        run_stream(s, &format!("tcpin client {peer}"), &tx, &mut rx).await
                    }
                    Err(e) => Err(format!("tcpin accept: {e}")),
                }
            }
            ConnectUrl::UdpIn { bind } => match UdpSocket::bind(bind.as_str()).await {
                Ok(s) => {
                    let p = UdpReply::Learned(peer.clone());
                    run_udp(s, p, &format!("udpin:{bind}"), &tx, &mut rx).await
                }
                Err(e) => Err(format!("udpin bind {bind}: {e}")),
            },
            ConnectUrl::UdpOut { peer } => match resolve(peer).await {
                Some(addr) => {
                    let local = if addr.is_ipv6() {
                        "[::]:0"
                    } else {
                        "0.0.0.0:0"
                    };
                    match UdpSocket::bind(local).await {
                        Ok(s) => {
                            let p = UdpReply::Fixed(addr);
                            run_udp(s, p, &format!("udpout:{peer}"), &tx, &mut rx).await
                        }
                        Err(e) => Err(format!("udpout bind: {e}")),
                    }
                }
                None => Err(format!("udpout: cannot resolve {peer}")),
            },
            ConnectUrl::Serial { path, baud } => {
                match tokio_serial::SerialStream::open(&tokio_serial::new(path.as_str(), *baud)) {
                    Ok(s) => run_stream(s, &format!("serial:{path}:{baud}"), &tx, &mut rx).await,
                    Err(e) => Err(format!("serial open {path}: {e}")),
                }
            }
        };
        let why = match result {
            Ok(()) => return, // the consumer went away
            Err(e) => e,
        };
        if tx.send(Inbound::Disconnected(why)).await.is_err() {
            return;
        }
        // Drop what was queued for the dead connection: stale frames are not replayed.
        while rx.try_recv().is_ok() {}
        tokio::time::sleep(retry).await;
    }
}

async fn resolve(peer: &str) -> Option<SocketAddr> {
    tokio::net::lookup_host(peer).await.ok()?.next()
}

/// Accept a client while discarding frames queued for nobody.
async fn accept_draining(
    l: &TcpListener,
    rx: &mut mpsc::Receiver<Vec<u8>>,
) -> std::io::Result<(TcpStream, SocketAddr)> {
    loop {
        tokio::select! {
            r = l.accept() => return r,
            m = rx.recv() => if m.is_none() { return Err(std::io::Error::other("closed")) },
        }
    }
}

/// Pump a byte stream both ways until it fails. Ok(()) means our side shut down.
async fn run_stream<S>(
    s: S,
    name: &str,
    tx: &mpsc::Sender<Inbound>,
    rx: &mut mpsc::Receiver<Vec<u8>>,
) -> Result<(), String>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin,
{
    if tx.send(Inbound::Connected(name.to_string())).await.is_err() {
        return Ok(());
    }
    let (mut r, mut w) = tokio::io::split(s);
    let mut buf = vec![0u8; 4096];
    loop {
        tokio::select! {
            n = r.read(&mut buf) => match n {
                Ok(0) => return Err(format!("{name}: closed by peer")),
                Ok(n) => if tx.send(Inbound::Bytes(buf[..n].to_vec())).await.is_err() { return Ok(()) },
                Err(e) => return Err(format!("{name}: read: {e}")),
            },
            m = rx.recv() => match m {
                Some(bytes) => if let Err(e) = w.write_all(&bytes).await { return Err(format!("{name}: write: {e}")) },
                None => return Ok(()),
            },
        }
    }
}

/// Where UDP replies go.
enum UdpReply {
    /// udpout: the configured peer; datagrams arrive as plain bytes.
    Fixed(SocketAddr),
    /// udpin: the address the fly loop learned from the autopilot's frames (none yet: drop).
    Learned(watch::Receiver<Option<SocketAddr>>),
}

/// UDP both ways until the socket fails. Ok(()) means our side shut down.
async fn run_udp(
    s: UdpSocket,
    reply: UdpReply,
    name: &str,
    tx: &mpsc::Sender<Inbound>,
    rx: &mut mpsc::Receiver<Vec<u8>>,
) -> Result<(), String> {
    if tx.send(Inbound::Connected(name.to_string())).await.is_err() {
        return Ok(());
    }
    let mut buf = vec![0u8; 65536];
    loop {
        tokio::select! {
            r = s.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    let bytes = buf[..n].to_vec();
                    let m = match reply {
                        UdpReply::Fixed(_) => Inbound::Bytes(bytes),
                        UdpReply::Learned(_) => Inbound::Datagram(bytes, from),
                    };
                    if tx.send(m).await.is_err() { return Ok(()) }
                }
                // ICMP "port unreachable" from an absent udpout peer surfaces here; keep going.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(format!("{name}: recv: {e}")),
            },
            m = rx.recv() => match m {
                Some(bytes) => {
                    let to = match &reply {
                        UdpReply::Fixed(a) => Some(*a),
                        UdpReply::Learned(w) => *w.borrow(),
                    };
                    // udpin before the autopilot is known: nobody to send to, drop.
                    if let Some(p) = to { let _ = s.send_to(&bytes, p).await; }
                }
                None => return Ok(()),
            },
        }
    }
}

/// The `udpin` reply address, sans IO: taken from the first valid frame of the chosen
/// autopilot, then changed only by another valid frame of that same autopilot (it moved, e.g.
/// a new port after its restart). Datagrams from anyone else never move it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct UdpPeer {
    pub addr: Option<SocketAddr>,
}

impl UdpPeer {
    /// A valid frame arrived from `from`; `autopilot` is its (system, component) when that is
    /// the chosen autopilot's, else None. Returns the link event when the reply address changed.
    pub fn on_frame(&mut self, from: SocketAddr, autopilot: Option<(u8, u8)>) -> Option<String> {
        let (sys, comp) = autopilot?;
        match self.addr.replace(from) {
            None => Some(format!(
                "udpin peer {from} learned from autopilot {sys}/{comp}"
            )),
            Some(old) if old != from => Some(format!(
                "udpin peer changed {old} -> {from} (autopilot {sys}/{comp})"
            )),
            Some(_) => None,
        }
    }
}

/// Connection failures said aloud without flooding, one line each (docs/mavlink.md, "Failures
/// said aloud"): the first failure at once, then at most one failure line per `every`, with how
/// many attempts failed (and how many connections did not last) since the last line. A
/// connection is said when it answers a failure line ("connected ... after N failed attempts")
/// or is the first; a link that connects and drops again within `every` (a flapping link) is
/// only counted, so it costs two lines per `every`, not two per retry. Unlike the record's
/// `link_events`, which keep every attempt.
#[derive(Debug, Clone)]
pub struct FailureLines {
    every: Duration,
    /// When the last failure line was said.
    last_line: Option<Duration>,
    /// Failed attempts since the last connection said.
    failures: u32,
    /// Failed attempts, and connections, since the last failure line and not said.
    unsaid: u32,
    unsaid_connections: u32,
    /// A failure line was said since the last connection line: the next connection answers it.
    failure_said: bool,
    connected_before: bool,
}

impl FailureLines {
    pub fn new(every: Duration) -> Self {
        Self {
            every,
            last_line: None,
            failures: 0,
            unsaid: 0,
            unsaid_connections: 0,
            failure_said: false,
            connected_before: false,
        }
    }

    /// A failed attempt (`why` names the endpoint and the reason); the line to print, if due.
    pub fn failed(&mut self, now: Duration, why: &str, retry: Duration) -> Option<String> {
        self.failures += 1;
        let due = self
            .last_line
            .is_none_or(|t| now.saturating_sub(t) >= self.every);
        if !due {
            self.unsaid += 1;
            return None;
        }
        let more = match (self.unsaid, self.unsaid_connections) {
            (0, 0) => String::new(),
            (n, 0) => format!(" ({n} more failed attempts since the last line)"),
            (n, c) => format!(
                " ({n} more failed attempts and {c} connections that did not last since the last line)"
            ),
        };
        self.last_line = Some(now);
        self.unsaid = 0;
        self.unsaid_connections = 0;
        self.failure_said = true;
        Some(format!(
            "{why}; retrying every {}s{more}",
            retry.as_secs_f64()
        ))
    }

    /// Connected: the line to print (the first connection, or one that answers a failure line
    /// said), else None (counted for the next failure line).
    pub fn connected(&mut self, name: &str) -> Option<String> {
        let first = !std::mem::replace(&mut self.connected_before, true);
        if !first && !self.failure_said {
            self.unsaid_connections += 1;
            return None;
        }
        self.failure_said = false;
        let n = std::mem::take(&mut self.failures);
        Some(match n {
            0 => format!("connected {name}"),
            n => format!("connected {name} after {n} failed attempts"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(s: &str) -> SocketAddr {
        s.parse().unwrap()
    }

    #[test]
    fn udp_peer_is_learned_only_from_the_autopilot() {
        let mut p = UdpPeer::default();
        assert_eq!(p.on_frame(addr("10.0.0.9:1234"), None), None);
        assert_eq!(p.addr, None, "a frame from anyone else teaches nothing");
        let ev = p.on_frame(addr("127.0.0.1:14555"), Some((1, 1))).unwrap();
        assert!(
            ev.contains("learned") && ev.contains("127.0.0.1:14555"),
            "{ev}"
        );
        assert_eq!(p.on_frame(addr("127.0.0.1:14555"), Some((1, 1))), None);
        assert_eq!(p.on_frame(addr("10.0.0.9:1234"), None), None);
        assert_eq!(p.addr, Some(addr("127.0.0.1:14555")));
        let ev = p.on_frame(addr("127.0.0.1:14600"), Some((1, 1))).unwrap();
        assert!(
            ev.contains("changed 127.0.0.1:14555 -> 127.0.0.1:14600"),
            "{ev}"
        );
    }

    fn secs(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    #[test]
    fn failure_lines_are_rate_limited_and_counted() {
        let mut f = FailureLines::new(secs(10.0));
        let retry = secs(1.0);
        let first = f
            .failed(secs(0.0), "tcp connect 127.0.0.1:1: refused", retry)
            .unwrap();
        assert!(
            first.contains("127.0.0.1:1") && first.contains("retrying"),
            "{first}"
        );
        for t in 1..10 {
            assert_eq!(f.failed(secs(t as f64), "again", retry), None);
        }
        let later = f.failed(secs(10.0), "again", retry).unwrap();
        assert!(later.contains("9 more failed attempts"), "{later}");
        assert_eq!(
            f.connected("tcp:127.0.0.1:1").as_deref(),
            Some("connected tcp:127.0.0.1:1 after 11 failed attempts")
        );
        assert!(
            f.failed(secs(25.0), "lost", retry).is_some(),
            "a new outage after a quiet spell is said at once"
        );
    }

    /// The autopilot's end accepts and drops the connection again and again (or a link was
    /// there, then every retry is refused): at most one failure line, and the connection that
    /// answers it, per 10 s, whatever the retries do in between.
    #[test]
    fn a_flapping_link_says_at_most_one_failure_per_interval() {
        let mut f = FailureLines::new(secs(10.0));
        let retry = secs(1.0);
        let mut lines = Vec::new();
        lines.extend(f.connected("tcp:127.0.0.1:5760"));
        for t in 0..60 {
            let t = 1.0 + t as f64;
            lines.extend(f.failed(secs(t), "tcp:127.0.0.1:5760: closed by peer", retry));
            lines.extend(f.connected("tcp:127.0.0.1:5760"));
        }
        let failures = lines
            .iter()
            .filter(|l| l.contains("closed by peer"))
            .count();
        assert_eq!(
            failures, 6,
            "one failure line per 10 s over 60 s: {lines:#?}"
        );
        assert_eq!(lines.len(), 1 + 2 * 6, "{lines:#?}");
        assert!(
            lines[3].contains("9 more failed attempts and 9 connections that did not last"),
            "{lines:#?}"
        );
        // Refused every second after the link existed: each failure once, one line per 10 s.
        let mut g = FailureLines::new(secs(10.0));
        assert!(g.connected("tcp:127.0.0.1:5760").is_some());
        let said: Vec<String> = (0..30)
            .filter_map(|t| g.failed(secs(t as f64), "tcp connect: Connection refused", retry))
            .collect();
        assert_eq!(said.len(), 3, "{said:#?}");
    }
}
