//! The MAVLink MAV_CMD numbers (common.xml) the route planner and `calibrate` read, defined once:
//! `companion-core` does not depend on the `mavlink` crate, so they are numbers here; the shell
//! checks each against `mavlink`'s `MavCmd` (companion/src/calibrate/legs.rs's tests).

/// MAV_CMD_NAV_WAYPOINT.
pub const NAV_WAYPOINT: u16 = 16;
/// MAV_CMD_NAV_LOITER_UNLIM.
pub const NAV_LOITER_UNLIM: u16 = 17;
/// MAV_CMD_NAV_LOITER_TURNS.
pub const NAV_LOITER_TURNS: u16 = 18;
/// MAV_CMD_NAV_LOITER_TIME.
pub const NAV_LOITER_TIME: u16 = 19;
/// MAV_CMD_NAV_RETURN_TO_LAUNCH.
pub const NAV_RETURN_TO_LAUNCH: u16 = 20;
/// MAV_CMD_NAV_LAND.
pub const NAV_LAND: u16 = 21;
/// MAV_CMD_NAV_TAKEOFF.
pub const NAV_TAKEOFF: u16 = 22;
/// MAV_CMD_DO_CHANGE_SPEED.
pub const DO_CHANGE_SPEED: u16 = 178;
