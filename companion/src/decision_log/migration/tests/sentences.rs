//! Schema-1 sentences read back as the variants that said them.

use super::*;
use companion_core::record::strategies::{
    event_from_sentence as event_strategy, link_event as link_event_strategy,
    outcome as outcome_strategy,
};
use proptest::prelude::*;

proptest! {
    /// Every outcome's schema-1 sentence reads back as itself.
    #[test]
    fn command_outcome_reads_back_as_written(o in outcome_strategy()) {
        prop_assert_eq!(outcome(&o.to_string()), o);
    }

    #[test]
    fn link_event_reads_back_as_written(e in link_event_strategy()) {
        prop_assert_eq!(link_event(&e.to_string()), e);
    }

    #[test]
    fn event_reads_back_as_written(e in event_strategy()) {
        prop_assert_eq!(event(&e.to_string()), e);
    }

    /// Any string at all (an older log, free text) reads without failing and says the same
    /// sentence again.
    #[test]
    fn any_string_writes_back_unchanged(s in ".{0,60}") {
        prop_assert_eq!(event(&s).to_string(), s.clone());
        prop_assert_eq!(link_event(&s).to_string(), s.clone());
        prop_assert_eq!(outcome(&s).to_string(), s.clone());
        prop_assert_eq!(degraded(&s).to_string(), s.clone());
        prop_assert_eq!(dropped(&s).to_string(), s.clone());
    }
}

/// The sentences producers have always written read as their variants, not as `Other`.
#[test]
fn known_sentences_read_as_their_variants() {
    use CommandOutcome as O;
    for (s, o) in [
        (
            "ACCEPTED (verified 4 items)",
            O::AcceptedVerified { items: 4 },
        ),
        (
            "WAITING_READY (gps; ekf)",
            O::WaitingReady("gps; ekf".into()),
        ),
        ("CANCELLED", O::Cancelled(None)),
        (
            "CANCELLED (pilot took control)",
            O::Cancelled(Some("pilot took control".into())),
        ),
        (
            // Older logs' Debug text of a cancelled transfer: the cancel it was.
            "FAILED (Cancelled(\"link lost\"))",
            O::Cancelled(Some("link lost".into())),
        ),
        ("UNMAPPED (not in commands.toml)", O::Unmapped),
        (
            "TIMEOUT (not within 5.0 m of the zone after 60 s; landing here)",
            O::Timeout(Some(
                "not within 5.0 m of the zone after 60 s; landing here".into(),
            )),
        ),
        (
            "ARRIVED (2.1 m from the zone)",
            O::Arrived("2.1 m from the zone".into()),
        ),
        ("COMMAND_LONG_ONLY", O::Other("COMMAND_LONG_ONLY".into())),
        (
            "UNMAPPED (something else)",
            O::Other("UNMAPPED (something else)".into()),
        ),
    ] {
        assert_eq!(outcome(s), o, "{s}");
    }
    for (s, e) in [
        (
            "command take_off ACCEPTED",
            Event::Command {
                action: "take_off".into(),
                outcome: O::Accepted,
            },
        ),
        (
            "command mission FAILED",
            Event::Command {
                action: "mission".into(),
                outcome: O::Failed(None),
            },
        ),
        ("battery below 30%", Event::BatteryBelow(30.0)),
        ("battery below 27.5%", Event::BatteryBelow(27.5)),
        ("waypoint 3", Event::Waypoint(3)),
        ("link lost", Event::Link(LinkEvent::Lost)),
        (
            "tracking: state `v9` unknown to this MDP",
            Event::MdpStateUnknown {
                mdp: "tracking".into(),
                state: "v9".into(),
            },
        ),
        (
            "guarantee: no allocation meets the goals",
            Event::GuaranteeInfeasible,
        ),
        (
            "tracking: probability P_V3 not provided",
            Event::MdpError {
                mdp: "tracking".into(),
                error: "probability P_V3 not provided".into(),
            },
        ),
        (
            "landing: probability P_appZ = 1.5 not in [0, 1]",
            Event::MdpError {
                mdp: "landing".into(),
                error: "probability P_appZ = 1.5 not in [0, 1]".into(),
            },
        ),
        (
            "navigation: unknown policy 'fast'",
            Event::MdpError {
                mdp: "navigation".into(),
                error: "unknown policy 'fast'".into(),
            },
        ),
        // Free text with a colon stays free text.
        (
            "operator: probability of rain high",
            Event::Other("operator: probability of rain high".into()),
        ),
        (
            "mission: search time 120 s over, target not found: land",
            Event::ShellLand("mission: search time 120 s over, target not found".into()),
        ),
        (
            "landing: land_at_zone again (the landing was interrupted or not done)",
            Event::LandingKept("land_at_zone".into()),
        ),
        // As fly has always written it (logs before the variant): read as the variant.
        (
            "flight over: landed and disarmed; waiting for the operator",
            Event::NewFlight,
        ),
        ("vibrations", Event::Other("vibrations".into())),
        ("waypoint 03", Event::Other("waypoint 03".into())),
        (
            "battery below 30.0%",
            Event::Other("battery below 30.0%".into()),
        ),
    ] {
        assert_eq!(event(s), e, "{s}");
    }
    for (s, e) in [
        (
            "autopilot 1/1 (ArduPilot)",
            LinkEvent::Autopilot {
                system: 1,
                component: 1,
                flavor: "ArduPilot".into(),
            },
        ),
        (
            "another autopilot 7/1 heard, ignored (not the chosen one)",
            LinkEvent::OtherAutopilot {
                system: 7,
                component: 1,
                why: "not the chosen one".into(),
            },
        ),
        (
            "autopilot: PreArm: GPS",
            LinkEvent::AutopilotText("PreArm: GPS".into()),
        ),
        (
            "stream GPS_RAW_INT: ACCEPTED",
            LinkEvent::Stream {
                name: "GPS_RAW_INT".into(),
                outcome: O::Accepted,
            },
        ),
        (
            "mission uploaded (4 items), verifying",
            LinkEvent::MissionUploaded { items: 4 },
        ),
        (
            "connected tcp:127.0.0.1:5760",
            LinkEvent::TransportConnected("tcp:127.0.0.1:5760".into()),
        ),
        (
            "onboard disconnected: refused",
            LinkEvent::OnboardDisconnected("refused".into()),
        ),
        (
            "autopilot 300/1 (PX4)",
            LinkEvent::Other("autopilot 300/1 (PX4)".into()),
        ),
    ] {
        assert_eq!(link_event(s), e, "{s}");
    }
}

/// A copy into an event of the same kind keeps its text buffer (the cycle's reused record).

/// A schema-1 record line becomes the schema-2 record the same cycle writes now.
#[test]
fn a_schema_1_record_reads_as_its_typed_values() {
    let mut v: Value = serde_json::from_str(
        r#"{"cycle":3,"events":["target detected","command land TIMEOUT (no answer)","lidar failed",
            "tracking V3 -> V1: insufficient resources","performance drift: x",
            "tracking V2: insufficient resources (no tile); policy safety ranks tracking 5 of 5"],
            "link_events":["link lost","autopilot 1/1 (ArduPilot)"],
            "commands":[{"action":"land","command":"SET_MODE LAND","result":"FAILED (Cancelled(\"link lost\"))"}],
            "resources":{"degraded":["tracking V3 -> V1: insufficient resources"],"dropped":["odd text"]},
            "vehicle":{"world_events_after":["collision"]}}"#,
    )
    .unwrap();
    record_v1(&mut v);
    let r: companion_core::record::DecisionRecord = serde_json::from_value(v).unwrap();
    assert_eq!(
        r.events,
        vec![
            Event::TargetDetected,
            Event::Command {
                action: "land".into(),
                outcome: CommandOutcome::Timeout(Some("no answer".into()))
            },
            Event::Other("lidar failed".into()),
            // The degradation the record's resources hold; free text of the same shape stays text.
            Event::Degraded(res_degraded()),
            Event::Other("performance drift: x".into()),
            // Said by the scheduler though a re-solve cleared the record's `dropped`.
            Event::Dropped(companion_core::record::Dropped {
                app: "tracking".into(),
                version: "V2".into(),
                reason: "insufficient resources (no tile); policy safety ranks tracking 5 of 5"
                    .into(),
            }),
        ]
    );
    assert_eq!(
        r.link_events,
        vec![
            LinkEvent::Lost,
            LinkEvent::Autopilot {
                system: 1,
                component: 1,
                flavor: "ArduPilot".into()
            }
        ]
    );
    // The old-log rule: a cancelled transfer's Debug text is the cancel it was.
    assert_eq!(
        r.commands[0].result,
        CommandOutcome::Cancelled(Some("link lost".into()))
    );
    let res = r.resources.unwrap();
    assert_eq!(
        (res.degraded[0].app.as_str(), res.degraded[0].to.as_str()),
        ("tracking", "V1")
    );
    assert_eq!(
        (res.dropped[0].app.as_str(), res.dropped[0].reason.as_str()),
        ("", "odd text")
    );
    assert_eq!(
        r.vehicle["world_events_after"],
        serde_json::json!([{"kind": "collision", "text": "collision"}])
    );
}

fn res_degraded() -> companion_core::record::Degraded {
    companion_core::record::Degraded {
        app: "tracking".into(),
        from: "V3".into(),
        to: "V1".into(),
        reason: "insufficient resources".into(),
    }
}
