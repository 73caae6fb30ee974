//! The command executor: primitive vehicle actions turned into protocol steps (modes, arm,
//! commands, mission upload, repositions), one job at a time, and their records.

mod steps;

use super::*;
use std::collections::BTreeMap;

/// PX4: how long AUTO waits after an upload for MISSION_CURRENT to show the mission loaded and
/// valid; then AUTO is sent anyway (and confirmed, or sent again, as any mode).
const PX4_MISSION_VALID_WAIT: Duration = Duration::from_secs(10);
/// PX4: AUTO after MISSION_CURRENT first shows the upload valid, no sooner than this. Its
/// commander reads the navigator's `mission_result.valid` in health checks run every 100 ms
/// (Commander.cpp, "Run arming checks @ 10Hz"): AUTO sent 4 ms after the mission became valid was
/// ACCEPTED, then TEMPORARILY_REJECTED (docs/mavlink.md). Two periods and a margin.
const PX4_COMMANDER_SETTLE: Duration = Duration::from_millis(300);

/// What a command ticket is for.
#[derive(Debug, Clone)]
pub(super) enum Purpose {
    Stream(u32),
    Step {
        action: String,
        name: String,
        latency_ms: Option<f64>,
    },
}

/// After a job step: run the next (or the same) step now, or wait for a message or tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Advance {
    Again,
    Wait,
}

/// The executor's own state: the job running and the last one, the commands in flight and
/// what each is for, the records not taken yet, and what the running steps wait on.
pub(super) struct Executor {
    purposes: BTreeMap<u64, Purpose>,
    job: Option<Job>,
    last: Option<(JobKey, JobStatus)>,
    /// Command records since the last `take_records`.
    records: Vec<CommandRecord>,
    /// Retry a failed action asked for again no sooner than this.
    pub(super) retry_failed_after: Duration,
    /// Modes this companion commanded (or made the autopilot enter, as a reposition enters
    /// GUIDED), with when; the newest last, a few kept. The operator gate tells its own mode
    /// changes from a pilot's with them.
    commanded_modes: Vec<(FlightMode, Duration)>,
    /// The hand-off job's mode, once [`Vehicle::hand_off`] issued it.
    handoff: Option<FlightMode>,
    /// Where the running zone reposition goes.
    zone_target: Option<(i32, i32)>,
    /// When the autopilot last accepted a mode step of a job (its COMMAND_ACK): only a
    /// heartbeat heard after that can show the new mode (one sent before the autopilot handled
    /// the command may arrive after we sent it, still showing the old mode).
    mode_acked_at: Option<Duration>,
    /// PX4 only: after an upload, (item count, give-up time) until MISSION_CURRENT reports the
    /// new mission's total and a valid mission. PX4's navigator loads and checks an uploaded
    /// mission asynchronously; AUTO requested before that flies the old (empty) one, "finishes"
    /// it at once and falls back to Hold (seen on PX4 SITL with the mode switch 10 ms after the
    /// upload), or is accepted and not run while the mission is not yet valid (PX4 SIH stayed in
    /// Hold ~3 s, CI rehearsal). `total` alone is the MAVLink module's own count, set at the
    /// upload; `mission_state` is NO_MISSION until the navigator's `mission_result.valid`
    /// (mavlink_mission.cpp, `update_mission_state`).
    px4_mission_pending: Option<(u16, Duration)>,
    /// PX4 only: give-up time for waiting out AUTO.TAKEOFF before another mode. PX4 ends a
    /// take-off by switching itself to Hold; a mode requested in the take-off's last moments is
    /// acknowledged and then overridden by that switch (seen on PX4 SITL: AUTO accepted at 8-9 m
    /// of a 10 m take-off, then Hold, the mission never flown).
    px4_takeoff_wait: Option<Duration>,
}

/// What the executor drives and reads of the rest of the vehicle, borrowed for one call
/// ([`Vehicle::ports`]).
pub(super) struct Ports<'a> {
    pub(super) cfg: &'a VehicleConfig,
    pub(super) flavor: Flavor,
    pub(super) liveness: &'a Liveness,
    pub(super) target: Option<(u8, u8)>,
    pub(super) commands: &'a mut CommandClient,
    pub(super) mission: &'a mut MissionClient,
    pub(super) readiness: &'a mut Readiness,
    pub(super) telemetry: &'a Telemetry,
    pub(super) actions: &'a ActionTable,
    pub(super) route: Option<&'a Route>,
    pub(super) events: &'a mut Vec<Event>,
    pub(super) link_events: &'a mut Vec<LinkEvent>,
    pub(super) launches: &'a mut Launches,
    pub(super) watch: &'a mut MissionWatch,
    pub(super) mode_heard_at: Option<Duration>,
}

impl Ports<'_> {
    /// A link event for the record; a significant one also triggers a decision cycle.
    pub(super) fn link_event(&mut self, e: LinkEvent, significant: bool) {
        if significant {
            self.events.push(Event::from(e.clone()));
        }
        self.link_events.push(e);
    }
}

impl Default for Executor {
    fn default() -> Self {
        Self {
            purposes: BTreeMap::new(),
            job: None,
            last: None,
            records: Vec::new(),
            retry_failed_after: Duration::from_secs(5),
            commanded_modes: Vec::new(),
            handoff: None,
            zone_target: None,
            mode_acked_at: None,
            px4_mission_pending: None,
            px4_takeoff_wait: None,
        }
    }
}

impl Executor {
    /// The decision core asked for these vehicle actions.
    /// The same action already running or done is not restarted; a different one replaces it.
    pub(super) fn request_actions(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        actions: &[Flown],
    ) -> Vec<Msg> {
        if actions.is_empty() {
            return Vec::new();
        }
        if let Some(job) = &self.job
            && job.key.is(actions)
        {
            return Vec::new();
        }
        if let Some((k, status)) = &self.last
            && k.is(actions)
        {
            match status {
                JobStatus::Done | JobStatus::Running => return Vec::new(),
                JobStatus::Failed(at) if now < *at + self.retry_failed_after => return Vec::new(),
                JobStatus::Failed(_) => {}
            }
        }
        if !io.liveness.alive() || io.target.is_none() {
            for &a in actions {
                self.records.push(CommandRecord {
                    action: io.actions.name(a).to_string(),
                    command: "-".into(),
                    result: CommandOutcome::NotSent("no link".into()),
                    attempts: 0,
                    latency_ms: None,
                });
            }
            return Vec::new();
        }
        let key = JobKey::Request(actions.to_vec());
        // The steps carry the action's name for their records, resolved once per job.
        let mut steps = VecDeque::new();
        let mut unmapped = false;
        for &a in actions {
            let name = io.actions.name(a).to_string();
            match io.actions.steps(a) {
                Some(s) => steps.extend(s.iter().cloned().map(|st| (name.clone(), st))),
                None => {
                    unmapped = true;
                    self.records.push(CommandRecord {
                        action: name,
                        command: "-".into(),
                        result: CommandOutcome::Unmapped,
                        attempts: 0,
                        latency_ms: None,
                    })
                }
            }
        }
        if let Some(old) = self.job.take() {
            for (action, step) in old.steps {
                self.records.push(CommandRecord {
                    action,
                    command: step_name(&step),
                    result: CommandOutcome::Superseded,
                    attempts: 0,
                    latency_ms: None,
                });
            }
        }
        if steps.is_empty() {
            if !unmapped {
                // An action that commands nothing (stay_on_ground) is done at once: the job it
                // superseded starts afresh when asked for again.
                self.last = Some((key, JobStatus::Done));
            }
            return Vec::new();
        }
        self.job = Some(Job {
            key: key.clone(),
            steps,
            running: Running::Idle,
            arm_attempts: 0,
            mode_attempts: 0,
            mode_from: None,
        });
        self.last = Some((key, JobStatus::Running));
        self.advance_job(io, now)
    }

    /// Latency of everything sent since the last call: from the message (or decision trigger)
    /// that caused it, `trigger_at`, to the moment it was handed to the transport, `sent_at`.
    /// The shell calls this right after sending, so the measurement includes decision and
    /// encoding time, which the injected clock of the state machines cannot see.
    pub(super) fn stamp_latency(&mut self, trigger_at: Duration, sent_at: Duration) {
        let ms = sent_at.saturating_sub(trigger_at).as_secs_f64() * 1000.0;
        for r in self
            .records
            .iter_mut()
            .filter(|r| r.result == "SENT" && r.latency_ms.is_none())
        {
            r.latency_ms = Some(ms);
        }
        for p in self.purposes.values_mut() {
            if let Purpose::Step {
                latency_ms: l @ None,
                ..
            } = p
            {
                *l = Some(ms);
            }
        }
    }

    pub(super) fn job_failed(&mut self, now: Duration) {
        if let Some(job) = self.job.take() {
            for (action, step) in job.steps.into_iter().skip(1) {
                self.records.push(CommandRecord {
                    action,
                    command: step_name(&step),
                    result: CommandOutcome::Skipped("earlier step failed".into()),
                    attempts: 0,
                    latency_ms: None,
                });
            }
            self.last = Some((job.key, JobStatus::Failed(now)));
        }
    }

    pub(super) fn step_done(&mut self) {
        if let Some(job) = &mut self.job {
            job.steps.pop_front();
            job.running = Running::Idle;
            job.arm_attempts = 0;
            job.mode_attempts = 0;
            job.mode_from = None;
        }
    }

    /// Run steps until one has to wait.
    pub(super) fn advance_job(&mut self, io: &mut Ports<'_>, now: Duration) -> Vec<Msg> {
        let mut out = Vec::new();
        let keep_mission = io.watch.flies();
        loop {
            let Some(job) = &mut self.job else { return out };
            let Some((action, step)) = job.steps.front().cloned() else {
                let key = std::mem::replace(&mut job.key, JobKey::Request(Vec::new()));
                self.job = None;
                self.last = Some((key, JobStatus::Done));
                return out;
            };
            let next = match (&job.running, &step) {
                (Running::Command(_) | Running::Mission, _) => Advance::Wait,
                (Running::Arrive { target, since }, _) => {
                    let (target, since) = (*target, *since);
                    self.arrive_step(io, now, action, target, since)
                }
                (Running::ConfirmMode { since }, Step::Mode(mode)) => {
                    let (from, since) = (job.mode_from, *since);
                    self.confirm_mode_step(io, now, action, *mode, from, since)
                }
                (Running::ConfirmMode { .. }, _) => {
                    job.running = Running::Idle;
                    Advance::Again
                }
                (Running::Idle, Step::Mode(mode)) => {
                    self.mode_step(io, now, action, *mode, &mut out)
                }
                (Running::Idle | Running::WaitReady { .. }, Step::Arm) => {
                    self.arm_step(io, now, action, &mut out)
                }
                (Running::Idle, Step::Command { command, params }) => {
                    self.command_step(io, now, action, *command, *params, &mut out)
                }
                (Running::Idle, Step::UploadMission) if keep_mission => {
                    self.keep_autopilot_mission_step(io, now, action)
                }
                (Running::Idle, Step::UploadMission) => {
                    self.upload_mission_step(io, now, action, &mut out)
                }
                (Running::Idle, Step::Reposition(o)) => {
                    self.reposition_step(io, now, action, *o, &mut out)
                }
                (Running::Idle, Step::GotoZone) => self.goto_zone_step(io, now, action, &mut out),
                (Running::WaitReady { .. }, _) => {
                    job.running = Running::Idle;
                    Advance::Again
                }
            };
            if next == Advance::Wait {
                return out;
            }
        }
    }

    /// A step's command: issued (the next step waits for its answer), or waiting to be.
    pub(super) fn issued(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        action: &str,
        name: String,
        spec: CommandSpec,
        out: &mut Vec<Msg>,
    ) -> Advance {
        if self.issue(io, now, action, name, spec, out) {
            Advance::Again
        } else {
            Advance::Wait
        }
    }

    /// Record a step settled without a command on the wire (`ALREADY`, `SKIPPED ...`).
    pub(super) fn record_step(&mut self, action: String, command: String, result: CommandOutcome) {
        self.records.push(CommandRecord {
            action,
            command,
            result,
            attempts: 0,
            latency_ms: None,
        });
    }

    /// Submit a step's command; false when it has to wait (in flight or sent).
    pub(super) fn issue(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        action: &str,
        name: String,
        spec: CommandSpec,
        out: &mut Vec<Msg>,
    ) -> bool {
        let launch = LaunchCommand::of(&spec).map(|c| (c, spec.command));
        match io.commands.submit(now, spec) {
            Ok((ticket, msgs)) => {
                if let Some(l) = launch {
                    io.launches.sent(now, ticket, l);
                }
                self.step_sent(
                    (msgs, out),
                    Running::Command(ticket),
                    action.to_string(),
                    name.clone(),
                );
                self.purposes.insert(
                    ticket,
                    Purpose::Step {
                        action: action.to_string(),
                        name,
                        latency_ms: None,
                    },
                );
                false
            }
            // Same command id still in flight (a stream request or a superseded step): next tick.
            Err(_) => false,
        }
    }

    /// A step's request went out: its messages queued, the job waiting on `running`, and a
    /// `Sent` record for the step's command.
    fn step_sent(
        &mut self,
        (msgs, out): (Vec<Msg>, &mut Vec<Msg>),
        running: Running,
        action: String,
        command: String,
    ) {
        out.extend(msgs);
        let job = self.job.as_mut().expect("a step runs inside a job");
        job.running = running;
        self.records.push(CommandRecord {
            action,
            command,
            result: CommandOutcome::Sent,
            attempts: 1,
            latency_ms: None,
        });
    }

    pub(super) fn on_command_events(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        evs: Vec<CommandEvent>,
    ) -> Vec<Msg> {
        let mut out = Vec::new();
        for ev in evs {
            let CommandEvent::Finished {
                ticket,
                command,
                outcome,
                attempts,
                ..
            } = ev
            else {
                continue;
            };
            io.launches.finished(ticket, &outcome);
            match self.purposes.remove(&ticket) {
                Some(Purpose::Stream(id)) => {
                    let name = <Msg as mavlink::Message>::default_message_from_id(id)
                        .map(|m| mavlink::Message::message_name(&m))
                        .unwrap_or("?");
                    io.link_event(
                        LinkEvent::Stream {
                            name: name.to_string(),
                            outcome: outcome.label(),
                        },
                        false,
                    );
                }
                Some(Purpose::Step {
                    action,
                    name,
                    latency_ms,
                }) => {
                    self.records.push(CommandRecord {
                        action: action.clone(),
                        command: name,
                        result: outcome.label(),
                        attempts,
                        latency_ms,
                    });
                    io.events.push(Event::Command {
                        action: action.clone(),
                        outcome: outcome.label(),
                    });
                    let is_current =
                        matches!(&self.job, Some(j) if j.running == Running::Command(ticket));
                    if !is_current {
                        continue;
                    }
                    let px4 = io.flavor == Flavor::Px4;
                    match outcome {
                        Outcome::Acked => match (&mut self.job, self.zone_target) {
                            (Some(j), Some(target))
                                if matches!(j.steps.front(), Some((_, Step::GotoZone))) =>
                            {
                                // Accepted is not arrived: LAND only once there.
                                j.running = Running::Arrive { target, since: now };
                            }
                            // PX4: accepted is not in the mode (see `confirm_mode_step`).
                            (Some(j), _)
                                if px4 && matches!(j.steps.front(), Some((_, Step::Mode(_)))) =>
                            {
                                j.running = Running::ConfirmMode { since: now };
                                self.mode_acked_at = Some(now);
                            }
                            (Some(j), _) if matches!(j.steps.front(), Some((_, Step::Mode(_)))) => {
                                self.mode_acked_at = Some(now);
                                self.step_done();
                            }
                            _ => self.step_done(),
                        },
                        Outcome::Failed(reason)
                            if command == MavCmd::MAV_CMD_COMPONENT_ARM_DISARM =>
                        {
                            // Not ready after all: wait for a fresh ready report, never resend blindly.
                            io.readiness.invalidate(now);
                            let attempts_used =
                                self.job.as_ref().map(|j| j.arm_attempts).unwrap_or(0);
                            if matches!(reason, FailReason::Cancelled(_))
                                || attempts_used >= io.cfg.max_arm_attempts
                            {
                                self.job_failed(now);
                            } else if let Some(j) = &mut self.job {
                                j.running = Running::WaitReady { since: now };
                            }
                        }
                        Outcome::Failed(_) => self.job_failed(now),
                    }
                }
                None => {}
            }
        }
        out.extend(self.advance_job(io, now));
        out
    }

    pub(super) fn on_mission_events(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        evs: Vec<MissionEvent>,
    ) -> Vec<Msg> {
        for ev in evs {
            let action = self
                .job
                .as_ref()
                .and_then(|j| j.steps.front().map(|s| s.0.clone()))
                .unwrap_or_default();
            let in_job = matches!(&self.job, Some(j) if j.running == Running::Mission);
            match ev {
                // Only the mission watch downloads on its own.
                MissionEvent::Done {
                    op: MissionOp::Download,
                    items,
                } => io.watch_downloaded(Some(items), ""),
                MissionEvent::Failed {
                    op: MissionOp::Download,
                    error,
                } => io.watch_downloaded(None, &error.outcome().to_string()),
                MissionEvent::Uploaded { count } => io.link_event(
                    LinkEvent::MissionUploaded {
                        items: count as usize,
                    },
                    false,
                ),
                MissionEvent::Done {
                    op: MissionOp::UploadVerified,
                    items,
                } => {
                    self.records.push(CommandRecord {
                        action,
                        command: "MISSION_UPLOAD".into(),
                        result: CommandOutcome::AcceptedVerified { items: items.len() },
                        attempts: 1,
                        latency_ms: None,
                    });
                    io.watch.uploaded(&items);
                    if io.flavor == Flavor::Px4 {
                        self.px4_mission_pending =
                            Some((items.len() as u16, now + PX4_MISSION_VALID_WAIT));
                    }
                    if in_job {
                        self.step_done();
                    }
                }
                MissionEvent::Done { .. } => {}
                MissionEvent::Failed { op, error } => {
                    self.records.push(CommandRecord {
                        action,
                        command: op.command_name(),
                        result: error.outcome(),
                        attempts: 1,
                        latency_ms: None,
                    });
                    io.events.push(Event::Command {
                        action: "mission".into(),
                        outcome: CommandOutcome::Failed(None),
                    });
                    if in_job {
                        self.job_failed(now);
                    }
                }
            }
        }
        self.advance_job(io, now)
    }

    /// Whether an action is being executed (for tests and the log).
    pub(super) fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// `action` is being flown or was flown to the end (asking for it again does nothing).
    pub(super) fn settled(&self, action: Flown) -> bool {
        let only = std::slice::from_ref(&action);
        matches!(&self.job, Some(j) if j.key.is(only))
            || matches!(&self.last, Some((k, JobStatus::Done | JobStatus::Running)) if k.is(only))
    }

    pub(super) fn note_mode(&mut self, now: Duration, mode: FlightMode) {
        self.commanded_modes.push((mode, now));
        if self.commanded_modes.len() > 8 {
            self.commanded_modes.remove(0);
        }
    }

    /// MAV_CMD_DO_REPOSITION with the change-mode flag: ArduPilot enters GUIDED, PX4 holds in
    /// LOITER (our GUIDED on PX4).
    pub(super) fn note_reposition(&mut self, now: Duration) {
        self.note_mode(now, FlightMode::Guided);
    }

    /// When the last action failed (its key and the time), if it did and nothing ran since.
    pub(super) fn failed_action(&self, actions: &ActionTable) -> Option<(String, Duration)> {
        match &self.last {
            Some((k, JobStatus::Failed(at))) => Some((self.job_name(actions, k), *at)),
            _ => None,
        }
    }

    /// The name a job goes by (`take_off`, `a+b` for several entries, `handoff:RTL`).
    fn job_name(&self, actions: &ActionTable, key: &JobKey) -> String {
        match key {
            JobKey::Request(r) => {
                let names: Vec<&str> = r.iter().map(|&f| actions.name(f)).collect();
                names.join("+")
            }
            JobKey::Handoff(mode) => format!("handoff:{mode}"),
        }
    }

    /// The companion stops: whatever it was doing ends now (recorded CANCELLED) and the vehicle
    /// is put in `mode` (`LOITER`, `RTL`, `LAND`) for the autopilot to fly on its own. The
    /// step is acknowledged (or fails) like any other; [`Vehicle::handoff_status`] tells.
    pub(super) fn hand_off(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        mode: FlightMode,
    ) -> Vec<Msg> {
        self.stop_actions(io, now, "companion stopping");
        let key = JobKey::Handoff(mode);
        self.job = Some(Job {
            steps: VecDeque::from([(self.job_name(io.actions, &key), Step::Mode(mode))]),
            key: key.clone(),
            running: Running::Idle,
            arm_attempts: 0,
            mode_attempts: 0,
            mode_from: None,
        });
        self.last = Some((key, JobStatus::Running));
        self.handoff = Some(mode);
        self.advance_job(io, now)
    }

    /// The hand-off's outcome: None while it runs (or none was issued), Some(true) when the
    /// autopilot accepted the mode, Some(false) when the step failed.
    pub(super) fn handoff_status(&self) -> Option<bool> {
        let ours = JobKey::Handoff(self.handoff?);
        match &self.last {
            Some((k, JobStatus::Done)) if *k == ours => Some(true),
            Some((k, JobStatus::Failed(_))) if *k == ours => Some(false),
            _ => None,
        }
    }

    /// Stop commanding motion (the pilot took over, or the flight is over): the running action
    /// and its commands in flight end now (recorded CANCELLED), nothing of them is resent, and
    /// any action may be asked for afresh later. Stream requests go on.
    pub(super) fn stop_actions(&mut self, io: &mut Ports<'_>, now: Duration, why: &str) {
        let step_tickets: Vec<u64> = self
            .purposes
            .iter()
            .filter(|(_, p)| matches!(p, Purpose::Step { .. }))
            .map(|(t, _)| *t)
            .collect();
        let evs = io
            .commands
            .cancel_tickets(now, why, |t| step_tickets.contains(&t));
        let job = self.job.take();
        // With the job gone, the cancelled commands are only recorded.
        let _ = self.on_command_events(io, now, evs);
        if let Some(job) = job {
            let running = matches!(job.running, Running::Command(_));
            for (action, step) in job.steps.into_iter().skip(usize::from(running)) {
                self.records.push(CommandRecord {
                    action,
                    command: step_name(&step),
                    result: CommandOutcome::Cancelled(Some(why.to_string())),
                    attempts: 0,
                    latency_ms: None,
                });
            }
        }
        if io.mission.cancel(why).is_some() {
            io.link_event(LinkEvent::MissionTransferCancelled(why.to_string()), false);
        }
        self.zone_target = None;
        self.last = None;
    }

    /// The stop: as [`Executor::stop_actions`], except the launch commands still waiting for
    /// their answer (`awaiting`: ticket and command), which are kept (never resent).
    pub(super) fn stop_keeping(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        why: &str,
        awaiting: Vec<(u64, MavCmd)>,
    ) {
        let kept: Vec<_> = awaiting
            .into_iter()
            .filter_map(|(t, c)| self.purposes.remove(&t).map(|p| (t, c, p)))
            .collect();
        // `stop_actions` cancels the commands of the steps it knows of: not these.
        self.stop_actions(io, now, why);
        for (ticket, command, purpose) in kept {
            self.purposes.insert(ticket, purpose);
            io.commands.no_resend(command);
        }
    }

    /// The link is gone (lost, or the autopilot rebooted): the running job's steps end now,
    /// recorded CANCELLED, and no command in flight is answered any more.
    pub(super) fn drop_job(&mut self, now: Duration, why: &str) {
        if let Some(job) = self.job.take() {
            for (action, step) in job.steps {
                self.records.push(CommandRecord {
                    action,
                    command: step_name(&step),
                    result: CommandOutcome::Cancelled(Some(why.to_string())),
                    attempts: 0,
                    latency_ms: None,
                });
            }
            self.last = Some((job.key, JobStatus::Failed(now)));
        }
    }

    /// After [`Executor::drop_job`] and the streams: no ticket is waited on.
    pub(super) fn forget_tickets(&mut self) {
        self.purposes.clear();
    }

    /// A stream request went out as `ticket`.
    pub(super) fn stream_requested(&mut self, ticket: u64, id: u32) {
        self.purposes.insert(ticket, Purpose::Stream(id));
    }

    /// MISSION_CURRENT reported `total` items in `state`: PX4 has loaded the mission uploaded
    /// with that many, and found it valid unless the state is NO_MISSION (an autopilot that
    /// reports no state, UNKNOWN, is taken at its total). AUTO then waits
    /// [`PX4_COMMANDER_SETTLE`] more, for PX4's commander to see the valid mission too.
    pub(super) fn mission_current_seen(&mut self, now: Duration, total: u16, state: MissionState) {
        if let Some((n, until)) = &mut self.px4_mission_pending
            && *n == total
            && state != MissionState::MISSION_STATE_NO_MISSION
        {
            *until = (*until).min(now + PX4_COMMANDER_SETTLE);
        }
    }

    /// Take the command records since the last call.
    pub(super) fn take_records(&mut self) -> Vec<CommandRecord> {
        std::mem::take(&mut self.records)
    }

    /// Modes this companion commanded, with when, the newest last.
    pub(super) fn commanded_modes(&self) -> &[(FlightMode, Duration)] {
        &self.commanded_modes
    }

    /// The route's upload step when the autopilot's mission is flown: nothing to upload once it
    /// is known; refused before (no start on a mission not yet read).
    pub(super) fn keep_autopilot_mission_step(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
    ) -> Advance {
        let result = if io.watch.known().is_some() {
            self.step_done();
            CommandOutcome::Skipped("the autopilot's own mission is flown".into())
        } else {
            self.job_failed(now);
            CommandOutcome::Failed(Some("the autopilot's mission is not downloaded yet".into()))
        };
        self.record_step(action, "MISSION_UPLOAD".into(), result);
        Advance::Again
    }
}

pub(super) fn step_name(s: &Step) -> String {
    match s {
        Step::Mode(m) => format!("SET_MODE {m}"),
        Step::Arm => "ARM".into(),
        Step::Command { command, .. } => crate::mavlink_name(&command),
        Step::UploadMission => "MISSION_UPLOAD".into(),
        Step::Reposition(_) => "MAV_CMD_DO_REPOSITION".into(),
        Step::GotoZone => "MAV_CMD_DO_REPOSITION (zone)".into(),
    }
}
