//! Byte transports on tokio: TCP (client, reconnecting), TCP server (accepts again after the
//! client leaves), UDP in/out, serial (tokio-serial, reopened after an error). A supervisor task
//! owns the connection and reports bytes and (re)connections; framing is the ingest's job.

use super::url::ConnectUrl;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};
use tokio::sync::mpsc;

/// What the transport reports.
#[derive(Debug)]
pub enum Inbound {
    Connected(String),
    Bytes(Vec<u8>),
    Disconnected(String),
}

/// Handle to a running transport task.
pub struct TransportHandle {
    pub inbound: mpsc::Receiver<Inbound>,
    pub outbound: mpsc::Sender<Vec<u8>>,
    pub task: tokio::task::JoinHandle<()>,
}

/// Start the supervisor for `url`. `retry` is the pause between reconnection attempts.
pub fn spawn(url: ConnectUrl, retry: Duration) -> TransportHandle {
    let (in_tx, in_rx) = mpsc::channel(256);
    let (out_tx, out_rx) = mpsc::channel(256);
    let task = tokio::spawn(supervise(url, retry, in_tx, out_rx));
    TransportHandle {
        inbound: in_rx,
        outbound: out_tx,
        task,
    }
}

async fn supervise(
    url: ConnectUrl,
    retry: Duration,
    tx: mpsc::Sender<Inbound>,
    mut rx: mpsc::Receiver<Vec<u8>>,
) {
    let mut listener: Option<TcpListener> = None;
    loop {
        let result = match &url {
            ConnectUrl::TcpOut { peer } => match TcpStream::connect(peer.as_str()).await {
                Ok(s) => {
                    let _ = s.set_nodelay(true);
                    run_stream(s, &format!("tcp:{peer}"), &tx, &mut rx).await
                }
                Err(e) => Err(format!("tcp connect {peer}: {e}")),
            },
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
                Ok(s) => run_udp(s, None, &format!("udpin:{bind}"), &tx, &mut rx).await,
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
                            run_udp(s, Some(addr), &format!("udpout:{peer}"), &tx, &mut rx).await
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

/// UDP: `peer` fixed (udpout) or learned from the last sender (udpin).
async fn run_udp(
    s: UdpSocket,
    mut peer: Option<SocketAddr>,
    name: &str,
    tx: &mpsc::Sender<Inbound>,
    rx: &mut mpsc::Receiver<Vec<u8>>,
) -> Result<(), String> {
    if tx.send(Inbound::Connected(name.to_string())).await.is_err() {
        return Ok(());
    }
    let learn = peer.is_none();
    let mut buf = vec![0u8; 65536];
    loop {
        tokio::select! {
            r = s.recv_from(&mut buf) => match r {
                Ok((n, from)) => {
                    if learn { peer = Some(from); }
                    if tx.send(Inbound::Bytes(buf[..n].to_vec())).await.is_err() { return Ok(()) }
                }
                // ICMP "port unreachable" from an absent udpout peer surfaces here; keep going.
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                Err(e) => return Err(format!("{name}: recv: {e}")),
            },
            m = rx.recv() => match m {
                // udpin with no sender yet: nobody to send to, drop.
                Some(bytes) => if let Some(p) = peer { let _ = s.send_to(&bytes, p).await; },
                None => return Ok(()),
            },
        }
    }
}
