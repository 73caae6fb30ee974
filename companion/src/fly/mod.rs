//! `companion fly`: the imperative shell around the link protocol and the decision core.
//!
//! Tasks: the transport supervisor(s) (bytes in/out, reconnect), and one loop that owns the
//! protocol state ([`Vehicle`]), the clock, the 1 Hz heartbeat, the 10 Hz protocol tick and the
//! decision cycles: one on every significant event, and one every `decision_period_s` otherwise.
//! Each cycle's record goes to a [`RecordSink`] with the commands it sent (latency measured from
//! the message that triggered the cycle to the command handed to the transport) and the results
//! of earlier commands that finished since.
//!
//! The operator decides when to fly ([`companion_link::operator`]): until the pilot arms or a ground
//! station sends the start command, cycles decide and log but command no motion; a pilot's mode
//! change stops the commanding until control is handed back. After a flight ends landed and
//! disarmed, `fly` waits for the operator again (`--once` exits instead).

use companion_link::Msg;
use companion_link::actions::{ActionTable, LinkParams, Route};
use companion_link::ingest::{self, Encoder, Ingest};
use companion_link::liveness::parse_duration;
use companion_link::mission_state::{self, Extra, MissionState};
use companion_link::operator::{Control, GcsText, OperatorGate};
pub mod gate;
pub mod link_security;
pub mod transport;
pub mod words;
use anyhow::Context;
use companion_core::launch::LaunchRefusal;
use companion_core::mission::RouteRole;
use companion_core::observations::Observations;
use companion_core::record::{CommandOutcome, DecisionRecord, Event, LinkEvent, Plan};
use companion_link::url::{self, ConnectUrl};
use companion_link::vehicle::{Vehicle, VehicleConfig};
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;
use transport::Inbound;

/// The decision core as the shell sees it: one observation snapshot in, one plan and its record out.
pub trait Decider {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord);
    /// Do the models agree to a start, judged from this record (the launch verdict,
    /// [`companion_core::launch::verdict`])?
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal>;
    /// A new flight begins (the last one ended landed and disarmed): forget the last one.
    fn new_flight(&mut self) {}
}

/// The real core is a decider as it is (fuzzing and the soak drive it without a wrapper).
impl Decider for companion_core::decision::Core<'_> {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        companion_core::decision::Core::step(self, obs)
    }
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal> {
        companion_core::launch::verdict(rec, self.model)
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
    /// Arbitration policy: a policy of params/policies.toml, safety (safety-first) or mission
    /// (mission-first); checked when the params load.
    #[arg(long, default_value = "safety")]
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
    /// Stop after this long (e.g. 60s); default: run until Ctrl-C or SIGTERM, flight after
    /// flight (see --once).
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<Duration>,
    /// Where run folders go (a new `<UTC time>/` inside with decisions.jsonl and flight.tlog,
    /// printed at the start).
    #[arg(long, default_value = crate::decision_log::DEFAULT_RUNS_DIR)]
    pub log_dir: PathBuf,
    /// For SITL and tests only: start the first mission (mode, ARM, take-off) as soon as the
    /// autopilot is ready, without waiting for the operator. This ARMS THE VEHICLE by itself.
    /// Without it, the companion commands no motion until the pilot arms the vehicle or a
    /// ground station sends MAV_CMD_MISSION_START to component 191.
    #[arg(long)]
    pub auto_start: bool,
    /// Command only the autopilot with this MAVLink system id (when several speak on the link);
    /// default: the first autopilot heard. Others are reported, never obeyed.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_sysid: Option<u8>,
    /// With --autopilot-sysid: the autopilot's component id (default 1, MAV_COMP_ID_AUTOPILOT1).
    /// The pin is system and component: another component of that system is not obeyed.
    #[arg(long, default_value_t = 1, requires = "autopilot_sysid", value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_compid: u8,
    /// Refuse to start without --signing-key, and to fly an autopilot whose frames are not
    /// signed with it (nothing is commanded; said on stderr and to the ground station).
    #[arg(long)]
    pub require_signing: bool,
    /// Exit with an error when no autopilot HEARTBEAT arrives within this time (e.g. 30s);
    /// default: wait (and retry the connection) for ever.
    #[arg(long, value_parser = parse_duration)]
    pub connect_timeout: Option<Duration>,
    /// Exit after one flight (flown, then landed and disarmed) instead of waiting for the
    /// operator's next start.
    #[arg(long)]
    pub once: bool,
    /// The pilot arming the vehicle is a start request (held armed over every heartbeat for
    /// `[flight] operator_confirm_s`). Off by default: arming for a manual flight is not a start.
    #[arg(long)]
    pub start_on_arm: bool,
    /// A ground station's MAVLink system id whose MAV_CMD_MISSION_START is taken even before it
    /// sent a GCS HEARTBEAT (repeat for several). Systems heard sending a GCS HEARTBEAT count
    /// too; an autopilot component never does.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub gcs_sysid: Vec<u8>,
}

impl FlyArgs {
    /// The arguments `companion fly ARGS...` gives, the command line's defaults for the rest
    /// (for tests and tools that build a fly setup without a process).
    pub fn from_cli<I: IntoIterator<Item = S>, S: Into<std::ffi::OsString> + Clone>(
        args: I,
    ) -> Result<Self, clap::Error> {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Fly {
            #[command(flatten)]
            args: FlyArgs,
        }
        let argv = std::iter::once(std::ffi::OsString::from("fly"))
            .chain(args.into_iter().map(Into::into));
        Ok(Fly::try_parse_from(argv)?.args)
    }
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
    /// The mission's states and phases (params/mission.toml) the mission estimator moves through.
    pub states: companion_core::mission::MissionStates,
}

impl FlySetup {
    pub fn load(args: &FlyArgs) -> anyhow::Result<Self> {
        let dir = args
            .params
            .clone()
            .unwrap_or_else(crate::params::default_params_dir);
        // The same loader `check` and `simulate` use (crate::params), so they cannot drift.
        let mut files = crate::params::read_params_dir(&dir)?;
        if let Some(r) = args.mission.as_deref() {
            crate::params::add_file(&mut files, r);
        }
        Self::from_files(&files, args)
    }

    /// [`FlySetup::load`] on params already read (`--mission`'s file, when given, among them).
    pub fn from_files(
        files: &companion_core::spec::ParamsFiles,
        args: &FlyArgs,
    ) -> anyhow::Result<Self> {
        link_security::check_args(args)?;
        let (link, actions, route, _) =
            crate::params::load_fly_files(files, args.mission.as_deref())?;
        let key = match &args.signing_key {
            Some(p) => {
                crate::params::regular_file(p)
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
                    companion_link::actions::Step::Command { command, params }
                        if *command == companion_link::dialect::MavCmd::MAV_CMD_NAV_TAKEOFF
                            && params[6] > 0.0 =>
                    {
                        Some(params[6] as f64)
                    }
                    _ => None,
                })
            })
            .unwrap_or(route.altitude_m);
        let states = companion_core::mission::MissionStates::load(files)?;
        Ok(Self {
            link,
            actions,
            route,
            key,
            takeoff_alt_m,
            states,
        })
    }

    /// The protocol state `fly` drives, configured from these params (clones the action table
    /// and route, so a soak run can build a fresh one per mission).
    pub fn vehicle(&self, link_timeout: Duration) -> Vehicle {
        let cfg = VehicleConfig {
            link_timeout,
            streams: self.link.stream_ids(),
            streams_not_sent: self.link.streams_not_sent(),
            telemetry: self.link.telemetry.clone(),
            arm_wait: Duration::from_secs_f64(self.link.arm_wait_s),
            max_arm_attempts: self.link.max_arm_attempts,
            zone_radius_m: self.link.flight.zone_radius_m,
            zone_arrive_timeout: Duration::from_secs_f64(self.link.flight.zone_arrive_timeout_s),
            mode_confirm: Duration::from_secs_f64(self.link.flight.mode_confirm_s),
            max_mode_attempts: self.link.flight.max_mode_attempts,
            ground_altitude_m: self.link.flight.ground_altitude_m,
            ..VehicleConfig::default()
        };
        Vehicle::new(cfg, self.actions.clone(), Some(self.route.clone()))
    }
}

/// Blocking entry point for the CLI: a run folder under `--log-dir` with the decision log and
/// `flight.tlog`; the folder is printed first.
pub fn run<D: Decider>(args: FlyArgs, decider: D) -> anyhow::Result<()> {
    use crate::decision_log::{self as dlog, Header, TlogWriter, WriterOptions};
    // Params first: a start that fails on them leaves no run folder behind.
    let setup = FlySetup::load(&args)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    let params = args
        .params
        .clone()
        .unwrap_or_else(crate::params::default_params_dir);
    let now = std::time::SystemTime::now();
    let command: Vec<String> = std::env::args().collect();
    let mut header = Header::new(command.join(" "), now)
        .with_params_dir(&params)
        .with_context(|| format!("reading {} for the log header", params.display()))?;
    header.policy = Some(args.policy.clone());
    header.model = Some(companion_core::decision::ModelKind::Bfm.name().to_string());
    let opts = WriterOptions::from_env()?;
    let mut log = dlog::start_run(&args.log_dir, now, header, opts.clone())
        .with_context(|| format!("starting a run folder in {}", args.log_dir.display()))?;
    let dir = log.dir().to_path_buf();
    println!("run folder: {}", dir.display());
    tracing::info!("run folder {}", dir.display());
    let tlog = TlogWriter::create(&dir.join("flight.tlog"))
        .with_context(|| format!("creating {}", dir.join("flight.tlog").display()))?
        .with_max_bytes(opts.max_bytes);
    // The tlog's cap is told like the decision log's: a loss line there, the end line, the exit.
    log.watch_tlog(tlog.capped_counter());
    let mut sink = LogSink(log);
    let result = rt.block_on(run_loop(args, setup, decider, &mut sink, Some(Tlog(tlog))));
    let stats = sink.0.close();
    let report = result?;
    eprintln!(
        "companion fly: {} records {} dropped {} tlog_capped {}",
        serde_json::to_string(&report).unwrap_or_default(),
        stats.records,
        stats.dropped,
        stats.tlog_capped
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
    decider: D,
    sink: &mut S,
    tlog: Option<Tlog>,
) -> anyhow::Result<FlyReport> {
    let setup = FlySetup::load(&args)?;
    run_loop(args, setup, decider, sink, tlog).await
}

async fn run_loop<D: Decider, S: RecordSink>(
    args: FlyArgs,
    setup: FlySetup,
    mut decider: D,
    sink: &mut S,
    mut tlog: Option<Tlog>,
) -> anyhow::Result<FlyReport> {
    let mut shell = Shell::new(&setup);
    shell.operator = OperatorGate::new(args.auto_start);
    shell.operator.confirm = Duration::from_secs_f64(setup.link.flight.operator_confirm_s);
    shell.operator.start_on_arm = args.start_on_arm;
    let mut stations = gate::GroundStations {
        pinned: args.gcs_sysid.iter().copied().collect(),
        ..Default::default()
    };
    if args.auto_start {
        eprintln!(
            "companion fly: WARNING --auto-start: the companion will set the mode, ARM and take off by itself as soon as the autopilot is ready (SITL and tests only)"
        );
        tracing::warn!("--auto-start: no operator start; the companion arms the vehicle itself");
    } else {
        tracing::info!(
            "waiting for the operator: a ground station sends MAV_CMD_MISSION_START to component {}, or the pilot switches the armed vehicle to GUIDED (ArduPilot){}",
            companion_link::OUR_COMPONENT_ID,
            if args.start_on_arm {
                ", or arms it (--start-on-arm)"
            } else {
                "; arming alone is not a start (see --start-on-arm)"
            }
        );
    }
    let mut vehicle = setup.vehicle(args.link_timeout);
    vehicle.cfg.autopilot_sysid = args.autopilot_sysid;
    vehicle.cfg.autopilot_compid = args.autopilot_compid;
    let mut link_security = link_security::LinkSecurity::start(&args, setup.key.is_some());
    let signing = || setup.key.map(ingest::signing_data);
    let mut ingest = Ingest::new(signing());
    let mut encoder = Encoder::new(signing());
    let retry = Duration::from_secs(1);
    let mut link = transport::spawn(args.connect.clone(), retry);
    let mut udp_peer = transport::UdpPeer::default();
    let mut link_failures = transport::FailureLines::new(Duration::from_secs(10));
    let mut onboard_failures = transport::FailureLines::new(Duration::from_secs(10));
    tracing::info!(url = %args.connect, "connecting to the autopilot");
    // Receive-only, but the handle (and its outbound sender) must live as long as the loop.
    let mut onboard = args
        .onboard
        .clone()
        .map(|u| transport::spawn(u, Duration::from_secs(1)));
    let mut onboard_ingest = Ingest::new(signing());
    let onboard_udpin = matches!(args.onboard, Some(ConnectUrl::UdpIn { .. }));

    let start = Instant::now();
    let now = || start.elapsed();
    let mut heartbeat = tokio::time::interval(Duration::from_secs(1));
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let mut periodic = tokio::time::interval(Duration::from_secs_f64(setup.link.decision_period_s));
    periodic.tick().await; // the first tick is immediate; the first cycle waits for telemetry
    let stop_at = args.duration.map(|d| start + d);
    let connect_by = args.connect_timeout.map(|d| start + d);
    let mut report = FlyReport::default();
    let mut transport_events: Vec<LinkEvent> = Vec::new();
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    let terminate = terminate_signal();
    tokio::pin!(terminate);
    let min_gap = Duration::from_secs_f64(setup.link.flight.min_event_cycle_interval_s);
    let mut last_cycle_at: Option<Duration> = None;
    // Events held back by the cycle rate limit: the earliest one's time, and when the next
    // cycle may run.
    let mut held_trigger: Option<Duration> = None;
    let mut cycle_due: Option<Duration> = None;
    let mut was_alive = false;
    let mut announced_auto_start = false;
    let mut gcs = GcsWatch::default();

    // The loop ends with why it stopped, or an error; either way the stop below runs (the
    // ground station told, the vehicle handed to the autopilot when the companion commands it).
    let outcome: anyhow::Result<&'static str> = async { Ok(loop {
        let mut out: Vec<Msg> = Vec::new();
        let mut trigger: Option<Duration> = None;
        let mut wake = false;
        tokio::select! {
            m = link.inbound.recv() => match m {
                Some(Inbound::Bytes(b)) => {
                    let t = now();
                    for f in ingest.push(&b) {
                        if let Some(w) = tlog.as_mut() {
                            w.received(&f);
                        }
                        gcs.on_frame(t, &f);
                        stations.on_frame(&f);
                        out.extend(vehicle.on_frame(t, &f));
                    }
                    ingest.set_our_system(vehicle.our_system());
                    shell.set_ingest(ingest.stats);
                    trigger = Some(t);
                }
                Some(Inbound::Datagram(b, from)) => {
                    let t = now();
                    // Each datagram is parsed on its own (MAVLink over UDP sends whole frames per
                    // datagram): a frame is then surely the sender's, and a junk datagram's
                    // half header cannot swallow or re-attribute the autopilot's next frames.
                    ingest.reset();
                    for f in ingest.push(&b) {
                        if let Some(w) = tlog.as_mut() {
                            w.received(&f);
                        }
                        gcs.on_frame(t, &f);
                        stations.on_frame(&f);
                        out.extend(vehicle.on_frame(t, &f));
                        // Replies go to the autopilot's address, learned from its own frames only.
                        let src = (f.header.system_id.min(255) as u8, f.header.component_id);
                        let autopilot = (vehicle.target == Some(src)).then_some(src);
                        if let Some(ev) = udp_peer.on_frame(from, autopilot) {
                            tracing::info!("{ev}");
                            let _ = link.peer.send(udp_peer.addr);
                            transport_events.push(LinkEvent::from(ev));
                        }
                    }
                    ingest.set_our_system(vehicle.our_system());
                    shell.set_ingest(ingest.stats);
                    trigger = Some(t);
                }
                Some(Inbound::Connected(name)) => {
                    ingest.reset();
                    vehicle.on_reconnect(now());
                    if let Some(line) = link_failures.connected(&name) {
                        tracing::info!("autopilot link: {line}");
                    }
                    transport_events.push(LinkEvent::TransportConnected(name.to_string()));
                }
                Some(Inbound::Disconnected(why)) => {
                    // One line (tracing writes to stderr, the journal), not one per retry.
                    if let Some(line) = link_failures.failed(now(), &why, retry) {
                        tracing::warn!("autopilot link {}: {line}", args.connect);
                    }
                    transport_events.push(LinkEvent::TransportDisconnected(why.to_string()));
                }
                None => anyhow::bail!("the transport task stopped"),
            },
            m = async { match &mut onboard { Some(h) => h.inbound.recv().await, None => std::future::pending().await } } => match m {
                // Receive-only: a udpin onboard link never learns a reply address.
                Some(Inbound::Bytes(b) | Inbound::Datagram(b, _)) => {
                    let t = now();
                    if onboard_udpin {
                        // One datagram, whole frames: parsed on its own (as on the autopilot link).
                        onboard_ingest.reset();
                    }
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
                    if let Some(line) = onboard_failures.connected(&name) {
                        tracing::info!("onboard link: {line}");
                    }
                    transport_events.push(LinkEvent::OnboardConnected(name.to_string()));
                }
                Some(Inbound::Disconnected(why)) => {
                    if let Some(line) = onboard_failures.failed(now(), &why, retry) {
                        tracing::warn!("onboard link: {line}");
                    }
                    transport_events.push(LinkEvent::OnboardDisconnected(why.to_string()));
                }
                None => anyhow::bail!("the onboard transport task stopped"),
            },
            _ = heartbeat.tick() => out.push(Vehicle::heartbeat()),
            _ = tick.tick() => out.extend(vehicle.tick(now())),
            _ = periodic.tick() => {
                if vehicle.target.is_some() {
                    let t = held_trigger.take().unwrap_or_else(now);
                    cycle_due = None;
                    run_cycle_at(&mut decider, &mut shell, &mut vehicle, &mut encoder, &link.outbound, &mut tlog, sink, t, now, &mut report, &mut transport_events).await?;
                    last_cycle_at = Some(now());
                }
            },
            _ = async { match connect_by { Some(t) if vehicle.target.is_none() => tokio::time::sleep_until(t).await, _ => std::future::pending().await } } => {
                let waited = args.connect_timeout.unwrap_or_default();
                let msg = format!(
                    "no autopilot HEARTBEAT on {} within {:?} (--connect-timeout){}",
                    args.connect,
                    waited,
                    if vehicle.other_autopilot_heartbeats > 0 { "; other autopilots were heard, see --autopilot-sysid" } else { "" }
                );
                tracing::error!("{msg}");
                anyhow::bail!(msg);
            },
            _ = async { match cycle_due { Some(t) => tokio::time::sleep_until(start + t).await, None => std::future::pending().await } } => {
                cycle_due = None;
                wake = true;
            },
            _ = &mut ctrl_c => break "SIGINT",
            _ = &mut terminate => break "SIGTERM",
            _ = async { match stop_at { Some(t) => tokio::time::sleep_until(t).await, None => std::future::pending().await } } => break "--duration elapsed",
        }
        // Commands addressed to us: answered every turn, before the autopilot is known too
        // (refused then, never queued for later).
        let t = now();
        for cmd in vehicle.take_commands_to_us() {
            wake |= gate::answer_command(&mut shell, &mut vehicle, &stations, cmd, t, &mut out);
        }
        if vehicle.target.is_some() {
            // The operator: a pilot's arming, GUIDED or mode change; a start voided.
            wake |= gate::observe(&mut shell, &mut vehicle, t, &mut out);
            let alive = vehicle.liveness.alive();
            if alive != was_alive {
                if alive {
                    tracing::info!("autopilot link up");
                } else {
                    tracing::warn!("autopilot link lost: no commands until it is back");
                }
                was_alive = alive;
            }
            if alive {
                if args.auto_start && !announced_auto_start {
                    announced_auto_start = true;
                    out.extend(shell.texts.say(
                        t,
                        WARNING,
                        "companion: AUTO-START, arms without operator",
                    ));
                }
                if shell.operator.control == Control::Waiting {
                    out.extend(shell.texts.say(
                        t,
                        INFO,
                        "companion ready, waiting for the operator",
                    ));
                }
            }
            if let Some((text, lost)) = gcs.check(t) {
                if lost {
                    tracing::warn!("{text}");
                } else {
                    tracing::info!("{text}");
                }
                shell.pending_events.push(Event::from(text));
                out.extend(shell.texts.say(
                    t,
                    if lost { WARNING } else { INFO },
                    &format!("companion: {text}"),
                ));
            }
        }
        out.extend(link_security.check(now(), &vehicle, &ingest.stats, &mut shell.texts));
        send(&mut encoder, &vehicle, &link.outbound, &mut tlog, &out).await;
        vehicle.stamp_latency(trigger.unwrap_or_else(now), now());
        // Significant telemetry (a new obstacle, a found target, a crossed battery threshold, a
        // mode change, a command result, link loss) triggers a cycle now, but no sooner than
        // `min_event_cycle_interval_s` after the last one: events in between wait for it.
        // Link loss found by the protocol tick counts too (its trigger is the tick itself).
        if (vehicle.has_events() || wake || held_trigger.is_some()) && vehicle.target.is_some() {
            let t_now = now();
            let first = *held_trigger.get_or_insert(trigger.unwrap_or(t_now));
            let due = last_cycle_at.map_or(Duration::ZERO, |l| l + min_gap);
            if t_now < due {
                cycle_due = Some(due);
                continue;
            }
            held_trigger = None;
            cycle_due = None;
            let t = first;
            last_cycle_at = Some(t_now);
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
        // Flew, landed and disarmed: the flight is over (one last cycle recorded it). Wait for
        // the operator's next start, or exit with --once.
        if shell.finished() {
            if args.once {
                tracing::info!("flight over: landed and disarmed; exiting (--once)");
                break "flight over (--once)";
            }
            tracing::info!("flight over: landed and disarmed; waiting for the operator");
            vehicle.stop_actions(now(), "flight over");
            shell.new_flight();
            decider.new_flight();
            let msgs: Vec<Msg> = shell
                .texts
                .say(now(), NOTICE, "companion: landed; waiting for the operator")
                .into_iter()
                .collect();
            send(&mut encoder, &vehicle, &link.outbound, &mut tlog, &msgs).await;
        }
    }) }
    .await;

    // The stop: said to the ground station; an armed vehicle the companion commands is handed to
    // the autopilot (params/link.toml [flight] handoff), its answer awaited a moment, and a last
    // record says so.
    let why = match &outcome {
        Ok(why) => (*why).to_string(),
        Err(e) => format!("error: {e:#}"),
    };
    let armed = vehicle.target.is_some() && vehicle.readiness.armed;
    let (msgs, commanded) = gate::begin_stop(
        &mut shell,
        &mut vehicle,
        setup.link.flight.handoff,
        &why,
        now(),
    );
    send(&mut encoder, &vehicle, &link.outbound, &mut tlog, &msgs).await;
    if commanded {
        let deadline = Instant::now() + HANDOFF_WAIT;
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        while vehicle.handoff_status().is_none() {
            let mut out = Vec::new();
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
                    }
                    Some(Inbound::Datagram(b, _)) => {
                        let t = now();
                        ingest.reset();
                        for f in ingest.push(&b) {
                            if let Some(w) = tlog.as_mut() {
                                w.received(&f);
                            }
                            out.extend(vehicle.on_frame(t, &f));
                        }
                    }
                    Some(_) => {}
                    None => break,
                },
                _ = tick.tick() => out.extend(vehicle.tick(now())),
                _ = tokio::time::sleep_until(deadline) => break,
            }
            send(&mut encoder, &vehicle, &link.outbound, &mut tlog, &out).await;
        }
        gate::end_stop(&mut shell, &vehicle, true);
    }
    if armed {
        let t = now();
        let recorded = run_cycle_at(
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
        .await;
        if let Err(e) = recorded {
            tracing::error!("the stop's record was not written: {e:#}");
        }
    }
    if !msgs.is_empty() {
        // Let the transport write the stop's words before the process ends.
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    outcome?;
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

const INFO: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_INFO;
const NOTICE: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_NOTICE;
const WARNING: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_WARNING;

/// How long the stop waits for the autopilot's answer to the hand-off mode (within systemd's
/// TimeoutStopSec in deploy/companion.service, and the 5 s a pilot can be asked to wait).
const HANDOFF_WAIT: Duration = Duration::from_millis(4500);

/// SIGTERM (systemd's stop): ends the loop like Ctrl-C, so the logs close whole.
async fn terminate_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        if let Ok(mut s) = signal(SignalKind::terminate()) {
            s.recv().await;
            return;
        }
    }
    std::future::pending::<()>().await
}

/// The ground station's heartbeats, to tell when it goes silent and when it is back.
#[derive(Debug, Default)]
struct GcsWatch {
    last: Option<Duration>,
    lost: bool,
}

impl GcsWatch {
    /// A ground station silent this long counts as lost.
    const TIMEOUT: Duration = Duration::from_secs(5);

    fn on_frame(&mut self, now: Duration, f: &ingest::Frame) {
        if let Msg::HEARTBEAT(h) = &f.msg
            && h.mavtype == companion_link::dialect::MavType::MAV_TYPE_GCS
        {
            self.last = Some(now);
        }
    }

    /// ("link to the ground station lost" or "... back", lost) when that changed.
    fn check(&mut self, now: Duration) -> Option<(&'static str, bool)> {
        let silent = self
            .last
            .is_some_and(|t| now.saturating_sub(t) > Self::TIMEOUT);
        if silent && !self.lost {
            self.lost = true;
            return Some(("link to the ground station lost", true));
        }
        if !silent && self.lost {
            self.lost = false;
            return Some(("link to the ground station back", false));
        }
        None
    }
}

/// What the shell keeps between cycles besides the protocol state (one per flight).
pub struct Shell {
    mission: MissionState,
    /// The mission state a new flight starts from.
    fresh_mission: MissionState,
    precedence: Vec<String>,
    /// Events of the shell itself (the mission's end, the operator) for the next record.
    pending_events: Vec<Event>,
    /// Who commands: the companion only once the operator started the mission. `Shell::new`
    /// starts it at once (the soak and fuzz runs); `fly` waits unless `--auto-start`.
    pub operator: OperatorGate,
    /// STATUSTEXT to the ground station, rate-limited.
    pub texts: GcsText,
    /// The last cycle's action set, to tell a change of behaviour.
    last_actions: Vec<String>,
    /// The last behaviour told to the ground station (motion and tracking version), and the
    /// evidence of that cycle (to say what changed).
    last_told: words::Behaviour,
    told_evidence: std::collections::BTreeMap<String, String>,
    /// What the guarantee's last verdict told was about (None: it could meet the goals).
    guarantee_told: Option<Vec<String>>,
    /// Ingest counters now, and as last reported in a record's link_events.
    ingest: ingest::IngestStats,
    ingest_reported: ingest::IngestStats,
    /// The launch verdict of the latest record while the gate waits (before any record: not
    /// on the ground yet, no decision to read).
    launch: Result<(), LaunchRefusal>,
    /// When the running start was granted (a job failing after it, before airborne, voids it).
    granted_at: Option<Duration>,
    /// The last `--auto-start` refusal said (said once per reason).
    refusal_told: Option<String>,
    /// A command addressed to us older than this is refused.
    command_max_age: Duration,
}

impl Shell {
    pub fn new(setup: &FlySetup) -> Self {
        let mut mission =
            MissionState::new(&setup.route, setup.takeoff_alt_m, setup.states.clone());
        let f = &setup.link.flight;
        mission.landed_confirm_s = f.landed_confirm_s;
        mission.ground_altitude_m = f.ground_altitude_m;
        Self {
            fresh_mission: mission.clone(),
            mission,
            precedence: setup.link.vehicle_action_precedence.clone(),
            pending_events: Vec::new(),
            operator: OperatorGate::started(),
            texts: GcsText::new(
                Duration::from_secs_f64(f.statustext_repeat_s),
                f.statustext_max_per_s,
            ),
            last_actions: Vec::new(),
            last_told: Default::default(),
            told_evidence: Default::default(),
            guarantee_told: None,
            ingest: Default::default(),
            ingest_reported: Default::default(),
            launch: Err(LaunchRefusal::NotOnGround {
                state: String::new(),
                on_ground: setup.states.route_state(RouteRole::OnGround).to_string(),
            }),
            granted_at: None,
            refusal_told: None,
            command_max_age: Duration::from_secs_f64(f.command_max_age_s),
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

    /// After a flight ended landed and disarmed: a fresh mission, and the operator must start
    /// the next one.
    pub fn new_flight(&mut self) {
        self.mission = self.fresh_mission.clone();
        self.operator.new_flight();
        self.granted_at = None;
        self.last_actions.clear();
        self.last_told = Default::default();
        self.told_evidence.clear();
        self.pending_events.push(Event::from(
            "flight over: landed and disarmed; waiting for the operator",
        ));
    }

    /// A change of the cycle's action set, described for the journal and the ground station
    /// ("take_off -> follow_trajectory (waypoint 2)"), or None when it is the same as the
    /// last cycle's.
    fn action_change(&mut self, rec: &DecisionRecord) -> Option<String> {
        if rec.actions == self.last_actions {
            return None;
        }
        let was = std::mem::replace(&mut self.last_actions, rec.actions.clone());
        let why = rec
            .events
            .iter()
            .find(|e| !matches!(e, Event::Command { .. }))
            .map_or_else(|| format!("state {}", rec.state), Event::to_string);
        let show = |a: &[String]| {
            if a.is_empty() {
                "-".to_string()
            } else {
                a.join("+")
            }
        };
        Some(format!("{} -> {} ({why})", show(&was), show(&rec.actions)))
    }

    /// What a pilot needs of a behaviour change: what the vehicle will do and why
    /// (`Battery 7%: returning home`, docs/mavlink.md "Words to the ground station"). `flown` is
    /// the vehicle action flown this cycle (the shell's landing included), so a landing the
    /// shell keeps is told as a landing. None when neither the motion nor the tracking version
    /// changed: one text per change, never one per cycle.
    fn behaviour_text(&mut self, rec: &DecisionRecord, flown: Option<&str>) -> Option<String> {
        let now = words::Behaviour {
            motion: flown.map(str::to_string),
            tracking: self
                .mission
                .states()
                .tracking_target(&rec.actions)
                .map(|(kept, _)| kept.to_string()),
        };
        if now == self.last_told {
            return None;
        }
        let text = words::behaviour_text(
            &now,
            &self.last_told,
            rec,
            &self.told_evidence,
            self.mission.end(),
        );
        self.last_told = now;
        self.told_evidence.clone_from(&rec.evidence);
        Some(text)
    }

    /// The guarantee's verdict when it changed (what it is short of, not by how much): the
    /// journal line and the STATUSTEXT with its severity. None while it is the same, so a
    /// vehicle on the ground after landing hears it once, not once a cycle.
    fn guarantee_change(
        &mut self,
        rec: &DecisionRecord,
    ) -> Option<(String, companion_link::dialect::MavSeverity, String)> {
        let g = rec.guarantee.as_ref()?;
        let key = words::guarantee_key(g);
        if key == self.guarantee_told {
            return None;
        }
        let was = std::mem::replace(&mut self.guarantee_told, key);
        match &self.guarantee_told {
            Some(_) => {
                let why = g
                    .infeasible_reason
                    .as_deref()
                    .unwrap_or("no allocation meets the goals");
                Some((
                    format!("guarantee: cannot meet the goals: {why}"),
                    WARNING,
                    words::guarantee_text(g),
                ))
            }
            None => was.map(|_| {
                (
                    "guarantee: the goals can be met again".to_string(),
                    NOTICE,
                    "Goals can be met again".to_string(),
                )
            }),
        }
    }

    /// A link event when bad input arrived since the last report: malformed frames or bad
    /// signatures, or more unframed bytes than one frame still arriving could explain.
    fn ingest_note(&mut self) -> Option<LinkEvent> {
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
        Some(LinkEvent::from(format!(
            "ingest: {} bytes outside valid frames (garbage or corrupt), {} malformed frames, {} bad signatures, {} unsigned commands refused, {} other unsigned frames refused (since start)",
            now.bytes_unframed(),
            now.frames_malformed,
            now.bad_signatures,
            now.unsigned_commands_refused,
            now.unsigned_refused
        )))
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
    transport_events: &mut Vec<LinkEvent>,
) -> anyhow::Result<()> {
    let decided = decide(decider, shell, vehicle, &now);
    send(encoder, vehicle, tx, tlog, &decided.msgs).await;
    vehicle.stamp_latency(trigger_at, now());
    report.cycles += 1;
    // The action flown, under its own name (a shell-only entry such as the route's resume is
    // told as the action it is flown for).
    let flown = decided.chosen.as_deref().map(|c| {
        vehicle
            .actions
            .flown_for
            .get(c)
            .map_or(c, String::as_str)
            .to_string()
    });
    let rec = finish_record(decided, shell, vehicle, report.cycles, transport_events);
    if !shell.operator.commanding() {
        shell.launch = decider.launch_verdict(&rec);
    }
    tracing::debug!(
        cycle = rec.cycle,
        state = %rec.state,
        actions = %rec.actions.join(","),
        "decision cycle"
    );
    let mut texts = Vec::new();
    if let Some(change) = shell.action_change(&rec) {
        tracing::info!("actions: {change}");
    }
    if shell.operator.commanding()
        && let Some(text) = shell.behaviour_text(&rec, flown.as_deref())
    {
        texts.extend(shell.texts.say(now(), NOTICE, &text));
    }
    if let Some((line, severity, text)) = shell.guarantee_change(&rec) {
        if severity == WARNING {
            tracing::warn!("{line}");
        } else {
            tracing::info!("{line}");
        }
        texts.extend(shell.texts.say(now(), severity, &text));
    }
    send(encoder, vehicle, tx, tlog, &texts).await;
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
    coalesce_events(&mut events);
    let mut obs = vehicle.observations(now(), events.clone());
    let extra = Extra {
        mode: vehicle.telemetry.mode.as_deref(),
        landed_state: vehicle.telemetry.landed_state.as_deref(),
        down_for_s: Some(vehicle.down_for(now()).map_or(0.0, |d| d.as_secs_f64())),
    };
    obs.state = shell.mission.update(&obs, &extra).to_string();
    complete_observations(&mut obs, &shell.mission);
    let (plan, mut rec) = decider.step(&obs);
    shell.mission.after_plan(&rec.actions);
    let mut chosen = mission_state::select_vehicle_action(&plan.vehicle_actions, &shell.precedence);
    let mut shell_events = Vec::new();
    if let Some(why) = shell.mission.mission_end(&obs) {
        // The mission's end, not the core's decision: recorded as an event with the action.
        shell_events.push(Event::ShellLand(why.to_string()));
        rec.shell_actions.push("land".into());
        shell.mission.after_plan(&["land".to_string()]);
        chosen = Some("land".into());
    }
    // The landing phase: the MDPs see `landing` as terminal and plan nothing there, so the shell
    // keeps flying the landing chosen until the vehicle is down, resuming it after an avoidance
    // sidestep and sending it again after a refusal or a timeout.
    if shell.operator.commanding()
        && let Some(landing) = shell.mission.landing_action().map(str::to_string)
    {
        let keep = chosen
            .as_deref()
            .is_some_and(|a| a == "avoid_obstacle" || shell.mission.is_landing_action(a));
        if !keep {
            if !vehicle.settled(&landing) {
                shell_events.push(Event::LandingKept(landing.clone()));
            }
            if !rec.actions.contains(&landing) && !rec.shell_actions.contains(&landing) {
                rec.shell_actions.push(landing.clone());
            }
            chosen = Some(landing);
        }
    }
    // Once the route is on the vehicle, an action with a shell-only entry flown for it
    // (`flown_for` in params/commands.toml: follow_trajectory -> resume in AUTO) is flown as that
    // entry, so the route is resumed where it was left, not uploaded again.
    if shell.mission.route_on_vehicle()
        && let Some(action) = chosen.as_deref()
        && let Some((resume, _)) = vehicle.actions.flown_for.iter().find(|(_, f)| *f == action)
    {
        chosen = Some(resume.clone());
    }
    // No motion until the operator starts the mission, none while the pilot has control.
    let msgs = if shell.operator.commanding() {
        vehicle.request_actions(now(), chosen.as_slice())
    } else {
        Vec::new()
    };
    Decided {
        msgs,
        chosen,
        plan,
        rec,
        obs,
        events,
        shell_events,
    }
}

/// At most this many events in one record: a flood is summarised, not copied.
const MAX_EVENTS: usize = 64;

/// Repeated events once each (in first-seen order), at most [`MAX_EVENTS`] with a count of the
/// rest.
fn coalesce_events(events: &mut Vec<Event>) {
    let mut seen = std::collections::BTreeSet::new();
    let total = events.len();
    events.retain(|e| seen.insert(e.to_string()));
    let unique = events.len();
    if unique > MAX_EVENTS {
        events.truncate(MAX_EVENTS);
    }
    if events.len() < total {
        events.push(Event::from(format!(
            "({} more events since the last cycle: {} repeats, {} not listed)",
            total - events.len(),
            total - unique,
            unique - events.len()
        )));
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
    events: Vec<Event>,
    /// Events of the shell's own decisions this cycle (mission end, landing resumed).
    shell_events: Vec<Event>,
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
    transport_events: &mut Vec<LinkEvent>,
) -> DecisionRecord {
    let Decided {
        mut rec,
        obs,
        events,
        shell_events,
        ..
    } = d;
    rec.cycle = cycle;
    rec.time_s = obs.time_s;
    rec.utc_us = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_micros() as u64);
    if rec.events.is_empty() {
        rec.events = events;
    }
    rec.events.extend(shell_events);
    if rec.observations.is_empty() {
        rec.observations = obs.values;
    }
    rec.commands.extend(vehicle.take_records());
    rec.link_events.append(transport_events);
    rec.link_events.extend(shell.ingest_note());
    rec.link_events.extend(vehicle.take_link_events());
    // A flood (STATUSTEXT from the autopilot) is summarised like events are, so the record stays
    // small enough to be logged.
    companion_core::record::coalesce_link_events(&mut rec.link_events);
    rec.vehicle.extend(vehicle.telemetry.vehicle());
    rec.vehicle.insert(
        "link_alive".into(),
        serde_json::Value::from(vehicle.liveness.alive()),
    );
    rec.vehicle.insert(
        "operator".into(),
        serde_json::Value::from(shell.operator.control.label()),
    );
    for c in &rec.commands {
        let failed = matches!(
            c.result,
            CommandOutcome::Failed(_)
                | CommandOutcome::Denied
                | CommandOutcome::Timeout(_)
                | CommandOutcome::NotSent(_)
                | CommandOutcome::NotReady(_)
                | CommandOutcome::Cancelled(_)
                | CommandOutcome::Unmapped
        );
        if failed {
            tracing::warn!("command {} {}: {}", c.action, c.command, c.result);
        } else {
            tracing::info!("command {} {}: {}", c.action, c.command, c.result);
        }
    }
    // Transport (dis)connections are said by `FailureLines` at most once per 10 s; the record
    // keeps every one.
    for e in rec.link_events.iter().filter(|e| {
        !matches!(
            e,
            LinkEvent::TransportConnected(_)
                | LinkEvent::TransportDisconnected(_)
                | LinkEvent::OnboardConnected(_)
                | LinkEvent::OnboardDisconnected(_)
        )
    }) {
        tracing::info!("link: {e}");
    }
    for e in rec.events.iter().filter(|e| matches!(e, Event::Mode(_))) {
        tracing::info!("vehicle {e}");
    }
    rec
}

/// The observations [`complete_observations`] adds to the telemetry's (fly's side of the
/// observation vocabulary checked at load, companion/src/vocabulary.rs).
pub const DERIVED_OBSERVATIONS: [&str; 2] = ["drone_speed_mps", "waypoints_remaining"];

/// Observations the health BNs read under names the telemetry does not produce directly.
fn complete_observations(obs: &mut Observations, mission: &MissionState) {
    if let Some(v) = obs.get("groundspeed_mps") {
        obs.values.entry("drone_speed_mps".into()).or_insert(v);
    }
    let remaining = mission.waypoints_remaining(obs);
    obs.set("waypoints_remaining", remaining);
}

/// Where the scripted decider is in its script (its own steps, not the mission's states: it
/// reads no params).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Script {
    OnGround,
    Route,
    Sidestep,
    Return,
    Landing,
}

impl Script {
    /// The step's name in the record's `state`.
    fn name(self) -> &'static str {
        match self {
            Script::OnGround => "scripted: on the ground",
            Script::Route => "scripted: route",
            Script::Sidestep => "scripted: sidestep",
            Script::Return => "scripted: return",
            Script::Landing => "scripted: landing",
        }
    }
}

/// A tiny rule-based stand-in for the decision core, for link tests: take off, fly the route,
/// sidestep obstacles, return on low battery, land when the route is done.
pub struct ScriptedDecider {
    pub takeoff_alt_m: f64,
    /// Mission seq of the last waypoint.
    pub last_seq: u16,
    pub low_battery_pct: f64,
    pub policy: String,
    phase: Script,
    avoid_until: f64,
}

impl ScriptedDecider {
    pub fn new(takeoff_alt_m: f64, last_seq: u16, policy: &str) -> Self {
        Self {
            takeoff_alt_m,
            last_seq,
            low_battery_pct: 20.0,
            policy: policy.to_string(),
            phase: Script::OnGround,
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
    /// The script agrees to a start when it proposes to take off (it has no guarantee).
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal> {
        if rec
            .actions
            .iter()
            .any(|a| a == "take_off")
        {
            Ok(())
        } else {
            Err(LaunchRefusal::NoTakeOff {
                actions: rec.actions.join("+"),
            })
        }
    }

    fn new_flight(&mut self) {
        self.phase = Script::OnGround;
        self.avoid_until = 0.0;
    }

    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        let alt = obs.get("altitude_m").unwrap_or(0.0);
        let battery = obs.get("battery_pct").unwrap_or(100.0);
        let seq = obs.get("mission_seq").unwrap_or(0.0) as u16;
        let speed = obs.get("groundspeed_mps").unwrap_or(0.0);
        let obstacle = obs.events.iter().any(|e| e == "obstacle detected");
        let airborne = alt > 0.8 * self.takeoff_alt_m;
        let action = if battery <= self.low_battery_pct && self.phase != Script::Landing {
            self.phase = Script::Return;
            "return_to_base"
        } else {
            match self.phase {
                Script::OnGround if airborne => {
                    self.phase = Script::Route;
                    "follow_trajectory"
                }
                Script::OnGround => "take_off",
                Script::Route if obstacle => {
                    self.phase = Script::Sidestep;
                    self.avoid_until = obs.time_s + 5.0;
                    "avoid_obstacle"
                }
                Script::Route if seq >= self.last_seq && speed < 1.0 => {
                    self.phase = Script::Landing;
                    "land"
                }
                Script::Route => "follow_trajectory",
                Script::Sidestep if obs.time_s >= self.avoid_until => {
                    self.phase = Script::Route;
                    "follow_trajectory"
                }
                Script::Sidestep => "avoid_obstacle",
                Script::Return => "return_to_base",
                Script::Landing => "land",
            }
        };
        let plan = Plan {
            vehicle_actions: vec![action.to_string()],
            applications: vec![],
        };
        let rec = DecisionRecord {
            state: self.phase.name().to_string(),
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
        o.events = events.iter().map(|s| Event::from(*s)).collect();
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
    fn an_event_flood_is_coalesced_into_one_bounded_list() {
        let mut ev: Vec<Event> = (0..10_000)
            .map(|i| Event::Mode(if i % 2 == 0 { "AUTO" } else { "GUIDED" }.into()))
            .collect();
        ev.push(Event::ObstacleDetected);
        coalesce_events(&mut ev);
        assert_eq!(
            ev[..3],
            [
                Event::Mode("AUTO".into()),
                Event::Mode("GUIDED".into()),
                Event::ObstacleDetected
            ]
        );
        assert_eq!(ev.len(), 4);
        assert!(ev[3].to_string().contains("9998 repeats"), "{}", ev[3]);
        let mut many: Vec<Event> = (0..500).map(Event::Waypoint).collect();
        coalesce_events(&mut many);
        assert_eq!(many.len(), MAX_EVENTS + 1);
        assert!(
            many[MAX_EVENTS].to_string().contains("436 not listed"),
            "{}",
            many[MAX_EVENTS]
        );
        let mut few = vec![Event::from("a"), Event::from("b")];
        coalesce_events(&mut few);
        assert_eq!(few, ["a", "b"]);
    }

    fn test_shell() -> Shell {
        let args =
            FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"]).unwrap();
        Shell::new(&FlySetup::load(&args).unwrap())
    }

    #[test]
    fn behaviour_text_names_the_tracking_state_the_plan_keeps() {
        let mut shell = test_shell();
        let rec = |actions: &[&str]| DecisionRecord {
            actions: actions.iter().map(|a| a.to_string()).collect(),
            ..Default::default()
        };
        let text = shell
            .behaviour_text(
                &rec(&["follow_trajectory", "track_v3"]),
                Some("follow_trajectory"),
            )
            .unwrap();
        assert_eq!(text, "Flying the route, tracking with V3");
        // detect_target runs the tracking application but keeps no tracking state.
        let text = shell
            .behaviour_text(
                &rec(&["follow_trajectory", "detect_target"]),
                Some("follow_trajectory"),
            )
            .unwrap();
        assert_eq!(text, "Flying the route");
    }

    /// The landing the shell keeps flying (the MDPs plan nothing in `landing`) is told as a
    /// landing, once, not as "hold (mode LAND)" and not once a cycle.
    #[test]
    fn a_kept_landing_is_told_once_as_a_landing() {
        let mut shell = test_shell();
        let flying = DecisionRecord {
            actions: vec!["follow_trajectory".into()],
            ..Default::default()
        };
        assert!(
            shell
                .behaviour_text(&flying, Some("follow_trajectory"))
                .is_some()
        );
        let landing = DecisionRecord {
            state: "landing".into(),
            shell_actions: vec!["land".into()],
            events: vec![Event::Mode("LAND".into())],
            observations: [("zone_found".to_string(), 0.0)].into_iter().collect(),
            ..Default::default()
        };
        assert_eq!(
            shell.behaviour_text(&landing, Some("land")).as_deref(),
            Some("Landing here")
        );
        for _ in 0..5 {
            assert_eq!(shell.behaviour_text(&landing, Some("land")), None);
        }
    }

    /// The guarantee's verdict is said when it changes: its amounts changing every cycle (the
    /// margins of a vehicle on the ground) say nothing more.
    #[test]
    fn the_guarantee_verdict_is_said_once_per_change() {
        use companion_core::record::GuaranteeRecord;
        let mut shell = test_shell();
        let rec = |infeasible: bool, energy: f64| DecisionRecord {
            guarantee: Some(GuaranteeRecord {
                margins: [("energy_j".to_string(), energy)].into_iter().collect(),
                infeasible,
                infeasible_reason: infeasible
                    .then(|| format!("negative energy_j margin {energy:.1}: no allocation")),
                ..Default::default()
            }),
            ..Default::default()
        };
        assert!(shell.guarantee_change(&rec(false, 100.0)).is_none());
        let (line, severity, text) = shell.guarantee_change(&rec(true, -4210.0)).unwrap();
        assert_eq!(severity, WARNING);
        assert!(line.contains("negative energy_j margin -4210.0"), "{line}");
        assert_eq!(text, "Cannot meet goals: energy short 4.2 kJ");
        for cycle in 0..30 {
            assert!(
                shell
                    .guarantee_change(&rec(true, -4210.0 - cycle as f64))
                    .is_none(),
                "cycle {cycle}"
            );
        }
        let (_, severity, text) = shell.guarantee_change(&rec(false, 50.0)).unwrap();
        assert_eq!(
            (severity, text.as_str()),
            (NOTICE, "Goals can be met again")
        );
        assert!(shell.guarantee_change(&rec(true, -10.0)).is_some());
    }

    #[test]
    fn policy_values_are_the_names_params_declare() {
        let model = crate::params::load_model(&crate::params::default_params_dir()).unwrap();
        for name in ["safety", "mission"] {
            let p = model.policy(name).unwrap();
            assert_eq!(model.policy_name(p), name);
        }
        let e = model.policy("yolo").unwrap_err();
        assert!(
            e.contains("unknown policy `yolo`") && e.contains("safety"),
            "{e}"
        );
    }
}
