//! `companion fly`: the imperative shell around the link protocol and the decision core.
//!
//! Tasks: the transport supervisor(s) (bytes in/out, reconnect), and one loop that owns the
//! protocol state ([`Vehicle`]), the clock, the 1 Hz heartbeat, the 10 Hz protocol tick and the
//! decision cycles: one on every significant event, and one every `decision_period_s` otherwise.
//! Each cycle's record goes to a [`RecordSink`] with the commands it sent (latency measured from
//! the message that triggered the cycle to the command handed to the transport) and the results
//! of earlier commands that finished since.

use super::Msg;
use super::actions::{ActionTable, LinkParams, Route};
use super::ingest::{self, Encoder, Ingest};
use super::liveness::parse_duration;
use super::mission_state::{self, Extra, MissionState};
use super::transport::{self, Inbound};
use super::url::{self, ConnectUrl};
use super::vehicle::{Vehicle, VehicleConfig};
use crate::observations::Observations;
use crate::record::{DecisionRecord, Plan};
use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;

/// The decision core as the shell sees it: one observation snapshot in, one plan and its record out.
pub trait Decider {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord);
}

/// The real core is a decider as it is (fuzzing and the soak drive it without a wrapper).
impl Decider for crate::decision::Core<'_> {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        crate::decision::Core::step(self, obs)
    }
}

/// Where decision records go (the log helper provides the file writer).
pub trait RecordSink {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()>;
}

/// One JSON object per line.
pub struct JsonLines<W: Write>(pub W);

impl<W: Write> RecordSink for JsonLines<W> {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        serde_json::to_writer(&mut self.0, rec)?;
        self.0.write_all(b"\n")?;
        self.0.flush()
    }
}

impl RecordSink for Vec<DecisionRecord> {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        self.push(rec.clone());
        Ok(())
    }
}

fn parse_policy(s: &str) -> Result<String, String> {
    match s {
        "safety" | "mission" => Ok(s.to_string()),
        other => Err(format!("{other:?}: expected safety or mission")),
    }
}

/// `companion fly` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct FlyArgs {
    /// Autopilot connection: serial:/dev/ttyAMA0:921600, udpin:0.0.0.0:14550, udpout:HOST:PORT,
    /// tcp:HOST:PORT, tcpin:ADDR:PORT.
    #[arg(long, value_parser = url::parse)]
    pub connect: ConnectUrl,
    /// Route for follow_trajectory (default params/missions/tracking_route.toml).
    #[arg(long)]
    pub mission: Option<PathBuf>,
    /// Arbitration policy: safety (safety-first) or mission (mission-first).
    #[arg(long, default_value = "safety", value_parser = parse_policy)]
    pub policy: String,
    /// MAVLink 2 signing key (32 raw bytes or 64 hex digits): sign outgoing frames, refuse
    /// unsigned commands addressed to us.
    #[arg(long)]
    pub signing_key: Option<PathBuf>,
    /// Second MAVLink connection carrying onboard monitors (NAMED_VALUE_FLOAT, ...).
    #[arg(long, value_parser = url::parse)]
    pub onboard: Option<ConnectUrl>,
    /// Silence after which the autopilot counts as lost (e.g. 3s, 500ms).
    #[arg(long, default_value = "3s", value_parser = parse_duration)]
    pub link_timeout: Duration,
    /// Params directory (default: $COMPANION_PARAMS or the workspace params/).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Stop after this long (e.g. 60s); default: until the vehicle has flown and is back on the
    /// ground disarmed, or Ctrl-C.
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<Duration>,
    /// Where run folders go (a new `<UTC time>/` inside with decisions.jsonl and flight.tlog,
    /// printed at the start).
    #[arg(long, default_value = crate::decision_log::DEFAULT_RUNS_DIR)]
    pub log_dir: PathBuf,
    /// For SITL and tests only: start the mission (mode, arm, take-off) as soon as the autopilot
    /// is ready, without waiting for the operator.
    #[arg(long)]
    pub auto_start: bool,
}

/// The decision log as a record sink: records go to its writer thread (never blocking the loop).
pub struct LogSink(pub crate::decision_log::DecisionLog);

impl RecordSink for LogSink {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        // A full queue drops the record; the log itself says so with a `loss` line.
        self.0.record(rec.clone());
        Ok(())
    }
}

/// Raw MAVLink traffic to `flight.tlog`: frames sent exactly as encoded, frames received exactly
/// as they arrived (signature included), so the tlog is the wire. Only frames the ingest accepted
/// are logged: garbage, bad signatures and refused unsigned commands are counted, not kept.
pub struct Tlog(pub crate::decision_log::TlogWriter);

impl Tlog {
    fn stamp() -> u64 {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_micros() as u64)
    }
    fn sent(&mut self, bytes: &[u8]) {
        let _ = self.0.write(Self::stamp(), bytes);
    }
    fn received(&mut self, f: &ingest::Frame) {
        let _ = self.0.write(Self::stamp(), &f.raw);
    }
}

/// What the run saw, for tests and the exit message.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FlyReport {
    pub cycles: u64,
    pub ingest: ingest::IngestStats,
    pub frames_out: u64,
    pub link_losses: u32,
}

/// Everything loaded from params before any socket opens.
pub struct FlySetup {
    pub link: LinkParams,
    pub actions: ActionTable,
    pub route: Route,
    pub key: Option<[u8; 32]>,
    /// Altitude the take_off action climbs to (m): MAV_CMD_NAV_TAKEOFF param 7, else the route's.
    pub takeoff_alt_m: f64,
}

impl FlySetup {
    pub fn load(args: &FlyArgs) -> anyhow::Result<Self> {
        let dir = args
            .params
            .clone()
            .unwrap_or_else(crate::spec::default_params_dir);
        // The same loader `check` and `simulate` use (crate::params), so they cannot drift.
        let (link, actions, route, _) =
            crate::params::load_fly_files(&dir, args.mission.as_deref())?;
        let key = match &args.signing_key {
            Some(p) => {
                crate::spec::regular_file(p)
                    .map_err(|reason| anyhow::anyhow!("--signing-key {}: {reason}", p.display()))?;
                Some(ingest::load_signing_key(p)?)
            }
            None => None,
        };
        let takeoff_alt_m = actions
            .actions
            .get("take_off")
            .and_then(|steps| {
                steps.iter().find_map(|st| match st {
                    super::actions::Step::Command { command, params }
                        if *command == super::dialect::MavCmd::MAV_CMD_NAV_TAKEOFF
                            && params[6] > 0.0 =>
                    {
                        Some(params[6] as f64)
                    }
                    _ => None,
                })
            })
            .unwrap_or(route.altitude_m);
        Ok(Self {
            link,
            actions,
            route,
            key,
            takeoff_alt_m,
        })
    }

    /// The protocol state `fly` drives, configured from these params (clones the action table
    /// and route, so a soak run can build a fresh one per mission).
    pub fn vehicle(&self, link_timeout: Duration) -> Vehicle {
        let cfg = VehicleConfig {
            link_timeout,
            streams: self.link.stream_ids(),
            telemetry: self.link.telemetry.clone(),
            arm_wait: Duration::from_secs_f64(self.link.arm_wait_s),
            max_arm_attempts: self.link.max_arm_attempts,
            ..VehicleConfig::default()
        };
        Vehicle::new(cfg, self.actions.clone(), Some(self.route.clone()))
    }
}

/// Blocking entry point for the CLI: a run folder under `--log-dir` with the decision log and
/// `flight.tlog`; the folder is printed first.
pub fn run<D: Decider>(args: FlyArgs, decider: D) -> anyhow::Result<()> {
    use crate::decision_log::{self as dlog, Header, TlogWriter, WriterOptions};
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    let params = args
        .params
        .clone()
        .unwrap_or_else(crate::spec::default_params_dir);
    let now = std::time::SystemTime::now();
    let command: Vec<String> = std::env::args().collect();
    let mut header = Header::new(command.join(" "), now)
        .with_params_dir(&params)
        .with_context(|| format!("reading {} for the log header", params.display()))?;
    header.policy = Some(args.policy.clone());
    let log = dlog::start_run(&args.log_dir, now, header, WriterOptions::default())
        .with_context(|| format!("starting a run folder in {}", args.log_dir.display()))?;
    let dir = log.dir().to_path_buf();
    println!("run folder: {}", dir.display());
    let tlog = TlogWriter::create(&dir.join("flight.tlog"))
        .with_context(|| format!("creating {}", dir.join("flight.tlog").display()))?;
    let mut sink = LogSink(log);
    let result = rt.block_on(run_with_tlog(args, decider, &mut sink, Some(Tlog(tlog))));
    let stats = sink.0.close();
    let report = result?;
    eprintln!(
        "companion fly: {} records {} dropped {}",
        serde_json::to_string(&report).unwrap_or_default(),
        stats.records,
        stats.dropped
    );
    Ok(())
}

/// The fly loop; returns when `duration` elapses, on Ctrl-C, or when the transport task dies.
pub async fn run_with<D: Decider, S: RecordSink>(
    args: FlyArgs,
    decider: D,
    sink: &mut S,
) -> anyhow::Result<FlyReport> {
    run_with_tlog(args, decider, sink, None).await
}

/// [`run_with`], also writing every frame sent and received to `tlog`.
pub async fn run_with_tlog<D: Decider, S: RecordSink>(
    args: FlyArgs,
    mut decider: D,
    sink: &mut S,
    mut tlog: Option<Tlog>,
) -> anyhow::Result<FlyReport> {
    let setup = FlySetup::load(&args)?;
    let mut shell = Shell::new(&setup);
    let mut vehicle = setup.vehicle(args.link_timeout);
    let signing = || setup.key.map(ingest::signing_data);
    let mut ingest = Ingest::new(signing());
    let mut encoder = Encoder::new(signing());
    let mut link = transport::spawn(args.connect.clone(), Duration::from_secs(1));
    // Receive-only, but the handle (and its outbound sender) must live as long as the loop.
    let mut onboard = args
        .onboard
        .clone()
        .map(|u| transport::spawn(u, Duration::from_secs(1)));
    let mut onboard_ingest = Ingest::new(signing());

    let start = Instant::now();
    let now = || start.elapsed();
    let mut heartbeat = tokio::time::interval(Duration::from_secs(1));
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let mut periodic = tokio::time::interval(Duration::from_secs_f64(setup.link.decision_period_s));
    periodic.tick().await; // the first tick is immediate; the first cycle waits for telemetry
    let stop_at = args.duration.map(|d| start + d);
    let mut report = FlyReport::default();
    let mut transport_events: Vec<String> = Vec::new();
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);

    loop {
        let mut out: Vec<Msg> = Vec::new();
        let mut trigger: Option<Duration> = None;
        tokio::select! {
            m = link.inbound.recv() => match m {
                Some(Inbound::Bytes(b)) => {
                    let t = now();
                    for f in ingest.push(&b) {
                        if let Some(w) = tlog.as_mut() {
                            w.received(&f);
                        }
                        out.extend(vehicle.on_frame(t, &f));
                    }
                    ingest.set_our_system(vehicle.our_system());
                    shell.set_ingest(ingest.stats);
                    trigger = Some(t);
                }
                Some(Inbound::Connected(name)) => {
                    ingest.reset();
                    vehicle.on_reconnect(now());
                    transport_events.push(format!("connected {name}"));
                }
                Some(Inbound::Disconnected(why)) => transport_events.push(format!("disconnected: {why}")),
                None => anyhow::bail!("the transport task stopped"),
            },
            m = async { match &mut onboard { Some(h) => h.inbound.recv().await, None => std::future::pending().await } } => match m {
                Some(Inbound::Bytes(b)) => {
                    let t = now();
                    for f in onboard_ingest.push(&b) {
                        if let Some(w) = tlog.as_mut() {
                            w.received(&f);
                        }
                        vehicle.on_monitor_frame(t, &f);
                    }
                    trigger = Some(t);
                }
                Some(Inbound::Connected(name)) => {
                    onboard_ingest.reset();
                    transport_events.push(format!("onboard connected {name}"));
                }
                Some(Inbound::Disconnected(why)) => transport_events.push(format!("onboard disconnected: {why}")),
                None => anyhow::bail!("the onboard transport task stopped"),
            },
            _ = heartbeat.tick() => out.push(Vehicle::heartbeat()),
            _ = tick.tick() => out.extend(vehicle.tick(now())),
            _ = periodic.tick() => {
                if vehicle.target.is_some() {
                    run_cycle_at(&mut decider, &mut shell, &mut vehicle, &mut encoder, &link.outbound, &mut tlog, sink, now(), now, &mut report, &mut transport_events).await?;
                }
            },
            _ = &mut ctrl_c => break,
            _ = async { match stop_at { Some(t) => tokio::time::sleep_until(t).await, None => std::future::pending().await } } => break,
        }
        send(&mut encoder, &vehicle, &link.outbound, &mut tlog, &out).await;
        vehicle.stamp_latency(trigger.unwrap_or_else(now), now());
        // Significant telemetry (a new obstacle, a found target, a crossed battery threshold, a
        // mode change, a command result, link loss) triggers a cycle now.
        // Link loss found by the protocol tick counts too (its trigger is the tick itself).
        if vehicle.has_events() && vehicle.target.is_some() {
            let t = trigger.unwrap_or_else(now);
            run_cycle_at(
                &mut decider,
                &mut shell,
                &mut vehicle,
                &mut encoder,
                &link.outbound,
                &mut tlog,
                sink,
                t,
                now,
                &mut report,
                &mut transport_events,
            )
            .await?;
        }
        // Flew, landed and disarmed: the mission is over (one last cycle recorded it).
        if shell.finished() {
            break;
        }
    }
    report.ingest = ingest.stats;
    report.frames_out = encoder.frames_out;
    report.link_losses = vehicle.liveness.losses;
    Ok(report)
}

async fn send(
    encoder: &mut Encoder,
    vehicle: &Vehicle,
    tx: &tokio::sync::mpsc::Sender<Vec<u8>>,
    tlog: &mut Option<Tlog>,
    msgs: &[Msg],
) {
    encoder.system_id = vehicle.our_system();
    for m in msgs {
        let bytes = encoder.encode(m);
        // A full queue means the transport is stuck or reconnecting: drop rather than block.
        if tx.try_send(bytes.clone()).is_ok()
            && let Some(w) = tlog.as_mut()
        {
            w.sent(&bytes);
        }
    }
}

/// What the shell keeps between cycles besides the protocol state (one per flight).
pub struct Shell {
    mission: MissionState,
    precedence: Vec<String>,
    /// Events of the shell itself (the mission's end) for the next record.
    pending_events: Vec<String>,
    /// Ingest counters now, and as last reported in a record's link_events.
    ingest: ingest::IngestStats,
    ingest_reported: ingest::IngestStats,
}

impl Shell {
    pub fn new(setup: &FlySetup) -> Self {
        Self {
            mission: MissionState::new(&setup.route, setup.takeoff_alt_m),
            precedence: setup.link.vehicle_action_precedence.clone(),
            pending_events: Vec::new(),
            ingest: Default::default(),
            ingest_reported: Default::default(),
        }
    }

    /// The ingest counters now (reported in a record's link_events when bad input grew).
    pub fn set_ingest(&mut self, stats: ingest::IngestStats) {
        self.ingest = stats;
    }

    /// Flew, landed and disarmed: the mission is over.
    pub fn finished(&self) -> bool {
        self.mission.finished()
    }

    /// A link event when bad input arrived since the last report: malformed frames or bad
    /// signatures, or more unframed bytes than one frame still arriving could explain.
    fn ingest_note(&mut self) -> Option<String> {
        let (now, was) = (&self.ingest, &self.ingest_reported);
        let grew = now.frames_malformed > was.frames_malformed
            || now.bad_signatures > was.bad_signatures
            || now.unsigned_commands_refused > was.unsigned_commands_refused
            || now.unsigned_refused > was.unsigned_refused
            || now.bytes_unframed() > was.bytes_unframed() + MAX_FRAME_BYTES;
        if !grew {
            return None;
        }
        self.ingest_reported = *now;
        Some(format!(
            "ingest: {} bytes outside valid frames (garbage or corrupt), {} malformed frames, {} bad signatures, {} unsigned commands refused, {} other unsigned frames refused (since start)",
            now.bytes_unframed(),
            now.frames_malformed,
            now.bad_signatures,
            now.unsigned_commands_refused,
            now.unsigned_refused
        ))
    }
}

/// Longest MAVLink 2 frame (signed): a frame still arriving is at most this many bytes.
const MAX_FRAME_BYTES: u64 = 280;

#[allow(clippy::too_many_arguments)]
async fn run_cycle_at<D: Decider, S: RecordSink>(
    decider: &mut D,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    encoder: &mut Encoder,
    tx: &tokio::sync::mpsc::Sender<Vec<u8>>,
    tlog: &mut Option<Tlog>,
    sink: &mut S,
    trigger_at: Duration,
    now: impl Fn() -> Duration,
    report: &mut FlyReport,
    transport_events: &mut Vec<String>,
) -> anyhow::Result<()> {
    let decided = decide(decider, shell, vehicle, &now);
    send(encoder, vehicle, tx, tlog, &decided.msgs).await;
    vehicle.stamp_latency(trigger_at, now());
    report.cycles += 1;
    let rec = finish_record(decided, shell, vehicle, report.cycles, transport_events);
    sink.write(&rec).context("writing the decision record")?;
    Ok(())
}

/// The first half of one decision cycle, without I/O: the observation snapshot from the
/// vehicle's telemetry and events, the mission state, the core's step, and the commands for
/// the chosen vehicle action. The shell sends `msgs`, stamps latency, then calls
/// [`finish_record`]. Public so that a soak run drives exactly the cycle `fly` runs.
pub fn decide<D: Decider>(
    decider: &mut D,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    now: impl Fn() -> Duration,
) -> Decided {
    let mut events = vehicle.take_events();
    events.append(&mut shell.pending_events);
    let mut obs = vehicle.observations(now(), events.clone());
    let extra = Extra {
        mode: vehicle.telemetry.mode.as_deref(),
    };
    obs.state = shell.mission.update(&obs, &extra).to_string();
    complete_observations(&mut obs, &shell.mission);
    let (plan, mut rec) = decider.step(&obs);
    shell.mission.after_plan(&rec.actions);
    let mut chosen = mission_state::select_vehicle_action(&plan.vehicle_actions, &shell.precedence);
    if let Some(why) = shell.mission.mission_end(&obs) {
        // The mission's end, not the core's decision: recorded as an event with the action.
        rec.events.push(format!("{why}: land"));
        rec.actions.push("land".into());
        shell.mission.after_plan(&["land".to_string()]);
        chosen = Some("land".into());
    }
    if chosen.as_deref() == Some("follow_trajectory")
        && shell.mission.route_on_vehicle()
        && vehicle.actions.actions.contains_key(RESUME)
    {
        chosen = Some(RESUME.into());
    }
    let msgs = vehicle.request_actions(now(), chosen.as_slice());
    Decided {
        msgs,
        chosen,
        plan,
        rec,
        obs,
        events,
    }
}

/// One cycle between [`decide`] and [`finish_record`].
pub struct Decided {
    /// Commands for the chosen vehicle action, to send now.
    pub msgs: Vec<Msg>,
    /// The vehicle action chosen this cycle (after the mission's end and the route's resume).
    pub chosen: Option<String>,
    pub plan: Plan,
    rec: DecisionRecord,
    obs: Observations,
    events: Vec<String>,
}

impl Decided {
    /// The core's record so far (its actions, state, ...).
    pub fn record(&self) -> &DecisionRecord {
        &self.rec
    }
}

/// The second half of one decision cycle: the record with the cycle number, the command
/// results, link events and vehicle telemetry, ready for the decision log.
pub fn finish_record(
    d: Decided,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    cycle: u64,
    transport_events: &mut Vec<String>,
) -> DecisionRecord {
    let Decided {
        mut rec,
        obs,
        events,
        ..
    } = d;
    rec.cycle = cycle;
    rec.time_s = obs.time_s;
    if rec.events.is_empty() {
        rec.events = events;
    }
    if rec.observations.is_empty() {
        rec.observations = obs.values;
    }
    rec.commands.extend(vehicle.take_records());
    rec.link_events.append(transport_events);
    rec.link_events.extend(shell.ingest_note());
    rec.link_events.extend(vehicle.take_link_events());
    rec.vehicle.extend(vehicle.telemetry.vehicle());
    rec.vehicle.insert(
        "link_alive".into(),
        serde_json::Value::from(vehicle.liveness.alive()),
    );
    rec
}

/// params/commands.toml entry flown for `follow_trajectory` once the route is on the vehicle.
const RESUME: &str = "follow_trajectory_resume";

/// Observations the health BNs read under names the telemetry does not produce directly.
fn complete_observations(obs: &mut Observations, mission: &MissionState) {
    if let Some(v) = obs.get("groundspeed_mps") {
        obs.values.entry("drone_speed_mps".into()).or_insert(v);
    }
    let remaining = mission.waypoints_remaining(obs);
    obs.set("waypoints_remaining", remaining);
}

/// A tiny rule-based stand-in for the decision core, for link tests and for flying before the
/// real core is wired in: take off, fly the route, sidestep obstacles, return on low battery,
/// land when the route is done.
pub struct ScriptedDecider {
    pub takeoff_alt_m: f64,
    /// Mission seq of the last waypoint.
    pub last_seq: u16,
    pub low_battery_pct: f64,
    pub policy: String,
    phase: &'static str,
    avoid_until: f64,
}

impl ScriptedDecider {
    pub fn new(takeoff_alt_m: f64, last_seq: u16, policy: &str) -> Self {
        Self {
            takeoff_alt_m,
            last_seq,
            low_battery_pct: 20.0,
            policy: policy.to_string(),
            phase: "base",
            avoid_until: 0.0,
        }
    }

    /// Built from the route the fly arguments name.
    pub fn from_args(args: &FlyArgs) -> anyhow::Result<Self> {
        let setup = FlySetup::load(args)?;
        let last = setup.route.items((0, 0)).len().saturating_sub(1) as u16;
        Ok(Self::new(setup.route.altitude_m, last, &args.policy))
    }
}

impl Decider for ScriptedDecider {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        let alt = obs.get("altitude_m").unwrap_or(0.0);
        let battery = obs.get("battery_pct").unwrap_or(100.0);
        let seq = obs.get("mission_seq").unwrap_or(0.0) as u16;
        let speed = obs.get("groundspeed_mps").unwrap_or(0.0);
        let obstacle = obs.events.iter().any(|e| e == "obstacle detected");
        let airborne = alt > 0.8 * self.takeoff_alt_m;
        let action = if battery <= self.low_battery_pct && self.phase != "landing" {
            self.phase = "return";
            "return_to_base"
        } else {
            match self.phase {
                "base" if airborne => {
                    self.phase = "wpi";
                    "follow_trajectory"
                }
                "base" => "take_off",
                "wpi" if obstacle => {
                    self.phase = "wp_avoid";
                    self.avoid_until = obs.time_s + 5.0;
                    "avoid_obstacle"
                }
                "wpi" if seq >= self.last_seq && speed < 1.0 => {
                    self.phase = "landing";
                    "land"
                }
                "wpi" => "follow_trajectory",
                "wp_avoid" if obs.time_s >= self.avoid_until => {
                    self.phase = "wpi";
                    "follow_trajectory"
                }
                "wp_avoid" => "avoid_obstacle",
                "return" => "return_to_base",
                _ => "land",
            }
        };
        let plan = Plan {
            vehicle_actions: vec![action.to_string()],
            applications: vec![],
        };
        let rec = DecisionRecord {
            state: self.phase.to_string(),
            actions: vec![action.to_string()],
            events: obs.events.clone(),
            observations: obs.values.clone(),
            ..Default::default()
        };
        (plan, rec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(t: f64, vals: &[(&str, f64)], events: &[&str]) -> Observations {
        let mut o = Observations {
            time_s: t,
            ..Default::default()
        };
        for (k, v) in vals {
            o.set(k, *v);
        }
        o.events = events.iter().map(|s| s.to_string()).collect();
        o
    }

    #[test]
    fn scripted_decider_flies_the_tracking_pattern() {
        let mut d = ScriptedDecider::new(10.0, 6, "safety");
        let act =
            |d: &mut ScriptedDecider, o: Observations| d.step(&o).0.vehicle_actions[0].clone();
        assert_eq!(
            act(&mut d, obs(0.0, &[("altitude_m", 0.0)], &[])),
            "take_off"
        );
        assert_eq!(
            act(&mut d, obs(5.0, &[("altitude_m", 9.5)], &[])),
            "follow_trajectory"
        );
        assert_eq!(
            act(
                &mut d,
                obs(6.0, &[("altitude_m", 20.0)], &["obstacle detected"])
            ),
            "avoid_obstacle"
        );
        assert_eq!(
            act(&mut d, obs(8.0, &[("altitude_m", 20.0)], &[])),
            "avoid_obstacle"
        );
        assert_eq!(
            act(&mut d, obs(11.0, &[("altitude_m", 20.0)], &[])),
            "follow_trajectory"
        );
        assert_eq!(
            act(
                &mut d,
                obs(
                    50.0,
                    &[
                        ("altitude_m", 20.0),
                        ("mission_seq", 6.0),
                        ("groundspeed_mps", 0.2)
                    ],
                    &[]
                )
            ),
            "land"
        );
        let mut d = ScriptedDecider::new(10.0, 6, "safety");
        assert_eq!(
            act(&mut d, obs(0.0, &[("battery_pct", 15.0)], &[])),
            "return_to_base"
        );
    }

    #[test]
    fn json_lines_sink_writes_one_object_per_line() {
        let mut buf = Vec::new();
        {
            let mut s = JsonLines(&mut buf);
            s.write(&DecisionRecord {
                cycle: 1,
                ..Default::default()
            })
            .unwrap();
            s.write(&DecisionRecord {
                cycle: 2,
                ..Default::default()
            })
            .unwrap();
        }
        let text = String::from_utf8(buf).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2);
        let back: DecisionRecord = serde_json::from_str(lines[1]).unwrap();
        assert_eq!(back.cycle, 2);
    }

    #[test]
    fn policy_values() {
        assert!(parse_policy("safety").is_ok() && parse_policy("mission").is_ok());
        assert!(parse_policy("yolo").is_err());
    }
}
