//! The route and zones `check` plans on (PANORAMA P1, `companion_core::route_plan`): the shell's
//! part is reading the files and loading the route TOML with its own loader; parsing, geometry and
//! the allocation are the core's.
//!
//! `--mission FILE` is told by content: a QGroundControl `.plan`, a WPL 110 file or the project's
//! route TOML is the route to derive activities from; a PANORAMA mission TOML (or a name) stays
//! the PANORAMA mission, as before. `--zones FILE.geojson` alone derives from the route `fly`
//! would fly (`--route`, default params/missions/tracking_route.toml). Neither given: nothing is
//! derived and `check` plans the mission's typed activities, as before.

use anyhow::Context;
use companion_core::guarantee::MissionSpec;
use companion_core::route_plan::{
    DerivedActivity, ItemKind, MissionSourceKind, PlannedRoute, Position, Zone,
};
use companion_core::spec::ParamsFiles;
use companion_link::actions::{Route, Waypoint};
use std::path::{Path, PathBuf};

/// The PANORAMA mission derived activities are planned against (its tasks, TIOs, goals) unless
/// `--mission` names another.
pub const DERIVE_MISSION: &str = "tracking";

/// What `check` derived.
#[derive(Debug, Clone)]
pub struct Derived {
    /// The route's file.
    pub route_file: PathBuf,
    /// The zones file, when given.
    pub zones_file: Option<PathBuf>,
    /// The activities, in flight order.
    pub activities: Vec<DerivedActivity>,
    /// The PANORAMA mission on them.
    pub spec: MissionSpec,
}

/// The route file `--mission` names, when it is one (by content); `files` holds its text.
pub fn mission_route_kind(
    files: &ParamsFiles,
    mission: Option<&str>,
) -> anyhow::Result<Option<MissionSourceKind>> {
    let Some(m) = mission.map(Path::new).filter(|m| files.contains(m)) else {
        return Ok(None);
    };
    let kind = companion_core::route_plan::detect_kind(m, files.text(m)?)?;
    Ok((kind != MissionSourceKind::PanoramaToml).then_some(kind))
}

/// Parse `home` given as `LAT,LON`.
pub fn parse_home(s: &str) -> anyhow::Result<(f64, f64)> {
    let (lat, lon) = s.split_once(',').context("--home: expected LAT,LON")?;
    let lat: f64 = lat.trim().parse().context("--home latitude")?;
    let lon: f64 = lon.trim().parse().context("--home longitude")?;
    anyhow::ensure!(
        lat.abs() <= 90.0 && lon.abs() <= 180.0,
        "--home {s}: not a latitude and longitude"
    );
    Ok((lat, lon))
}

/// The project's route as mission items: take-off first when it says so, its waypoints (placed
/// from `home` when relative), its search and tracking limits.
pub fn planned_from_route(
    route: &Route,
    file: &Path,
    home: Option<(f64, f64)>,
) -> anyhow::Result<PlannedRoute> {
    let relative = route
        .waypoints
        .iter()
        .any(|w| matches!(w, Waypoint::Relative { .. }));
    let home = match (home, relative) {
        (Some(h), _) => Some(h),
        (None, false) => None,
        (None, true) => anyhow::bail!(
            "{}: a route relative to home needs --home LAT,LON to be placed among the zones",
            file.display()
        ),
    };
    let mut items = Vec::with_capacity(route.waypoints.len() + 1);
    if route.takeoff_first {
        items.push(companion_core::route_plan::Item {
            index: 0,
            kind: ItemKind::TakeOff {
                alt_m: route.altitude_m,
            },
        });
    }
    for (i, w) in route.waypoints.iter().enumerate() {
        let p = match *w {
            Waypoint::Relative {
                north_m,
                east_m,
                alt_m,
            } => Position::offset(home.unwrap_or((0.0, 0.0)), north_m, east_m, alt_m),
            Waypoint::Absolute {
                lat_e7,
                lon_e7,
                alt_m,
            } => Position {
                lat_deg: f64::from(lat_e7) / 1e7,
                lon_deg: f64::from(lon_e7) / 1e7,
                alt_m,
            },
        };
        // Waypoints are numbered from 1, as the route file's comments (wp1 .. wpf).
        items.push(companion_core::route_plan::Item {
            index: i + 1,
            kind: ItemKind::Waypoint(p),
        });
    }
    Ok(PlannedRoute {
        file: file.to_path_buf(),
        home,
        items,
        search_time_limit_s: route.search_time_limit_s,
        tracking_time_limit_s: route.tracking_time_limit_s,
        zones: Vec::new(),
    })
}

/// Derive the activities and the PANORAMA mission on them, when `--mission` is a route file or
/// `--zones` is given; `None` otherwise (the typed mission, unchanged).
pub fn derive(
    files: &ParamsFiles,
    mission: Option<&str>,
    zones_file: Option<&Path>,
    route_file: Option<&Path>,
    home: Option<&str>,
) -> anyhow::Result<Option<Derived>> {
    let kind = mission_route_kind(files, mission)?;
    if kind.is_none() && zones_file.is_none() {
        return Ok(None);
    }
    let home = home.map(parse_home).transpose()?;
    // A PANORAMA mission given with `--zones` is the one planned; a route file in `--mission`
    // leaves the default.
    let panorama = match kind {
        None => mission.unwrap_or(DERIVE_MISSION),
        Some(_) => DERIVE_MISSION,
    };
    let settings = companion_core::guarantee::derive_settings(files, panorama)?;
    let zones: Vec<Zone> = match zones_file {
        Some(z) => companion_core::route_plan::parse_zones(z, files.text(z)?)?,
        None => Vec::new(),
    };
    let (file, planned) = match (kind, mission) {
        (Some(MissionSourceKind::QgcPlan), Some(m)) => {
            let p = Path::new(m);
            (
                p.to_path_buf(),
                companion_core::route_plan::parse_plan(
                    p,
                    files.text(p)?,
                    settings.cruise_speed_mps,
                )?,
            )
        }
        (Some(MissionSourceKind::Wpl110), Some(m)) => {
            let p = Path::new(m);
            (
                p.to_path_buf(),
                companion_core::route_plan::parse_wpl(
                    p,
                    files.text(p)?,
                    settings.cruise_speed_mps,
                )?,
            )
        }
        (Some(_), Some(m)) => route_toml(files, Path::new(m), home, !zones.is_empty())?,
        _ => {
            let p = route_file.map_or_else(
                || files.dir().join(crate::params::DEFAULT_ROUTE),
                Path::to_path_buf,
            );
            route_toml(files, &p, home, !zones.is_empty())?
        }
    };
    let activities = companion_core::route_plan::derive_activities(&planned, &zones, &settings);
    let mut sets: Vec<(&Path, &[Zone])> = vec![(file.as_path(), planned.zones.as_slice())];
    if let Some(z) = zones_file {
        sets.push((z, zones.as_slice()));
    }
    let spec = companion_core::guarantee::derived_mission(files, panorama, &activities, &sets)?;
    Ok(Some(Derived {
        route_file: file,
        zones_file: zones_file.map(Path::to_path_buf),
        activities,
        spec,
    }))
}

fn route_toml(
    files: &ParamsFiles,
    p: &Path,
    home: Option<(f64, f64)>,
    zones: bool,
) -> anyhow::Result<(PathBuf, PlannedRoute)> {
    let route = Route::load(files, p)?;
    // Without zones a relative route's lengths do not depend on where home is.
    let home = home.or((!zones).then_some((0.0, 0.0)));
    Ok((p.to_path_buf(), planned_from_route(&route, p, home)?))
}

/// `check --json`'s `activities`: each with `name`, `length_m`, `hold_s`, `constraints`, `source`
/// (and its `kind` and `speed_mps`).
pub fn activities_json(d: &Derived) -> serde_json::Value {
    serde_json::to_value(&d.activities).unwrap_or(serde_json::Value::Null)
}

/// The derived activities for people, one a line with its source.
pub fn activities_text(d: &Derived) -> String {
    use std::fmt::Write;
    let mut t = format!("\nActivities derived from {}", d.route_file.display());
    if let Some(z) = &d.zones_file {
        let _ = write!(t, " and the zones of {}", z.display());
    }
    let _ = writeln!(t, " (PANORAMA P1):");
    for a in &d.activities {
        let c = if a.constraints.is_empty() {
            "-".to_string()
        } else {
            a.constraints.join(" ")
        };
        let _ = writeln!(
            t,
            "  {:<14} {:>9.1} m {:>7.1} s hold {:>5.1} m/s  constraints {:<14} <- {}",
            a.name, a.length_m, a.hold_s, a.speed_mps, c, a.source
        );
    }
    t
}
