//! What the fly shell's operator gate decided and which ground stations it heard
//! ([`OperatorEvent`], in a record's events as `Event::Operator`), with how a start came about
//! ([`StartBy`]). Written as `{"kind":"start_refused","by":"start_command","why":..,"text":..}`
//! (the fields, then the sentence for people); the sentences are the ones the gate always said.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// How a mission start or a hand-back came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
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
    /// Every way, in the order of the sentences' parsers (schema-1 migration).
    pub const ALL: [StartBy; 4] = [
        StartBy::AutoStart,
        StartBy::PilotArmed,
        StartBy::StartCommand,
        StartBy::GuidedSwitch,
    ];

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

/// The operator gate's decision, or what it heard from the ground stations (fly only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self", tag = "kind", rename_all = "snake_case")]
pub enum OperatorEvent {
    /// `operator: start requested (BY)`
    StartRequested {
        /// How the operator asked.
        by: StartBy,
    },
    /// `operator: mission started (BY)`: the companion may command from now on.
    Started {
        /// How the operator asked.
        by: StartBy,
    },
    /// `operator: start refused (BY): WHY; still waiting for the operator`
    StartRefused {
        /// How the operator asked.
        by: StartBy,
        /// The models' reason, in words.
        why: String,
    },
    /// `operator: start void: the vehicle was disarmed before it was airborne; ...`
    StartVoidedDisarmed,
    /// `operator: start void: the take-off failed before the vehicle was airborne (WHY); ...`
    StartVoidedTakeoffFailed {
        /// The step that failed and the autopilot's answer.
        why: String,
    },
    /// `operator: mode MODE was not commanded by the companion: commanding stopped until ...`
    TakeoverSuspected {
        /// The mode the autopilot reported.
        mode: String,
    },
    /// `operator: mode MODE was not commanded by the companion: the pilot or the autopilot has
    /// control; ...`
    TakenOver {
        /// The mode the pilot or the autopilot flies in.
        mode: String,
    },
    /// `operator: takeover not confirmed: MODE was reported, then ... OWN again; ...`
    FalseAlarm {
        /// The mode reported, not confirmed.
        mode: String,
        /// The companion's own mode, shown again.
        own: String,
    },
    /// `operator: control handed back (...)`
    HandedBack {
        /// How control came back (a switch to GUIDED, else MISSION_START).
        by: StartBy,
    },
    /// `operator: COMMAND from SYS/COMP refused: WHY`: a command to the companion refused
    /// before the gate decides (too old, not a ground station, the vehicle not yet known).
    CommandRefused {
        /// MAVLink command name (`MAV_CMD_MISSION_START`).
        command: String,
        /// Sender's MAVLink system id.
        system: u8,
        /// Sender's MAVLink component id.
        component: u8,
        /// Why it is refused.
        why: String,
    },
    /// `operator: a ground station SYS/COMP is heard (GCS HEARTBEAT) but --gcs-sysid names
    /// NAMED: its commands are refused, never obeyed`
    GroundStationNotNamed {
        /// MAVLink system id heard.
        system: u8,
        /// MAVLink component id heard.
        component: u8,
        /// The `--gcs-sysid` list, in words.
        named: String,
    },
    /// `link to the ground station lost`: no GCS HEARTBEAT for the ground-station timeout.
    GroundStationLost,
    /// `link to the ground station back`
    GroundStationBack,
}

impl fmt::Display for OperatorEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use OperatorEvent::*;
        match self {
            StartRequested { by } => write!(f, "operator: start requested ({})", by.describe()),
            Started { by } => write!(f, "operator: mission started ({})", by.describe()),
            StartRefused { by, why } => write!(
                f,
                "operator: start refused ({}): {why}; still waiting for the operator",
                by.describe()
            ),
            StartVoidedDisarmed => f.write_str(
                "operator: start void: the vehicle was disarmed before it was airborne; waiting for a new start",
            ),
            StartVoidedTakeoffFailed { why } => write!(
                f,
                "operator: start void: the take-off failed before the vehicle was airborne ({why}); waiting for a new start"
            ),
            TakeoverSuspected { mode } => write!(
                f,
                "operator: mode {mode} was not commanded by the companion: commanding stopped until every heartbeat confirms it or shows the companion's mode again"
            ),
            TakenOver { mode } => write!(
                f,
                "operator: mode {mode} was not commanded by the companion: the pilot or the autopilot has control; the companion stops commanding"
            ),
            FalseAlarm { mode, own } => write!(
                f,
                "operator: takeover not confirmed: {mode} was reported, then the autopilot showed the companion's {own} again; commanding resumed (false alarm)"
            ),
            HandedBack {
                by: StartBy::GuidedSwitch,
            } => f.write_str("operator: control handed back (switch to GUIDED)"),
            HandedBack { .. } => f.write_str(
                "operator: control handed back (MAV_CMD_MISSION_START from the ground station)",
            ),
            CommandRefused {
                command,
                system,
                component,
                why,
            } => write!(
                f,
                "operator: {command} from {system}/{component} refused: {why}"
            ),
            GroundStationNotNamed {
                system,
                component,
                named,
            } => write!(
                f,
                "operator: a ground station {system}/{component} is heard (GCS HEARTBEAT) but --gcs-sysid names {named}: its commands are refused, never obeyed"
            ),
            GroundStationLost => f.write_str("link to the ground station lost"),
            GroundStationBack => f.write_str("link to the ground station back"),
        }
    }
}

eq_sentence!(OperatorEvent);

/// The derived (remote = "Self") form, fields only, as a value `WithText` flattens.
struct Fields<'a>(&'a OperatorEvent);

impl Serialize for Fields<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        OperatorEvent::serialize(self.0, serializer)
    }
}

impl Serialize for OperatorEvent {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        super::wire::WithText {
            wire: Fields(self),
            text: self,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for OperatorEvent {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // `text` is the sentence for people, never read back (the derived form ignores it).
        OperatorEvent::deserialize(deserializer)
    }
}
