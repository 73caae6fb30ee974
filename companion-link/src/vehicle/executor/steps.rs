//! The executor's steps, one kind each: how a mode, an arm, a command, a mission upload, a
//! reposition and the zone's arrival are carried out and recorded.

use super::*;
use crate::telemetry::LINK_READS;

impl Executor {
    /// The zone reposition was accepted: done when within the zone radius, or after the
    /// timeout (landing where the vehicle is).
    pub(super) fn arrive_step(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        target: (i32, i32),
        since: Duration,
    ) -> Advance {
        let off = io.telemetry.position.map(|p| {
            let (n, e) = crate::telemetry::offset_m(target, (p.lat_e7, p.lon_e7));
            n.hypot(e)
        });
        let result = match off {
            Some(d) if d <= io.cfg.zone_radius_m => {
                CommandOutcome::Arrived(format!("{d:.1} m from the zone"))
            }
            _ if now.saturating_sub(since) >= io.cfg.zone_arrive_timeout => {
                CommandOutcome::Timeout(Some(format!(
                    "not within {:.1} m of the zone after {:.0} s{}; landing here",
                    io.cfg.zone_radius_m,
                    io.cfg.zone_arrive_timeout.as_secs_f64(),
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        mode: FlightMode,
        out: &mut Vec<Msg>,
    ) -> Advance {
        // Landing and return never wait.
        let shown = io.telemetry.mode.and_then(ReportedMode::known);
        if io.flavor == Flavor::Px4
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
            .find(|(_, at)| io.mode_heard_at.is_none_or(|h| *at >= h))
            .is_some_and(|(m, _)| *m != mode);
        self.note_mode(now, mode);
        if modes::is_in_mode(io.flavor, io.telemetry.custom_mode, mode)
            && io.telemetry.mode.is_some()
            && !stale
        {
            self.record_step(action, format!("SET_MODE {mode}"), CommandOutcome::Already);
            self.step_done();
            return Advance::Again;
        }
        match modes::set_mode_command(io.flavor, mode) {
            Some(spec) => {
                let shown = io
                    .telemetry
                    .mode
                    .is_some()
                    .then_some(io.telemetry.custom_mode);
                if let Some(j) = &mut self.job {
                    if j.mode_attempts == 0 {
                        j.mode_from = shown;
                    }
                    j.mode_attempts += 1;
                }
                self.issued(io, now, &action, format!("SET_MODE {mode}"), spec, out)
            }
            None => {
                let result = CommandOutcome::Failed(Some(format!(
                    "no {mode} mode for {}",
                    io.flavor.name()
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        name: FlightMode,
        from: Option<u32>,
        since: Duration,
    ) -> Advance {
        let heard_since = io.mode_heard_at.is_some_and(|h| h > since);
        if heard_since && modes::is_in_mode(io.flavor, io.telemetry.custom_mode, name) {
            self.step_done();
            return Advance::Again;
        }
        if now.saturating_sub(since) < io.cfg.mode_confirm {
            return Advance::Wait;
        }
        let shown = io
            .telemetry
            .mode
            .map_or_else(|| "?".into(), |m| m.to_string());
        let unchanged = heard_since && from == Some(io.telemetry.custom_mode);
        let attempts = self.job.as_ref().map_or(0, |j| j.mode_attempts);
        let waited = io.cfg.mode_confirm.as_secs_f64();
        if unchanged && attempts < io.cfg.max_mode_attempts {
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        if io.telemetry.armed {
            self.record_step(action, "ARM".into(), CommandOutcome::Already);
            self.step_done();
            return Advance::Again;
        }
        match io.readiness.check() {
            Ok(()) => {
                // Arm only in the mode this companion set last (ArduCopter may leave GUIDED
                // for its RC mode switch right after accepting it): wait for a heartbeat
                // newer than the mode command; if it shows another mode, this take-off
                // fails and the next request sets the mode again.
                if io.flavor == Flavor::ArduPilot
                    && let Some((want, at)) = self.commanded_modes.last().copied()
                    && !modes::is_in_mode(io.flavor, io.telemetry.custom_mode, want)
                {
                    // The mode is shown by a heartbeat sent after the autopilot handled the
                    // command: on an ordered link, one heard after its ACK (a heartbeat heard
                    // between our send and the ACK may predate the change).
                    let shown_after = self.mode_acked_at.filter(|&a| a >= at).unwrap_or(at);
                    if io.mode_heard_at.is_none_or(|h| h <= shown_after) {
                        return Advance::Wait;
                    }
                    let now_mode = io
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
                self.issued(io, now, &action, "ARM".into(), spec, out)
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
                if now.saturating_sub(since) >= io.cfg.arm_wait {
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        command: MavCmd,
        params: [f32; 7],
        out: &mut Vec<Msg>,
    ) -> Advance {
        // Before take-off the vehicle stands at home: its AMSL altitude serves
        // until HOME_POSITION arrives.
        let home_amsl_m = io.telemetry.home.map(|h| h.2).or_else(|| {
            io.telemetry
                .position
                .filter(|_| !io.telemetry.armed)
                .map(|p| p.alt_amsl_m)
        });
        let Some(params) = modes::command_params(io.flavor, command, params, home_amsl_m) else {
            self.record_step(
                action,
                crate::mavlink_name(&command),
                CommandOutcome::Failed(Some("no home position yet".into())),
            );
            self.job_failed(now);
            return Advance::Again;
        };
        if command == MavCmd::MAV_CMD_NAV_TAKEOFF && io.flavor == Flavor::Px4 {
            // PX4 flies a take-off command in its TAKEOFF mode.
            self.note_mode(now, FlightMode::Takeoff);
        }
        let spec = CommandSpec::long(command, params);
        self.issued(io, now, &action, crate::mavlink_name(&command), spec, out)
    }

    pub(super) fn upload_mission_step(
        &mut self,
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        let home = io
            .telemetry
            .home
            .map(|h| (h.0, h.1))
            .or_else(|| io.telemetry.position.map(|p| (p.lat_e7, p.lon_e7)));
        let (Some(route), Some(home)) = (&io.route, home) else {
            let why = if io.route.is_none() {
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
        let items = route.mission_items(io.flavor, home);
        match io.mission.upload(now, items) {
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        o: Offset,
        out: &mut Vec<Msg>,
    ) -> Advance {
        match self.reposition_spec(io, o) {
            Some(spec) => {
                self.note_reposition(now);
                self.issued(io, now, &action, "MAV_CMD_DO_REPOSITION".into(), spec, out)
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
        io: &mut Ports<'_>,
        now: Duration,
        action: String,
        out: &mut Vec<Msg>,
    ) -> Advance {
        let zone = (
            io.telemetry.get(LINK_READS[0]),
            io.telemetry.get(LINK_READS[1]),
            io.telemetry.position,
        );
        match zone {
            (Some(n), Some(e), Some(p)) => {
                let (x, y) = displace((p.lat_e7, p.lon_e7), n, e);
                let (frame, z) =
                    modes::reposition_frame_alt(io.flavor, p.alt_rel_m, p.alt_amsl_m, p.alt_rel_m);
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
                    io,
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

    pub(super) fn reposition_spec(&self, io: &Ports<'_>, o: Offset) -> Option<CommandSpec> {
        let p = io.telemetry.position?;
        let h = p.heading_deg?.to_radians();
        let north = o.forward_m * h.cos() - o.right_m * h.sin();
        let east = o.forward_m * h.sin() + o.right_m * h.cos();
        let (x, y) = displace((p.lat_e7, p.lon_e7), north, east);
        let (frame, z) =
            modes::reposition_frame_alt(io.flavor, p.alt_rel_m + o.up_m, p.alt_amsl_m, p.alt_rel_m);
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
}
