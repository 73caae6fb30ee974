use super::*;
use proptest::prelude::*;
use serde::Serialize;

/// Free text as producers write it: words of letters, digits and the punctuation the
/// sentences use, never empty.
fn text() -> impl Strategy<Value = String> {
    "[A-Za-z0-9_./;,%-]{1,8}( [A-Za-z0-9_./;,%-]{1,8}){0,3}"
}
fn word() -> impl Strategy<Value = String> {
    "[a-z_0-9]{1,12}"
}

fn outcome() -> impl Strategy<Value = CommandOutcome> {
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

fn link_event() -> impl Strategy<Value = LinkEvent> {
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

fn event() -> impl Strategy<Value = Event> {
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
    ]
}

fn json<T: Serialize>(v: &T) -> String {
    serde_json::to_string(v).unwrap()
}

proptest! {
    /// Every outcome reads back as itself from its schema-2 JSON: an object tagged by `kind`.
    #[test]
    fn command_outcome_reads_back_as_written(o in outcome()) {
        let v = serde_json::to_value(&o).unwrap();
        prop_assert!(v["kind"].is_string(), "{}", v);
        prop_assert_eq!(serde_json::from_str::<CommandOutcome>(&json(&o)).unwrap(), o);
    }

    #[test]
    fn link_event_reads_back_as_written(e in link_event()) {
        let v = serde_json::to_value(&e).unwrap();
        prop_assert!(v["kind"].is_string(), "{}", v);
        prop_assert_eq!(serde_json::from_str::<LinkEvent>(&json(&e)).unwrap(), e);
    }

    #[test]
    fn event_reads_back_as_written(e in event()) {
        let v = serde_json::to_value(&e).unwrap();
        prop_assert!(v["kind"].is_string(), "{}", v);
        prop_assert!(e == e.to_string().as_str());
        prop_assert_eq!(serde_json::from_str::<Event>(&json(&e)).unwrap(), e);
    }
}

/// The wire form names the variant and its fields: what a script reads with `jq`.
#[test]
fn events_are_written_as_objects_with_their_fields() {
    let cases: [(Event, &str); 6] = [
        (
            Event::TargetDetected,
            r#"{"kind":"target_detected","text":"target detected"}"#,
        ),
        (
            Event::Mode("RTL".into()),
            r#"{"kind":"mode","mode":"RTL","text":"mode RTL"}"#,
        ),
        (
            Event::Link(LinkEvent::Lost),
            r#"{"kind":"link","link":{"kind":"lost","text":"link lost"},"text":"link lost"}"#,
        ),
        (
            Event::Command {
                action: "land".into(),
                outcome: CommandOutcome::Timeout(Some("zone not reached".into())),
            },
            r#"{"kind":"command","action":"land","outcome":{"kind":"TIMEOUT","why":"zone not reached","text":"TIMEOUT (zone not reached)"},"text":"command land TIMEOUT (zone not reached)"}"#,
        ),
        (
            Event::Degraded(super::super::Degraded {
                app: "tracking".into(),
                from: "V3".into(),
                to: "V1".into(),
                reason: "no room".into(),
            }),
            r#"{"kind":"degraded","degraded":{"app":"tracking","from":"V3","to":"V1","reason":"no room"},"text":"tracking V3 -> V1: no room"}"#,
        ),
        (
            Event::Other("vibrations".into()),
            r#"{"kind":"other","text":"vibrations"}"#,
        ),
    ];
    for (e, written) in cases {
        assert_eq!(json(&e), written);
        assert_eq!(serde_json::from_str::<Event>(written).unwrap(), e);
    }
    assert_eq!(
        json(&CommandOutcome::Accepted),
        r#"{"kind":"ACCEPTED","text":"ACCEPTED"}"#
    );
    assert_eq!(
        json(&LinkEvent::Stream {
            name: "ATTITUDE".into(),
            outcome: CommandOutcome::Denied
        }),
        r#"{"kind":"stream","name":"ATTITUDE","outcome":{"kind":"DENIED","text":"DENIED"},"text":"stream ATTITUDE: DENIED"}"#
    );
    // A sentence is schema 1: not read here (decision_log::migration reads it).
    assert!(serde_json::from_str::<Event>(r#""target detected""#).is_err());
}

#[test]
fn clone_from_keeps_the_buffer_of_the_same_kind() {
    let src = Event::Other("gps jamming".into());
    let mut dst = Event::Other(String::with_capacity(64));
    let before = match &dst {
        Event::Other(s) => s.as_ptr(),
        _ => unreachable!(),
    };
    dst.clone_from(&src);
    assert_eq!(dst, src);
    assert!(matches!(&dst, Event::Other(s) if s.as_ptr() == before));
    let mut other_kind = Event::TargetLost;
    other_kind.clone_from(&src);
    assert_eq!(other_kind, src);
}

/// `Event == "text"` compares with the written sentence, whole.
#[test]
fn event_equals_its_sentence_only() {
    let e = Event::Mode("AUTO".into());
    assert!(e == "mode AUTO");
    assert!(e != "mode AUT");
    assert!(e != "mode AUTOS");
    assert!(e != "");
}

#[test]
fn a_link_event_flood_is_capped_with_its_count() {
    let mut evs: Vec<LinkEvent> = (0..11_653)
        .map(|i| LinkEvent::AutopilotText(format!("flood {}", i % 10_000)))
        .collect();
    evs.insert(0, LinkEvent::Lost);
    coalesce_link_events(&mut evs);
    assert_eq!(evs.len(), MAX_LINK_EVENTS + 1);
    assert_eq!(evs[0], LinkEvent::Lost, "first seen stays first");
    assert_eq!(evs[1], LinkEvent::AutopilotText("flood 0".into()));
    // 11,654 in; 64 listed; 1,653 repeats; 10,001 distinct of which 9,937 not listed.
    assert_eq!(
        evs[MAX_LINK_EVENTS].to_string(),
        "(11590 more link events since the last cycle: 1653 repeats, 9937 not listed)"
    );
    // Under the cap nothing changes: repeats and order are the link's story.
    let story = vec![LinkEvent::Lost, LinkEvent::Regained, LinkEvent::Lost];
    let mut few = story.clone();
    coalesce_link_events(&mut few);
    assert_eq!(few, story);
}
