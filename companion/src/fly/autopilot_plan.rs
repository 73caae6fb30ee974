//! `fly --mission autopilot`, the shell's side: the autopilot's mission, once the link has
//! downloaded it ([`companion_link::vehicle::AutopilotMission`]), is planned
//! ([`crate::autopilot_mission::plan`]) and handed to the decider's guarantee; until a plan
//! stands, no start is granted. A mission changed by a ground station is re-planned the same
//! way; each plan, change and refusal is said to the ground station and recorded.

use super::{Decider, NOTICE, Shell, WARNING};
use companion_core::launch::LaunchRefusal;
use companion_core::record::Event;
use companion_core::route_plan::{DeriveSettings, ItemKind};
use companion_core::spec::ParamsFiles;
use companion_link::Msg;
use companion_link::dialect::MavSeverity;
use companion_link::mission::MissionItem;
use companion_link::vehicle::{AutopilotMission, Vehicle};
use std::time::Duration;

/// Why no start is granted before the first download.
pub(super) const NOT_DOWNLOADED: &str = "the autopilot's mission is not downloaded yet";

/// What the shell needs to plan the autopilot's mission, and what the last plan was made from.
pub(super) struct AutopilotPlan {
    /// The params the activities' tasks and goals come from.
    files: ParamsFiles,
    /// The speeds' params fallback (`[derive]`, read at start).
    params_speeds: crate::autopilot_mission::ParamsSpeeds,
    /// `--zones`: the zones the mission is planned among (placed from its home).
    zones: Option<crate::autopilot_mission::MissionZones>,
    /// The mission last planned (or refused) and what it was planned from: a speed the
    /// autopilot reports later (its PARAM_VALUE after the download, a ground station's
    /// PARAM_SET) or PX4's home arriving re-plans it.
    last: Option<Planned>,
    /// The mission's states (the route progress of a planned mission reads the phase).
    states: companion_core::mission::MissionStates,
    /// The activities the guarantee plans now (a change in flight keeps those flown).
    activities: Vec<companion_core::route_plan::DerivedActivity>,
    /// What the ground station must still be told (held back by the STATUSTEXT rate cap, said
    /// as soon as it allows). A newer plan replaces one not yet said: the pilot hears the plan in
    /// force; the record keeps both.
    unsaid: Option<(MavSeverity, String)>,
}

/// What the last plan was made from.
struct Planned {
    items: Vec<MissionItem>,
    /// The speeds used ...
    speeds: DeriveSettings,
    /// ... and which of them were the params' fallback (the autopilot had not reported them).
    fallback: Vec<&'static str>,
    /// Whether the autopilot's home was known.
    had_home: bool,
}

impl AutopilotPlan {
    /// Planning from `files`; the start stays refused until the first plan stands.
    pub(super) fn new(
        files: ParamsFiles,
        params_speeds: crate::autopilot_mission::ParamsSpeeds,
        zones: Option<crate::autopilot_mission::MissionZones>,
        states: companion_core::mission::MissionStates,
        shell: &mut Shell,
    ) -> Self {
        shell.mission_unplanned = Some(NOT_DOWNLOADED.to_string());
        Self {
            files,
            params_speeds,
            zones,
            states,
            activities: Vec::new(),
            last: None,
            unsaid: None,
        }
    }

    /// Tell the ground station what is still unsaid, unless the rate cap holds it back again.
    pub(super) fn say(&mut self, shell: &mut Shell, now: Duration) -> Vec<Msg> {
        super::shell::say_until_said(shell, now, &mut self.unsaid)
    }

    /// The mission loaded or changed on the autopilot: planned.
    pub(super) fn on_mission<D: Decider>(
        &mut self,
        update: AutopilotMission,
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) {
        let (items, what) = match update {
            AutopilotMission::Loaded(i) => (i, "mission planned"),
            AutopilotMission::Changed(i) => {
                if self.from_point_reached(&i, vehicle, decider, shell) {
                    return;
                }
                (i, "mission changed, re-planned")
            }
        };
        self.plan(items, what, vehicle, decider, shell);
    }

    /// A mission changed in flight (armed, the activity flown known): planned from the point
    /// reached ([`crate::autopilot_mission::from_point_reached`]), the activities flown and what
    /// they spent kept, the rest re-allocated; said to the ground station. `false`: not in
    /// flight or not plannable so, and the whole mission is planned afresh instead.
    fn from_point_reached<D: Decider>(
        &mut self,
        items: &[MissionItem],
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) -> bool {
        let t = vehicle.telemetry();
        let (Some(at), Some(pos), true) = (shell.route_activity, t.position, t.armed) else {
            return false;
        };
        let Some(flown) = self.activities.get(..at) else {
            return false;
        };
        let planned: Vec<_> = items
            .iter()
            .enumerate()
            .map(|(k, i)| i.planned(k))
            .collect();
        let home = t
            .home
            .map(|(lat, lon, alt)| (f64::from(lat) / 1e7, f64::from(lon) / 1e7, alt));
        let (speeds, fallback) =
            crate::autopilot_mission::speeds(&self.params_speeds, |n| t.get(n));
        let home_at_seq0 = vehicle.home_at_seq0();
        let Ok(route) = crate::autopilot_mission::autopilot_mission(
            &planned,
            home_at_seq0,
            home,
            speeds.cruise_speed_mps,
        ) else {
            return false;
        };
        let here = companion_core::route_plan::Position {
            lat_deg: f64::from(pos.lat_e7) / 1e7,
            lon_deg: f64::from(pos.lon_e7) / 1e7,
            alt_m: pos.alt_rel_m,
        };
        let seq = usize::from(t.mission_seq.unwrap_or(1));
        let whole = crate::autopilot_mission::plan(
            &self.files,
            &planned,
            home_at_seq0,
            home,
            &speeds,
            self.zones.as_ref(),
        );
        let part = crate::autopilot_mission::from_point_reached(
            &self.files,
            flown,
            &route,
            seq,
            here,
            &speeds,
            self.zones.as_ref(),
        );
        let (Ok(whole), Ok(part)) = (whole, part) else {
            return false;
        };
        let from = flown.len();
        let left: f64 = part.activities[from..].iter().map(|a| a.length_m).sum();
        let replanned = Event::MissionReplannedFromPoint {
            item: seq,
            kept: from,
            left: part.activities.len() - from,
            left_m: left,
        };
        set_waypoints(shell, &route.items);
        shell.route_progress = super::route_progress::RouteProgress::for_items(
            &part.activities,
            from,
            &route.items,
            |i| u16::try_from(i).ok(),
            Some((here.lat_deg, here.lon_deg)),
            self.states.clone(),
        );
        let feasible = decider.replan_from(whole.spec, part.spec, from);
        shell.mission_unplanned =
            (!feasible).then(|| "the guarantee finds no allocation for it".to_string());
        self.activities = part.activities;
        let text = replanned.to_string();
        tracing::info!("{text}");
        shell.pending_events.push(replanned);
        self.unsaid = Some((NOTICE, text));
        self.last = Some(Planned {
            items: items.to_vec(),
            speeds,
            fallback,
            had_home: home_at_seq0 || home.is_some(),
        });
        true
    }

    /// Every turn: the same mission planned again when the autopilot now reports a speed other
    /// than the one planned with, or (PX4) its home arrived after the plan. On the ground, also
    /// when a speed planned from the params' fallback is now reported at the same value (the
    /// [derive] defaults are ArduCopter's own): the plan then says it is the autopilot's, seen
    /// on ArduCopter SITL when its PARAM_VALUEs came after the mission download.
    pub(super) fn recheck<D: Decider>(
        &mut self,
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) {
        let Some(last) = &self.last else {
            return;
        };
        let (now, fallback) =
            crate::autopilot_mission::speeds(&self.params_speeds, |n| vehicle.telemetry().get(n));
        let home_came = !last.had_home && vehicle.telemetry().home.is_some();
        let confirmed = fallback.len() < last.fallback.len() && !vehicle.telemetry().armed;
        if now == last.speeds && !home_came && !confirmed {
            return;
        }
        let what = if now == last.speeds && home_came {
            "mission re-planned from the autopilot's home"
        } else {
            "mission re-planned at the autopilot's speeds"
        };
        if let Some(last) = self.last.take() {
            self.plan(last.items, what, vehicle, decider, shell);
        }
    }

    /// Plan `items`, replace the decider's guarantee, set the mission estimate's waypoints, and
    /// tell the ground station and the record (`what`: planned, changed, re-planned).
    fn plan<D: Decider>(
        &mut self,
        items: Vec<MissionItem>,
        what: &str,
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) {
        let planned: Vec<_> = items
            .iter()
            .enumerate()
            .map(|(k, i)| i.planned(k))
            .collect();
        let home = vehicle
            .telemetry()
            .home
            .map(|(lat, lon, alt)| (f64::from(lat) / 1e7, f64::from(lon) / 1e7, alt));
        let (speeds, fallback) =
            crate::autopilot_mission::speeds(&self.params_speeds, |n| vehicle.telemetry().get(n));
        let home_at_seq0 = vehicle.home_at_seq0();
        let result = crate::autopilot_mission::plan(
            &self.files,
            &planned,
            home_at_seq0,
            home,
            &speeds,
            self.zones.as_ref(),
        );
        let (event, severity) = match result {
            Ok(d) => {
                let summary = crate::autopilot_mission::summary(&d, &fallback);
                let route = crate::autopilot_mission::autopilot_mission(
                    &planned,
                    home_at_seq0,
                    home,
                    speeds.cruise_speed_mps,
                );
                if let Ok(route) = route {
                    set_waypoints(shell, &route.items);
                    // The autopilot's seq is the item's index.
                    shell.route_progress = super::route_progress::RouteProgress::for_items(
                        &d.activities,
                        0,
                        &route.items,
                        |i| u16::try_from(i).ok(),
                        None,
                        self.states.clone(),
                    );
                }
                self.activities = d.activities.clone();
                let feasible = decider.replace_mission(d.spec);
                shell.mission_unplanned =
                    (!feasible).then(|| "the guarantee finds no allocation for it".to_string());
                let planned = Event::AutopilotMissionPlanned {
                    what: what.to_string(),
                    summary,
                };
                (planned, NOTICE)
            }
            Err(e) => {
                let why = format!("{e:#}");
                shell.mission_unplanned = Some(why.clone());
                (Event::MissionRefused(why), WARNING)
            }
        };
        let text = event.to_string();
        tracing::info!("{text}");
        shell.pending_events.push(event);
        self.unsaid = Some((severity, text));
        self.last = Some(Planned {
            items,
            speeds,
            fallback,
            had_home: home_at_seq0 || home.is_some(),
        });
    }
}

/// The mission estimate follows the autopilot's mission: its first and last waypoint
/// (or loiter) by sequence number, and no search or tracking limit of the route file (the plan
/// holds none: the mission's own items end it).
fn set_waypoints(shell: &mut Shell, items: &[companion_core::route_plan::Item]) {
    let nav: Vec<u16> = items
        .iter()
        .filter(|i| matches!(i.kind, ItemKind::Waypoint(_) | ItemKind::Loiter { .. }))
        .map(|i| i.index as u16)
        .collect();
    if let (Some(&first), Some(&last)) = (nav.first(), nav.last()) {
        for m in [&mut shell.mission, &mut shell.fresh_mission] {
            m.wp1_seq = first;
            m.last_seq = last.max(first);
            m.search_time_limit_s = None;
            m.tracking_time_limit_s = None;
        }
    }
}

/// The launch verdict while a mission is not planned: refused, saying why.
pub(super) fn unplanned_refusal(shell: &Shell) -> Option<LaunchRefusal> {
    shell
        .mission_unplanned
        .as_ref()
        .map(|reason| LaunchRefusal::MissionNotPlanned {
            reason: reason.clone(),
        })
}
