//! How the uploaded route ends after its last waypoint (`wpf`), for when nobody commands the
//! vehicle (the companion dead, hung or restarting): never a hover until the battery fails.

use crate::dialect::{MavCmd, MavFrame};
use crate::mission::MissionItem;

/// The uploaded mission's last item, after the search loiter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RouteEnd {
    /// MAV_CMD_NAV_RETURN_TO_LAUNCH: home, then land (the autopilot's own RTL).
    ReturnToLaunch,
    /// MAV_CMD_NAV_LAND at the last waypoint.
    Land,
}

/// Most NAV_LOITER_TIME seconds: ArduPilot keeps them in 16 bits (AP_Mission `p1`).
pub const MAX_LOITER_TIME_S: f64 = 65_535.0;

/// The items after `wpf`: NAV_LOITER_TIME at wpf for `search_time_limit_s` (when set), then
/// NAV_RETURN_TO_LAUNCH or NAV_LAND at wpf.
pub(super) fn end_items(
    end: RouteEnd,
    search_time_limit_s: Option<f64>,
    wpf: Option<MissionItem>,
) -> Vec<MissionItem> {
    let (x, y, z) = wpf.map_or((0, 0, 0.0), |w| (w.x, w.y, w.z));
    let mut items = Vec::new();
    if let Some(limit) = search_time_limit_s {
        items.push(MissionItem {
            command: MavCmd::MAV_CMD_NAV_LOITER_TIME,
            params: [limit.min(MAX_LOITER_TIME_S) as f32, 0.0, 0.0, 0.0],
            ..MissionItem::waypoint(x, y, z)
        });
    }
    items.push(match end {
        RouteEnd::ReturnToLaunch => MissionItem {
            command: MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH,
            ..MissionItem::waypoint(0, 0, 0.0)
        },
        RouteEnd::Land => MissionItem {
            command: MavCmd::MAV_CMD_NAV_LAND,
            ..MissionItem::waypoint(x, y, 0.0)
        },
    });
    items
}

/// PX4 takes RTL (no position) only in MAV_FRAME_MISSION, else MISSION_ACK UNSUPPORTED (seen on
/// PX4 SITL main 02e73e3b).
pub(super) fn px4_frames(items: &mut [MissionItem]) {
    for it in items {
        if it.command == MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH {
            it.frame = MavFrame::MAV_FRAME_MISSION;
        }
    }
}

/// An operator's mission (`fly --mission FILE.plan`): its items after `home`, and when they do
/// not end the flight (no RTL or LAND) the route's own end ([`RouteEnd`], as `[flight] handoff`
/// says): a companion that dies after the last item never leaves the vehicle hovering.
pub(super) fn operator_mission(
    route: &super::Route,
    mut items: Vec<MissionItem>,
) -> Vec<MissionItem> {
    let ops = &route.operator_items;
    items.extend(ops.iter().cloned());
    let ends = ops.iter().any(|i| {
        matches!(
            i.command,
            MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH | MavCmd::MAV_CMD_NAV_LAND
        )
    });
    if !ends {
        let last_nav = ops.iter().rev().find(|i| is_nav_position(i));
        items.extend(end_items(route.end, None, last_nav.cloned()));
    }
    items
}

/// The seqs (item k at k + 1) of the operator's items that fly to a position (waypoints,
/// loiters): the mission estimate's first and last waypoint.
pub(super) fn operator_nav_seqs(ops: &[MissionItem]) -> Vec<u16> {
    (ops.iter().enumerate())
        .filter(|(_, i)| is_nav_position(i) && i.command != MavCmd::MAV_CMD_NAV_LAND)
        .map(|(k, _)| (k + 1) as u16)
        .collect()
}

/// An item that flies to a position: waypoint, loiter, or a land at a given point.
fn is_nav_position(i: &MissionItem) -> bool {
    matches!(
        i.command,
        MavCmd::MAV_CMD_NAV_WAYPOINT
            | MavCmd::MAV_CMD_NAV_LOITER_TIME
            | MavCmd::MAV_CMD_NAV_LOITER_TURNS
    ) || (i.command == MavCmd::MAV_CMD_NAV_LAND && (i.x != 0 || i.y != 0))
}
