//! What happened in a cycle ([`Event`]), on the link ([`LinkEvent`]) and to a vehicle command
//! ([`CommandOutcome`]), as types built by their producers with their fields. The decision log
//! (schema 2) writes each as a JSON object tagged by `kind` (`wire`); `Display` gives the
//! sentence for people (the review, the journal, the ground station's text). Schema-1 logs wrote
//! the sentences; `companion::decision_log::migration` reads them.

use std::fmt;

mod wire;

/// `value == "sentence"`: compares the written form (`Display`) without allocating.
macro_rules! eq_sentence {
    ($t:ty) => {
        impl PartialEq<str> for $t {
            fn eq(&self, other: &str) -> bool {
                struct Eq<'a>(&'a str, bool);
                impl fmt::Write for Eq<'_> {
                    fn write_str(&mut self, s: &str) -> fmt::Result {
                        match self.0.strip_prefix(s) {
                            Some(rest) => {
                                self.0 = rest;
                                Ok(())
                            }
                            None => {
                                self.1 = false;
                                Err(fmt::Error)
                            }
                        }
                    }
                }
                let mut w = Eq(other, true);
                let _ = fmt::write(&mut w, format_args!("{self}"));
                w.1 && w.0.is_empty()
            }
        }
        impl PartialEq<&str> for $t {
            fn eq(&self, other: &&str) -> bool {
                self == *other
            }
        }
    };
}

mod operator;
mod stop;
pub use operator::{OperatorEvent, StartBy};
pub use stop::StopEvent;

/// What became of a vehicle command (`CommandRecord.result`).
#[derive(Debug, Clone, PartialEq)]
pub enum CommandOutcome {
    /// `ACCEPTED`: the autopilot acknowledged it.
    Accepted,
    /// `ACCEPTED (verified N items)`: a mission upload read back and found equal.
    AcceptedVerified {
        /// Mission items read back from the autopilot.
        items: usize,
    },
    /// `SIMULATED`: flown in the simulated world.
    Simulated,
    /// `SENT`: sent, no answer expected or not yet due.
    Sent,
    /// `IN_PROGRESS`: the autopilot is still working on it.
    InProgress,
    /// `PENDING`.
    Pending,
    /// `WAITING_READY (why)`: held until the autopilot reports ready.
    WaitingReady(String),
    /// `NOT_READY (why)`: not sent, the autopilot says it is not ready.
    NotReady(String),
    /// `ALREADY`: the vehicle was already in the asked state.
    Already,
    /// `SKIPPED (why)`: not sent on purpose.
    Skipped(String),
    /// `SUPERSEDED`: a newer action set replaced it.
    Superseded,
    /// `NOT_SENT (why)`.
    NotSent(String),
    /// `CANCELLED` (the autopilot's MAV_RESULT) or `CANCELLED (why)` (commanding stopped).
    Cancelled(Option<String>),
    /// `UNMAPPED (not in commands.toml)`.
    Unmapped,
    /// `DENIED`.
    Denied,
    /// `TEMPORARILY_REJECTED` after every attempt.
    TemporarilyRejected,
    /// `UNSUPPORTED`.
    Unsupported,
    /// `TIMEOUT` (no answer after every attempt) or `TIMEOUT (why)` (the zone not reached in time).
    Timeout(Option<String>),
    /// `ARRIVED (where)`: the vehicle reached the landing zone.
    Arrived(String),
    /// `NOT_CONFIRMED (why)`: accepted, but no HEARTBEAT showed the mode in time (PX4); sent
    /// again while the vehicle stays in its earlier mode.
    NotConfirmed(String),
    /// `FAILED` or `FAILED (why)`.
    Failed(Option<String>),
    /// Any other spelling, kept whole (an autopilot's other MAV_RESULT, a newer log's word).
    Other(String),
}

impl Default for CommandOutcome {
    fn default() -> Self {
        CommandOutcome::Other(String::new())
    }
}

impl fmt::Display for CommandOutcome {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use CommandOutcome::*;
        match self {
            Accepted => f.write_str("ACCEPTED"),
            AcceptedVerified { items } => write!(f, "ACCEPTED (verified {items} items)"),
            Simulated => f.write_str("SIMULATED"),
            Sent => f.write_str("SENT"),
            InProgress => f.write_str("IN_PROGRESS"),
            Pending => f.write_str("PENDING"),
            WaitingReady(why) => write!(f, "WAITING_READY ({why})"),
            NotConfirmed(why) => write!(f, "NOT_CONFIRMED ({why})"),
            NotReady(why) => write!(f, "NOT_READY ({why})"),
            Already => f.write_str("ALREADY"),
            Skipped(why) => write!(f, "SKIPPED ({why})"),
            Superseded => f.write_str("SUPERSEDED"),
            NotSent(why) => write!(f, "NOT_SENT ({why})"),
            Cancelled(None) => f.write_str("CANCELLED"),
            Cancelled(Some(why)) => write!(f, "CANCELLED ({why})"),
            Unmapped => f.write_str("UNMAPPED (not in commands.toml)"),
            Denied => f.write_str("DENIED"),
            TemporarilyRejected => f.write_str("TEMPORARILY_REJECTED"),
            Unsupported => f.write_str("UNSUPPORTED"),
            Timeout(None) => f.write_str("TIMEOUT"),
            Timeout(Some(why)) => write!(f, "TIMEOUT ({why})"),
            Arrived(at) => write!(f, "ARRIVED ({at})"),
            Failed(None) => f.write_str("FAILED"),
            Failed(Some(why)) => write!(f, "FAILED ({why})"),
            Other(s) => f.write_str(s),
        }
    }
}

eq_sentence!(CommandOutcome);

/// The sentence of [`Event::NewFlight`].
const NEW_FLIGHT: &str = "flight over: landed and disarmed; waiting for the operator";

/// How [`Event::StartedInFlight`] and [`Event::ResumedInFlight`] begin.
pub const STARTED_IN_FLIGHT: &str = "started in flight: ";

/// How [`Event::RouteReplanned`] begins.
pub const ROUTE_REPLANNED: &str = "companion: route re-planned at the autopilot's cruise ";

/// What triggered or happened at a cycle (`DecisionRecord.events`).
#[derive(Debug, PartialEq)]
pub enum Event {
    /// `target detected`
    TargetDetected,
    /// `target lost`
    TargetLost,
    /// `obstacle detected`
    ObstacleDetected,
    /// `obstacle cleared`
    ObstacleCleared,
    /// `obstacle avoided` (simulate)
    ObstacleAvoided,
    /// `collision` (simulate)
    Collision,
    /// `'T' zone found` (simulate)
    TZoneFound,
    /// `emergency zone found` (simulate)
    EmergencyZoneFound,
    /// `landing` (simulate)
    Landing,
    /// `battery exhausted` (simulate)
    BatteryExhausted,
    /// `armed`
    Armed,
    /// `disarmed`
    Disarmed,
    /// `mode NAME`: the autopilot's flight mode changed.
    Mode(String),
    /// `waypoint N`: the autopilot reached mission item N.
    Waypoint(u16),
    /// `battery below N%`: a threshold of params' telemetry section crossed.
    BatteryBelow(f64),
    /// `link connected`, `link regained`, `link lost`, `autopilot rebooted`,
    /// `transport reconnected`: the link events that also matter to the decision.
    Link(LinkEvent),
    /// `command ACTION OUTCOME`: a vehicle command finished.
    Command {
        /// Primitive action the command carried out (`take_off`, `land`, ...).
        action: String,
        /// What the autopilot answered, or that it did not.
        outcome: CommandOutcome,
    },
    /// `health: ERROR`: the health models could not be evaluated.
    HealthError(String),
    /// `arbitration: ERROR`: the behaviour conflicts could not be resolved.
    ArbitrationError(String),
    /// `resources: ERROR`: no resource policy to arbitrate with.
    ResourcesError(String),
    /// `MDP: state `STATE` unknown to this MDP`.
    MdpStateUnknown {
        /// MDP name from params.
        mdp: String,
        /// Mission state the MDP has no local state for.
        state: String,
    },
    /// `MDP: ERROR`: an MDP could not be instantiated or solved this cycle (a probability it
    /// reads missing or out of [0, 1], a policy it has no rewards for, an invalid model).
    MdpError {
        /// MDP name from params.
        mdp: String,
        /// What went wrong (the error's sentence).
        error: String,
    },
    /// `re-allocation: REASON`: PANORAMA re-allocated the remaining activities.
    Reallocation(String),
    /// `APP FROM -> TO: REASON`: the resource arbitration started placing an application in a
    /// lower version (said when it starts, not on every cycle it lasts).
    Degraded(super::Degraded),
    /// `APP VERSION: REASON`: the resource arbitration started leaving an application out.
    Dropped(super::Dropped),
    /// `guarantee: no allocation meets the goals`
    GuaranteeInfeasible,
    /// `WHY: land`: the fly shell ended the mission on its own rule (not a model's proposal)
    /// and flies `land` (`DecisionRecord.shell_actions`).
    ShellLand(String),
    /// `landing: ACTION again (the landing was interrupted or not done)`: the fly shell keeps
    /// flying the landing chosen until the vehicle is down.
    LandingKept(String),
    /// `flight over: landed and disarmed; waiting for the operator`: the fly shell starts a
    /// fresh core for the next flight at this cycle (replay restarts its core there).
    NewFlight,
    /// `operator: ...`: the fly shell's operator gate decided, or heard a ground station.
    Operator(OperatorEvent),
    /// `companion stopping ...`: the fly shell's stop, and the hand-off's outcome.
    Stop(StopEvent),
    /// `started in flight: the vehicle is FOUND; DOES`: `fly` started with the vehicle in the
    /// air, and what it does about it (hand-off, proof of its own flight, not resumed).
    StartedInFlight {
        /// What the vehicle was found doing (armed, landed state, altitude, mode).
        found_as: String,
        /// What the companion does about it, in words.
        does: String,
    },
    /// `started in flight: resumed on the operator's consent (MISSION_START from SYS/COMP): the
    /// vehicle is FOUND; FACTS`: the companion resumed its own flight.
    ResumedInFlight {
        /// MAVLink system id of the consenting ground station.
        system: u8,
        /// MAVLink component id of the consenting ground station.
        component: u8,
        /// What the vehicle was found doing.
        found_as: String,
        /// Why the flight is the companion's own (the proof's facts).
        facts: Vec<String>,
    },
    /// `performance drift: ACTIVITY measured M J against P J predicted in T s (xR, beyond
    /// TOL %); remaining energy estimates xS`: the activity's power left the tolerance.
    PerformanceDrift {
        /// Activity flown.
        activity: String,
        /// Energy measured so far in the activity (J).
        measured_j: f64,
        /// Energy predicted for the same time (J).
        predicted_j: f64,
        /// Time in the activity (s).
        activity_s: f64,
        /// Measured over predicted.
        ratio: f64,
        /// The tolerance passed (percent).
        tolerance_pct: f64,
        /// The factor the remaining activities' energy estimates now carry.
        energy_scale: f64,
    },
    /// `guarantee: no alternative carrying VERSIONS meets the goals: PROBABILITIES capped at P`
    VersionsCapped {
        /// Versions no feasible alternative carries.
        versions: Vec<String>,
        /// Probabilities their activation nodes publish, capped.
        capped: Vec<String>,
        /// The cap (the mission's `infeasible_p_battery`).
        at: f64,
    },
    /// `companion: route re-planned at the autopilot's cruise C m/s (params W): PLAN`: `fly`
    /// planned its route again at the autopilot's cruise speed (replay plans again at `cruise_mps`).
    RouteReplanned {
        /// The autopilot's cruise speed as read (m/s).
        cruise_mps: f64,
        /// The cruise speed planned before (m/s).
        was_mps: f64,
        /// `E kJ T s`, or `no allocation meets the goals`.
        plan: String,
    },
    /// `companion: route not re-planned at C m/s: WHY`
    RouteNotReplanned {
        /// The autopilot's cruise speed as read (m/s).
        cruise_mps: f64,
        /// Why the route could not be derived at it.
        why: String,
    },
    /// `companion: mission planned from the autopilot's home (FROM): N activities, E kJ T s`
    MissionPlannedFromHome {
        /// The home used, in words.
        home: String,
        /// Activities planned.
        activities: usize,
        /// Planned energy (J), when the guarantee planned it.
        energy_j: Option<f64>,
        /// Planned duration (s), when the guarantee planned it.
        duration_s: Option<f64>,
    },
    /// `companion: WHAT: SUMMARY`: the autopilot's mission planned, changed or re-planned.
    AutopilotMissionPlanned {
        /// `mission planned`, `mission changed, re-planned`, `mission re-planned at ...`.
        what: String,
        /// Activities, length, planned energy and time, the params speeds used.
        summary: String,
    },
    /// `companion: mission changed, re-planned from the point reached (item SEQ): K activities
    /// flown kept, L left M m`
    MissionReplannedFromPoint {
        /// Mission item reached.
        item: usize,
        /// Activities flown, kept.
        kept: usize,
        /// Activities left.
        left: usize,
        /// Length left (m).
        left_m: f64,
    },
    /// `companion: mission refused: WHY`: the mission could not be planned.
    MissionRefused(String),
    /// `(N more events since the last cycle: R repeats, K not listed)`: a flood summarised.
    EventsNotListed {
        /// Events left out.
        more: usize,
        /// Of which repeats.
        repeats: usize,
        /// Of which distinct, not listed.
        not_listed: usize,
    },
    /// Free text: a scenario's hazard, a resource degradation, an MDP's error, a shell's or
    /// operator's sentence, or a spelling this build does not know.
    Other(String),
}

// `Clone` is written out so that `clone_from` keeps the destination's text buffer when both
// are the same variant: the decision cycle copies the observed events into a reused record
// (`Core::step_into`), and a scenario's event held over cycles then allocates nothing.
impl Clone for Event {
    fn clone(&self) -> Self {
        use Event::*;
        match self {
            TargetDetected => TargetDetected,
            TargetLost => TargetLost,
            ObstacleDetected => ObstacleDetected,
            ObstacleCleared => ObstacleCleared,
            ObstacleAvoided => ObstacleAvoided,
            Collision => Collision,
            TZoneFound => TZoneFound,
            EmergencyZoneFound => EmergencyZoneFound,
            Landing => Landing,
            BatteryExhausted => BatteryExhausted,
            Armed => Armed,
            Disarmed => Disarmed,
            Mode(m) => Mode(m.clone()),
            Waypoint(n) => Waypoint(*n),
            BatteryBelow(t) => BatteryBelow(*t),
            Link(l) => Link(l.clone()),
            Command { action, outcome } => Command {
                action: action.clone(),
                outcome: outcome.clone(),
            },
            HealthError(e) => HealthError(e.clone()),
            ArbitrationError(e) => ArbitrationError(e.clone()),
            ResourcesError(e) => ResourcesError(e.clone()),
            MdpStateUnknown { mdp, state } => MdpStateUnknown {
                mdp: mdp.clone(),
                state: state.clone(),
            },
            MdpError { mdp, error } => MdpError {
                mdp: mdp.clone(),
                error: error.clone(),
            },
            Reallocation(r) => Reallocation(r.clone()),
            Degraded(d) => Degraded(d.clone()),
            Dropped(d) => Dropped(d.clone()),
            GuaranteeInfeasible => GuaranteeInfeasible,
            ShellLand(w) => ShellLand(w.clone()),
            LandingKept(a) => LandingKept(a.clone()),
            NewFlight => NewFlight,
            Operator(o) => Operator(o.clone()),
            Stop(s) => Stop(s.clone()),
            StartedInFlight { found_as, does } => StartedInFlight {
                found_as: found_as.clone(),
                does: does.clone(),
            },
            ResumedInFlight {
                system,
                component,
                found_as,
                facts,
            } => ResumedInFlight {
                system: *system,
                component: *component,
                found_as: found_as.clone(),
                facts: facts.clone(),
            },
            PerformanceDrift {
                activity,
                measured_j,
                predicted_j,
                activity_s,
                ratio,
                tolerance_pct,
                energy_scale,
            } => PerformanceDrift {
                activity: activity.clone(),
                measured_j: *measured_j,
                predicted_j: *predicted_j,
                activity_s: *activity_s,
                ratio: *ratio,
                tolerance_pct: *tolerance_pct,
                energy_scale: *energy_scale,
            },
            VersionsCapped {
                versions,
                capped,
                at,
            } => VersionsCapped {
                versions: versions.clone(),
                capped: capped.clone(),
                at: *at,
            },
            RouteReplanned {
                cruise_mps,
                was_mps,
                plan,
            } => RouteReplanned {
                cruise_mps: *cruise_mps,
                was_mps: *was_mps,
                plan: plan.clone(),
            },
            RouteNotReplanned { cruise_mps, why } => RouteNotReplanned {
                cruise_mps: *cruise_mps,
                why: why.clone(),
            },
            MissionPlannedFromHome {
                home,
                activities,
                energy_j,
                duration_s,
            } => MissionPlannedFromHome {
                home: home.clone(),
                activities: *activities,
                energy_j: *energy_j,
                duration_s: *duration_s,
            },
            AutopilotMissionPlanned { what, summary } => AutopilotMissionPlanned {
                what: what.clone(),
                summary: summary.clone(),
            },
            MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            } => MissionReplannedFromPoint {
                item: *item,
                kept: *kept,
                left: *left,
                left_m: *left_m,
            },
            MissionRefused(w) => MissionRefused(w.clone()),
            EventsNotListed {
                more,
                repeats,
                not_listed,
            } => EventsNotListed {
                more: *more,
                repeats: *repeats,
                not_listed: *not_listed,
            },
            Other(s) => Other(s.clone()),
        }
    }

    fn clone_from(&mut self, src: &Self) {
        use Event::*;
        match (self, src) {
            (Mode(d), Mode(s))
            | (HealthError(d), HealthError(s))
            | (ArbitrationError(d), ArbitrationError(s))
            | (ResourcesError(d), ResourcesError(s))
            | (Reallocation(d), Reallocation(s))
            | (ShellLand(d), ShellLand(s))
            | (LandingKept(d), LandingKept(s))
            | (Other(d), Other(s)) => d.clone_from(s),
            (
                Command { action, outcome },
                Command {
                    action: a,
                    outcome: o,
                },
            ) => {
                action.clone_from(a);
                outcome.clone_from(o);
            }
            (MdpStateUnknown { mdp, state }, MdpStateUnknown { mdp: m, state: st }) => {
                mdp.clone_from(m);
                state.clone_from(st);
            }
            (d, s) => *d = s.clone(),
        }
    }
}

impl Default for Event {
    fn default() -> Self {
        Event::Other(String::new())
    }
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use Event::*;
        match self {
            TargetDetected => f.write_str("target detected"),
            TargetLost => f.write_str("target lost"),
            ObstacleDetected => f.write_str("obstacle detected"),
            ObstacleCleared => f.write_str("obstacle cleared"),
            ObstacleAvoided => f.write_str("obstacle avoided"),
            Collision => f.write_str("collision"),
            TZoneFound => f.write_str("'T' zone found"),
            EmergencyZoneFound => f.write_str("emergency zone found"),
            Landing => f.write_str("landing"),
            BatteryExhausted => f.write_str("battery exhausted"),
            Armed => f.write_str("armed"),
            Disarmed => f.write_str("disarmed"),
            Mode(m) => write!(f, "mode {m}"),
            Waypoint(n) => write!(f, "waypoint {n}"),
            BatteryBelow(t) => write!(f, "battery below {t}%"),
            Link(l) => l.fmt(f),
            Command { action, outcome } => write!(f, "command {action} {outcome}"),
            HealthError(e) => write!(f, "health: {e}"),
            ArbitrationError(e) => write!(f, "arbitration: {e}"),
            ResourcesError(e) => write!(f, "resources: {e}"),
            MdpStateUnknown { mdp, state } => {
                write!(f, "{mdp}: state `{state}` unknown to this MDP")
            }
            MdpError { mdp, error } => write!(f, "{mdp}: {error}"),
            Reallocation(r) => write!(f, "re-allocation: {r}"),
            Degraded(d) => d.fmt(f),
            Dropped(d) => d.fmt(f),
            GuaranteeInfeasible => f.write_str("guarantee: no allocation meets the goals"),
            ShellLand(why) => write!(f, "{why}: land"),
            LandingKept(action) => write!(
                f,
                "landing: {action} again (the landing was interrupted or not done)"
            ),
            NewFlight => f.write_str(NEW_FLIGHT),
            Operator(o) => o.fmt(f),
            Stop(s) => s.fmt(f),
            StartedInFlight { found_as, does } => {
                write!(f, "{STARTED_IN_FLIGHT}the vehicle is {found_as}; {does}")
            }
            ResumedInFlight {
                system,
                component,
                found_as,
                facts,
            } => write!(
                f,
                "{STARTED_IN_FLIGHT}resumed on the operator's consent (MISSION_START from {system}/{component}): the vehicle is {found_as}; {}",
                facts.join("; ")
            ),
            PerformanceDrift {
                activity,
                measured_j,
                predicted_j,
                activity_s,
                ratio,
                tolerance_pct,
                energy_scale,
            } => write!(
                f,
                "performance drift: {activity} measured {measured_j:.0} J against {predicted_j:.0} J predicted in {activity_s:.0} s (x{ratio:.2}, beyond {tolerance_pct:.0} %); remaining energy estimates x{energy_scale:.2}"
            ),
            VersionsCapped {
                versions,
                capped,
                at,
            } => write!(
                f,
                "guarantee: no alternative carrying {} meets the goals: {} capped at {at}",
                versions.join(", "),
                capped.join(", ")
            ),
            RouteReplanned {
                cruise_mps,
                was_mps,
                plan,
            } => write!(
                f,
                "{ROUTE_REPLANNED}{cruise_mps} m/s (params {was_mps}): {plan}"
            ),
            RouteNotReplanned { cruise_mps, why } => write!(
                f,
                "companion: route not re-planned at {cruise_mps:.1} m/s: {why}"
            ),
            MissionPlannedFromHome {
                home,
                activities,
                energy_j,
                duration_s,
            } => write!(
                f,
                "companion: mission planned from the autopilot's home ({home}): {activities} activities, {:.1} kJ {:.0} s",
                energy_j.unwrap_or(f64::NAN) / 1000.0,
                duration_s.unwrap_or(f64::NAN)
            ),
            AutopilotMissionPlanned { what, summary } => {
                write!(f, "companion: {what}: {summary}")
            }
            MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            } => write!(
                f,
                "companion: mission changed, re-planned from the point reached (item {item}): {kept} activities flown kept, {left} left {left_m:.0} m"
            ),
            MissionRefused(why) => write!(f, "companion: mission refused: {why}"),
            EventsNotListed {
                more,
                repeats,
                not_listed,
            } => write!(
                f,
                "({more} more events since the last cycle: {repeats} repeats, {not_listed} not listed)"
            ),
            Other(s) => f.write_str(s),
        }
    }
}

impl Event {
    /// Written by the fly shell on its own safety rules, after the core's events.
    pub fn is_shell(&self) -> bool {
        matches!(self, Event::ShellLand(_) | Event::LandingKept(_))
    }
}

eq_sentence!(Event);

/// What happened on the MAVLink link or its transport (`DecisionRecord.link_events`, fly only).
#[derive(Debug, Clone, PartialEq)]
pub enum LinkEvent {
    /// `link connected`: the first heartbeat of the autopilot.
    Connected,
    /// `link regained`
    Regained,
    /// `link lost`: no message from the autopilot for the link timeout.
    Lost,
    /// `autopilot rebooted`
    Rebooted,
    /// `transport reconnected`
    TransportReconnected,
    /// `autopilot SYS/COMP (FLAVOR)`: the autopilot this link commands.
    Autopilot {
        /// MAVLink system id of the autopilot.
        system: u8,
        /// MAVLink component id of the autopilot.
        component: u8,
        /// Autopilot family read from its HEARTBEAT, as the link's `Flavor` prints it.
        flavor: String,
    },
    /// `another autopilot SYS/COMP heard, ignored (WHY)`
    OtherAutopilot {
        /// MAVLink system id of the ignored autopilot.
        system: u8,
        /// MAVLink component id of the ignored autopilot.
        component: u8,
        /// Why it is ignored (the autopilot already chosen, or the `--autopilot-sysid` asked for).
        why: String,
    },
    /// `autopilot: TEXT`: the autopilot's STATUSTEXT.
    AutopilotText(String),
    /// `stream NAME: OUTCOME`: a telemetry stream request answered.
    Stream {
        /// Telemetry message requested (`ATTITUDE`, `GPS_RAW_INT`, ...).
        name: String,
        /// How the autopilot answered the interval request.
        outcome: CommandOutcome,
    },
    /// `mission uploaded (N items), verifying`
    MissionUploaded {
        /// Number of mission items the upload sent.
        items: usize,
    },
    /// `mission transfer cancelled (WHY)`
    MissionTransferCancelled(String),
    /// `connected NAME`: the transport to the autopilot is up.
    TransportConnected(String),
    /// `disconnected: WHY`
    TransportDisconnected(String),
    /// `onboard connected NAME`: the onboard applications' transport is up.
    OnboardConnected(String),
    /// `onboard disconnected: WHY`
    OnboardDisconnected(String),
    /// Free text (the ingest's bad-input report, a transport's note) or a spelling this build
    /// does not know.
    Other(String),
}

impl Default for LinkEvent {
    fn default() -> Self {
        LinkEvent::Other(String::new())
    }
}

impl fmt::Display for LinkEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use LinkEvent::*;
        match self {
            Connected => f.write_str("link connected"),
            Regained => f.write_str("link regained"),
            Lost => f.write_str("link lost"),
            Rebooted => f.write_str("autopilot rebooted"),
            TransportReconnected => f.write_str("transport reconnected"),
            Autopilot {
                system,
                component,
                flavor,
            } => write!(f, "autopilot {system}/{component} ({flavor})"),
            OtherAutopilot {
                system,
                component,
                why,
            } => write!(
                f,
                "another autopilot {system}/{component} heard, ignored ({why})"
            ),
            AutopilotText(t) => write!(f, "autopilot: {t}"),
            Stream { name, outcome } => write!(f, "stream {name}: {outcome}"),
            MissionUploaded { items } => write!(f, "mission uploaded ({items} items), verifying"),
            MissionTransferCancelled(why) => write!(f, "mission transfer cancelled ({why})"),
            TransportConnected(n) => write!(f, "connected {n}"),
            TransportDisconnected(why) => write!(f, "disconnected: {why}"),
            OnboardConnected(n) => write!(f, "onboard connected {n}"),
            OnboardDisconnected(why) => write!(f, "onboard disconnected: {why}"),
            Other(s) => f.write_str(s),
        }
    }
}

impl LinkEvent {
    /// The link events that are also the cycle's events (the decision sees them).
    pub fn is_significant(&self) -> bool {
        use LinkEvent::*;
        matches!(
            self,
            Connected | Regained | Lost | Rebooted | TransportReconnected
        )
    }
}

eq_sentence!(LinkEvent);

/// At most this many link events in one record (as for events): a flood of STATUSTEXT from the
/// autopilot is summarised, not copied, so it cannot make the record too large to log.
pub const MAX_LINK_EVENTS: usize = 64;

/// Over [`MAX_LINK_EVENTS`]: repeated link events once each (in first-seen order), at most
/// [`MAX_LINK_EVENTS`], then one `Other` line with the count of the rest: `(N more link events
/// since the last cycle: R repeats, K not listed)`. At or under the cap they stay as they came
/// (order and repeats: `link lost`, `link regained`, `link lost` is a story).
pub fn coalesce_link_events(events: &mut Vec<LinkEvent>) {
    if events.len() <= MAX_LINK_EVENTS {
        return;
    }
    if let Some((more, repeats, not_listed)) = dedupe_capped(events, MAX_LINK_EVENTS) {
        events.push(LinkEvent::Other(format!(
            "({more} more link events since the last cycle: {repeats} repeats, {not_listed} not listed)"
        )));
    }
}

/// Repeated items once each (by their text, in first-seen order), at most `max` kept. When any
/// were dropped: (how many, of which repeats, of which distinct but not listed), for the line
/// that says so (the record's events and link events both summarise a flood this way).
pub fn dedupe_capped<T: std::fmt::Display>(
    items: &mut Vec<T>,
    max: usize,
) -> Option<(usize, usize, usize)> {
    let total = items.len();
    let mut seen = std::collections::HashSet::with_capacity(total.min(4 * max));
    items.retain(|e| seen.insert(e.to_string()));
    let unique = items.len();
    items.truncate(max);
    (items.len() < total).then(|| (total - items.len(), total - unique, unique - items.len()))
}

impl From<LinkEvent> for Event {
    fn from(l: LinkEvent) -> Self {
        if l.is_significant() {
            Event::Link(l)
        } else {
            Event::Other(l.to_string())
        }
    }
}

#[cfg(test)]
mod tests;
