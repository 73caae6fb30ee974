//! Soak run (issue 8): a simulated hour of 50 Hz telemetry through the full `fly` cycle, with
//! memory measured after warm-up, every simulated 5 minutes and at the end.
//!
//! The simulated world (`companion::sim`, params/world.toml, a scenario) is the truth; every
//! 20 ms one telemetry frame of it ([`companion::sim_link::Telemetry50`]) is encoded with the
//! link's `Encoder`, the bytes are delivered every 100 ms (5 frames, 200-600 bytes: a UDP/serial
//! read) to `Ingest`, and the frames go through `Vehicle::on_frame` exactly as `fly` does. The
//! fly shell's timers are replayed on the simulated clock: the 10 Hz protocol tick, the 1 Hz
//! heartbeat, a decision cycle every `decision_period_s` (params/link.toml) and one after any
//! significant event, each through `fly::decide` / `fly::finish_record` (the real `Core::step`),
//! the record serialised to JSON as the decision log would. What the companion sends is encoded,
//! decoded by a second `Ingest` and answered by a minimal autopilot (commands acked, missions
//! accepted). The world advances every `step_s` under the latest plan; when its mission ends the
//! vehicle lands and disarms, and the next mission (next seed) starts with a fresh mission state
//! (the core, vehicle and ingest live on, as in one long `fly` session).
//!
//! Memory: live heap bytes from a counting global allocator (all threads) and VmRSS from
//! /proc/self/status. Exits 1 when live heap at the end exceeds the post-warm-up sample by more
//! than the tolerance (default 16 KiB: a leak of one byte per frame would add 176 KiB, of 8 bytes
//! per decision cycle at least 28 KiB). Not in CI; `scripts/soak.sh` runs it in release.
//!
//! Run: `cargo run --release -p companion --example soak -- [--minutes 60] [--scenario NAME]
//! [--seed N] [--tolerance-kib 16] [--params DIR]`.

use companion::decision::{Core, Model, ModelKind, Policy};
use companion::link::fly::{self, Decider, FlyArgs, FlySetup, JsonLines, RecordSink, Shell};
use companion::link::ingest::{Encoder, Ingest};
use companion::link::vehicle::Vehicle;
use companion::link::{Msg, url};
use companion::observations::Observations;
use companion::record::{DecisionRecord, Plan};
use companion::sim::{Scenario, World, WorldSpec};
use companion::sim_link::{AUTOPILOT, Responder, Telemetry50, VehicleView};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicI64, AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

/// Live heap bytes and allocation count, all threads.
struct Counting;
static LIVE: AtomicI64 = AtomicI64::new(0);
static ALLOCS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            LIVE.fetch_add(l.size() as i64, Relaxed);
            ALLOCS.fetch_add(1, Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        LIVE.fetch_sub(l.size() as i64, Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            LIVE.fetch_add(new as i64 - l.size() as i64, Relaxed);
            ALLOCS.fetch_add(1, Relaxed);
        }
        q
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

struct CoreDecider<'m>(Core<'m>);

impl Decider for CoreDecider<'_> {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        self.0.step(obs)
    }
}

struct Opts {
    minutes: u64,
    scenario: String,
    seed: u64,
    tolerance_kib: i64,
    params: std::path::PathBuf,
}

fn opts() -> anyhow::Result<Opts> {
    let mut o = Opts {
        minutes: 60,
        scenario: "complete-1".into(),
        seed: 1,
        tolerance_kib: 16,
        params: companion::spec::default_params_dir(),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{a}: missing value"))
        };
        match a.as_str() {
            "--minutes" => o.minutes = val()?.parse()?,
            "--scenario" => o.scenario = val()?.clone(),
            "--seed" => o.seed = val()?.parse()?,
            "--tolerance-kib" => o.tolerance_kib = val()?.parse()?,
            "--params" => o.params = val()?.into(),
            other => anyhow::bail!("unknown argument {other}"),
        }
    }
    anyhow::ensure!(o.minutes >= 10, "--minutes: at least 10 (5 of warm-up)");
    Ok(o)
}

/// What the autopilot reports for the world's mission phase (the world knows phases, not
/// altitudes or modes). Sequence numbers follow the route file: take-off item first.
fn view(phase: &str, wp1_seq: u16, last_seq: u16, landed: bool) -> VehicleView {
    let air = |seq, mode, spd| VehicleView {
        armed: true,
        altitude_m: 20.0,
        mission_seq: seq,
        custom_mode: mode,
        groundspeed_mps: spd,
    };
    match phase {
        _ if landed => VehicleView {
            armed: false,
            altitude_m: 0.0,
            mission_seq: last_seq,
            custom_mode: 9,
            groundspeed_mps: 0.0,
        },
        "base" => VehicleView {
            armed: false,
            altitude_m: 0.0,
            mission_seq: 0,
            custom_mode: 4,
            groundspeed_mps: 0.0,
        },
        "wp1" => air(wp1_seq, 3, 5.0),
        "wpi" => air((wp1_seq + 1).min(last_seq), 3, 5.0),
        "landing" => air(last_seq, 9, 0.5),
        _ => air(last_seq, 4, 0.3), // wpf, target, v0..v5: at the tracking area
    }
}

struct Sample {
    minute: f64,
    wall_s: f64,
    frames: u64,
    cycles: u64,
    missions: u32,
    live: i64,
    allocs: u64,
    rss_kib: Option<u64>,
}

fn main() -> anyhow::Result<()> {
    let o = opts()?;
    let wall0 = Instant::now();
    let model = Model::load(&o.params)?;
    let mut decider = CoreDecider(Core::new(&model, ModelKind::Bfm, Policy::Safety));
    let args = FlyArgs {
        connect: url::parse("udpin:0.0.0.0:14550").map_err(anyhow::Error::msg)?,
        mission: None,
        policy: "safety".into(),
        signing_key: None,
        onboard: None,
        link_timeout: Duration::from_secs(3),
        params: Some(o.params.clone()),
        duration: None,
        log_dir: "runs".into(),
    };
    let setup = FlySetup::load(&args)?;
    let spec = WorldSpec::load(&o.params)?;
    let scenario = Scenario::load(&o.params, &o.scenario)?;
    let first = if setup.route.takeoff_first { 2 } else { 1 };
    let (wp1_seq, last_seq) = (first, setup.route.waypoints.len() as u16 + first - 1);

    let period = Duration::from_secs_f64(setup.link.decision_period_s);
    let step = Duration::from_secs_f64(spec.step_s);
    let frame_dt = Duration::from_millis(20);
    let total_frames = o.minutes * 60 * 50;

    let mut vehicle: Vehicle = setup.vehicle(args.link_timeout);
    let mut shell = Shell::new(&setup);
    let mut ingest = Ingest::new(None);
    let mut out_enc = Encoder::new(None);
    let mut ap_in = Ingest::new(None);
    let (mut enc_ap, mut enc_mon) = (Encoder::new(None), Encoder::new(None));
    let mut responder = Responder::default();
    let mut sink = JsonLines(std::io::sink());
    let mut telem = Telemetry50::new();

    let mut seed = o.seed;
    let mut world = World::new(&spec, &scenario, seed);
    let mut world_obs = world.observe();
    let mut next_step = step;
    let mut landed_until: Option<Duration> = None;
    let mut last: Option<(Plan, DecisionRecord)> = None;
    let (mut next_tick, mut next_hb, mut next_cycle) = (Duration::ZERO, Duration::ZERO, period);
    let mut replies: Vec<Msg> = Vec::new();
    let mut chunk: Vec<u8> = Vec::with_capacity(2048);
    let (mut cycles, mut missions, mut frames_ok) = (0u64, 1u32, 0u64);
    let mut samples: Vec<Sample> = Vec::new();
    let sample_every = 5 * 60 * 50;

    // The companion's sends: encoded, decoded by the autopilot, answered on the next delivery.
    let mut send = |msgs: &[Msg], vehicle: &Vehicle, replies: &mut Vec<Msg>| {
        out_enc.system_id = vehicle.our_system();
        for m in msgs {
            let bytes = out_enc.encode(m);
            for f in ap_in.push(&bytes) {
                replies.extend(responder.respond(&f.msg));
            }
        }
    };

    for i in 0..total_frames {
        let t = frame_dt * i as u32;
        // The world: one step per step_s under the latest plan; a landing after its mission.
        if t >= next_step {
            next_step += step;
            match landed_until {
                Some(end) if t >= end => {
                    seed += 1;
                    missions += 1;
                    world = World::new(&spec, &scenario, seed);
                    world_obs = world.observe();
                    shell = Shell::new(&setup);
                    landed_until = None;
                }
                Some(_) => {}
                None if world.finished() => landed_until = Some(t + step),
                None => {
                    if let Some((plan, rec)) = &last {
                        world.advance(plan, rec);
                    }
                    if !world.finished() {
                        world_obs = world.observe();
                    }
                }
            }
        }
        let v = view(&world_obs.state, wp1_seq, last_seq, landed_until.is_some());
        let ((sys, comp), msg) = telem.frame(&world_obs, &v);
        let enc = if (sys, comp) == AUTOPILOT {
            &mut enc_ap
        } else {
            &mut enc_mon
        };
        enc.system_id = sys;
        enc.component_id = comp;
        chunk.extend_from_slice(&enc.encode(&msg));
        for r in replies.drain(..) {
            enc_ap.system_id = AUTOPILOT.0;
            enc_ap.component_id = AUTOPILOT.1;
            chunk.extend_from_slice(&enc_ap.encode(&r));
        }

        let mut out: Vec<Msg> = Vec::new();
        if i % 5 == 4 {
            // One read every 100 ms.
            for f in ingest.push(&chunk) {
                frames_ok += 1;
                out.extend(vehicle.on_frame(t, &f));
            }
            chunk.clear();
            ingest.set_our_system(vehicle.our_system());
            shell.set_ingest(ingest.stats);
        }
        if t >= next_hb {
            next_hb += Duration::from_secs(1);
            out.push(Vehicle::heartbeat());
        }
        if t >= next_tick {
            next_tick += Duration::from_millis(100);
            out.extend(vehicle.tick(t));
        }
        let periodic = t >= next_cycle;
        if periodic {
            next_cycle += period;
        }
        send(&out, &vehicle, &mut replies);
        vehicle.stamp_latency(t, t);
        let mut run_cycle = |vehicle: &mut Vehicle, shell: &mut Shell, replies: &mut Vec<Msg>| {
            let d = fly::decide(&mut decider, shell, vehicle, || t);
            send(&d.msgs, vehicle, replies);
            vehicle.stamp_latency(t, t);
            cycles += 1;
            let plan = d.plan.clone();
            let rec = fly::finish_record(d, shell, vehicle, cycles, &mut Vec::new());
            let _ = sink.write(&rec);
            last = Some((plan, rec));
        };
        if periodic && vehicle.target.is_some() {
            run_cycle(&mut vehicle, &mut shell, &mut replies);
        }
        if vehicle.has_events() && vehicle.target.is_some() {
            run_cycle(&mut vehicle, &mut shell, &mut replies);
        }

        let done = i + 1;
        if done % sample_every == 0 || done == total_frames {
            samples.push(Sample {
                minute: done as f64 / 3000.0,
                wall_s: wall0.elapsed().as_secs_f64(),
                frames: frames_ok,
                cycles,
                missions,
                live: LIVE.load(Relaxed),
                allocs: ALLOCS.load(Relaxed),
                rss_kib: rss_kib(),
            });
        }
    }

    println!(
        "soak: {} simulated min of 50 Hz telemetry, scenario {}, seeds {}..{}; {} frames in, {} unframed bytes, {} commands acked, {} missions accepted",
        o.minutes,
        o.scenario,
        o.seed,
        seed,
        ingest.stats.frames_ok,
        ingest.stats.bytes_unframed(),
        responder.commands_acked,
        responder.missions_accepted
    );
    println!(
        "| sim min | wall s | frames | cycles | missions | live heap (bytes) | vs 5 min | allocations | VmRSS (KiB) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let base = samples[0].live;
    for s in &samples {
        println!(
            "| {:.0} | {:.1} | {} | {} | {} | {} | {:+} | {} | {} |",
            s.minute,
            s.wall_s,
            s.frames,
            s.cycles,
            s.missions,
            s.live,
            s.live - base,
            s.allocs,
            s.rss_kib.map_or("?".into(), |r| r.to_string())
        );
    }
    let end = samples.last().map_or(base, |s| s.live);
    let growth = end - base;
    let tol = o.tolerance_kib * 1024;
    println!(
        "live heap growth after warm-up: {growth:+} bytes (tolerance {tol} bytes): {}; wall time {:.1} s",
        if growth <= tol { "ok" } else { "GROWTH" },
        wall0.elapsed().as_secs_f64()
    );
    if growth > tol {
        std::process::exit(1);
    }
    Ok(())
}
