//! `companion fly`: the imperative shell around the link protocol and the decision core.
//!
//! Tasks: the transport supervisor(s) (bytes in/out, reconnect), and one loop that owns the
//! protocol state ([`Vehicle`]), the clock, the 1 Hz heartbeat, the 10 Hz protocol tick and the
//! decision cycles: one on every significant event, and one every `decision_period_s` otherwise.
//! Each cycle's record goes to a [`RecordSink`] with the commands it sent (latency measured from
//! the message that triggered the cycle to the command handed to the transport) and the results
//! of earlier commands that finished since.
//!
//! The operator decides when to fly ([`companion_link::operator`], [`gate`]): until a ground
//! station sends the start command (or the pilot switches to GUIDED, or arms with
//! `--start-on-arm`) and the models agree, cycles decide and log but command no motion; a
//! pilot's mode change stops the commanding until control is handed back. After a flight ends
//! landed and disarmed, `fly` waits for the operator again (`--once` exits instead). Stopped in
//! flight, it hands the vehicle to the autopilot.
//!
//! Files: `args` (the command line), `setup` (params loaded before any socket), `run_loop` (the
//! loop, one method per event source, and the stop), `cycle` (one decision cycle), `shell` (what
//! is kept between cycles), `gate` (the operator gate's shell side), `words` (texts for the
//! ground station), `link_security` (signing warnings), `transport` (bytes in and out),
//! `restart` (started next to a vehicle already flying: said, handed off or resumed on the
//! operator's consent, never waited on), `resume` (the proof that such a flight is its own),
//! `watchdog` (systemd's READY=1, WATCHDOG=1 from the loop, STOPPING=1).

mod args;
mod autopilot_plan;
mod cycle;
pub mod gate;
mod home_plan;
pub mod link_security;
mod restart;
mod resume;
pub mod route_progress;
mod route_replan;
mod run_loop;
#[cfg(test)]
mod said;
mod setup;
mod shell;
pub mod stop;
pub mod transport;
mod watchdog;
pub mod words;

pub use crate::vocabulary::DERIVED_OBSERVATIONS;
pub use args::FlyArgs;
pub use cycle::{Decided, decide, finish_record};
pub use setup::FlySetup;
pub use shell::Shell;

use anyhow::Context;
use companion_core::launch::LaunchRefusal;
use companion_core::mission::ActionCatalogue;
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};
use companion_link::Msg;
use companion_link::ingest::{self, Encoder};
use companion_link::vehicle::Vehicle;
use run_loop::RunLoop;
use std::io::Write;

/// The decision core as the shell sees it: one observation snapshot in, one plan and its record out.
pub trait Decider {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord);
    /// The catalogue the plan's action ids index (names for the record, the commands table).
    fn actions(&self) -> &ActionCatalogue;
    /// Do the models agree to a start, judged from this record (the launch verdict,
    /// [`companion_core::launch::verdict`])?
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal>;
    /// A new flight begins (the last one ended landed and disarmed): forget the last one.
    fn new_flight(&mut self) {}
    /// Guarantee `spec` from now on (`fly --mission autopilot`: the autopilot's mission as
    /// planned, again after it changed), this flight and the next ones; `false` when it has no
    /// allocation at all or the decider plans no mission.
    fn replace_mission(&mut self, _spec: companion_core::guarantee::MissionSpec) -> bool {
        false
    }
    /// A mission changed in flight, guaranteed from the point reached: `spliced`'s first
    /// `flown` activities are those flown (what they spent stays counted), the rest the new
    /// mission from where the vehicle is; `whole` (the new mission from home) is planned for the
    /// next flights. By default the whole mission is planned afresh.
    fn replan_from(
        &mut self,
        whole: companion_core::guarantee::MissionSpec,
        _spliced: companion_core::guarantee::MissionSpec,
        _flown: usize,
    ) -> bool {
        self.replace_mission(whole)
    }
}

/// The one decision core of every driver (fly, simulate, soak, fuzzing): it learns and starts
/// afresh between flights.
impl Decider for crate::decider::CoreDecider {
    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        self.step_flown(obs)
    }
    fn actions(&self) -> &ActionCatalogue {
        &self.model().actions
    }
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal> {
        companion_core::launch::verdict(rec, self.model())
    }
    fn new_flight(&mut self) {
        crate::decider::CoreDecider::new_flight(self)
    }
    fn replace_mission(&mut self, spec: companion_core::guarantee::MissionSpec) -> bool {
        crate::decider::CoreDecider::replace_mission(self, spec)
    }
    fn replan_from(
        &mut self,
        whole: companion_core::guarantee::MissionSpec,
        spliced: companion_core::guarantee::MissionSpec,
        flown: usize,
    ) -> bool {
        crate::decider::CoreDecider::replan_from(self, whole, spliced, flown)
    }
}

/// Where decision records go (the log helper provides the file writer).
pub trait RecordSink {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()>;
    /// [`RecordSink::write`] of a record the caller shares (`--live`): a sink that keeps records
    /// keeps this one without copying it.
    fn write_shared(&mut self, rec: std::sync::Arc<DecisionRecord>) -> std::io::Result<()> {
        self.write(&rec)
    }
    /// [`RecordSink::write_shared`], and records the caller lets go of: a sink with a thread of
    /// its own drops them there ([`crate::decision_log::LetGo`]); by default, here.
    fn write_shared_letting_go(
        &mut self,
        rec: std::sync::Arc<DecisionRecord>,
        let_go: crate::decision_log::LetGo,
    ) -> std::io::Result<()> {
        drop(let_go);
        self.write_shared(rec)
    }
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

/// The decision log as a record sink: records go to its writer thread (never blocking the loop).
pub struct LogSink(pub crate::decision_log::DecisionLog);

impl RecordSink for LogSink {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        // A full queue drops the record; the log itself says so with a `loss` line.
        self.0.record(rec.clone());
        Ok(())
    }
    fn write_shared(&mut self, rec: std::sync::Arc<DecisionRecord>) -> std::io::Result<()> {
        self.0.record_shared(rec);
        Ok(())
    }
    fn write_shared_letting_go(
        &mut self,
        rec: std::sync::Arc<DecisionRecord>,
        let_go: crate::decision_log::LetGo,
    ) -> std::io::Result<()> {
        self.0.record_letting_go(rec, let_go);
        Ok(())
    }
}

/// `--live`: the record written (with `live_dropped`), then served; without a hub, as it is.
impl<S: RecordSink> RecordSink for crate::live::LiveSink<S> {
    fn write(&mut self, rec: &DecisionRecord) -> std::io::Result<()> {
        let Some(rec) = self.stamp(rec) else {
            return self.inner.write(rec);
        };
        // Served, then logged with what the hub let go of (freed on the log's thread). What is
        // written never depends on the viewers: the record was stamped before either.
        let let_go = self.publish(std::sync::Arc::clone(&rec));
        self.inner.write_shared_letting_go(rec, let_go)
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

/// Blocking entry point for the CLI: a run folder under `--log-dir` with the decision log and
/// `flight.tlog`; the folder is printed first.
pub fn run<D: Decider>(args: FlyArgs, decider: D) -> anyhow::Result<()> {
    use crate::decision_log::{self as dlog, Header, TlogWriter, WriterOptions};
    // Params first: a start that fails on them leaves no run folder behind.
    let mut setup = FlySetup::load(&args)?;
    if setup.link.flight.restart_in_air
        == companion_link::restart_in_air::RestartInAir::ResumeWithConsent
    {
        // The previous run's log, before this run's own folder becomes the latest.
        setup.previous_run = Some(resume::read_previous_run(&args.log_dir));
    }
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
    header.plan = args.plan.clone();
    header.model = Some(companion_core::decision::ModelKind::Bfm.name().to_string());
    let opts = WriterOptions::from_env()?;
    // `--live` before the run folder (an address in use leaves none behind); messages stamped
    // as the export stamps them: the header's start plus `time_s`.
    let start_ns = crate::export::rfc3339_ns(&header.started_utc).unwrap_or(0);
    let live = crate::live::start(&args.live, start_ns)?;
    let mut log = dlog::start_run(&args.log_dir, now, header, opts.clone())
        .with_context(|| format!("starting a run folder in {}", args.log_dir.display()))?;
    let dir = log.dir().to_path_buf();
    // The folder's name comes from --log-dir: shown escaped.
    println!(
        "run folder: {}",
        crate::review::text::escape_controls(&dir.display().to_string(), false)
    );
    tracing::info!("run folder {}", dir.display());
    let tlog = TlogWriter::create(&dir.join("flight.tlog"))
        .with_context(|| format!("creating {}", dir.join("flight.tlog").display()))?
        .with_max_bytes(opts.max_bytes);
    // The tlog's cap is told like the decision log's: a loss line there, the end line, the exit.
    log.watch_tlog(tlog.capped_counter());
    // `--live`: served beside the loop, never waited on (crate::live).
    let mut sink = crate::live::LiveSink::new(LogSink(log), live.as_ref().map(|l| l.hub()));
    let result = rt.block_on(async {
        // Inside the runtime: the loop spawns its transport tasks as it starts.
        RunLoop::new(args, setup, decider, &mut sink, Some(Tlog(tlog)))
            .run()
            .await
    });
    let stats = sink.inner.0.close();
    let live_line = crate::live::finish(live);
    let report = result?;
    eprintln!(
        "companion fly: {} records {} dropped {} tlog_capped {}{live_line}",
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

/// [`run_with`], also ending, as `--duration` does (the stop and its hand-off), when `stop`
/// completes: a test ends the flight once what it checks has happened instead of after a fixed
/// time.
pub async fn run_until<D: Decider, S: RecordSink>(
    args: FlyArgs,
    decider: D,
    sink: &mut S,
    stop: impl std::future::Future<Output = ()>,
) -> anyhow::Result<FlyReport> {
    let setup = FlySetup::load(&args)?;
    RunLoop::new(args, setup, decider, sink, None)
        .run_until(stop)
        .await
}

/// [`run_with`], also writing every frame sent and received to `tlog`.
pub async fn run_with_tlog<D: Decider, S: RecordSink>(
    args: FlyArgs,
    decider: D,
    sink: &mut S,
    tlog: Option<Tlog>,
) -> anyhow::Result<FlyReport> {
    let setup = FlySetup::load(&args)?;
    RunLoop::new(args, setup, decider, sink, tlog).run().await
}

pub(super) async fn send(
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

pub(super) const INFO: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_INFO;
pub(super) const NOTICE: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_NOTICE;
pub(super) const WARNING: companion_link::dialect::MavSeverity =
    companion_link::dialect::MavSeverity::MAV_SEVERITY_WARNING;

#[cfg(test)]
mod tests {
    use super::*;

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

    fn rec(cycle: u64) -> DecisionRecord {
        DecisionRecord {
            cycle,
            ..Default::default()
        }
    }

    #[test]
    fn the_live_sink_writes_the_record_first_with_the_losses_so_far() {
        use std::sync::Arc;
        let hub = Arc::new(crate::live::Hub::new(1, 0));
        let (v, _wake) = hub.connect();
        hub.subscribed(&v, 1);
        let mut sink =
            crate::live::LiveSink::new(Vec::<DecisionRecord>::new(), Some(Arc::clone(&hub)));
        for c in 1..=3 {
            sink.write(&rec(c)).unwrap();
        }
        let lost: Vec<_> = sink.inner.iter().map(|r| r.live_dropped).collect();
        assert_eq!(lost, [Some(0), Some(0), Some(1)]);
        // Without a hub the record goes through as it is.
        let mut plain = crate::live::LiveSink::new(Vec::<DecisionRecord>::new(), None);
        plain.write(&rec(1)).unwrap();
        assert_eq!(plain.inner[0].live_dropped, None);
    }
}
