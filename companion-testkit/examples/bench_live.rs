//! The decision cycle with and without a stalled live viewer, side by side in one run (issue 37:
//! "the cycle never waits for a viewer"; docs/performance.md).
//!
//! Per cycle, timed: the core's step (`Core::step_into`) and the record written to the decision
//! log (`LogSink`, its writer thread, a real run folder in a temporary directory), as `fly`
//! does. `no_live`: the log alone. `stalled_viewer`: the same through `fly --live`'s
//! `LiveSink` with a viewer on the live server (loopback) that subscribed to every channel and
//! never reads, so its queue is full and every record drops its oldest. The two cases alternate
//! in blocks of 100 cycles (the machine's drift hits both); each gets `cycles` cycles.
//!
//! Prints `{"cases":[{"name","median_us","p99_us","cycles"}],"ratio_of_medians","live_dropped"}`.
//!
//! Run: `cargo run --release -p companion-testkit --example bench_live -- 4000`
use companion::fly::{LogSink, RecordSink};
use companion::live::{LiveArgs, LiveSink};
use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Plan};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
use serde_json::json;
use std::hint::black_box;
use std::time::Instant;
use tokio_tungstenite::tungstenite;

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn log_sink(dir: &std::path::Path) -> LogSink {
    let header = companion::decision_log::Header::new("bench_live", std::time::SystemTime::now());
    let log = companion::decision_log::start_run(
        dir,
        std::time::SystemTime::now(),
        header,
        Default::default(),
    )
    .expect("a run folder in the temporary directory");
    LogSink(log)
}

/// A viewer that subscribes to every channel and never reads again.
fn stalled_viewer(addr: std::net::SocketAddr) -> tungstenite::WebSocket<std::net::TcpStream> {
    use tungstenite::client::IntoClientRequest;
    let stream = std::net::TcpStream::connect(addr).expect("connect to the live server");
    let mut req = format!("ws://{addr}").into_client_request().unwrap();
    req.headers_mut().insert(
        "sec-websocket-protocol",
        "foxglove.websocket.v1".parse().unwrap(),
    );
    let (mut ws, _) = tungstenite::client(req, stream).expect("WebSocket handshake");
    let subs: Vec<_> = (1..=10).map(|c| json!({"id": c, "channelId": c})).collect();
    ws.send(tungstenite::Message::text(
        json!({"op": "subscribe", "subscriptions": subs}).to_string(),
    ))
    .unwrap();
    ws
}

fn main() {
    let cycles: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("cycles: a number"))
        .unwrap_or(4000);
    let params = default_params_dir();
    let model = std::sync::Arc::new(companion::params::load_model(&params).expect("params load"));
    let base = tracking_snapshot(&model, &params, "complete-1");
    let stream_gen = StreamGen::new(&model, base.clone(), Stream::Changing);
    let mut core = Core::new(
        std::sync::Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    let mut obs = base.clone();
    let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
    for k in 0..100 {
        stream_gen.advance(&mut obs, k);
        core.step_into(&obs, &mut plan, &mut rec);
    }
    let tmp = tempfile::tempdir().unwrap();
    let args = LiveArgs {
        live: Some("127.0.0.1:0".parse().unwrap()),
        live_queue: companion::live::DEFAULT_QUEUE,
    };
    let server = companion::live::start(&args, 0).unwrap().unwrap();
    let _viewer = stalled_viewer(server.addr);
    let mut plain = LiveSink::new(log_sink(&tmp.path().join("plain")), None);
    let mut live = LiveSink::new(log_sink(&tmp.path().join("live")), Some(server.hub()));
    let (mut t_plain, mut t_live) = (Vec::with_capacity(cycles), Vec::with_capacity(cycles));
    let mut k = 100;
    while t_plain.len() < cycles {
        for (sink, times) in [
            (&mut plain as &mut dyn RecordSink, &mut t_plain),
            (&mut live as &mut dyn RecordSink, &mut t_live),
        ] {
            for _ in 0..100 {
                stream_gen.advance(&mut obs, k);
                k += 1;
                let t0 = Instant::now();
                core.step_into(black_box(&obs), &mut plan, &mut rec);
                sink.write(&rec).unwrap();
                times.push(t0.elapsed().as_secs_f64() * 1e6);
            }
        }
    }
    let dropped = server.hub().dropped();
    let mut cases = Vec::new();
    let mut medians = Vec::new();
    for (name, mut t) in [("no_live", t_plain), ("stalled_viewer", t_live)] {
        t.sort_by(f64::total_cmp);
        medians.push(percentile(&t, 0.5));
        cases.push(json!({"name": name, "median_us": percentile(&t, 0.5), "p99_us": percentile(&t, 0.99), "cycles": t.len()}));
    }
    plain.inner.0.close();
    live.inner.0.close();
    assert!(dropped > 0, "the viewer never stalled: nothing was dropped");
    println!(
        "{}",
        json!({"cases": cases, "ratio_of_medians": medians[1] / medians[0], "live_dropped": dropped})
    );
}
