//! The fly loop: one task that owns the protocol state ([`Vehicle`]), the clock and the decision
//! cycles, with one method per event source (the autopilot link, the onboard link, the timers,
//! the operator) and the stop. The cycle itself is [`super::cycle`]; the operator gate's shell
//! side is [`super::gate`].

use super::cycle::run_cycle_at;
use super::shell::Shell;
use super::transport::{self, Inbound, TransportHandle};
use super::{
    Decider, FlyArgs, FlyReport, FlySetup, INFO, NOTICE, RecordSink, Tlog, WARNING, gate,
    link_security, send, stop,
};
use super::{restart, watchdog};
use companion_core::record::{Event, LinkEvent, OperatorEvent};
use companion_link::Msg;
use companion_link::ingest::{self, Encoder, Ingest};
use companion_link::operator::{Control, OperatorGate};
use companion_link::url::ConnectUrl;
use companion_link::vehicle::Vehicle;
use std::time::Duration;
use tokio::time::Instant;

/// Why the loop ended without an error (said in the stop's record and to the ground station).
type StopReason = &'static str;

/// Transports retry a failed connection this often.
const RETRY: Duration = Duration::from_secs(1);

/// How long the stop waits for the autopilot's answer to the hand-off mode (within systemd's
/// TimeoutStopSec in deploy/companion.service, and the 5 s a pilot can be asked to wait).
const HANDOFF_WAIT: Duration = Duration::from_millis(4500);

/// Beyond the ACK timeout, how long the stop waits for the answer to the companion's last ARM
/// or take-off (an answer sent just before the timeout is still on its way).
const LAUNCH_WAIT_MARGIN: Duration = Duration::from_millis(500);

/// The fly loop's state: everything one `fly` run owns.
pub(super) struct RunLoop<'s, D, S> {
    args: FlyArgs,
    setup: FlySetup,
    decider: D,
    sink: &'s mut S,
    tlog: Option<Tlog>,
    shell: Shell,
    vehicle: Vehicle,
    stations: gate::GroundStations,
    link_security: link_security::LinkSecurity,
    ingest: Ingest,
    encoder: Encoder,
    link: TransportHandle,
    udp_peer: transport::UdpPeer,
    link_failures: transport::FailureLines,
    onboard_failures: transport::FailureLines,
    /// Receive-only, but the handle (and its outbound sender) must live as long as the loop.
    onboard: Option<TransportHandle>,
    onboard_ingest: Ingest,
    onboard_udpin: bool,
    start: Instant,
    report: FlyReport,
    transport_events: Vec<LinkEvent>,
    min_gap: Duration,
    last_cycle_at: Option<Duration>,
    /// Events held back by the cycle rate limit: the earliest one's time, and when the next
    /// cycle may run.
    held_trigger: Option<Duration>,
    cycle_due: Option<Duration>,
    was_alive: bool,
    announced_auto_start: bool,
    gcs: GcsWatch,
    /// What the vehicle was doing when the companion started (a flight in progress is handed
    /// off, never waited on).
    start_look: restart::StartLook,
    /// systemd's watchdog (a no-op outside systemd), and when the last decision cycle ended.
    watchdog: watchdog::Watchdog,
    last_cycle_done: Option<Duration>,
    /// `--mission autopilot`: the autopilot's mission is planned as it is downloaded.
    autopilot_plan: Option<super::autopilot_plan::AutopilotPlan>,
    /// The companion's own route: re-planned at the autopilot's cruise speed on the ground.
    route_replan: Option<super::route_replan::RouteReplan>,
    /// A route relative to home among absolute zones: planned once home is known.
    home_plan: Option<super::home_plan::HomePlan>,
}

impl<'s, D: Decider, S: RecordSink> RunLoop<'s, D, S> {
    /// Set up the run (the operator gate, the vehicle, the transports) and say how it will start.
    pub(super) fn new(
        args: FlyArgs,
        mut setup: FlySetup,
        decider: D,
        sink: &'s mut S,
        tlog: Option<Tlog>,
    ) -> Self {
        let start_look =
            restart::StartLook::new(setup.link.flight.restart_in_air, setup.previous_run.take());
        let mut shell = Shell::new(&setup);
        shell.operator = OperatorGate::new(args.auto_start);
        shell.operator.confirm = Duration::from_secs_f64(setup.link.flight.operator_confirm_s);
        shell.operator.start_on_arm = args.start_on_arm;
        announce_start(&args);
        let mut vehicle = setup
            .vehicle(args.link_timeout)
            .obeying(args.autopilot_sysid, args.autopilot_compid);
        let autopilot_plan = setup.autopilot_speeds.map(|speeds| {
            vehicle.watch_autopilot_mission();
            super::autopilot_plan::AutopilotPlan::new(
                setup.files.clone(),
                speeds,
                setup.autopilot_zones.clone(),
                setup.states.clone(),
                &mut shell,
            )
        });
        let route_replan = super::route_replan::RouteReplan::new(&args, &setup.files);
        let home_plan = super::home_plan::HomePlan::new(&setup, &args, &mut shell);
        let signing = || setup.key.map(ingest::signing_data);
        tracing::info!(url = %args.connect, "connecting to the autopilot");
        Self {
            stations: gate::GroundStations {
                pinned: args.gcs_sysid.iter().copied().collect(),
                ..Default::default()
            },
            link_security: link_security::LinkSecurity::start(&args, setup.key.is_some()),
            ingest: Ingest::new(signing()),
            encoder: Encoder::new(signing()),
            link: transport::spawn(args.connect.clone(), RETRY),
            udp_peer: transport::UdpPeer::default(),
            link_failures: transport::FailureLines::new(Duration::from_secs(10)),
            onboard_failures: transport::FailureLines::new(Duration::from_secs(10)),
            onboard: args.onboard.clone().map(|u| transport::spawn(u, RETRY)),
            onboard_ingest: Ingest::new(signing()),
            onboard_udpin: matches!(args.onboard, Some(ConnectUrl::UdpIn { .. })),
            start: Instant::now(),
            report: FlyReport::default(),
            transport_events: Vec::new(),
            min_gap: Duration::from_secs_f64(setup.link.flight.min_event_cycle_interval_s),
            last_cycle_at: None,
            held_trigger: None,
            cycle_due: None,
            was_alive: false,
            announced_auto_start: false,
            gcs: GcsWatch::default(),
            start_look,
            watchdog: watchdog::Watchdog::from_env(setup.link.decision_period_s),
            last_cycle_done: None,
            autopilot_plan,
            route_replan,
            home_plan,
            args,
            setup,
            decider,
            sink,
            tlog,
            shell,
            vehicle,
        }
    }

    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    /// Run until `--duration`, a signal, `--once`'s landing or an error; then the stop.
    pub(super) async fn run(self) -> anyhow::Result<FlyReport> {
        self.run_until(std::future::pending()).await
    }

    /// [`RunLoop::run`], also ending when `stop` completes (a caller's own stop condition).
    pub(super) async fn run_until(
        mut self,
        stop: impl std::future::Future<Output = ()>,
    ) -> anyhow::Result<FlyReport> {
        let outcome = self.turns(stop).await;
        self.stop(outcome).await
    }

    /// The loop's turns: wait for the next event, handle it, answer the operator, send, and
    /// run a decision cycle when one is due.
    async fn turns(
        &mut self,
        stop: impl std::future::Future<Output = ()>,
    ) -> anyhow::Result<StopReason> {
        tokio::pin!(stop);
        let mut heartbeat = tokio::time::interval(Duration::from_secs(1));
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        let mut periodic =
            tokio::time::interval(Duration::from_secs_f64(self.setup.link.decision_period_s));
        periodic.tick().await; // the first tick is immediate; the first cycle waits for telemetry
        let stop_at = self.args.duration.map(|d| self.start + d);
        let connect_by = self.args.connect_timeout.map(|d| self.start + d);
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        let terminate = terminate_signal();
        tokio::pin!(terminate);
        self.watchdog.ready();
        loop {
            let mut out: Vec<Msg> = Vec::new();
            let mut trigger: Option<Duration> = None;
            let mut wake = false;
            let connect_wait = connect_by.filter(|_| self.vehicle.target().is_none());
            let due = self.cycle_due.map(|t| self.start + t);
            tokio::select! {
                m = self.link.inbound.recv() => trigger = self.on_link(m, &mut out)?,
                m = recv_opt(&mut self.onboard) => trigger = self.on_onboard(m)?,
                _ = heartbeat.tick() => out.push(Vehicle::heartbeat()),
                _ = tick.tick() => {
                    let t = self.now();
                    out.extend(self.vehicle.tick(t));
                }
                _ = periodic.tick() => self.on_period().await?,
                _ = sleep_until_opt(connect_wait) => return Err(self.no_autopilot()),
                _ = sleep_until_opt(due) => {
                    self.cycle_due = None;
                    wake = true;
                }
                _ = &mut ctrl_c => return Ok("SIGINT"),
                _ = &mut terminate => return Ok("SIGTERM"),
                _ = sleep_until_opt(stop_at) => return Ok("--duration elapsed"),
                _ = &mut stop => return Ok("stop requested by the caller"),
            }
            wake |= self.on_operator(&mut out);
            let t = self.now();
            if let Some(plan) = self.autopilot_plan.as_mut() {
                if let Some(m) = self.vehicle.take_autopilot_mission() {
                    plan.on_mission(m, &self.vehicle, &mut self.decider, &mut self.shell);
                    wake = true;
                }
                plan.recheck(&self.vehicle, &mut self.decider, &mut self.shell);
                out.extend(plan.say(&mut self.shell, t));
            }
            if let Some(plan) = self.route_replan.as_mut() {
                plan.recheck(&self.vehicle, &mut self.decider, &mut self.shell);
                out.extend(plan.say(&mut self.shell, t));
            }
            if let Some(plan) = self.home_plan.as_mut() {
                plan.recheck(&self.vehicle, &mut self.decider, &mut self.shell);
                out.extend(plan.say(&mut self.shell, t));
            }
            let t = self.now();
            out.extend(self.link_security.check(
                t,
                &self.vehicle,
                &self.ingest.stats,
                &mut self.shell.texts,
            ));
            self.send(&out).await;
            self.vehicle.stamp_latency(trigger.unwrap_or(t), self.now());
            self.maybe_cycle(trigger, wake).await?;
            // The turn ended: systemd hears the loop is alive (its cycles too).
            let (t, known) = (self.now(), self.vehicle.target().is_some());
            self.watchdog.turn(t, known, self.last_cycle_done);
            if self.shell.finished()
                && let Some(why) = self.flight_over().await
            {
                return Ok(why);
            }
        }
    }

    /// Frames, connects and disconnects on the autopilot link; the frames' arrival time when
    /// frames came (a cycle may be triggered by them).
    fn on_link(
        &mut self,
        m: Option<Inbound>,
        out: &mut Vec<Msg>,
    ) -> anyhow::Result<Option<Duration>> {
        match m {
            Some(Inbound::Bytes(b)) => {
                let t = self.now();
                for f in self.ingest.push(&b) {
                    self.on_autopilot_frame(t, &f, out);
                }
                self.ingest.set_our_system(self.vehicle.our_system());
                self.shell.set_ingest(self.ingest.stats);
                return Ok(Some(t));
            }
            Some(Inbound::Datagram(b, from)) => {
                let t = self.now();
                // Each datagram is parsed on its own (MAVLink over UDP sends whole frames per
                // datagram): a frame is then surely the sender's, and a junk datagram's half
                // header cannot swallow or re-attribute the autopilot's next frames.
                self.ingest.reset();
                for f in self.ingest.push(&b) {
                    self.on_autopilot_frame(t, &f, out);
                    // Replies go to the autopilot's address, learned from its own frames only.
                    let src = (f.header.system_id.min(255) as u8, f.header.component_id);
                    let autopilot = (self.vehicle.target() == Some(src)).then_some(src);
                    if let Some(ev) = self.udp_peer.on_frame(from, autopilot) {
                        tracing::info!("{ev}");
                        let _ = self.link.peer.send(self.udp_peer.addr);
                        self.transport_events.push(LinkEvent::Other(ev));
                    }
                }
                self.ingest.set_our_system(self.vehicle.our_system());
                self.shell.set_ingest(self.ingest.stats);
                return Ok(Some(t));
            }
            Some(Inbound::Connected(name)) => {
                self.ingest.reset();
                let t = self.now();
                self.vehicle.on_reconnect(t);
                if let Some(line) = self.link_failures.connected(&name) {
                    tracing::info!("autopilot link: {line}");
                }
                self.transport_events
                    .push(LinkEvent::TransportConnected(name.to_string()));
            }
            Some(Inbound::Disconnected(why)) => {
                // One line (tracing writes to stderr, the journal), not one per retry.
                if let Some(line) = self.link_failures.failed(self.now(), &why, RETRY) {
                    tracing::warn!("autopilot link {}: {line}", self.args.connect);
                }
                self.transport_events
                    .push(LinkEvent::TransportDisconnected(why.to_string()));
            }
            None => anyhow::bail!("the transport task stopped"),
        }
        Ok(None)
    }

    /// One frame from the autopilot link: the tlog, the ground station watches, the vehicle.
    fn on_autopilot_frame(&mut self, t: Duration, f: &ingest::Frame, out: &mut Vec<Msg>) {
        if let Some(w) = self.tlog.as_mut() {
            w.received(f);
        }
        if let Some(heard) = self.stations.on_frame(f) {
            tracing::warn!("{heard}");
            self.shell.pending_events.push(Event::Operator(heard));
        }
        // Only the operator's ground stations count for the ground-station watch.
        if self.stations.counts(f.header.system_id.min(255) as u8) {
            self.gcs.on_frame(t, f);
        }
        out.extend(self.vehicle.on_frame(t, f));
    }

    /// Frames, connects and disconnects on the onboard link (receive-only: a udpin onboard link
    /// never learns a reply address).
    fn on_onboard(&mut self, m: Option<Inbound>) -> anyhow::Result<Option<Duration>> {
        match m {
            Some(Inbound::Bytes(b) | Inbound::Datagram(b, _)) => {
                let t = self.now();
                if self.onboard_udpin {
                    // One datagram, whole frames: parsed on its own (as on the autopilot link).
                    self.onboard_ingest.reset();
                }
                for f in self.onboard_ingest.push(&b) {
                    if let Some(w) = self.tlog.as_mut() {
                        w.received(&f);
                    }
                    self.vehicle.on_monitor_frame(t, &f);
                }
                return Ok(Some(t));
            }
            Some(Inbound::Connected(name)) => {
                self.onboard_ingest.reset();
                if let Some(line) = self.onboard_failures.connected(&name) {
                    tracing::info!("onboard link: {line}");
                }
                self.transport_events
                    .push(LinkEvent::OnboardConnected(name.to_string()));
            }
            Some(Inbound::Disconnected(why)) => {
                if let Some(line) = self.onboard_failures.failed(self.now(), &why, RETRY) {
                    tracing::warn!("onboard link: {line}");
                }
                self.transport_events
                    .push(LinkEvent::OnboardDisconnected(why.to_string()));
            }
            None => anyhow::bail!("the onboard transport task stopped"),
        }
        Ok(None)
    }

    /// The periodic decision cycle (once the autopilot is known).
    async fn on_period(&mut self) -> anyhow::Result<()> {
        if self.vehicle.target().is_some() {
            let t = self.held_trigger.take().unwrap_or_else(|| self.now());
            self.cycle_due = None;
            self.run_cycle(t).await?;
            self.last_cycle_at = Some(self.now());
        }
        Ok(())
    }

    /// `--connect-timeout` passed with no autopilot heard.
    fn no_autopilot(&self) -> anyhow::Error {
        let waited = self.args.connect_timeout.unwrap_or_default();
        let msg = format!(
            "no autopilot HEARTBEAT on {} within {:?} (--connect-timeout){}",
            self.args.connect,
            waited,
            if self.vehicle.other_autopilot_heartbeats() > 0 {
                "; other autopilots were heard, see --autopilot-sysid"
            } else {
                ""
            }
        );
        tracing::error!("{msg}");
        anyhow::anyhow!(msg)
    }

    /// The operator and the ground station, every turn: commands addressed to us (answered
    /// before the autopilot is known too: refused then, never queued for later), the gate's
    /// look at the vehicle, the link's state, the waiting reminder, the GCS watch. True when
    /// the gate changed (a cycle should run now).
    fn on_operator(&mut self, out: &mut Vec<Msg>) -> bool {
        let t = self.now();
        let mut wake = false;
        // A vehicle found flying when the companion started: said and handed off, before the
        // gate may take any start (an --auto-start of this run included).
        if self.vehicle.target().is_some() {
            wake |= self.start_look.look(
                &mut self.shell,
                &mut self.vehicle,
                self.setup.link.flight.handoff,
                t,
                out,
            );
        }
        let undecided =
            self.vehicle.target().is_some() && self.start_look.found == restart::AtStart::Undecided;
        for cmd in self.vehicle.take_commands_to_us() {
            if undecided && cmd.command == companion_link::operator::START_COMMAND {
                // Armed, and not yet known to be on the ground: no start, whatever the models say.
                wake |= restart::refuse_start_until_known(&mut self.shell, &cmd, t, out);
                continue;
            }
            // The operator's consent to resume a flight found in progress: a start the gate's
            // rules accept (an accepted ground station, not stale), answered here.
            if self.start_look.awaits_consent()
                && cmd.command == companion_link::operator::START_COMMAND
                && gate::start_acceptable(
                    &cmd,
                    t,
                    self.shell.command_max_age,
                    &self.vehicle,
                    &self.stations,
                )
            {
                let from = cmd.from;
                if self
                    .start_look
                    .consent(&mut self.shell, &mut self.vehicle, from, t, out)
                {
                    out.push(companion_link::operator::ack(
                        cmd.command,
                        companion_link::dialect::MavResult::MAV_RESULT_ACCEPTED,
                        from,
                    ));
                    wake = true;
                    continue;
                }
            }
            wake |= gate::answer_command(
                &mut self.shell,
                &mut self.vehicle,
                &self.stations,
                cmd,
                t,
                out,
            );
        }
        if self.vehicle.target().is_none() {
            return wake;
        }
        // A pilot's arming, GUIDED or mode change; a start voided.
        if self.start_look.found != restart::AtStart::Undecided {
            wake |= gate::observe(&mut self.shell, &mut self.vehicle, t, out);
        }
        let alive = self.vehicle.liveness().alive();
        if alive != self.was_alive {
            if alive {
                tracing::info!("autopilot link up");
            } else {
                tracing::warn!("autopilot link lost: no commands until it is back");
            }
            self.was_alive = alive;
        }
        if alive {
            if self.args.auto_start && !self.announced_auto_start {
                self.announced_auto_start = true;
                out.extend(self.shell.texts.say(
                    t,
                    WARNING,
                    "companion: AUTO-START, arms without operator",
                ));
            }
            if self.shell.operator.control == Control::Waiting
                && self.start_look.may_wait_for_operator()
            {
                out.extend(self.shell.texts.say(
                    t,
                    INFO,
                    "companion ready, waiting for the operator",
                ));
            }
        }
        if let Some(lost) = self.gcs.check(t) {
            let heard = if lost {
                OperatorEvent::GroundStationLost
            } else {
                OperatorEvent::GroundStationBack
            };
            if lost {
                tracing::warn!("{heard}");
            } else {
                tracing::info!("{heard}");
            }
            out.extend(self.shell.texts.say(
                t,
                if lost { WARNING } else { INFO },
                &format!("companion: {heard}"),
            ));
            self.shell.pending_events.push(Event::Operator(heard));
        }
        wake
    }

    /// Significant telemetry (a new obstacle, a found target, a crossed battery threshold, a
    /// mode change, a command result, link loss) or a gate change triggers a cycle now, but no
    /// sooner than `min_event_cycle_interval_s` after the last one: events in between wait for
    /// it. Link loss found by the protocol tick counts too (its trigger is the tick itself).
    async fn maybe_cycle(&mut self, trigger: Option<Duration>, wake: bool) -> anyhow::Result<()> {
        let pending = self.vehicle.has_events() || wake || self.held_trigger.is_some();
        if !pending || self.vehicle.target().is_none() {
            return Ok(());
        }
        let t_now = self.now();
        let first = *self.held_trigger.get_or_insert(trigger.unwrap_or(t_now));
        let due = self
            .last_cycle_at
            .map_or(Duration::ZERO, |l| l + self.min_gap);
        if t_now < due {
            self.cycle_due = Some(due);
            return Ok(());
        }
        self.held_trigger = None;
        self.cycle_due = None;
        self.last_cycle_at = Some(t_now);
        self.run_cycle(first).await
    }

    /// One decision cycle triggered at `t`, its commands sent and its record written.
    async fn run_cycle(&mut self, t: Duration) -> anyhow::Result<()> {
        let start = self.start;
        let done = run_cycle_at(
            &mut self.decider,
            &mut self.shell,
            &mut self.vehicle,
            &mut self.encoder,
            &self.link.outbound,
            &mut self.tlog,
            self.sink,
            t,
            move || start.elapsed(),
            &mut self.report,
            &mut self.transport_events,
        )
        .await;
        if done.is_ok() {
            self.last_cycle_done = Some(self.now());
        }
        done
    }

    /// Flew, landed and disarmed: the flight is over (one last cycle recorded it). Wait for the
    /// operator's next start (None), or stop with `--once`.
    async fn flight_over(&mut self) -> Option<StopReason> {
        if self.args.once {
            tracing::info!("flight over: landed and disarmed; exiting (--once)");
            return Some("flight over (--once)");
        }
        tracing::info!("flight over: landed and disarmed; waiting for the operator");
        let t = self.now();
        self.vehicle.stop_actions(t, "flight over");
        self.shell.new_flight();
        self.decider.new_flight();
        let msgs = self.shell.texts.say(
            self.now(),
            NOTICE,
            "companion: landed; waiting for the operator",
        );
        self.send(&msgs).await;
        None
    }

    /// The stop: what the companion was doing ends (its pending steps cancelled), the answer to
    /// its own last ARM or take-off still in flight is awaited a moment, then it is said to the
    /// ground station, and a vehicle the companion commands or launched that is (or may be)
    /// armed or in the air is handed to the autopilot (params/link.toml `[flight] handoff`), its
    /// answer awaited a moment, and a last record says so. Then the loop's report, or its error.
    async fn stop(mut self, outcome: anyhow::Result<StopReason>) -> anyhow::Result<FlyReport> {
        self.watchdog.stopping();
        let why = match &outcome {
            Ok(why) => (*why).to_string(),
            Err(e) => format!("error: {e:#}"),
        };
        let t = self.now();
        self.vehicle.stop_commanding(t, "companion stopping");
        self.await_launch(&why).await;
        let t = self.now();
        let landed_confirm = Duration::from_secs_f64(self.setup.link.flight.landed_confirm_s);
        let (msgs, stopped) = stop::begin_stop(
            &mut self.shell,
            &mut self.vehicle,
            self.setup.link.flight.handoff,
            &why,
            t,
            landed_confirm,
        );
        self.send(&msgs).await;
        if stopped.commanded {
            self.await_handoff().await;
            let t = self.now();
            let msgs = stop::end_stop(&mut self.shell, &self.vehicle, true, t);
            self.send(&msgs).await;
        }
        // A last record: the vehicle is (or may be) up, or a start in progress ended.
        if stopped.up || (stopped.was_commanding && !self.shell.finished()) {
            let t = self.now();
            if let Err(e) = self.run_cycle(t).await {
                tracing::error!("the stop's record was not written: {e:#}");
            }
        }
        if !msgs.is_empty() {
            // Let the transport write the stop's words before the process ends.
            tokio::time::sleep(Duration::from_millis(300)).await;
        }
        outcome?;
        self.report.ingest = self.ingest.stats;
        self.report.frames_out = self.encoder.frames_out;
        self.report.link_losses = self.vehicle.liveness().losses;
        Ok(self.report)
    }

    /// The answer to the companion's own ARM or take-off still in flight when it stops, for at
    /// most the command's ACK timeout and [`LAUNCH_WAIT_MARGIN`]: whether the vehicle armed or
    /// took off decides the hand-off. Never resent meanwhile.
    async fn await_launch(&mut self, why: &str) {
        if !self.vehicle.launch_awaiting() {
            return;
        }
        let wait = self.vehicle.cfg().command.ack_timeout + LAUNCH_WAIT_MARGIN;
        tracing::info!(
            "companion stopping ({why}): waiting up to {:.1} s for the answer to its last ARM or take-off",
            wait.as_secs_f64()
        );
        self.await_link_until(wait, |v| !v.launch_awaiting()).await;
    }

    /// The autopilot's answer to the hand-off mode, for at most [`HANDOFF_WAIT`]: the link and
    /// the protocol tick go on meanwhile (the step is resent, acknowledged or fails as any other).
    async fn await_handoff(&mut self) {
        self.await_link_until(HANDOFF_WAIT, |v| v.handoff_status().is_some())
            .await;
    }

    /// Only the autopilot link and the protocol tick, until `done` or `wait` has passed (the
    /// stop's waits: no decision cycle, no operator).
    async fn await_link_until(&mut self, wait: Duration, done: impl Fn(&Vehicle) -> bool) {
        let deadline = Instant::now() + wait;
        let mut tick = tokio::time::interval(Duration::from_millis(100));
        while !done(&self.vehicle) {
            let mut out = Vec::new();
            tokio::select! {
                m = self.link.inbound.recv() => match m {
                    None => break,
                    m => {
                        let _ = self.on_link(m, &mut out);
                    }
                },
                _ = tick.tick() => {
                    let t = self.now();
                    out.extend(self.vehicle.tick(t));
                }
                _ = tokio::time::sleep_until(deadline) => break,
            }
            self.send(&out).await;
        }
    }

    async fn send(&mut self, msgs: &[Msg]) {
        send(
            &mut self.encoder,
            &self.vehicle,
            &self.link.outbound,
            &mut self.tlog,
            msgs,
        )
        .await;
    }
}

/// How this run will start, on stderr and in the journal.
fn announce_start(args: &FlyArgs) {
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
}

/// The next message of a transport that may be absent (never, then).
async fn recv_opt(h: &mut Option<TransportHandle>) -> Option<Inbound> {
    match h {
        Some(h) => h.inbound.recv().await,
        None => std::future::pending().await,
    }
}

/// Sleep until `t`, or for ever.
async fn sleep_until_opt(t: Option<Instant>) {
    match t {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

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

    /// Whether the ground station is lost (true) or back (false), when that changed.
    fn check(&mut self, now: Duration) -> Option<bool> {
        let silent = self
            .last
            .is_some_and(|t| now.saturating_sub(t) > Self::TIMEOUT);
        if silent && !self.lost {
            self.lost = true;
            return Some(true);
        }
        if !silent && self.lost {
            self.lost = false;
            return Some(false);
        }
        None
    }
}
