//! A companion started (or restarted: systemd after a crash, a hang caught by the watchdog, a
//! power cut of the board) next to a vehicle already armed and in the air. It never says it waits
//! for the operator then: it tells the ground station that a flight is in progress and what it
//! does, and (the default) hands the vehicle to the autopilot at once (params/link.toml
//! `[flight] handoff`), because it cannot tell from the link alone whether the plan it would
//! resume still holds. It resumes no flight (docs/mavlink.md, "Started in flight").
//!
//! Only a vehicle in a mode the companion flies (GUIDED, AUTO; PX4's hold, which stands for
//! GUIDED there) is handed off: in any other mode the pilot or the autopilot already flies it
//! (a manual flight, a failsafe, an earlier hand-off), and the companion only says so and
//! stands by. Either way the gate takes no start until the vehicle is landed and disarmed.

use super::{Shell, WARNING};
use companion_core::record::Event;
use companion_link::Msg;
use companion_link::actions::Handoff;
use companion_link::dialect::MavResult;
use companion_link::modes::{Flavor, FlightMode, ReportedMode};
use companion_link::operator::{self, Control};
use companion_link::vehicle::{CommandToUs, Vehicle};
use std::time::Duration;

/// How long an armed vehicle may go without a landed state or a position before the start
/// counts it as flying (the conservative reading: a hand-off of a vehicle that was on the ground
/// costs nothing, a missed one leaves it flying alone).
const EVIDENCE_WAIT: Duration = Duration::from_secs(5);

/// What the companion found the vehicle doing when it started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(super) enum AtStart {
    /// No autopilot heartbeat yet, or armed without a landed state or position yet.
    #[default]
    Undecided,
    /// Disarmed, or armed on the ground: the operator starts flights as usual.
    OnGround,
    /// Armed and in the air: said, handed off, no start until landed and disarmed.
    InFlight,
}

/// The look at the vehicle when the companion starts.
#[derive(Debug, Default)]
pub(super) struct StartLook {
    /// What was found (decided once per run).
    pub(super) found: AtStart,
    /// When the autopilot was first heard armed without evidence of where it is.
    armed_since: Option<Duration>,
}

/// The vehicle's state as the start reads it.
#[derive(Debug, Clone, PartialEq)]
struct Seen {
    armed: bool,
    landed_state: Option<String>,
    alt_rel_m: Option<f64>,
    mode: Option<ReportedMode>,
}

impl Seen {
    fn of(vehicle: &Vehicle) -> Self {
        Self {
            // Any armed report counts: the conservative reading for leaving a vehicle alone.
            armed: vehicle.telemetry.armed || vehicle.armed_heartbeats > 0,
            landed_state: vehicle.telemetry.landed_state.clone(),
            alt_rel_m: vehicle.telemetry.position.map(|p| p.alt_rel_m),
            mode: vehicle.telemetry.mode,
        }
    }

    /// In the air by the landed state, else by the altitude; None without either (an
    /// UNDEFINED landed state says nothing).
    fn airborne(&self, ground_altitude_m: f64) -> Option<bool> {
        let landed_state = self.landed_state.as_deref().filter(|s| *s != "UNDEFINED");
        match (landed_state, self.alt_rel_m) {
            (Some(s), _) => Some(s != "ON_GROUND"),
            (None, Some(alt)) => Some(alt > ground_altitude_m),
            (None, None) => None,
        }
    }

    fn describe(&self) -> String {
        let mode = self
            .mode
            .map_or_else(|| "unknown".to_string(), |m| m.to_string());
        let state = self.landed_state.as_deref().unwrap_or("not reported");
        let alt = self
            .alt_rel_m
            .map_or_else(|| "unknown".to_string(), |a| format!("{a:.1} m"));
        format!("armed, landed state {state}, altitude {alt} above home, mode {mode}")
    }
}

/// A mode the companion itself flies the vehicle in (GUIDED, AUTO; PX4 holds in LOITER for
/// GUIDED): a vehicle found flying in it was the companion's, and nobody flies it now.
fn companion_mode(flavor: Flavor, mode: Option<ReportedMode>) -> bool {
    match mode.and_then(ReportedMode::known) {
        Some(FlightMode::Guided | FlightMode::Auto) => true,
        Some(FlightMode::Loiter) => flavor == Flavor::Px4,
        _ => false,
    }
}

impl StartLook {
    /// The operator may be told that the companion waits for them: the vehicle was found on
    /// the ground.
    pub(super) fn may_wait_for_operator(&self) -> bool {
        self.found == AtStart::OnGround
    }

    /// One look per loop turn until decided, and, while a flight found in progress goes on,
    /// whether it ended (landed and disarmed: back to waiting for the operator). Words for the
    /// ground station and the hand-off's messages go to `out`; True when the gate changed.
    pub(super) fn look(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        handoff: Handoff,
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        match self.found {
            AtStart::Undecided => self.decide(shell, vehicle, handoff, now, out),
            AtStart::InFlight => self.watch_landing(shell, vehicle, now, out),
            AtStart::OnGround => false,
        }
    }

    fn decide(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        handoff: Handoff,
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        if vehicle.target.is_none() || vehicle.telemetry.mode.is_none() {
            return false; // no autopilot heartbeat yet
        }
        if shell.operator.control != Control::Waiting {
            self.found = AtStart::OnGround; // started already (--auto-start on the ground)
            return false;
        }
        let seen = Seen::of(vehicle);
        if !seen.armed {
            self.found = AtStart::OnGround;
            return false;
        }
        let since = *self.armed_since.get_or_insert(now);
        let airborne = match seen.airborne(vehicle.cfg.ground_altitude_m) {
            Some(a) => a,
            None if now.saturating_sub(since) >= EVIDENCE_WAIT => true,
            None => return false,
        };
        if !airborne {
            self.found = AtStart::OnGround;
            return false;
        }
        self.found = AtStart::InFlight;
        shell.operator.control = Control::FlightInProgress;
        let ours = companion_mode(vehicle.flavor, seen.mode);
        let (does, text) = match (ours, handoff.mode()) {
            (true, Some(mode)) => {
                out.extend(vehicle.hand_off(now, mode));
                (
                    format!("hand-off {mode} (params/link.toml [flight] handoff)"),
                    format!("companion: flight in progress, hand-off {mode}"),
                )
            }
            (true, None) => (
                "no hand-off (handoff = none): the vehicle goes on as it flies".to_string(),
                "companion: flight in progress, no hand-off".to_string(),
            ),
            (false, _) => {
                let mode = seen.mode.map_or_else(|| "?".to_string(), |m| m.to_string());
                (
                    format!(
                        "no hand-off: the vehicle flies in {mode}, not a mode of the companion; standing by"
                    ),
                    format!("companion: flight in progress in {mode}, no action"),
                )
            }
        };
        let line = format!(
            "started in flight: the vehicle is {}; {does}; not resumed (the companion resumes no flight it did not start in this run); no start until it is landed and disarmed",
            seen.describe()
        );
        tracing::warn!("{line}");
        shell.pending_events.push(Event::from(line));
        out.extend(shell.texts.say(now, WARNING, &text));
        true
    }

    /// The flight found in progress is over when the vehicle is landed and disarmed for the
    /// landing confirmation. One the mission estimate saw airborne ends through the shell's own
    /// end of a flight (`Shell::finished`); this ends one it never saw high enough.
    fn watch_landing(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        if shell.operator.control != Control::FlightInProgress || shell.mission.flown() {
            return false;
        }
        let confirm = Duration::from_secs_f64(shell.mission.landed_confirm_s);
        if vehicle.armed_heartbeats > 0 || vehicle.down_for(now).is_none_or(|d| d < confirm) {
            return false;
        }
        vehicle.stop_actions(now, "flight over");
        shell.new_flight();
        self.found = AtStart::OnGround;
        tracing::info!("the flight found in progress is over: landed and disarmed");
        out.extend(shell.texts.say(
            now,
            super::NOTICE,
            "companion: landed; waiting for the operator",
        ));
        true
    }
}

/// A MISSION_START while the start has not yet found where an armed vehicle is (a few seconds at
/// most): refused for now with TEMPORARILY_REJECTED (said in the record and to the ground
/// station), never granted: the launch verdict alone would take an armed vehicle at 3 m for one
/// on the ground. True: the gate's record has news.
pub(super) fn refuse_start_until_known(
    shell: &mut Shell,
    cmd: &CommandToUs,
    now: Duration,
    out: &mut Vec<Msg>,
) -> bool {
    let (sys, comp) = cmd.from;
    let line = format!(
        "operator: MAV_CMD_MISSION_START from {sys}/{comp} refused: the vehicle is armed and not yet known to be on the ground"
    );
    tracing::warn!("{line}");
    shell.pending_events.push(Event::from(line));
    out.extend(
        shell
            .texts
            .say(now, WARNING, "Start refused: vehicle armed, state unknown"),
    );
    out.push(operator::ack(
        cmd.command,
        MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
        cmd.from,
    ));
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fly::{FlyArgs, FlySetup};
    use companion_link::dialect::*;
    use companion_link::ingest::Frame;
    use companion_link::operator::OperatorGate;
    use mavlink::{MavHeader, MavlinkVersion};

    fn setup(auto_start: bool) -> (Shell, Vehicle) {
        let args = FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550"]).unwrap();
        let setup = FlySetup::load(&args).unwrap();
        let mut shell = Shell::new(&setup);
        shell.operator = OperatorGate::new(auto_start);
        (shell, setup.vehicle(Duration::from_secs(3)))
    }

    fn frame(msg: Msg) -> Frame {
        Frame {
            header: MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: 0,
            },
            msg,
            signed: false,
            version: MavlinkVersion::V2,
            raw: Vec::new(),
        }
    }

    /// ArduCopter's heartbeat: `custom_mode` 3 AUTO, 4 GUIDED, 5 LOITER, 6 RTL.
    fn heartbeat(armed: bool, custom_mode: u32) -> Frame {
        let base_mode = if armed {
            MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        } else {
            MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        };
        frame(Msg::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode,
            custom_mode,
            system_status: MavState::MAV_STATE_ACTIVE,
            ..HEARTBEAT_DATA::DEFAULT
        }))
    }

    fn landed(state: MavLandedState) -> Frame {
        frame(Msg::EXTENDED_SYS_STATE(EXTENDED_SYS_STATE_DATA {
            landed_state: state,
            ..EXTENDED_SYS_STATE_DATA::DEFAULT
        }))
    }

    fn s(t: f64) -> Duration {
        Duration::from_secs_f64(t)
    }

    /// Feed the frames at `t`, then one look; the STATUSTEXTs and the SET_MODE modes sent.
    fn turn(
        look: &mut StartLook,
        shell: &mut Shell,
        v: &mut Vehicle,
        t: f64,
        frames: &[Frame],
    ) -> (Vec<String>, Vec<f32>) {
        for f in frames {
            v.on_frame(s(t), f);
        }
        let mut out = Vec::new();
        look.look(shell, v, Handoff::Rtl, s(t), &mut out);
        let texts = out
            .iter()
            .filter_map(|m| match m {
                Msg::STATUSTEXT(st) => Some(st.text.to_str().unwrap_or_default().to_string()),
                _ => None,
            })
            .collect();
        let modes = out
            .iter()
            .filter_map(|m| match m {
                Msg::COMMAND_LONG(c) if c.command == MavCmd::MAV_CMD_DO_SET_MODE => Some(c.param2),
                _ => None,
            })
            .collect();
        (texts, modes)
    }

    /// Restarted while the vehicle flies the route in AUTO: no "waiting for the operator", the
    /// words say a flight is in progress and the hand-off, RTL is commanded at once, the record
    /// says it was not resumed, and no start is taken (not even --auto-start's).
    #[test]
    fn a_vehicle_found_flying_in_auto_is_said_and_handed_off_at_once() {
        for auto_start in [false, true] {
            let (mut shell, mut v) = setup(auto_start);
            let mut look = StartLook::default();
            let (texts, modes) = turn(&mut look, &mut shell, &mut v, 0.0, &[heartbeat(true, 3)]);
            assert_eq!(look.found, AtStart::Undecided, "armed, but where?");
            assert!(!look.may_wait_for_operator());
            assert!(texts.is_empty() && modes.is_empty());
            let (texts, modes) = turn(
                &mut look,
                &mut shell,
                &mut v,
                0.5,
                &[landed(MavLandedState::MAV_LANDED_STATE_IN_AIR)],
            );
            assert_eq!(look.found, AtStart::InFlight);
            assert_eq!(texts, vec!["companion: flight in progress, hand-off RTL"]);
            assert_eq!(modes, vec![6.0], "ArduCopter RTL");
            assert_eq!(shell.operator.control, Control::FlightInProgress);
            assert!(!look.may_wait_for_operator());
            let events: Vec<String> = shell.pending_events.iter().map(|e| e.to_string()).collect();
            assert!(
                events.iter().any(|e| e.starts_with("started in flight")
                    && e.contains("mode AUTO")
                    && e.contains("hand-off RTL")
                    && e.contains("not resumed")),
                "{events:?}"
            );
            assert_eq!(shell.operator.on_start_command(), None, "no start taken");
        }
    }

    /// On the ground (disarmed, or armed and ON_GROUND) the operator is waited for as before; a
    /// vehicle flying in a pilot's mode is said and left to the pilot.
    #[test]
    fn on_the_ground_it_waits_and_a_pilots_flight_is_left_alone() {
        let (mut shell, mut v) = setup(false);
        let mut look = StartLook::default();
        turn(&mut look, &mut shell, &mut v, 0.0, &[heartbeat(false, 0)]);
        assert!(look.may_wait_for_operator());
        let (mut shell, mut v) = setup(false);
        let mut look = StartLook::default();
        let frames = [
            heartbeat(true, 4),
            landed(MavLandedState::MAV_LANDED_STATE_ON_GROUND),
        ];
        turn(&mut look, &mut shell, &mut v, 0.0, &frames);
        assert!(look.may_wait_for_operator());
        assert_eq!(shell.operator.control, Control::Waiting);

        let (mut shell, mut v) = setup(false);
        let mut look = StartLook::default();
        let frames = [
            heartbeat(true, 5),
            landed(MavLandedState::MAV_LANDED_STATE_IN_AIR),
        ];
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 0.0, &frames);
        assert_eq!(
            texts,
            vec!["companion: flight in progress in LOITER, no action"]
        );
        assert!(modes.is_empty(), "a pilot's LOITER is not overridden");
        assert_eq!(shell.operator.control, Control::FlightInProgress);
    }

    /// Armed with neither a landed state nor a position: after a short wait it counts as
    /// flying (the conservative reading), never as waiting for the operator.
    #[test]
    fn armed_without_evidence_counts_as_flying_after_the_wait() {
        let (mut shell, mut v) = setup(false);
        let mut look = StartLook::default();
        turn(&mut look, &mut shell, &mut v, 0.0, &[heartbeat(true, 4)]);
        let undefined = landed(MavLandedState::MAV_LANDED_STATE_UNDEFINED);
        turn(
            &mut look,
            &mut shell,
            &mut v,
            4.0,
            &[heartbeat(true, 4), undefined],
        );
        assert_eq!(look.found, AtStart::Undecided, "UNDEFINED says nothing");
        let (_, modes) = turn(&mut look, &mut shell, &mut v, 5.0, &[heartbeat(true, 4)]);
        assert_eq!(look.found, AtStart::InFlight);
        assert_eq!(modes, vec![6.0]);
        // Landed and disarmed long enough: back to waiting for the operator.
        let down = [
            heartbeat(false, 6),
            landed(MavLandedState::MAV_LANDED_STATE_ON_GROUND),
        ];
        turn(&mut look, &mut shell, &mut v, 6.0, &down);
        turn(&mut look, &mut shell, &mut v, 7.0, &down);
        assert_eq!(shell.operator.control, Control::FlightInProgress);
        let (texts, _) = turn(&mut look, &mut shell, &mut v, 10.5, &down);
        assert_eq!(shell.operator.control, Control::Waiting);
        assert_eq!(texts, vec!["companion: landed; waiting for the operator"]);
    }

    /// A MISSION_START before the start knows where the armed vehicle is: refused for now,
    /// said, recorded; never passed to the gate.
    #[test]
    fn a_start_before_the_vehicle_is_placed_is_refused_for_now() {
        let (mut shell, _) = setup(false);
        shell.launch = Ok(()); // the models would agree
        let cmd = CommandToUs {
            command: MavCmd::MAV_CMD_MISSION_START,
            from: (255, 190),
            at: s(1.0),
            before_autopilot: false,
        };
        let mut out = Vec::new();
        assert!(refuse_start_until_known(&mut shell, &cmd, s(1.0), &mut out));
        assert!(out.iter().any(|m| matches!(m, Msg::COMMAND_ACK(a)
            if a.result == MavResult::MAV_RESULT_TEMPORARILY_REJECTED
                && (a.target_system, a.target_component) == (255, 190))));
        assert_eq!(shell.operator.control, Control::Waiting);
        assert!(
            shell
                .pending_events
                .iter()
                .any(|e| e.to_string().contains("not yet known to be on the ground"))
        );
    }
}
