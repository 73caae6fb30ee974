//! The command executor: primitive vehicle actions turned into protocol steps (modes, arm,
//! commands, mission upload, repositions), one job at a time, and their records.

use super::*;
use crate::actions::Flown;

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

impl Vehicle {
    /// The decision core asked for these vehicle actions.
    /// The same action already running or done is not restarted; a different one replaces it.
    pub fn request_actions(&mut self, now: Duration, actions: &[Flown]) -> Vec<Msg> {
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
        if !self.liveness.alive() || self.target.is_none() {
            for &a in actions {
                self.records.push(CommandRecord {
                    action: self.actions.name(a).to_string(),
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
            let name = self.actions.name(a).to_string();
            match self.actions.steps(a) {
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
        self.advance_job(now)
    }

    /// Latency of everything sent since the last call: from the message (or decision trigger)
    /// that caused it, `trigger_at`, to the moment it was handed to the transport, `sent_at`.
    /// The shell calls this right after sending, so the measurement includes decision and
    /// encoding time, which the injected clock of the state machines cannot see.
    pub fn stamp_latency(&mut self, trigger_at: Duration, sent_at: Duration) {
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
    pub(super) fn advance_job(&mut self, now: Duration) -> Vec<Msg> {
        let mut out = Vec::new();
        let keep_mission = self.flies_autopilot_mission();
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
                    self.arrive_step(now, action, target, since)
                }
                (Running::ConfirmMode { since }, Step::Mode(mode)) => {
                    let (from, since) = (job.mode_from, *since);
                    self.confirm_mode_step(now, action, *mode, from, since)
                }
                (Running::ConfirmMode { .. }, _) => {
                    job.running = Running::Idle;
                    Advance::Again
                }
                (Running::Idle, Step::Mode(mode)) => self.mode_step(now, action, *mode, &mut out),
                (Running::Idle | Running::WaitReady { .. }, Step::Arm) => {
                    self.arm_step(now, action, &mut out)
                }
                (Running::Idle, Step::Command { command, params }) => {
                    self.command_step(now, action, *command, *params, &mut out)
                }
                (Running::Idle, Step::UploadMission) if keep_mission => {
                    self.keep_autopilot_mission_step(now, action)
                }
                (Running::Idle, Step::UploadMission) => {
                    self.upload_mission_step(now, action, &mut out)
                }
                (Running::Idle, Step::Reposition(o)) => {
                    self.reposition_step(now, action, *o, &mut out)
                }
                (Running::Idle, Step::GotoZone) => self.goto_zone_step(now, action, &mut out),
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
        now: Duration,
        action: &str,
        name: String,
        spec: CommandSpec,
        out: &mut Vec<Msg>,
    ) -> Advance {
        if self.issue(now, action, name, spec, out) {
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

    /// The zone reposition was accepted: done when within the zone radius, or after the
    /// timeout (landing where the vehicle is).
    pub(super) fn arrive_step(
        &mut self,
        now: Duration,
        action: String,
        target: (i32, i32),
        since: Duration,
    ) -> Advance {
        let off = self.telemetry.position.map(|p| {
            let (n, e) = crate::telemetry::offset_m(target, (p.lat_e7, p.lon_e7));
            n.hypot(e)
        });
        let result = match off {
            Some(d) if d <= self.cfg.zone_radius_m => {
                CommandOutcome::Arrived(format!("{d:.1} m from the zone"))
            }
            _ if now.saturating_sub(since) >= self.cfg.zone_arrive_timeout => {
                CommandOutcome::Timeout(Some(format!(
                    "not within {:.1} m of the zone after {:.0} s{}; landing here",
                    self.cfg.zone_radius_m,
                    self.cfg.zone_arrive_timeout.as_secs_f64(),
                    off.map(|d| format!(", {d:.1} m away")).unwrap_or_default()
                )))
            }
            _ => return Advance::Wait,
        };
        self.record_step(action, "ARRIVE (zone)".into(), result);
        self.zone_target = None;
        self.step_done();
        Advance::Again
    }

    pub(super) fn mode_step(
        &mut self,
        now: Duration,
        action: String,
        mode: FlightMode,
        out: &mut Vec<Msg>,
    ) -> Advance {
        // Landing and return never wait.
        let shown = self.telemetry.mode.and_then(ReportedMode::known);
        if self.flavor == Flavor::Px4
            && !matches!(
                mode,
                FlightMode::Land | FlightMode::Rtl | FlightMode::SmartRtl | FlightMode::Takeoff
            )
            && shown == Some(FlightMode::Takeoff)
        {
            let until = *self
                .px4_takeoff_wait
                .get_or_insert(now + Duration::from_secs(30));
            if now < until {
                return Advance::Wait; // the heartbeat that shows Hold moves on
            }
        }
        self.px4_takeoff_wait = None;
        if mode == FlightMode::Auto
            && let Some((_, until)) = self.px4_mission_pending
        {
            if now < until {
                return Advance::Wait; // the next MISSION_CURRENT or tick moves on
            }
            self.px4_mission_pending = None;
        }
        // A different mode commanded since the last heartbeat: the reported mode is
        // stale (LAND reported, GUIDED just accepted for a sidestep).
        let stale = self
            .commanded_modes
            .iter()
            .rev()
            .find(|(_, at)| self.mode_heard_at.is_none_or(|h| *at >= h))
            .is_some_and(|(m, _)| *m != mode);
        self.note_mode(now, mode);
        if modes::is_in_mode(self.flavor, self.telemetry.custom_mode, mode)
            && self.telemetry.mode.is_some()
            && !stale
        {
            self.record_step(action, format!("SET_MODE {mode}"), CommandOutcome::Already);
            self.step_done();
            return Advance::Again;
        }
        match modes::set_mode_command(self.flavor, mode) {
            Some(spec) => {
                let shown = self
                    .telemetry
                    .mode
                    .is_some()
                    .then_some(self.telemetry.custom_mode);
                if let Some(j) = &mut self.job {
                    if j.mode_attempts == 0 {
                        j.mode_from = shown;
                    }
                    j.mode_attempts += 1;
                }
                self.issued(now, &action, format!("SET_MODE {mode}"), spec, out)
            }
            None => {
                let result = CommandOutcome::Failed(Some(format!(
                    "no {mode} mode for {}",
                    self.flavor.name()
                )));
                self.record_step(action, format!("SET_MODE {mode}"), result);
                self.job_failed(now);
                Advance::Again
            }
        }
    }

    /// PX4 accepted SET_MODE `name`: PX4's ACK says the user's intention changed, not the mode
    /// (it can still refuse to run it, e.g. a mission not yet valid). Done when a HEARTBEAT newer
    /// than the acceptance shows the mode. After `mode_confirm` without it: sent again while the
    /// vehicle still shows the mode it was in (the command had no effect), at most
    /// `max_mode_attempts` in all; a third mode is someone else's and is never overridden.
    pub(super) fn confirm_mode_step(
        &mut self,
        now: Duration,
        action: String,
        name: FlightMode,
        from: Option<u32>,
        since: Duration,
    ) -> Advance {
        let heard_since = self.mode_heard_at.is_some_and(|h| h > since);
        if heard_since && modes::is_in_mode(self.flavor, self.telemetry.custom_mode, name) {
            self.step_done();
            return Advance::Again;
        }
        if now.saturating_sub(since) < self.cfg.mode_confirm {
            return Advance::Wait;
        }
        let shown = self
            .telemetry
            .mode
            .map_or_else(|| "?".into(), |m| m.to_string());
        let unchanged = heard_since && from == Some(self.telemetry.custom_mode);
        let attempts = self.job.as_ref().map_or(0, |j| j.mode_attempts);
        let waited = self.cfg.mode_confirm.as_secs_f64();
        if unchanged && attempts < self.cfg.max_mode_attempts {
            self.record_step(
                action,
                format!("SET_MODE {name}"),
                CommandOutcome::NotConfirmed(format!(
                    "still {shown} {waited:.0} s after ACCEPTED; sending again"
                )),
            );
            if let Some(j) = &mut self.job {
                j.running = Running::Idle;
            }
            return Advance::Again;
        }
        let why = if !heard_since {
            format!("accepted, but no HEARTBEAT in {waited:.0} s to show it")
        } else if unchanged {
            format!("accepted {attempts} times, but the vehicle stays in {shown}")
        } else {
            format!("accepted, but the vehicle went to {shown}, not {name}: not overriding")
        };
        self.record_step(
            action,
            format!("SET_MODE {name}"),
            CommandOutcome::Failed(Some(why)),
        );
        self.job_failed(now);
        Advance::Again
    }

    pub(super) fn arm_step(
        &mut self,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        if self.telemetry.armed {
            self.record_step(action, "ARM".into(), CommandOutcome::Already);
            self.step_done();
            return Advance::Again;
        }
        match self.readiness.check() {
            Ok(()) => {
                // Arm only in the mode this companion set last (ArduCopter may leave GUIDED
                // for its RC mode switch right after accepting it): wait for a heartbeat
                // newer than the mode command; if it shows another mode, this take-off
                // fails and the next request sets the mode again.
                if self.flavor == Flavor::ArduPilot
                    && let Some((want, at)) = self.commanded_modes.last().copied()
                    && !modes::is_in_mode(self.flavor, self.telemetry.custom_mode, want)
                {
                    // The mode is shown by a heartbeat sent after the autopilot handled the
                    // command: on an ordered link, one heard after its ACK (a heartbeat heard
                    // between our send and the ACK may predate the change).
                    let shown_after = self.mode_acked_at.filter(|&a| a >= at).unwrap_or(at);
                    if self.mode_heard_at.is_none_or(|h| h <= shown_after) {
                        return Advance::Wait;
                    }
                    let now_mode = self
                        .telemetry
                        .mode
                        .map_or_else(|| "?".into(), |m| m.to_string());
                    self.record_step(
                        action,
                        "ARM".into(),
                        CommandOutcome::Failed(Some(format!(
                            "vehicle in {now_mode}, not {want} as commanded: not arming"
                        ))),
                    );
                    self.job_failed(now);
                    return Advance::Again;
                }
                let spec = CommandSpec::long(
                    MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                    [1., 0., 0., 0., 0., 0., 0.],
                )
                .once();
                if let Some(j) = &mut self.job {
                    j.arm_attempts += 1;
                }
                self.issued(now, &action, "ARM".into(), spec, out)
            }
            Err(why) => {
                let Some(job) = self.job.as_mut() else {
                    return Advance::Wait;
                };
                let since = match job.running {
                    Running::WaitReady { since } => since,
                    _ => {
                        job.running = Running::WaitReady { since: now };
                        self.record_step(
                            action.clone(),
                            "ARM".into(),
                            CommandOutcome::WaitingReady(why.join("; ")),
                        );
                        now
                    }
                };
                if now.saturating_sub(since) >= self.cfg.arm_wait {
                    self.record_step(
                        action,
                        "ARM".into(),
                        CommandOutcome::NotReady(why.join("; ")),
                    );
                    self.job_failed(now);
                }
                Advance::Wait
            }
        }
    }

    pub(super) fn command_step(
        &mut self,
        now: Duration,
        action: String,
        command: MavCmd,
        params: [f32; 7],
        out: &mut Vec<Msg>,
    ) -> Advance {
        // Before take-off the vehicle stands at home: its AMSL altitude serves
        // until HOME_POSITION arrives.
        let home_amsl_m = self.telemetry.home.map(|h| h.2).or_else(|| {
            self.telemetry
                .position
                .filter(|_| !self.telemetry.armed)
                .map(|p| p.alt_amsl_m)
        });
        let Some(params) = modes::command_params(self.flavor, command, params, home_amsl_m) else {
            self.record_step(
                action,
                crate::mavlink_name(&command),
                CommandOutcome::Failed(Some("no home position yet".into())),
            );
            self.job_failed(now);
            return Advance::Again;
        };
        if command == MavCmd::MAV_CMD_NAV_TAKEOFF && self.flavor == Flavor::Px4 {
            // PX4 flies a take-off command in its TAKEOFF mode.
            self.note_mode(now, FlightMode::Takeoff);
        }
        let spec = CommandSpec::long(command, params);
        self.issued(now, &action, crate::mavlink_name(&command), spec, out)
    }

    pub(super) fn upload_mission_step(
        &mut self,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        let home = self
            .telemetry
            .home
            .map(|h| (h.0, h.1))
            .or_else(|| self.telemetry.position.map(|p| (p.lat_e7, p.lon_e7)));
        let (Some(route), Some(home)) = (&self.route, home) else {
            let why = if self.route.is_none() {
                "no route loaded"
            } else {
                "no home position yet"
            };
            self.record_step(
                action,
                "MISSION_UPLOAD".into(),
                CommandOutcome::Failed(Some(why.into())),
            );
            self.job_failed(now);
            return Advance::Again;
        };
        let items = route.mission_items(self.flavor, home);
        match self.mission.upload(now, items) {
            Ok(msgs) => {
                self.step_sent(
                    (msgs, out),
                    Running::Mission,
                    action,
                    "MISSION_UPLOAD".into(),
                );
                Advance::Wait
            }
            Err(_) => Advance::Wait, // another transfer still running: wait for it
        }
    }

    pub(super) fn reposition_step(
        &mut self,
        now: Duration,
        action: String,
        o: Offset,
        out: &mut Vec<Msg>,
    ) -> Advance {
        match self.reposition_spec(o) {
            Some(spec) => {
                self.note_reposition(now);
                self.issued(now, &action, "MAV_CMD_DO_REPOSITION".into(), spec, out)
            }
            None => {
                self.record_step(
                    action,
                    "MAV_CMD_DO_REPOSITION".into(),
                    CommandOutcome::Failed(Some("no position/heading yet".into())),
                );
                self.job_failed(now);
                Advance::Again
            }
        }
    }

    pub(super) fn goto_zone_step(
        &mut self,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        let zone = (
            self.telemetry.get("zone_north_m"),
            self.telemetry.get("zone_east_m"),
            self.telemetry.position,
        );
        match zone {
            (Some(n), Some(e), Some(p)) => {
                let (x, y) = displace((p.lat_e7, p.lon_e7), n, e);
                let (frame, z) = modes::reposition_frame_alt(
                    self.flavor,
                    p.alt_rel_m,
                    p.alt_amsl_m,
                    p.alt_rel_m,
                );
                let spec = CommandSpec::int(
                    MavCmd::MAV_CMD_DO_REPOSITION,
                    frame,
                    [-1.0, 1.0, 0.0, f32::NAN],
                    x,
                    y,
                    z,
                );
                self.note_reposition(now);
                self.zone_target = Some((x, y));
                self.issued(
                    now,
                    &action,
                    "MAV_CMD_DO_REPOSITION (zone)".into(),
                    spec,
                    out,
                )
            }
            _ => {
                self.record_step(
                    action,
                    "MAV_CMD_DO_REPOSITION (zone)".into(),
                    CommandOutcome::Skipped("no zone reported; landing here".into()),
                );
                self.step_done();
                Advance::Again
            }
        }
    }

    /// Submit a step's command; false when it has to wait (in flight or sent).
    pub(super) fn issue(
        &mut self,
        now: Duration,
        action: &str,
        name: String,
        spec: CommandSpec,
        out: &mut Vec<Msg>,
    ) -> bool {
        let launch = LaunchCommand::of(&spec).map(|c| (c, spec.command));
        match self.commands.submit(now, spec) {
            Ok((ticket, msgs)) => {
                if let Some(l) = launch {
                    self.launch_sent(now, ticket, l);
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

    pub(super) fn reposition_spec(&self, o: Offset) -> Option<CommandSpec> {
        let p = self.telemetry.position?;
        let h = p.heading_deg?.to_radians();
        let north = o.forward_m * h.cos() - o.right_m * h.sin();
        let east = o.forward_m * h.sin() + o.right_m * h.cos();
        let (x, y) = displace((p.lat_e7, p.lon_e7), north, east);
        let (frame, z) = modes::reposition_frame_alt(
            self.flavor,
            p.alt_rel_m + o.up_m,
            p.alt_amsl_m,
            p.alt_rel_m,
        );
        // param1 -1: default speed; param2 1: MAV_DO_REPOSITION_FLAGS_CHANGE_MODE; param4 NaN: keep yaw.
        Some(CommandSpec::int(
            MavCmd::MAV_CMD_DO_REPOSITION,
            frame,
            [-1.0, 1.0, 0.0, f32::NAN],
            x,
            y,
            z,
        ))
    }

    pub(super) fn on_command_events(&mut self, now: Duration, evs: Vec<CommandEvent>) -> Vec<Msg> {
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
            self.launch_finished(ticket, &outcome);
            match self.purposes.remove(&ticket) {
                Some(Purpose::Stream(id)) => {
                    let name = <Msg as mavlink::Message>::default_message_from_id(id)
                        .map(|m| mavlink::Message::message_name(&m))
                        .unwrap_or("?");
                    self.link_event(
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
                    self.events.push(Event::Command {
                        action: action.clone(),
                        outcome: outcome.label(),
                    });
                    let is_current =
                        matches!(&self.job, Some(j) if j.running == Running::Command(ticket));
                    if !is_current {
                        continue;
                    }
                    let px4 = self.flavor == Flavor::Px4;
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
                            self.readiness.invalidate(now);
                            let attempts_used =
                                self.job.as_ref().map(|j| j.arm_attempts).unwrap_or(0);
                            if matches!(reason, FailReason::Cancelled(_))
                                || attempts_used >= self.cfg.max_arm_attempts
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
        out.extend(self.advance_job(now));
        out
    }

    pub(super) fn on_mission_events(&mut self, now: Duration, evs: Vec<MissionEvent>) -> Vec<Msg> {
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
                } => self.watch_downloaded(Some(items), ""),
                MissionEvent::Failed {
                    op: MissionOp::Download,
                    error,
                } => self.watch_downloaded(None, &error.outcome().to_string()),
                MissionEvent::Uploaded { count } => self.link_event(
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
                    self.watch_uploaded(&items);
                    if self.flavor == Flavor::Px4 {
                        self.px4_mission_pending =
                            Some((items.len() as u16, now + Duration::from_secs(5)));
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
                    self.events.push(Event::Command {
                        action: "mission".into(),
                        outcome: CommandOutcome::Failed(None),
                    });
                    if in_job {
                        self.job_failed(now);
                    }
                }
            }
        }
        self.advance_job(now)
    }

    /// Whether an action is being executed (for tests and the log).
    pub fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// `action` is being flown or was flown to the end (asking for it again does nothing).
    pub fn settled(&self, action: Flown) -> bool {
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
    pub fn failed_action(&self) -> Option<(String, Duration)> {
        match &self.last {
            Some((k, JobStatus::Failed(at))) => Some((self.job_name(k), *at)),
            _ => None,
        }
    }

    /// The name a job goes by (`take_off`, `a+b` for several entries, `handoff:RTL`).
    fn job_name(&self, key: &JobKey) -> String {
        match key {
            JobKey::Request(r) => {
                let names: Vec<&str> = r.iter().map(|&f| self.actions.name(f)).collect();
                names.join("+")
            }
            JobKey::Handoff(mode) => format!("handoff:{mode}"),
        }
    }

    /// The companion stops: whatever it was doing ends now (recorded CANCELLED) and the vehicle
    /// is put in `mode` (`LOITER`, `RTL`, `LAND`) for the autopilot to fly on its own. The
    /// step is acknowledged (or fails) like any other; [`Vehicle::handoff_status`] tells.
    pub fn hand_off(&mut self, now: Duration, mode: FlightMode) -> Vec<Msg> {
        self.stop_actions(now, "companion stopping");
        let key = JobKey::Handoff(mode);
        self.job = Some(Job {
            steps: VecDeque::from([(self.job_name(&key), Step::Mode(mode))]),
            key: key.clone(),
            running: Running::Idle,
            arm_attempts: 0,
            mode_attempts: 0,
            mode_from: None,
        });
        self.last = Some((key, JobStatus::Running));
        self.handoff = Some(mode);
        self.advance_job(now)
    }

    /// The hand-off's outcome: None while it runs (or none was issued), Some(true) when the
    /// autopilot accepted the mode, Some(false) when the step failed.
    pub fn handoff_status(&self) -> Option<bool> {
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
    pub fn stop_actions(&mut self, now: Duration, why: &str) {
        let step_tickets: Vec<u64> = self
            .purposes
            .iter()
            .filter(|(_, p)| matches!(p, Purpose::Step { .. }))
            .map(|(t, _)| *t)
            .collect();
        let evs = self
            .commands
            .cancel_tickets(now, why, |t| step_tickets.contains(&t));
        let job = self.job.take();
        // With the job gone, the cancelled commands are only recorded.
        let _ = self.on_command_events(now, evs);
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
        if self.mission.cancel(why).is_some() {
            self.link_event(LinkEvent::MissionTransferCancelled(why.to_string()), false);
        }
        self.zone_target = None;
        self.last = None;
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
