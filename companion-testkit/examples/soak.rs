//! Soak run: a simulated hour of 50 Hz telemetry through the full `fly` cycle, with
//! memory measured after warm-up, every simulated 5 minutes and at the end.
//!
//! The simulated world (`companion::sim`, params/world.toml, a scenario) is the truth; every
//! 20 ms one telemetry frame of it ([`companion_testkit::sim_link::Telemetry50`]) is encoded with the
//! link's `Encoder`, the bytes are delivered every 100 ms (5 frames, 200-600 bytes: a UDP/serial
//! read) to `Ingest`, and the frames go through `Vehicle::on_frame` exactly as `fly` does. The
//! fly shell's timers are replayed on the simulated clock: the 10 Hz protocol tick, the 1 Hz
//! heartbeat, a decision cycle every `decision_period_s` (params/link.toml) and one after any
//! significant event, each through `fly::decide` / `fly::finish_record` (the real `Core::step` behind `companion::decider::CoreDecider`),
//! the record serialised to JSON as the decision log would. What the companion sends is encoded,
//! decoded by a second `Ingest` and answered by a minimal autopilot (commands acked, missions
//! accepted). The world advances every `step_s` under the latest plan (plus any landing commanded
//! during the step). Each mission is one fresh `fly` session (core, vehicle, ingest, mission
//! state new; clock from zero; battery swapped): the PANORAMA guarantee rightly refuses one
//! hour-long mission on the 74 Wh pack. After landing and one step on the ground, the next
//! mission starts on the next seed; the loaded params model and the process live on.
//!
//! Memory: live heap bytes from a counting global allocator (all threads) and VmRSS from
//! /proc/self/status. Exits 1 when live heap at the end exceeds the post-warm-up sample by more
//! than the tolerance (default 16 KiB: a leak of one byte per frame would add 176 KiB, of 8 bytes
//! per decision cycle at least 28 KiB). Not in CI; `scripts/soak.sh` runs it in release.
//!
//! Run: `cargo run --release -p companion --example soak -- [--minutes 60] [--scenario NAME]
//! [--seed N] [--tolerance-kib 16] [--params DIR]`.

use companion::decider::CoreDecider;
use companion::fly::{self, FlyArgs, FlySetup, JsonLines, RecordSink, Shell};
use companion::sim::{Scenario, World, WorldSpec};
use companion_core::decision::{Model, ModelKind};
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};
use companion_link::Msg;
use companion_link::ingest::{Encoder, Ingest};
use companion_link::vehicle::Vehicle;
use companion_testkit::sim_link::{AUTOPILOT, Responder, Telemetry50, VehicleView};
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
        params: companion::params::default_params_dir(),
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
        energy_consumed_j: 0.0,
    };
    match phase {
        _ if landed => VehicleView {
            armed: false,
            altitude_m: 0.0,
            mission_seq: last_seq,
            custom_mode: 9,
            groundspeed_mps: 0.0,
            energy_consumed_j: 0.0,
        },
        "base" => VehicleView {
            armed: false,
            altitude_m: 0.0,
            mission_seq: 0,
            custom_mode: 4,
            groundspeed_mps: 0.0,
            energy_consumed_j: 0.0,
        },
        "wp1" => air(wp1_seq, 3, 5.0),
        "wpi" => air((wp1_seq + 1).min(last_seq), 3, 5.0),
        "landing" => air(last_seq, 9, 0.5),
        _ => air(last_seq, 4, 0.3), // wpf, target, v0..v5: at the tracking area
    }
}

/// Everything one `companion fly` run owns: a new one per mission (the clock restarts at zero,
/// the autopilot's battery is swapped), while the loaded params model and the process live on.
struct Session<'m> {
    start: Duration,
    decider: CoreDecider,
    vehicle: Vehicle,
    shell: Shell,
    ingest: Ingest,
    out_enc: Encoder,
    ap_in: Ingest,
    enc_ap: Encoder,
    enc_mon: Encoder,
    responder: Responder,
    telem: Telemetry50,
    world: World<'m>,
    world_obs: Observations,
    next_step: Duration,
    landed_until: Option<Duration>,
    last: Option<(Plan, DecisionRecord)>,
    landing_cmd: Option<companion_core::action_id::ActionId>,
    period: Duration,
    next_tick: Duration,
    next_hb: Duration,
    next_cycle: Duration,
    replies: Vec<Msg>,
    chunk: Vec<u8>,
}

impl<'m> Session<'m> {
    fn new(
        model: &std::sync::Arc<Model>,
        setup: &FlySetup,
        spec: &'m WorldSpec,
        scenario: &'m Scenario,
        seed: u64,
        start: Duration,
    ) -> Self {
        let mut world = World::new(spec, scenario, seed);
        let world_obs = world.observe();
        let period = Duration::from_secs_f64(setup.link.decision_period_s);
        Self {
            start,
            decider: CoreDecider::new(
                std::sync::Arc::clone(model),
                ModelKind::Bfm,
                model.policy("safety").unwrap(),
                None,
            ),
            vehicle: setup.vehicle(Duration::from_secs(3)),
            shell: Shell::new(setup),
            ingest: Ingest::new(None),
            out_enc: Encoder::new(None),
            ap_in: Ingest::new(None),
            enc_ap: Encoder::new(None),
            enc_mon: Encoder::new(None),
            responder: Responder::default(),
            telem: Telemetry50::new(),
            world,
            world_obs,
            next_step: Duration::from_secs_f64(spec.step_s),
            landed_until: None,
            last: None,
            landing_cmd: None,
            period,
            next_tick: Duration::ZERO,
            next_hb: Duration::ZERO,
            next_cycle: period,
            replies: Vec::new(),
            chunk: Vec::with_capacity(2048),
        }
    }

    /// The companion's sends: encoded, decoded by the autopilot, answered on the next read.
    fn send(&mut self, msgs: &[Msg]) {
        self.out_enc.system_id = self.vehicle.our_system();
        for m in msgs {
            let bytes = self.out_enc.encode(m);
            for f in self.ap_in.push(&bytes) {
                self.replies.extend(self.responder.respond(&f.msg));
            }
        }
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
    let files = companion::params::read_params_dir(&o.params)?;
    let model = std::sync::Arc::new(Model::load(&files)?);
    let mut args = FlyArgs::from_cli(["--connect", "udpin:0.0.0.0:14550", "--auto-start"])?;
    args.params = Some(o.params.clone());
    let setup = FlySetup::load(&args)?;
    let spec = WorldSpec::load(&files)?;
    let scenario = Scenario::load(&files, &o.scenario)?;
    let first = if setup.route.takeoff_first { 2 } else { 1 };
    let (wp1_seq, last_seq) = (first, setup.route.waypoints.len() as u16 + first - 1);
    let step = Duration::from_secs_f64(spec.step_s);
    let frame_dt = Duration::from_millis(20);
    let total_frames = o.minutes * 60 * 50;

    let mut sink = JsonLines(std::io::sink());
    let mut seed = o.seed;
    let mut session = Session::new(&model, &setup, &spec, &scenario, seed, Duration::ZERO);
    let (mut cycles, mut missions, mut frames_ok) = (0u64, 1u32, 0u64);
    let (mut acked, mut accepted, mut unframed) = (0u64, 0u64, 0u64);
    let mut samples: Vec<Sample> = Vec::new();
    let sample_every = 5 * 60 * 50;
    let trace = std::env::var_os("SOAK_TRACE").is_some();
    // Which mission states the fly shell saw and which vehicle actions the core chose (shows
    // the run went through the mission, not just sat at base).
    let mut states: std::collections::BTreeMap<String, u64> = Default::default();
    let mut actions: std::collections::BTreeMap<String, u64> = Default::default();

    for i in 0..total_frames {
        let tg = frame_dt * i as u32;
        // Mission over (landed, disarmed, one step on the ground): the next `fly` session.
        if session.landed_until.is_some_and(|end| tg >= end) {
            frames_ok += session.ingest.stats.frames_ok;
            unframed += session.ingest.stats.bytes_unframed();
            acked += session.responder.commands_acked;
            accepted += session.responder.missions_accepted;
            seed += 1;
            missions += 1;
            session = Session::new(&model, &setup, &spec, &scenario, seed, tg);
        }
        let s = &mut session;
        // Session clock: each `fly` run starts at zero, as the real one does.
        let t = tg - s.start;
        if t >= s.next_step {
            s.next_step += step;
            if s.landed_until.is_none() {
                if s.world.finished() {
                    s.landed_until = Some(tg + step);
                } else {
                    // The latest plan, plus a landing any cycle of this step commanded (the
                    // records after it propose nothing: the vehicle is already landing).
                    if let Some((plan, rec)) = &mut s.last {
                        if let Some(l) = s.landing_cmd.take()
                            && !rec.actions.contains(l)
                        {
                            rec.actions.push(l);
                        }
                        s.world.advance(plan, rec);
                    }
                    if !s.world.finished() {
                        s.world_obs = s.world.observe();
                    }
                }
            }
        }
        let mut v = view(
            &s.world_obs.state,
            wp1_seq,
            last_seq,
            s.landed_until.is_some(),
        );
        let battery = s.world_obs.get("battery_pct").unwrap_or(100.0);
        v.energy_consumed_j = (100.0 - battery) / 100.0 * spec.vehicle.battery_wh * 3600.0;
        if trace && i % 500 == 0 {
            eprintln!(
                "t={:.0}s mission={missions} world={} finished={} landed={} last_actions={:?}",
                tg.as_secs_f64(),
                s.world_obs.state,
                s.world.finished(),
                s.landed_until.is_some(),
                s.last.as_ref().map(|l| &l.1.actions)
            );
        }
        let ((sys, comp), msg) = s.telem.frame(&s.world_obs, &v);
        let enc = if (sys, comp) == AUTOPILOT {
            &mut s.enc_ap
        } else {
            &mut s.enc_mon
        };
        enc.system_id = sys;
        enc.component_id = comp;
        s.chunk.extend_from_slice(&enc.encode(&msg));
        for r in s.replies.drain(..) {
            s.enc_ap.system_id = AUTOPILOT.0;
            s.enc_ap.component_id = AUTOPILOT.1;
            s.chunk.extend_from_slice(&s.enc_ap.encode(&r));
        }

        let mut out: Vec<Msg> = Vec::new();
        if i % 5 == 4 {
            // One read every 100 ms.
            for f in s.ingest.push(&s.chunk) {
                out.extend(s.vehicle.on_frame(t, &f));
            }
            s.chunk.clear();
            s.ingest.set_our_system(s.vehicle.our_system());
            s.shell.set_ingest(s.ingest.stats);
        }
        if t >= s.next_hb {
            s.next_hb += Duration::from_secs(1);
            out.push(Vehicle::heartbeat());
        }
        if t >= s.next_tick {
            s.next_tick += Duration::from_millis(100);
            out.extend(s.vehicle.tick(t));
        }
        let periodic = t >= s.next_cycle;
        if periodic {
            s.next_cycle += s.period;
        }
        s.send(&out);
        s.vehicle.stamp_latency(t, t);
        let mut run = periodic && s.vehicle.target().is_some();
        for _ in 0..2 {
            if run {
                let d = fly::decide(&mut s.decider, &mut s.shell, &mut s.vehicle, || t);
                s.send(&d.msgs);
                s.vehicle.stamp_latency(t, t);
                cycles += 1;
                let plan = d.plan.clone();
                let rec =
                    fly::finish_record(d, &mut s.shell, &mut s.vehicle, cycles, &mut Vec::new());
                let _ = sink.write(&rec);
                *states.entry(rec.state.clone()).or_default() += 1;
                for &a in &plan.vehicle_actions {
                    *actions
                        .entry(model.actions.name(a).to_string())
                        .or_default() += 1;
                }
                let ends = |&a: &companion_core::action_id::ActionId| {
                    model.states.actions().ends_flight(rec.actions.name(a))
                };
                if let Some(&a) = rec.actions.ids().iter().find(|a| ends(a)) {
                    s.landing_cmd = Some(a);
                }
                s.last = Some((plan, rec));
            }
            // Then one for significant events, as fly does after every message.
            run = s.vehicle.has_events() && s.vehicle.target().is_some();
        }

        let done = i + 1;
        if done % sample_every == 0 || done == total_frames {
            samples.push(Sample {
                minute: done as f64 / 3000.0,
                wall_s: wall0.elapsed().as_secs_f64(),
                frames: frames_ok + s.ingest.stats.frames_ok,
                cycles,
                missions,
                live: LIVE.load(Relaxed),
                allocs: ALLOCS.load(Relaxed),
                rss_kib: rss_kib(),
            });
        }
    }
    frames_ok += session.ingest.stats.frames_ok;
    unframed += session.ingest.stats.bytes_unframed();
    acked += session.responder.commands_acked;
    accepted += session.responder.missions_accepted;
    println!(
        "soak: {} simulated min of 50 Hz telemetry, scenario {}, {missions} missions (seeds {}..{seed}); {frames_ok} frames in, {unframed} unframed bytes, {acked} commands acked, {accepted} mission uploads accepted",
        o.minutes, o.scenario, o.seed,
    );
    println!("cycles by mission state: {states:?}");
    println!("vehicle actions proposed: {actions:?}");
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
