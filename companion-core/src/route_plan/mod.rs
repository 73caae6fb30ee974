//! PANORAMA phase P1 (section 5 of the paper) done by the companion: the route the vehicle will fly
//! and the operator's zones, split into activities wherever a leg enters or leaves a zone.
//!
//! Pure: every source is parsed from text (`sources`: QGroundControl `.plan`, WPL 110; the shell
//! converts the route TOML, which `companion-link` loads), zones from GeoJSON text (`zones`), and
//! the geometry is `geo`'s. What geometry cannot give (the tasks and TIOs per constraint class, the
//! goals) stays typed in the PANORAMA mission; `crate::guarantee::derived_mission` joins the two.

mod derive;
pub mod mav_cmd;
mod sources;
mod zones;

pub use derive::{
    ActivityKind, DeriveSettings, DerivedActivity, derive_activities, derive_activities_from,
    leg_length_m,
};
pub use sources::{
    AUTOPILOT_MISSION, AutopilotItem, DEFAULT_LOITER_RADIUS_M, MissionSourceKind, detect_kind,
    parse_autopilot_mission, parse_plan, parse_wpl,
};
pub use zones::{HOME_RELATIVE, Zone, parse_zones, parse_zones_at, zones_home_relative};

use std::path::PathBuf;

/// A position of the route: latitude and longitude (degrees, WGS84) and altitude above home (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Position {
    /// Latitude, degrees.
    pub lat_deg: f64,
    /// Longitude, degrees.
    pub lon_deg: f64,
    /// Metres above home.
    pub alt_m: f64,
}

impl Position {
    /// The point `north_m` north and `east_m` east of `home` (geodesic, WGS84), at `alt_m`.
    pub fn offset(home: (f64, f64), north_m: f64, east_m: f64, alt_m: f64) -> Self {
        use geo::{Destination, Geodesic, Point};
        let d = north_m.hypot(east_m);
        let bearing = east_m.atan2(north_m).to_degrees();
        let p = Geodesic.destination(Point::new(home.1, home.0), bearing, d);
        Self {
            lat_deg: p.y(),
            lon_deg: p.x(),
            alt_m,
        }
    }
}

/// Geodesic distance (m, WGS84) between two (lat, lon) points in degrees.
pub fn distance_m(a: (f64, f64), b: (f64, f64)) -> f64 {
    use geo::{Distance, Geodesic, Point};
    Geodesic.distance(Point::new(a.1, a.0), Point::new(b.1, b.0))
}

/// One plannable mission item.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ItemKind {
    /// Climb to `alt_m` above home where the vehicle is.
    TakeOff {
        /// Metres above home.
        alt_m: f64,
    },
    /// Fly to a waypoint.
    Waypoint(Position),
    /// Fly to `at`, then stay there `hold_s` seconds.
    Loiter {
        /// Where.
        at: Position,
        /// How long (LOITER_TIME's time, LOITER_TURNS' turns at the loiter speed).
        hold_s: f64,
    },
    /// Fly the following legs at this horizontal speed (DO_CHANGE_SPEED).
    ChangeSpeed {
        /// m/s.
        mps: f64,
    },
    /// Return to home at the current altitude, then land there.
    ReturnToLaunch,
    /// Land at `at` (fly there first) or, without a position, where the vehicle is.
    Land {
        /// Landing point, when the item gives one.
        at: Option<Position>,
    },
}

/// An item with its index in the source file (`.plan` item index, WPL seq, route waypoint index).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Item {
    /// Index in the file, for the activities' `source` and for errors.
    pub index: usize,
    /// What it does.
    pub kind: ItemKind,
}

/// A mission as the vehicle will fly it, whatever file it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedRoute {
    /// The file it was read from.
    pub file: PathBuf,
    /// Home (lat, lon degrees): the `.plan`'s planned home, WPL seq 0, or the shell's home for a
    /// relative route; `None`: the first position stands in.
    pub home: Option<(f64, f64)>,
    /// Items in flight order.
    pub items: Vec<Item>,
    /// Search at the last waypoint this long (s) before landing: the fly shell's search limit.
    pub search_time_limit_s: Option<f64>,
    /// Track the target this long (s) before landing: the fly shell's tracking limit.
    pub tracking_time_limit_s: Option<f64>,
    /// Zones the file itself carries (a `.plan`'s tagged geofence polygons).
    pub zones: Vec<Zone>,
}

#[cfg(test)]
mod tests;
