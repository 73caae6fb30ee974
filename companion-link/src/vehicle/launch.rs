//! What the stop reads: the companion's own last ARM or take-off and its answer, and the last
//! autopilot frame that said the vehicle was armed or in the air.
//!
//! Starting and stopping read the vehicle differently. A start needs the confirmed reading
//! (every heartbeat over a window, so a spoofed frame cannot start anything); a stop takes the
//! conservative one: the vehicle counts as up from its own ARM or take-off that was not refused,
//! or from any single frame that says armed or airborne, until every autopilot frame has agreed
//! for `landed_confirm_s` that it is disarmed on the ground. A stop inside the start's windows
//! (the ARM sent, its answer or the first armed heartbeat still on the way) would otherwise
//! leave a vehicle the companion armed to finish its take-off and hover alone.

use super::*;
use crate::operator::Control;

/// One of the companion's launch commands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaunchCommand {
    /// MAV_CMD_COMPONENT_ARM_DISARM with param1 = 1.
    Arm,
    /// A command that takes off or starts a mission that can (NAV_TAKEOFF, NAV_VTOL_TAKEOFF,
    /// MISSION_START).
    TakeOff,
}

impl LaunchCommand {
    /// The launch command `spec` is, if it is one.
    pub fn of(spec: &CommandSpec) -> Option<Self> {
        let param1 = match &spec.body {
            super::super::command::CommandBody::Long { params } => params[0],
            super::super::command::CommandBody::Int { params, .. } => params[0],
        };
        match spec.command {
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM if param1 == 1.0 => Some(Self::Arm),
            MavCmd::MAV_CMD_NAV_TAKEOFF
            | MavCmd::MAV_CMD_NAV_TAKEOFF_LOCAL
            | MavCmd::MAV_CMD_NAV_VTOL_TAKEOFF
            | MavCmd::MAV_CMD_MISSION_START => Some(Self::TakeOff),
            _ => None,
        }
    }

    /// "ARM" or "take-off", for the words.
    pub fn name(self) -> &'static str {
        match self {
            Self::Arm => "ARM",
            Self::TakeOff => "take-off",
        }
    }
}

/// What became of a launch command so far.
#[derive(Debug, Clone, PartialEq)]
pub enum LaunchOutcome {
    /// Sent; no final answer yet.
    Awaiting,
    /// ACCEPTED.
    Accepted,
    /// A final answer other than ACCEPTED (the result's name): the autopilot did not do it.
    Refused(String),
    /// No answer (timed out, or dropped unanswered): the autopilot may have done it.
    Unanswered(String),
}

/// The companion's last launch command of one kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Launch {
    /// Which.
    pub command: LaunchCommand,
    /// Its answer so far.
    pub outcome: LaunchOutcome,
    /// When it was first sent.
    pub sent_at: Duration,
    ticket: u64,
    mav_cmd: MavCmd,
}

/// What an autopilot frame said that puts the vehicle up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpEvidence {
    /// A heartbeat said armed.
    Armed,
    /// A position or landed state said in the air.
    Airborne,
}

/// The stop's reading of the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub struct StopReading {
    /// The companion's last ARM and last take-off since the vehicle was last confirmed down, in
    /// the order sent.
    pub launches: Vec<Launch>,
    /// The last frame since then that said armed or airborne.
    pub up: Option<UpEvidence>,
    /// The last heartbeat said armed.
    pub armed_now: bool,
}

impl StopReading {
    /// Why the vehicle counts as up, in words (empty: it does not).
    pub fn reasons(&self) -> Vec<String> {
        let mut why = Vec::new();
        for l in &self.launches {
            let c = l.command.name();
            match &l.outcome {
                LaunchOutcome::Refused(_) => {}
                LaunchOutcome::Accepted => why.push(format!("its {c} accepted")),
                LaunchOutcome::Awaiting => why.push(format!("its {c} unanswered")),
                LaunchOutcome::Unanswered(w) => why.push(format!("its {c} unanswered ({w})")),
            }
        }
        match self.up {
            Some(UpEvidence::Armed) => why.push("the autopilot reported it armed".into()),
            Some(UpEvidence::Airborne) => why.push("the autopilot reported it in the air".into()),
            None => {}
        }
        why
    }

    /// Armed or in the air, or about to be by the companion's own command.
    pub fn up(&self) -> bool {
        !self.reasons().is_empty()
    }
}

/// What the stop does with the vehicle.
#[derive(Debug, Clone, PartialEq)]
pub enum StopVerdict {
    /// The companion commands (or launched) a vehicle that is up: hand it to the autopilot.
    /// Why it counts as up, in words.
    HandOff(Vec<String>),
    /// The last heartbeat said armed but the pilot flies the vehicle (a confirmed takeover),
    /// or the companion never started: change nothing. Why it counts as up.
    NotCommanding(Vec<String>),
    /// Disarmed on the ground, and nothing of the companion's can have armed it; or not the
    /// companion's, and the last heartbeat said disarmed.
    Down,
}

/// The stop's decision: the conservative reading of the vehicle ([`StopReading`]) and who
/// commands it. The companion's own launch makes the vehicle its own to hand off even when the
/// gate went back to waiting (a start voided by a disarmed heartbeat that was spoofed or came
/// before the ARM); only a pilot's confirmed takeover keeps it from handing off.
pub fn stop_verdict(control: &Control, reading: &StopReading) -> StopVerdict {
    let why = reading.reasons();
    if why.is_empty() {
        return StopVerdict::Down;
    }
    let launched = reading
        .launches
        .iter()
        .any(|l| !matches!(l.outcome, LaunchOutcome::Refused(_)));
    let ours = match control {
        Control::Started | Control::Unconfirmed { .. } | Control::Stopping => true,
        // A flight found in progress was handed off (or left to its pilot) at start; the
        // companion launched nothing since, so only its own launch would make it ours.
        Control::Waiting | Control::FlightInProgress => launched,
        Control::TakenOver { .. } => false,
    };
    if ours {
        StopVerdict::HandOff(why)
    } else if reading.armed_now {
        // Nothing is commanded either way: the words follow the last heartbeat.
        StopVerdict::NotCommanding(why)
    } else {
        StopVerdict::Down
    }
}

/// The stop's memory (inside [`Vehicle`]): the companion's last ARM and last take-off command
/// with their answers so far, and the last autopilot frame that said armed or in the air.
#[derive(Debug, Clone, Default)]
pub(super) struct Launches {
    launches: Vec<Launch>,
    /// The last autopilot frame that said armed or in the air: what, and when.
    up_seen: Option<(UpEvidence, Duration)>,
}

impl Launches {
    /// A step's command went out as `ticket`: remembered when it is a launch command.
    pub(super) fn sent(
        &mut self,
        now: Duration,
        ticket: u64,
        (command, mav_cmd): (LaunchCommand, MavCmd),
    ) {
        self.launches.retain(|l| l.command != command);
        self.launches.push(Launch {
            command,
            outcome: LaunchOutcome::Awaiting,
            sent_at: now,
            ticket,
            mav_cmd,
        });
    }

    /// A command ended: the launch command's answer, if it was that.
    pub(super) fn finished(&mut self, ticket: u64, outcome: &Outcome) {
        let Some(l) = self.launches.iter_mut().find(|l| l.ticket == ticket) else {
            return;
        };
        l.outcome = match outcome {
            Outcome::Acked => LaunchOutcome::Accepted,
            Outcome::Failed(FailReason::Timeout) => LaunchOutcome::Unanswered("no answer".into()),
            Outcome::Failed(FailReason::Cancelled(why)) => LaunchOutcome::Unanswered(why.clone()),
            Outcome::Failed(_) => LaunchOutcome::Refused(outcome.label().to_string()),
        };
    }

    /// An autopilot frame said the vehicle is armed or in the air.
    pub(super) fn note_up(&mut self, now: Duration, what: UpEvidence) {
        self.up_seen = Some((what, now));
    }

    /// A launch command still waits for its answer.
    pub(super) fn awaiting(&self) -> bool {
        self.launches
            .iter()
            .any(|l| l.outcome == LaunchOutcome::Awaiting)
    }

    /// The launch commands still waiting for their answer: ticket and command.
    pub(super) fn awaiting_commands(&self) -> Vec<(u64, MavCmd)> {
        self.launches
            .iter()
            .filter(|l| l.outcome == LaunchOutcome::Awaiting)
            .map(|l| (l.ticket, l.mav_cmd))
            .collect()
    }

    /// The stop's conservative reading at `now` (see [`Vehicle::stop_reading`]): `down_since`
    /// is when every autopilot frame began to agree that the vehicle is down, `armed_now` what
    /// the last heartbeat said.
    pub(super) fn reading(
        &self,
        now: Duration,
        landed_confirm: Duration,
        down_since: Option<Duration>,
        armed_now: bool,
    ) -> StopReading {
        let down_since = down_since.filter(|&d| now.saturating_sub(d) >= landed_confirm);
        let since_down = |t: Duration| down_since.is_none_or(|d| t > d);
        StopReading {
            launches: self
                .launches
                .iter()
                .filter(|l| since_down(l.sent_at))
                .cloned()
                .collect(),
            // Every frame that says up resets `down_since`: one seen is newer than it.
            up: self
                .up_seen
                .filter(|_| down_since.is_none())
                .map(|(w, _)| w),
            armed_now,
        }
    }
}

#[cfg(test)]
mod tests;
