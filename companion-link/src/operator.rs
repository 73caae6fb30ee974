//! The operator in command, sans IO: who may start the mission, when a pilot has taken over, and
//! what the companion tells the ground station.
//!
//! `fly` connects, streams, decides and logs from the start, but commands no motion until the
//! operator starts the mission: a ground station sends MAV_CMD_MISSION_START addressed to this
//! companion (component 191), or (ArduPilot) the pilot puts an armed vehicle into GUIDED, or, with
//! `--start-on-arm` only, the pilot arms the vehicle. A start is only a request: the shell grants
//! it when the models agree (the launch verdict) and refuses it otherwise. A granted start is used
//! once: disarmed, or a failed take-off, before the vehicle is airborne voids it.
//!
//! Every confirmation takes wall time, not a count of frames (docs/mavlink.md, "What an attacker
//! on an unsigned link can do"): a start by arming or by GUIDED, a hand-back and a takeover count
//! only when every autopilot heartbeat over `confirm` agrees; a contradicting heartbeat resets
//! the window. A takeover stops commanding at once (safety first) but is confirmed the same way:
//! when the autopilot's heartbeats show the companion's own mode again within the window, the
//! companion resumes and records a false alarm.
//!
//! [`GcsText`] is the STATUSTEXT outbox: MAVLink severities, no repeat of the same text within
//! `repeat`, and at most `max_per_s` texts in any second (an answer to a refused start one more).

use super::Msg;
use super::dialect::*;
use super::modes::{self, Flavor, FlightMode, ReportedMode};
use companion_core::record::OperatorEvent;
use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

/// Who commands the vehicle now.
#[derive(Debug, Clone, PartialEq)]
pub enum Control {
    /// Deciding and logging; no motion commanded until the operator starts the mission.
    Waiting,
    /// The operator started the mission (or `--auto-start`): the companion commands.
    Started,
    /// A mode the companion did not command was reported (`mode`, first at `since`): the
    /// companion stopped commanding at once; the takeover is confirmed once every heartbeat over
    /// the confirmation window shows a mode not the companion's, or withdrawn (a false alarm)
    /// when one shows the companion's own mode again.
    Unconfirmed {
        /// The mode the autopilot reported.
        mode: ReportedMode,
        /// When it was first reported.
        since: Duration,
    },
    /// A mode the companion did not command (`mode`): the pilot or the autopilot flies.
    TakenOver {
        /// The mode the autopilot reported.
        mode: ReportedMode,
    },
    /// The companion is stopping (a signal, the end of `--duration`, a fatal error): it handed
    /// the vehicle to the autopilot and commands nothing more.
    Stopping,
    /// The companion started (or restarted) next to a vehicle already armed and in the air: it
    /// said so, handed the vehicle to the autopilot when it flew in a companion's mode, and
    /// commands nothing and takes no start until the vehicle is landed and disarmed.
    FlightInProgress,
}

impl Control {
    /// The decision record's `vehicle.operator` value: `waiting`, `started`,
    /// `takeover_unconfirmed` or `taken_over`.
    pub fn label(&self) -> &'static str {
        match self {
            Control::Waiting => "waiting",
            Control::Started => "started",
            Control::Unconfirmed { .. } => "takeover_unconfirmed",
            Control::TakenOver { .. } => "taken_over",
            Control::Stopping => "stopping",
            Control::FlightInProgress => "flight_in_progress",
        }
    }
}

/// How a mission start or a hand-back came about (a record type: the record's operator events
/// carry it).
pub use companion_core::record::StartBy;

/// Why a granted start was voided before the vehicle was airborne.
#[derive(Debug, Clone, PartialEq)]
pub enum VoidReason {
    /// The autopilot reported the vehicle disarmed after it had been armed.
    Disarmed,
    /// The take-off failed (the step and the autopilot's answer).
    TakeoffFailed(String),
}

/// What the gate decided on one observation.
#[derive(Debug, Clone, PartialEq)]
pub enum GateEvent {
    /// The operator asks for a start: the shell grants it ([`OperatorGate::grant`]) when the
    /// models agree, else refuses it ([`OperatorGate::refuse`]).
    StartRequested(StartBy),
    /// The companion may command from now on.
    Started(StartBy),
    /// The start was refused (the models' reason, in words); the companion keeps waiting.
    StartRefused(StartBy, String),
    /// A granted start was voided before the vehicle was airborne: back to waiting, and no arming
    /// without a new operator action.
    StartVoided(VoidReason),
    /// A mode the companion did not command: commanding stopped at once, the takeover waits
    /// for confirmation.
    TakeoverSuspected(ReportedMode),
    /// The takeover is confirmed: the pilot or the autopilot flies in this mode.
    TakenOver(ReportedMode),
    /// The suspected takeover's mode (first) was not confirmed: the autopilot shows the
    /// companion's own mode (second) again, and the companion resumes.
    FalseAlarm(ReportedMode, ReportedMode),
    /// Control came back to the companion after a take-over.
    HandedBack(StartBy),
}

impl GateEvent {
    /// The decision record's event (its sentence is the journal's line).
    pub fn record(&self) -> OperatorEvent {
        use OperatorEvent as O;
        match self {
            GateEvent::StartRequested(by) => O::StartRequested { by: *by },
            GateEvent::Started(by) => O::Started { by: *by },
            GateEvent::StartRefused(by, why) => O::StartRefused {
                by: *by,
                why: why.clone(),
            },
            GateEvent::StartVoided(VoidReason::Disarmed) => O::StartVoidedDisarmed,
            GateEvent::StartVoided(VoidReason::TakeoffFailed(why)) => {
                O::StartVoidedTakeoffFailed { why: why.clone() }
            }
            GateEvent::TakeoverSuspected(m) => O::TakeoverSuspected {
                mode: m.to_string(),
            },
            GateEvent::TakenOver(m) => O::TakenOver {
                mode: m.to_string(),
            },
            GateEvent::FalseAlarm(m, own) => O::FalseAlarm {
                mode: m.to_string(),
                own: own.to_string(),
            },
            GateEvent::HandedBack(by) => O::HandedBack { by: *by },
        }
    }

    /// The decision record's event text.
    pub fn describe(&self) -> String {
        self.record().to_string()
    }
}

/// What the gate reads from the vehicle each loop turn.
#[derive(Debug, Clone, Copy)]
pub struct VehicleView<'a> {
    /// Autopilot family (mode names differ).
    pub flavor: Flavor,
    /// The heartbeat's custom mode and its name, once known.
    pub custom_mode: u32,
    /// `custom_mode` decoded for this autopilot, once a heartbeat was heard.
    pub mode: Option<ReportedMode>,
    /// Consecutive autopilot heartbeats that reported the vehicle armed (0 when disarmed).
    pub armed_heartbeats: u32,
    /// Every autopilot heartbeat has reported the vehicle armed for this long (None when the
    /// last one reported it disarmed).
    pub armed_for: Option<Duration>,
    /// Every autopilot heartbeat has shown `custom_mode` for this long.
    pub mode_for: Duration,
    /// The vehicle has been airborne in this flight (the mission estimator's word).
    pub airborne: bool,
    /// Modes the companion commanded, with the time it sent each (newest last).
    pub commanded_modes: &'a [(FlightMode, Duration)],
    /// The mode the mission item MISSION_CURRENT names flies by itself: RTL for the mission's
    /// own NAV_RETURN_TO_LAUNCH, LAND for its NAV_LAND ([`mission_item_mode`]); None for any
    /// other item or an unknown mission. PX4 flies those items as its RTL and LAND modes.
    pub mission_item_mode: Option<FlightMode>,
}

impl VehicleView<'_> {
    fn armed(&self) -> bool {
        self.armed_heartbeats > 0
    }
}

/// The operator gate: one per `fly` run; [`OperatorGate::new_flight`] after each landing.
#[derive(Debug, Clone)]
pub struct OperatorGate {
    /// Who commands the vehicle now.
    pub control: Control,
    /// A mode change to a mode commanded less than this long ago is the companion's own.
    pub grace: Duration,
    /// Armed (or in GUIDED, or the pilot's mode) on every autopilot heartbeat for this long
    /// confirms a start by arming, a start or hand-back by GUIDED, and a takeover.
    pub confirm: Duration,
    /// Armed reported by at least this many consecutive heartbeats besides `confirm` (one
    /// spoofed or corrupt heartbeat cannot start anything).
    pub armed_heartbeats_to_start: u32,
    /// `--start-on-arm`: the pilot arming the vehicle is a start request (off by default:
    /// arming for a manual flight is not a start).
    pub start_on_arm: bool,
    /// `--auto-start`: a start is requested until the models grant it.
    auto_start_pending: bool,
    last_custom_mode: Option<u32>,
    /// The vehicle was seen disarmed since the gate began waiting: only then is arming the
    /// pilot's start (a companion started next to a vehicle already flying does not take it).
    seen_disarmed: bool,
    /// This run of armed heartbeats already made a start request (granted or refused).
    arm_used: bool,
    /// The pilot switched the armed vehicle into GUIDED while the gate waited or had handed
    /// control over; consumed by the request it makes.
    guided_entered: bool,
    /// The vehicle was armed since the start was granted (a disarm after that voids the start
    /// while not airborne).
    armed_since_start: bool,
}

impl OperatorGate {
    /// `auto_start`: request a start at once (SITL and tests); it is granted like any other, when
    /// the models agree.
    pub fn new(auto_start: bool) -> Self {
        Self {
            control: Control::Waiting,
            grace: Duration::from_secs(5),
            confirm: Duration::from_secs(2),
            armed_heartbeats_to_start: 2,
            start_on_arm: false,
            auto_start_pending: auto_start,
            last_custom_mode: None,
            seen_disarmed: false,
            arm_used: false,
            guided_entered: false,
            armed_since_start: false,
        }
    }

    /// A gate already commanding (soak and fuzz runs of the cycle, no operator).
    pub fn started() -> Self {
        let mut g = Self::new(false);
        g.control = Control::Started;
        g
    }

    /// The companion may command motion now.
    pub fn commanding(&self) -> bool {
        self.control == Control::Started
    }

    /// Back to waiting for the operator (after a flight ended landed and disarmed).
    pub fn new_flight(&mut self) {
        self.control = Control::Waiting;
        self.seen_disarmed = false;
        self.arm_used = true; // the arming of the flight just flown is not a new start
        self.guided_entered = false;
        self.armed_since_start = false;
    }

    /// Grant a requested start (the models agree).
    pub fn grant(&mut self, by: StartBy) -> GateEvent {
        if by == StartBy::AutoStart {
            self.auto_start_pending = false;
        }
        self.control = Control::Started;
        self.armed_since_start = false;
        GateEvent::Started(by)
    }

    /// Refuse a requested start (the models do not agree): still waiting. An `--auto-start`
    /// request stays pending (asked again each turn, said once per reason by the shell).
    pub fn refuse(&mut self, by: StartBy, why: &str) -> GateEvent {
        GateEvent::StartRefused(by, why.to_string())
    }

    /// The take-off failed: a granted start not yet airborne is void.
    pub fn takeoff_failed(&mut self, airborne: bool, why: &str) -> Option<GateEvent> {
        if self.control == Control::Started && !airborne {
            self.void();
            return Some(GateEvent::StartVoided(VoidReason::TakeoffFailed(
                why.to_string(),
            )));
        }
        None
    }

    fn void(&mut self) {
        self.control = Control::Waiting;
        self.auto_start_pending = false; // --auto-start starts the first flight only
        self.armed_since_start = false;
        self.arm_used = true;
        self.guided_entered = false;
    }

    /// A MAV_CMD_MISSION_START addressed to us from a ground station. Returns the event (a start
    /// request or a hand-back).
    pub fn on_start_command(&mut self) -> Option<GateEvent> {
        match self.control {
            Control::Waiting => Some(GateEvent::StartRequested(StartBy::StartCommand)),
            Control::TakenOver { .. } | Control::Unconfirmed { .. } => {
                self.control = Control::Started;
                Some(GateEvent::HandedBack(StartBy::StartCommand))
            }
            Control::Started | Control::Stopping | Control::FlightInProgress => None,
        }
    }

    /// One look at the vehicle: start requests (GUIDED, arming with `--start-on-arm`,
    /// `--auto-start`), a disarm that voids a start, a takeover and its confirmation, a hand-back.
    pub fn observe(&mut self, now: Duration, v: &VehicleView) -> Option<GateEvent> {
        let Some(reported) = v.mode else {
            return None; // no heartbeat yet
        };
        if !v.armed() {
            self.seen_disarmed = true;
            self.arm_used = false;
        }
        let changed = self.last_custom_mode != Some(v.custom_mode);
        let first_mode = self.last_custom_mode.is_none();
        self.last_custom_mode = Some(v.custom_mode);
        let in_guided = v.flavor == Flavor::ArduPilot
            && modes::is_in_mode(v.flavor, v.custom_mode, FlightMode::Guided);
        if !in_guided || !v.armed() {
            self.guided_entered = false;
        } else if changed && !first_mode && !self.is_own_mode(now, v) {
            self.guided_entered = true;
        }
        let guided_held = self.guided_entered && v.mode_for >= self.confirm;
        match &self.control {
            Control::Waiting => {
                if self.auto_start_pending {
                    return Some(GateEvent::StartRequested(StartBy::AutoStart));
                }
                if guided_held {
                    self.guided_entered = false;
                    return Some(GateEvent::StartRequested(StartBy::GuidedSwitch));
                }
                if self.start_on_arm
                    && !self.arm_used
                    && self.seen_disarmed
                    && v.armed_heartbeats >= self.armed_heartbeats_to_start
                    && v.armed_for.is_some_and(|d| d >= self.confirm)
                {
                    self.arm_used = true;
                    return Some(GateEvent::StartRequested(StartBy::PilotArmed));
                }
                None
            }
            Control::Started => {
                if v.armed() {
                    self.armed_since_start = true;
                } else if self.armed_since_start && !v.airborne {
                    self.void();
                    return Some(GateEvent::StartVoided(VoidReason::Disarmed));
                }
                if !changed || first_mode {
                    return None;
                }
                // Disarmed, nothing moves: a mode change on the ground (ArduCopter reads the RC
                // mode switch at start-up and leaves GUIDED for it) takes no flight from the
                // companion. Its take-off arms only in the mode it set (the vehicle's ARM step).
                if !v.armed() {
                    return None;
                }
                if self.is_own_mode(now, v) {
                    return None;
                }
                self.control = Control::Unconfirmed {
                    mode: reported,
                    since: now,
                };
                Some(GateEvent::TakeoverSuspected(reported))
            }
            &Control::Unconfirmed { mode, .. } => {
                if self.is_own_mode(now, v) {
                    self.control = Control::Started;
                    return Some(GateEvent::FalseAlarm(mode, reported));
                }
                if v.mode_for >= self.confirm {
                    self.control = Control::TakenOver { mode: reported };
                    return Some(GateEvent::TakenOver(reported));
                }
                None
            }
            Control::Stopping | Control::FlightInProgress => None,
            Control::TakenOver { .. } => {
                if guided_held {
                    self.guided_entered = false;
                    self.control = Control::Started;
                    return Some(GateEvent::HandedBack(StartBy::GuidedSwitch));
                }
                if changed && let Control::TakenOver { mode } = &mut self.control {
                    *mode = reported;
                }
                None
            }
        }
    }

    /// The mode the vehicle reports is one the companion commanded recently, or one the
    /// autopilot enters by itself after such a command (PX4 holds in LOITER after a take-off,
    /// a mission's end or a reposition).
    fn is_own_mode(&self, now: Duration, v: &VehicleView) -> bool {
        let recent = v
            .commanded_modes
            .iter()
            .filter(|(_, at)| now.saturating_sub(*at) <= self.grace);
        let latest = v.commanded_modes.last();
        let candidates = recent.chain(latest);
        for &(mode, _) in candidates {
            if modes::is_in_mode(v.flavor, v.custom_mode, mode) {
                return true;
            }
        }
        let mission_flown = latest.is_some_and(|&(m, _)| m == FlightMode::Auto);
        // The mission's own end: PX4 flies a mission's RTL (LAND) item by switching to its RTL
        // (LAND) mode, and names the item in MISSION_CURRENT before its HEARTBEAT shows the mode.
        // A pilot's RTL in the middle of the mission leaves MISSION_CURRENT on a waypoint.
        if mission_flown
            && v.mission_item_mode
                .is_some_and(|m| modes::is_in_mode(v.flavor, v.custom_mode, m))
        {
            return true;
        }
        v.flavor == Flavor::Px4
            && !v.commanded_modes.is_empty()
            && modes::is_in_mode(v.flavor, v.custom_mode, FlightMode::Loiter)
    }
}

/// The mode a mission item flies by itself when it is the current one: RTL for
/// NAV_RETURN_TO_LAUNCH, LAND for NAV_LAND, None for every other command.
pub fn mission_item_mode(command: MavCmd) -> Option<FlightMode> {
    match command {
        MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH => Some(FlightMode::Rtl),
        MavCmd::MAV_CMD_NAV_LAND => Some(FlightMode::Land),
        _ => None,
    }
}

/// MAV_CMD_MISSION_START is the operator's start command when addressed to component 191.
pub const START_COMMAND: MavCmd = MavCmd::MAV_CMD_MISSION_START;

/// The COMMAND_ACK for a command addressed to us, to the sender.
pub fn ack(command: MavCmd, result: MavResult, to: (u8, u8)) -> Msg {
    Msg::COMMAND_ACK(COMMAND_ACK_DATA {
        command,
        result,
        progress: 0,
        result_param2: 0,
        target_system: to.0,
        target_component: to.1,
    })
}

/// STATUSTEXT outbox with rate limits.
#[derive(Debug, Clone)]
pub struct GcsText {
    /// The same text is not sent again within this long.
    pub repeat: Duration,
    /// At most this many texts in any one second; more are dropped (and counted).
    pub max_per_s: u32,
    last: BTreeMap<String, Duration>,
    window: VecDeque<Duration>,
    /// Texts dropped by the rate limit, since start.
    pub dropped: u64,
    /// The `id` of the last text sent in chunks.
    chunk_id: u16,
    /// When an answer last went out over the per-second cap ([`GcsText::say_answer`]).
    answer_over_cap: Option<Duration>,
}

/// Why [`GcsText`] holds a text back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Held {
    /// The same text went out less than `repeat` ago.
    Repeat,
    /// The per-second cap is full.
    Cap,
}

/// STATUSTEXT carries 50 bytes of text.
const TEXT_LEN: usize = 50;

/// The text as it can go out. ASCII only: a non-final chunk must be exactly 50 bytes, which a
/// multi-byte character could not always fill, and ground stations show STATUSTEXT as plain bytes.
fn sendable(text: &str) -> String {
    text.chars()
        .filter(|c| !c.is_control())
        .map(|c| if c.is_ascii() { c } else { '?' })
        .take(MAX_CHUNKS * TEXT_LEN - 1)
        .collect()
}

impl GcsText {
    /// A limiter sending a text again after `repeat` at the earliest, at most `max_per_s` a second.
    pub fn new(repeat: Duration, max_per_s: u32) -> Self {
        Self {
            repeat,
            max_per_s,
            last: BTreeMap::new(),
            window: VecDeque::new(),
            dropped: 0,
            chunk_id: 0,
            answer_over_cap: None,
        }
    }

    /// The STATUSTEXT to send now: none when the same text went out less than `repeat` ago or
    /// the per-second cap is reached. A text longer than one STATUSTEXT (50 bytes) goes out in
    /// MAVLink 2 chunks, as ArduPilot sends its own and QGroundControl and pymavlink join them:
    /// one non-zero `id` for all, `chunk_seq` 0, 1, ..., 50 bytes each, the last one shorter (an
    /// empty last chunk when the text fills the others exactly) so its NUL ends the text. At most
    /// [`MAX_CHUNKS`] chunks; a longer text is cut. One text counts once against `max_per_s`,
    /// however many chunks it takes, so its chunks are never split by the cap.
    pub fn say(&mut self, now: Duration, severity: MavSeverity, text: &str) -> Vec<Msg> {
        self.say_unless_held(now, severity, text, false)
    }

    /// `text` out unless [`GcsText::held`]; over a full cap when `past_cap` (then noted as the
    /// last answer over it).
    fn say_unless_held(
        &mut self,
        now: Duration,
        severity: MavSeverity,
        text: &str,
        past_cap: bool,
    ) -> Vec<Msg> {
        let text = sendable(text);
        match self.held(now, &text) {
            Some(Held::Repeat) => Vec::new(),
            Some(Held::Cap) if past_cap => {
                self.answer_over_cap = Some(now);
                self.send(now, severity, text)
            }
            Some(Held::Cap) => {
                self.dropped += 1;
                Vec::new()
            }
            None => self.send(now, severity, text),
        }
    }

    /// Why `text` cannot go out now, if it cannot: the same text went out less than `repeat`
    /// ago, or `max_per_s` texts went out in the last second.
    fn held(&mut self, now: Duration, text: &str) -> Option<Held> {
        if let Some(at) = self.last.get(text)
            && now.saturating_sub(*at) < self.repeat
        {
            return Some(Held::Repeat);
        }
        while self
            .window
            .front()
            .is_some_and(|t| now.saturating_sub(*t) >= Duration::from_secs(1))
        {
            self.window.pop_front();
        }
        (self.window.len() as u32 >= self.max_per_s).then_some(Held::Cap)
    }

    /// The words answering a ground station's request (a start refused by the models, with why):
    /// as [`GcsText::say`], but when the per-second cap is full it still goes out, at most one
    /// such answer a second, so the operator who was just refused is told why even right after
    /// the start-up texts (a CI run's MISSION_START refused 0.35 s after "Cannot meet goals" got
    /// its DENIED and no words). At most `max_per_s` + 1 texts in any second.
    pub fn say_answer(&mut self, now: Duration, severity: MavSeverity, text: &str) -> Vec<Msg> {
        let answered_lately = self
            .answer_over_cap
            .is_some_and(|t| now.saturating_sub(t) < Duration::from_secs(1));
        self.say_unless_held(now, severity, text, !answered_lately)
    }

    /// A text the ground station must get whatever the rate cap: the companion stopping and a
    /// hand-off the pilot must take over. Once per run, so it cannot flood the link; it still
    /// counts against the cap for the texts after it.
    pub fn say_always(&mut self, now: Duration, severity: MavSeverity, text: &str) -> Vec<Msg> {
        let text = sendable(text);
        self.send(now, severity, text)
    }

    fn send(&mut self, now: Duration, severity: MavSeverity, text: String) -> Vec<Msg> {
        self.window.push_back(now);
        // Old texts no longer hold anything back: keep the map small.
        let repeat = self.repeat;
        self.last.retain(|_, at| now.saturating_sub(*at) < repeat);
        self.last.insert(text.clone(), now);
        match severity {
            MavSeverity::MAV_SEVERITY_EMERGENCY
            | MavSeverity::MAV_SEVERITY_ALERT
            | MavSeverity::MAV_SEVERITY_CRITICAL
            | MavSeverity::MAV_SEVERITY_ERROR
            | MavSeverity::MAV_SEVERITY_WARNING => {
                tracing::warn!(target: "companion::gcs", "STATUSTEXT {text}")
            }
            _ => tracing::info!(target: "companion::gcs", "STATUSTEXT {text}"),
        }
        let chunks = chunks(&text);
        let id = if chunks.len() > 1 {
            // Non-zero and new for each long text (0 means "a text of one chunk").
            self.chunk_id = self.chunk_id.checked_add(1).unwrap_or(1);
            self.chunk_id
        } else {
            0
        };
        chunks
            .into_iter()
            .enumerate()
            .map(|(seq, part)| {
                Msg::STATUSTEXT(STATUSTEXT_DATA {
                    severity,
                    text: part.into(),
                    id,
                    chunk_seq: seq as u8,
                })
            })
            .collect()
    }
}

impl GcsText {
    /// Texts that belong together (a refusal, then what would fit): they count once against
    /// `max_per_s`, as one text's chunks do, so the cap never sends the first without the rest.
    /// None when the first is held back (repeated, or the cap reached).
    pub fn say_together(
        &mut self,
        now: Duration,
        severity: MavSeverity,
        texts: &[String],
    ) -> Vec<Msg> {
        let mut out = Vec::new();
        for (k, text) in texts.iter().enumerate() {
            // The group holds one place in the window: the first's.
            let held = if k > 0 { self.window.pop_back() } else { None };
            let msgs = self.say(now, severity, text);
            if msgs.is_empty() {
                if k == 0 {
                    return out;
                }
                self.window.extend(held);
            }
            out.extend(msgs);
        }
        out
    }
}

/// Most STATUSTEXT chunks one text is sent in (ArduPilot queues up to about this many).
pub const MAX_CHUNKS: usize = 4;

/// `text` in pieces of [`TEXT_LEN`] bytes; a text longer than one piece ends with a piece
/// shorter than that, empty if need be, whose NUL padding tells the receiver the text is
/// complete. `text` is ASCII (see [`GcsText::say`]), so every byte index is a boundary.
fn chunks(text: &str) -> Vec<&str> {
    if text.len() <= TEXT_LEN {
        return vec![text];
    }
    let mut out: Vec<&str> = text
        .as_bytes()
        .chunks(TEXT_LEN)
        .map(|c| std::str::from_utf8(c).unwrap_or_default())
        .collect();
    if text.len().is_multiple_of(TEXT_LEN) {
        out.push("");
    }
    out
}

#[cfg(test)]
mod tests;
