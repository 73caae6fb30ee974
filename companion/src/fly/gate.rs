//! The operator gate in the shell: who sent a command addressed to the companion and how old it
//! is, a start granted only when the models agree (the launch verdict, [`companion_core::launch::verdict`]), a
//! start voided by a failed take-off, and what each gate decision tells the record, the journal
//! and the ground station. The gate's own state machine is [`companion_link::operator`].

use super::{NOTICE, Shell, WARNING};
use companion_core::launch::LaunchRefusal;
use companion_core::record::{Event, OperatorEvent};
use companion_link::Msg;
use companion_link::dialect::{MavResult, MavSeverity};
use companion_link::operator::{self, GateEvent, StartBy, VehicleView};
use companion_link::vehicle::{AUTOPILOT_COMPONENT, CommandToUs, Vehicle};
use std::collections::BTreeSet;
use std::time::Duration;

/// Ground stations the companion takes a start from: those `--gcs-sysid` names when it names
/// any (a GCS HEARTBEAT from another system is reported, never obeyed); else the systems heard
/// sending a GCS HEARTBEAT on the autopilot link.
#[derive(Debug, Default, Clone)]
pub struct GroundStations {
    /// `--gcs-sysid`.
    pub pinned: BTreeSet<u8>,
    /// Heard sending a HEARTBEAT with MAV_TYPE_GCS (without `--gcs-sysid`), at most
    /// [`MAX_STATIONS`].
    pub heard: BTreeSet<u8>,
    /// With `--gcs-sysid`: other systems heard sending a GCS HEARTBEAT, reported once each.
    pub unnamed: BTreeSet<u8>,
}

/// At most this many ground stations kept (and reported): a flood of invented systems cannot
/// grow the sets.
const MAX_STATIONS: usize = 16;

impl GroundStations {
    /// A frame from the autopilot link: a GCS HEARTBEAT makes its system a ground station, or,
    /// when `--gcs-sysid` names others, is reported: the line for the journal and the record,
    /// once per system.
    pub fn on_frame(&mut self, f: &companion_link::ingest::Frame) -> Option<OperatorEvent> {
        let Msg::HEARTBEAT(h) = &f.msg else {
            return None;
        };
        if h.mavtype != companion_link::dialect::MavType::MAV_TYPE_GCS {
            return None;
        }
        let sys = f.header.system_id.min(255) as u8;
        if self.pinned.is_empty() {
            if self.heard.len() < MAX_STATIONS {
                self.heard.insert(sys);
            }
            return None;
        }
        if self.pinned.contains(&sys)
            || self.unnamed.len() >= MAX_STATIONS
            || !self.unnamed.insert(sys)
        {
            return None;
        }
        Some(OperatorEvent::GroundStationNotNamed {
            system: sys,
            component: f.header.component_id,
            named: self.named(),
        })
    }

    /// The `--gcs-sysid` list, in words.
    fn named(&self) -> String {
        let ids: Vec<String> = self.pinned.iter().map(u8::to_string).collect();
        ids.join(", ")
    }

    /// Whether `system` is one of the operator's ground stations (its heartbeats count for the
    /// ground-station watch, its start is taken).
    pub fn counts(&self, system: u8) -> bool {
        if self.pinned.is_empty() {
            self.heard.contains(&system)
        } else {
            self.pinned.contains(&system)
        }
    }
}

/// A command addressed to us that the gate's rules accept (an accepted ground station, not
/// stale, the autopilot heard first): the same rules as a start.
pub(super) fn start_acceptable(
    cmd: &CommandToUs,
    now: Duration,
    max_age: Duration,
    vehicle: &Vehicle,
    gcs: &GroundStations,
) -> bool {
    command_refusal(cmd, now, max_age, vehicle, gcs).is_none()
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
    if comp == AUTOPILOT_COMPONENT || vehicle.target() == Some((sys, comp)) {
        return Some((
            MavResult::MAV_RESULT_DENIED,
            format!("the sender {sys}/{comp} is an autopilot component, not a ground station"),
            "Start refused: sender is not a ground station",
        ));
    }
    if cmd.command == operator::START_COMMAND && !gcs.counts(sys) {
        let why = if gcs.pinned.is_empty() {
            format!("system {sys} sent no GCS HEARTBEAT and is not named by --gcs-sysid")
        } else {
            format!(
                "system {sys} is not a ground station --gcs-sysid names ({}): only those may start",
                gcs.named()
            )
        };
        return Some((
            MavResult::MAV_RESULT_DENIED,
            why,
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
        let refused = OperatorEvent::CommandRefused {
            command: name.to_string(),
            system: sys,
            component: comp,
            why,
        };
        tracing::warn!("{refused}");
        shell.pending_events.push(Event::Operator(refused));
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
            None if matches!(
                shell.operator.control,
                operator::Control::Stopping | operator::Control::FlightInProgress
            ) =>
            {
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
            let no_decision_yet =
                matches!(&refusal, LaunchRefusal::NotOnGround { state, .. } if state.is_empty());
            if no_decision_yet && by == StartBy::AutoStart {
                return Err(refusal); // asked again once the first record is in
            }
            let ev = shell.operator.refuse(by, &refusal.description());
            let lines = if no_decision_yet {
                vec!["Start refused: not ready yet, send again".to_string()]
            } else {
                // With the guarantee's verdict: planned against available, then what fits.
                refusal.pilot_lines()
            };
            // Said once per first line: the verdict's time left changes every second.
            let first = lines.first().cloned().unwrap_or_default();
            if by != StartBy::AutoStart || shell.refusal_told.as_deref() != Some(&first) {
                let refused = ev.record();
                tracing::warn!("{refused}");
                shell.pending_events.push(Event::Operator(refused));
                // One change of decision, one STATUSTEXT (chunked when longer than 50).
                out.extend(shell.texts.say_answer(now, WARNING, &lines.join(". ")));
                shell.refusal_told = Some(first);
            }
            Err(refusal)
        }
    }
}

/// One look at the vehicle for the gate: start requests, a void, a takeover and its
/// confirmation, a hand-back; and a take-off that failed before the vehicle was airborne.
/// True when the gate changed.
pub fn observe(
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    now: Duration,
    out: &mut Vec<Msg>,
) -> bool {
    let view = VehicleView {
        flavor: vehicle.flavor(),
        custom_mode: vehicle.telemetry().custom_mode,
        mode: vehicle.telemetry().mode,
        armed_heartbeats: vehicle.armed_heartbeats(),
        armed_for: vehicle.armed_for(now),
        mode_for: vehicle.mode_for(now),
        airborne: shell.mission.flown(),
        commanded_modes: vehicle.commanded_modes(),
        mission_item_mode: vehicle.mission_item_mode(),
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
    let decided = ev.record();
    if matches!(ev, GateEvent::Started(_) | GateEvent::HandedBack(_)) {
        tracing::info!("{decided}");
    } else {
        tracing::warn!("{decided}");
    }
    shell.pending_events.push(Event::Operator(decided));
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
        GateEvent::FalseAlarm(mode, _) => Some((
            WARNING,
            format!("Mode {mode} not confirmed: companion resumes"),
        )),
        GateEvent::HandedBack(_) => Some((NOTICE, "companion: control handed back".to_string())),
    };
    if let Some((severity, gcs)) = said {
        out.extend(shell.texts.say(now, severity, &gcs));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fly::{FlyArgs, FlySetup};
    use companion_link::Msg;
    use companion_link::dialect::*;
    use companion_link::ingest::Frame;
    use companion_link::operator::{Control, OperatorGate};
    use mavlink::{MavHeader, MavlinkVersion};

    fn setup() -> (Shell, Vehicle) {
        let args = FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550"]).unwrap();
        let setup = FlySetup::load(&args).unwrap();
        let mut shell = Shell::new(&setup);
        shell.operator = OperatorGate::new(false);
        (shell, setup.vehicle(Duration::from_secs(3)))
    }

    fn frame(sys: u8, comp: u8, msg: Msg) -> Frame {
        Frame {
            header: MavHeader {
                system_id: sys.into(),
                component_id: comp,
                sequence: 0,
            },
            msg,
            signed: false,
            version: MavlinkVersion::V2,
            raw: Vec::new(),
        }
    }

    fn autopilot_heartbeat() -> Frame {
        frame(
            1,
            1,
            Msg::HEARTBEAT(HEARTBEAT_DATA {
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                ..HEARTBEAT_DATA::DEFAULT
            }),
        )
    }

    fn start_from(sys: u8, comp: u8) -> Frame {
        frame(
            sys,
            comp,
            Msg::COMMAND_LONG(COMMAND_LONG_DATA {
                command: MavCmd::MAV_CMD_MISSION_START,
                target_system: 1,
                target_component: companion_link::OUR_COMPONENT_ID,
                ..COMMAND_LONG_DATA::DEFAULT
            }),
        )
    }

    fn gcs_heartbeat(sys: u8) -> Frame {
        frame(
            sys,
            190,
            Msg::HEARTBEAT(HEARTBEAT_DATA {
                mavtype: MavType::MAV_TYPE_GCS,
                autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
                ..HEARTBEAT_DATA::DEFAULT
            }),
        )
    }

    /// Feed `f` at `t` s; answer the commands to us; the ACK results sent.
    fn feed(
        shell: &mut Shell,
        v: &mut Vehicle,
        gcs: &mut GroundStations,
        t: f64,
        f: &Frame,
    ) -> Vec<MavResult> {
        let now = Duration::from_secs_f64(t);
        if let Some(heard) = gcs.on_frame(f) {
            shell.pending_events.push(Event::Operator(heard));
        }
        v.on_frame(now, f);
        let mut out = Vec::new();
        for cmd in v.take_commands_to_us() {
            answer_command(shell, v, gcs, cmd, now, &mut out);
        }
        out.iter()
            .filter_map(|m| match m {
                Msg::COMMAND_ACK(a) => Some(a.result),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_start_before_the_autopilot_is_heard_is_refused_and_not_kept() {
        let (mut shell, mut v) = setup();
        let mut gcs = GroundStations::default();
        feed(&mut shell, &mut v, &mut gcs, 0.1, &gcs_heartbeat(255));
        let acks = feed(&mut shell, &mut v, &mut gcs, 0.2, &start_from(255, 190));
        assert_eq!(acks, vec![MavResult::MAV_RESULT_TEMPORARILY_REJECTED]);
        shell.launch = Ok(()); // the models would agree now
        feed(&mut shell, &mut v, &mut gcs, 1.0, &autopilot_heartbeat());
        assert!(v.take_commands_to_us().is_empty());
        assert_eq!(shell.operator.control, Control::Waiting);
    }

    #[test]
    fn a_start_is_taken_only_from_a_ground_station() {
        let (mut shell, mut v) = setup();
        let mut gcs = GroundStations::default();
        shell.launch = Ok(());
        feed(&mut shell, &mut v, &mut gcs, 0.0, &autopilot_heartbeat());
        feed(&mut shell, &mut v, &mut gcs, 0.1, &gcs_heartbeat(255));
        // The autopilot's own component, another system's component 1, a system never heard as a GCS.
        for (sys, comp) in [(1, 1), (66, 1), (77, 190)] {
            let acks = feed(&mut shell, &mut v, &mut gcs, 0.5, &start_from(sys, comp));
            assert_eq!(acks, vec![MavResult::MAV_RESULT_DENIED], "{sys}/{comp}");
            assert_eq!(shell.operator.control, Control::Waiting);
        }
        // --gcs-sysid names a ground station before its heartbeat.
        gcs.pinned.insert(77);
        let acks = feed(&mut shell, &mut v, &mut gcs, 0.6, &start_from(77, 190));
        assert_eq!(acks, vec![MavResult::MAV_RESULT_ACCEPTED]);
        assert_eq!(shell.operator.control, Control::Started);
    }

    #[test]
    fn with_gcs_sysid_only_the_named_stations_start_and_another_is_reported() {
        let (mut shell, mut v) = setup();
        let mut gcs = GroundStations {
            pinned: [255].into(),
            ..Default::default()
        };
        shell.launch = Ok(());
        feed(&mut shell, &mut v, &mut gcs, 0.0, &autopilot_heartbeat());
        feed(&mut shell, &mut v, &mut gcs, 0.1, &gcs_heartbeat(255));
        assert!(shell.pending_events.is_empty());
        // A forged GCS heartbeat from 77, then its start: reported once, refused.
        feed(&mut shell, &mut v, &mut gcs, 0.2, &gcs_heartbeat(77));
        feed(&mut shell, &mut v, &mut gcs, 0.3, &gcs_heartbeat(77));
        let reported: Vec<String> = shell
            .pending_events
            .iter()
            .map(|e| e.to_string())
            .filter(|e| e.contains("ground station 77/190 is heard"))
            .collect();
        assert_eq!(reported.len(), 1, "{:?}", shell.pending_events);
        assert!(!gcs.counts(77));
        let acks = feed(&mut shell, &mut v, &mut gcs, 0.5, &start_from(77, 190));
        assert_eq!(acks, vec![MavResult::MAV_RESULT_DENIED]);
        assert_eq!(shell.operator.control, Control::Waiting);
        assert!(shell.pending_events.iter().any(|e| {
            e.to_string()
                .contains("system 77 is not a ground station --gcs-sysid names (255)")
        }));
        // The named station starts.
        let acks = feed(&mut shell, &mut v, &mut gcs, 0.6, &start_from(255, 190));
        assert_eq!(acks, vec![MavResult::MAV_RESULT_ACCEPTED]);
        assert_eq!(shell.operator.control, Control::Started);
    }

    #[test]
    fn a_flood_of_invented_ground_stations_is_bounded() {
        let mut gcs = GroundStations::default();
        for sys in 1..=200 {
            gcs.on_frame(&gcs_heartbeat(sys));
        }
        assert_eq!(gcs.heard.len(), MAX_STATIONS);
        let mut named = GroundStations {
            pinned: [255].into(),
            ..Default::default()
        };
        let said = (1..=200)
            .filter(|&sys| named.on_frame(&gcs_heartbeat(sys)).is_some())
            .count();
        assert_eq!(said, MAX_STATIONS);
    }

    #[test]
    fn a_command_that_waited_too_long_is_refused() {
        let (mut shell, mut v) = setup();
        let mut gcs = GroundStations::default();
        shell.launch = Ok(());
        feed(&mut shell, &mut v, &mut gcs, 0.0, &autopilot_heartbeat());
        feed(&mut shell, &mut v, &mut gcs, 0.1, &gcs_heartbeat(255));
        v.on_frame(Duration::from_secs(1), &start_from(255, 190));
        let mut out = Vec::new();
        let late = Duration::from_secs(1) + shell.command_max_age + Duration::from_millis(1);
        for cmd in v.take_commands_to_us() {
            answer_command(&mut shell, &mut v, &gcs, cmd, late, &mut out);
        }
        assert!(
            matches!(&out[..], [.., Msg::COMMAND_ACK(a)] if a.result == MavResult::MAV_RESULT_TEMPORARILY_REJECTED)
        );
        assert_eq!(shell.operator.control, Control::Waiting);
    }

    #[test]
    fn the_models_refusal_is_denied_with_the_pilots_words_and_the_gate_keeps_waiting() {
        let (mut shell, mut v) = setup();
        let mut gcs = GroundStations::default();
        shell.launch = Err(LaunchRefusal::BatteryLow {
            pct: 12.0,
            short_j: 9_600.0,
            reason: String::new(),
            verdict: None,
        });
        feed(&mut shell, &mut v, &mut gcs, 0.0, &autopilot_heartbeat());
        feed(&mut shell, &mut v, &mut gcs, 0.1, &gcs_heartbeat(255));
        let now = Duration::from_millis(500);
        v.on_frame(now, &start_from(255, 190));
        let mut out = Vec::new();
        for cmd in v.take_commands_to_us() {
            answer_command(&mut shell, &mut v, &gcs, cmd, now, &mut out);
        }
        let texts = crate::fly::said::statustexts(&out);
        // The margin (-9.6 kJ) is plotted (`e_margin`): the text does not repeat it.
        assert_eq!(
            texts,
            vec!["Start refused: battery 12%, not enough energy".to_string()]
        );
        assert!(
            matches!(&out[..], [.., Msg::COMMAND_ACK(a)] if a.result == MavResult::MAV_RESULT_DENIED)
        );
        assert_eq!(shell.operator.control, Control::Waiting);
        // The refusal by kind (review reads it so), its sentence as the journal says it.
        let refused = shell.pending_events.iter().find(|e| {
            matches!(
                e,
                Event::Operator(OperatorEvent::StartRefused {
                    by: StartBy::StartCommand,
                    ..
                })
            )
        });
        assert!(
            refused.is_some_and(|e| e.to_string().starts_with("operator: start refused")),
            "{:?}",
            shell.pending_events
        );
    }

    /// With the guarantee's verdict the refusal is one STATUSTEXT (a change of decision is one
    /// text; MAVLink 2 chunks when longer than 50): planned against available, then what fits
    /// (the verdict's own words).
    #[test]
    fn a_refusal_with_the_verdict_names_planned_available_and_what_fits() {
        let (mut shell, mut v) = setup();
        let verdict = companion_core::record::Verdict {
            planned_energy_j: Some(143_012.0),
            available_energy_j: Some(98_900.0),
            battery_pct: Some(100.0),
            planned_duration_s: Some(1012.0),
            available_duration_s: Some(1800.0),
            planned_search_s: Some(300.0),
            longest_search_s: Some(180.0),
            ..Default::default()
        };
        shell.launch = Err(LaunchRefusal::BatteryLow {
            pct: 100.0,
            short_j: 44_112.0,
            reason: String::new(),
            verdict: Some(Box::new(verdict)),
        });
        let mut out = Vec::new();
        let r = request_start(
            &mut shell,
            &mut v,
            StartBy::StartCommand,
            Duration::from_secs(1),
            &mut out,
        );
        assert!(r.is_err());
        let texts = crate::fly::said::statustexts(&out);
        assert_eq!(
            texts,
            [
                "Start refused: plan 143 kJ, have 98.9 kJ at 100%. Time 1012 s of 1800 s; fits: search 180 s"
            ]
        );
        let journal: Vec<String> = shell.pending_events.iter().map(|e| e.to_string()).collect();
        assert!(
            journal
                .iter()
                .any(|e| e.contains("plan 143 kJ, have 98.9 kJ at 100%; Time 1012 s of 1800 s")),
            "{journal:?}"
        );
    }

    #[test]
    fn an_auto_start_refusal_is_said_once_per_reason() {
        let (mut shell, mut v) = setup();
        shell.operator = OperatorGate::new(true);
        shell.launch = Err(LaunchRefusal::NoGuarantee);
        let mut out = Vec::new();
        for i in 0..5 {
            let _ = request_start(
                &mut shell,
                &mut v,
                StartBy::AutoStart,
                Duration::from_secs(i),
                &mut out,
            );
        }
        let said = out
            .iter()
            .filter(|m| matches!(m, Msg::STATUSTEXT(_)))
            .count();
        assert_eq!(said, 1);
        shell.launch = Ok(());
        assert!(
            request_start(
                &mut shell,
                &mut v,
                StartBy::AutoStart,
                Duration::from_secs(6),
                &mut out
            )
            .is_ok()
        );
        assert!(shell.operator.commanding());
    }
}
