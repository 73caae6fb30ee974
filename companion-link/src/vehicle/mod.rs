//! The whole link protocol for one autopilot, sans IO: identity, streams, liveness, readiness,
//! telemetry, commands, missions, and the executor that turns primitive vehicle actions into
//! protocol steps. `fly` feeds it frames and clock ticks and sends what it returns.

mod executor;
mod identity;
mod job;
mod launch;
mod mission_watch;
mod pack;
#[cfg(test)]
mod tests;

use super::Msg;
use super::actions::{ActionTable, Offset, Route, Step};
use super::command::{
    CommandClient, CommandConfig, CommandEvent, CommandSpec, FailReason, Outcome,
};
use super::dialect::*;
use super::ingest::Frame;
use super::liveness::{Liveness, LivenessEvent};
use super::mission::{MissionClient, MissionConfig, MissionEvent, MissionOp};
use super::modes::{self, Flavor, FlightMode, ReportedMode};
use super::readiness::Readiness;
use super::telemetry::{PackParam, Telemetry, TelemetryConfig, displace};
use companion_core::observations::Observations;
use companion_core::record::{CommandOutcome, CommandRecord, Event, LinkEvent};
use executor::{Purpose, step_name};
use identity::Choice;
pub use identity::{AUTOPILOT_COMPONENT, OTHER_COMPONENT_WAIT, is_autopilot_heartbeat};
use job::{Job, JobKey, JobStatus, Running};
pub use launch::{
    Launch, LaunchCommand, LaunchOutcome, StopReading, StopVerdict, UpEvidence, stop_verdict,
};
use mission_watch::MissionWatch;
pub use mission_watch::{AutopilotMission, MISSION_POLL};
use pack::PackRequest;
pub use pack::{PACK_PARAM_ATTEMPTS, PACK_PARAM_RETRY, ParamUse, pack_params, speed_params};
use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

/// Settings of the vehicle link, from params/link.toml and the `fly` flags.
#[derive(Debug, Clone)]
pub struct VehicleConfig {
    /// Command protocol timing.
    pub command: CommandConfig,
    /// Mission protocol timing.
    pub mission: MissionConfig,
    /// Silence from the autopilot after which the link counts as lost.
    pub link_timeout: Duration,
    /// (message id, Hz) requested with SET_MESSAGE_INTERVAL.
    pub streams: Vec<(u32, f32)>,
    /// (flavour, message id): streams that autopilot flavour does not send, never requested
    /// from it (ArduPilot answers such a request with `No ap_message for mavlink id (N)` to the
    /// ground station).
    pub streams_not_sent: Vec<(Flavor, u32)>,
    /// Telemetry settings.
    pub telemetry: TelemetryConfig,
    /// Time to wait for the autopilot to report ready before an arm step fails.
    pub arm_wait: Duration,
    /// Arm attempts, each only after a fresh ready report.
    pub max_arm_attempts: u32,
    /// Only the autopilot with this system id is chosen (`fly --autopilot-sysid`) ...
    pub autopilot_sysid: Option<u8>,
    /// ... and this component id (`fly --autopilot-compid`, default 1 = MAV_COMP_ID_AUTOPILOT1);
    /// read only when `autopilot_sysid` is set.
    pub autopilot_compid: u8,
    /// Streams are re-requested (connect, reconnect, regain, reboot) no more often than this:
    /// spoofed or flapping triggers cannot multiply the requests.
    pub stream_request_min_interval: Duration,
    /// "Land at the zone": the vehicle must be this close to the zone (m) before LAND.
    pub zone_radius_m: f64,
    /// ... and gets this long to get there; then it lands where it is (said in the record).
    pub zone_arrive_timeout: Duration,
    /// PX4: an accepted SET_MODE is done only when a HEARTBEAT shows the mode within this long.
    pub mode_confirm: Duration,
    /// PX4: SET_MODE attempts while the vehicle stays in the mode it was in.
    pub max_mode_attempts: u32,
    /// Without EXTENDED_SYS_STATE: disarmed at or below this altitude above home (m) is on the
    /// ground (params/link.toml `[flight] ground_altitude_m`).
    pub ground_altitude_m: f64,
    /// The tracker's reports (NAMED_VALUE_FLOAT, CAMERA_TRACKING_IMAGE_STATUS) are taken only
    /// from the `--onboard` link ([`Vehicle::on_monitor_frame`]); on the autopilot link they are
    /// counted as refused, whoever sends them (`fly --learn-cpt` learning from a dedicated
    /// onboard link while the autopilot link is unsigned).
    pub tracker_onboard_only: bool,
}

/// A tracker's report, which in-flight learning reads (`target_detected`).
fn is_tracker_report(msg: &Msg) -> bool {
    matches!(
        msg,
        Msg::NAMED_VALUE_FLOAT(_) | Msg::CAMERA_TRACKING_IMAGE_STATUS(_)
    )
}

impl Default for VehicleConfig {
    fn default() -> Self {
        Self {
            command: CommandConfig::default(),
            mission: MissionConfig::default(),
            link_timeout: Duration::from_secs(3),
            streams: Vec::new(),
            streams_not_sent: Vec::new(),
            telemetry: TelemetryConfig::default(),
            arm_wait: Duration::from_secs(60),
            max_arm_attempts: 3,
            autopilot_sysid: None,
            autopilot_compid: AUTOPILOT_COMPONENT,
            stream_request_min_interval: Duration::from_secs(5),
            zone_radius_m: 3.0,
            zone_arrive_timeout: Duration::from_secs(60),
            mode_confirm: Duration::from_secs(3),
            max_mode_attempts: 3,
            ground_altitude_m: 1.0,
            tracker_onboard_only: false,
        }
    }
}

/// A command addressed to this companion (our system, component 191), kept for the shell, which
/// answers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandToUs {
    /// The MAV_CMD.
    pub command: MavCmd,
    /// Sender (system, component) from the frame header.
    pub from: (u8, u8),
    /// When it arrived (shell clock): a command that waited too long is refused, never run late.
    pub at: Duration,
    /// The autopilot was not known yet when it arrived: refused, never queued for later.
    pub before_autopilot: bool,
}

/// The link protocol state for one autopilot.
pub struct Vehicle {
    /// Link settings.
    pub cfg: VehicleConfig,
    /// (system, component) of the autopilot, once its HEARTBEAT is seen.
    pub target: Option<(u8, u8)>,
    /// Autopilot family, from its HEARTBEAT (`Other` until one is seen).
    pub flavor: Flavor,
    /// COMMAND_LONG / COMMAND_INT client.
    pub commands: CommandClient,
    /// Mission protocol client.
    pub mission: MissionClient,
    /// Whether the autopilot is still heard.
    pub liveness: Liveness,
    /// Whether the autopilot reports itself ready to arm.
    pub readiness: Readiness,
    /// Telemetry turned into observations.
    pub telemetry: Telemetry,
    /// Vehicle action name -> steps (params/commands.toml).
    pub actions: ActionTable,
    /// The route `follow_trajectory` uploads, if one was given.
    pub route: Option<Route>,
    purposes: BTreeMap<u64, Purpose>,
    job: Option<Job>,
    last: Option<(JobKey, JobStatus)>,
    stream_queue: VecDeque<(u32, f32)>,
    /// Significant events since the last `take_events` (trigger a decision cycle).
    events: Vec<Event>,
    /// Command records since the last `take_records`.
    records: Vec<CommandRecord>,
    link_events: Vec<LinkEvent>,
    /// Retry a failed action asked for again no sooner than this.
    pub retry_failed_after: Duration,
    /// When the stream requests were last queued, and whether another set is waiting for the
    /// minimum interval.
    streams_queued_at: Option<Duration>,
    streams_deferred: bool,
    /// Without a pin: an autopilot on a component other than 1, and when it was first heard,
    /// waiting [`OTHER_COMPONENT_WAIT`] for a component-1 autopilot before it is chosen.
    candidate: Option<((u8, u8), Duration)>,
    /// Other autopilots heard (reported once each, never obeyed).
    other_autopilots: std::collections::BTreeSet<(u8, u8)>,
    /// Refused for trust reasons since start: monitor frames from components not allowed, and
    /// the totals as last reported in a link event.
    pub foreign_monitor_frames: u64,
    /// HEARTBEATs from other autopilots, ignored, since start.
    pub other_autopilot_heartbeats: u64,
    trust_reported: (u64, u64, u64, u64),
    /// Consecutive autopilot heartbeats reporting the vehicle armed (0 once one says disarmed).
    pub armed_heartbeats: u32,
    /// Modes this companion commanded (or made the autopilot enter, as a reposition enters
    /// GUIDED), with when; the newest last, a few kept. The operator gate tells its own mode
    /// changes from a pilot's with them.
    pub commanded_modes: Vec<(FlightMode, Duration)>,
    /// Commands addressed to this companion (component 191) since the last
    /// [`Vehicle::take_commands_to_us`].
    commands_to_us: Vec<CommandToUs>,
    /// Since when every autopilot heartbeat has reported the vehicle armed (None once one
    /// reports it disarmed).
    armed_since: Option<Duration>,
    /// The custom mode of the last autopilot heartbeat, and since when every heartbeat has
    /// shown it.
    mode_since: Option<(u32, Duration)>,
    /// Since when every autopilot frame has agreed that the vehicle is disarmed on the ground
    /// (heartbeats disarmed, altitude at most `ground_altitude_m`, landed state ON_GROUND);
    /// any contradicting frame resets it.
    down_since: Option<Duration>,
    /// The hand-off job's mode, once [`Vehicle::hand_off`] issued it.
    handoff: Option<FlightMode>,
    /// Where the running zone reposition goes.
    zone_target: Option<(i32, i32)>,
    /// When the autopilot last reported its mode (its heartbeat).
    mode_heard_at: Option<Duration>,
    /// When the autopilot last accepted a mode step of a job (its COMMAND_ACK): only a
    /// heartbeat heard after that can show the new mode (one sent before the autopilot handled
    /// the command may arrive after we sent it, still showing the old mode).
    mode_acked_at: Option<Duration>,
    /// PX4 only: after an upload, (item count, give-up time) until MISSION_CURRENT reports the
    /// new mission's total. PX4's navigator loads an uploaded mission asynchronously; AUTO
    /// requested before that flies the old (empty) one, "finishes" it at once and falls back to
    /// Hold (seen on PX4 SITL with the mode switch 10 ms after the upload).
    px4_mission_pending: Option<(u16, Duration)>,
    /// PX4 only: give-up time for waiting out AUTO.TAKEOFF before another mode. PX4 ends a
    /// take-off by switching itself to Hold; a mode requested in the take-off's last moments is
    /// acknowledged and then overridden by that switch (seen on PX4 SITL: AUTO accepted at 8-9 m
    /// of a 10 m take-off, then Hold, the mission never flown).
    px4_takeoff_wait: Option<Duration>,
    /// The pack parameters asked for (the chosen autopilot's family's [`pack_params`]).
    pack_requests: Vec<PackRequest>,
    /// The companion's last ARM and last take-off command, and their answers so far (the stop
    /// reads them).
    launches: Vec<Launch>,
    /// The last autopilot frame that said armed or in the air: what, and when.
    up_seen: Option<(UpEvidence, Duration)>,
    /// The autopilot's own mission, when it is the one flown (`fly --mission autopilot`).
    watch: MissionWatch,
}

impl Vehicle {
    /// A link to no autopilot yet: it chooses one on its first HEARTBEAT.
    pub fn new(cfg: VehicleConfig, actions: ActionTable, route: Option<Route>) -> Self {
        Self {
            commands: CommandClient::new(cfg.command),
            mission: MissionClient::new(cfg.mission),
            liveness: Liveness::new(cfg.link_timeout),
            telemetry: Telemetry::new(cfg.telemetry.clone()),
            readiness: Readiness::default(),
            cfg,
            target: None,
            flavor: Flavor::Other,
            actions,
            route,
            purposes: BTreeMap::new(),
            job: None,
            last: None,
            stream_queue: VecDeque::new(),
            events: Vec::new(),
            records: Vec::new(),
            link_events: Vec::new(),
            retry_failed_after: Duration::from_secs(5),
            streams_queued_at: None,
            streams_deferred: false,
            candidate: None,
            other_autopilots: Default::default(),
            foreign_monitor_frames: 0,
            other_autopilot_heartbeats: 0,
            trust_reported: (0, 0, 0, 0),
            armed_heartbeats: 0,
            commanded_modes: Vec::new(),
            commands_to_us: Vec::new(),
            armed_since: None,
            mode_since: None,
            down_since: None,
            handoff: None,
            zone_target: None,
            mode_heard_at: None,
            mode_acked_at: None,
            px4_mission_pending: None,
            px4_takeoff_wait: None,
            pack_requests: Vec::new(),
            launches: Vec::new(),
            up_seen: None,
            watch: MissionWatch::default(),
        }
    }

    /// The system id we use in our headers: the autopilot's (we are a component of its vehicle).
    pub fn our_system(&self) -> u8 {
        self.target.map(|t| t.0).unwrap_or(super::DEFAULT_SYSTEM_ID)
    }

    /// Our 1 Hz HEARTBEAT: an onboard controller, not an autopilot.
    pub fn heartbeat() -> Msg {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    /// Whether significant events wait to be taken (they trigger a decision cycle).
    pub fn has_events(&self) -> bool {
        !self.events.is_empty()
    }
    /// Take the significant events since the last call.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }
    /// Take the command records since the last call.
    pub fn take_records(&mut self) -> Vec<CommandRecord> {
        std::mem::take(&mut self.records)
    }
    /// Take the link events since the last call, with a trust note when refused frames were
    /// counted.
    pub fn take_link_events(&mut self) -> Vec<LinkEvent> {
        if let Some(note) = self.trust_note() {
            self.link_events.push(LinkEvent::Other(note));
        }
        std::mem::take(&mut self.link_events)
    }

    /// Queue every stream request, unless a set was queued less than the minimum interval ago:
    /// then once that interval has passed.
    fn request_streams(&mut self, now: Duration) {
        let due = self
            .streams_queued_at
            .is_none_or(|t| now.saturating_sub(t) >= self.cfg.stream_request_min_interval);
        if due {
            let flavor = self.flavor;
            let not_sent = &self.cfg.streams_not_sent;
            self.stream_queue = self
                .cfg
                .streams
                .iter()
                .filter(|(id, _)| !not_sent.contains(&(flavor, *id)))
                .copied()
                .collect();
            self.streams_queued_at = Some(now);
            self.streams_deferred = false;
            if !self.stream_queue.is_empty() {
                tracing::debug!(count = self.stream_queue.len(), "requesting streams");
            }
        } else {
            self.streams_deferred = true;
        }
    }

    /// An observation snapshot at `now` from the latest telemetry, carrying `events`.
    pub fn observations(&self, now: Duration, events: Vec<Event>) -> Observations {
        self.telemetry.observations(now, events)
    }

    fn link_event(&mut self, e: LinkEvent, significant: bool) {
        if significant {
            self.events.push(Event::from(e.clone()));
        }
        self.link_events.push(e);
    }

    /// A frame from the autopilot link.
    pub fn on_frame(&mut self, now: Duration, f: &Frame) -> Vec<Msg> {
        if self.command_to_us(now, f) {
            return Vec::new();
        }
        let sys = f.header.system_id.min(255) as u8;
        let comp = f.header.component_id;
        if let Msg::HEARTBEAT(h) = &f.msg
            && is_autopilot_heartbeat(h)
            && self.target != Some((sys, comp))
        {
            let choice = self.choice(now, sys, comp);
            if choice == Choice::Take {
                self.candidate = None;
                self.target = Some((sys, comp));
                self.flavor = Flavor::from_autopilot(h.autopilot);
                self.readiness.flavor = self.flavor;
                self.mission.home_at_seq0 = self.flavor != Flavor::Px4;
                self.commands.set_target(sys, comp);
                self.mission.set_target(sys, comp);
                self.reset_pack_requests();
                self.reset_mission_watch();
                tracing::info!(sys, comp, flavor = ?self.flavor, "autopilot chosen");
                self.link_event(
                    LinkEvent::Autopilot {
                        system: sys,
                        component: comp,
                        flavor: self.flavor.name().to_string(),
                    },
                    false,
                );
                if let Some(note) = self.identity_note() {
                    self.link_event(LinkEvent::Other(note), false);
                }
            } else if choice == Choice::Other {
                self.other_autopilot(sys, comp);
            }
        }
        let from_autopilot = self.target == Some((sys, comp));
        if self.cfg.tracker_onboard_only && is_tracker_report(&f.msg) {
            if self.foreign_monitor_frames == 0 {
                tracing::warn!(
                    sys,
                    comp,
                    "a tracker report on the autopilot link ignored: taken only from the --onboard link"
                );
            }
            self.foreign_monitor_frames += 1;
            return Vec::new();
        }
        if !from_autopilot {
            // Onboard monitors speak on the same link from their own components.
            return self.on_monitor_frame(now, f);
        }
        let mut out = Vec::new();
        if let Some(ev) = self.liveness.on_message(now) {
            out.extend(self.on_liveness(now, ev));
        }
        if let Msg::SYSTEM_TIME(t) = &f.msg
            && let Some(ev) = self.liveness.on_boot_time(t.time_boot_ms)
        {
            out.extend(self.on_liveness(now, ev));
        }
        let flavor = self.flavor;
        let ev = self.telemetry.on_message(now, &f.msg, flavor);
        self.events.extend(ev);
        match &f.msg {
            Msg::HEARTBEAT(h) => {
                self.readiness.armed = h
                    .base_mode
                    .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                self.mode_heard_at = Some(now);
                self.armed_heartbeats = if self.readiness.armed {
                    self.armed_heartbeats.saturating_add(1)
                } else {
                    0
                };
                if self.readiness.armed {
                    self.armed_since.get_or_insert(now);
                    self.down_since = None;
                    self.note_up(now, UpEvidence::Armed);
                } else {
                    self.armed_since = None;
                    if self.low_now() {
                        self.down_since.get_or_insert(now);
                    } else {
                        self.down_since = None;
                    }
                }
                if self.mode_since.map(|(m, _)| m) != Some(h.custom_mode) {
                    self.mode_since = Some((h.custom_mode, now));
                }
                self.readiness.on_heartbeat_status(h.system_status);
            }
            Msg::SYS_STATUS(s) => self.readiness.on_sys_status(now, s),
            // Frames that say "in the air" reset the end-of-flight window.
            Msg::GLOBAL_POSITION_INT(_) | Msg::EXTENDED_SYS_STATE(_) if !self.low_now() => {
                self.down_since = None;
                self.note_up(now, UpEvidence::Airborne);
            }
            Msg::EKF_STATUS_REPORT(e) => self.readiness.on_ekf(now, e),
            Msg::ESTIMATOR_STATUS(e) => self.readiness.on_estimator(now, e),
            Msg::MISSION_CURRENT(m) => {
                if matches!(self.px4_mission_pending, Some((n, _)) if n == m.total) {
                    self.px4_mission_pending = None;
                }
                self.watch_mission_current(m);
            }
            Msg::STATUSTEXT(t) => {
                let text = t.text.to_str().unwrap_or("").to_string();
                self.readiness.on_text(now, &text);
                if (t.severity as u8) <= (MavSeverity::MAV_SEVERITY_WARNING as u8) {
                    self.link_event(LinkEvent::AutopilotText(text), false);
                }
            }
            Msg::PARAM_VALUE(p) => self.on_param_value(p),
            Msg::COMMAND_ACK(a) => {
                let (msgs, evs) = self.commands.on_ack(now, a);
                out.extend(msgs);
                out.extend(self.on_command_events(now, evs));
            }
            _ => {}
        }
        let (msgs, evs) = self.mission.on_message(now, &f.msg);
        out.extend(msgs);
        out.extend(self.on_mission_events(now, evs));
        out.extend(self.pump(now));
        out
    }

    /// A frame from an onboard monitor (on the autopilot link from another component, or on
    /// the `--onboard` link): telemetry only. Only the chosen autopilot and the components `[telemetry.monitors]` names are heard;
    /// frames from anyone else are counted and dropped.
    pub fn on_monitor_frame(&mut self, now: Duration, f: &Frame) -> Vec<Msg> {
        if matches!(
            f.msg,
            Msg::NAMED_VALUE_FLOAT(_)
                | Msg::CAMERA_TRACKING_IMAGE_STATUS(_)
                | Msg::OBSTACLE_DISTANCE(_)
                | Msg::DISTANCE_SENSOR(_)
        ) {
            let sys = f.header.system_id.min(255) as u8;
            let comp = f.header.component_id;
            if !self.cfg.telemetry.monitors.allows(sys, comp, self.target) {
                if self.foreign_monitor_frames == 0 {
                    tracing::warn!(
                        sys,
                        comp,
                        "onboard-monitor values from a component not in [telemetry.monitors] ignored"
                    );
                }
                self.foreign_monitor_frames += 1;
                return Vec::new();
            }
            let flavor = self.flavor;
            let ev = self.telemetry.on_message(now, &f.msg, flavor);
            self.events.extend(ev);
        }
        Vec::new()
    }

    fn on_liveness(&mut self, now: Duration, ev: LivenessEvent) -> Vec<Msg> {
        match ev {
            LivenessEvent::Connected | LivenessEvent::Regained | LivenessEvent::Rebooted => {
                if ev == LivenessEvent::Rebooted {
                    self.readiness.reset();
                    self.reset_pack_requests();
                    self.drop_everything(now, "autopilot rebooted");
                    self.reset_mission_watch();
                }
                let link = match ev {
                    LivenessEvent::Connected => LinkEvent::Connected,
                    LivenessEvent::Regained => LinkEvent::Regained,
                    _ => LinkEvent::Rebooted,
                };
                tracing::info!("{link}");
                self.link_event(link, true);
                self.request_streams(now);
                Vec::new()
            }
            LivenessEvent::Lost => {
                tracing::warn!(
                    "link lost: no message from the autopilot for {} s",
                    self.cfg.link_timeout.as_secs_f64()
                );
                self.drop_everything(now, "link lost");
                self.link_event(LinkEvent::Lost, true);
                Vec::new()
            }
        }
    }

    /// Stop commanding: pending commands, mission transfer and the running action end now, and
    /// none of them is replayed later.
    fn drop_everything(&mut self, now: Duration, why: &str) {
        let evs = self.commands.cancel_all(now, why);
        let _ = self.on_command_events(now, evs);
        if let Some(ev) = self.mission.cancel(why) {
            let _ = self.on_mission_events(now, vec![ev]);
        }
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
        self.stream_queue.clear();
        self.streams_deferred = false;
        self.purposes.clear();
    }

    /// Transport reconnected: the new stream is a new session (streams re-requested, sent once
    /// the autopilot speaks). A reconnect is not a message from the autopilot: liveness counts
    /// only its frames, so a link that reconnects over and over is still declared lost.
    pub fn on_reconnect(&mut self, now: Duration) {
        if self.liveness.alive() {
            self.request_streams(now);
            self.link_event(LinkEvent::TransportReconnected, true);
        }
    }

    /// Advance time.
    pub fn tick(&mut self, now: Duration) -> Vec<Msg> {
        let mut out = Vec::new();
        if let Some(ev) = self.liveness.tick(now) {
            out.extend(self.on_liveness(now, ev));
        }
        if !self.liveness.alive() {
            return out;
        }
        let (msgs, evs) = self.commands.tick(now);
        out.extend(msgs);
        out.extend(self.on_command_events(now, evs));
        let (msgs, evs) = self.mission.tick(now);
        out.extend(msgs);
        out.extend(self.on_mission_events(now, evs));
        out.extend(self.pump(now));
        out
    }

    /// Send the next stream request and advance the running job.
    fn pump(&mut self, now: Duration) -> Vec<Msg> {
        let mut out = Vec::new();
        if !self.liveness.alive() || self.target.is_none() {
            return out;
        }
        if self.streams_deferred {
            self.request_streams(now);
        }
        if !self
            .commands
            .in_flight(MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL)
            && let Some((id, hz)) = self.stream_queue.pop_front()
        {
            let spec = CommandSpec::long(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                [id as f32, 1e6 / hz, 0., 0., 0., 0., 0.],
            );
            if let Ok((ticket, msgs)) = self.commands.submit(now, spec) {
                self.purposes.insert(ticket, Purpose::Stream(id));
                out.extend(msgs);
            }
        }
        self.request_pack_params(now, &mut out);
        self.pump_mission_watch(now, &mut out);
        out.extend(self.advance_job(now));
        out
    }

    /// A COMMAND_LONG / COMMAND_INT addressed to this companion (our system, component 191)
    /// from anyone on the link: kept for the shell, which answers it, even before the autopilot
    /// is known (the shell refuses such a command; it is never queued for later). True when it
    /// was one.
    fn command_to_us(&mut self, now: Duration, f: &Frame) -> bool {
        let (command, sys, comp) = match &f.msg {
            Msg::COMMAND_LONG(c) => (c.command, c.target_system, c.target_component),
            Msg::COMMAND_INT(c) => (c.command, c.target_system, c.target_component),
            _ => return false,
        };
        if comp != super::OUR_COMPONENT_ID || sys != self.our_system() {
            return false;
        }
        if self.commands_to_us.len() < 16 {
            self.commands_to_us.push(CommandToUs {
                command,
                from: (f.header.system_id.min(255) as u8, f.header.component_id),
                at: now,
                before_autopilot: self.target.is_none(),
            });
        }
        true
    }

    /// Commands addressed to us since the last call.
    pub fn take_commands_to_us(&mut self) -> Vec<CommandToUs> {
        std::mem::take(&mut self.commands_to_us)
    }

    /// Every autopilot heartbeat has reported the vehicle armed for this long (None: the last
    /// one reported it disarmed, or none was heard).
    pub fn armed_for(&self, now: Duration) -> Option<Duration> {
        self.armed_since.map(|s| now.saturating_sub(s))
    }

    /// Every autopilot heartbeat has shown the current custom mode for this long.
    pub fn mode_for(&self, now: Duration) -> Duration {
        self.mode_since
            .map_or(Duration::ZERO, |(_, s)| now.saturating_sub(s))
    }

    /// Every autopilot frame has agreed for this long that the vehicle is disarmed on the
    /// ground (None: the last one disagreed).
    pub fn down_for(&self, now: Duration) -> Option<Duration> {
        self.down_since.map(|s| now.saturating_sub(s))
    }

    /// The last telemetry puts the vehicle low: landed state ON_GROUND when the autopilot
    /// reports one, else at most `ground_altitude_m` above home (or no position yet).
    fn low_now(&self) -> bool {
        match self.telemetry.landed_state.as_deref() {
            Some(s) => s == "ON_GROUND",
            None => self
                .telemetry
                .position
                .is_none_or(|p| p.alt_rel_m <= self.cfg.ground_altitude_m),
        }
    }
}
