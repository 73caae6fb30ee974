//! The operator gate in the shell: who sent a command addressed to the companion and how old it
//! is, a start granted only when the models agree (the launch verdict, [`companion_core::launch::verdict`]), a
//! start voided by a failed take-off, and what each gate decision tells the record, the journal
//! and the ground station. The gate's own state machine is [`companion_link::operator`].

use super::{NOTICE, Shell, WARNING};
use companion_core::launch::LaunchRefusal;
use companion_core::record::Event;
use companion_link::Msg;
use companion_link::dialect::{MavResult, MavSeverity};
use companion_link::operator::{self, GateEvent, StartBy, VehicleView};
use companion_link::vehicle::{AUTOPILOT_COMPONENT, CommandToUs, Vehicle};
use std::collections::BTreeSet;
use std::time::Duration;

const CRITICAL: MavSeverity = MavSeverity::MAV_SEVERITY_CRITICAL;

/// Ground stations the companion takes a start from: systems heard sending a GCS HEARTBEAT on
/// the autopilot link, and those `--gcs-sysid` names.
#[derive(Debug, Default, Clone)]
pub struct GroundStations {
    /// `--gcs-sysid`.
    pub pinned: BTreeSet<u8>,
    /// Heard sending a HEARTBEAT with MAV_TYPE_GCS.
    pub heard: BTreeSet<u8>,
}

impl GroundStations {
    /// A frame from the autopilot link: a GCS HEARTBEAT makes its system a ground station
    /// (at most 16 kept: a flood of invented systems cannot grow it).
    pub fn on_frame(&mut self, f: &companion_link::ingest::Frame) {
        if let Msg::HEARTBEAT(h) = &f.msg
            && h.mavtype == companion_link::dialect::MavType::MAV_TYPE_GCS
            && self.heard.len() < 16
        {
            self.heard.insert(f.header.system_id.min(255) as u8);
        }
    }

    fn knows(&self, system: u8) -> bool {
        self.pinned.contains(&system) || self.heard.contains(&system)
    }
}

/// Why a command addressed to us is refused before the gate sees it, or None.
fn command_refusal(
    cmd: &CommandToUs,
    now: Duration,
    max_age: Duration,
    vehicle: &Vehicle,
    gcs: &GroundStations,
) -> Option<(MavResult, String, &'static str)> {
    let (sys, comp) = cmd.from;
    if cmd.before_autopilot {
        return Some((
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            "it arrived before the autopilot was heard".into(),
            "Start refused: autopilot not heard yet",
        ));
    }
    let age = now.saturating_sub(cmd.at);
    if age > max_age {
        return Some((
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            format!(
                "it waited {:.1} s, more than command_max_age_s {:.1} s",
                age.as_secs_f64(),
                max_age.as_secs_f64()
            ),
            "Start refused: command too old, send again",
        ));
    }
    if comp == AUTOPILOT_COMPONENT || vehicle.target == Some((sys, comp)) {
        return Some((
            MavResult::MAV_RESULT_DENIED,
            format!("the sender {sys}/{comp} is an autopilot component, not a ground station"),
            "Start refused: sender is not a ground station",
        ));
    }
    if cmd.command == operator::START_COMMAND && !gcs.knows(sys) {
        return Some((
            MavResult::MAV_RESULT_DENIED,
            format!(
                "system {sys} sent no GCS HEARTBEAT and is not named by --gcs-sysid"
            ),
            "Start refused: sender is not a ground station",
        ));
    }
    None
}

/// Answer one command addressed to the companion: the COMMAND_ACK (and the gate decision it
/// makes) into `out`. True when the gate changed (a cycle should run now).
pub fn answer_command(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    gcs: &GroundStations,
    cmd: CommandToUs,
    now: Duration,
    out: &mut Vec<Msg>,
) -> bool {
    let (sys, comp) = cmd.from;
    let name = "MAV_CMD_MISSION_START";
    let mut changed = false;
    let result = if cmd.command != operator::START_COMMAND {
        MavResult::MAV_RESULT_UNSUPPORTED
    } else if let Some((result, why, text)) =
        command_refusal(&cmd, now, shell.command_max_age, vehicle, gcs)
    {
        let line = format!("operator: {name} from {sys}/{comp} refused: {why}");
        tracing::warn!("{line}");
        shell.pending_events.push(Event::from(line));
        out.extend(shell.texts.say(now, WARNING, text));
        changed = true;
        result
    } else {
        match shell.operator.on_start_command() {
            Some(GateEvent::StartRequested(by)) => {
                changed = true;
                match request_start(shell, vehicle, by, now, out) {
                    Ok(()) => MavResult::MAV_RESULT_ACCEPTED,
                    Err(r) if matches!(&r, LaunchRefusal::NotOnGround { state, .. } if state.is_empty()) => {
                        MavResult::MAV_RESULT_TEMPORARILY_REJECTED
                    }
                    Err(_) => MavResult::MAV_RESULT_DENIED,
                }
            }
            Some(ev) => {
                on_gate_event(shell, vehicle, now, &ev, out);
                changed = true;
                MavResult::MAV_RESULT_ACCEPTED
            }
            None if shell.operator.control == operator::Control::Stopping => {
                MavResult::MAV_RESULT_DENIED
            }
            None => MavResult::MAV_RESULT_ACCEPTED, // already started
        }
    };
    tracing::info!(
        "command {:?} from {sys}/{comp} addressed to us: {result:?}",
        cmd.command
    );
    out.push(operator::ack(cmd.command, result, (sys, comp)));
    changed
}

/// A start request: granted when the latest launch verdict agrees, else refused with the
/// models' reason (in the record and the journal) and the pilot's words (STATUSTEXT). An
/// `--auto-start` request asks again every turn: its refusal is said once per reason.
pub fn request_start(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    by: StartBy,
    now: Duration,
    out: &mut Vec<Msg>,
) -> Result<(), LaunchRefusal> {
    match shell.launch.clone() {
        Ok(()) => {
            let ev = shell.operator.grant(by);
            shell.granted_at = Some(now);
            shell.refusal_told = None;
            on_gate_event(shell, vehicle, now, &ev, out);
            Ok(())
        }
        Err(refusal) => {
            let ev = shell.operator.refuse(by, &refusal.description());
            let text = refusal.pilot_text();
            if by != StartBy::AutoStart || shell.refusal_told.as_deref() != Some(&text) {
                let line = ev.describe();
                tracing::warn!("{line}");
                shell.pending_events.push(Event::from(line));
                out.extend(shell.texts.say(now, WARNING, &text));
                shell.refusal_told = Some(text);
            }
            Err(refusal)
        }
    }
}

/// One look at the vehicle for the gate: start requests, a void, a takeover and its
/// confirmation, a hand-back; and a take-off that failed before the vehicle was airborne.
/// True when the gate changed.
pub fn observe(shell: &mut Shell, vehicle: &mut Vehicle, now: Duration, out: &mut Vec<Msg>) -> bool {
    let view = VehicleView {
        flavor: vehicle.flavor,
        custom_mode: vehicle.telemetry.custom_mode,
        mode: vehicle.telemetry.mode.as_deref(),
        armed_heartbeats: vehicle.armed_heartbeats,
        armed_for: vehicle.armed_for(now),
        mode_for: vehicle.mode_for(now),
        airborne: shell.mission.flown(),
        commanded_modes: &vehicle.commanded_modes,
    };
    let mut changed = false;
    match shell.operator.observe(now, &view) {
        Some(GateEvent::StartRequested(by)) => {
            let _ = request_start(shell, vehicle, by, now, out);
            changed = true;
        }
        Some(ev) => {
            on_gate_event(shell, vehicle, now, &ev, out);
            changed = true;
        }
        None => {}
    }
    // A job that failed after the start was granted, before the vehicle was airborne: the
    // take-off failed, the start is void (never retried without a new operator action).
    if shell.operator.commanding()
        && let Some(granted) = shell.granted_at
        && let Some((action, at)) = vehicle.failed_action()
        && at >= granted
    {
        let why = format!("{action} failed");
        let airborne = shell.mission.flown();
        if let Some(ev) = shell.operator.takeoff_failed(airborne, &why) {
            on_gate_event(shell, vehicle, now, &ev, out);
            changed = true;
        }
    }
    changed
}

/// A gate decision: said in the record, the journal and to the ground station; a suspected
/// takeover or a void stops the running action at once.
pub fn on_gate_event(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    now: Duration,
    ev: &GateEvent,
    out: &mut Vec<Msg>,
) {
    let text = ev.describe();
    shell.pending_events.push(Event::from(text.as_str()));
    let said: Option<(MavSeverity, String)> = match ev {
        GateEvent::Started(_) => Some((NOTICE, "companion: mission started".to_string())),
        GateEvent::StartRequested(_) | GateEvent::StartRefused(..) => None,
        GateEvent::StartVoided(why) => {
            vehicle.stop_actions(now, "start void");
            shell.granted_at = None;
            Some((
                WARNING,
                match why {
                    operator::VoidReason::Disarmed => "Start void: disarmed before take-off".into(),
                    operator::VoidReason::TakeoffFailed(_) => "Start void: take-off failed".into(),
                },
            ))
        }
        // Safety first: commanding stops now; the ground station hears of it once confirmed.
        GateEvent::TakeoverSuspected(_) => {
            vehicle.stop_actions(now, "mode not commanded by the companion");
            None
        }
        GateEvent::TakenOver(mode) => {
            vehicle.stop_actions(now, "pilot took control");
            Some((
                WARNING,
                format!("companion: pilot has control ({mode}), standing by"),
            ))
        }
        GateEvent::FalseAlarm(mode, _) => {
            Some((WARNING, format!("Mode {mode} not confirmed: companion resumes")))
        }
        GateEvent::HandedBack(_) => Some((NOTICE, "companion: control handed back".to_string())),
    };
    if matches!(ev, GateEvent::Started(_) | GateEvent::HandedBack(_)) {
        tracing::info!("{text}");
    } else {
        tracing::warn!("{text}");
    }
    if let Some((severity, gcs)) = said {
        out.extend(shell.texts.say(now, severity, &gcs));
    }
}

/// What the companion tells the ground station and the vehicle when it stops (`why`: the
/// signal, the end of `--duration`, the error): the hand-off from params/link.toml when it
/// commands an armed vehicle, else only the words. Returns the messages to send and whether a
/// hand-off mode was commanded.
pub fn begin_stop(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    handoff: companion_link::actions::Handoff,
    why: &str,
    now: Duration,
) -> (Vec<Msg>, bool) {
    let mut out = Vec::new();
    if vehicle.target.is_none() {
        return (out, false);
    }
    let armed = vehicle.readiness.armed;
    let commanding = matches!(
        shell.operator.control,
        operator::Control::Started | operator::Control::Unconfirmed { .. }
    );
    let was = shell.operator.control.label();
    shell.operator.control = operator::Control::Stopping;
    let mode = vehicle.telemetry.mode.clone().unwrap_or_else(|| "?".into());
    let alt = vehicle.telemetry.position.map(|p| p.alt_rel_m);
    let at = alt.map_or(String::new(), |a| format!(" at {a:.0} m"));
    let mut commanded = false;
    let (severity, text, line) = if armed && commanding {
        match handoff.mode() {
            Some(m) => {
                out.extend(vehicle.hand_off(now, m));
                commanded = true;
                (
                    CRITICAL,
                    format!("Companion stopping: {}, take over", handoff.pilot_words()),
                    format!(
                        "companion stopping ({why}) while commanding the armed vehicle{at} in {mode}: hand-off {m} (params/link.toml [flight] handoff)"
                    ),
                )
            }
            None => (
                CRITICAL,
                "Companion stopping: vehicle continues, take over".into(),
                format!(
                    "companion stopping ({why}) while commanding the armed vehicle{at} in {mode}: no hand-off (handoff = none), the vehicle goes on in {mode}"
                ),
            ),
        }
    } else if armed {
        (
            CRITICAL,
            "Companion stopping: not commanding".into(),
            format!(
                "companion stopping ({why}); the vehicle is armed{at} in {mode} and the companion was not commanding it ({was})"
            ),
        )
    } else {
        (
            NOTICE,
            "Companion stopping".into(),
            format!("companion stopping ({why}); the vehicle is disarmed"),
        )
    };
    if severity == CRITICAL {
        tracing::warn!("{line}");
    } else {
        tracing::info!("{line}");
    }
    shell.pending_events.push(Event::from(line));
    // The stop's words go first, ahead of the mode command.
    let mut msgs = shell.texts.say(now, severity, &text);
    msgs.extend(out);
    (msgs, commanded)
}

/// The hand-off's outcome, for the record once it is known (or the wait ended).
pub fn end_stop(shell: &mut Shell, vehicle: &Vehicle, commanded: bool) {
    if !commanded {
        return;
    }
    let line = match vehicle.handoff_status() {
        Some(true) => "companion stopping: the autopilot accepted the hand-off mode".to_string(),
        Some(false) => "companion stopping: the hand-off mode failed (see commands); the pilot must take over".to_string(),
        None => "companion stopping: no answer to the hand-off mode before exit; the pilot must take over".to_string(),
    };
    tracing::warn!("{line}");
    shell.pending_events.push(Event::from(line));
}
