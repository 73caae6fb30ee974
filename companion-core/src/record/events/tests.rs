use super::*;
use crate::record::strategies::{event, link_event, outcome};
use proptest::prelude::*;
use serde::Serialize;

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
    let cases: [(Event, &str); 8] = [
        (
            Event::Operator(OperatorEvent::StartRefused {
                by: StartBy::StartCommand,
                why: "battery 12%".into(),
            }),
            r#"{"kind":"operator","operator":{"kind":"start_refused","by":"start_command","why":"battery 12%","text":"operator: start refused (MAV_CMD_MISSION_START from the ground station): battery 12%; still waiting for the operator"},"text":"operator: start refused (MAV_CMD_MISSION_START from the ground station): battery 12%; still waiting for the operator"}"#,
        ),
        (
            Event::RouteReplanned {
                cruise_mps: 7.5,
                was_mps: 5.0,
                plan: "81.9 kJ 386 s".into(),
            },
            r#"{"kind":"route_replanned","cruise_mps":7.5,"was_mps":5.0,"plan":"81.9 kJ 386 s","text":"companion: route re-planned at the autopilot's cruise 7.5 m/s (params 5): 81.9 kJ 386 s"}"#,
        ),
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
