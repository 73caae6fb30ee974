//! The whole link protocol for one autopilot, sans IO: identity, streams, liveness, readiness,
//! telemetry, commands, missions, and the executor that turns primitive vehicle actions into
//! protocol steps. `fly` feeds it frames and clock ticks and sends what it returns.

use super::Msg;
use super::actions::{ActionTable, Offset, Route, Step};
use super::command::{
    CommandClient, CommandConfig, CommandEvent, CommandSpec, FailReason, Outcome,
};
use super::dialect::*;
use super::ingest::Frame;
use super::liveness::{Liveness, LivenessEvent};
use super::mission::{MissionClient, MissionConfig, MissionEvent, MissionOp};
use super::modes::{self, Flavor};
use super::readiness::Readiness;
use super::telemetry::{PackParam, Telemetry, TelemetryConfig, displace};
use companion_core::observations::Observations;
use companion_core::record::{CommandOutcome, CommandRecord, Event, LinkEvent};
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
}

/// The pack parameters each autopilot family names, read with PARAM_REQUEST_READ: the capacity
/// (mAh) and, where there is one, the cell count. ArduPilot has no cell-count parameter.
pub fn pack_params(flavor: Flavor) -> &'static [(&'static str, PackParam)] {
    match flavor {
        Flavor::ArduPilot => &[("BATT_CAPACITY", PackParam::CapacityMah)],
        Flavor::Px4 => &[
            ("BAT1_CAPACITY", PackParam::CapacityMah),
            ("BAT1_N_CELLS", PackParam::Cells),
        ],
        Flavor::Other => &[],
    }
}

/// PARAM_REQUEST_READ of one pack parameter is sent at most this many times ...
pub const PACK_PARAM_ATTEMPTS: u32 = 5;
/// ... this far apart, until the autopilot answers (PARAM_VALUE is not acknowledged otherwise).
pub const PACK_PARAM_RETRY: Duration = Duration::from_secs(2);

/// One pack parameter asked for until the autopilot answers.
#[derive(Debug, Clone)]
struct PackRequest {
    name: &'static str,
    what: PackParam,
    sent: u32,
    next_at: Duration,
    answered: bool,
}

/// Distinct other autopilots reported by name; more are only counted.
const MAX_OTHER_AUTOPILOTS: usize = 16;

/// MAV_COMP_ID_AUTOPILOT1: the component an autopilot speaks from (ArduPilot and PX4 alike).
pub const AUTOPILOT_COMPONENT: u8 = 1;

/// Without a pin, an autopilot HEARTBEAT from a component other than 1 is chosen only after it
/// has been heard this long with no component-1 autopilot speaking: a real autopilot is
/// preferred over an impostor on another component of the same system that spoke first.
pub const OTHER_COMPONENT_WAIT: Duration = Duration::from_secs(2);

/// What an autopilot HEARTBEAT does to the choice of the autopilot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Choice {
    /// It is the autopilot: choose it now.
    Take,
    /// Not component 1 and no pin: chosen only if it is still the only one after
    /// [`OTHER_COMPONENT_WAIT`].
    Wait,
    /// Another autopilot: reported, never obeyed.
    Other,
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

/// What a command ticket is for.
#[derive(Debug, Clone)]
enum Purpose {
    Stream(u32),
    Step {
        action: String,
        name: String,
        latency_ms: Option<f64>,
    },
}

/// After a job step: run the next (or the same) step now, or wait for a message or tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Advance {
    Again,
    Wait,
}

#[derive(Debug, Clone, PartialEq)]
enum Running {
    /// Nothing issued for the current step yet.
    Idle,
    Command(u64),
    Mission,
    WaitReady {
        since: Duration,
    },
    /// The zone reposition was accepted: flying there (lat, lon in degrees * 1e7).
    Arrive {
        target: (i32, i32),
        since: Duration,
    },
    /// PX4 accepted SET_MODE at `since`: waiting for a HEARTBEAT that shows the mode.
    ConfirmMode {
        since: Duration,
    },
}

#[derive(Debug, Clone)]
struct Job {
    key: String,
    steps: VecDeque<(String, Step)>,
    running: Running,
    arm_attempts: u32,
    /// SET_MODE sent for the current mode step (PX4 confirmation resends).
    mode_attempts: u32,
    /// The custom mode reported when the current step's SET_MODE was first issued.
    mode_from: Option<u32>,
}

#[derive(Debug, Clone, PartialEq)]
enum JobStatus {
    Running,
    Done,
    Failed(Duration),
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
    last: Option<(String, JobStatus)>,
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
    pub commanded_modes: Vec<(String, Duration)>,
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
    handoff: Option<String>,
    /// Where the running zone reposition goes.
    zone_target: Option<(i32, i32)>,
    /// When the autopilot last reported its mode (its heartbeat).
    mode_heard_at: Option<Duration>,
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
            px4_mission_pending: None,
            px4_takeoff_wait: None,
            pack_requests: Vec::new(),
        }
    }

    /// Ask (again) for the pack parameters of the chosen autopilot's family.
    fn reset_pack_requests(&mut self) {
        self.pack_requests = pack_params(self.flavor)
            .iter()
            .map(|&(name, what)| PackRequest {
                name,
                what,
                sent: 0,
                next_at: Duration::ZERO,
                answered: false,
            })
            .collect();
    }

    /// PARAM_REQUEST_READ of the pack parameters not answered yet, each retried a few times.
    fn request_pack_params(&mut self, now: Duration, out: &mut Vec<Msg>) {
        let Some((sys, comp)) = self.target else {
            return;
        };
        for r in &mut self.pack_requests {
            if r.answered || r.sent >= PACK_PARAM_ATTEMPTS || now < r.next_at {
                continue;
            }
            r.sent += 1;
            r.next_at = now + PACK_PARAM_RETRY;
            out.push(Msg::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: sys,
                target_component: comp,
                param_id: r.name.into(),
            }));
        }
    }

    /// A PARAM_VALUE from the autopilot: a pack parameter asked for goes to the telemetry.
    fn on_param_value(&mut self, p: &PARAM_VALUE_DATA) {
        let id = p.param_id.to_str().unwrap_or("").trim_end_matches('\0');
        let Some(r) = self.pack_requests.iter_mut().find(|r| r.name == id) else {
            return;
        };
        // PX4 sends integer parameters bytewise in the float (MAV_PROTOCOL_CAPABILITY_PARAM_
        // ENCODE_BYTEWISE); ArduPilot casts them to float.
        let int = matches!(
            p.param_type,
            MavParamType::MAV_PARAM_TYPE_INT32
                | MavParamType::MAV_PARAM_TYPE_UINT32
                | MavParamType::MAV_PARAM_TYPE_INT16
                | MavParamType::MAV_PARAM_TYPE_UINT16
                | MavParamType::MAV_PARAM_TYPE_INT8
                | MavParamType::MAV_PARAM_TYPE_UINT8
        );
        let value = if int && self.flavor == Flavor::Px4 {
            p.param_value.to_bits() as i32 as f64
        } else {
            p.param_value as f64
        };
        r.answered = true;
        let (name, what) = (r.name, r.what);
        self.telemetry.on_pack_param(what, value);
        if what == PackParam::CapacityMah && value <= 0.0 {
            self.link_event(
                LinkEvent::from(
                    format!(
                        "autopilot {name} = {value}: the pack's capacity is not set, the guarantee uses params [battery]"
                    )
                    .as_str(),
                ),
                false,
            );
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
            self.link_events.push(LinkEvent::from(note));
        }
        std::mem::take(&mut self.link_events)
    }

    /// One link event when frames or values were refused for trust since the last report.
    fn trust_note(&mut self) -> Option<String> {
        let r = &self.telemetry.rejected;
        let now = (
            self.foreign_monitor_frames,
            r.out_of_range,
            r.names_dropped,
            self.other_autopilot_heartbeats,
        );
        if now == self.trust_reported {
            return None;
        }
        self.trust_reported = now;
        let last = r
            .last
            .as_deref()
            .map(|l| format!(" (last: {l})"))
            .unwrap_or_default();
        Some(format!(
            "trust: {} monitor frames from components not allowed, {} values out of range{last}, {} onboard names dropped (over the cap of {} or not printable), {} heartbeats from other autopilots refused (since start)",
            now.0, now.1, now.2, self.cfg.telemetry.max_onboard_names, now.3
        ))
    }

    /// A HEARTBEAT that can choose the autopilot: from a flight controller (an autopilot type,
    /// not INVALID) of a vehicle (not a GCS, companion, gimbal, camera or other peripheral).
    /// `--autopilot-sysid` narrows the choice further in `on_frame`.
    fn is_autopilot_heartbeat(h: &HEARTBEAT_DATA) -> bool {
        h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID && is_vehicle_type(h.mavtype)
    }

    /// An autopilot other than the chosen one (or than the one `--autopilot-sysid` asks for)
    /// speaks: reported once per identity, never obeyed.
    fn other_autopilot(&mut self, sys: u8, comp: u8) {
        self.other_autopilot_heartbeats += 1;
        if self.other_autopilots.len() >= MAX_OTHER_AUTOPILOTS
            || !self.other_autopilots.insert((sys, comp))
        {
            return;
        }
        let why = match (self.target, self.cfg.autopilot_sysid) {
            (Some((ts, tc)), _) => format!("autopilot {ts}/{tc} already chosen"),
            (None, Some(want)) => format!(
                "--autopilot-sysid {want} --autopilot-compid {}",
                self.cfg.autopilot_compid
            ),
            (None, None) => match self.candidate {
                Some(((cs, cc), _)) => format!("autopilot {cs}/{cc} heard first"),
                None => "not chosen".to_string(),
            },
        };
        tracing::warn!(
            sys,
            comp,
            "another autopilot {sys}/{comp} heard and ignored ({why})"
        );
        self.link_event(
            LinkEvent::OtherAutopilot {
                system: sys,
                component: comp,
                why: why.to_string(),
            },
            false,
        );
    }

    /// Whether the autopilot HEARTBEAT of `sys`/`comp` (not the chosen one) chooses it: with a
    /// pin only that system and component; without one, component 1 at once and another
    /// component only after [`OTHER_COMPONENT_WAIT`] with no component 1 heard.
    fn choice(&mut self, now: Duration, sys: u8, comp: u8) -> Choice {
        if self.target.is_some() {
            return Choice::Other;
        }
        if let Some(want) = self.cfg.autopilot_sysid {
            return if (sys, comp) == (want, self.cfg.autopilot_compid) {
                Choice::Take
            } else {
                Choice::Other
            };
        }
        if comp == AUTOPILOT_COMPONENT {
            return Choice::Take;
        }
        match self.candidate {
            None => {
                self.candidate = Some(((sys, comp), now));
                Choice::Wait
            }
            Some((id, since)) if id == (sys, comp) => {
                if now.saturating_sub(since) >= OTHER_COMPONENT_WAIT {
                    Choice::Take
                } else {
                    Choice::Wait
                }
            }
            Some(_) => Choice::Other,
        }
    }

    /// When the autopilot was chosen without a pin (`--autopilot-sysid`): which one, that it was
    /// the first heard, and how to pin it. `fly` says it on stderr and to the ground station on
    /// a network link, where anyone who can reach the port can speak first.
    pub fn identity_note(&self) -> Option<String> {
        if self.cfg.autopilot_sysid.is_some() {
            return None;
        }
        let (sys, comp) = self.target?;
        let compid = if comp == AUTOPILOT_COMPONENT {
            String::new()
        } else {
            format!(" --autopilot-compid {comp}")
        };
        Some(format!(
            "autopilot {sys}/{comp} chosen: the first autopilot heard (no pin); pin it with --autopilot-sysid {sys}{compid}"
        ))
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
            && Self::is_autopilot_heartbeat(h)
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
                tracing::info!(sys, comp, flavor = ?self.flavor, "autopilot chosen");
                self.link_event(
                    LinkEvent::Autopilot {
                        system: sys,
                        component: comp,
                        flavor: format!("{:?}", self.flavor),
                    },
                    false,
                );
                if let Some(note) = self.identity_note() {
                    self.link_event(LinkEvent::from(note.as_str()), false);
                }
            } else if choice == Choice::Other {
                self.other_autopilot(sys, comp);
            }
        }
        let from_autopilot = self.target == Some((sys, comp));
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
        let ev = self
            .telemetry
            .on_message(now, &f.msg, |m| modes::mode_name(flavor, m));
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
            }
            Msg::EKF_STATUS_REPORT(e) => self.readiness.on_ekf(now, e),
            Msg::ESTIMATOR_STATUS(e) => self.readiness.on_estimator(now, e),
            Msg::MISSION_CURRENT(m) => {
                if matches!(self.px4_mission_pending, Some((n, _)) if n == m.total) {
                    self.px4_mission_pending = None;
                }
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
            let ev = self
                .telemetry
                .on_message(now, &f.msg, |m| modes::mode_name(flavor, m));
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
                    "link lost: no message from the autopilot for {:?}",
                    self.cfg.link_timeout
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
        out.extend(self.advance_job(now));
        out
    }

    /// The decision core asked for these vehicle actions.
    /// The same action already running or done is not restarted; a different one replaces it.
    pub fn request_actions(&mut self, now: Duration, actions: &[String]) -> Vec<Msg> {
        if actions.is_empty() {
            return Vec::new();
        }
        let key = actions.join("+");
        if let Some(job) = &self.job
            && job.key == key
        {
            return Vec::new();
        }
        if let Some((k, status)) = &self.last
            && *k == key
        {
            match status {
                JobStatus::Done | JobStatus::Running => return Vec::new(),
                JobStatus::Failed(at) if now < *at + self.retry_failed_after => return Vec::new(),
                JobStatus::Failed(_) => {}
            }
        }
        if !self.liveness.alive() || self.target.is_none() {
            for a in actions {
                self.records.push(CommandRecord {
                    action: a.clone(),
                    command: "-".into(),
                    result: CommandOutcome::NotSent("no link".into()),
                    attempts: 0,
                    latency_ms: None,
                });
            }
            return Vec::new();
        }
        let mut steps = VecDeque::new();
        let mut unmapped = false;
        for a in actions {
            match self.actions.actions.get(a) {
                Some(s) => steps.extend(s.iter().cloned().map(|st| (a.clone(), st))),
                None => {
                    unmapped = true;
                    self.records.push(CommandRecord {
                        action: a.clone(),
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

    fn job_failed(&mut self, now: Duration) {
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

    fn step_done(&mut self) {
        if let Some(job) = &mut self.job {
            job.steps.pop_front();
            job.running = Running::Idle;
            job.arm_attempts = 0;
            job.mode_attempts = 0;
            job.mode_from = None;
        }
    }

    /// Run steps until one has to wait.
    fn advance_job(&mut self, now: Duration) -> Vec<Msg> {
        let mut out = Vec::new();
        loop {
            let Some(job) = &mut self.job else { return out };
            let Some((action, step)) = job.steps.front().cloned() else {
                let key = job.key.clone();
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
                (Running::ConfirmMode { since }, Step::Mode(name)) => {
                    let (from, since) = (job.mode_from, *since);
                    self.confirm_mode_step(now, action, name, from, since)
                }
                (Running::ConfirmMode { .. }, _) => {
                    job.running = Running::Idle;
                    Advance::Again
                }
                (Running::Idle, Step::Mode(name)) => self.mode_step(now, action, name, &mut out),
                (Running::Idle | Running::WaitReady { .. }, Step::Arm) => {
                    self.arm_step(now, action, &mut out)
                }
                (Running::Idle, Step::Command { command, params }) => {
                    self.command_step(now, action, *command, *params, &mut out)
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
    fn issued(
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

    /// Record a step that did not need a command (`ALREADY`, `SKIPPED ...`).
    /// A step settled without a command on the wire; `result` in the log's spelling.
    fn record_step(&mut self, action: String, command: String, result: String) {
        self.records.push(CommandRecord {
            action,
            command,
            result: CommandOutcome::from(result.as_str()),
            attempts: 0,
            latency_ms: None,
        });
    }

    /// The zone reposition was accepted: done when within the zone radius, or after the
    /// timeout (landing where the vehicle is).
    fn arrive_step(
        &mut self,
        now: Duration,
        action: String,
        target: (i32, i32),
        since: Duration,
    ) -> Advance {
        let off = self.telemetry.position.map(|p| {
            let (n, e) = super::telemetry::offset_m(target, (p.lat_e7, p.lon_e7));
            n.hypot(e)
        });
        let result = match off {
            Some(d) if d <= self.cfg.zone_radius_m => format!("ARRIVED ({d:.1} m from the zone)"),
            _ if now.saturating_sub(since) >= self.cfg.zone_arrive_timeout => format!(
                "TIMEOUT (not within {:.1} m of the zone after {:.0} s{}; landing here)",
                self.cfg.zone_radius_m,
                self.cfg.zone_arrive_timeout.as_secs_f64(),
                off.map(|d| format!(", {d:.1} m away")).unwrap_or_default()
            ),
            _ => return Advance::Wait,
        };
        self.record_step(action, "ARRIVE (zone)".into(), result);
        self.zone_target = None;
        self.step_done();
        Advance::Again
    }

    fn mode_step(
        &mut self,
        now: Duration,
        action: String,
        name: &str,
        out: &mut Vec<Msg>,
    ) -> Advance {
        // Landing and return never wait.
        if self.flavor == Flavor::Px4
            && !matches!(name, "LAND" | "RTL" | "SMART_RTL" | "TAKEOFF")
            && self.telemetry.mode.as_deref() == Some("TAKEOFF")
        {
            let until = *self
                .px4_takeoff_wait
                .get_or_insert(now + Duration::from_secs(30));
            if now < until {
                return Advance::Wait; // the heartbeat that shows Hold moves on
            }
        }
        self.px4_takeoff_wait = None;
        if name == "AUTO"
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
            .is_some_and(|(m, _)| m != name);
        self.note_mode(now, name);
        if modes::is_in_mode(self.flavor, self.telemetry.custom_mode, name)
            && self.telemetry.mode.is_some()
            && !stale
        {
            self.record_step(action, format!("SET_MODE {name}"), "ALREADY".into());
            self.step_done();
            return Advance::Again;
        }
        match modes::set_mode_command(self.flavor, name) {
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
                self.issued(now, &action, format!("SET_MODE {name}"), spec, out)
            }
            None => {
                let result = format!("FAILED (no {name} mode for {:?})", self.flavor);
                self.record_step(action, format!("SET_MODE {name}"), result);
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
    fn confirm_mode_step(
        &mut self,
        now: Duration,
        action: String,
        name: &str,
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
        let shown = self.telemetry.mode.clone().unwrap_or_else(|| "?".into());
        let unchanged = heard_since && from == Some(self.telemetry.custom_mode);
        let attempts = self.job.as_ref().map_or(0, |j| j.mode_attempts);
        let waited = self.cfg.mode_confirm.as_secs_f64();
        if unchanged && attempts < self.cfg.max_mode_attempts {
            self.record_step(
                action,
                format!("SET_MODE {name}"),
                format!(
                    "NOT_CONFIRMED (still {shown} {waited:.0} s after ACCEPTED; sending again)"
                ),
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
            format!("FAILED ({why})"),
        );
        self.job_failed(now);
        Advance::Again
    }

    fn arm_step(&mut self, now: Duration, action: String, out: &mut Vec<Msg>) -> Advance {
        if self.telemetry.armed {
            self.record_step(action, "ARM".into(), "ALREADY".into());
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
                    && let Some((want, at)) = self.commanded_modes.last().cloned()
                    && !modes::is_in_mode(self.flavor, self.telemetry.custom_mode, &want)
                {
                    if self.mode_heard_at.is_none_or(|h| h <= at) {
                        return Advance::Wait;
                    }
                    let now_mode = self.telemetry.mode.clone().unwrap_or_else(|| "?".into());
                    self.record_step(
                        action,
                        "ARM".into(),
                        format!(
                            "FAILED (vehicle in {now_mode}, not {want} as commanded: not arming)"
                        ),
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
                            format!("WAITING_READY ({})", why.join("; ")),
                        );
                        now
                    }
                };
                if now.saturating_sub(since) >= self.cfg.arm_wait {
                    self.record_step(
                        action,
                        "ARM".into(),
                        format!("NOT_READY ({})", why.join("; ")),
                    );
                    self.job_failed(now);
                }
                Advance::Wait
            }
        }
    }

    fn command_step(
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
                format!("{command:?}"),
                "FAILED (no home position yet)".into(),
            );
            self.job_failed(now);
            return Advance::Again;
        };
        if command == MavCmd::MAV_CMD_NAV_TAKEOFF && self.flavor == Flavor::Px4 {
            // PX4 flies a take-off command in its TAKEOFF mode.
            self.note_mode(now, "TAKEOFF");
        }
        let spec = CommandSpec::long(command, params);
        self.issued(now, &action, format!("{command:?}"), spec, out)
    }

    fn upload_mission_step(
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
            self.record_step(action, "MISSION_UPLOAD".into(), format!("FAILED ({why})"));
            self.job_failed(now);
            return Advance::Again;
        };
        let items = modes::mission_items(self.flavor, route, home);
        match self.mission.upload(now, items) {
            Ok(msgs) => {
                out.extend(msgs);
                let job = self.job.as_mut().expect("job checked above");
                job.running = Running::Mission;
                self.records.push(CommandRecord {
                    action,
                    command: "MISSION_UPLOAD".into(),
                    result: CommandOutcome::Sent,
                    attempts: 1,
                    latency_ms: None,
                });
                Advance::Wait
            }
            Err(_) => Advance::Wait, // another transfer still running: wait for it
        }
    }

    fn reposition_step(
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
                    "FAILED (no position/heading yet)".into(),
                );
                self.job_failed(now);
                Advance::Again
            }
        }
    }

    fn goto_zone_step(&mut self, now: Duration, action: String, out: &mut Vec<Msg>) -> Advance {
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
                    "SKIPPED (no zone reported; landing here)".into(),
                );
                self.step_done();
                Advance::Again
            }
        }
    }

    /// Submit a step's command; false when it has to wait (in flight or sent).
    fn issue(
        &mut self,
        now: Duration,
        action: &str,
        name: String,
        spec: CommandSpec,
        out: &mut Vec<Msg>,
    ) -> bool {
        match self.commands.submit(now, spec) {
            Ok((ticket, msgs)) => {
                out.extend(msgs);
                let job = self.job.as_mut().expect("issue runs inside a job");
                job.running = Running::Command(ticket);
                self.records.push(CommandRecord {
                    action: action.to_string(),
                    command: name.clone(),
                    result: CommandOutcome::Sent,
                    attempts: 1,
                    latency_ms: None,
                });
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

    fn reposition_spec(&self, o: Offset) -> Option<CommandSpec> {
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

    fn on_command_events(&mut self, now: Duration, evs: Vec<CommandEvent>) -> Vec<Msg> {
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

    fn on_mission_events(&mut self, now: Duration, evs: Vec<MissionEvent>) -> Vec<Msg> {
        for ev in evs {
            let action = self
                .job
                .as_ref()
                .and_then(|j| j.steps.front().map(|s| s.0.clone()))
                .unwrap_or_default();
            let in_job = matches!(&self.job, Some(j) if j.running == Running::Mission);
            match ev {
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
                        command: format!("{op:?}"),
                        result: CommandOutcome::Failed(Some(format!("{error:?}"))),
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
    pub fn settled(&self, action: &str) -> bool {
        matches!(&self.job, Some(j) if j.key == action)
            || matches!(&self.last, Some((k, JobStatus::Done | JobStatus::Running)) if k == action)
    }

    fn note_mode(&mut self, now: Duration, name: &str) {
        self.commanded_modes.push((name.to_string(), now));
        if self.commanded_modes.len() > 8 {
            self.commanded_modes.remove(0);
        }
    }

    /// MAV_CMD_DO_REPOSITION with the change-mode flag: ArduPilot enters GUIDED, PX4 holds in
    /// LOITER (our GUIDED on PX4).
    fn note_reposition(&mut self, now: Duration) {
        self.note_mode(now, "GUIDED");
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

    /// When the last action failed (its key and the time), if it did and nothing ran since.
    pub fn failed_action(&self) -> Option<(&str, Duration)> {
        match &self.last {
            Some((k, JobStatus::Failed(at))) => Some((k.as_str(), *at)),
            _ => None,
        }
    }

    /// The companion stops: whatever it was doing ends now (recorded CANCELLED) and the vehicle
    /// is put in `mode` (`LOITER`, `RTL`, `LAND`) for the autopilot to fly on its own. The
    /// step is acknowledged (or fails) like any other; [`Vehicle::handoff_status`] tells.
    pub fn hand_off(&mut self, now: Duration, mode: &str) -> Vec<Msg> {
        self.stop_actions(now, "companion stopping");
        let key = format!("handoff:{mode}");
        self.job = Some(Job {
            key: key.clone(),
            steps: VecDeque::from([(key.clone(), Step::Mode(mode.to_string()))]),
            running: Running::Idle,
            arm_attempts: 0,
            mode_attempts: 0,
            mode_from: None,
        });
        self.last = Some((key, JobStatus::Running));
        self.handoff = Some(mode.to_string());
        self.advance_job(now)
    }

    /// The hand-off's outcome: None while it runs (or none was issued), Some(true) when the
    /// autopilot accepted the mode, Some(false) when the step failed.
    pub fn handoff_status(&self) -> Option<bool> {
        let mode = self.handoff.as_deref()?;
        match &self.last {
            Some((k, JobStatus::Done)) if k.strip_prefix("handoff:") == Some(mode) => Some(true),
            Some((k, JobStatus::Failed(_))) if k.strip_prefix("handoff:") == Some(mode) => {
                Some(false)
            }
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

/// A vehicle's MAV_TYPE, not a ground station, companion computer or peripheral.
fn is_vehicle_type(t: MavType) -> bool {
    !matches!(
        t,
        MavType::MAV_TYPE_GCS
            | MavType::MAV_TYPE_ONBOARD_CONTROLLER
            | MavType::MAV_TYPE_GIMBAL
            | MavType::MAV_TYPE_CAMERA
            | MavType::MAV_TYPE_ADSB
            | MavType::MAV_TYPE_ANTENNA_TRACKER
            | MavType::MAV_TYPE_CHARGING_STATION
            | MavType::MAV_TYPE_FLARM
            | MavType::MAV_TYPE_SERVO
            | MavType::MAV_TYPE_ODID
            | MavType::MAV_TYPE_BATTERY
            | MavType::MAV_TYPE_PARACHUTE
            | MavType::MAV_TYPE_LOG
            | MavType::MAV_TYPE_OSD
            | MavType::MAV_TYPE_IMU
            | MavType::MAV_TYPE_GPS
            | MavType::MAV_TYPE_WINCH
            | MavType::MAV_TYPE_GRIPPER
            | MavType::MAV_TYPE_ILLUMINATOR
            | MavType::MAV_TYPE_RADIO
    )
}

fn step_name(s: &Step) -> String {
    match s {
        Step::Mode(m) => format!("SET_MODE {m}"),
        Step::Arm => "ARM".into(),
        Step::Command { command, .. } => format!("{command:?}"),
        Step::UploadMission => "MISSION_UPLOAD".into(),
        Step::Reposition(_) => "MAV_CMD_DO_REPOSITION".into(),
        Step::GotoZone => "MAV_CMD_DO_REPOSITION (zone)".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::{MavHeader, MavlinkVersion};

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    fn frame(msg: Msg) -> Frame {
        Frame {
            header: MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: 0,
            },
            msg,
            signed: false,
            version: MavlinkVersion::V2,
            raw: Vec::new(),
        }
    }

    fn hb(mode: u32, armed: bool) -> Frame {
        frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: mode,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            } else {
                MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            },
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        }))
    }

    fn ready_frames() -> Vec<Frame> {
        let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        vec![
            frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
                onboard_control_sensors_present: bit,
                onboard_control_sensors_enabled: bit,
                onboard_control_sensors_health: bit,
                ..SYS_STATUS_DATA::DEFAULT
            })),
            frame(Msg::EKF_STATUS_REPORT(EKF_STATUS_REPORT_DATA {
                flags: EkfStatusFlags::EKF_ATTITUDE
                    | EkfStatusFlags::EKF_VELOCITY_HORIZ
                    | EkfStatusFlags::EKF_POS_HORIZ_ABS
                    | EkfStatusFlags::EKF_POS_VERT_ABS,
                ..EKF_STATUS_REPORT_DATA::DEFAULT
            })),
        ]
    }

    fn not_ready() -> Frame {
        let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
            onboard_control_sensors_present: bit,
            onboard_control_sensors_enabled: bit,
            ..SYS_STATUS_DATA::DEFAULT
        }))
    }

    fn ack(command: MavCmd, result: MavResult) -> Frame {
        frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
            command,
            result,
            ..COMMAND_ACK_DATA::DEFAULT
        }))
    }

    fn table() -> ActionTable {
        let mut t = ActionTable::default();
        t.actions.insert(
            "take_off".into(),
            vec![
                Step::Mode("GUIDED".into()),
                Step::Arm,
                Step::Command {
                    command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                    params: [0., 0., 0., 0., 0., 0., 10.],
                },
            ],
        );
        t.actions
            .insert("return_to_base".into(), vec![Step::Mode("RTL".into())]);
        t
    }

    fn vehicle() -> Vehicle {
        let cfg = VehicleConfig {
            streams: vec![(168, 1.0)],
            ..VehicleConfig::default()
        };
        Vehicle::new(cfg, table(), None)
    }

    fn commands(out: &[Msg]) -> Vec<MavCmd> {
        out.iter()
            .filter_map(|m| {
                if let Msg::COMMAND_LONG(c) = m {
                    Some(c.command)
                } else {
                    None
                }
            })
            .collect()
    }

    /// Connect, let the stream request complete.
    fn connected(v: &mut Vehicle, mode: u32) {
        let out = v.on_frame(s(0.0), &hb(mode, false));
        assert_eq!(v.target, Some((1, 1)));
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL],
            "streams requested on connect"
        );
        v.on_frame(
            s(0.05),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert!(v.take_events().contains(&Event::Link(LinkEvent::Connected)));
    }

    #[test]
    fn arms_only_once_the_vehicle_reports_the_mode_it_was_set_to() {
        // ArduCopter SITL: GUIDED accepted, then STABILIZE from its RC mode switch.
        let mut v = vehicle();
        connected(&mut v, 0);
        for f in ready_frames() {
            v.on_frame(s(0.1), &f);
        }
        let out = v.request_actions(s(0.2), &["take_off".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        // The ack comes before any heartbeat shows the new mode: no ARM yet.
        let out = v.on_frame(
            s(0.3),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert!(commands(&out).is_empty(), "armed before the mode was seen");
        // The next heartbeat says STABILIZE (0): not armed, the take-off fails and says why.
        let mut out = v.on_frame(s(1.0), &hb(0, false));
        out.extend(v.tick(s(1.1)));
        assert!(
            !commands(&out).contains(&MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
            "armed in STABILIZE"
        );
        assert!(v.take_records().iter().any(|r| {
            r.command == "ARM"
                && matches!(&r.result, CommandOutcome::Failed(Some(why))
                    if why.starts_with("vehicle in STABILIZE, not GUIDED"))
        }));
        // Asked again after the retry delay: GUIDED is set again, and with GUIDED reported it arms.
        let out = v.request_actions(s(7.0), &["take_off".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        v.on_frame(
            s(7.1),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        let out = v.on_frame(s(7.5), &hb(4, false));
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
    }

    /// An action that commands nothing (stay_on_ground) supersedes a take-off being flown, and a
    /// take-off asked for again afterwards starts afresh (it used to stay "running" and never
    /// resumed: seen on ArduCopter SITL).
    #[test]
    fn take_off_after_staying_on_the_ground_starts_again() {
        let mut t = table();
        t.actions.insert("stay_on_ground".into(), Vec::new());
        let mut v = Vehicle::new(
            VehicleConfig {
                streams: vec![(168, 1.0)],
                ..VehicleConfig::default()
            },
            t,
            None,
        );
        connected(&mut v, 0);
        for f in ready_frames() {
            v.on_frame(s(0.1), &f);
        }
        let out = v.request_actions(s(0.2), &["take_off".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        v.on_frame(
            s(0.25),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        let out = v.request_actions(s(0.3), &["stay_on_ground".into()]);
        assert!(out.is_empty(), "staying commands nothing");
        assert!(
            v.take_records()
                .iter()
                .any(|r| r.action == "take_off" && r.result == CommandOutcome::Superseded)
        );
        // GUIDED reported: no arming while staying.
        let out = v.on_frame(s(0.5), &hb(4, false));
        assert!(
            commands(&out).is_empty(),
            "armed while staying on the ground"
        );
        let mut out = v.request_actions(s(1.3), &["take_off".into()]);
        out.extend(v.on_frame(s(1.4), &hb(4, false)));
        out.extend(v.tick(s(1.5)));
        let sent = commands(&out);
        assert!(
            sent.contains(&MavCmd::MAV_CMD_DO_SET_MODE)
                || sent.contains(&MavCmd::MAV_CMD_COMPONENT_ARM_DISARM),
            "take-off again: {sent:?}"
        );
    }

    #[test]
    fn take_off_waits_for_readiness_before_arming() {
        let mut v = vehicle();
        connected(&mut v, 0);
        v.on_frame(s(0.1), &not_ready());
        let out = v.request_actions(s(0.2), &["take_off".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        v.stamp_latency(s(0.15), s(0.2));
        let recs = v.take_records();
        assert_eq!(recs[0].latency_ms, Some(50.0));
        let out = v.on_frame(
            s(0.3),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert!(
            commands(&out).is_empty(),
            "must not arm a vehicle that reports not ready"
        );
        assert!(
            v.take_records()
                .iter()
                .any(|r| matches!(r.result, CommandOutcome::WaitingReady(_)))
        );
        v.on_frame(s(3.0), &hb(4, false));
        assert!(commands(&v.tick(s(5.0))).is_empty());
        let mut out = Vec::new();
        for f in ready_frames() {
            out.extend(v.on_frame(s(6.0), &f));
        }
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
        let out = v.on_frame(
            s(6.1),
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
        v.on_frame(
            s(6.2),
            &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert!(!v.busy());
        // Asking again for the finished action does nothing.
        assert!(v.request_actions(s(7.0), &["take_off".into()]).is_empty());
    }

    #[test]
    fn failed_arm_is_retried_only_after_a_fresh_ready_report() {
        let mut v = vehicle();
        connected(&mut v, 4);
        for f in ready_frames() {
            v.on_frame(s(0.1), &f);
        }
        let out = v.request_actions(s(0.2), &["take_off".into()]);
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM],
            "already GUIDED: straight to arm"
        );
        // ArduPilot refuses: prearm failed.
        let out = v.on_frame(
            s(0.3),
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_FAILED,
            ),
        );
        assert!(commands(&out).is_empty());
        assert!(commands(&v.tick(s(2.0))).is_empty(), "no blind retry");
        assert!(commands(&v.on_frame(s(2.5), &not_ready())).is_empty());
        let out = v.on_frame(s(3.0), &ready_frames()[0]);
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM],
            "retried after the autopilot reported ready again"
        );
        let out = v.on_frame(
            s(3.1),
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_NAV_TAKEOFF]);
    }

    #[test]
    fn arm_gives_up_when_never_ready() {
        let mut v = vehicle();
        connected(&mut v, 4);
        v.on_frame(s(0.1), &not_ready());
        v.request_actions(s(0.2), &["take_off".into()]);
        for t in 1..=61 {
            v.on_frame(s(t as f64), &hb(4, false));
            assert!(commands(&v.tick(s(t as f64 + 0.5))).is_empty());
        }
        assert!(!v.busy());
        assert!(
            v.take_records()
                .iter()
                .any(|r| matches!(r.result, CommandOutcome::NotReady(_)))
        );
    }

    #[test]
    fn link_loss_drops_commands_and_resume_does_not_replay() {
        let mut v = vehicle();
        connected(&mut v, 0);
        let out = v.request_actions(s(1.0), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        // Silence: the autopilot is gone.
        assert!(
            commands(&v.tick(s(2.5)))
                .iter()
                .all(|c| *c == MavCmd::MAV_CMD_DO_SET_MODE),
            "resend while alive is fine"
        );
        let out = v.tick(s(4.1));
        assert!(out.is_empty());
        assert!(!v.liveness.alive());
        assert!(v.take_events().contains(&Event::Link(LinkEvent::Lost)));
        assert!(
            v.take_records()
                .iter()
                .any(|r| matches!(r.result, CommandOutcome::Cancelled(_)))
        );
        assert_eq!(v.commands.pending_count(), 0);
        for t in [5.0, 10.0, 20.0] {
            assert!(v.tick(s(t)).is_empty(), "nothing sent while lost");
        }
        assert!(v.request_actions(s(20.0), &["take_off".into()]).is_empty());
        assert!(
            v.take_records()
                .iter()
                .any(|r| matches!(r.result, CommandOutcome::NotSent(_)))
        );
        // Autopilot back: only stream requests go out, never the old SET_MODE.
        let out = v.on_frame(s(21.0), &hb(0, false));
        assert!(v.take_events().contains(&Event::Link(LinkEvent::Regained)));
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL]);
        let out = v.on_frame(
            s(21.1),
            &ack(
                MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert!(commands(&out).is_empty());
        v.on_frame(s(23.0), &hb(0, false));
        assert!(commands(&v.tick(s(24.0))).is_empty());
        // A fresh decision may command again.
        let out = v.request_actions(s(25.0), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    }

    #[test]
    fn reboot_re_requests_streams_and_resets_readiness() {
        let mut v = vehicle();
        connected(&mut v, 0);
        for f in ready_frames() {
            v.on_frame(s(0.1), &f);
        }
        assert!(v.readiness.check().is_ok());
        // Past the minimum interval since the connect's stream requests.
        v.on_frame(
            s(5.5),
            &frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 0,
                time_boot_ms: 90_000,
            })),
        );
        let out = v.on_frame(
            s(6.0),
            &frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
                time_unix_usec: 0,
                time_boot_ms: 500,
            })),
        );
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL]);
        assert!(v.take_events().contains(&Event::Link(LinkEvent::Rebooted)));
        assert!(v.readiness.check().is_err());
    }

    fn system_time(ms: u32) -> Frame {
        frame(Msg::SYSTEM_TIME(SYSTEM_TIME_DATA {
            time_unix_usec: 0,
            time_boot_ms: ms,
        }))
    }

    /// Acknowledge every stream request in `out` and those the acks release; how many went out.
    fn ack_streams(v: &mut Vehicle, t: f64, out: &[Msg]) -> usize {
        let mut out = out.to_vec();
        let mut n = 0;
        while commands(&out).contains(&MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL) {
            n += 1;
            out = v.on_frame(
                s(t),
                &ack(
                    MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                    MavResult::MAV_RESULT_ACCEPTED,
                ),
            );
        }
        n
    }

    /// Message ids the vehicle asks for with SET_MESSAGE_INTERVAL after a HEARTBEAT of
    /// `autopilot`, with the shipped params/link.toml, every request acknowledged in turn.
    fn streams_requested(autopilot: MavAutopilot) -> Vec<u32> {
        let path = crate::test_support::default_params_dir().join("link.toml");
        let link = crate::test_support::disk(crate::actions::LinkParams::load)(&path).unwrap();
        let cfg = VehicleConfig {
            streams: link.stream_ids(),
            streams_not_sent: link.streams_not_sent(),
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, table(), None);
        let mut heartbeat = hb(0, false);
        if let Msg::HEARTBEAT(h) = &mut heartbeat.msg {
            h.autopilot = autopilot;
        }
        let mut out = v.on_frame(s(0.0), &heartbeat);
        let mut ids = Vec::new();
        for _ in 0..100 {
            let asked: Vec<u32> = out
                .iter()
                .filter_map(|m| match m {
                    Msg::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL => {
                        Some(c.param1 as u32)
                    }
                    _ => None,
                })
                .collect();
            if asked.is_empty() {
                break;
            }
            ids.extend(asked);
            out = v.on_frame(
                s(0.1),
                &ack(
                    MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                    MavResult::MAV_RESULT_ACCEPTED,
                ),
            );
        }
        ids
    }

    /// ArduPilot has no ESTIMATOR_STATUS (230), OBSTACLE_DISTANCE (330) or STATUSTEXT (253) in
    /// its ap_message map: asking makes it send `No ap_message for mavlink id (N)` to the ground
    /// station on every connect. PX4 has those streams and no EKF_STATUS_REPORT (193) or WIND
    /// (168).
    #[test]
    fn each_autopilot_is_asked_only_for_streams_it_has() {
        let ardupilot = streams_requested(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA);
        for id in [230, 330, 253] {
            assert!(
                !ardupilot.contains(&id),
                "ArduPilot asked for {id}: {ardupilot:?}"
            );
        }
        for id in [1, 33, 147, 193, 168, 241, 245, 42, 242, 2] {
            assert!(
                ardupilot.contains(&id),
                "ArduPilot not asked for {id}: {ardupilot:?}"
            );
        }
        let px4 = streams_requested(MavAutopilot::MAV_AUTOPILOT_PX4);
        for id in [230, 330, 253, 1, 33, 147, 241, 245, 242, 2] {
            assert!(px4.contains(&id), "PX4 not asked for {id}: {px4:?}");
        }
        for id in [193, 168] {
            assert!(!px4.contains(&id), "PX4 asked for {id}: {px4:?}");
        }
        // An autopilot of neither flavour is asked for everything listed.
        let other = streams_requested(MavAutopilot::MAV_AUTOPILOT_GENERIC);
        assert!(
            other.len() > px4.len() && other.len() > ardupilot.len(),
            "{other:?}"
        );
    }

    /// 35 spoofed "reboots" (the boot clock jumping back and forth) in 3.5 s cannot multiply the
    /// stream requests: at most one set per minimum interval, and the last one still goes out.
    #[test]
    fn spoofed_system_time_cannot_multiply_stream_requests() {
        let cfg = VehicleConfig {
            streams: vec![(1, 2.0), (33, 5.0), (168, 1.0)],
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, table(), None);
        let mut sent = 0;
        let out = v.on_frame(s(0.0), &hb(0, false));
        sent += ack_streams(&mut v, 0.0, &out);
        for i in 0..35u32 {
            let t = 0.1 + i as f64 * 0.1;
            let ms = if i % 2 == 0 { 500_000 } else { 1_000 };
            let out = v.on_frame(s(t), &system_time(ms));
            sent += ack_streams(&mut v, t, &out);
            let out = v.tick(s(t + 0.05));
            sent += ack_streams(&mut v, t + 0.05, &out);
        }
        assert_eq!(sent, 3, "only the connect's set within the first 5 s");
        for k in 0..40 {
            let t = 4.0 + k as f64 * 0.1;
            if k % 10 == 0 {
                v.on_frame(s(t), &hb(0, false));
            }
            let out = v.tick(s(t));
            sent += ack_streams(&mut v, t, &out);
        }
        assert_eq!(sent, 6, "one deferred set once the interval passed, not 35");
    }

    /// A TCP link that keeps reconnecting without the autopilot saying anything is lost: a
    /// reconnect is not a message from the autopilot.
    #[test]
    fn reconnects_alone_do_not_keep_the_link_alive() {
        let mut v = vehicle();
        connected(&mut v, 0);
        for k in 1..=10 {
            let t = k as f64 * 0.5;
            v.on_reconnect(s(t));
            v.tick(s(t));
        }
        assert!(!v.liveness.alive());
        assert!(v.take_events().contains(&Event::Link(LinkEvent::Lost)));
    }

    fn from(sys: u8, comp: u8, mut f: Frame) -> Frame {
        f.header.system_id = sys as u32;
        f.header.component_id = comp;
        f
    }

    /// A fake autopilot heard first is not obeyed when `--autopilot-sysid` names the real one,
    /// and a second autopilot after the choice is reported, never followed.
    #[test]
    fn autopilot_sysid_chooses_and_others_are_reported_not_obeyed() {
        let cfg = VehicleConfig {
            autopilot_sysid: Some(1),
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, table(), None);
        v.on_frame(s(0.0), &from(7, 1, hb(4, true)));
        assert_eq!(v.target, None, "sysid 7 is not the one asked for");
        assert!(!v.liveness.alive());
        v.on_frame(s(0.5), &hb(0, false));
        assert_eq!(v.target, Some((1, 1)));
        // The impostor keeps talking: reported once, counted, never drives the state.
        for t in 1..5 {
            v.on_frame(s(t as f64), &from(7, 1, hb(4, true)));
        }
        assert!(!v.telemetry.armed, "armed came only from the impostor");
        assert_eq!(v.telemetry.mode.as_deref(), Some("STABILIZE"));
        let evs = v.take_link_events();
        let reports: Vec<_> = evs
            .iter()
            .filter(|e| {
                matches!(
                    e,
                    LinkEvent::OtherAutopilot {
                        system: 7,
                        component: 1,
                        ..
                    }
                )
            })
            .collect();
        assert_eq!(reports.len(), 1, "{evs:?}");
        assert!(
            evs.iter()
                .any(|e| e.to_string().contains("5 heartbeats from other autopilots")),
            "{evs:?}"
        );
        // Its acks do not finish our commands either.
        let out = v.request_actions(s(5.0), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        v.on_frame(
            s(5.1),
            &from(
                7,
                1,
                ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
            ),
        );
        assert!(
            v.busy(),
            "an ack from another system is not our autopilot's"
        );
    }

    /// Issue 26: `--autopilot-sysid 1` pinned only the system, so an impostor 1/2 heard first
    /// became the autopilot. The pin is system and component: 1/2 is reported, 1/1 chosen, and
    /// only 1/1's frames drive the state.
    #[test]
    fn the_pin_names_the_component_and_an_impostor_on_another_component_is_refused() {
        let cfg = VehicleConfig {
            autopilot_sysid: Some(1),
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, table(), None);
        for t in 0..3 {
            v.on_frame(s(t as f64), &from(1, 2, hb(4, true)));
        }
        assert_eq!(v.target, None, "1/2 is not the pinned 1/1");
        v.on_frame(s(3.0), &hb(0, false));
        assert_eq!(v.target, Some((1, 1)));
        v.on_frame(s(3.5), &from(1, 2, hb(4, true)));
        assert!(!v.telemetry.armed, "armed came only from the impostor 1/2");
        let evs = v.take_link_events();
        assert!(
            evs.iter().any(|e| matches!(
                e,
                LinkEvent::OtherAutopilot {
                    system: 1,
                    component: 2,
                    ..
                }
            )),
            "{evs:?}"
        );
        assert!(
            !evs.iter()
                .any(|e| e.to_string().contains("first autopilot heard")),
            "a pinned choice is not 'the first heard': {evs:?}"
        );
        assert_eq!(v.identity_note(), None);
    }

    /// `--autopilot-compid` moves the pin to another component: then 1/1 is the stranger.
    #[test]
    fn autopilot_compid_pins_another_component() {
        let cfg = VehicleConfig {
            autopilot_sysid: Some(1),
            autopilot_compid: 2,
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, table(), None);
        v.on_frame(s(0.0), &hb(0, false));
        assert_eq!(v.target, None);
        v.on_frame(s(0.5), &from(1, 2, hb(0, false)));
        assert_eq!(v.target, Some((1, 2)));
    }

    /// Without a pin, the autopilot component (1) is preferred over an impostor on another
    /// component heard first, and the choice is said with how to pin it.
    #[test]
    fn without_a_pin_component_1_is_preferred_and_the_choice_is_named() {
        let mut v = vehicle();
        v.on_frame(s(0.0), &from(1, 2, hb(4, true)));
        v.on_frame(s(1.0), &from(1, 2, hb(4, true)));
        assert_eq!(v.target, None, "1/2 waits for a component-1 autopilot");
        v.on_frame(s(1.5), &hb(0, false));
        assert_eq!(v.target, Some((1, 1)));
        v.on_frame(s(2.0), &from(1, 2, hb(4, true)));
        assert!(!v.telemetry.armed);
        let note = v.identity_note().expect("an unpinned choice is named");
        assert!(note.contains("autopilot 1/1"), "{note}");
        assert!(note.contains("first autopilot heard"), "{note}");
        assert!(note.contains("--autopilot-sysid 1"), "{note}");
        let evs: Vec<String> = v.take_link_events().iter().map(|e| e.to_string()).collect();
        assert!(evs.iter().any(|e| e == &note), "{evs:?}");
        assert!(
            evs.iter().any(|e| e.contains("another autopilot 1/2")),
            "{evs:?}"
        );
    }

    /// An autopilot that speaks only from another component is still chosen (alone on the link
    /// for the wait), and the note says how to pin it, component included.
    #[test]
    fn without_a_pin_a_lone_autopilot_on_another_component_is_chosen_after_the_wait() {
        let mut v = vehicle();
        v.on_frame(s(0.0), &from(3, 2, hb(0, false)));
        v.on_frame(s(1.0), &from(3, 2, hb(0, false)));
        assert_eq!(v.target, None);
        v.on_frame(s(2.0), &from(3, 2, hb(0, false)));
        assert_eq!(v.target, Some((3, 2)));
        let note = v.identity_note().unwrap();
        assert!(
            note.contains("--autopilot-sysid 3 --autopilot-compid 2"),
            "{note}"
        );
    }

    #[test]
    fn only_vehicles_with_an_autopilot_are_chosen() {
        let mut v = vehicle();
        for (mavtype, autopilot) in [
            (MavType::MAV_TYPE_GCS, MavAutopilot::MAV_AUTOPILOT_INVALID),
            (
                MavType::MAV_TYPE_QUADROTOR,
                MavAutopilot::MAV_AUTOPILOT_INVALID,
            ),
            (
                MavType::MAV_TYPE_ONBOARD_CONTROLLER,
                MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            ),
            (
                MavType::MAV_TYPE_ADSB,
                MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            ),
            (MavType::MAV_TYPE_GIMBAL, MavAutopilot::MAV_AUTOPILOT_PX4),
        ] {
            let f = from(
                3,
                50,
                frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
                    mavtype,
                    autopilot,
                    ..HEARTBEAT_DATA::DEFAULT
                })),
            );
            v.on_frame(s(0.0), &f);
            assert_eq!(v.target, None, "{mavtype:?} {autopilot:?}");
        }
        v.on_frame(s(0.1), &hb(0, false));
        assert_eq!(v.target, Some((1, 1)));
    }

    fn nvf(name: &str, value: f32) -> Msg {
        Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: 0,
            value,
            name: name.into(),
        })
    }

    fn zone_vehicle() -> Vehicle {
        let mut t = table();
        t.actions.insert(
            "replan_and_land".into(),
            vec![Step::GotoZone, Step::Mode("LAND".into())],
        );
        let mut cfg = VehicleConfig::default();
        cfg.telemetry.onboard.extend([
            ("zone_n".into(), "zone_north_m".into()),
            ("zone_e".into(), "zone_east_m".into()),
        ]);
        cfg.telemetry
            .ranges
            .insert("zone_north_m".into(), [-1000.0, 1000.0]);
        cfg.telemetry
            .ranges
            .insert("zone_east_m".into(), [-1000.0, 1000.0]);
        let mut v = Vehicle::new(cfg, t, None);
        v.on_frame(s(0.0), &hb(4, true));
        v.on_frame(
            s(0.0),
            &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                lat: 473_977_420,
                lon: 1_799_900_000,
                relative_alt: 20_000,
                hdg: 0,
                ..GLOBAL_POSITION_INT_DATA::DEFAULT
            })),
        );
        v
    }

    fn repositions(out: &[Msg]) -> usize {
        out.iter()
            .filter(
                |m| matches!(m, Msg::COMMAND_INT(c) if c.command == MavCmd::MAV_CMD_DO_REPOSITION),
            )
            .count()
    }

    /// A landing zone from an unknown system is never flown to; one from the allowed camera is.
    #[test]
    fn landing_zone_from_an_unknown_sysid_produces_no_reposition() {
        let mut v = zone_vehicle();
        v.on_frame(s(0.1), &from(99, 100, frame(nvf("zone_n", 30.0))));
        v.on_frame(s(0.1), &from(99, 100, frame(nvf("zone_e", -5_000_000.0))));
        v.on_frame(s(0.1), &from(1, 77, frame(nvf("zone_e", 40.0))));
        assert_eq!(v.telemetry.get("zone_north_m"), None);
        assert_eq!(v.telemetry.get("zone_east_m"), None);
        let out = v.request_actions(s(0.2), &["replan_and_land".into()]);
        assert_eq!(repositions(&out), 0, "{out:?}");
        assert!(v.take_link_events().iter().any(|e| {
            e.to_string()
                .contains("3 monitor frames from components not allowed")
        }));

        let mut v = zone_vehicle();
        v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_n", 30.0))));
        v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_e", -5_000_000.0))));
        assert_eq!(v.telemetry.get("zone_east_m"), None, "out of range");
        v.on_frame(s(0.1), &from(1, 100, frame(nvf("zone_e", 40.0))));
        let out = v.request_actions(s(0.2), &["replan_and_land".into()]);
        assert_eq!(repositions(&out), 1);
        match &out[0] {
            Msg::COMMAND_INT(c) => {
                assert!(crate::telemetry::on_globe(c.x, c.y), "{} {}", c.x, c.y);
            }
            other => panic!("{other:?}"),
        }
    }

    /// A DISTANCE_SENSOR from a foreign system raises no obstacle event (so no mode toggling).
    #[test]
    fn foreign_distance_sensor_raises_no_obstacle() {
        let mut v = vehicle();
        connected(&mut v, 4);
        let near = frame(Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
            min_distance: 20,
            max_distance: 4000,
            current_distance: 300,
            orientation: MavSensorOrientation::MAV_SENSOR_ROTATION_NONE,
            ..DISTANCE_SENSOR_DATA::DEFAULT
        }));
        for k in 0..30 {
            v.on_frame(s(1.0 + k as f64 * 0.1), &from(77, 158, near.clone()));
        }
        assert!(
            !v.take_events()
                .iter()
                .any(|e| e.to_string().contains("obstacle"))
        );
        assert_eq!(v.telemetry.obstacle_m(s(3.0)), None);
        assert_eq!(v.foreign_monitor_frames, 30);
        // The autopilot's own rangefinder still counts.
        v.on_frame(s(4.0), &near);
        assert!(v.take_events().contains(&Event::ObstacleDetected));
    }

    #[test]
    fn unmapped_actions_are_recorded_not_sent() {
        let mut v = vehicle();
        connected(&mut v, 0);
        assert!(v.request_actions(s(1.0), &["track_v3".into()]).is_empty());
        assert_eq!(v.take_records()[0].result, CommandOutcome::Unmapped);
    }

    #[test]
    fn other_components_do_not_keep_the_link_alive() {
        let mut v = vehicle();
        connected(&mut v, 0);
        let mut gcs = hb(0, false);
        gcs.header.component_id = 190;
        for t in 1..10 {
            v.on_frame(s(t as f64), &gcs);
            v.tick(s(t as f64));
        }
        assert!(!v.liveness.alive());
    }

    fn route_vehicle() -> Vehicle {
        use crate::actions::{Route, Waypoint};
        let mut t = table();
        t.actions.insert(
            "follow_trajectory".into(),
            vec![Step::UploadMission, Step::Mode("AUTO".into())],
        );
        t.actions.insert(
            "avoid_obstacle".into(),
            vec![Step::Reposition(Offset {
                forward_m: 0.0,
                right_m: 8.0,
                up_m: 0.0,
            })],
        );
        let route = Route {
            waypoints: vec![Waypoint::Relative {
                north_m: 100.0,
                east_m: 0.0,
                alt_m: 20.0,
            }],
            altitude_m: 20.0,
            search_time_limit_s: None,
            tracking_time_limit_s: None,
            takeoff_first: false,
        };
        let cfg = VehicleConfig {
            streams: vec![],
            ..VehicleConfig::default()
        };
        let mut v = Vehicle::new(cfg, t, Some(route));
        v.on_frame(s(0.0), &hb(4, true));
        v.on_frame(
            s(0.0),
            &frame(Msg::HOME_POSITION(HOME_POSITION_DATA {
                latitude: 473_977_420,
                longitude: 85_455_940,
                altitude: 488_000,
                ..HOME_POSITION_DATA::DEFAULT
            })),
        );
        v.on_frame(
            s(0.0),
            &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                lat: 473_977_420,
                lon: 85_455_940,
                relative_alt: 20_000,
                hdg: 9000,
                ..GLOBAL_POSITION_INT_DATA::DEFAULT
            })),
        );
        v.take_records();
        v
    }

    /// Run the autopilot side of upload + download; `stored` is what the autopilot keeps.
    fn serve_upload(v: &mut Vehicle, first: Vec<Msg>, stored_alt: f32) -> Vec<Msg> {
        let count = match &first[0] {
            Msg::MISSION_COUNT(c) => c.count,
            other => panic!("expected MISSION_COUNT, got {other:?}"),
        };
        let mut items = Vec::new();
        for seq in 0..count {
            let out = v.on_frame(
                s(1.0),
                &frame(Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                    seq,
                    target_system: 1,
                    target_component: 191,
                    ..MISSION_REQUEST_INT_DATA::DEFAULT
                })),
            );
            match &out[0] {
                Msg::MISSION_ITEM_INT(i) => items.push(i.clone()),
                other => panic!("{other:?}"),
            }
        }
        let out = v.on_frame(
            s(1.1),
            &frame(Msg::MISSION_ACK(MISSION_ACK_DATA {
                mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
                ..MISSION_ACK_DATA::DEFAULT
            })),
        );
        assert!(
            matches!(out[0], Msg::MISSION_REQUEST_LIST(_)),
            "verification download starts: {out:?}"
        );
        let mut out = v.on_frame(
            s(1.2),
            &frame(Msg::MISSION_COUNT(MISSION_COUNT_DATA {
                count,
                ..MISSION_COUNT_DATA::DEFAULT
            })),
        );
        for (i, mut it) in items.into_iter().enumerate() {
            if i > 0 {
                it.z = stored_alt;
            }
            assert!(
                matches!(out[0], Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA { seq, .. }) if seq as usize == i),
                "{out:?}"
            );
            out = v.on_frame(s(1.3), &frame(Msg::MISSION_ITEM_INT(it)));
        }
        out
    }

    #[test]
    fn follow_trajectory_uploads_verifies_then_switches_to_auto() {
        let mut v = route_vehicle();
        let out = v.request_actions(s(1.0), &["follow_trajectory".into()]);
        let out = serve_upload(&mut v, out, 20.0);
        assert!(
            matches!(out[0], Msg::MISSION_ACK(_)),
            "download acknowledged"
        );
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_DO_SET_MODE],
            "AUTO only after the verified upload"
        );
        match &out[1] {
            Msg::COMMAND_LONG(c) => assert_eq!(c.param2, 3.0, "ArduPilot AUTO"),
            other => panic!("{other:?}"),
        }
        assert!(
            v.take_records()
                .iter()
                .any(|r| r.result == CommandOutcome::AcceptedVerified { items: 2 })
        );
    }

    #[test]
    fn a_mission_that_does_not_verify_is_never_flown() {
        let mut v = route_vehicle();
        let out = v.request_actions(s(1.0), &["follow_trajectory".into()]);
        let out = serve_upload(&mut v, out, 35.0);
        assert!(
            commands(&out).is_empty(),
            "no AUTO after a mismatch: {out:?}"
        );
        assert!(!v.busy());
        let recs = v.take_records();
        assert!(
            recs.iter()
                .any(|r| matches!(&r.result, CommandOutcome::Failed(Some(why))
                    if why.contains("VerifyMismatch") && why.contains("altitude"))),
            "{recs:?}"
        );
        assert!(recs.iter().any(
            |r| r.command == "SET_MODE AUTO" && matches!(r.result, CommandOutcome::Skipped(_))
        ));
    }

    fn zone_route_vehicle() -> Vehicle {
        let mut v = route_vehicle();
        v.actions.actions.insert(
            "land".into(),
            vec![Step::GotoZone, Step::Mode("LAND".into())],
        );
        v.cfg.zone_radius_m = 3.0;
        v.cfg.zone_arrive_timeout = Duration::from_secs(60);
        let onboard = &mut v.telemetry.cfg.onboard;
        onboard.insert("zone_n".into(), "zone_north_m".into());
        onboard.insert("zone_e".into(), "zone_east_m".into());
        // The landing-zone monitor: the zone 40 m north of the vehicle.
        for (name, value) in [("zone_n", 40.0), ("zone_e", 0.0)] {
            let mut f = frame(Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
                time_boot_ms: 0,
                value,
                name: name.into(),
            }));
            f.header.component_id = 100;
            v.on_frame(s(0.5), &f);
        }
        v
    }

    fn at(v: &mut Vehicle, t: f64, north_m: f64) -> Vec<Msg> {
        let (lat, lon) = displace((473_977_420, 85_455_940), north_m, 0.0);
        v.on_frame(
            s(t),
            &frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                lat,
                lon,
                relative_alt: 20_000,
                hdg: 9000,
                ..GLOBAL_POSITION_INT_DATA::DEFAULT
            })),
        )
    }

    #[test]
    fn land_at_the_zone_flies_within_the_radius_before_land() {
        let mut v = zone_route_vehicle();
        let out = v.request_actions(s(1.0), &["land".into()]);
        let target = match &out[..] {
            [Msg::COMMAND_INT(c)] if c.command == MavCmd::MAV_CMD_DO_REPOSITION => (c.x, c.y),
            other => panic!("{other:?}"),
        };
        let (n, _) = crate::telemetry::offset_m((473_977_420, 85_455_940), target);
        assert!((n - 40.0).abs() < 0.1, "zone 40 m north: {n}");
        let out = v.on_frame(
            s(1.1),
            &ack(
                MavCmd::MAV_CMD_DO_REPOSITION,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert!(
            commands(&out).is_empty(),
            "accepted is not arrived: {out:?}"
        );
        for (t, north) in [(2.0, 5.0), (5.0, 20.0), (8.0, 36.0)] {
            assert!(commands(&at(&mut v, t, north)).is_empty(), "{north} m");
            assert!(commands(&v.tick(s(t + 0.05))).is_empty());
        }
        assert!(v.busy());
        let out = at(&mut v, 10.0, 38.5);
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_DO_SET_MODE],
            "LAND once within 3 m"
        );
        let recs = v.take_records();
        assert!(
            recs.iter()
                .any(|r| r.command == "ARRIVE (zone)"
                    && matches!(r.result, CommandOutcome::Arrived(_))),
            "{recs:?}"
        );
    }

    #[test]
    fn land_at_the_zone_lands_where_it_is_after_the_arrive_timeout() {
        let mut v = zone_route_vehicle();
        v.request_actions(s(1.0), &["land".into()]);
        v.on_frame(
            s(1.1),
            &ack(
                MavCmd::MAV_CMD_DO_REPOSITION,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        assert!(commands(&at(&mut v, 30.0, 2.0)).is_empty());
        let out = at(&mut v, 61.5, 2.0);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        assert!(
            v.take_records()
                .iter()
                .any(|r| matches!(&r.result, CommandOutcome::Timeout(Some(why)) if why.contains("landing here")))
        );
    }

    #[test]
    fn stop_actions_cancels_the_running_action_and_nothing_is_resent() {
        let mut v = vehicle();
        connected(&mut v, 0);
        let out = v.request_actions(s(1.0), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        v.stop_actions(s(1.2), "pilot took control");
        assert!(!v.busy());
        assert!(v.take_records().iter().any(|r| r.command == "SET_MODE RTL"
            && r.result == CommandOutcome::Cancelled(Some("pilot took control".into()))));
        for t in [2.0, 3.0, 5.0] {
            v.on_frame(s(t), &hb(0, false));
            assert!(commands(&v.tick(s(t + 0.5))).is_empty(), "no resend at {t}");
        }
        // Asked again later (control handed back), the same action runs afresh.
        let out = v.request_actions(s(6.0), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        assert_eq!(v.commanded_modes.last().map(|m| m.0.as_str()), Some("RTL"));
    }

    #[test]
    fn commands_addressed_to_the_companion_are_kept_for_the_shell() {
        let mut v = vehicle();
        connected(&mut v, 0);
        let start = |comp: u8| {
            let mut f = frame(Msg::COMMAND_LONG(COMMAND_LONG_DATA {
                command: MavCmd::MAV_CMD_MISSION_START,
                target_system: 1,
                target_component: comp,
                ..COMMAND_LONG_DATA::DEFAULT
            }));
            f.header.system_id = 255;
            f.header.component_id = 190;
            f
        };
        v.on_frame(s(1.0), &start(191));
        v.on_frame(s(1.1), &start(1)); // for the autopilot: not ours
        assert_eq!(
            v.take_commands_to_us(),
            vec![CommandToUs {
                command: MavCmd::MAV_CMD_MISSION_START,
                from: (255, 190),
                at: s(1.0),
                before_autopilot: false
            }]
        );
        assert!(v.take_commands_to_us().is_empty());
    }

    #[test]
    fn a_command_before_the_autopilot_is_kept_marked_so_the_shell_can_refuse_it() {
        let mut v = Vehicle::new(VehicleConfig::default(), ActionTable::default(), None);
        let mut f = frame(Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_MISSION_START,
            target_system: crate::DEFAULT_SYSTEM_ID,
            target_component: crate::OUR_COMPONENT_ID,
            ..COMMAND_LONG_DATA::DEFAULT
        }));
        f.header.system_id = 66;
        v.on_frame(s(0.5), &f);
        let got = v.take_commands_to_us();
        assert_eq!(got.len(), 1);
        assert!(got[0].before_autopilot);
        assert_eq!(got[0].from.0, 66);
    }

    #[test]
    fn the_end_of_flight_window_resets_on_any_frame_that_says_airborne() {
        let mut v = vehicle();
        connected(&mut v, 0);
        let hb = |armed: bool| hb(0, armed);
        let pos = |alt_mm: i32| {
            frame(Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                relative_alt: alt_mm,
                lat: 473_977_000,
                lon: 85_455_000,
                ..GLOBAL_POSITION_INT_DATA::DEFAULT
            }))
        };
        v.on_frame(s(1.0), &pos(20_000));
        v.on_frame(s(1.1), &hb(false)); // a disarmed heartbeat at 20 m: not down
        assert_eq!(v.down_for(s(1.2)), None);
        v.on_frame(s(1.3), &pos(100));
        v.on_frame(s(1.4), &hb(false));
        assert_eq!(v.down_for(s(2.4)), Some(Duration::from_secs(1)));
        v.on_frame(s(2.5), &hb(true)); // the real armed heartbeat in between
        assert_eq!(v.down_for(s(2.6)), None);
        assert_eq!(v.armed_for(s(3.5)), Some(Duration::from_secs(1)));
        v.on_frame(s(3.6), &hb(false));
        assert_eq!(v.armed_for(s(3.7)), None);
        assert!(v.down_for(s(3.7)).is_some());
        v.on_frame(s(3.8), &pos(15_000)); // a position in the air
        assert_eq!(v.down_for(s(3.9)), None);
    }

    #[test]
    fn a_mode_reported_before_our_last_mode_command_is_not_already_set() {
        let mut v = route_vehicle();
        v.actions
            .actions
            .insert("land".into(), vec![Step::Mode("LAND".into())]);
        v.on_frame(s(1.0), &hb(9, true)); // LAND
        // A sidestep: GUIDED accepted, the heartbeat still says LAND.
        v.request_actions(s(1.1), &["avoid_obstacle".into()]);
        v.on_frame(
            s(1.2),
            &ack(
                MavCmd::MAV_CMD_DO_REPOSITION,
                MavResult::MAV_RESULT_ACCEPTED,
            ),
        );
        let out = v.request_actions(s(1.3), &["land".into()]);
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_DO_SET_MODE],
            "LAND sent again, not taken as already set"
        );
        // With a fresh heartbeat in LAND and nothing commanded since, LAND is already set.
        v.on_frame(
            s(1.4),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        v.on_frame(s(2.5), &hb(9, true));
        v.take_records();
        v.request_actions(s(2.6), &["return_to_base".into()]);
        v.on_frame(
            s(2.7),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        v.on_frame(s(3.5), &hb(6, true)); // RTL
        let out = v.request_actions(s(3.6), &["land".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    }

    #[test]
    fn armed_heartbeats_count_consecutive_reports() {
        let mut v = vehicle();
        connected(&mut v, 0);
        v.on_frame(s(1.0), &hb(0, true));
        v.on_frame(s(2.0), &hb(0, true));
        assert_eq!(v.armed_heartbeats, 2);
        v.on_frame(s(3.0), &hb(0, false));
        assert_eq!(v.armed_heartbeats, 0);
    }

    #[test]
    fn sidestep_is_to_the_right_of_the_heading() {
        let mut v = route_vehicle();
        // Heading east (90 deg): 8 m to the right is 8 m south.
        let out = v.request_actions(s(1.0), &["avoid_obstacle".into()]);
        match &out[0] {
            Msg::COMMAND_INT(c) => {
                assert_eq!(c.command, MavCmd::MAV_CMD_DO_REPOSITION);
                let (n, e) = crate::telemetry::offset_m((473_977_420, 85_455_940), (c.x, c.y));
                assert!(
                    (n + 8.0).abs() < 0.05 && e.abs() < 0.05,
                    "north {n} east {e}"
                );
                assert_eq!(c.z, 20.0);
            }
            other => panic!("{other:?}"),
        }
    }

    fn px4_frame(msg: Msg) -> Frame {
        let mut f = frame(msg);
        f.header.system_id = 2; // PX4 instance 1: MAV_SYS_ID 2
        f
    }

    /// PX4 SITL's own evidence (no EKF_STATUS_REPORT): STANDBY heartbeat in Hold, the prearm bit
    /// in SYS_STATUS health only, ESTIMATOR_STATUS 1023, home at 488 m AMSL.
    fn px4_ready(v: &mut Vehicle, t: f64) -> Vec<Msg> {
        let mut out = Vec::new();
        for msg in [
            Msg::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: modes::px4_custom_mode(4, 3),
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
                base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                system_status: MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            }),
            Msg::SYS_STATUS(SYS_STATUS_DATA {
                onboard_control_sensors_present: MavSysStatusSensor::from_bits_truncate(
                    0x0300_402f,
                ),
                onboard_control_sensors_enabled: MavSysStatusSensor::from_bits_truncate(
                    0x0301_402f,
                ),
                onboard_control_sensors_health: MavSysStatusSensor::from_bits_truncate(0x1320_c83f),
                ..SYS_STATUS_DATA::DEFAULT
            }),
            Msg::ESTIMATOR_STATUS(ESTIMATOR_STATUS_DATA {
                flags: EstimatorStatusFlags::from_bits_truncate(1023),
                ..ESTIMATOR_STATUS_DATA::DEFAULT
            }),
            Msg::HOME_POSITION(HOME_POSITION_DATA {
                latitude: 473_977_420,
                longitude: 85_455_940,
                altitude: 488_000,
                ..HOME_POSITION_DATA::DEFAULT
            }),
        ] {
            out.extend(v.on_frame(s(t), &px4_frame(msg)));
        }
        out
    }

    #[test]
    fn px4_arms_on_its_own_evidence_and_takes_off_to_amsl_altitude() {
        let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
        px4_ready(&mut v, 0.0);
        assert_eq!((v.flavor, v.target), (Flavor::Px4, Some((2, 1))));
        let out = v.request_actions(s(0.5), &["take_off".into()]);
        // Hold already stands for GUIDED on PX4; ready without any EKF_STATUS_REPORT.
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
        let mut ack_arm = px4_frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..COMMAND_ACK_DATA::DEFAULT
        }));
        ack_arm.header.component_id = 1;
        let out = v.on_frame(s(0.6), &ack_arm);
        match &out[..] {
            [Msg::COMMAND_LONG(c)] => {
                assert_eq!(c.command, MavCmd::MAV_CMD_NAV_TAKEOFF);
                assert_eq!(c.param7, 498.0, "home 488 m AMSL + 10 m");
                assert!(c.param4.is_nan() && c.param5.is_nan() && c.param6.is_nan());
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn px4_not_ready_while_prearm_health_bit_is_clear() {
        let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
        px4_ready(&mut v, 0.0);
        v.on_frame(
            s(0.1),
            &px4_frame(Msg::SYS_STATUS(SYS_STATUS_DATA {
                onboard_control_sensors_health: MavSysStatusSensor::from_bits_truncate(0x0320_c83f),
                ..SYS_STATUS_DATA::DEFAULT
            })),
        );
        let out = v.request_actions(s(0.5), &["take_off".into()]);
        assert!(commands(&out).is_empty(), "{out:?}");
    }

    #[test]
    fn px4_auto_waits_until_px4_reports_the_uploaded_mission() {
        use crate::actions::{Route, Waypoint};
        let mut t = table();
        t.actions.insert(
            "follow_trajectory".into(),
            vec![Step::UploadMission, Step::Mode("AUTO".into())],
        );
        let route = Route {
            waypoints: vec![Waypoint::Relative {
                north_m: 30.0,
                east_m: 0.0,
                alt_m: 15.0,
            }],
            altitude_m: 15.0,
            search_time_limit_s: None,
            tracking_time_limit_s: None,
            takeoff_first: true,
        };
        let mut v = Vehicle::new(VehicleConfig::default(), t, Some(route));
        px4_ready(&mut v, 0.0);
        let out = v.request_actions(s(1.0), &["follow_trajectory".into()]);
        assert!(
            matches!(&out[0], Msg::MISSION_COUNT(c) if c.count == 3),
            "{out:?}"
        );
        let mut sent = Vec::new();
        for seq in 0..3 {
            let out = v.on_frame(
                s(1.0),
                &px4_frame(Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                    seq,
                    ..MISSION_REQUEST_INT_DATA::DEFAULT
                })),
            );
            match &out[0] {
                Msg::MISSION_ITEM_INT(i) => sent.push(i.clone()),
                other => panic!("{other:?}"),
            }
        }
        assert_eq!(
            sent[0].command,
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            "PX4: take-off first"
        );
        assert_eq!((sent[0].x, sent[0].y), (473_977_420, 85_455_940));
        v.on_frame(
            s(1.1),
            &px4_frame(Msg::MISSION_ACK(MISSION_ACK_DATA {
                mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
                ..MISSION_ACK_DATA::DEFAULT
            })),
        );
        let mut out = v.on_frame(
            s(1.2),
            &px4_frame(Msg::MISSION_COUNT(MISSION_COUNT_DATA {
                count: 3,
                ..MISSION_COUNT_DATA::DEFAULT
            })),
        );
        for it in sent {
            out = v.on_frame(s(1.3), &px4_frame(Msg::MISSION_ITEM_INT(it)));
        }
        assert!(matches!(out[0], Msg::MISSION_ACK(_)), "verified: {out:?}");
        assert!(
            commands(&out).is_empty(),
            "no AUTO before PX4 reports the mission"
        );
        assert!(commands(&v.tick(s(2.0))).is_empty());
        let stale = Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
            total: 0,
            ..MISSION_CURRENT_DATA::DEFAULT
        });
        assert!(commands(&v.on_frame(s(2.1), &px4_frame(stale))).is_empty());
        let loaded = Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
            total: 3,
            ..MISSION_CURRENT_DATA::DEFAULT
        });
        let out = v.on_frame(s(2.5), &px4_frame(loaded));
        match &out[..] {
            [Msg::COMMAND_LONG(c)] => {
                assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
                assert_eq!(
                    (c.param1, c.param2, c.param3),
                    (1.0, 4.0, 4.0),
                    "AUTO.MISSION"
                );
            }
            other => panic!("{other:?}"),
        }
    }

    fn px4_heartbeat(main: u8, sub: u8) -> Frame {
        px4_frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: modes::px4_custom_mode(main, sub),
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                | MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED,
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        }))
    }

    #[test]
    fn px4_mode_change_waits_out_the_takeoff_but_return_does_not() {
        let mut t = table();
        t.actions
            .insert("hold".into(), vec![Step::Mode("LOITER".into())]);
        let mut v = Vehicle::new(VehicleConfig::default(), t, None);
        px4_ready(&mut v, 0.0);
        v.on_frame(s(1.0), &px4_heartbeat(4, 2)); // AUTO.TAKEOFF
        assert!(commands(&v.request_actions(s(1.1), &["hold".into()])).is_empty());
        assert!(commands(&v.on_frame(s(2.0), &px4_heartbeat(4, 2))).is_empty());
        assert!(commands(&v.tick(s(2.5))).is_empty(), "still taking off");
        // Returning home is never held back.
        let out = v.request_actions(s(2.6), &["return_to_base".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        // Hold again, once PX4 has ended the take-off: sent at once.
        let mut v = Vehicle::new(VehicleConfig::default(), table(), None);
        v.actions
            .actions
            .insert("hold".into(), vec![Step::Mode("AUTO".into())]);
        px4_ready(&mut v, 0.0);
        v.on_frame(s(1.0), &px4_heartbeat(4, 2));
        assert!(commands(&v.request_actions(s(1.1), &["hold".into()])).is_empty());
        let out = v.on_frame(s(3.0), &px4_heartbeat(4, 3)); // PX4 switched itself to Hold
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
    }

    fn px4_ack(command: MavCmd, result: MavResult) -> Frame {
        let mut f = px4_frame(Msg::COMMAND_ACK(COMMAND_ACK_DATA {
            command,
            result,
            ..COMMAND_ACK_DATA::DEFAULT
        }));
        f.header.component_id = 1;
        f
    }

    /// A PX4 vehicle in Hold with an action "go": AUTO, then LAND (to see when AUTO counts done).
    fn px4_go() -> Vehicle {
        let mut t = table();
        t.actions.insert(
            "go".into(),
            vec![Step::Mode("AUTO".into()), Step::Mode("LAND".into())],
        );
        let mut v = Vehicle::new(VehicleConfig::default(), t, None);
        px4_ready(&mut v, 0.0);
        v.on_frame(s(0.5), &px4_heartbeat(4, 3));
        v.take_records();
        v
    }

    fn results(v: &mut Vehicle) -> Vec<String> {
        v.take_records()
            .iter()
            .map(|r| format!("{} {}", r.command, r.result))
            .collect()
    }

    // Seen on PX4 SITL: DO_SET_MODE AUTO ACCEPTED, then TEMPORARILY_REJECTED, vehicle in LOITER.
    #[test]
    fn px4_accepted_mode_counts_only_when_a_heartbeat_shows_it_and_is_sent_again_if_not() {
        let mut v = px4_go();
        let out = v.request_actions(s(1.0), &["go".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        let ok = MavResult::MAV_RESULT_ACCEPTED;
        let out = v.on_frame(s(1.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
        assert!(
            commands(&out).is_empty(),
            "LAND only once AUTO shows: {out:?}"
        );
        for t in [2.0, 3.0, 4.0] {
            assert!(commands(&v.on_frame(s(t), &px4_heartbeat(4, 3))).is_empty());
        }
        // 3 s after ACCEPTED, still in Hold: the command had no effect, send it again.
        let out = v.tick(s(4.2));
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        let r = results(&mut v);
        let pos = |p: &str| r.iter().position(|x| x.starts_with(p));
        assert!(pos("SET_MODE AUTO ACCEPTED") < pos("SET_MODE AUTO NOT_CONFIRMED (still LOITER"));
        assert!(pos("SET_MODE AUTO NOT_CONFIRMED").is_some(), "{r:?}");
        v.on_frame(s(4.3), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
        // A heartbeat from before the acceptance does not count; the next one in AUTO does.
        let out = v.on_frame(s(5.0), &px4_heartbeat(4, 4));
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_DO_SET_MODE],
            "now LAND"
        );
        match &out[..] {
            [Msg::COMMAND_LONG(c)] => assert_eq!((c.param2, c.param3), (4.0, 6.0), "AUTO.LAND"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn px4_mode_that_never_shows_fails_after_the_attempts_and_another_mode_is_never_overridden() {
        let ok = MavResult::MAV_RESULT_ACCEPTED;
        let mut v = px4_go();
        let mut sent = commands(&v.request_actions(s(1.0), &["go".into()])).len();
        let mut t = 1.0;
        for _ in 0..6 {
            v.on_frame(s(t + 0.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
            v.on_frame(s(t + 1.0), &px4_heartbeat(4, 3));
            sent += commands(&v.tick(s(t + 3.5))).len();
            t += 3.5;
        }
        let r = results(&mut v);
        assert_eq!(sent, 3, "max_mode_attempts = 3 in all: {r:?}");
        assert!(
            r.iter()
                .any(|x| x
                    == "SET_MODE AUTO FAILED (accepted 3 times, but the vehicle stays in LOITER)"),
            "{r:?}"
        );
        assert_eq!(
            r.last().map(String::as_str),
            Some("SET_MODE LAND SKIPPED (earlier step failed)")
        );

        // The pilot switches to Position right after AUTO is accepted: never overridden.
        let mut v = px4_go();
        v.request_actions(s(1.0), &["go".into()]);
        v.on_frame(s(1.1), &px4_ack(MavCmd::MAV_CMD_DO_SET_MODE, ok));
        v.on_frame(s(2.0), &px4_heartbeat(3, 0)); // POSCTL
        assert!(commands(&v.tick(s(4.5))).is_empty());
        assert!(commands(&v.tick(s(9.0))).is_empty());
        let r = results(&mut v);
        assert!(
            r.iter()
                .any(|x| x.ends_with("went to POSHOLD, not AUTO: not overriding)")),
            "{r:?}"
        );
    }

    #[test]
    fn ardupilot_accepted_mode_is_the_mode() {
        // ArduPilot acknowledges DO_SET_MODE after set_mode() succeeded: no wait.
        let mut t = table();
        t.actions.insert(
            "go".into(),
            vec![Step::Mode("AUTO".into()), Step::Mode("LAND".into())],
        );
        let mut v = Vehicle::new(VehicleConfig::default(), t, None);
        v.on_frame(s(0.0), &hb(5, true)); // LOITER
        let out = v.request_actions(s(1.0), &["go".into()]);
        assert_eq!(commands(&out), vec![MavCmd::MAV_CMD_DO_SET_MODE]);
        let out = v.on_frame(
            s(1.1),
            &ack(MavCmd::MAV_CMD_DO_SET_MODE, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert_eq!(
            commands(&out),
            vec![MavCmd::MAV_CMD_DO_SET_MODE],
            "LAND at once"
        );
    }

    fn param_requests(out: &[Msg]) -> Vec<String> {
        out.iter()
            .filter_map(|m| match m {
                Msg::PARAM_REQUEST_READ(p) => Some(p.param_id.to_str().unwrap_or("").to_string()),
                _ => None,
            })
            .collect()
    }

    fn param_value(name: &str, value: f32, param_type: MavParamType) -> Msg {
        Msg::PARAM_VALUE(PARAM_VALUE_DATA {
            param_value: value,
            param_id: name.into(),
            param_type,
            ..PARAM_VALUE_DATA::DEFAULT
        })
    }

    #[test]
    fn ardupilot_pack_capacity_is_read_retried_until_answered_and_observed() {
        let mut v = vehicle();
        let mut asked = Vec::new();
        for t in 0..20 {
            asked.extend(param_requests(&v.on_frame(s(t as f64), &hb(0, false))));
        }
        // Asked, re-asked every PACK_PARAM_RETRY while unanswered, never more than the attempts.
        assert_eq!(asked, vec!["BATT_CAPACITY"; PACK_PARAM_ATTEMPTS as usize]);
        // A parameter nobody asked for changes nothing.
        v.on_frame(
            s(21.0),
            &frame(param_value(
                "BATT_LOW_MAH",
                500.0,
                MavParamType::MAV_PARAM_TYPE_INT32,
            )),
        );
        assert_eq!(v.telemetry.get("battery_capacity_mah"), None);
        // ArduPilot casts its integer parameters to float.
        v.on_frame(
            s(22.0),
            &frame(param_value(
                "BATT_CAPACITY",
                3300.0,
                MavParamType::MAV_PARAM_TYPE_INT32,
            )),
        );
        assert_eq!(v.telemetry.get("battery_capacity_mah"), Some(3300.0));
        // Answered at once: asked once only.
        let mut v = vehicle();
        v.on_frame(s(0.0), &hb(0, false));
        v.on_frame(
            s(0.5),
            &frame(param_value(
                "BATT_CAPACITY",
                5000.0,
                MavParamType::MAV_PARAM_TYPE_REAL32,
            )),
        );
        let out: Vec<Msg> = (1..6)
            .flat_map(|t| v.on_frame(s(t as f64), &hb(0, false)))
            .collect();
        assert!(param_requests(&out).is_empty(), "answered: not asked again");
    }

    #[test]
    fn px4_pack_parameters_are_decoded_bytewise_and_an_unset_capacity_is_said() {
        let mut v = vehicle();
        let out = px4_ready(&mut v, 0.0);
        assert_eq!(param_requests(&out), vec!["BAT1_CAPACITY", "BAT1_N_CELLS"]);
        // PX4 SIH: capacity -1 (a float parameter), 4 cells (an int32, sent bytewise).
        v.on_frame(
            s(1.0),
            &px4_frame(param_value(
                "BAT1_CAPACITY",
                -1.0,
                MavParamType::MAV_PARAM_TYPE_REAL32,
            )),
        );
        v.on_frame(
            s(1.1),
            &px4_frame(param_value(
                "BAT1_N_CELLS",
                f32::from_bits(4),
                MavParamType::MAV_PARAM_TYPE_INT32,
            )),
        );
        assert_eq!(v.telemetry.get("battery_capacity_mah"), Some(-1.0));
        assert_eq!(v.telemetry.get("battery_cells"), Some(4.0));
        let said = v
            .take_link_events()
            .iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>();
        assert!(
            said.iter()
                .any(|e| e.contains("BAT1_CAPACITY = -1") && e.contains("params [battery]")),
            "{said:?}"
        );
    }
}
