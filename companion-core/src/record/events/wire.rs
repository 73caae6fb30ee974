//! How [`Event`], [`LinkEvent`] and [`CommandOutcome`] are written in a schema-2 decision log:
//! a JSON object tagged by `kind`, with the variant's fields by name
//! (`{"kind":"mode","mode":"RTL","text":"mode RTL"}`), `text` being the sentence for people.
//! Each type is written through a borrowed mirror of itself (no copy of its text), and read into
//! an owned one. Schema-1 logs (plain sentences) are read by `companion::decision_log::migration`.

use super::super::{Degraded, Dropped};
use super::{CommandOutcome, Event, LinkEvent, OperatorEvent, StopEvent};
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::borrow::Cow;
use std::fmt;

type Text<'a> = Cow<'a, str>;

fn b(s: &str) -> Text<'_> {
    Cow::Borrowed(s)
}

fn own(s: Text<'_>) -> String {
    s.into_owned()
}

/// The wire form of [`CommandOutcome`]: `kind` is the word the autopilot and the review use
/// (`ACCEPTED`, `DENIED`, ...), the detail a field.
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "SCREAMING_SNAKE_CASE")]
enum OutcomeWire<'a> {
    Accepted,
    AcceptedVerified {
        items: usize,
    },
    Simulated,
    Sent,
    InProgress,
    Pending,
    WaitingReady {
        why: Text<'a>,
    },
    NotReady {
        why: Text<'a>,
    },
    Already,
    Skipped {
        why: Text<'a>,
    },
    Superseded,
    NotSent {
        why: Text<'a>,
    },
    Cancelled {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        why: Option<Text<'a>>,
    },
    Unmapped,
    Denied,
    TemporarilyRejected,
    Unsupported,
    Timeout {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        why: Option<Text<'a>>,
    },
    Arrived {
        at: Text<'a>,
    },
    NotConfirmed {
        why: Text<'a>,
    },
    Failed {
        #[serde(default, skip_serializing_if = "Option::is_none")]
        why: Option<Text<'a>>,
    },
    Other {
        text: Text<'a>,
    },
}

impl<'a> From<&'a CommandOutcome> for OutcomeWire<'a> {
    fn from(o: &'a CommandOutcome) -> Self {
        use CommandOutcome as C;
        use OutcomeWire as W;
        let opt = |x: &'a Option<String>| x.as_deref().map(b);
        match o {
            C::Accepted => W::Accepted,
            C::AcceptedVerified { items } => W::AcceptedVerified { items: *items },
            C::Simulated => W::Simulated,
            C::Sent => W::Sent,
            C::InProgress => W::InProgress,
            C::Pending => W::Pending,
            C::WaitingReady(why) => W::WaitingReady { why: b(why) },
            C::NotReady(why) => W::NotReady { why: b(why) },
            C::Already => W::Already,
            C::Skipped(why) => W::Skipped { why: b(why) },
            C::Superseded => W::Superseded,
            C::NotSent(why) => W::NotSent { why: b(why) },
            C::Cancelled(why) => W::Cancelled { why: opt(why) },
            C::Unmapped => W::Unmapped,
            C::Denied => W::Denied,
            C::TemporarilyRejected => W::TemporarilyRejected,
            C::Unsupported => W::Unsupported,
            C::Timeout(why) => W::Timeout { why: opt(why) },
            C::Arrived(at) => W::Arrived { at: b(at) },
            C::NotConfirmed(why) => W::NotConfirmed { why: b(why) },
            C::Failed(why) => W::Failed { why: opt(why) },
            C::Other(text) => W::Other { text: b(text) },
        }
    }
}

impl From<OutcomeWire<'_>> for CommandOutcome {
    fn from(w: OutcomeWire<'_>) -> Self {
        use CommandOutcome as C;
        use OutcomeWire as W;
        match w {
            W::Accepted => C::Accepted,
            W::AcceptedVerified { items } => C::AcceptedVerified { items },
            W::Simulated => C::Simulated,
            W::Sent => C::Sent,
            W::InProgress => C::InProgress,
            W::Pending => C::Pending,
            W::WaitingReady { why } => C::WaitingReady(own(why)),
            W::NotReady { why } => C::NotReady(own(why)),
            W::Already => C::Already,
            W::Skipped { why } => C::Skipped(own(why)),
            W::Superseded => C::Superseded,
            W::NotSent { why } => C::NotSent(own(why)),
            W::Cancelled { why } => C::Cancelled(why.map(own)),
            W::Unmapped => C::Unmapped,
            W::Denied => C::Denied,
            W::TemporarilyRejected => C::TemporarilyRejected,
            W::Unsupported => C::Unsupported,
            W::Timeout { why } => C::Timeout(why.map(own)),
            W::Arrived { at } => C::Arrived(own(at)),
            W::NotConfirmed { why } => C::NotConfirmed(own(why)),
            W::Failed { why } => C::Failed(why.map(own)),
            W::Other { text } => C::Other(own(text)),
        }
    }
}

/// The wire form of [`LinkEvent`].
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum LinkWire<'a, O> {
    Connected,
    Regained,
    Lost,
    Rebooted,
    TransportReconnected,
    Autopilot {
        system: u8,
        component: u8,
        flavor: Text<'a>,
    },
    OtherAutopilot {
        system: u8,
        component: u8,
        why: Text<'a>,
    },
    AutopilotText {
        statustext: Text<'a>,
    },
    Stream {
        name: Text<'a>,
        outcome: O,
    },
    MissionUploaded {
        items: usize,
    },
    MissionTransferCancelled {
        why: Text<'a>,
    },
    TransportConnected {
        name: Text<'a>,
    },
    TransportDisconnected {
        why: Text<'a>,
    },
    OnboardConnected {
        name: Text<'a>,
    },
    OnboardDisconnected {
        why: Text<'a>,
    },
    Other {
        text: Text<'a>,
    },
}

impl<'a> From<&'a LinkEvent> for LinkWire<'a, &'a CommandOutcome> {
    fn from(l: &'a LinkEvent) -> Self {
        use LinkEvent as L;
        use LinkWire as W;
        match l {
            L::Connected => W::Connected,
            L::Regained => W::Regained,
            L::Lost => W::Lost,
            L::Rebooted => W::Rebooted,
            L::TransportReconnected => W::TransportReconnected,
            L::Autopilot {
                system,
                component,
                flavor,
            } => W::Autopilot {
                system: *system,
                component: *component,
                flavor: b(flavor),
            },
            L::OtherAutopilot {
                system,
                component,
                why,
            } => W::OtherAutopilot {
                system: *system,
                component: *component,
                why: b(why),
            },
            L::AutopilotText(text) => W::AutopilotText {
                statustext: b(text),
            },
            L::Stream { name, outcome } => W::Stream {
                name: b(name),
                outcome,
            },
            L::MissionUploaded { items } => W::MissionUploaded { items: *items },
            L::MissionTransferCancelled(why) => W::MissionTransferCancelled { why: b(why) },
            L::TransportConnected(name) => W::TransportConnected { name: b(name) },
            L::TransportDisconnected(why) => W::TransportDisconnected { why: b(why) },
            L::OnboardConnected(name) => W::OnboardConnected { name: b(name) },
            L::OnboardDisconnected(why) => W::OnboardDisconnected { why: b(why) },
            L::Other(text) => W::Other { text: b(text) },
        }
    }
}

impl From<LinkWire<'_, CommandOutcome>> for LinkEvent {
    fn from(w: LinkWire<'_, CommandOutcome>) -> Self {
        use LinkEvent as L;
        use LinkWire as W;
        match w {
            W::Connected => L::Connected,
            W::Regained => L::Regained,
            W::Lost => L::Lost,
            W::Rebooted => L::Rebooted,
            W::TransportReconnected => L::TransportReconnected,
            W::Autopilot {
                system,
                component,
                flavor,
            } => L::Autopilot {
                system,
                component,
                flavor: own(flavor),
            },
            W::OtherAutopilot {
                system,
                component,
                why,
            } => L::OtherAutopilot {
                system,
                component,
                why: own(why),
            },
            W::AutopilotText { statustext } => L::AutopilotText(own(statustext)),
            W::Stream { name, outcome } => L::Stream {
                name: own(name),
                outcome,
            },
            W::MissionUploaded { items } => L::MissionUploaded { items },
            W::MissionTransferCancelled { why } => L::MissionTransferCancelled(own(why)),
            W::TransportConnected { name } => L::TransportConnected(own(name)),
            W::TransportDisconnected { why } => L::TransportDisconnected(own(why)),
            W::OnboardConnected { name } => L::OnboardConnected(own(name)),
            W::OnboardDisconnected { why } => L::OnboardDisconnected(own(why)),
            W::Other { text } => L::Other(own(text)),
        }
    }
}

/// The wire form of [`Event`]. A link event the decision sees is nested whole
/// (`{"kind":"link","link":{"kind":"lost"}}`), as is a command's outcome.
#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
enum EventWire<'a, L, O, D, X, P, V, S> {
    TargetDetected,
    TargetLost,
    ObstacleDetected,
    ObstacleCleared,
    ObstacleAvoided,
    Collision,
    TZoneFound,
    EmergencyZoneFound,
    Landing,
    BatteryExhausted,
    Armed,
    Disarmed,
    Mode {
        mode: Text<'a>,
    },
    Waypoint {
        seq: u16,
    },
    BatteryBelow {
        threshold_pct: f64,
    },
    Link {
        link: L,
    },
    Command {
        action: Text<'a>,
        outcome: O,
    },
    HealthError {
        error: Text<'a>,
    },
    ArbitrationError {
        error: Text<'a>,
    },
    ResourcesError {
        error: Text<'a>,
    },
    MdpStateUnknown {
        mdp: Text<'a>,
        state: Text<'a>,
    },
    MdpError {
        mdp: Text<'a>,
        error: Text<'a>,
    },
    Reallocation {
        reason: Text<'a>,
    },
    Degraded {
        degraded: D,
    },
    Dropped {
        dropped: X,
    },
    GuaranteeInfeasible,
    ShellLand {
        why: Text<'a>,
    },
    LandingKept {
        action: Text<'a>,
    },
    NewFlight,
    Operator {
        operator: P,
    },
    Stop {
        stop: S,
    },
    StartedInFlight {
        found_as: Text<'a>,
        does: Text<'a>,
    },
    ResumedInFlight {
        system: u8,
        component: u8,
        found_as: Text<'a>,
        facts: V,
    },
    PerformanceDrift {
        activity: Text<'a>,
        measured_j: f64,
        predicted_j: f64,
        activity_s: f64,
        ratio: f64,
        tolerance_pct: f64,
        energy_scale: f64,
    },
    VersionsCapped {
        versions: V,
        capped: V,
        at: f64,
    },
    RouteReplanned {
        cruise_mps: f64,
        was_mps: f64,
        plan: Text<'a>,
    },
    RouteNotReplanned {
        cruise_mps: f64,
        why: Text<'a>,
    },
    MissionPlannedFromHome {
        home: Text<'a>,
        activities: usize,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        energy_j: Option<f64>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        duration_s: Option<f64>,
    },
    AutopilotMissionPlanned {
        what: Text<'a>,
        summary: Text<'a>,
    },
    MissionReplannedFromPoint {
        item: usize,
        kept: usize,
        left: usize,
        left_m: f64,
    },
    MissionRefused {
        why: Text<'a>,
    },
    EventsNotListed {
        more: usize,
        repeats: usize,
        not_listed: usize,
    },
    Other {
        text: Text<'a>,
    },
}

type EventOut<'a> = EventWire<
    'a,
    &'a LinkEvent,
    &'a CommandOutcome,
    &'a Degraded,
    &'a Dropped,
    &'a OperatorEvent,
    &'a [String],
    &'a StopEvent,
>;
type EventIn<'a> = EventWire<
    'a,
    LinkEvent,
    CommandOutcome,
    Degraded,
    Dropped,
    OperatorEvent,
    Vec<String>,
    StopEvent,
>;

impl<'a> From<&'a Event> for EventOut<'a> {
    fn from(e: &'a Event) -> Self {
        use Event as E;
        use EventWire as W;
        match e {
            E::TargetDetected => W::TargetDetected,
            E::TargetLost => W::TargetLost,
            E::ObstacleDetected => W::ObstacleDetected,
            E::ObstacleCleared => W::ObstacleCleared,
            E::ObstacleAvoided => W::ObstacleAvoided,
            E::Collision => W::Collision,
            E::TZoneFound => W::TZoneFound,
            E::EmergencyZoneFound => W::EmergencyZoneFound,
            E::Landing => W::Landing,
            E::BatteryExhausted => W::BatteryExhausted,
            E::Armed => W::Armed,
            E::Disarmed => W::Disarmed,
            E::Mode(m) => W::Mode { mode: b(m) },
            E::Waypoint(n) => W::Waypoint { seq: *n },
            E::BatteryBelow(t) => W::BatteryBelow { threshold_pct: *t },
            E::Link(l) => W::Link { link: l },
            E::Command { action, outcome } => W::Command {
                action: b(action),
                outcome,
            },
            E::HealthError(e) => W::HealthError { error: b(e) },
            E::ArbitrationError(e) => W::ArbitrationError { error: b(e) },
            E::ResourcesError(e) => W::ResourcesError { error: b(e) },
            E::MdpStateUnknown { mdp, state } => W::MdpStateUnknown {
                mdp: b(mdp),
                state: b(state),
            },
            E::MdpError { mdp, error } => W::MdpError {
                mdp: b(mdp),
                error: b(error),
            },
            E::Reallocation(r) => W::Reallocation { reason: b(r) },
            E::Degraded(d) => W::Degraded { degraded: d },
            E::Dropped(d) => W::Dropped { dropped: d },
            E::GuaranteeInfeasible => W::GuaranteeInfeasible,
            E::ShellLand(why) => W::ShellLand { why: b(why) },
            E::LandingKept(a) => W::LandingKept { action: b(a) },
            E::NewFlight => W::NewFlight,
            E::Operator(o) => W::Operator { operator: o },
            E::Stop(s) => W::Stop { stop: s },
            E::StartedInFlight { found_as, does } => W::StartedInFlight {
                found_as: b(found_as),
                does: b(does),
            },
            E::ResumedInFlight {
                system,
                component,
                found_as,
                facts,
            } => W::ResumedInFlight {
                system: *system,
                component: *component,
                found_as: b(found_as),
                facts,
            },
            E::PerformanceDrift {
                activity,
                measured_j,
                predicted_j,
                activity_s,
                ratio,
                tolerance_pct,
                energy_scale,
            } => W::PerformanceDrift {
                activity: b(activity),
                measured_j: *measured_j,
                predicted_j: *predicted_j,
                activity_s: *activity_s,
                ratio: *ratio,
                tolerance_pct: *tolerance_pct,
                energy_scale: *energy_scale,
            },
            E::VersionsCapped {
                versions,
                capped,
                at,
            } => W::VersionsCapped {
                versions,
                capped,
                at: *at,
            },
            E::RouteReplanned {
                cruise_mps,
                was_mps,
                plan,
            } => W::RouteReplanned {
                cruise_mps: *cruise_mps,
                was_mps: *was_mps,
                plan: b(plan),
            },
            E::RouteNotReplanned { cruise_mps, why } => W::RouteNotReplanned {
                cruise_mps: *cruise_mps,
                why: b(why),
            },
            E::MissionPlannedFromHome {
                home,
                activities,
                energy_j,
                duration_s,
            } => W::MissionPlannedFromHome {
                home: b(home),
                activities: *activities,
                energy_j: *energy_j,
                duration_s: *duration_s,
            },
            E::AutopilotMissionPlanned { what, summary } => W::AutopilotMissionPlanned {
                what: b(what),
                summary: b(summary),
            },
            E::MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            } => W::MissionReplannedFromPoint {
                item: *item,
                kept: *kept,
                left: *left,
                left_m: *left_m,
            },
            E::MissionRefused(why) => W::MissionRefused { why: b(why) },
            E::EventsNotListed {
                more,
                repeats,
                not_listed,
            } => W::EventsNotListed {
                more: *more,
                repeats: *repeats,
                not_listed: *not_listed,
            },
            E::Other(text) => W::Other { text: b(text) },
        }
    }
}

impl From<EventIn<'_>> for Event {
    fn from(w: EventIn<'_>) -> Self {
        use Event as E;
        use EventWire as W;
        match w {
            W::TargetDetected => E::TargetDetected,
            W::TargetLost => E::TargetLost,
            W::ObstacleDetected => E::ObstacleDetected,
            W::ObstacleCleared => E::ObstacleCleared,
            W::ObstacleAvoided => E::ObstacleAvoided,
            W::Collision => E::Collision,
            W::TZoneFound => E::TZoneFound,
            W::EmergencyZoneFound => E::EmergencyZoneFound,
            W::Landing => E::Landing,
            W::BatteryExhausted => E::BatteryExhausted,
            W::Armed => E::Armed,
            W::Disarmed => E::Disarmed,
            W::Mode { mode } => E::Mode(own(mode)),
            W::Waypoint { seq } => E::Waypoint(seq),
            W::BatteryBelow { threshold_pct } => E::BatteryBelow(threshold_pct),
            W::Link { link } => E::Link(link),
            W::Command { action, outcome } => E::Command {
                action: own(action),
                outcome,
            },
            W::HealthError { error } => E::HealthError(own(error)),
            W::ArbitrationError { error } => E::ArbitrationError(own(error)),
            W::ResourcesError { error } => E::ResourcesError(own(error)),
            W::MdpStateUnknown { mdp, state } => E::MdpStateUnknown {
                mdp: own(mdp),
                state: own(state),
            },
            W::MdpError { mdp, error } => E::MdpError {
                mdp: own(mdp),
                error: own(error),
            },
            W::Reallocation { reason } => E::Reallocation(own(reason)),
            W::Degraded { degraded } => E::Degraded(degraded),
            W::Dropped { dropped } => E::Dropped(dropped),
            W::GuaranteeInfeasible => E::GuaranteeInfeasible,
            W::ShellLand { why } => E::ShellLand(own(why)),
            W::LandingKept { action } => E::LandingKept(own(action)),
            W::NewFlight => E::NewFlight,
            W::Operator { operator } => E::Operator(operator),
            W::Stop { stop } => E::Stop(stop),
            W::StartedInFlight { found_as, does } => E::StartedInFlight {
                found_as: own(found_as),
                does: own(does),
            },
            W::ResumedInFlight {
                system,
                component,
                found_as,
                facts,
            } => E::ResumedInFlight {
                system,
                component,
                found_as: own(found_as),
                facts,
            },
            W::PerformanceDrift {
                activity,
                measured_j,
                predicted_j,
                activity_s,
                ratio,
                tolerance_pct,
                energy_scale,
            } => E::PerformanceDrift {
                activity: own(activity),
                measured_j,
                predicted_j,
                activity_s,
                ratio,
                tolerance_pct,
                energy_scale,
            },
            W::VersionsCapped {
                versions,
                capped,
                at,
            } => E::VersionsCapped {
                versions,
                capped,
                at,
            },
            W::RouteReplanned {
                cruise_mps,
                was_mps,
                plan,
            } => E::RouteReplanned {
                cruise_mps,
                was_mps,
                plan: own(plan),
            },
            W::RouteNotReplanned { cruise_mps, why } => E::RouteNotReplanned {
                cruise_mps,
                why: own(why),
            },
            W::MissionPlannedFromHome {
                home,
                activities,
                energy_j,
                duration_s,
            } => E::MissionPlannedFromHome {
                home: own(home),
                activities,
                energy_j,
                duration_s,
            },
            W::AutopilotMissionPlanned { what, summary } => E::AutopilotMissionPlanned {
                what: own(what),
                summary: own(summary),
            },
            W::MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            } => E::MissionReplannedFromPoint {
                item,
                kept,
                left,
                left_m,
            },
            W::MissionRefused { why } => E::MissionRefused(own(why)),
            W::EventsNotListed {
                more,
                repeats,
                not_listed,
            } => E::EventsNotListed {
                more,
                repeats,
                not_listed,
            },
            W::Other { text } => E::Other(own(text)),
        }
    }
}

/// A wire form written with `text`: the sentence `Display` gives, for people and for scripts
/// that read sentences (never read back: the fields are the data). `Other` is its text already.
#[derive(Serialize)]
pub(super) struct WithText<'a, W, T: fmt::Display> {
    #[serde(flatten)]
    pub(super) wire: W,
    #[serde(serialize_with = "said")]
    pub(super) text: &'a T,
}

fn said<T: fmt::Display, S: Serializer>(t: &&T, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(*t)
}

impl Serialize for CommandOutcome {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let wire = OutcomeWire::from(self);
        if matches!(self, CommandOutcome::Other(_)) {
            return wire.serialize(serializer);
        }
        WithText { wire, text: self }.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for CommandOutcome {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        OutcomeWire::deserialize(deserializer).map(Self::from)
    }
}

impl Serialize for LinkEvent {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let wire = LinkWire::from(self);
        if matches!(self, LinkEvent::Other(_)) {
            return wire.serialize(serializer);
        }
        WithText { wire, text: self }.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for LinkEvent {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        LinkWire::<CommandOutcome>::deserialize(deserializer).map(Self::from)
    }
}

impl Serialize for Event {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let wire = EventOut::from(self);
        if matches!(self, Event::Other(_)) {
            return wire.serialize(serializer);
        }
        WithText { wire, text: self }.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Event {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        EventIn::deserialize(deserializer).map(Self::from)
    }
}
