//! Proptest strategies for the record's event types, shared by the core's wire tests
//! (`record/events/tests.rs`) and the companion's schema-1 migration tests
//! (`decision_log/migration/tests`), so both generate the same values. Built for the core's
//! own tests and, through the `test-support` feature, for the companion's dev build only.

use super::events::{CommandOutcome, Event, LinkEvent, OperatorEvent, StartBy, StopEvent};
use proptest::prelude::*;

/// Free text as producers write it: words of letters, digits and the punctuation the
/// sentences use, never empty.
pub fn text() -> impl Strategy<Value = String> {
    "[A-Za-z0-9_./;,%-]{1,8}( [A-Za-z0-9_./;,%-]{1,8}){0,3}"
}

/// One word, as an action, a stream or an MDP is named.
pub fn word() -> impl Strategy<Value = String> {
    "[a-z_0-9]{1,12}"
}

/// Every [`CommandOutcome`].
pub fn outcome() -> impl Strategy<Value = CommandOutcome> {
    use CommandOutcome::*;
    prop_oneof![
        Just(Accepted),
        any::<usize>().prop_map(|items| AcceptedVerified { items }),
        Just(Simulated),
        Just(Sent),
        Just(InProgress),
        Just(Pending),
        text().prop_map(WaitingReady),
        text().prop_map(NotReady),
        Just(Already),
        text().prop_map(Skipped),
        Just(Superseded),
        text().prop_map(NotSent),
        proptest::option::of(text()).prop_map(Cancelled),
        Just(Unmapped),
        Just(Denied),
        Just(TemporarilyRejected),
        Just(Unsupported),
        proptest::option::of(text()).prop_map(Timeout),
        text().prop_map(Arrived),
        text().prop_map(NotConfirmed),
        proptest::option::of(text()).prop_map(Failed),
        "COMMAND_[A-Z_]{1,12}".prop_map(Other),
    ]
}

/// Every [`LinkEvent`].
pub fn link_event() -> impl Strategy<Value = LinkEvent> {
    use LinkEvent::*;
    prop_oneof![
        Just(Connected),
        Just(Regained),
        Just(Lost),
        Just(Rebooted),
        Just(TransportReconnected),
        (any::<u8>(), any::<u8>(), "[A-Za-z]{1,10}").prop_map(|(system, component, flavor)| {
            Autopilot {
                system,
                component,
                flavor,
            }
        }),
        (any::<u8>(), any::<u8>(), text()).prop_map(|(system, component, why)| {
            OtherAutopilot {
                system,
                component,
                why,
            }
        }),
        text().prop_map(AutopilotText),
        (word(), outcome()).prop_map(|(name, outcome)| Stream { name, outcome }),
        any::<usize>().prop_map(|items| MissionUploaded { items }),
        text().prop_map(MissionTransferCancelled),
        text().prop_map(TransportConnected),
        text().prop_map(TransportDisconnected),
        text().prop_map(OnboardConnected),
        text().prop_map(OnboardDisconnected),
        "ingest: [0-9]{1,5} bytes outside valid frames".prop_map(Other),
    ]
}

/// Every way a start comes about.
pub fn start_by() -> impl Strategy<Value = StartBy> {
    proptest::sample::select(StartBy::ALL.to_vec())
}

/// Every [`OperatorEvent`] (its sentence carries all its fields).
pub fn operator_event() -> impl Strategy<Value = OperatorEvent> {
    use OperatorEvent::*;
    let mode = || "[A-Z][A-Z_0-9]{0,11}";
    prop_oneof![
        start_by().prop_map(|by| StartRequested { by }),
        start_by().prop_map(|by| Started { by }),
        (start_by(), text()).prop_map(|(by, why)| StartRefused { by, why }),
        Just(StartVoidedDisarmed),
        text().prop_map(|why| StartVoidedTakeoffFailed { why }),
        mode().prop_map(|mode| TakeoverSuspected { mode }),
        mode().prop_map(|mode| TakenOver { mode }),
        (mode(), mode()).prop_map(|(mode, own)| FalseAlarm { mode, own }),
        // The sentence tells a switch to GUIDED from a start command only.
        prop_oneof![Just(StartBy::GuidedSwitch), Just(StartBy::StartCommand)]
            .prop_map(|by| HandedBack { by }),
        ("MAV_CMD_[A-Z_]{1,12}", any::<u8>(), any::<u8>(), text()).prop_map(
            |(command, system, component, why)| CommandRefused {
                command,
                system,
                component,
                why,
            }
        ),
        (any::<u8>(), any::<u8>(), "[0-9]{1,3}(, [0-9]{1,3}){0,3}").prop_map(
            |(system, component, named)| GroundStationNotNamed {
                system,
                component,
                named,
            }
        ),
        Just(GroundStationLost),
        Just(GroundStationBack),
    ]
}

/// Every [`StopEvent`] (the height is rounded in its sentence).
pub fn stop_event() -> impl Strategy<Value = StopEvent> {
    use StopEvent::*;
    let mode = || "[A-Z][A-Z_0-9]{0,11}";
    let alt = || proptest::option::of(-1e3f64..1e4);
    let up = || proptest::collection::vec("[a-z][a-z0-9 ]{0,15}", 1..3);
    prop_oneof![
        (text(), alt(), mode(), up(), mode()).prop_map(|(why, alt_m, mode, up, handoff)| {
            HandOff {
                why,
                alt_m,
                mode,
                up,
                handoff,
            }
        }),
        (text(), alt(), mode(), up()).prop_map(|(why, alt_m, mode, up)| NoHandOff {
            why,
            alt_m,
            mode,
            up
        }),
        (text(), alt(), mode(), up(), word()).prop_map(|(why, alt_m, mode, up, was)| {
            NotCommanding {
                why,
                alt_m,
                mode,
                up,
                was,
            }
        }),
        (
            text(),
            proptest::collection::vec(("[A-Z_]{1,12}", "[A-Z_]{1,20}"), 0..2)
        )
            .prop_map(|(why, refused)| Down { why, refused }),
        Just(HandOffAccepted),
        Just(HandOffFailed),
        Just(HandOffUnanswered),
    ]
}

/// The fly shell's events whose sentence carries every field (a schema-1 log's sentence reads
/// back as the same value).
fn shell_event_said_whole() -> impl Strategy<Value = Event> {
    use Event::*;
    // What the start found: no `; ` inside (the sentence's separator).
    let found_as = "armed, landed state [A-Z_]{1,9}, altitude [0-9]{1,3}\\.[0-9] m above home, mode [A-Z]{1,8}";
    let fact = "[a-z0-9][a-z0-9 ]{0,19}";
    prop_oneof![
        operator_event().prop_map(Operator),
        (found_as, text()).prop_map(|(found_as, does)| StartedInFlight { found_as, does }),
        (
            any::<u8>(),
            any::<u8>(),
            found_as,
            proptest::collection::vec(fact, 1..4)
        )
            .prop_map(|(system, component, found_as, facts)| ResumedInFlight {
                system,
                component,
                found_as,
                facts,
            }),
        (0.1f64..60.0, 0.1f64..60.0, text()).prop_map(|(cruise_mps, was_mps, plan)| {
            RouteReplanned {
                cruise_mps,
                was_mps,
                plan,
            }
        }),
        text().prop_map(MissionRefused),
        (any::<usize>(), any::<usize>(), any::<usize>()).prop_map(|(more, repeats, not_listed)| {
            EventsNotListed {
                more,
                repeats,
                not_listed,
            }
        }),
    ]
}

/// The events whose sentence rounds a number or joins words: written and read on the wire by
/// their fields, kept whole as text by the schema-1 migration.
fn event_said_rounded() -> impl Strategy<Value = Event> {
    use Event::*;
    let f = || -1e6f64..1e6;
    prop_oneof![
        (word(), (f(), f(), f()), (f(), f(), f())).prop_map(
            |(
                activity,
                (measured_j, predicted_j, activity_s),
                (ratio, tolerance_pct, energy_scale),
            )| {
                PerformanceDrift {
                    activity,
                    measured_j,
                    predicted_j,
                    activity_s,
                    ratio,
                    tolerance_pct,
                    energy_scale,
                }
            }
        ),
        (
            proptest::collection::vec(word(), 1..3),
            proptest::collection::vec(word(), 0..3),
            0.0f64..1.0
        )
            .prop_map(|(versions, capped, at)| VersionsCapped {
                versions,
                capped,
                at,
            }),
        (f(), text()).prop_map(|(cruise_mps, why)| RouteNotReplanned { cruise_mps, why }),
        (
            text(),
            any::<usize>(),
            proptest::option::of(f()),
            proptest::option::of(f())
        )
            .prop_map(|(home, activities, energy_j, duration_s)| {
                MissionPlannedFromHome {
                    home,
                    activities,
                    energy_j,
                    duration_s,
                }
            }),
        (text(), text()).prop_map(|(what, summary)| AutopilotMissionPlanned { what, summary }),
        stop_event().prop_map(Stop),
        (any::<usize>(), any::<usize>(), any::<usize>(), f()).prop_map(
            |(item, kept, left, left_m)| MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            }
        ),
    ]
}

/// The events a schema-1 sentence reads back as (every kind but [`event_said_rounded`]'s).
pub fn event_from_sentence() -> impl Strategy<Value = Event> {
    use Event::*;
    prop_oneof![
        prop_oneof![
            Just(TargetDetected),
            Just(TargetLost),
            Just(ObstacleDetected),
            Just(ObstacleCleared),
            Just(ObstacleAvoided),
            Just(Collision),
            Just(TZoneFound),
            Just(EmergencyZoneFound),
            Just(Landing),
            Just(BatteryExhausted),
            Just(NewFlight),
            Just(Armed),
            Just(Disarmed),
            Just(GuaranteeInfeasible),
        ],
        "[A-Z_]{1,12}".prop_map(Mode),
        any::<u16>().prop_map(Waypoint),
        (-1e6f64..1e6).prop_map(BatteryBelow),
        link_event()
            .prop_filter("significant", LinkEvent::is_significant)
            .prop_map(Link),
        (word(), outcome()).prop_map(|(action, outcome)| Command { action, outcome }),
        text().prop_map(HealthError),
        text().prop_map(ArbitrationError),
        text().prop_map(ResourcesError),
        (word(), "[a-z0-9_]{1,10}").prop_map(|(mdp, state)| MdpStateUnknown { mdp, state }),
        (word(), "probability P_[A-Za-z0-9]{1,6} not provided")
            .prop_map(|(mdp, error)| MdpError { mdp, error }),
        text().prop_map(Reallocation),
        "mission: [a-z ]{1,20}".prop_map(ShellLand),
        word().prop_map(LandingKept),
        "tracking V[0-9] -> V[0-9]: insufficient resources".prop_map(Other),
        shell_event_said_whole(),
    ]
}

/// Every [`Event`].
pub fn event() -> impl Strategy<Value = Event> {
    prop_oneof![event_from_sentence(), event_said_rounded()]
}
