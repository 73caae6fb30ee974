//! Criterion: MAVLink ingest (bytes -> decoded frames) on the same kind of capture as
//! `bench/compare`'s ingest case, generated here in Rust so `cargo bench` needs no Python:
//! 60 s of the simulated autopilot's ~50 Hz telemetry (`companion_testkit::sim_link`), the first 10 s in
//! MAVLink 1, a few bytes of line noise every 300 frames and one corrupted frame every 500, fed to
//! `Ingest::push` (owned frames) and `Ingest::push_each` (borrowed wire bytes) in chunks of
//! 64..1024 bytes.

use companion_core::observations::Observations;
use companion_link::ingest::{Encoder, Ingest};
use companion_testkit::sim_link::{AUTOPILOT, Telemetry50, VehicleView};
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use mavlink::{MavHeader, MavlinkVersion};
use std::hint::black_box;

/// xorshift64: deterministic noise without a dependency.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.next() % (hi - lo + 1)
    }
}

/// (capture bytes, chunk sizes, frames written, frames corrupted).
fn capture(seconds: u64) -> (Vec<u8>, Vec<usize>, usize, usize) {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut tel = Telemetry50::new();
    let mut encs = [Encoder::new(None), Encoder::new(None)];
    let mut v1_seq = 0u8;
    let mut buf = Vec::new();
    let (mut n, mut bad) = (0, 0);
    for i in 0..seconds * 50 {
        let t = i as f64 / 50.0;
        let mut obs = Observations::default();
        obs.set("battery_pct", 100.0 - t / 40.0);
        obs.set("obstacle_m", 12.0 + 10.0 * (t / 13.0).sin());
        obs.set("vibration_mps2", 3.0 + (t / 3.0).sin());
        obs.set("target_detected", ((t / 20.0) as u64 % 2) as f64);
        let v = VehicleView {
            armed: true,
            altitude_m: 20.0,
            mission_seq: 2 + (t / 20.0) as u16,
            custom_mode: 3,
            groundspeed_mps: 5.0,
            energy_consumed_j: t * 200.0,
        };
        let ((sys, comp), msg) = tel.frame(&obs, &v);
        let mut frame =
            if t < 10.0 && (sys, comp) == AUTOPILOT && mavlink::Message::message_id(&msg) < 256 {
                let mut b = Vec::new();
                let h = MavHeader {
                    system_id: sys as u32,
                    component_id: comp,
                    sequence: v1_seq,
                };
                v1_seq = v1_seq.wrapping_add(1);
                mavlink::write_versioned_msg(&mut b, MavlinkVersion::V1, h, &msg).unwrap();
                b
            } else {
                let e = &mut encs[((sys, comp) != AUTOPILOT) as usize];
                e.system_id = sys;
                e.component_id = comp;
                e.encode(&msg)
            };
        n += 1;
        if n % 500 == 0 {
            let hdr = if frame[0] == 0xFD { 10 } else { 6 };
            let i = rng.range(hdr as u64, frame.len() as u64 - 3) as usize;
            frame[i] ^= 1 << rng.range(0, 7);
            bad += 1;
        }
        if n % 300 == 0 {
            for _ in 0..rng.range(1, 40) {
                let b = loop {
                    let b = rng.next() as u8;
                    if b != 0xFD && b != 0xFE {
                        break b;
                    }
                };
                buf.push(b);
            }
        }
        buf.extend_from_slice(&frame);
    }
    let mut sizes = Vec::new();
    let mut left = buf.len();
    while left > 0 {
        let s = (rng.range(64, 1024) as usize).min(left);
        sizes.push(s);
        left -= s;
    }
    (buf, sizes, n, bad)
}

fn bench(c: &mut Criterion) {
    let (buf, sizes, written, corrupted) = capture(60);
    let chunks: Vec<&[u8]> = {
        let mut at = 0;
        sizes
            .iter()
            .map(|&s| {
                at += s;
                &buf[at - s..at]
            })
            .collect()
    };
    // Sanity, not timing: every intact frame comes out.
    let mut ing = Ingest::new(None);
    let got: usize = chunks.iter().map(|c| ing.push(c).len()).sum();
    assert_eq!(got, written - corrupted);
    let mut g = c.benchmark_group("ingest");
    g.throughput(Throughput::Bytes(buf.len() as u64));
    g.bench_function(format!("capture_60s_{written}_frames"), |b| {
        b.iter_batched_ref(
            || Ingest::new(None),
            |ing| {
                let mut n = 0;
                for c in &chunks {
                    n += ing.push(black_box(c)).len();
                }
                n
            },
            BatchSize::SmallInput,
        )
    });
    // The allocation-free path (wire bytes borrowed): what bench/compare times.
    g.bench_function(format!("capture_60s_{written}_frames_push_each"), |b| {
        b.iter_batched_ref(
            || Ingest::new(None),
            |ing| {
                let mut n = 0;
                for c in &chunks {
                    ing.push_each(black_box(c), |f| {
                        n += 1;
                        black_box(f.msg);
                    });
                }
                n
            },
            BatchSize::SmallInput,
        )
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
