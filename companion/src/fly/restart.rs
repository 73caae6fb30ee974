//! A companion started (or restarted: systemd after a crash, a hang caught by the watchdog, a
//! power cut of the board) next to a vehicle already armed and in the air. It never says it waits
//! for the operator then: it tells the ground station that a flight is in progress and what it
//! does. By default (params/link.toml `[flight] restart_in_air = "handoff"`) it hands the vehicle
//! to the autopilot at once (`[flight] handoff`). With `"resume_with_consent"`, when its own run
//! log proves the flight is its own and the plan still holds ([`super::resume`]), it offers the
//! operator to resume it: a MISSION_START from an accepted ground station within
//! [`resume::CONSENT_WINDOW`] resumes it where it is (no arming, take-off or upload), else it
//! hands off; a failed proof hands off at once, its reason said (docs/mavlink.md, "Started in
//! flight").
//!
//! Only a vehicle in a mode the companion flies (GUIDED, AUTO; PX4's hold, which stands for
//! GUIDED there) is handed off or resumed: in any other mode the pilot or the autopilot already
//! flies it (a manual flight, a failsafe, an earlier hand-off), and the companion only says so
//! and stands by. Either way the gate takes no start until the vehicle is landed and disarmed.

use super::resume::{self, NotProved, PreviousRun};
use super::{Shell, WARNING};
use companion_core::record::{Event, OperatorEvent};
use companion_link::Msg;
use companion_link::actions::Handoff;
use companion_link::dialect::MavResult;
use companion_link::modes::{Flavor, FlightMode, ReportedMode};
use companion_link::operator::{self, Control};
use companion_link::restart_in_air::RestartInAir;
use companion_link::vehicle::{AutopilotMission, CommandToUs, Vehicle};
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
    /// Armed and in the air: said, handed off (or offered to resume), no start until landed
    /// and disarmed.
    InFlight,
    /// Armed and in the air, and resumed on the operator's consent: the companion commands.
    Resumed,
}

/// A flight found in progress on its way to being resumed.
#[derive(Debug, Clone, PartialEq, Default)]
enum Resume {
    /// Not offered (the default params, a pilot's mode), or over (handed off, resumed).
    #[default]
    Off,
    /// The log proved it; the mission download and a judged guarantee are awaited.
    Proving {
        since: Duration,
        facts: Vec<String>,
        mission_checked: bool,
    },
    /// Proved; the operator's MISSION_START is awaited until `until`.
    AwaitingConsent { until: Duration, facts: Vec<String> },
}

/// The look at the vehicle when the companion starts.
#[derive(Debug, Default)]
pub(super) struct StartLook {
    /// What was found (decided once per run).
    pub(super) found: AtStart,
    /// When the autopilot was first heard armed without evidence of where it is.
    armed_since: Option<Duration>,
    /// params/link.toml `[flight] restart_in_air`.
    restart_in_air: RestartInAir,
    /// The previous run's log in `--log-dir` (read before this run's folder was made), when
    /// `restart_in_air` may resume.
    previous: Option<Result<PreviousRun, String>>,
    resume: Resume,
    /// The vehicle as found, in words (for the record's later lines).
    found_as: String,
    /// Words for the ground station not yet sent (held back by the STATUSTEXT rate cap): sent
    /// on the next turns, so the operator hears the offer, the hand-off and why.
    unsaid: Vec<String>,
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
            armed: vehicle.telemetry().armed || vehicle.armed_heartbeats() > 0,
            landed_state: vehicle.telemetry().landed_state.clone(),
            alt_rel_m: vehicle.telemetry().position.map(|p| p.alt_rel_m),
            mode: vehicle.telemetry().mode,
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
    /// The look of a run whose params say `restart_in_air`, with the previous run's log.
    pub(super) fn new(
        restart_in_air: RestartInAir,
        previous: Option<Result<PreviousRun, String>>,
    ) -> Self {
        Self {
            restart_in_air,
            previous,
            ..Self::default()
        }
    }

    /// The operator may be told that the companion waits for them: the vehicle was found on
    /// the ground (or the flight resumed, once it is over).
    pub(super) fn may_wait_for_operator(&self) -> bool {
        matches!(self.found, AtStart::OnGround | AtStart::Resumed)
    }

    /// The operator's MISSION_START is awaited as the consent to resume the flight found.
    pub(super) fn awaits_consent(&self) -> bool {
        matches!(self.resume, Resume::AwaitingConsent { .. })
    }

    /// One look per loop turn until decided, and, while a flight found in progress goes on,
    /// the resume's proof and consent window, and whether it ended (landed and disarmed: back
    /// to waiting for the operator). Words for the ground station and the hand-off's messages
    /// go to `out`; True when the gate changed.
    pub(super) fn look(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        handoff: Handoff,
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        self.say_unsaid(shell, now, out);
        match self.found {
            AtStart::Undecided => self.decide(shell, vehicle, handoff, now, out),
            AtStart::InFlight => {
                self.resume_turn(shell, vehicle, handoff, now, out)
                    || self.watch_landing(shell, vehicle, now, out)
            }
            AtStart::OnGround | AtStart::Resumed => false,
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
        if vehicle.target().is_none() || vehicle.telemetry().mode.is_none() {
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
        let airborne = match seen.airborne(vehicle.cfg().ground_altitude_m) {
            Some(a) => a,
            None if now.saturating_sub(since) >= EVIDENCE_WAIT => true,
            None => return false,
        };
        if !airborne {
            self.found = AtStart::OnGround;
            return false;
        }
        self.found = AtStart::InFlight;
        self.found_as = seen.describe();
        shell.operator.control = Control::FlightInProgress;
        if !companion_mode(vehicle.flavor(), seen.mode) {
            let mode = seen.mode.map_or_else(|| "?".to_string(), |m| m.to_string());
            self.say_found(
                shell,
                &format!(
                    "no hand-off: the vehicle flies in {mode}, not a mode of the companion; standing by; not resumed"
                ),
                &[format!("companion: flight in progress in {mode}, no action")],
                now,
                out,
            );
            return true;
        }
        if self.restart_in_air == RestartInAir::Handoff {
            let why = "params/link.toml [flight] restart_in_air = \"handoff\" (the default)";
            self.hand_off(shell, vehicle, handoff, &not_offered(why), now, out);
            return true;
        }
        let target = vehicle.target().unwrap_or_default();
        match resume::check_log(self.previous.as_ref(), target, utc_us_now()) {
            Ok(fact) => {
                // The mission on the autopilot is downloaded once to compare it with the route.
                vehicle.watch_autopilot_mission();
                self.resume = Resume::Proving {
                    since: now,
                    facts: vec![fact],
                    mission_checked: false,
                };
                self.say_found(
                    shell,
                    "checking whether it is the companion's own flight to resume (restart_in_air = resume_with_consent)",
                    &["companion: flight in progress, checking it".to_string()],
                    now,
                    out,
                );
            }
            Err(no) => self.hand_off(shell, vehicle, handoff, &no, now, out),
        }
        true
    }

    /// The words held back, together, once the rate cap lets them go.
    fn say_unsaid(&mut self, shell: &mut Shell, now: Duration, out: &mut Vec<Msg>) {
        if !self.unsaid.is_empty() {
            let msgs = shell.texts.say_together(now, WARNING, &self.unsaid);
            if !msgs.is_empty() {
                self.unsaid.clear();
                out.extend(msgs);
            }
        }
    }

    /// The record's line and the words for the ground station when the flight is found.
    fn say_found(
        &mut self,
        shell: &mut Shell,
        does: &str,
        texts: &[String],
        now: Duration,
        out: &mut Vec<Msg>,
    ) {
        let found = Event::StartedInFlight {
            found_as: self.found_as.clone(),
            does: does.to_string(),
        };
        tracing::warn!("{found}");
        shell.pending_events.push(found);
        // Newer words replace older ones not yet said: what the companion does now counts.
        self.unsaid = texts.to_vec();
        self.say_unsaid(shell, now, out);
    }

    /// Hand the flight found to the autopilot (params/link.toml `[flight] handoff`), saying why
    /// it is not resumed.
    fn hand_off(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        handoff: Handoff,
        no: &NotProved,
        now: Duration,
        out: &mut Vec<Msg>,
    ) {
        self.resume = Resume::Off;
        if vehicle.flies_autopilot_mission() {
            vehicle.unwatch_autopilot_mission();
        }
        let (does, mut texts) = match handoff.mode() {
            Some(mode) => {
                out.extend(vehicle.hand_off(now, mode));
                (
                    format!("handed off: hand-off {mode} (params/link.toml [flight] handoff)"),
                    vec![format!("companion: flight in progress, hand-off {mode}")],
                )
            }
            None => (
                "handed off: no hand-off (handoff = none): the vehicle goes on as it flies"
                    .to_string(),
                vec!["companion: flight in progress, no hand-off".to_string()],
            ),
        };
        // One change of decision, one STATUSTEXT: the hand-off and why it is not resumed together
        // (chunked when longer than 50).
        if !no.short.is_empty()
            && let Some(t) = texts.first_mut()
        {
            t.push_str(&format!(", not resumed: {}", no.short));
        }
        let does = format!(
            "{does}; not resumed: {}; no start until it is landed and disarmed",
            no.why
        );
        self.say_found(shell, &does, &texts, now, out);
    }

    /// The resume's proof and consent window, one step per turn. True when something was said.
    fn resume_turn(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        handoff: Handoff,
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        if self.resume == Resume::Off {
            return false;
        }
        if !companion_mode(vehicle.flavor(), vehicle.telemetry().mode) {
            // The pilot or the autopilot took it meanwhile: theirs now.
            self.resume = Resume::Off;
            vehicle.unwatch_autopilot_mission();
            let mode =
                (vehicle.telemetry().mode).map_or_else(|| "?".to_string(), |m| m.to_string());
            self.say_found(
                shell,
                &format!("not resumed: the vehicle flies in {mode} now; standing by"),
                &[format!("companion: flight in {mode}, no action")],
                now,
                out,
            );
            return true;
        }
        match self.prove(shell, vehicle, now) {
            Ok(None) => false,
            Ok(Some(facts)) => {
                let wait = resume::CONSENT_WINDOW.as_secs();
                let mode = handoff
                    .mode()
                    .map_or("no hand-off".into(), |m| format!("{m}"));
                self.say_found(
                    shell,
                    &format!(
                        "the flight is the companion's own ({}); it resumes on the operator's MISSION_START within {wait} s, else hand-off",
                        facts.join("; ")
                    ),
                    &[
                        "companion: flight in progress is our own".to_string(),
                        format!("companion: MISSION_START in {wait}s resumes, else {mode}"),
                    ],
                    now,
                    out,
                );
                self.resume = Resume::AwaitingConsent {
                    until: now + resume::CONSENT_WINDOW,
                    facts,
                };
                true
            }
            Err(no) => {
                self.hand_off(shell, vehicle, handoff, &no, now, out);
                true
            }
        }
    }

    /// The proof's next step: Ok(Some(facts)) once proved (the consent window opens), Ok(None)
    /// while awaited, Err when it failed or the consent window passed.
    fn prove(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        now: Duration,
    ) -> Result<Option<Vec<String>>, NotProved> {
        let (since, facts, mission_checked) = match &mut self.resume {
            Resume::AwaitingConsent { until, .. } if now >= *until => {
                return Err(NotProved {
                    short: "no consent",
                    why: format!(
                        "no MISSION_START from the operator within {} s",
                        resume::CONSENT_WINDOW.as_secs()
                    ),
                });
            }
            Resume::Proving {
                since,
                facts,
                mission_checked,
            } => (*since, facts, mission_checked),
            _ => return Ok(None),
        };
        if !*mission_checked && let Some(m) = vehicle.take_autopilot_mission() {
            let items = match m {
                AutopilotMission::Loaded(i) | AutopilotMission::Changed(i) => i,
            };
            vehicle.unwatch_autopilot_mission();
            let home = vehicle.telemetry().home.map(|h| (h.0, h.1));
            let route = vehicle.route().ok_or_else(|| NotProved {
                short: "no route",
                why: "no route loaded".into(),
            })?;
            let home_at_seq0 = vehicle.home_at_seq0();
            facts.push(resume::check_mission(
                route,
                vehicle.flavor(),
                home_at_seq0,
                home,
                &items,
            )?);
            *mission_checked = true;
        }
        let judged = shell
            .guarantee_in_flight
            .as_ref()
            .filter(|(at, ..)| *at > since);
        if *mission_checked && let Some((_, g, battery)) = judged {
            facts.push(resume::check_plan(g.as_ref(), *battery)?);
            return Ok(Some(std::mem::take(facts)));
        }
        if now.saturating_sub(since) >= resume::PROOF_WAIT {
            let what = if *mission_checked {
                "no guarantee was judged"
            } else {
                "the autopilot's mission was not downloaded"
            };
            return Err(NotProved {
                short: "proof timed out",
                why: format!("{what} within {} s", resume::PROOF_WAIT.as_secs()),
            });
        }
        Ok(None)
    }

    /// The operator's MISSION_START (already accepted by the gate's rules: an accepted ground
    /// station, not stale) while the consent window is open: the companion commands the flight
    /// again from where it is (no arming, take-off or upload: the decision cycle flies the
    /// route's resume in AUTO and lands as it would have). True when resumed.
    pub(super) fn consent(
        &mut self,
        shell: &mut Shell,
        vehicle: &mut Vehicle,
        from: (u8, u8),
        now: Duration,
        out: &mut Vec<Msg>,
    ) -> bool {
        let Resume::AwaitingConsent { facts, .. } = std::mem::take(&mut self.resume) else {
            return false;
        };
        self.found = AtStart::Resumed;
        shell.operator.control = Control::Started;
        shell.granted_at = None; // no take-off to void: the vehicle is in the air
        shell.guarantee_in_flight = None;
        let resumed = Event::ResumedInFlight {
            system: from.0,
            component: from.1,
            found_as: self.found_as.clone(),
            facts,
        };
        tracing::warn!("{resumed}");
        shell.pending_events.push(resumed);
        self.unsaid = vec!["companion: resumed its own flight".to_string()];
        self.say_unsaid(shell, now, out);
        vehicle.unwatch_autopilot_mission();
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
        if vehicle.armed_heartbeats() > 0 || vehicle.down_for(now).is_none_or(|d| d < confirm) {
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

/// A reason of the params, not of a failed proof: said in the record only.
fn not_offered(why: &str) -> NotProved {
    NotProved {
        short: "",
        why: why.to_string(),
    }
}

/// The wall clock (µs since the epoch), the clock of the records' `utc_us`.
fn utc_us_now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
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
    let refused = OperatorEvent::CommandRefused {
        command: "MAV_CMD_MISSION_START".to_string(),
        system: sys,
        component: comp,
        why: "the vehicle is armed and not yet known to be on the ground".to_string(),
    };
    tracing::warn!("{refused}");
    shell.pending_events.push(Event::Operator(refused));
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
        let texts = crate::fly::said::statustexts(&out);
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

    fn resuming(previous: Option<Result<PreviousRun, String>>) -> StartLook {
        StartLook::new(RestartInAir::ResumeWithConsent, previous)
    }

    fn own_run(autopilot: &str) -> PreviousRun {
        PreviousRun {
            folder: "runs/x".into(),
            last_utc_us: Some(utc_us_now()),
            autopilot: Some(autopilot.into()),
            operator: Some("started".into()),
            uploaded: true,
            state: "wpi".into(),
            ..Default::default()
        }
    }

    fn in_air_auto() -> [Frame; 2] {
        [
            heartbeat(true, 3),
            landed(MavLandedState::MAV_LANDED_STATE_IN_AIR),
        ]
    }

    fn events(shell: &Shell) -> Vec<String> {
        shell.pending_events.iter().map(|e| e.to_string()).collect()
    }

    /// With resume_with_consent, a log that proves nothing (another autopilot's, or none)
    /// hands off at once, the reason said to the ground station and in the record; a log that
    /// holds starts the proof (the mission downloaded) and commands nothing yet.
    #[test]
    fn a_log_that_is_not_its_own_hands_off_at_once_with_the_reason() {
        for (previous, short) in [
            (Some(Ok(own_run("7/1"))), "other autopilot"),
            (Some(Err("no run folder in runs".to_string())), "no run log"),
        ] {
            let (mut shell, mut v) = setup(false);
            let mut look = resuming(previous);
            let (texts, modes) = turn(&mut look, &mut shell, &mut v, 0.0, &in_air_auto());
            assert_eq!(modes, vec![6.0], "RTL at once");
            assert_eq!(
                texts,
                vec![format!(
                    "companion: flight in progress, hand-off RTL, not resumed: {short}"
                )]
            );
            assert!(
                events(&shell)
                    .iter()
                    .any(|e| e.contains("handed off: hand-off RTL") && e.contains("not resumed:"))
            );
        }
        let (mut shell, mut v) = setup(false);
        let mut look = resuming(Some(Ok(own_run("1/1"))));
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 0.0, &in_air_auto());
        assert!(modes.is_empty(), "no hand-off while the proof runs");
        assert_eq!(texts, vec!["companion: flight in progress, checking it"]);
        assert!(
            v.flies_autopilot_mission(),
            "the mission is downloaded to compare"
        );
        assert!(matches!(look.resume, Resume::Proving { .. }));
        // No download and no judged guarantee within the proof's wait: handed off.
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 16.0, &[]);
        assert_eq!(modes, vec![6.0]);
        assert!(
            texts
                .iter()
                .any(|t| t.ends_with(", not resumed: proof timed out")),
            "{texts:?}"
        );
        assert!(!v.flies_autopilot_mission());
        assert_eq!(shell.operator.control, Control::FlightInProgress);
    }

    fn offered(look: &mut StartLook, shell: &mut Shell, v: &mut Vehicle) {
        turn(look, shell, v, 0.0, &in_air_auto());
        look.resume = Resume::AwaitingConsent {
            until: s(20.0),
            facts: vec!["fact one".into(), "fact two".into()],
        };
        assert!(look.awaits_consent());
    }

    /// The operator's consent inside the window: the companion commands again, without a
    /// hand-off, and the record says resumed with the proof's facts.
    #[test]
    fn a_consent_in_the_window_resumes_the_flight() {
        let (mut shell, mut v) = setup(false);
        let mut look = resuming(Some(Ok(own_run("1/1"))));
        offered(&mut look, &mut shell, &mut v);
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 10.0, &[heartbeat(true, 3)]);
        assert!(texts.is_empty() && modes.is_empty());
        let mut out = Vec::new();
        assert!(look.consent(&mut shell, &mut v, (255, 190), s(10.5), &mut out));
        assert_eq!(shell.operator.control, Control::Started);
        assert_eq!(look.found, AtStart::Resumed);
        assert!(!look.awaits_consent());
        let resumed: Vec<String> = events(&shell)
            .into_iter()
            .filter(|e| e.starts_with("started in flight: resumed"))
            .collect();
        assert_eq!(resumed.len(), 1);
        assert!(
            resumed[0].contains("MISSION_START from 255/190")
                && resumed[0].contains("fact one; fact two"),
            "{resumed:?}"
        );
        // After the window no hand-off comes: the companion flies it.
        let (_, modes) = turn(&mut look, &mut shell, &mut v, 30.0, &[heartbeat(true, 3)]);
        assert!(modes.is_empty());
        // A second consent does nothing.
        assert!(!look.consent(&mut shell, &mut v, (255, 190), s(31.0), &mut Vec::new()));
    }

    /// No consent within the window: handed off, said why; a pilot's mode meanwhile: theirs.
    #[test]
    fn no_consent_hands_off_and_a_pilots_mode_is_left_alone() {
        let (mut shell, mut v) = setup(false);
        let mut look = resuming(Some(Ok(own_run("1/1"))));
        offered(&mut look, &mut shell, &mut v);
        let (_, modes) = turn(&mut look, &mut shell, &mut v, 19.0, &[heartbeat(true, 3)]);
        assert!(modes.is_empty(), "still inside the window");
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 20.0, &[heartbeat(true, 3)]);
        assert_eq!(modes, vec![6.0]);
        assert!(
            texts
                .iter()
                .any(|t| t.ends_with(", not resumed: no consent")),
            "{texts:?}"
        );
        assert!(!look.consent(&mut shell, &mut v, (255, 190), s(21.0), &mut Vec::new()));
        assert_eq!(shell.operator.control, Control::FlightInProgress);

        let (mut shell, mut v) = setup(false);
        let mut look = resuming(Some(Ok(own_run("1/1"))));
        offered(&mut look, &mut shell, &mut v);
        let (texts, modes) = turn(&mut look, &mut shell, &mut v, 5.0, &[heartbeat(true, 5)]);
        assert!(modes.is_empty(), "a pilot's LOITER is not overridden");
        assert_eq!(texts, vec!["companion: flight in LOITER, no action"]);
        assert!(!look.awaits_consent());
    }
}
