//! Reading logs of schema 1, where events, link events, command results and the resources'
//! degradations were written as sentences (docs/decision-log.md, "Schema 1"). This module is
//! the one place that parses those sentences: [`record_v1`] rewrites a schema-1 record line into
//! schema 2 before it is read as a [`DecisionRecord`], so `read_log`, `stream_log` (and through
//! them `review`, `export`, `calibrate`) and `replay` read both schemas through the same types.
//! It also holds the rules for logs older than a field or a declaration (their routes' states,
//! their actions' roles).
//!
//! A sentence that parses into no variant (free text, a spelling this build does not know) is
//! kept whole as `Other`; one that parses is kept only when the variant writes back to exactly
//! the same sentence, so no text is lost or changed by the migration.
//!
//! [`DecisionRecord`]: companion_core::record::DecisionRecord

use super::Header;
use companion_core::mission::{MissionStates, RouteRole};
use companion_core::record::{CommandOutcome, Degraded, Dropped, Event, LinkEvent};
use serde_json::Value;
use std::fmt;
use std::path::Path;

/// The schema whose sentences this module reads.
pub const SCHEMA_1: u32 = 1;

/// Whether lines under a header of `schema` (`None`: no header) need [`record_v1`]. A log
/// without any header is taken as schema 1 when its sentences say so: a string where schema 2
/// has an object is only ever schema 1.
pub fn needs_migration(schema: Option<u32>) -> bool {
    schema.is_none_or(|s| s <= SCHEMA_1)
}

/// Rewrite a schema-1 record line (as JSON) into schema 2, in place: every sentence among
/// `events`, `link_events`, `commands[].result`, `resources.degraded`, `resources.dropped` and
/// `vehicle.world_events_after` becomes its typed value. Values that are not strings (already
/// schema 2) are left as they are.
pub fn record_v1(value: &mut Value) {
    let Some(obj) = value.as_object_mut() else {
        return;
    };
    // A degradation's event is its sentence in the same record's resources (the arbitration
    // says one when it starts), not any text of its shape (`performance drift: ...`).
    let resource_list = |key: &str| -> Vec<String> {
        let list = obj.get("resources").and_then(|r| r.get(key));
        let items = list.and_then(Value::as_array).map(Vec::as_slice);
        let text = items.unwrap_or_default().iter().filter_map(Value::as_str);
        text.map(str::to_string).collect()
    };
    let (was_degraded, was_dropped) = (resource_list("degraded"), resource_list("dropped"));
    // A re-solve within the cycle can clear the resources the event was said for: the
    // scheduler's own reason (`insufficient resources ...`) then tells it.
    let scheduler =
        |app: &str, reason: &str| !app.is_empty() && reason.starts_with("insufficient resources");
    migrate_list(obj.get_mut("events"), |s| {
        let (d, x) = (degraded(s), dropped(s));
        if was_degraded.iter().any(|w| w == s) || scheduler(&d.app, &d.reason) {
            to_value(&Event::Degraded(d))
        } else if was_dropped.iter().any(|w| w == s) || scheduler(&x.app, &x.reason) {
            to_value(&Event::Dropped(x))
        } else {
            to_value(&event(s))
        }
    });
    migrate_list(obj.get_mut("link_events"), |s| to_value(&link_event(s)));
    if let Some(commands) = obj.get_mut("commands").and_then(Value::as_array_mut) {
        for c in commands {
            if let Some(r) = c.get_mut("result")
                && let Some(s) = r.as_str()
            {
                *r = to_value(&outcome(s));
            }
        }
    }
    if let Some(res) = obj.get_mut("resources").and_then(Value::as_object_mut) {
        migrate_list(res.get_mut("degraded"), |s| to_value(&degraded(s)));
        migrate_list(res.get_mut("dropped"), |s| to_value(&dropped(s)));
    }
    if let Some(v) = obj.get_mut("vehicle").and_then(Value::as_object_mut) {
        migrate_list(v.get_mut("world_events_after"), |s| to_value(&event(s)));
    }
}

fn migrate_list(list: Option<&mut Value>, f: impl Fn(&str) -> Value) {
    if let Some(items) = list.and_then(Value::as_array_mut) {
        for item in items {
            if let Some(s) = item.as_str() {
                *item = f(s);
            }
        }
    }
}

fn to_value<T: serde::Serialize>(v: &T) -> Value {
    // The record types serialise to JSON objects without fail (no map with non-string keys).
    serde_json::to_value(v).unwrap_or(Value::Null)
}

/// `WORD (detail)` split into `WORD` and `detail`; `WORD` alone gives no detail.
fn word_and_detail(s: &str) -> (&str, Option<&str>) {
    match s.split_once(" (") {
        Some((w, rest)) if rest.ends_with(')') => (w, Some(&rest[..rest.len() - 1])),
        _ => (s, None),
    }
}

/// Parses with `known`; keeps `s` whole in `other` unless the value found writes back exactly
/// as `s` (so `display(parse(s)) == s` for every string).
fn parse_exact<T: fmt::Display>(
    s: &str,
    known: impl FnOnce(&str) -> Option<T>,
    other: impl FnOnce(String) -> T,
) -> T {
    match known(s) {
        Some(v) if v.to_string() == s => v,
        _ => other(s.to_string()),
    }
}

/// A schema-1 `CommandRecord.result` (`ACCEPTED`, `TIMEOUT (why)`, ...). Logs written before
/// the mission error was typed spelled a transfer stopped by a cancel `FAILED
/// (Cancelled("why"))` (its error's Debug text): read as what it was, `CANCELLED (why)`.
pub fn outcome(s: &str) -> CommandOutcome {
    if let Some(why) = s
        .strip_prefix("FAILED (Cancelled(\"")
        .and_then(|r| r.strip_suffix("\"))"))
    {
        return CommandOutcome::Cancelled(Some(why.to_string()));
    }
    parse_exact(s, outcome_known, CommandOutcome::Other)
}

fn outcome_known(s: &str) -> Option<CommandOutcome> {
    use CommandOutcome::*;
    let (word, detail) = word_and_detail(s);
    let d = || detail.map(str::to_string);
    Some(match (word, detail) {
        ("ACCEPTED", None) => Accepted,
        ("ACCEPTED", Some(x)) => AcceptedVerified {
            items: x
                .strip_prefix("verified ")?
                .strip_suffix(" items")?
                .parse()
                .ok()?,
        },
        ("SIMULATED", None) => Simulated,
        ("SENT", None) => Sent,
        ("IN_PROGRESS", None) => InProgress,
        ("PENDING", None) => Pending,
        ("WAITING_READY", Some(_)) => WaitingReady(d()?),
        ("NOT_READY", Some(_)) => NotReady(d()?),
        ("ALREADY", None) => Already,
        ("SKIPPED", Some(_)) => Skipped(d()?),
        ("SUPERSEDED", None) => Superseded,
        ("NOT_SENT", Some(_)) => NotSent(d()?),
        ("CANCELLED", _) => Cancelled(d()),
        ("UNMAPPED", Some(_)) => Unmapped,
        ("DENIED", None) => Denied,
        ("TEMPORARILY_REJECTED", None) => TemporarilyRejected,
        ("UNSUPPORTED", None) => Unsupported,
        ("TIMEOUT", _) => Timeout(d()),
        ("ARRIVED", Some(_)) => Arrived(d()?),
        ("NOT_CONFIRMED", Some(_)) => NotConfirmed(d()?),
        ("FAILED", _) => Failed(d()),
        _ => return None,
    })
}

/// Whether `MDP: ERROR` is an MDP's instantiate or solve error (the sentences of
/// `mission_mdp::InstantiateError`), not free text that happens to hold a colon.
fn is_mdp_error(mdp: &str, error: &str) -> bool {
    let word = !mdp.is_empty() && !mdp.contains(char::is_whitespace);
    let known = (error.starts_with("probability ")
        && (error.ends_with(" not provided") || error.ends_with(" not in [0, 1]")))
        || (error.starts_with("unknown policy '") && error.ends_with('\''))
        || error.starts_with("mdp '");
    word && known
}

/// A schema-1 `events` sentence (a resource degradation's needs its record: [`record_v1`]).
pub fn event(s: &str) -> Event {
    parse_exact(s, event_known, Event::Other)
}

fn event_known(s: &str) -> Option<Event> {
    use Event::*;
    Some(match s {
        "target detected" => TargetDetected,
        "target lost" => TargetLost,
        "obstacle detected" => ObstacleDetected,
        "obstacle cleared" => ObstacleCleared,
        "obstacle avoided" => ObstacleAvoided,
        "collision" => Collision,
        "'T' zone found" => TZoneFound,
        "emergency zone found" => EmergencyZoneFound,
        "landing" => Landing,
        "battery exhausted" => BatteryExhausted,
        "armed" => Armed,
        "disarmed" => Disarmed,
        "guarantee: no allocation meets the goals" => GuaranteeInfeasible,
        "flight over: landed and disarmed; waiting for the operator" => NewFlight,
        _ => return event_with_fields(s),
    })
}

fn event_with_fields(s: &str) -> Option<Event> {
    use Event::*;
    if let Some(l) = link_known(s).filter(LinkEvent::is_significant) {
        return Some(Link(l));
    }
    if let Some(m) = s.strip_prefix("mode ") {
        return Some(Mode(m.to_string()));
    }
    if let Some(n) = s.strip_prefix("waypoint ") {
        return n.parse().ok().map(Waypoint);
    }
    if let Some(t) = s.strip_prefix("battery below ") {
        return t.strip_suffix('%')?.parse().ok().map(BatteryBelow);
    }
    if let Some(rest) = s.strip_prefix("command ") {
        let (action, result) = rest.split_once(' ')?;
        return Some(Command {
            action: action.to_string(),
            outcome: parse_exact(result, outcome_known, CommandOutcome::Other),
        });
    }
    let prefixed: [(&str, fn(String) -> Event); 4] = [
        ("health: ", HealthError),
        ("arbitration: ", ArbitrationError),
        ("resources: ", ResourcesError),
        ("re-allocation: ", Reallocation),
    ];
    for (prefix, variant) in prefixed {
        if let Some(e) = s.strip_prefix(prefix) {
            return Some(variant(e.to_string()));
        }
    }
    if let Some(a) = s
        .strip_prefix("landing: ")
        .and_then(|r| r.strip_suffix(" again (the landing was interrupted or not done)"))
    {
        return Some(LandingKept(a.to_string()));
    }
    if let Some(why) = s.strip_suffix(": land") {
        return Some(ShellLand(why.to_string()));
    }
    if let Some((mdp, error)) = s.split_once(": ")
        && is_mdp_error(mdp, error)
    {
        return Some(MdpError {
            mdp: mdp.to_string(),
            error: error.to_string(),
        });
    }
    if let Some((mdp, rest)) = s.split_once(": state `")
        && let Some(state) = rest.strip_suffix("` unknown to this MDP")
    {
        return Some(MdpStateUnknown {
            mdp: mdp.to_string(),
            state: state.to_string(),
        });
    }
    shell::shell_event(s)
}

/// A schema-1 `link_events` sentence.
pub fn link_event(s: &str) -> LinkEvent {
    parse_exact(s, link_known, LinkEvent::Other)
}

fn link_known(s: &str) -> Option<LinkEvent> {
    use LinkEvent::*;
    let sys_comp = |x: &str| -> Option<(u8, u8)> {
        let (a, b) = x.split_once('/')?;
        Some((a.parse().ok()?, b.parse().ok()?))
    };
    Some(match s {
        "link connected" => Connected,
        "link regained" => Regained,
        "link lost" => Lost,
        "autopilot rebooted" => Rebooted,
        "transport reconnected" => TransportReconnected,
        _ => {
            if let Some(t) = s.strip_prefix("autopilot: ") {
                return Some(AutopilotText(t.to_string()));
            }
            if let Some(rest) = s.strip_prefix("another autopilot ") {
                let (ids, why) = rest.split_once(" heard, ignored (")?;
                let (system, component) = sys_comp(ids)?;
                return Some(OtherAutopilot {
                    system,
                    component,
                    why: why.strip_suffix(')')?.to_string(),
                });
            }
            if let Some(rest) = s.strip_prefix("autopilot ") {
                let (ids, flavor) = rest.split_once(" (")?;
                let (system, component) = sys_comp(ids)?;
                return Some(Autopilot {
                    system,
                    component,
                    flavor: flavor.strip_suffix(')')?.to_string(),
                });
            }
            if let Some(rest) = s.strip_prefix("stream ") {
                let (name, result) = rest.split_once(": ")?;
                return Some(Stream {
                    name: name.to_string(),
                    outcome: parse_exact(result, outcome_known, CommandOutcome::Other),
                });
            }
            if let Some(rest) = s.strip_prefix("mission uploaded (") {
                let n = rest.strip_suffix(" items), verifying")?;
                return n.parse().ok().map(|items| MissionUploaded { items });
            }
            if let Some(rest) = s.strip_prefix("mission transfer cancelled (") {
                return Some(MissionTransferCancelled(
                    rest.strip_suffix(')')?.to_string(),
                ));
            }
            if let Some(n) = s.strip_prefix("connected ") {
                return Some(TransportConnected(n.to_string()));
            }
            if let Some(w) = s.strip_prefix("disconnected: ") {
                return Some(TransportDisconnected(w.to_string()));
            }
            if let Some(n) = s.strip_prefix("onboard connected ") {
                return Some(OnboardConnected(n.to_string()));
            }
            let w = s.strip_prefix("onboard disconnected: ")?;
            return Some(OnboardDisconnected(w.to_string()));
        }
    })
}

/// `APP VERSION` split at its one space; None unless both are single words.
fn app_and_version(s: &str) -> Option<(&str, &str)> {
    let (app, version) = s.split_once(' ')?;
    let word = |w: &str| !w.is_empty() && !w.contains(char::is_whitespace);
    (word(app) && word(version)).then_some((app, version))
}

/// A schema-1 `resources.degraded` sentence: `APP FROM -> TO: REASON`; other text is kept whole
/// in `reason`.
pub fn degraded(s: &str) -> Degraded {
    let parsed = s.split_once(": ").and_then(|(head, reason)| {
        let (app_from, to) = head.split_once(" -> ")?;
        let (app, from) = app_and_version(app_from)?;
        Some(Degraded {
            app: app.into(),
            from: from.into(),
            to: to.into(),
            reason: reason.into(),
        })
    });
    match parsed {
        Some(d) if d.to_string() == s => d,
        _ => Degraded {
            reason: s.into(),
            ..Default::default()
        },
    }
}

/// A schema-1 `resources.dropped` sentence: `APP VERSION: REASON`; other text is kept whole in
/// `reason`.
pub fn dropped(s: &str) -> Dropped {
    let parsed = s.split_once(": ").and_then(|(head, reason)| {
        let (app, version) = app_and_version(head)?;
        Some(Dropped {
            app: app.into(),
            version: version.into(),
            reason: reason.into(),
        })
    });
    match parsed {
        Some(d) if d.to_string() == s => d,
        _ => Dropped {
            reason: s.into(),
            ..Default::default()
        },
    }
}

/// A `[route_states]` table naming the route states of the logs before params/mission.toml
/// declared them ([`MissionStates::undeclared`]).
pub fn route_states_before_declared() -> String {
    let undeclared = MissionStates::undeclared();
    let mut table = String::from("\n[route_states]\n");
    for role in RouteRole::ALL {
        table.push_str(&format!(
            "{} = {:?}\n",
            role.key(),
            undeclared.route().state(role)
        ));
    }
    table
}

/// The mission's states as the run's own params declared them (embedded in the log's header).
/// Logs whose mission.toml declared states and phases but not yet `[route_states]` take the
/// route names of that time; logs written before the states were declared, or whose header
/// carries no readable params, are read by the rule of that time
/// ([`MissionStates::undeclared`]: the route states and action roles of that time).
pub fn mission_states_of(h: &Header) -> MissionStates {
    let dir = Path::new("params");
    let mut files = companion_core::spec::ParamsFiles::new(dir);
    for name in ["mission.toml", "actions.toml"] {
        if let Some(text) = h.params.get(name) {
            files.insert(dir.join(name), text.as_str());
        }
    }
    MissionStates::load(&files)
        .or_else(|e| match h.params.get("mission.toml") {
            Some(text) if !text.contains("[route_states]") => {
                files.insert(
                    dir.join("mission.toml"),
                    format!("{text}{}", route_states_before_declared()),
                );
                MissionStates::load(&files)
            }
            _ => Err(e),
        })
        .unwrap_or_else(|_| MissionStates::undeclared())
}

mod shell;

#[cfg(test)]
mod tests;
