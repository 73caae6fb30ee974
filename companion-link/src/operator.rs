//! The operator in command, sans IO: who may start the mission, when a pilot has taken over, and
//! what the companion tells the ground station.
//!
//! `fly` connects, streams, decides and logs from the start, but commands no motion until the
//! operator starts the mission: the pilot arms the vehicle (RC or GCS), or a ground station sends
//! MAV_CMD_MISSION_START addressed to this companion (component 191). A mode change the companion
//! did not command (the pilot switches to LOITER, POSHOLD, RTL, LAND, ..., or an autopilot
//! failsafe does) stops its commanding until the operator hands control back: the start command
//! again, or (ArduPilot) a switch to GUIDED. docs/mavlink.md, "Operator in command".
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
    /// A mode the companion did not command (`mode`): the pilot or the autopilot flies.
    TakenOver {
        /// Name of the mode the autopilot reported.
        mode: String,
    },
}

impl Control {
    /// The decision record's `vehicle.operator` value: `waiting`, `started` or `taken_over`.
    pub fn label(&self) -> &'static str {
        match self {
            Control::Waiting => "waiting",
            Control::Started => "started",
            Control::TakenOver { .. } => "taken_over",
        }
    }
}

/// How a mission start or a hand-back came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StartBy {
    /// `fly --auto-start`: no operator.
    AutoStart,
    /// The pilot armed the vehicle.
    PilotArmed,
    /// MAV_CMD_MISSION_START from the ground station.
    StartCommand,
    /// The pilot switched to GUIDED (hand-back only).
    GuidedSwitch,
}

/// What the gate decided on one observation.
#[derive(Debug, Clone, PartialEq)]
pub enum GateEvent {
    /// The companion may command from now on.
    Started(StartBy),
    /// A mode the companion did not command (its name): the companion stops commanding.
    TakenOver(String),
    /// Control came back to the companion after a take-over.
    HandedBack(StartBy),
}

impl GateEvent {
    /// The decision record's event text.
    pub fn describe(&self) -> String {
        match self {
            GateEvent::Started(StartBy::AutoStart) => {
                "operator: mission started by --auto-start (no operator)".into()
            }
            GateEvent::Started(StartBy::PilotArmed) => {
                "operator: mission started (the pilot armed the vehicle)".into()
            }
            GateEvent::Started(_) => {
                "operator: mission started (MAV_CMD_MISSION_START from the ground station)".into()
            }
            GateEvent::TakenOver(m) => format!(
                "operator: mode {m} was not commanded by the companion: the pilot or the autopilot has control; the companion stops commanding"
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
    /// Modes the companion commanded, with the time it sent each (newest last).
    pub commanded_modes: &'a [(String, Duration)],
}

/// The operator gate: one per `fly` run; [`OperatorGate::new_flight`] after each landing.
#[derive(Debug, Clone)]
pub struct OperatorGate {
    /// Who commands the vehicle now.
    pub control: Control,
    /// A mode change to a mode commanded less than this long ago is the companion's own.
    pub grace: Duration,
    /// Armed reported by this many consecutive heartbeats starts the mission (one spoofed or
    /// corrupt heartbeat cannot).
    pub armed_heartbeats_to_start: u32,
    last_custom_mode: Option<u32>,
    /// The vehicle was seen disarmed since the gate began waiting: only then is arming the
    /// pilot's start (a companion started next to a vehicle already flying does not take it).
    seen_disarmed: bool,
}

impl OperatorGate {
    /// `auto_start`: start at once (SITL and tests), as the first [`GateEvent`] of the run.
    pub fn new(auto_start: bool) -> Self {
        Self {
            control: if auto_start {
                Control::Started
            } else {
                Control::Waiting
            },
            grace: Duration::from_secs(5),
            armed_heartbeats_to_start: 2,
            last_custom_mode: None,
            seen_disarmed: false,
        }
    }

    /// The companion may command motion now.
    pub fn commanding(&self) -> bool {
        self.control == Control::Started
    }

    /// Back to waiting for the operator (after a flight ended landed and disarmed).
    pub fn new_flight(&mut self) {
        self.control = Control::Waiting;
        self.seen_disarmed = false;
    }

    /// A MAV_CMD_MISSION_START addressed to us. Returns the event (a start or a hand-back).
    pub fn on_start_command(&mut self) -> Option<GateEvent> {
        match self.control {
            Control::Waiting => {
                self.control = Control::Started;
                Some(GateEvent::Started(StartBy::StartCommand))
            }
            Control::TakenOver { .. } => {
                self.control = Control::Started;
                Some(GateEvent::HandedBack(StartBy::StartCommand))
            }
            Control::Started => None,
        }
    }

    /// One look at the vehicle: a pilot's arming starts the mission; a mode change the companion
    /// did not command is a takeover; GUIDED (ArduPilot) hands control back.
    pub fn observe(&mut self, now: Duration, v: &VehicleView) -> Option<GateEvent> {
        if v.armed_heartbeats == 0 && v.mode.is_some() {
            self.seen_disarmed = true;
        }
        let changed = v.mode.is_some() && self.last_custom_mode != Some(v.custom_mode);
        let first_mode = self.last_custom_mode.is_none();
        if v.mode.is_some() {
            self.last_custom_mode = Some(v.custom_mode);
        }
        match &self.control {
            Control::Waiting => {
                if v.armed_heartbeats >= self.armed_heartbeats_to_start && self.seen_disarmed {
                    self.control = Control::Started;
                    return Some(GateEvent::Started(StartBy::PilotArmed));
                }
                None
            }
            Control::Started => {
                if !changed || first_mode {
                    return None;
                }
                // Disarmed, nothing moves: a mode change on the ground (ArduCopter reads the RC
                // mode switch at start-up and leaves GUIDED for it) takes no flight from the
                // companion. Its take-off arms only in the mode it set (the vehicle's ARM step).
                if v.armed_heartbeats == 0 {
                    return None;
                }
                if self.is_own_mode(now, v) {
                    return None;
                }
                let name = v.mode.unwrap_or("?").to_string();
                self.control = Control::TakenOver { mode: name.clone() };
                Some(GateEvent::TakenOver(name))
            }
            Control::TakenOver { .. } => {
                if changed
                    && v.flavor == Flavor::ArduPilot
                    && modes::is_in_mode(v.flavor, v.custom_mode, "GUIDED")
                    && !self.is_own_mode(now, v)
                {
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

    fn view<'a>(
        mode: u32,
        name: &'a str,
        armed_hb: u32,
        cmds: &'a [(String, Duration)],
    ) -> VehicleView<'a> {
        VehicleView {
            flavor: Flavor::ArduPilot,
            custom_mode: mode,
            mode: Some(name),
            armed_heartbeats: armed_hb,
            commanded_modes: cmds,
        }
    }

    #[test]
    fn waits_until_the_pilot_arms_in_two_heartbeats() {
        let mut g = OperatorGate::new(false);
        assert!(!g.commanding());
        assert_eq!(g.observe(s(1.0), &view(0, "STABILIZE", 0, &[])), None);
        // One heartbeat saying armed (spoofed or a glitch) is not a start.
        assert_eq!(g.observe(s(2.0), &view(0, "STABILIZE", 1, &[])), None);
        assert!(!g.commanding());
        assert_eq!(
            g.observe(s(3.0), &view(0, "STABILIZE", 2, &[])),
            Some(GateEvent::Started(StartBy::PilotArmed))
        );
        assert!(g.commanding());
    }

    #[test]
    fn a_mode_change_on_the_ground_disarmed_is_not_a_takeover() {
        // ArduCopter SITL: GUIDED accepted, then STABILIZE from the RC mode switch, disarmed.
        let mut g = OperatorGate::new(true);
        let cmds = vec![("GUIDED".to_string(), s(1.0))];
        assert_eq!(g.observe(s(1.0), &view(0, "STABILIZE", 0, &cmds)), None);
        assert_eq!(g.observe(s(1.5), &view(GUIDED, "GUIDED", 0, &cmds)), None);
        assert_eq!(g.observe(s(9.0), &view(0, "STABILIZE", 0, &cmds)), None);
        assert!(g.commanding());
        // Armed, the same change is the pilot's.
        assert_eq!(g.observe(s(20.0), &view(GUIDED, "GUIDED", 2, &cmds)), None);
        assert_eq!(
            g.observe(s(30.0), &view(0, "STABILIZE", 2, &cmds)),
            Some(GateEvent::TakenOver("STABILIZE".into()))
        );
    }

    #[test]
    fn start_command_starts_and_hands_back() {
        let mut g = OperatorGate::new(false);
        assert_eq!(
            g.on_start_command(),
            Some(GateEvent::Started(StartBy::StartCommand))
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
    fn a_mode_the_companion_did_not_command_is_a_takeover() {
        let mut g = OperatorGate::new(true);
        let cmds = vec![("GUIDED".to_string(), s(1.0))];
        assert_eq!(g.observe(s(1.0), &view(0, "STABILIZE", 2, &cmds)), None);
        assert_eq!(g.observe(s(1.5), &view(GUIDED, "GUIDED", 2, &cmds)), None);
        let cmds = vec![
            ("GUIDED".to_string(), s(1.0)),
            ("AUTO".to_string(), s(10.0)),
        ];
        assert_eq!(g.observe(s(10.5), &view(AUTO, "AUTO", 2, &cmds)), None);
        assert!(g.commanding());
        assert_eq!(
            g.observe(s(30.0), &view(LOITER, "LOITER", 2, &cmds)),
            Some(GateEvent::TakenOver("LOITER".into()))
        );
        assert!(!g.commanding());
        // The pilot moves on to LAND: still theirs.
        assert_eq!(g.observe(s(31.0), &view(LAND, "LAND", 2, &cmds)), None);
        assert_eq!(
            g.control,
            Control::TakenOver {
                mode: "LAND".into()
            }
        );
        // Switching to GUIDED hands control back.
        assert_eq!(
            g.observe(s(40.0), &view(GUIDED, "GUIDED", 2, &cmds)),
            Some(GateEvent::HandedBack(StartBy::GuidedSwitch))
        );
        assert!(g.commanding());
    }

    #[test]
    fn a_late_heartbeat_of_an_earlier_command_is_not_a_takeover() {
        let mut g = OperatorGate::new(true);
        // AUTO commanded at 5 s, GUIDED at 6 s; the heartbeat showing AUTO arrives at 6.5 s.
        let cmds = vec![("AUTO".to_string(), s(5.0)), ("GUIDED".to_string(), s(6.0))];
        g.observe(s(4.0), &view(GUIDED, "GUIDED", 2, &cmds));
        assert_eq!(g.observe(s(6.5), &view(AUTO, "AUTO", 2, &cmds)), None);
        assert_eq!(g.observe(s(7.0), &view(GUIDED, "GUIDED", 2, &cmds)), None);
        assert!(g.commanding());
    }

    #[test]
    fn armed_before_waiting_is_not_a_start_until_seen_disarmed() {
        let mut g = OperatorGate::new(false);
        g.new_flight();
        assert_eq!(g.observe(s(1.0), &view(LAND, "LAND", 5, &[])), None);
        assert_eq!(g.observe(s(2.0), &view(LAND, "LAND", 0, &[])), None);
        assert_eq!(
            g.observe(s(3.0), &view(LAND, "LAND", 2, &[])),
            Some(GateEvent::Started(StartBy::PilotArmed))
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
