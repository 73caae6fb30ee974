//! The stop in the shell (a signal, the end of `--duration`, the caller's stop, a fatal error):
//! what it tells the ground station, the journal and the record, and whether it hands the
//! vehicle to the autopilot. The decision is [`companion_link::vehicle::stop_verdict`] on the
//! conservative reading of the vehicle: the companion's own ARM or take-off not refused, or any
//! frame that said armed or airborne, is a vehicle to hand off (see
//! `companion_link::vehicle::launch`).

use super::{NOTICE, Shell};
use companion_core::record::{Event, StopEvent};
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
    let alt_m = vehicle.telemetry().position.map(|p| p.alt_rel_m);
    let mut stopped = Stopped {
        commanded: false,
        up: verdict != StopVerdict::Down,
        was_commanding: matches!(
            shell.operator.control,
            Control::Started | Control::Unconfirmed { .. }
        ),
    };
    shell.operator.control = Control::Stopping;
    let why = why.to_string();
    let (severity, text, event) = match verdict {
        StopVerdict::HandOff(up) => match handoff.mode() {
            Some(m) => {
                out.extend(vehicle.hand_off(now, m));
                stopped.commanded = true;
                (
                    CRITICAL,
                    format!("Companion stopping: {}, take over", handoff.pilot_words()),
                    StopEvent::HandOff {
                        why,
                        alt_m,
                        mode,
                        up,
                        handoff: m.to_string(),
                    },
                )
            }
            None => (
                CRITICAL,
                "Companion stopping: vehicle continues, take over".into(),
                StopEvent::NoHandOff {
                    why,
                    alt_m,
                    mode,
                    up,
                },
            ),
        },
        StopVerdict::NotCommanding(up) => (
            CRITICAL,
            "Companion stopping: not commanding".into(),
            StopEvent::NotCommanding {
                why,
                alt_m,
                mode,
                up,
                was: was.to_string(),
            },
        ),
        StopVerdict::Down => {
            let refused = reading
                .launches
                .iter()
                .filter_map(|l| match &l.outcome {
                    LaunchOutcome::Refused(r) => {
                        Some((l.command.name().to_string(), r.to_string()))
                    }
                    _ => None,
                })
                .collect();
            (
                NOTICE,
                "Companion stopping".into(),
                StopEvent::Down { why, refused },
            )
        }
    };
    if severity == CRITICAL {
        tracing::warn!("{event}");
    } else {
        tracing::info!("{event}");
    }
    shell.pending_events.push(Event::Stop(event));
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
    let (event, gcs) = match vehicle.handoff_status() {
        Some(true) => (StopEvent::HandOffAccepted, None),
        Some(false) => (
            StopEvent::HandOffFailed,
            Some("Companion: hand-off refused, take over"),
        ),
        None => (
            StopEvent::HandOffUnanswered,
            Some("Companion: hand-off unanswered, take over"),
        ),
    };
    tracing::warn!("{event}");
    shell.pending_events.push(Event::Stop(event));
    gcs.map_or_else(Vec::new, |text| shell.texts.say_always(now, CRITICAL, text))
}

#[cfg(test)]
mod tests;
