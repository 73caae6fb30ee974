//! The stop in the shell (a signal, the end of `--duration`, the caller's stop, a fatal error):
//! what it tells the ground station, the journal and the record, and whether it hands the
//! vehicle to the autopilot. The decision is [`companion_link::vehicle::stop_verdict`] on the
//! conservative reading of the vehicle: the companion's own ARM or take-off not refused, or any
//! frame that said armed or airborne, is a vehicle to hand off (see
//! `companion_link::vehicle::launch`).

use super::{NOTICE, Shell};
use companion_core::record::Event;
use companion_link::Msg;
use companion_link::actions::Handoff;
use companion_link::dialect::MavSeverity;
use companion_link::operator::Control;
use companion_link::vehicle::{LaunchOutcome, StopVerdict, Vehicle, stop_verdict};
use std::time::Duration;

const CRITICAL: MavSeverity = MavSeverity::MAV_SEVERITY_CRITICAL;

/// What the stop did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Stopped {
    /// A hand-off mode was commanded (its answer is awaited, then [`end_stop`]).
    pub commanded: bool,
    /// The vehicle counted as armed or in the air (a last record is written).
    pub up: bool,
    /// The companion was commanding (started, or a takeover not confirmed): a start in progress
    /// ends, and a last record says how.
    pub was_commanding: bool,
}

/// What the companion tells the ground station and the vehicle when it stops (`why`: the
/// signal, the end of `--duration`, the error): the hand-off from params/link.toml when the
/// verdict says the vehicle is the companion's and up, else only the words. Call it after
/// [`Vehicle::stop_commanding`] and the wait for the launch command's answer. Returns the
/// messages to send and what it did.
pub fn begin_stop(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    handoff: Handoff,
    why: &str,
    now: Duration,
    landed_confirm: Duration,
) -> (Vec<Msg>, Stopped) {
    let mut out = Vec::new();
    if vehicle.target().is_none() {
        return (out, Stopped::default());
    }
    let reading = vehicle.stop_reading(now, landed_confirm);
    let verdict = stop_verdict(&shell.operator.control, &reading);
    let was = shell.operator.control.label();
    let mode = vehicle
        .telemetry()
        .mode
        .map_or_else(|| "?".into(), |m| m.to_string());
    let alt = vehicle.telemetry().position.map(|p| p.alt_rel_m);
    let at = alt.map_or(String::new(), |a| format!(" at {a:.0} m"));
    let mut stopped = Stopped {
        commanded: false,
        up: verdict != StopVerdict::Down,
        was_commanding: matches!(
            shell.operator.control,
            Control::Started | Control::Unconfirmed { .. }
        ),
    };
    shell.operator.control = Control::Stopping;
    let (severity, text, line) = match &verdict {
        StopVerdict::HandOff(up) => {
            let up = up.join("; ");
            match handoff.mode() {
                Some(m) => {
                    out.extend(vehicle.hand_off(now, m));
                    stopped.commanded = true;
                    (
                        CRITICAL,
                        format!("Companion stopping: {}, take over", handoff.pilot_words()),
                        format!(
                            "companion stopping ({why}) while commanding the vehicle{at} in {mode}, armed or arming ({up}): hand-off {m} (params/link.toml [flight] handoff)"
                        ),
                    )
                }
                None => (
                    CRITICAL,
                    "Companion stopping: vehicle continues, take over".into(),
                    format!(
                        "companion stopping ({why}) while commanding the vehicle{at} in {mode}, armed or arming ({up}): no hand-off (handoff = none), the vehicle goes on in {mode}"
                    ),
                ),
            }
        }
        StopVerdict::NotCommanding(up) => (
            CRITICAL,
            "Companion stopping: not commanding".into(),
            format!(
                "companion stopping ({why}); the vehicle is armed or in the air{at} in {mode} ({}) and the companion was not commanding it ({was})",
                up.join("; ")
            ),
        ),
        StopVerdict::Down => {
            let refused: String = reading
                .launches
                .iter()
                .filter_map(|l| match &l.outcome {
                    LaunchOutcome::Refused(r) => Some(format!(
                        " (the autopilot refused its {}: {r})",
                        l.command.name()
                    )),
                    _ => None,
                })
                .collect();
            (
                NOTICE,
                "Companion stopping".into(),
                format!("companion stopping ({why}); the vehicle is disarmed{refused}"),
            )
        }
    };
    if severity == CRITICAL {
        tracing::warn!("{line}");
    } else {
        tracing::info!("{line}");
    }
    shell.pending_events.push(Event::Other(line.into()));
    // The stop's words go first, ahead of the mode command.
    let mut msgs = shell.texts.say_always(now, severity, &text);
    msgs.extend(out);
    (msgs, stopped)
}

/// The hand-off's outcome, for the record once it is known (or the wait ended); a refused or
/// unanswered hand-off is also said to the ground station (the pilot must take over). Returns
/// the messages to send.
pub fn end_stop(shell: &mut Shell, vehicle: &Vehicle, commanded: bool, now: Duration) -> Vec<Msg> {
    if !commanded {
        return Vec::new();
    }
    let (line, gcs) = match vehicle.handoff_status() {
        Some(true) => (
            "companion stopping: the autopilot accepted the hand-off mode",
            None,
        ),
        Some(false) => (
            "companion stopping: the hand-off mode failed (see commands); the pilot must take over",
            Some("Companion: hand-off refused, take over"),
        ),
        None => (
            "companion stopping: no answer to the hand-off mode before exit; the pilot must take over",
            Some("Companion: hand-off unanswered, take over"),
        ),
    };
    tracing::warn!("{line}");
    shell.pending_events.push(Event::Other(line.into()));
    gcs.map_or_else(Vec::new, |text| shell.texts.say_always(now, CRITICAL, text))
}

#[cfg(test)]
mod tests;
