//! The route `follow_trajectory` uploads (`params/missions/*_route.toml`, or the operator's
//! `.plan`/WPL items): read and checked, and its mission items per autopilot.

use super::*;

/// A route, relative to home (default) or absolute.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRoute {
    #[serde(default = "relative")]
    frame: String,
    /// Altitude above home for waypoints that give none (m).
    altitude_m: f64,
    /// Give up searching after this long (s); the decision core reads it.
    #[serde(default)]
    search_time_limit_s: Option<f64>,
    /// Land after tracking the target this long (s); the fly shell's mission end.
    #[serde(default)]
    tracking_time_limit_s: Option<f64>,
    /// Put a NAV_TAKEOFF first so AUTO works from the ground too.
    #[serde(default = "yes")]
    takeoff_first: bool,
    #[serde(default)]
    description: String,
    waypoint: Vec<RawWaypoint>,
}

fn relative() -> String {
    "relative".into()
}
fn yes() -> bool {
    true
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWaypoint {
    north_m: Option<f64>,
    east_m: Option<f64>,
    lat_deg: Option<f64>,
    lon_deg: Option<f64>,
    alt_m: Option<f64>,
}

/// One route waypoint as the route file gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Waypoint {
    /// Metres north / east of home.
    Relative {
        /// Metres north of home.
        north_m: f64,
        /// Metres east of home.
        east_m: f64,
        /// Metres above home.
        alt_m: f64,
    },
    /// Global position.
    Absolute {
        /// Latitude, degrees * 1e7.
        lat_e7: i32,
        /// Longitude, degrees * 1e7.
        lon_e7: i32,
        /// Metres above home.
        alt_m: f64,
    },
}

/// Highest altitude a route may name (m above home): far above any multirotor's ceiling, low
/// enough that no cast to the autopilot's `f32` or `i32` fields can overflow.
pub const MAX_ALTITUDE_M: f64 = 10_000.0;
/// Most waypoints in a route: MAVLink counts mission items in a `u16`, and autopilots store a
/// few hundred (ArduPilot's default storage holds 724 on most boards).
pub const MAX_WAYPOINTS: usize = 1000;

/// The route flown by `follow_trajectory` (`fly --mission`, params/missions/tracking_route.toml).
#[derive(Debug, Clone, PartialEq)]
pub struct Route {
    /// Waypoints in flight order.
    pub waypoints: Vec<Waypoint>,
    /// Altitude (m above home) of the waypoints that give no `alt_m`.
    pub altitude_m: f64,
    /// Land after this long (s) at the last waypoint without a target: the mission's end.
    pub search_time_limit_s: Option<f64>,
    /// Land after tracking this long (s): the mission's end, which the fly shell enforces.
    pub tracking_time_limit_s: Option<f64>,
    /// Upload a NAV_TAKEOFF before the waypoints, so AUTO also works from the ground.
    pub takeoff_first: bool,
    /// How the uploaded mission ends (RTL unless params/link.toml `[flight] handoff` is land).
    pub end: RouteEnd,
    /// An operator's mission (a QGroundControl `.plan` or a WPL 110 file, `fly --mission FILE`):
    /// its items, uploaded after home (seq 0) in this order, so item k is seq k + 1; empty for
    /// the route TOML, whose `waypoints` are uploaded. `waypoints` then holds its positions.
    pub operator_items: Vec<MissionItem>,
}

impl RouteEnd {
    /// `land` lands; every other hand-off returns (`hold` and `none` say what a stop does: a
    /// mission that holds would hover until the battery failsafe).
    pub fn for_handoff(handoff: Handoff) -> Self {
        match handoff {
            Handoff::Land => RouteEnd::Land,
            Handoff::None | Handoff::Hold | Handoff::Rtl => RouteEnd::ReturnToLaunch,
        }
    }
}

impl Route {
    /// The route as mission items for this autopilot. ArduPilot: [`Route::items`] (seq 0 is home,
    /// which ArduPilot overwrites). PX4 flies seq 0 and rejects a mission whose take-off is not the
    /// first item, and reads a take-off item's lat/lon; so for PX4 the take-off (at home) comes first
    /// and a waypoint over home at the route altitude takes the other slot, which keeps every
    /// waypoint at the same seq on both autopilots (the mission state counts on it).
    ///
    /// PX4 gets the route TOML's end as the shell flies it: after the search loiter a NAV_LAND at
    /// the last waypoint, never an RTL. PX4 flies a mission's RTL item as its RTL mode, which
    /// races the shell's LAND when the search limit runs out and returns home where the plan
    /// lands at wpf (docs/guarantee.md, "PX4 SIH"); an operator's own mission keeps its end.
    pub fn mission_items(&self, flavor: Flavor, home: (i32, i32)) -> Vec<MissionItem> {
        if flavor != Flavor::Px4 {
            return self.items(home);
        }
        let mut items = self.items_ending(home, RouteEnd::Land);
        items[0] = MissionItem::waypoint(home.0, home.1, self.altitude_m as f32);
        if self.takeoff_first && items.len() > 1 {
            items[1].x = home.0;
            items[1].y = home.1;
            items.swap(0, 1);
        }
        route_end::px4_frames(&mut items);
        items
    }

    /// Read and check the route file at `path`.
    pub fn load(files: &ParamsFiles, path: &Path) -> Result<Self, SpecError> {
        let raw: RawRoute = read_toml(files, path)?;
        let _ = raw.description;
        let rel = match raw.frame.as_str() {
            "relative" => true,
            "absolute" => false,
            other => {
                return Err(SpecError::new(
                    path,
                    "frame",
                    format!("{other:?}: expected \"relative\" (to home) or \"absolute\""),
                ));
            }
        };
        check_positive(
            path,
            "altitude_m",
            raw.altitude_m,
            MAX_ALTITUDE_M,
            " m above home",
        )?;
        if let Some(t) = raw.search_time_limit_s {
            check_positive(path, "search_time_limit_s", t, 86_400.0, " s")?;
        }
        if let Some(t) = raw.tracking_time_limit_s {
            check_positive(path, "tracking_time_limit_s", t, 86_400.0, " s")?;
        }
        if raw.waypoint.len() > MAX_WAYPOINTS {
            return Err(SpecError::new(
                path,
                "waypoint",
                format!(
                    "{} waypoints: a route holds at most {MAX_WAYPOINTS}",
                    raw.waypoint.len()
                ),
            ));
        }
        if raw.waypoint.is_empty() {
            return Err(SpecError::new(
                path,
                "waypoint",
                "a route needs at least one waypoint",
            ));
        }
        let mut waypoints = Vec::new();
        for (i, w) in raw.waypoint.iter().enumerate() {
            let entry = format!("waypoint[{i}]");
            let alt_m = w.alt_m.unwrap_or(raw.altitude_m);
            check_range(
                path,
                format!("{entry}.alt_m"),
                alt_m,
                0.0,
                MAX_ALTITUDE_M,
                " m above home",
            )?;
            let wp = if rel {
                if w.lat_deg.is_some() || w.lon_deg.is_some() {
                    return Err(SpecError::new(
                        path,
                        entry,
                        "relative route: use north_m / east_m, not lat_deg / lon_deg",
                    ));
                }
                let (Some(n), Some(e)) = (w.north_m, w.east_m) else {
                    return Err(SpecError::new(path, entry, "needs north_m and east_m"));
                };
                if !n.is_finite() || !e.is_finite() || n.abs() > 50_000.0 || e.abs() > 50_000.0 {
                    return Err(SpecError::new(
                        path,
                        entry,
                        "offsets must be finite and within 50 km of home",
                    ));
                }
                Waypoint::Relative {
                    north_m: n,
                    east_m: e,
                    alt_m,
                }
            } else {
                if w.north_m.is_some() || w.east_m.is_some() {
                    return Err(SpecError::new(
                        path,
                        entry,
                        "absolute route: use lat_deg / lon_deg, not north_m / east_m",
                    ));
                }
                let (Some(lat), Some(lon)) = (w.lat_deg, w.lon_deg) else {
                    return Err(SpecError::new(path, entry, "needs lat_deg and lon_deg"));
                };
                if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
                    return Err(SpecError::new(
                        path,
                        entry,
                        "latitude must be in -90..90 and longitude in -180..180",
                    ));
                }
                Waypoint::Absolute {
                    lat_e7: (lat * 1e7).round() as i32,
                    lon_e7: (lon * 1e7).round() as i32,
                    alt_m,
                }
            };
            waypoints.push(wp);
        }
        Ok(Self {
            waypoints,
            altitude_m: raw.altitude_m,
            search_time_limit_s: raw.search_time_limit_s,
            tracking_time_limit_s: raw.tracking_time_limit_s,
            takeoff_first: raw.takeoff_first,
            end: RouteEnd::ReturnToLaunch,
            operator_items: Vec::new(),
        })
    }

    /// Mission items for upload: seq 0 home, an optional takeoff, the waypoints, then the
    /// mission's own end for when nobody commands: NAV_LOITER_TIME at the last waypoint for
    /// `search_time_limit_s` (when set), and NAV_RETURN_TO_LAUNCH or NAV_LAND ([`RouteEnd`]).
    pub fn items(&self, home: (i32, i32)) -> Vec<MissionItem> {
        self.items_ending(home, self.end)
    }

    /// [`Route::items`] with the route TOML's end `end` (an operator's mission keeps its own).
    fn items_ending(&self, home: (i32, i32), end: RouteEnd) -> Vec<MissionItem> {
        use crate::dialect::MavFrame;
        let mut items = vec![MissionItem {
            frame: MavFrame::MAV_FRAME_GLOBAL,
            ..MissionItem::waypoint(home.0, home.1, 0.0)
        }];
        if !self.operator_items.is_empty() {
            return route_end::operator_mission(self, items);
        }
        if self.takeoff_first {
            items.push(MissionItem {
                command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                ..MissionItem::waypoint(0, 0, self.altitude_m as f32)
            });
        }
        for w in &self.waypoints {
            let (x, y, alt) = match *w {
                Waypoint::Relative {
                    north_m,
                    east_m,
                    alt_m,
                } => {
                    let (x, y) = displace(home, north_m, east_m);
                    (x, y, alt_m)
                }
                Waypoint::Absolute {
                    lat_e7,
                    lon_e7,
                    alt_m,
                } => (lat_e7, lon_e7, alt_m),
            };
            items.push(MissionItem::waypoint(x, y, alt as f32));
        }
        let wpf = items.last().cloned();
        items.extend(route_end::end_items(end, self.search_time_limit_s, wpf));
        items
    }

    /// Mission seq of the first waypoint (`wp1`): after the take-off.
    pub fn first_waypoint_seq(&self) -> u16 {
        match route_end::operator_nav_seqs(&self.operator_items).first() {
            Some(&s) => s,
            None => 1 + u16::from(self.takeoff_first),
        }
    }

    /// Mission seq of the last waypoint (`wpf`): the items after it are the mission's end.
    pub fn last_waypoint_seq(&self) -> u16 {
        match route_end::operator_nav_seqs(&self.operator_items).last() {
            Some(&s) => s,
            None => (self.waypoints.len() + usize::from(self.takeoff_first)) as u16,
        }
    }
}
