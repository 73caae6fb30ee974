//! Time MAVLink ingest (bytes -> decoded frames) on a capture, for the side-by-side comparison
//! with pymavlink's `parse_buffer` (`bench/compare`).
//!
//! Reads the capture and its chunk sizes written by `bench/make_capture.py`, then per repetition
//! feeds every chunk to a fresh [`Ingest`] (created before the clock starts, as the Python side's
//! parser is) and counts the frames `push` returns. `times_ns` holds one `Instant` measurement
//! per pass over the whole capture. With a third argument, every decoded frame of one pass is
//! written there as a JSON line `{"s":sysid,"c":compid,"id":msgid,"v":1|2,"m":<message>}` for the
//! agreement check (serde form of the mavlink crate's message).
//!
//! Prints `{"frames":N,"stats":{..IngestStats..},"bytes":B,"times_ns":[..]}`.
//! Run: `cargo run --release -p companion --example bench_ingest -- CAPTURE.bin CAPTURE.chunks
//! [DUMP.jsonl|-] [reps] [budget_s]`.
use companion_link::ingest::Ingest;
use mavlink::{MavlinkVersion, Message};
use std::hint::black_box;
use std::io::Write;
use std::time::Instant;

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let usage = "usage: bench_ingest CAPTURE.bin CAPTURE.chunks [DUMP.jsonl|-] [reps] [budget_s]";
    let cap_path = args.get(1).ok_or(usage)?;
    let chunks_path = args.get(2).ok_or(usage)?;
    let bytes = std::fs::read(cap_path).map_err(|e| format!("{cap_path}: {e}"))?;
    let sizes: Vec<usize> = std::fs::read_to_string(chunks_path)
        .map_err(|e| format!("{chunks_path}: {e}"))?
        .split_whitespace()
        .map(|s| s.parse())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{chunks_path}: {e}"))?;
    if sizes.iter().sum::<usize>() != bytes.len() {
        return Err(format!(
            "{chunks_path}: chunk sizes do not add up to {}",
            bytes.len()
        )
        .into());
    }
    let reps: usize = args.get(4).map_or(Ok(1000), |s| s.parse())?;
    let budget: f64 = args.get(5).map_or(Ok(1.0), |s| s.parse())?;
    let mut chunks = Vec::with_capacity(sizes.len());
    let mut at = 0;
    for s in sizes {
        chunks.push(&bytes[at..at + s]);
        at += s;
    }

    // One untimed pass: the frames for the agreement dump and the counters.
    let mut ing = Ingest::new(None);
    let mut frames = 0usize;
    let mut dump = match args.get(3).map(String::as_str) {
        None | Some("-") => None,
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).map_err(|e| format!("{p}: {e}"))?,
        )),
    };
    let mut failed: Option<Box<dyn std::error::Error>> = None;
    for c in &chunks {
        ing.push_each(c, |f| {
            frames += 1;
            if let Some(w) = dump.as_mut() {
                let line = serde_json::json!({
                    "s": f.header.system_id,
                    "c": f.header.component_id,
                    "id": f.msg.message_id(),
                    "v": if f.version == MavlinkVersion::V1 { 1 } else { 2 },
                    "m": f.msg,
                });
                let r = serde_json::to_writer(&mut *w, &line)
                    .map_err(Into::into)
                    .and_then(|()| w.write_all(b"\n").map_err(Into::into));
                if let Err(e) = r {
                    failed.get_or_insert(e);
                }
            }
        });
    }
    if let Some(e) = failed {
        return Err(e);
    }
    if let Some(mut w) = dump {
        w.flush()?;
    }
    let stats = ing.stats;

    let mut times_ns: Vec<u64> = Vec::with_capacity(reps);
    let mut spent = 0.0;
    while times_ns.len() < reps && (times_ns.len() < 3 || spent < budget) {
        let mut ing = Ingest::new(None);
        let t0 = Instant::now();
        let mut n = 0;
        for c in &chunks {
            ing.push_each(black_box(c), |f| {
                n += 1;
                black_box(f.msg);
            });
        }
        let dt = t0.elapsed();
        black_box(n);
        spent += dt.as_secs_f64();
        times_ns.push(dt.as_nanos() as u64);
    }
    println!(
        "{}",
        serde_json::json!({
            "frames": frames,
            "bytes": bytes.len(),
            "stats": stats,
            "times_ns": times_ns,
        })
    );
    Ok(())
}
