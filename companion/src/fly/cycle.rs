//! One decision cycle, sans IO where it can be: the observation snapshot, the mission state, the
//! core's step, the commands for the chosen vehicle action ([`decide`]), then the record
//! ([`finish_record`]); [`run_cycle_at`] sends and writes between them.

use super::shell::{DeciderIds, Shell, our_ids};
use super::words;
use super::{Decider, FlyReport, NOTICE, RecordSink, Tlog, WARNING, send};
use anyhow::Context;
use companion_core::action_id::{ActionId, ActionNames};
use companion_core::action_role::ActionRole;
use companion_core::observations::Observations;
use companion_core::record::{CommandOutcome, DecisionRecord, Event, LinkEvent, Plan};
use companion_link::Msg;
use companion_link::actions::Flown;
use companion_link::ingest::Encoder;
use companion_link::mission_state::{self, Extra, MissionState};
use companion_link::modes::ReportedMode;
use companion_link::vehicle::Vehicle;
use std::time::Duration;

#[allow(clippy::too_many_arguments)]
pub(super) async fn run_cycle_at<D: Decider, S: RecordSink>(
    decider: &mut D,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    encoder: &mut Encoder,
    tx: &tokio::sync::mpsc::Sender<Vec<u8>>,
    tlog: &mut Option<Tlog>,
    sink: &mut S,
    trigger_at: Duration,
    now: impl Fn() -> Duration,
    report: &mut FlyReport,
    transport_events: &mut Vec<LinkEvent>,
) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let decided = decide(decider, shell, vehicle, &now);
    let decide_ms = started.elapsed().as_secs_f64() * 1e3;
    send(encoder, vehicle, tx, tlog, &decided.msgs).await;
    vehicle.stamp_latency(trigger_at, now());
    report.cycles += 1;
    // The action flown, under its own name (a shell-only entry such as the route's resume is
    // told as the action it is flown for).
    let flown = decided.chosen.map(|c| {
        vehicle
            .actions()
            .name(Flown::Action(c.action()))
            .to_string()
    });
    let mut rec = finish_record(decided, shell, vehicle, report.cycles, transport_events);
    rec.decide_ms = Some(decide_ms);
    if shell.operator.control == companion_link::operator::Control::FlightInProgress {
        let battery = rec.vehicle.get("battery_pct").and_then(|v| v.as_f64());
        shell.guarantee_in_flight = Some((now(), rec.guarantee.clone(), battery));
    }
    if !shell.operator.commanding() {
        shell.launch = match super::autopilot_plan::unplanned_refusal(shell) {
            Some(refusal) => Err(refusal),
            None => decider.launch_verdict(&rec),
        };
    }
    tracing::debug!(
        cycle = rec.cycle,
        state = %rec.state,
        actions = %rec.actions.join(","),
        "decision cycle"
    );
    let mut texts = Vec::new();
    if let Some(change) = shell.action_change(&rec) {
        tracing::info!("actions: {change}");
    }
    // One change of decision, one STATUSTEXT (chunked when long): what the vehicle does, a
    // re-allocation and the guarantee's verdict of this cycle are said together.
    let mut said: Vec<String> = Vec::new();
    let mut severity = NOTICE;
    if shell.operator.commanding()
        && let Some(text) = shell.behaviour_text(&rec, flown.as_deref())
    {
        said.push(text);
    }
    if shell.operator.commanding()
        && let Some(text) = rec.guarantee.as_ref().and_then(words::reallocation_text)
    {
        said.push(text);
    }
    if let Some((line, sev, text)) = shell.guarantee_change(&rec) {
        if sev == WARNING {
            tracing::warn!("{line}");
            severity = WARNING;
        } else {
            tracing::info!("{line}");
        }
        said.push(text);
    }
    if !said.is_empty() {
        texts.extend(shell.texts.say(now(), severity, &said.join(". ")));
    }
    // The plotted values ride the same queue as the texts, after them.
    texts.extend(shell.ground_values.due(&rec, now()));
    send(encoder, vehicle, tx, tlog, &texts).await;
    sink.write(&rec).context("writing the decision record")?;
    Ok(())
}

/// The first half of one decision cycle, without I/O: the observation snapshot from the
/// vehicle's telemetry and events, the mission state, the core's step, and the commands for
/// the chosen vehicle action. The shell sends `msgs`, stamps latency, then calls
/// [`finish_record`]. Public so that a soak run drives exactly the cycle `fly` runs.
pub fn decide<D: Decider>(
    decider: &mut D,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    now: impl Fn() -> Duration,
) -> Decided {
    let mut events = vehicle.take_events();
    events.append(&mut shell.pending_events);
    coalesce_events(&mut events);
    let mut obs = vehicle.observations(now(), events.clone());
    let extra = Extra {
        mode: vehicle.telemetry().mode.and_then(ReportedMode::known),
        landed_state: vehicle.telemetry().landed_state.as_deref(),
        down_for_s: Some(vehicle.down_for(now()).map_or(0.0, |d| d.as_secs_f64())),
    };
    obs.state = shell.mission.update(&obs, &extra).to_string();
    complete_observations(&mut obs, &shell.mission);
    let home = vehicle.telemetry().home;
    let landed = vehicle.telemetry().landed_state.as_deref();
    shell.route_activity =
        (shell.route_progress.as_mut()).and_then(|p| p.activity_landing(&obs, home, landed));
    if let Some(a) = shell.route_activity {
        obs.set(companion_core::evidence::ROUTE_ACTIVITY, a as f64);
    }
    let (plan, mut rec) = decider.step(&obs);
    let catalogue = decider.actions();
    let decider_ids = (shell.shell_ids)
        .get_or_insert_with(|| DeciderIds::new(catalogue, shell.mission.actions()));
    // The core's actions as ids of the shell's catalogue: no name is looked up in the cycle.
    let ours = shell.mission.actions().names().clone();
    (shell.mission).after_plan(our_ids(&ours, Some(decider_ids), &rec.actions));
    let shell_ids = &decider_ids.to_ours;
    let precedence = shell.precedence_ids.get_or_insert_with(|| {
        let ids = shell.precedence.iter().filter_map(|p| catalogue.id(p));
        ids.collect()
    });
    // The chosen action as an id of the shell's catalogue, which the commands table and the
    // mission estimate index; names are resolved only for the record and the messages.
    let mut chosen = mission_state::select_vehicle_action(&plan.vehicle_actions, precedence)
        .and_then(|&a| {
            let ours = shell_ids.get(a.index()).copied().flatten();
            if ours.is_none() {
                tracing::warn!(
                    "the decider's action `{}` is not in params/actions.toml: not flown",
                    catalogue.name(a)
                );
            }
            ours
        });
    let mut shell_events = Vec::new();
    if let Some(why) = shell.mission.mission_end(&obs) {
        // The mission's end, not the core's decision: recorded as an event with the action.
        shell_events.push(Event::ShellLand(why.to_string()));
        if let Some(land) = shell.mission.action(ActionRole::Land) {
            shell_action(&mut rec, &ours, land);
            shell.mission.after_plan([land]);
            chosen = Some(land);
        }
    }
    // The landing phase: the MDPs see `landing` as terminal and plan nothing there, so the shell
    // keeps flying the landing chosen until the vehicle is down, resuming it after an avoidance
    // sidestep and sending it again after a refusal or a timeout.
    if shell.operator.commanding()
        && let Some(landing) = shell.mission.landing_action()
    {
        let mission = &shell.mission;
        let keep = chosen.is_some_and(|a| {
            mission.role(a) == Some(ActionRole::AvoidObstacle) || mission.is_landing_action(a)
        });
        if !keep {
            let name = mission.name(landing);
            if !vehicle.settled(Flown::Action(landing)) {
                shell_events.push(Event::LandingKept(name.to_string()));
            }
            let planned = our_ids(&ours, Some(decider_ids), &rec.actions)
                .chain(our_ids(&ours, None, &rec.shell_actions))
                .any(|a| a == landing);
            if !planned {
                shell_action(&mut rec, &ours, landing);
            }
            chosen = Some(landing);
        }
    }
    // Once the route is on the vehicle, an action with a shell-only entry flown for it
    // (`flown_for` in params/commands.toml: follow_trajectory -> resume in AUTO) is flown as that
    // entry, so the route is resumed where it was left, not uploaded again.
    let mut flown = chosen.map(Flown::Action);
    if shell.mission.route_on_vehicle()
        && let Some(action) = chosen
        && let Some(resume) = vehicle.actions().in_place_of(action)
    {
        flown = Some(resume);
    }
    // No motion until the operator starts the mission, none while the pilot has control.
    let msgs = if shell.operator.commanding() {
        vehicle.request_actions(now(), flown.as_slice())
    } else {
        Vec::new()
    };
    Decided {
        msgs,
        chosen: flown,
        plan,
        rec,
        obs,
        events,
        shell_events,
    }
}

/// The shell flies `action` (an id of its catalogue, whose names are `ours`) on its own rules:
/// into the record's `shell_actions`, over that catalogue.
fn shell_action(rec: &mut DecisionRecord, ours: &ActionNames, action: ActionId) {
    let list = &mut rec.shell_actions;
    if !std::sync::Arc::ptr_eq(list.vocabulary(), ours) {
        let had: Vec<ActionId> = our_ids(ours, None, list).collect();
        list.set(ours, had);
    }
    list.push(action);
}

/// At most this many events in one record: a flood is summarised, not copied.
const MAX_EVENTS: usize = 64;

/// Repeated events once each (in first-seen order), at most [`MAX_EVENTS`] with a count of the
/// rest.
fn coalesce_events(events: &mut Vec<Event>) {
    if let Some((more, repeats, not_listed)) =
        companion_core::record::dedupe_capped(events, MAX_EVENTS)
    {
        events.push(Event::EventsNotListed {
            more,
            repeats,
            not_listed,
        });
    }
}

/// One cycle between [`decide`] and [`finish_record`].
pub struct Decided {
    /// Commands for the chosen vehicle action, to send now.
    pub msgs: Vec<Msg>,
    /// The vehicle action chosen this cycle (after the mission's end and the route's resume),
    /// as an entry of the vehicle's commands table (`vehicle.actions().name` names it).
    pub chosen: Option<Flown>,
    pub plan: Plan,
    rec: DecisionRecord,
    obs: Observations,
    events: Vec<Event>,
    /// Events of the shell's own decisions this cycle (mission end, landing resumed).
    shell_events: Vec<Event>,
}

impl Decided {
    /// The core's record so far (its actions, state, ...).
    pub fn record(&self) -> &DecisionRecord {
        &self.rec
    }
}

/// The second half of one decision cycle: the record with the cycle number, the command
/// results, link events and vehicle telemetry, ready for the decision log.
pub fn finish_record(
    d: Decided,
    shell: &mut Shell,
    vehicle: &mut Vehicle,
    cycle: u64,
    transport_events: &mut Vec<LinkEvent>,
) -> DecisionRecord {
    let Decided {
        mut rec,
        obs,
        events,
        shell_events,
        ..
    } = d;
    rec.cycle = cycle;
    rec.time_s = obs.time_s;
    rec.utc_us = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .ok()
        .map(|d| d.as_micros() as u64);
    if rec.events.is_empty() {
        rec.events = events;
    }
    rec.events.extend(shell_events);
    if rec.observations.is_empty() {
        rec.observations = obs.values;
    }
    rec.commands.extend(vehicle.take_records());
    rec.link_events.append(transport_events);
    rec.link_events.extend(shell.ingest_note());
    rec.link_events.extend(vehicle.take_link_events());
    // A flood (STATUSTEXT from the autopilot) is summarised like events are, so the record stays
    // small enough to be logged.
    companion_core::record::coalesce_link_events(&mut rec.link_events);
    rec.vehicle.extend(vehicle.telemetry().vehicle());
    // Which autopilot this run flies: a restarted companion proves a flight its own by it.
    if let Some((sys, comp)) = vehicle.target() {
        rec.vehicle.insert(
            "autopilot".into(),
            serde_json::Value::from(format!("{sys}/{comp}")),
        );
    }
    rec.vehicle.insert(
        "link_alive".into(),
        serde_json::Value::from(vehicle.liveness().alive()),
    );
    rec.vehicle.insert(
        "operator".into(),
        serde_json::Value::from(shell.operator.control.label()),
    );
    for c in &rec.commands {
        let failed = matches!(
            c.result,
            CommandOutcome::Failed(_)
                | CommandOutcome::Denied
                | CommandOutcome::Timeout(_)
                | CommandOutcome::NotSent(_)
                | CommandOutcome::NotReady(_)
                | CommandOutcome::Cancelled(_)
                | CommandOutcome::Unmapped
        );
        if failed {
            tracing::warn!("command {} {}: {}", c.action, c.command, c.result);
        } else {
            tracing::info!("command {} {}: {}", c.action, c.command, c.result);
        }
    }
    // Transport (dis)connections are said by `FailureLines` at most once per 10 s; the record
    // keeps every one.
    for e in rec.link_events.iter().filter(|e| {
        !matches!(
            e,
            LinkEvent::TransportConnected(_)
                | LinkEvent::TransportDisconnected(_)
                | LinkEvent::OnboardConnected(_)
                | LinkEvent::OnboardDisconnected(_)
        )
    }) {
        tracing::info!("link: {e}");
    }
    for e in rec.events.iter().filter(|e| matches!(e, Event::Mode(_))) {
        tracing::info!("vehicle {e}");
    }
    rec
}

/// Observations the health BNs read under names the telemetry does not produce directly.
fn complete_observations(obs: &mut Observations, mission: &MissionState) {
    if let Some(v) = obs.get("groundspeed_mps")
        && !obs.values.contains_key("drone_speed_mps")
    {
        obs.set("drone_speed_mps", v);
    }
    let remaining = mission.waypoints_remaining(obs);
    obs.set("waypoints_remaining", remaining);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_event_flood_is_coalesced_into_one_bounded_list() {
        let mut ev: Vec<Event> = (0..10_000)
            .map(|i| Event::Mode(if i % 2 == 0 { "AUTO" } else { "GUIDED" }.into()))
            .collect();
        ev.push(Event::ObstacleDetected);
        coalesce_events(&mut ev);
        assert_eq!(
            ev[..3],
            [
                Event::Mode("AUTO".into()),
                Event::Mode("GUIDED".into()),
                Event::ObstacleDetected
            ]
        );
        assert_eq!(ev.len(), 4);
        assert!(ev[3].to_string().contains("9998 repeats"), "{}", ev[3]);
        let mut many: Vec<Event> = (0..500).map(Event::Waypoint).collect();
        coalesce_events(&mut many);
        assert_eq!(many.len(), MAX_EVENTS + 1);
        assert!(
            many[MAX_EVENTS].to_string().contains("436 not listed"),
            "{}",
            many[MAX_EVENTS]
        );
        let mut few = vec![Event::Other("a".into()), Event::Other("b".into())];
        coalesce_events(&mut few);
        assert_eq!(few, ["a", "b"]);
    }
}
