//! Schema-1 sentences of the fly shell's events (the operator gate, a start in flight, a route
//! re-plan, a refused mission, a summarised flood) read back into their kinds: review finds the
//! start refusal and the restart by kind, replay the route re-plan's cruise speed, `fly` a
//! resumed predecessor. Each parse is kept only when it writes back to the same sentence
//! (`parse_exact` in the parent). Sentences whose numbers were rounded when written (a
//! performance drift, a mission's planned energy) stay `Other`: their fields cannot be read back.

use companion_core::record::{Event, OperatorEvent, ROUTE_REPLANNED, STARTED_IN_FLIGHT, StartBy};

/// `S/C` as MAVLink system and component ids.
fn sys_comp(x: &str) -> Option<(u8, u8)> {
    let (a, b) = x.split_once('/')?;
    Some((a.parse().ok()?, b.parse().ok()?))
}

/// The [`StartBy`] whose words `s` is.
fn start_by(s: &str) -> Option<StartBy> {
    StartBy::ALL.into_iter().find(|b| b.describe() == s)
}

pub(super) fn shell_event(s: &str) -> Option<Event> {
    if let Some(rest) = s.strip_prefix(STARTED_IN_FLIGHT) {
        return started_in_flight(rest);
    }
    if let Some(rest) = s.strip_prefix(ROUTE_REPLANNED) {
        let (cruise, rest) = rest.split_once(" m/s (params ")?;
        let (was, plan) = rest.split_once("): ")?;
        return Some(Event::RouteReplanned {
            cruise_mps: cruise.parse().ok()?,
            was_mps: was.parse().ok()?,
            plan: plan.to_string(),
        });
    }
    if let Some(why) = s.strip_prefix("companion: mission refused: ") {
        return Some(Event::MissionRefused(why.to_string()));
    }
    if let Some(rest) = s.strip_prefix('(')
        && let Some(rest) = rest.strip_suffix(" not listed)")
    {
        let (more, rest) = rest.split_once(" more events since the last cycle: ")?;
        let (repeats, not_listed) = rest.split_once(" repeats, ")?;
        return Some(Event::EventsNotListed {
            more: more.parse().ok()?,
            repeats: repeats.parse().ok()?,
            not_listed: not_listed.parse().ok()?,
        });
    }
    operator(s).map(Event::Operator)
}

fn started_in_flight(rest: &str) -> Option<Event> {
    if let Some(rest) = rest.strip_prefix("resumed on the operator's consent (MISSION_START from ")
    {
        let (ids, rest) = rest.split_once("): the vehicle is ")?;
        let (system, component) = sys_comp(ids)?;
        let (found_as, facts) = rest.split_once("; ")?;
        return Some(Event::ResumedInFlight {
            system,
            component,
            found_as: found_as.to_string(),
            facts: facts.split("; ").map(str::to_string).collect(),
        });
    }
    let (found_as, does) = rest.strip_prefix("the vehicle is ")?.split_once("; ")?;
    Some(Event::StartedInFlight {
        found_as: found_as.to_string(),
        does: does.to_string(),
    })
}

fn operator(s: &str) -> Option<OperatorEvent> {
    use OperatorEvent::*;
    match s {
        "link to the ground station lost" => return Some(GroundStationLost),
        "link to the ground station back" => return Some(GroundStationBack),
        _ => {}
    }
    let rest = s.strip_prefix("operator: ")?;
    let by_in = |r: &str, suffix: &str| -> Option<StartBy> {
        start_by(r.strip_prefix('(')?.strip_suffix(suffix)?)
    };
    if let Some(r) = rest.strip_prefix("start requested ") {
        return by_in(r, ")").map(|by| StartRequested { by });
    }
    if let Some(r) = rest.strip_prefix("mission started ") {
        return by_in(r, ")").map(|by| Started { by });
    }
    if let Some(r) = rest.strip_prefix("start refused ") {
        let r = r.strip_suffix("; still waiting for the operator")?;
        let (by, why) = r.split_once("): ")?;
        return Some(StartRefused {
            by: by_in(by, "")?,
            why: why.to_string(),
        });
    }
    if let Some(why) = rest
        .strip_prefix("start void: the take-off failed before the vehicle was airborne (")
        .and_then(|r| r.strip_suffix("); waiting for a new start"))
    {
        return Some(StartVoidedTakeoffFailed {
            why: why.to_string(),
        });
    }
    if rest.starts_with("start void: the vehicle was disarmed") {
        return Some(StartVoidedDisarmed);
    }
    if let Some(r) = rest.strip_prefix("mode ") {
        let (mode, then) = r.split_once(" was not commanded by the companion: ")?;
        let mode = mode.to_string();
        return Some(if then.starts_with("commanding stopped") {
            TakeoverSuspected { mode }
        } else {
            TakenOver { mode }
        });
    }
    if let Some(r) = rest.strip_prefix("takeover not confirmed: ") {
        let (mode, r) =
            r.split_once(" was reported, then the autopilot showed the companion's ")?;
        let own = r.strip_suffix(" again; commanding resumed (false alarm)")?;
        return Some(FalseAlarm {
            mode: mode.to_string(),
            own: own.to_string(),
        });
    }
    if let Some(r) = rest.strip_prefix("control handed back (") {
        let by = if r.starts_with("switch to GUIDED") {
            StartBy::GuidedSwitch
        } else {
            StartBy::StartCommand
        };
        return Some(HandedBack { by });
    }
    if let Some(r) = rest.strip_prefix("a ground station ") {
        let (ids, r) = r.split_once(" is heard (GCS HEARTBEAT) but --gcs-sysid names ")?;
        let (system, component) = sys_comp(ids)?;
        let named = r.strip_suffix(": its commands are refused, never obeyed")?;
        return Some(GroundStationNotNamed {
            system,
            component,
            named: named.to_string(),
        });
    }
    let (command, r) = rest.split_once(" from ")?;
    let (ids, why) = r.split_once(" refused: ")?;
    let (system, component) = sys_comp(ids)?;
    Some(CommandRefused {
        command: command.to_string(),
        system,
        component,
        why: why.to_string(),
    })
}
