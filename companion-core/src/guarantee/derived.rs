//! The PANORAMA mission on activities derived from a route and zones (`crate::route_plan`): the
//! mission file's goals, battery, power model, tasks and constraint classes stay typed; its
//! `[activities]` are replaced by the derived ones, each running the tasks `[derive].tasks` gives
//! its kind.

use super::schema::{ActivityFile, DeriveFile, MissionFile};
use super::{MissionSpec, compile_against_catalogue, mission_path};
use crate::route_plan::{ActivityKind, DeriveSettings, DerivedActivity, Zone};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use std::path::Path;

fn read(
    params: &ParamsFiles,
    mission: &str,
) -> Result<(std::path::PathBuf, MissionFile, DeriveFile), SpecError> {
    let path = mission_path(params, mission);
    let file: MissionFile = read_toml(params, &path)?;
    let derive = file.derive.clone().ok_or_else(|| {
        SpecError::new(
            &path,
            "derive",
            "no [derive] table: the speeds and the tasks of activities derived from a route",
        )
    })?;
    for (key, v) in [
        ("cruise_speed_mps", derive.cruise_speed_mps),
        ("climb_speed_mps", derive.climb_speed_mps),
        ("descent_speed_mps", derive.descent_speed_mps),
    ] {
        if !(v.is_finite() && v > 0.0 && v <= 100.0) {
            return Err(SpecError::new(
                &path,
                format!("derive.{key}"),
                format!("{v}: expected 0..100 m/s"),
            ));
        }
    }
    if !(derive.tracking_speed_mps.is_finite()
        && (0.0..=100.0).contains(&derive.tracking_speed_mps))
    {
        return Err(SpecError::new(
            &path,
            "derive.tracking_speed_mps",
            "expected 0..100 m/s",
        ));
    }
    for (key, v) in [
        ("waypoint_overhead_s", derive.waypoint_overhead_s),
        ("rtl_loiter_s", derive.rtl_loiter_s),
    ] {
        if !(v.is_finite() && (0.0..=600.0).contains(&v)) {
            return Err(SpecError::new(
                &path,
                format!("derive.{key}"),
                format!("{v}: expected 0..600 s"),
            ));
        }
    }
    if !(derive.speed_fraction.is_finite()
        && derive.speed_fraction > 0.0
        && derive.speed_fraction <= 1.0)
    {
        return Err(SpecError::new(
            &path,
            "derive.speed_fraction",
            format!("{}: expected above 0, at most 1", derive.speed_fraction),
        ));
    }
    Ok((path, file, derive))
}

/// The speeds a route does not give, from the mission's `[derive]` (params: the fallback until
/// the autopilot's cruise parameter is read).
pub fn derive_settings(params: &ParamsFiles, mission: &str) -> Result<DeriveSettings, SpecError> {
    let (_, _, d) = read(params, mission)?;
    Ok(DeriveSettings {
        cruise_speed_mps: d.cruise_speed_mps,
        climb_speed_mps: d.climb_speed_mps,
        descent_speed_mps: d.descent_speed_mps,
        waypoint_overhead_s: d.waypoint_overhead_s,
        speed_fraction: d.speed_fraction,
        rtl_loiter_s: d.rtl_loiter_s,
    })
}

fn kind_key(k: ActivityKind) -> &'static str {
    match k {
        ActivityKind::TakeOff => "take_off",
        ActivityKind::Leg => "leg",
        ActivityKind::Loiter => "loiter",
        ActivityKind::Search => "search",
        ActivityKind::Tracking => "tracking",
        ActivityKind::Return => "return",
        ActivityKind::Land => "land",
    }
}

/// The mission `mission` (a name or a path, as `load_mission`) with `activities` in place of its
/// own. Every zone's constraint classes must be the mission's (`zone_sets`: each zones file with
/// its zones, named in the error).
pub fn derived_mission(
    params: &ParamsFiles,
    mission: &str,
    activities: &[DerivedActivity],
    zone_sets: &[(&Path, &[Zone])],
) -> Result<MissionSpec, SpecError> {
    let (path, mut file, derive) = read(params, mission)?;
    for (zones_file, zones) in zone_sets {
        for z in *zones {
            for c in &z.constraints {
                if !file.constraints.contains_key(c) {
                    let known: Vec<&str> = file.constraints.keys().map(String::as_str).collect();
                    return Err(SpecError::new(
                        zones_file,
                        format!("{}.constraints", z.entry),
                        format!(
                            "`{c}` is no constraint class of {} ({})",
                            path.display(),
                            known.join(", ")
                        ),
                    ));
                }
            }
        }
    }
    if activities.is_empty() {
        return Err(SpecError::new(
            &path,
            "activities",
            "the route gives no activity",
        ));
    }
    let mut out = Vec::with_capacity(activities.len());
    for a in activities {
        let key = kind_key(a.kind);
        let tasks = derive.tasks.get(key).cloned().ok_or_else(|| {
            SpecError::new(
                &path,
                format!("derive.tasks.{key}"),
                format!("missing: the tasks a derived `{key}` activity runs"),
            )
        })?;
        let tracking = a.kind == ActivityKind::Tracking;
        out.push(ActivityFile {
            name: a.name.clone(),
            objective: key.to_string(),
            env: a.source.clone(),
            tasks,
            length_m: a.length_m,
            v_max_mps: (a.speed_mps > 0.0).then_some(a.speed_mps),
            speed_commanded: a.speed_mps > 0.0,
            hold_s: a.hold_s,
            hold_speed_mps: if tracking {
                derive.tracking_speed_mps
            } else {
                0.0
            },
            constraints: a.constraints.clone(),
            hold_kind: match a.kind {
                ActivityKind::Search => Some(super::HoldKind::Search),
                ActivityKind::Tracking => Some(super::HoldKind::Tracking),
                _ => None,
            },
            x_start_m: None,
            x_end_m: None,
        });
    }
    file.activities = out;
    compile_against_catalogue(params, &path, file)
}
