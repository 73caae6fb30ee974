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
use super::actions::Flown;
use super::actions::{ActionTable, Offset, Route, Step};
use super::command::{
    CommandClient, CommandConfig, CommandEvent, CommandSpec, FailReason, Outcome,
};
use super::dialect::*;
use super::ingest::Frame;
use super::liveness::{Liveness, LivenessEvent};
use super::mission::MissionItem;
use super::mission::{MissionClient, MissionConfig, MissionEvent, MissionOp};
use super::modes::{self, Flavor, FlightMode, ReportedMode};
use super::readiness::Readiness;
use super::telemetry::{PackParam, Telemetry, TelemetryConfig, displace};
use companion_core::observations::Observations;
use companion_core::record::{CommandOutcome, CommandRecord, Event, LinkEvent};
use executor::{Executor, Ports};
pub use identity::{AUTOPILOT_COMPONENT, OTHER_COMPONENT_WAIT, is_autopilot_heartbeat};
use identity::{Choice, Identity};
use job::{Job, JobKey, JobStatus, Running};
use launch::Launches;
pub use launch::{
    Launch, LaunchCommand, LaunchOutcome, StopReading, StopVerdict, UpEvidence, stop_verdict,
};
use mission_watch::MissionWatch;
pub use mission_watch::{AutopilotMission, MISSION_POLL};
use pack::PackRequests;
pub use pack::{PACK_PARAM_ATTEMPTS, PACK_PARAM_RETRY, ParamUse, pack_params, speed_params};
use std::collections::VecDeque;
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
    cfg: VehicleConfig,
    /// (system, component) of the autopilot, once its HEARTBEAT is seen.
    target: Option<(u8, u8)>,
    /// Autopilot family, from its HEARTBEAT (`Other` until one is seen).
    flavor: Flavor,
    /// COMMAND_LONG / COMMAND_INT client.
    commands: CommandClient,
    /// Mission protocol client.
    mission: MissionClient,
    /// Whether the autopilot is still heard.
    liveness: Liveness,
    /// Whether the autopilot reports itself ready to arm.
    readiness: Readiness,
    /// Telemetry turned into observations.
    telemetry: Telemetry,
    /// Vehicle action name -> steps (params/commands.toml).
    actions: ActionTable,
    /// The route `follow_trajectory` uploads, if one was given.
    route: Option<Route>,
    /// The mode each uploaded route item flies by itself, by seq, for each upload flavour: the
    /// route is fixed at construction, and [`Vehicle::mission_item_mode`] asks on every loop
    /// turn while the autopilot reports RTL or LAND.
    route_item_modes: RouteItemModes,
    /// The command executor: the running action's steps, the commands in flight, the records.
    exec: Executor,
    stream_queue: VecDeque<(u32, f32)>,
    /// Significant events since the last `take_events` (trigger a decision cycle).
    events: Vec<Event>,
    link_events: Vec<LinkEvent>,
    /// When the stream requests were last queued, and whether another set is waiting for the
    /// minimum interval.
    streams_queued_at: Option<Duration>,
    streams_deferred: bool,
    /// Which autopilot is obeyed, who else was heard, the trust counters.
    identity: Identity,
    /// Consecutive autopilot heartbeats reporting the vehicle armed (0 once one says disarmed).
    armed_heartbeats: u32,
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
    /// When the autopilot last reported its mode (its heartbeat).
    mode_heard_at: Option<Duration>,
    /// The pack parameters asked for.
    pack_requests: PackRequests,
    /// The stop's memory: the companion's last ARM and take-off, the last frame that said up.
    launches: Launches,
    /// The autopilot's own mission, when it is the one flown (`fly --mission autopilot`).
    watch: MissionWatch,
}

/// The mode each item of the uploaded route flies by itself (RTL, LAND or none), by seq: PX4
/// gets other items than the rest ([`Route::mission_items`]).
#[derive(Debug, Default)]
struct RouteItemModes {
    px4: Vec<Option<FlightMode>>,
    others: Vec<Option<FlightMode>>,
}

impl RouteItemModes {
    fn of(route: Option<&Route>) -> Self {
        let Some(route) = route else {
            return Self::default();
        };
        let modes = |flavor| {
            let items = route.mission_items(flavor, (0, 0));
            (items.iter())
                .map(|i| crate::operator::mission_item_mode(i.command))
                .collect()
        };
        Self {
            px4: modes(Flavor::Px4),
            others: modes(Flavor::ArduPilot),
        }
    }

    fn at(&self, flavor: Flavor, seq: usize) -> Option<FlightMode> {
        let modes = if flavor == Flavor::Px4 {
            &self.px4
        } else {
            &self.others
        };
        *modes.get(seq)?
    }
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
            route_item_modes: RouteItemModes::of(route.as_ref()),
            route,
            exec: Executor::default(),
            stream_queue: VecDeque::new(),
            events: Vec::new(),
            link_events: Vec::new(),
            streams_queued_at: None,
            streams_deferred: false,
            identity: Identity::default(),
            armed_heartbeats: 0,
            commands_to_us: Vec::new(),
            armed_since: None,
            mode_since: None,
            down_since: None,
            mode_heard_at: None,
            pack_requests: PackRequests::default(),
            launches: Launches::default(),
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
        self.exec.take_records()
    }
    /// Take the link events since the last call, with a trust note when refused frames were
    /// counted.
    pub fn take_link_events(&mut self) -> Vec<LinkEvent> {
        if let Some(note) = self.identity.trust_note(&self.telemetry, &self.cfg) {
            self.link_events.push(LinkEvent::Other(note));
        }
        std::mem::take(&mut self.link_events)
    }

    /// Pin the autopilot to obey (`--autopilot-sysid`, `--autopilot-compid`), before any
    /// HEARTBEAT is heard: without a system id the first autopilot heard is chosen.
    pub fn obeying(mut self, sysid: Option<u8>, compid: u8) -> Self {
        self.cfg.autopilot_sysid = sysid;
        self.cfg.autopilot_compid = compid;
        self
    }

    // Read-only views for the shell: it reads the link's state here and changes it only through
    // the operations above and below, so the protocol clients keep their invariants.

    /// Link settings.
    pub fn cfg(&self) -> &VehicleConfig {
        &self.cfg
    }
    /// (system, component) of the autopilot, once its HEARTBEAT is seen.
    pub fn target(&self) -> Option<(u8, u8)> {
        self.target
    }
    /// Autopilot family, from its HEARTBEAT (`Other` until one is seen).
    pub fn flavor(&self) -> Flavor {
        self.flavor
    }
    /// The latest telemetry.
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }
    /// Whether the autopilot is still heard, and how often it was lost.
    pub fn liveness(&self) -> &Liveness {
        &self.liveness
    }
    /// Whether the autopilot reports itself ready to arm (and armed).
    pub fn readiness(&self) -> &Readiness {
        &self.readiness
    }
    /// Vehicle action name -> steps (params/commands.toml).
    pub fn actions(&self) -> &ActionTable {
        &self.actions
    }
    /// The route `follow_trajectory` uploads, if one was given.
    pub fn route(&self) -> Option<&Route> {
        self.route.as_ref()
    }
    /// The mode the current mission item (MISSION_CURRENT) flies by itself, when the autopilot
    /// reports that mode now: RTL for the flown mission's own NAV_RETURN_TO_LAUNCH, LAND for its
    /// NAV_LAND ([`crate::operator::mission_item_mode`]). The mission is the autopilot's (`fly
    /// --mission autopilot`) or the route uploaded. None otherwise or unknown.
    pub fn mission_item_mode(&self) -> Option<FlightMode> {
        let t = &self.telemetry;
        let (seq, custom) = (usize::from(t.mission_seq?), t.custom_mode);
        let reports = |m| modes::is_in_mode(self.flavor, custom, m);
        if !reports(FlightMode::Rtl) && !reports(FlightMode::Land) {
            return None; // only those two: no mission items built every loop turn
        }
        if self.flies_autopilot_mission() {
            let command = self.autopilot_mission()?.get(seq)?.command;
            return crate::operator::mission_item_mode(command);
        }
        self.route_item_modes.at(self.flavor, seq)
    }
    /// Whether the autopilot answers its own home at mission seq 0 (ArduPilot) rather than
    /// storing it like any other item (PX4): set when the autopilot is chosen.
    pub fn home_at_seq0(&self) -> bool {
        self.mission.home_at_seq0
    }
    /// Consecutive autopilot heartbeats reporting the vehicle armed (0 once one says disarmed).
    pub fn armed_heartbeats(&self) -> u32 {
        self.armed_heartbeats
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
        self.ports().1.link_event(e, significant);
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
            let choice = self
                .identity
                .choice(now, (sys, comp), self.target, &self.cfg);
            if choice == Choice::Take {
                self.identity.candidate = None;
                self.target = Some((sys, comp));
                self.flavor = Flavor::from_autopilot(h.autopilot);
                self.readiness.flavor = self.flavor;
                self.mission.home_at_seq0 = self.flavor != Flavor::Px4;
                self.commands.set_target(sys, comp);
                self.mission.set_target(sys, comp);
                self.pack_requests.reset(self.flavor);
                self.watch.reset();
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
            } else if choice == Choice::Other
                && let Some(e) = self
                    .identity
                    .other_autopilot((sys, comp), self.target, &self.cfg)
            {
                self.link_event(e, false);
            }
        }
        let from_autopilot = self.target == Some((sys, comp));
        if self.cfg.tracker_onboard_only && is_tracker_report(&f.msg) {
            if self.identity.foreign_monitor_frames == 0 {
                tracing::warn!(
                    sys,
                    comp,
                    "a tracker report on the autopilot link ignored: taken only from the --onboard link"
                );
            }
            self.identity.foreign_monitor_frames += 1;
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
                    self.launches.note_up(now, UpEvidence::Armed);
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
                self.launches.note_up(now, UpEvidence::Airborne);
            }
            Msg::EKF_STATUS_REPORT(e) => self.readiness.on_ekf(now, e),
            Msg::ESTIMATOR_STATUS(e) => self.readiness.on_estimator(now, e),
            Msg::MISSION_CURRENT(m) => {
                self.exec
                    .mission_current_seen(now, m.total, m.mission_state);
                self.watch.on_mission_current(m);
            }
            Msg::STATUSTEXT(t) => {
                let text = t.text.to_str().unwrap_or("").to_string();
                self.readiness.on_text(now, &text);
                if (t.severity as u8) <= (MavSeverity::MAV_SEVERITY_WARNING as u8) {
                    self.link_event(LinkEvent::AutopilotText(text), false);
                }
            }
            Msg::PARAM_VALUE(p) => {
                let flavor = self.flavor;
                if let Some(e) = self
                    .pack_requests
                    .on_param_value(p, flavor, &mut self.telemetry)
                {
                    self.link_event(e, false);
                }
            }
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
                if self.identity.foreign_monitor_frames == 0 {
                    tracing::warn!(
                        sys,
                        comp,
                        "onboard-monitor values from a component not in [telemetry.monitors] ignored"
                    );
                }
                self.identity.foreign_monitor_frames += 1;
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
                    self.pack_requests.reset(self.flavor);
                    self.drop_everything(now, "autopilot rebooted");
                    self.watch.reset();
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
        self.exec.drop_job(now, why);
        self.stream_queue.clear();
        self.streams_deferred = false;
        self.exec.forget_tickets();
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
                self.exec.stream_requested(ticket, id);
                out.extend(msgs);
            }
        }
        self.pack_requests.request(now, self.target, &mut out);
        self.watch
            .pump(now, self.target, &mut self.mission, &mut out);
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

    /// The executor, and what it drives and reads of the rest of the vehicle, for one call.
    fn ports(&mut self) -> (&mut Executor, Ports<'_>) {
        let ports = Ports {
            cfg: &self.cfg,
            flavor: self.flavor,
            liveness: &self.liveness,
            target: self.target,
            commands: &mut self.commands,
            mission: &mut self.mission,
            readiness: &mut self.readiness,
            telemetry: &self.telemetry,
            actions: &self.actions,
            route: self.route.as_ref(),
            events: &mut self.events,
            link_events: &mut self.link_events,
            launches: &mut self.launches,
            watch: &mut self.watch,
            mode_heard_at: self.mode_heard_at,
        };
        (&mut self.exec, ports)
    }

    fn on_command_events(&mut self, now: Duration, evs: Vec<CommandEvent>) -> Vec<Msg> {
        let (exec, mut io) = self.ports();
        exec.on_command_events(&mut io, now, evs)
    }

    fn on_mission_events(&mut self, now: Duration, evs: Vec<MissionEvent>) -> Vec<Msg> {
        let (exec, mut io) = self.ports();
        exec.on_mission_events(&mut io, now, evs)
    }

    fn advance_job(&mut self, now: Duration) -> Vec<Msg> {
        let (exec, mut io) = self.ports();
        exec.advance_job(&mut io, now)
    }

    /// The decision core asked for these vehicle actions.
    /// The same action already running or done is not restarted; a different one replaces it.
    pub fn request_actions(&mut self, now: Duration, actions: &[Flown]) -> Vec<Msg> {
        let (exec, mut io) = self.ports();
        exec.request_actions(&mut io, now, actions)
    }

    /// Latency of everything sent since the last call: from the message (or decision trigger)
    /// that caused it, `trigger_at`, to the moment it was handed to the transport, `sent_at`.
    /// The shell calls this right after sending, so the measurement includes decision and
    /// encoding time, which the injected clock of the state machines cannot see.
    pub fn stamp_latency(&mut self, trigger_at: Duration, sent_at: Duration) {
        self.exec.stamp_latency(trigger_at, sent_at);
    }

    /// Whether an action is being executed (for tests and the log).
    pub fn busy(&self) -> bool {
        self.exec.busy()
    }

    /// `action` is being flown or was flown to the end (asking for it again does nothing).
    pub fn settled(&self, action: Flown) -> bool {
        self.exec.settled(action)
    }

    /// When the last action failed (its key and the time), if it did and nothing ran since.
    pub fn failed_action(&self) -> Option<(String, Duration)> {
        self.exec.failed_action(&self.actions)
    }

    /// The companion stops: whatever it was doing ends now (recorded CANCELLED) and the vehicle
    /// is put in `mode` (`LOITER`, `RTL`, `LAND`) for the autopilot to fly on its own. The
    /// step is acknowledged (or fails) like any other; [`Vehicle::handoff_status`] tells.
    pub fn hand_off(&mut self, now: Duration, mode: FlightMode) -> Vec<Msg> {
        let (exec, mut io) = self.ports();
        exec.hand_off(&mut io, now, mode)
    }

    /// The hand-off's outcome: None while it runs (or none was issued), Some(true) when the
    /// autopilot accepted the mode, Some(false) when the step failed.
    pub fn handoff_status(&self) -> Option<bool> {
        self.exec.handoff_status()
    }

    /// Stop commanding motion (the pilot took over, or the flight is over): the running action
    /// and its commands in flight end now (recorded CANCELLED), nothing of them is resent, and
    /// any action may be asked for afresh later. Stream requests go on.
    pub fn stop_actions(&mut self, now: Duration, why: &str) {
        let (exec, mut io) = self.ports();
        exec.stop_actions(&mut io, now, why);
    }

    /// Modes this companion commanded (or made the autopilot enter, as a reposition enters
    /// GUIDED), with when; the newest last, a few kept. The operator gate tells its own mode
    /// changes from a pilot's with them.
    pub fn commanded_modes(&self) -> &[(FlightMode, Duration)] {
        self.exec.commanded_modes()
    }

    /// A launch command still waits for its answer.
    pub fn launch_awaiting(&self) -> bool {
        self.launches.awaiting()
    }

    /// The stop's conservative reading at `now`: what the companion launched and what any
    /// frame said, unless every autopilot frame has agreed for `landed_confirm` since that the
    /// vehicle is disarmed on the ground.
    pub fn stop_reading(&self, now: Duration, landed_confirm: Duration) -> StopReading {
        self.launches
            .reading(now, landed_confirm, self.down_since, self.readiness.armed)
    }

    /// The companion stops: the running action, its queued steps and every command in flight
    /// end now (recorded CANCELLED), except a launch command still waiting for its answer,
    /// which is kept (never resent) so that the stop can hear whether the vehicle armed or took
    /// off ([`Vehicle::launch_awaiting`]).
    pub fn stop_commanding(&mut self, now: Duration, why: &str) {
        let awaiting = self.launches.awaiting_commands();
        let (exec, mut io) = self.ports();
        exec.stop_keeping(&mut io, now, why, awaiting);
    }

    /// Watch the autopilot's own mission (`fly --mission autopilot`): download it once the
    /// autopilot is chosen and whenever it may have changed; [`Vehicle::take_autopilot_mission`]
    /// hands it over. The route's upload step then uploads nothing: the autopilot's mission is
    /// the one flown.
    pub fn watch_autopilot_mission(&mut self) {
        self.watch.enable();
    }

    /// Stop watching (a restarted companion downloaded the mission once to compare it with its
    /// own route, and flies that route): no more downloads, the route's upload step uploads.
    pub fn unwatch_autopilot_mission(&mut self) {
        self.watch = MissionWatch::default();
    }

    /// Whether the autopilot's own mission is the one flown (and watched).
    pub fn flies_autopilot_mission(&self) -> bool {
        self.watch.flies()
    }

    /// The autopilot's mission as last downloaded, if any.
    pub fn autopilot_mission(&self) -> Option<&[MissionItem]> {
        self.watch.known()
    }

    /// The mission loaded or changed since the last call.
    pub fn take_autopilot_mission(&mut self) -> Option<AutopilotMission> {
        self.watch.take_pending()
    }

    /// When the autopilot was chosen without a pin (`--autopilot-sysid`): which one, that it was
    /// the first heard, and how to pin it. `fly` says it on stderr and to the ground station on
    /// a network link, where anyone who can reach the port can speak first.
    pub fn identity_note(&self) -> Option<String> {
        Identity::note(&self.cfg, self.target)
    }

    /// Monitor frames refused since start: from components not allowed, or tracker reports on
    /// the autopilot link when they are taken only from the `--onboard` link.
    pub fn foreign_monitor_frames(&self) -> u64 {
        self.identity.foreign_monitor_frames
    }

    /// HEARTBEATs from other autopilots, ignored, since start.
    pub fn other_autopilot_heartbeats(&self) -> u64 {
        self.identity.other_autopilot_heartbeats
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
