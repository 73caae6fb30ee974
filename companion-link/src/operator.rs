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
//! `repeat`, and at most `max_per_s` texts in any second.

use super::Msg;
use super::dialect::*;
use super::modes::{self, Flavor};
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
        /// Name of the mode the autopilot reported.
        mode: String,
        /// When it was first reported.
        since: Duration,
    },
    /// A mode the companion did not command (`mode`): the pilot or the autopilot flies.
    TakenOver {
        /// Name of the mode the autopilot reported.
        mode: String,
    },
    /// The companion is stopping (a signal, the end of `--duration`, a fatal error): it handed
    /// the vehicle to the autopilot and commands nothing more.
    Stopping,
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
        }
    }
}

/// How a mission start or a hand-back came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartBy {
    /// `fly --auto-start`: no operator.
    AutoStart,
    /// The pilot armed the vehicle (`--start-on-arm` only).
    PilotArmed,
    /// MAV_CMD_MISSION_START from the ground station.
    StartCommand,
    /// The pilot switched an armed vehicle to GUIDED (ArduPilot).
    GuidedSwitch,
}

impl StartBy {
    /// How the operator asked, in words.
    pub fn describe(self) -> &'static str {
        match self {
            StartBy::AutoStart => "--auto-start (no operator)",
            StartBy::PilotArmed => "the pilot armed the vehicle (--start-on-arm)",
            StartBy::StartCommand => "MAV_CMD_MISSION_START from the ground station",
            StartBy::GuidedSwitch => "the pilot switched the armed vehicle to GUIDED",
        }
    }
}

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
    /// A mode the companion did not command (its name): commanding stopped at once, the
    /// takeover waits for confirmation.
    TakeoverSuspected(String),
    /// The takeover is confirmed: the pilot or the autopilot flies in this mode.
    TakenOver(String),
    /// The suspected takeover's mode (first) was not confirmed: the autopilot shows the
    /// companion's own mode (second) again, and the companion resumes.
    FalseAlarm(String, String),
    /// Control came back to the companion after a take-over.
    HandedBack(StartBy),
}

impl GateEvent {
    /// The decision record's event text.
    pub fn describe(&self) -> String {
        match self {
            GateEvent::StartRequested(by) => {
                format!("operator: start requested ({})", by.describe())
            }
            GateEvent::Started(by) => format!("operator: mission started ({})", by.describe()),
            GateEvent::StartRefused(by, why) => format!(
                "operator: start refused ({}): {why}; still waiting for the operator",
                by.describe()
            ),
            GateEvent::StartVoided(VoidReason::Disarmed) => "operator: start void: the vehicle was disarmed before it was airborne; waiting for a new start".into(),
            GateEvent::StartVoided(VoidReason::TakeoffFailed(why)) => format!(
                "operator: start void: the take-off failed before the vehicle was airborne ({why}); waiting for a new start"
            ),
            GateEvent::TakeoverSuspected(m) => format!(
                "operator: mode {m} was not commanded by the companion: commanding stopped until every heartbeat confirms it or shows the companion's mode again"
            ),
            GateEvent::TakenOver(m) => format!(
                "operator: mode {m} was not commanded by the companion: the pilot or the autopilot has control; the companion stops commanding"
            ),
            GateEvent::FalseAlarm(m, own) => format!(
                "operator: takeover not confirmed: {m} was reported, then the autopilot showed the companion's {own} again; commanding resumed (false alarm)"
            ),
            GateEvent::HandedBack(StartBy::GuidedSwitch) => {
                "operator: control handed back (switch to GUIDED)".into()
            }
            GateEvent::HandedBack(_) => {
                "operator: control handed back (MAV_CMD_MISSION_START from the ground station)"
                    .into()
            }
        }
    }
}

/// What the gate reads from the vehicle each loop turn.
#[derive(Debug, Clone, Copy)]
pub struct VehicleView<'a> {
    /// Autopilot family (mode names differ).
    pub flavor: Flavor,
    /// The heartbeat's custom mode and its name, once known.
    pub custom_mode: u32,
    /// Name of `custom_mode` for this autopilot, if known.
    pub mode: Option<&'a str>,
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
    pub commanded_modes: &'a [(String, Duration)],
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
            Control::Started | Control::Stopping => None,
        }
    }

    /// One look at the vehicle: start requests (GUIDED, arming with `--start-on-arm`,
    /// `--auto-start`), a disarm that voids a start, a takeover and its confirmation, a hand-back.
    pub fn observe(&mut self, now: Duration, v: &VehicleView) -> Option<GateEvent> {
        if v.mode.is_none() {
            return None; // no heartbeat yet
        }
        if !v.armed() {
            self.seen_disarmed = true;
            self.arm_used = false;
        }
        let changed = self.last_custom_mode != Some(v.custom_mode);
        let first_mode = self.last_custom_mode.is_none();
        self.last_custom_mode = Some(v.custom_mode);
        let in_guided =
            v.flavor == Flavor::ArduPilot && modes::is_in_mode(v.flavor, v.custom_mode, "GUIDED");
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
                let name = v.mode.unwrap_or("?").to_string();
                self.control = Control::Unconfirmed {
                    mode: name.clone(),
                    since: now,
                };
                Some(GateEvent::TakeoverSuspected(name))
            }
            Control::Unconfirmed { mode, .. } => {
                let mode = mode.clone();
                if self.is_own_mode(now, v) {
                    self.control = Control::Started;
                    return Some(GateEvent::FalseAlarm(
                        mode,
                        v.mode.unwrap_or("?").to_string(),
                    ));
                }
                if v.mode_for >= self.confirm {
                    let name = v.mode.unwrap_or("?").to_string();
                    self.control = Control::TakenOver { mode: name.clone() };
                    return Some(GateEvent::TakenOver(name));
                }
                None
            }
            Control::Stopping => None,
            Control::TakenOver { .. } => {
                if guided_held {
                    self.guided_entered = false;
                    self.control = Control::Started;
                    return Some(GateEvent::HandedBack(StartBy::GuidedSwitch));
                }
                if changed && let Control::TakenOver { mode } = &mut self.control {
                    *mode = v.mode.unwrap_or("?").to_string();
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
        for (name, _) in candidates {
            if modes::is_in_mode(v.flavor, v.custom_mode, name) {
                return true;
            }
        }
        v.flavor == Flavor::Px4
            && !v.commanded_modes.is_empty()
            && modes::is_in_mode(v.flavor, v.custom_mode, "LOITER")
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
}

/// STATUSTEXT carries 50 bytes of text.
const TEXT_LEN: usize = 50;

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
        // ASCII only: a non-final chunk must be exactly 50 bytes, which a multi-byte character
        // could not always fill, and ground stations show STATUSTEXT as plain bytes.
        let text: String = text
            .chars()
            .filter(|c| !c.is_control())
            .map(|c| if c.is_ascii() { c } else { '?' })
            .take(MAX_CHUNKS * TEXT_LEN - 1)
            .collect();
        if let Some(at) = self.last.get(&text)
            && now.saturating_sub(*at) < self.repeat
        {
            return Vec::new();
        }
        while self
            .window
            .front()
            .is_some_and(|t| now.saturating_sub(*t) >= Duration::from_secs(1))
        {
            self.window.pop_front();
        }
        if self.window.len() as u32 >= self.max_per_s {
            self.dropped += 1;
            return Vec::new();
        }
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
mod tests {
    use super::*;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    const GUIDED: u32 = 4;
    const LOITER: u32 = 5;
    const AUTO: u32 = 3;
    const LAND: u32 = 9;
    const STABILIZE: u32 = 0;

    /// A simulated autopilot heartbeat stream as the vehicle tracks it: the view after each
    /// heartbeat, with `armed_for` and `mode_for` computed over the frames fed so far (a
    /// contradicting frame resets them, as `Vehicle::on_frame` does).
    struct Feed {
        cmds: Vec<(String, Duration)>,
        armed_since: Option<Duration>,
        armed_hb: u32,
        mode: u32,
        mode_since: Duration,
        airborne: bool,
        last: Option<(Duration, u32, bool)>,
    }

    fn name(mode: u32) -> &'static str {
        match mode {
            GUIDED => "GUIDED",
            LOITER => "LOITER",
            AUTO => "AUTO",
            LAND => "LAND",
            _ => "STABILIZE",
        }
    }

    impl Feed {
        fn new() -> Self {
            Self {
                cmds: Vec::new(),
                armed_since: None,
                armed_hb: 0,
                mode: u32::MAX,
                mode_since: Duration::ZERO,
                airborne: false,
                last: None,
            }
        }
        fn hb(&mut self, t: f64, mode: u32, armed: bool) {
            let t = s(t);
            if armed {
                self.armed_since.get_or_insert(t);
                self.armed_hb += 1;
            } else {
                self.armed_since = None;
                self.armed_hb = 0;
            }
            if mode != self.mode {
                self.mode = mode;
                self.mode_since = t;
            }
            self.last = Some((t, mode, armed));
        }
        fn view(&self, now: Duration) -> VehicleView<'_> {
            VehicleView {
                flavor: Flavor::ArduPilot,
                custom_mode: self.mode,
                mode: self.last.map(|(_, m, _)| name(m)),
                armed_heartbeats: self.armed_hb,
                armed_for: self.armed_since.map(|a| now.saturating_sub(a)),
                mode_for: now.saturating_sub(self.mode_since),
                airborne: self.airborne,
                commanded_modes: &self.cmds,
            }
        }
        /// Feed a heartbeat and let the gate look, at the heartbeat's time.
        fn at(
            &mut self,
            g: &mut OperatorGate,
            t: f64,
            mode: u32,
            armed: bool,
        ) -> Option<GateEvent> {
            self.hb(t, mode, armed);
            g.observe(s(t), &self.view(s(t)))
        }
        /// The gate looks without a new heartbeat (the loop's 100 ms tick).
        fn look(&self, g: &mut OperatorGate, t: f64) -> Option<GateEvent> {
            g.observe(s(t), &self.view(s(t)))
        }
    }

    #[test]
    fn arming_is_no_start_without_start_on_arm() {
        let mut g = OperatorGate::new(false);
        let mut f = Feed::new();
        assert_eq!(f.at(&mut g, 0.0, LOITER, false), None);
        for i in 1..20 {
            assert_eq!(f.at(&mut g, f64::from(i), LOITER, true), None);
        }
        assert_eq!(g.control, Control::Waiting);
    }

    #[test]
    fn with_start_on_arm_every_heartbeat_armed_for_two_seconds_requests_a_start_once() {
        let mut g = OperatorGate::new(false);
        g.start_on_arm = true;
        let mut f = Feed::new();
        assert_eq!(f.at(&mut g, 1.0, STABILIZE, false), None);
        assert_eq!(f.at(&mut g, 2.0, STABILIZE, true), None);
        assert_eq!(
            f.at(&mut g, 3.0, STABILIZE, true),
            None,
            "two heartbeats, 1 s"
        );
        assert_eq!(
            f.look(&mut g, 4.0),
            Some(GateEvent::StartRequested(StartBy::PilotArmed))
        );
        assert_eq!(f.look(&mut g, 4.1), None, "one request per arming");
        let ev = g.refuse(StartBy::PilotArmed, "battery 12%");
        assert!(matches!(ev, GateEvent::StartRefused(..)));
        assert_eq!(
            f.at(&mut g, 5.0, STABILIZE, true),
            None,
            "refused: not asked again"
        );
        // Disarm and arm again: a new operator action.
        assert_eq!(f.at(&mut g, 6.0, STABILIZE, false), None);
        assert_eq!(f.at(&mut g, 7.0, STABILIZE, true), None);
        assert_eq!(
            f.at(&mut g, 9.0, STABILIZE, true),
            Some(GateEvent::StartRequested(StartBy::PilotArmed))
        );
    }

    #[test]
    fn two_back_to_back_spoofed_armed_heartbeats_request_nothing() {
        let mut g = OperatorGate::new(false);
        g.start_on_arm = true;
        let mut f = Feed::new();
        let mut t = 0.0;
        for _ in 0..10 {
            assert_eq!(f.at(&mut g, t, STABILIZE, false), None);
            // two spoofed frames in one write, then the real disarmed heartbeat a second later
            assert_eq!(f.at(&mut g, t + 0.3, STABILIZE, true), None);
            assert_eq!(f.at(&mut g, t + 0.3, STABILIZE, true), None);
            assert_eq!(f.look(&mut g, t + 0.9), None);
            t += 1.0;
        }
        assert_eq!(g.control, Control::Waiting);
    }

    #[test]
    fn guided_switch_of_an_armed_vehicle_requests_a_start_after_two_seconds() {
        let mut g = OperatorGate::new(false);
        let mut f = Feed::new();
        f.at(&mut g, 0.0, LOITER, false);
        f.at(&mut g, 1.0, LOITER, true);
        assert_eq!(f.at(&mut g, 2.0, GUIDED, true), None);
        assert_eq!(f.at(&mut g, 3.0, GUIDED, true), None);
        assert_eq!(
            f.at(&mut g, 4.0, GUIDED, true),
            Some(GateEvent::StartRequested(StartBy::GuidedSwitch))
        );
        assert_eq!(f.at(&mut g, 5.0, GUIDED, true), None, "once per switch");
    }

    #[test]
    fn a_guided_heartbeat_among_real_loiter_ones_is_no_start_and_no_hand_back() {
        for taken_over in [false, true] {
            let mut g = OperatorGate::new(false);
            if taken_over {
                g.control = Control::TakenOver {
                    mode: "LOITER".into(),
                };
            }
            let mut f = Feed::new();
            f.at(&mut g, 0.0, LOITER, true);
            for i in 1..10 {
                let t = f64::from(i);
                assert_eq!(f.at(&mut g, t, LOITER, true), None);
                assert_eq!(f.at(&mut g, t + 0.5, GUIDED, true), None, "spoofed");
                assert_eq!(f.look(&mut g, t + 0.9), None);
            }
            assert!(!g.commanding());
        }
    }

    #[test]
    fn a_mode_change_on_the_ground_disarmed_is_not_a_takeover() {
        // ArduCopter SITL: GUIDED accepted, then STABILIZE from the RC mode switch, disarmed.
        let mut g = OperatorGate::started();
        let mut f = Feed::new();
        f.cmds = vec![("GUIDED".to_string(), s(1.0))];
        assert_eq!(f.at(&mut g, 1.0, STABILIZE, false), None);
        assert_eq!(f.at(&mut g, 1.5, GUIDED, false), None);
        assert_eq!(f.at(&mut g, 9.0, STABILIZE, false), None);
        assert!(g.commanding());
        // Armed, the same change is the pilot's (suspected at once).
        assert_eq!(f.at(&mut g, 20.0, GUIDED, true), None);
        assert_eq!(
            f.at(&mut g, 30.0, STABILIZE, true),
            Some(GateEvent::TakeoverSuspected("STABILIZE".into()))
        );
    }

    #[test]
    fn start_command_requests_and_hands_back() {
        let mut g = OperatorGate::new(false);
        assert_eq!(
            g.on_start_command(),
            Some(GateEvent::StartRequested(StartBy::StartCommand))
        );
        assert_eq!(g.control, Control::Waiting, "only a request");
        assert_eq!(
            g.grant(StartBy::StartCommand),
            GateEvent::Started(StartBy::StartCommand)
        );
        assert_eq!(g.on_start_command(), None, "already started");
        g.control = Control::TakenOver {
            mode: "LOITER".into(),
        };
        assert_eq!(
            g.on_start_command(),
            Some(GateEvent::HandedBack(StartBy::StartCommand))
        );
    }

    #[test]
    fn a_takeover_stops_at_once_and_is_confirmed_after_two_seconds_of_heartbeats() {
        let mut g = OperatorGate::started();
        let mut f = Feed::new();
        f.airborne = true;
        f.cmds = vec![
            ("GUIDED".to_string(), s(1.0)),
            ("AUTO".to_string(), s(10.0)),
        ];
        assert_eq!(f.at(&mut g, 10.5, AUTO, true), None);
        assert!(g.commanding());
        assert_eq!(
            f.at(&mut g, 30.0, LOITER, true),
            Some(GateEvent::TakeoverSuspected("LOITER".into()))
        );
        assert!(!g.commanding(), "commanding stops at once");
        assert_eq!(f.at(&mut g, 31.0, LOITER, true), None);
        assert_eq!(
            f.at(&mut g, 32.0, LOITER, true),
            Some(GateEvent::TakenOver("LOITER".into()))
        );
        // The pilot moves on to LAND: still theirs.
        assert_eq!(f.at(&mut g, 33.0, LAND, true), None);
        assert_eq!(
            g.control,
            Control::TakenOver {
                mode: "LAND".into()
            }
        );
        // Switching to GUIDED and staying there hands control back.
        assert_eq!(f.at(&mut g, 40.0, GUIDED, true), None);
        assert_eq!(f.at(&mut g, 41.0, GUIDED, true), None);
        assert_eq!(
            f.at(&mut g, 42.0, GUIDED, true),
            Some(GateEvent::HandedBack(StartBy::GuidedSwitch))
        );
        assert!(g.commanding());
    }

    #[test]
    fn one_spoofed_loiter_heartbeat_is_a_false_alarm_and_commanding_resumes() {
        let mut g = OperatorGate::started();
        let mut f = Feed::new();
        f.airborne = true;
        f.cmds = vec![("AUTO".to_string(), s(10.0))];
        assert_eq!(f.at(&mut g, 20.0, AUTO, true), None);
        assert_eq!(
            f.at(&mut g, 20.4, LOITER, true),
            Some(GateEvent::TakeoverSuspected("LOITER".into()))
        );
        assert_eq!(f.look(&mut g, 20.9), None);
        assert_eq!(
            f.at(&mut g, 21.0, AUTO, true),
            Some(GateEvent::FalseAlarm("LOITER".into(), "AUTO".into()))
        );
        assert!(g.commanding());
    }

    #[test]
    fn a_late_heartbeat_of_an_earlier_command_is_not_a_takeover() {
        let mut g = OperatorGate::started();
        let mut f = Feed::new();
        // AUTO commanded at 5 s, GUIDED at 6 s; the heartbeat showing AUTO arrives at 6.5 s.
        f.cmds = vec![("AUTO".to_string(), s(5.0)), ("GUIDED".to_string(), s(6.0))];
        f.at(&mut g, 4.0, GUIDED, true);
        assert_eq!(f.at(&mut g, 6.5, AUTO, true), None);
        assert_eq!(f.at(&mut g, 7.0, GUIDED, true), None);
        assert!(g.commanding());
    }

    #[test]
    fn a_disarm_before_airborne_voids_the_start_and_nothing_restarts_it() {
        let mut g = OperatorGate::new(false);
        g.start_on_arm = true;
        let mut f = Feed::new();
        f.at(&mut g, 0.0, STABILIZE, false);
        f.at(&mut g, 1.0, STABILIZE, true);
        f.at(&mut g, 2.0, STABILIZE, true);
        assert_eq!(
            f.at(&mut g, 3.0, STABILIZE, true),
            Some(GateEvent::StartRequested(StartBy::PilotArmed))
        );
        g.grant(StartBy::PilotArmed);
        assert_eq!(f.at(&mut g, 4.0, STABILIZE, true), None);
        // ArduCopter's DISARM_DELAY: disarmed on the ground.
        assert_eq!(
            f.at(&mut g, 12.0, STABILIZE, false),
            Some(GateEvent::StartVoided(VoidReason::Disarmed))
        );
        assert_eq!(g.control, Control::Waiting);
        for i in 13..80 {
            assert_eq!(f.at(&mut g, f64::from(i), STABILIZE, false), None);
        }
        assert!(!g.commanding());
    }

    #[test]
    fn a_failed_take_off_voids_only_before_airborne() {
        let mut g = OperatorGate::started();
        assert_eq!(
            g.takeoff_failed(false, "SET_MODE GUIDED: DENIED"),
            Some(GateEvent::StartVoided(VoidReason::TakeoffFailed(
                "SET_MODE GUIDED: DENIED".into()
            )))
        );
        assert!(!g.commanding());
        let mut g = OperatorGate::started();
        assert_eq!(g.takeoff_failed(true, "x"), None);
        assert!(g.commanding());
    }

    #[test]
    fn auto_start_is_requested_until_granted_then_never_again() {
        let mut g = OperatorGate::new(true);
        let mut f = Feed::new();
        assert_eq!(
            f.at(&mut g, 0.0, STABILIZE, false),
            Some(GateEvent::StartRequested(StartBy::AutoStart))
        );
        g.refuse(StartBy::AutoStart, "energy short");
        assert_eq!(
            f.at(&mut g, 1.0, STABILIZE, false),
            Some(GateEvent::StartRequested(StartBy::AutoStart))
        );
        g.grant(StartBy::AutoStart);
        g.new_flight();
        assert_eq!(f.at(&mut g, 2.0, STABILIZE, false), None);
    }

    #[test]
    fn armed_before_waiting_is_not_a_start_until_seen_disarmed() {
        let mut g = OperatorGate::new(false);
        g.start_on_arm = true;
        g.new_flight();
        let mut f = Feed::new();
        assert_eq!(f.at(&mut g, 1.0, LAND, true), None);
        assert_eq!(f.at(&mut g, 5.0, LAND, true), None);
        assert_eq!(f.at(&mut g, 6.0, LAND, false), None);
        f.at(&mut g, 7.0, LAND, true);
        assert_eq!(
            f.at(&mut g, 9.0, LAND, true),
            Some(GateEvent::StartRequested(StartBy::PilotArmed))
        );
    }

    #[test]
    fn statustext_is_rate_limited_per_text_and_per_second() {
        let mut t = GcsText::new(Duration::from_secs(10), 2);
        let sev = MavSeverity::MAV_SEVERITY_INFO;
        assert_eq!(t.say(s(0.0), sev, "a").len(), 1);
        assert!(t.say(s(1.0), sev, "a").is_empty(), "same text within 10 s");
        assert_eq!(t.say(s(1.1), sev, "b").len(), 1);
        assert_eq!(t.say(s(1.2), sev, "c").len(), 1);
        assert!(
            t.say(s(1.3), sev, "d").is_empty(),
            "third text in one second"
        );
        assert_eq!(t.dropped, 1);
        assert_eq!(t.say(s(2.5), sev, "d").len(), 1);
        assert_eq!(
            t.say(s(10.5), sev, "a").len(),
            1,
            "after the repeat interval"
        );
    }

    /// (id, chunk_seq, text) of each STATUSTEXT.
    fn parts(msgs: &[Msg]) -> Vec<(u16, u8, String)> {
        msgs.iter()
            .map(|m| match m {
                Msg::STATUSTEXT(st) => (st.id, st.chunk_seq, st.text.to_str().unwrap().to_string()),
                other => panic!("{other:?}"),
            })
            .collect()
    }

    /// A receiver's join, as the MAVLink spec describes it: chunks of one non-zero id in
    /// chunk_seq order, complete at the first chunk shorter than 50 bytes.
    fn joined(parts: &[(u16, u8, String)]) -> String {
        let id = parts[0].0;
        let mut text = String::new();
        for (i, (pid, seq, t)) in parts.iter().enumerate() {
            assert_eq!((*pid, *seq as usize), (id, i), "{parts:?}");
            text.push_str(t);
            if t.len() < 50 {
                assert_eq!(i, parts.len() - 1, "a short chunk ends the text: {parts:?}");
            }
        }
        assert!(
            parts.last().unwrap().2.len() < 50,
            "the last chunk ends the text: {parts:?}"
        );
        text
    }

    #[test]
    fn a_short_text_is_one_statustext_with_id_zero() {
        let mut t = GcsText::new(Duration::from_secs(10), 2);
        let sev = MavSeverity::MAV_SEVERITY_NOTICE;
        let fifty = "y".repeat(50);
        assert_eq!(
            parts(&t.say(s(0.0), sev, "Battery 7%: returning home")),
            vec![(0, 0, "Battery 7%: returning home".to_string())]
        );
        assert_eq!(
            parts(&t.say(s(2.0), sev, &fifty)),
            vec![(0, 0, fifty.clone())]
        );
    }

    #[test]
    fn a_long_text_goes_out_whole_in_chunks_sharing_a_new_id() {
        let mut t = GcsText::new(Duration::from_secs(10), 2);
        let sev = MavSeverity::MAV_SEVERITY_WARNING;
        let long = "Cannot meet goals: energy short 4.2 kJ, time short 35 s, lidar failed";
        let first = parts(&t.say(s(0.0), sev, long));
        assert_eq!(first.len(), 2, "{first:?}");
        assert_ne!(first[0].0, 0, "chunks carry a non-zero id");
        assert_eq!(joined(&first), long);
        // Exactly two chunks' worth: an empty third chunk ends it.
        let hundred: String = ('a'..='z').cycle().take(100).collect();
        let second = parts(&t.say(s(2.0), sev, &hundred));
        assert_eq!(second.len(), 3, "{second:?}");
        assert_eq!(second[2].2, "");
        assert_eq!(joined(&second), hundred);
        assert_ne!(second[0].0, first[0].0, "each long text has its own id");
        // Longer than the chunks allow: cut, still ended by a short chunk.
        let huge = "z".repeat(500);
        let third = parts(&t.say(s(4.0), sev, &huge));
        assert_eq!(third.len(), MAX_CHUNKS);
        assert_eq!(joined(&third), "z".repeat(MAX_CHUNKS * 50 - 1));
    }

    #[test]
    fn the_chunks_of_one_text_count_once_against_the_rate() {
        let mut t = GcsText::new(Duration::from_secs(10), 1);
        let sev = MavSeverity::MAV_SEVERITY_INFO;
        assert_eq!(t.say(s(0.0), sev, &"q".repeat(120)).len(), 3);
        assert!(t.say(s(0.5), sev, "next").is_empty());
        assert_eq!(t.dropped, 1);
    }

    #[test]
    fn non_ascii_and_control_characters_never_break_a_chunk() {
        let mut t = GcsText::new(Duration::from_secs(10), 2);
        let sev = MavSeverity::MAV_SEVERITY_INFO;
        let text = format!("{}\n{}", "é".repeat(30), "ü".repeat(40));
        let got = parts(&t.say(s(0.0), sev, &text));
        assert_eq!(joined(&got), "?".repeat(70));
    }
}
