//! The route and zones `check`, `simulate` and `fly` plan on (PANORAMA P1,
//! `companion_core::route_plan`): the shell's part is reading the files and loading the route
//! TOML with its own loader; parsing, geometry and the allocation are the core's.
//!
//! The plan judged is the route's (docs/guarantee.md):
//! - nothing given: the activities derived from the route `fly` flies (`--route` / fly's
//!   `--mission`, default params/missions/tracking_route.toml) and, for the default route, the
//!   shipped zones (params/missions/tracking_zones.geojson);
//! - `--mission FILE` told by content: a QGroundControl `.plan`, a WPL 110 file or the project's
//!   route TOML is the route (zones only from `--zones` and a `.plan`'s own tagged fence);
//! - `--zones FILE.geojson`: the zones, on the route given or the default one;
//! - `--mission NAME` (a PANORAMA mission, `tracking`, `patrolling` or its file) without
//!   `--zones`: that mission's typed `[[activities]]`, the legacy plan, chosen explicitly.

use anyhow::Context;
use companion_core::guarantee::MissionSpec;
use companion_core::route_plan::{
    DerivedActivity, ItemKind, MissionSourceKind, PlannedRoute, Position, Zone,
};
use companion_core::spec::ParamsFiles;
use companion_link::actions::{Route, Waypoint};
use std::path::{Path, PathBuf};

// The plan summary is the log header's record (`crate::decision_log`, floor 2); kept here by
// its old path.
pub use crate::decision_log::{PlanSummary, PlannedActivity};

pub use crate::operator_mission::DERIVE_MISSION;

/// The zones of the default route, relative to the params directory (home-relative: they sit on
/// the route wherever the autopilot's home is).
pub const DEFAULT_ZONES: &str = "missions/tracking_zones.geojson";

/// What `check`, `simulate` and `fly` derived.
#[derive(Debug, Clone)]
pub struct Derived {
    /// The PANORAMA mission the activities are planned against (tasks, TIOs, goals).
    pub panorama: String,
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

/// Add the files the plan reads to `files`: `--mission FILE` (when a file), `--zones`, `--route`,
/// and the default zones (params/missions/tracking_zones.geojson: not a `.toml`, so not read
/// with the params directory) when it exists.
pub fn add_plan_files(
    files: &mut ParamsFiles,
    mission: Option<&str>,
    zones: Option<&Path>,
    route: Option<&Path>,
) {
    // A mission name (`tracking`) is no file; a path that is there but not a regular file (a
    // FIFO) is added, so the loader names it.
    let mission = mission.map(Path::new).filter(|m| m.exists());
    for f in [mission, zones, route].into_iter().flatten() {
        crate::params::add_file(files, f);
    }
    let default_zones = files.dir().join(DEFAULT_ZONES);
    if default_zones.is_file() {
        crate::params::add_file(files, &default_zones);
    }
}

/// `fly` with a route relative to home among absolute zones and no `--home`: the geometry
/// depends on where home is, so the plan waits for the autopilot's (`fly::home_plan`).
pub fn plan_needs_home(
    dir: &Path,
    zones: Option<&Path>,
    route: Option<&Path>,
    home: Option<&str>,
) -> anyhow::Result<bool> {
    let Some(z) = zones.filter(|_| home.is_none()) else {
        return Ok(false);
    };
    let mut files = crate::params::read_params_dir(dir)?;
    add_plan_files(&mut files, None, Some(z), route);
    let route = route.map_or_else(|| dir.join(crate::params::DEFAULT_ROUTE), Path::to_path_buf);
    if operator_kind(&files, &route)?.is_some()
        || companion_core::route_plan::zones_home_relative(files.text(z)?)
    {
        return Ok(false);
    }
    let r = Route::load(&files, &route)?;
    Ok(r.waypoints
        .iter()
        .any(|w| matches!(w, Waypoint::Relative { .. })))
}

/// Derive the activities and the PANORAMA mission on them: the plan `check`, `simulate` and
/// `fly` judge (the module's rules); `None` only for a PANORAMA mission named without `--zones`
/// (its typed activities, the legacy plan).
pub fn derive(
    files: &ParamsFiles,
    mission: Option<&str>,
    zones_file: Option<&Path>,
    route_file: Option<&Path>,
    home: Option<&str>,
) -> anyhow::Result<Option<Derived>> {
    derive_at_cruise(files, mission, zones_file, route_file, home, None)
}

/// [`derive`] with the cruise speed the autopilot reports (`fly`: WPNAV_SPEED, MPC_XY_CRUISE)
/// in place of params' `[derive].cruise_speed_mps`; `None`: params'.
pub fn derive_at_cruise(
    files: &ParamsFiles,
    mission: Option<&str>,
    zones_file: Option<&Path>,
    route_file: Option<&Path>,
    home: Option<&str>,
    cruise_speed_mps: Option<f64>,
) -> anyhow::Result<Option<Derived>> {
    let mut kind = mission_route_kind(files, mission)?;
    if kind.is_none() && mission.is_some() && zones_file.is_none() {
        return Ok(None);
    }
    // `fly --mission FILE.plan`: the route flown is the operator's file (told by content).
    let mut mission = mission;
    if kind.is_none()
        && let Some(r) = route_file
        && let Some(k) = operator_kind(files, r)?
    {
        kind = Some(k);
        mission = r.to_str();
    }
    // The shipped zones belong to the shipped route: only the default route gets them unasked.
    let default_zones = files.dir().join(DEFAULT_ZONES);
    let default_route = files.dir().join(crate::params::DEFAULT_ROUTE);
    let is_default_route = route_file.is_none_or(|r| same_file(r, &default_route));
    let zones_file = match (zones_file, kind) {
        (Some(z), _) => Some(z),
        (None, None) if is_default_route && files.contains(&default_zones) => {
            Some(default_zones.as_path())
        }
        _ => None,
    };
    let home = home.map(parse_home).transpose()?;
    // A PANORAMA mission given with `--zones` is the one planned; a route file in `--mission`
    // leaves the default.
    let panorama = match kind {
        None => mission.unwrap_or(DERIVE_MISSION),
        Some(_) => DERIVE_MISSION,
    };
    let mut settings = companion_core::guarantee::derive_settings(files, panorama)?;
    if let Some(v) = cruise_speed_mps {
        settings.cruise_speed_mps = v;
    }
    // Home-relative zones are placed from the route's home: `--home`, a `.plan`'s planned home
    // or WPL seq 0; a route TOML relative to home and home-relative zones need none (both are
    // placed from the same point, so the geometry is the same anywhere: 0, 0 stands in).
    let relative_zones = match zones_file {
        Some(z) => companion_core::route_plan::zones_home_relative(files.text(z)?),
        None => false,
    };
    let (file, planned) = match (kind, mission) {
        (Some(MissionSourceKind::QgcPlan | MissionSourceKind::Wpl110), Some(m))
            if route_file.is_some_and(|r| Some(r) == Some(Path::new(m))) =>
        {
            // `fly --mission FILE`: planned as uploaded (its end included).
            let p = Path::new(m);
            let plan =
                crate::operator_mission::parse(files, p)?.context("the operator's mission file")?;
            (p.to_path_buf(), plan)
        }
        (Some(MissionSourceKind::QgcPlan), Some(m)) => {
            let p = Path::new(m);
            let plan = companion_core::route_plan::parse_plan(
                p,
                files.text(p)?,
                settings.cruise_speed_mps,
            )?;
            (p.to_path_buf(), plan)
        }
        (Some(MissionSourceKind::Wpl110), Some(m)) => {
            let p = Path::new(m);
            let plan = companion_core::route_plan::parse_wpl(
                p,
                files.text(p)?,
                settings.cruise_speed_mps,
            )?;
            (p.to_path_buf(), plan)
        }
        (Some(_), Some(m)) => {
            let free = zones_file.is_none() || relative_zones;
            route_toml(files, Path::new(m), home, free)?
        }
        _ => {
            let p = route_file.map_or_else(
                || files.dir().join(crate::params::DEFAULT_ROUTE),
                Path::to_path_buf,
            );
            route_toml(files, &p, home, zones_file.is_none() || relative_zones)?
        }
    };
    let zones_home = home.or(planned.home);
    let zones: Vec<Zone> = match zones_file {
        Some(z) => companion_core::route_plan::parse_zones_at(z, files.text(z)?, zones_home)?,
        None => Vec::new(),
    };
    let activities = companion_core::route_plan::derive_activities(&planned, &zones, &settings);
    let mut sets: Vec<(&Path, &[Zone])> = vec![(file.as_path(), planned.zones.as_slice())];
    if let Some(z) = zones_file {
        sets.push((z, zones.as_slice()));
    }
    let spec = companion_core::guarantee::derived_mission(files, panorama, &activities, &sets)?;
    Ok(Some(Derived {
        panorama: panorama.to_string(),
        route_file: file,
        zones_file: zones_file.map(Path::to_path_buf),
        activities,
        spec,
    }))
}

fn same_file(a: &Path, b: &Path) -> bool {
    a == b || matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// Params loaded and cross-checked as `check`, `simulate` and `fly` load them, with the plan
/// they judge in place of the typed PANORAMA mission (the module's rules): `mission` a route
/// file or a PANORAMA mission (`check`, `simulate`), `route` the route `fly` flies.
pub fn load_with_plan(
    dir: &Path,
    mission: Option<&str>,
    zones: Option<&Path>,
    route: Option<&Path>,
    home: Option<&str>,
) -> anyhow::Result<(crate::params::Params, PlanSummary)> {
    let mut files = crate::params::read_params_dir(dir)?;
    add_plan_files(&mut files, mission, zones, route);
    let mut loaded = crate::params::Params::from_files(files, route)?;
    let derived = derive(&loaded.files, mission, zones, route, home)?;
    let plan = apply(&mut loaded.model, derived.as_ref());
    // The simulated world reports where it is on the derived plan (`crate::sim_plan`).
    loaded.world.plan =
        derived.map_or_else(Vec::new, |d| d.activities.iter().map(|a| a.kind).collect());
    Ok((loaded, plan))
}

/// `fly --mission FILE`'s kind when it is an operator's mission (a `.plan` or WPL 110 file, by
/// content); `None` for the route TOML.
pub fn operator_kind(
    files: &ParamsFiles,
    route: &Path,
) -> anyhow::Result<Option<MissionSourceKind>> {
    let Ok(text) = files.text(route) else {
        return Ok(None);
    };
    let kind = companion_core::route_plan::detect_kind(route, text)?;
    Ok(matches!(kind, MissionSourceKind::QgcPlan | MissionSourceKind::Wpl110).then_some(kind))
}

/// A route TOML as mission items; `home_free`: where home is does not change its geometry
/// (no zones, or zones placed from home too), so a relative route needs no `--home`.
fn route_toml(
    files: &ParamsFiles,
    p: &Path,
    home: Option<(f64, f64)>,
    home_free: bool,
) -> anyhow::Result<(PathBuf, PlannedRoute)> {
    let route = Route::load(files, p)?;
    // An absolute route's home is its first position (no stand-in at 0, 0).
    let relative = (route.waypoints.iter()).any(|w| matches!(w, Waypoint::Relative { .. }));
    let home = home.or((home_free && relative).then_some((0.0, 0.0)));
    Ok((p.to_path_buf(), planned_from_route(&route, p, home)?))
}

/// The plan judged: `derived` when there is one, else `spec` (the typed mission).
pub fn summary(derived: Option<&Derived>, spec: &MissionSpec) -> PlanSummary {
    let spec = derived.map_or(spec, |d| &d.spec);
    let mut lifted = spec.clone();
    for g in &mut lifted.problem.goals {
        g.bound = f64::MAX;
    }
    let ras0 = companion_core::guarantee::Guarantee::pre_flight(&lifted).ok();
    let goal = |name: &str| (spec.problem.goals.iter()).position(|g| g.name == name);
    let (energy, duration) = (
        goal(companion_core::guarantee::ENERGY),
        goal(companion_core::guarantee::DURATION),
    );
    let planned = ras0.as_ref().map_or_else(Vec::new, |r| {
        (spec.problem.activities.iter().zip(&r.choice))
            .map(|(a, &i)| {
                let ia = &a.ias[i];
                PlannedActivity {
                    name: a.name.clone(),
                    ia: ia.name.clone(),
                    energy_j: energy.map(|g| ia.cost[g]),
                    duration_s: duration.map(|g| ia.cost[g]),
                }
            })
            .collect()
    });
    let totals = ras0.map(|r| r.totals).unwrap_or_default();
    PlanSummary {
        mission: derived.map_or_else(|| spec.name.clone(), |d| d.panorama.clone()),
        route_file: derived.map(|d| d.route_file.display().to_string()),
        zones_file: derived.and_then(|d| Some(d.zones_file.as_ref()?.display().to_string())),
        activities: spec.problem.activities.len(),
        planned_energy_j: totals.get("energy_j").copied(),
        planned_duration_s: totals.get("duration_s").copied(),
        derived: derived.map(|d| d.activities.clone()).unwrap_or_default(),
        planned,
    }
}

/// One line for people: `plan: 9 activities derived from ROUTE and the zones of ZONES (mission
/// tracking): planned 61.2 kJ over 512 s`.
pub fn summary_line(s: &PlanSummary) -> String {
    use std::fmt::Write;
    let mut t = format!("plan: {} activities ", s.activities);
    match &s.route_file {
        Some(r) => {
            let _ = write!(t, "derived from {r}");
            if let Some(z) = &s.zones_file {
                let _ = write!(t, " and the zones of {z}");
            }
            let _ = write!(t, " (mission {})", s.mission);
        }
        None => {
            let _ = write!(t, "typed in mission {} (legacy plan)", s.mission);
        }
    }
    let _ = write!(t, ": planned");
    if let Some(e) = s.planned_energy_j {
        let _ = write!(t, " {:.1} kJ", e / 1000.0);
    }
    if let Some(d) = s.planned_duration_s {
        let _ = write!(t, " over {d:.0} s");
    }
    t
}

/// The plan `check`, `simulate` and `fly` judge, in place of the model's typed PANORAMA mission
/// (`None`: the typed mission stays). Returns what was planned.
pub fn apply(
    model: &mut companion_core::decision::Model,
    derived: Option<&Derived>,
) -> PlanSummary {
    if let Some(d) = derived {
        model.guarantee = d.spec.clone();
    }
    summary(derived, &model.guarantee)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> ParamsFiles {
        let mut files =
            crate::params::read_params_dir(&crate::params::default_params_dir()).unwrap();
        add_plan_files(&mut files, None, None, None);
        files
    }

    /// The default plan is the shipped route with the shipped zones; a PANORAMA mission named
    /// without zones is the typed plan; another route gets no zones unasked.
    #[test]
    fn the_default_plan_is_the_shipped_route_and_zones_and_a_named_mission_is_typed() {
        let mut files = shipped();
        let d = derive(&files, None, None, None, None).unwrap().unwrap();
        assert!(d.zones_file.unwrap().ends_with(DEFAULT_ZONES));
        let degraded: Vec<&str> = (d.activities.iter())
            .filter(|a| a.constraints == ["gps_degraded"])
            .map(|a| a.name.as_str())
            .collect();
        assert_eq!(degraded, ["leg1-2.2", "leg3-4.2"]);
        assert!(
            derive(&files, Some("tracking"), None, None, None)
                .unwrap()
                .is_none()
        );
        let other = files.dir().join("other_route.toml");
        let text = files
            .text(&files.dir().join(crate::params::DEFAULT_ROUTE))
            .unwrap()
            .to_string();
        files.insert(&other, text.as_str());
        let d = derive(&files, None, None, Some(&other), None)
            .unwrap()
            .unwrap();
        assert!(d.zones_file.is_none());
        assert!(d.activities.iter().all(|a| a.constraints.is_empty()));
    }

    /// An absolute route TOML starts from its first position (not from a stand-in home at 0, 0),
    /// and home-relative zones with it need a home.
    #[test]
    fn an_absolute_route_starts_at_its_first_position_and_relative_zones_need_home() {
        let mut files = shipped();
        let r = files.dir().join("abs_route.toml");
        files.insert(
            &r,
            "frame = \"absolute\"\naltitude_m = 20.0\ntakeoff_first = true\n\
             [[waypoint]]\nlat_deg = -35.363261\nlon_deg = 149.165230\n\
             [[waypoint]]\nlat_deg = -35.362261\nlon_deg = 149.165230\n",
        );
        let d = derive(&files, None, None, Some(&r), None).unwrap().unwrap();
        let moved: f64 = d.activities.iter().map(|a| a.length_m).sum();
        // climb 20 + ~111 m north + descent 20: not the 16,000 km from 0, 0
        assert!((140.0..160.0).contains(&moved), "{:#?}", d.activities);
        let zones = files.dir().join(DEFAULT_ZONES);
        let e = derive(&files, None, Some(&zones), Some(&r), None).unwrap_err();
        let e = format!("{e:#}");
        assert!(
            e.contains("tracking_zones.geojson") && e.contains("need home"),
            "{e}"
        );
        assert!(
            derive(
                &files,
                None,
                Some(&zones),
                Some(&r),
                Some("-35.363261,149.165230")
            )
            .is_ok()
        );
    }
}
