//! `fly --mission FILE` with an operator's mission: a QGroundControl `.plan` or a WPL 110 file
//! (told by content), parsed by `check`'s rules, ended as the route TOML is when it does not end
//! the flight, and turned into the items `fly` uploads (docs/guarantee.md).

use companion_core::route_plan::{ItemKind, PlannedRoute, Position};
use companion_core::spec::{ParamsFiles, SpecError};
use companion_link::actions::{LinkParams, Route, Waypoint};
use std::path::Path;

/// The PANORAMA mission derived activities are planned against (its tasks, TIOs, goals) unless
/// `--mission` names another.
pub const DERIVE_MISSION: &str = "tracking";

/// `fly --mission FILE`, when FILE is an operator's `.plan` or WPL 110 file (told by content):
/// parsed by `check`'s rules (LOITER_TURNS timed at the derived mission's cruise speed), so a
/// malformed one is refused at start with file, item and reason; ended as `[flight] handoff`
/// says when it does not end the flight itself (what is uploaded is what is planned).
pub fn parse(
    files: &ParamsFiles,
    route_file: &Path,
) -> Result<Option<companion_core::route_plan::PlannedRoute>, SpecError> {
    use companion_core::route_plan::{MissionSourceKind, detect_kind, parse_plan, parse_wpl};
    let Ok(text) = files.text(route_file) else {
        return Ok(None);
    };
    let kind = detect_kind(route_file, text)?;
    if !matches!(kind, MissionSourceKind::QgcPlan | MissionSourceKind::Wpl110) {
        return Ok(None);
    }
    let speed = companion_core::guarantee::derive_settings(files, DERIVE_MISSION)?.cruise_speed_mps;
    let mut planned = match kind {
        MissionSourceKind::QgcPlan => parse_plan(route_file, text, speed)?,
        _ => parse_wpl(route_file, text, speed)?,
    };
    let link = LinkParams::load(files, &files.dir().join("link.toml"))?;
    let end = companion_link::actions::RouteEnd::for_handoff(link.flight.handoff);
    end_operator_mission(&mut planned, end);
    Ok(Some(planned))
}

/// An operator's mission that does not end the flight (no RTL or LAND) ends as the route TOML
/// does ([`companion_link::actions::RouteEnd`], `[flight] handoff`): RTL, or LAND at its last
/// position. A companion that dies after the last item never leaves the vehicle hovering, and
/// the plan holds the end flown. Items after an RTL or LAND are not flown: dropped.
pub fn end_operator_mission(planned: &mut PlannedRoute, end: companion_link::actions::RouteEnd) {
    if let Some(k) = (planned.items.iter())
        .position(|i| matches!(i.kind, ItemKind::ReturnToLaunch | ItemKind::Land { .. }))
    {
        planned.items.truncate(k + 1);
        return;
    }
    let last = planned.items.iter().rev().find_map(|i| match i.kind {
        ItemKind::Waypoint(p) | ItemKind::Loiter { at: p, .. } => Some(p),
        _ => None,
    });
    let index = planned.items.last().map_or(0, |i| i.index + 1);
    let kind = match end {
        companion_link::actions::RouteEnd::ReturnToLaunch => ItemKind::ReturnToLaunch,
        companion_link::actions::RouteEnd::Land => ItemKind::Land { at: last },
    };
    planned
        .items
        .push(companion_core::route_plan::Item { index, kind });
}

/// The operator's mission as the route `fly` uploads: each planned item as a mission item
/// (positions in the relative-altitude frame, metres above the plan's home; a LOITER_TURNS as
/// the LOITER_TIME it was planned to take; a DO_CHANGE_SPEED as a ground speed), item k of the
/// plan at seq k + 1, and nothing after its RTL or LAND. Returns the route and, per planned
/// item, its file index and upload seq (the route progress follows MISSION_CURRENT by them).
pub fn operator_route(
    planned: &PlannedRoute,
    end: companion_link::actions::RouteEnd,
) -> (Route, Vec<(usize, u16)>) {
    use companion_link::dialect::{MavCmd, MavFrame};
    use companion_link::mission::MissionItem;
    let e7 = |d: f64| (d * 1e7).round() as i32;
    let at = |p: &Position| MissionItem::waypoint(e7(p.lat_deg), e7(p.lon_deg), p.alt_m as f32);
    let mut out = Vec::with_capacity(planned.items.len());
    let mut seqs = Vec::with_capacity(planned.items.len());
    let mut waypoints = Vec::new();
    let mut takeoff_alt = None;
    for item in &planned.items {
        let it = match &item.kind {
            ItemKind::TakeOff { alt_m } => {
                takeoff_alt.get_or_insert(*alt_m);
                MissionItem {
                    command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                    ..MissionItem::waypoint(0, 0, *alt_m as f32)
                }
            }
            ItemKind::Waypoint(p) => at(p),
            ItemKind::Loiter { at: p, hold_s } => MissionItem {
                command: MavCmd::MAV_CMD_NAV_LOITER_TIME,
                params: [*hold_s as f32, 0.0, 0.0, 0.0],
                ..at(p)
            },
            ItemKind::ChangeSpeed { mps } => MissionItem {
                command: MavCmd::MAV_CMD_DO_CHANGE_SPEED,
                frame: MavFrame::MAV_FRAME_MISSION,
                // param1 1: ground speed; param3 -1: throttle unchanged.
                params: [1.0, *mps as f32, -1.0, 0.0],
                ..MissionItem::waypoint(0, 0, 0.0)
            },
            ItemKind::ReturnToLaunch => MissionItem {
                command: MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH,
                ..MissionItem::waypoint(0, 0, 0.0)
            },
            ItemKind::Land { at: p } => MissionItem {
                command: MavCmd::MAV_CMD_NAV_LAND,
                ..p.as_ref().map_or(MissionItem::waypoint(0, 0, 0.0), at)
            },
        };
        if let ItemKind::Waypoint(p) | ItemKind::Loiter { at: p, .. } = &item.kind {
            waypoints.push(Waypoint::Absolute {
                lat_e7: e7(p.lat_deg),
                lon_e7: e7(p.lon_deg),
                alt_m: p.alt_m,
            });
        }
        let ends = matches!(item.kind, ItemKind::ReturnToLaunch | ItemKind::Land { .. });
        out.push(it);
        seqs.push((item.index, out.len() as u16));
        if ends {
            break;
        }
    }
    let altitude_m = takeoff_alt
        .or_else(|| {
            waypoints.iter().find_map(|w| match w {
                Waypoint::Absolute { alt_m, .. } | Waypoint::Relative { alt_m, .. } => Some(*alt_m),
            })
        })
        .filter(|a| *a > 0.0)
        .unwrap_or(10.0);
    let route = Route {
        waypoints,
        altitude_m,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        takeoff_first: matches!(
            planned.items.first().map(|i| i.kind),
            Some(ItemKind::TakeOff { .. })
        ),
        end,
        operator_items: out,
    };
    (route, seqs)
}
