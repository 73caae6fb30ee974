//! How the fly shell stopped ([`StopEvent`], in a record's events as `Event::Stop`): what the
//! vehicle was doing when the companion exited and whether the autopilot took the hand-off.
//! Written as `{"kind":"hand_off","why":"SIGTERM",...,"text":..}` (the fields, then the sentence
//! for people); the sentences are the ones the shell always wrote (`companion stopping ...`).

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// The shell's stop: the verdict when the companion exits, then the hand-off's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self", tag = "kind", rename_all = "snake_case")]
pub enum StopEvent {
    /// `companion stopping (WHY) while commanding the vehicle at A m in MODE, armed or arming
    /// (UP): hand-off HANDOFF (params/link.toml [flight] handoff)`
    HandOff {
        /// Why the companion stops (`SIGTERM`, `operator stop`, ...).
        why: String,
        /// Height above home when it stopped, if known (m).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alt_m: Option<f64>,
        /// The autopilot's mode when it stopped (`?` unknown).
        mode: String,
        /// What says the vehicle is up (armed, in the air, an ARM or take-off in flight).
        up: Vec<String>,
        /// The mode commanded to hand the flight to the autopilot.
        handoff: String,
    },
    /// `companion stopping (WHY) while commanding the vehicle ...: no hand-off (handoff =
    /// none), the vehicle goes on in MODE`
    NoHandOff {
        /// Why the companion stops.
        why: String,
        /// Height above home, if known (m).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alt_m: Option<f64>,
        /// The autopilot's mode, which it keeps flying.
        mode: String,
        /// What says the vehicle is up.
        up: Vec<String>,
    },
    /// `companion stopping (WHY); the vehicle is armed or in the air at A m in MODE (UP) and
    /// the companion was not commanding it (WAS)`
    NotCommanding {
        /// Why the companion stops.
        why: String,
        /// Height above home, if known (m).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alt_m: Option<f64>,
        /// The autopilot's mode.
        mode: String,
        /// What says the vehicle is up.
        up: Vec<String>,
        /// The operator gate's state (`waiting`, `taken over`, ...).
        was: String,
    },
    /// `companion stopping (WHY); the vehicle is disarmed[ (the autopilot refused its ARM:
    /// DENIED)]`
    Down {
        /// Why the companion stops.
        why: String,
        /// Launch commands the autopilot refused: (command, its answer).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        refused: Vec<(String, String)>,
    },
    /// `companion stopping: the autopilot accepted the hand-off mode`
    HandOffAccepted,
    /// `companion stopping: the hand-off mode failed (see commands); the pilot must take over`
    HandOffFailed,
    /// `companion stopping: no answer to the hand-off mode before exit; the pilot must take over`
    HandOffUnanswered,
}

/// ` at A m`, or nothing when the height is unknown.
struct At(Option<f64>);

impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(a) => write!(f, " at {a:.0} m"),
            None => Ok(()),
        }
    }
}

/// The list joined by `; `.
struct Joined<'a>(&'a [String]);

impl fmt::Display for Joined<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, s) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("; ")?;
            }
            f.write_str(s)?;
        }
        Ok(())
    }
}

impl fmt::Display for StopEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use StopEvent::*;
        match self {
            HandOff {
                why,
                alt_m,
                mode,
                up,
                handoff,
            } => write!(
                f,
                "companion stopping ({why}) while commanding the vehicle{} in {mode}, armed or arming ({}): hand-off {handoff} (params/link.toml [flight] handoff)",
                At(*alt_m),
                Joined(up)
            ),
            NoHandOff {
                why,
                alt_m,
                mode,
                up,
            } => write!(
                f,
                "companion stopping ({why}) while commanding the vehicle{} in {mode}, armed or arming ({}): no hand-off (handoff = none), the vehicle goes on in {mode}",
                At(*alt_m),
                Joined(up)
            ),
            NotCommanding {
                why,
                alt_m,
                mode,
                up,
                was,
            } => write!(
                f,
                "companion stopping ({why}); the vehicle is armed or in the air{} in {mode} ({}) and the companion was not commanding it ({was})",
                At(*alt_m),
                Joined(up)
            ),
            Down { why, refused } => {
                write!(f, "companion stopping ({why}); the vehicle is disarmed")?;
                for (command, answer) in refused {
                    write!(f, " (the autopilot refused its {command}: {answer})")?;
                }
                Ok(())
            }
            HandOffAccepted => {
                f.write_str("companion stopping: the autopilot accepted the hand-off mode")
            }
            HandOffFailed => f.write_str(
                "companion stopping: the hand-off mode failed (see commands); the pilot must take over",
            ),
            HandOffUnanswered => f.write_str(
                "companion stopping: no answer to the hand-off mode before exit; the pilot must take over",
            ),
        }
    }
}

eq_sentence!(StopEvent);

/// The derived (remote = "Self") form, fields only, as a value `WithText` flattens.
struct Fields<'a>(&'a StopEvent);

impl Serialize for Fields<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        StopEvent::serialize(self.0, serializer)
    }
}

impl Serialize for StopEvent {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        super::wire::WithText {
            wire: Fields(self),
            text: self,
        }
        .serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for StopEvent {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        // `text` is the sentence for people, never read back (the derived form ignores it).
        StopEvent::deserialize(deserializer)
    }
}
