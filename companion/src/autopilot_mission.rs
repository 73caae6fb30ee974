//! `fly --mission autopilot`: the mission on the vehicle, as a ground station uploaded it, is the
//! one flown and planned. The link downloads it (`companion_link::vehicle::Vehicle::
//! watch_autopilot_mission`); here it becomes a route by the `.plan`/WPL rules
//! (`companion_core::route_plan::parse_autopilot_mission`), its activities are derived with the
//! autopilot's own speeds (params `[derive]` only where the autopilot has not answered, said) and
//! planned on the PANORAMA mission [`crate::route_input::DERIVE_MISSION`].

use crate::route_input::{DERIVE_MISSION, Derived};
use companion_core::observations::Observations;
use companion_core::route_plan::{AutopilotItem, DeriveSettings, PlannedRoute};
use companion_core::spec::ParamsFiles;
use std::path::PathBuf;

/// The `--mission` value that flies the autopilot's own mission.
pub const AUTOPILOT: &str = "autopilot";

/// The autopilot's mission as a route: ArduPilot's home at seq 0 (`home_at_seq0`) or, for PX4,
/// the reported `home` (lat, lon, AMSL m). An item the companion cannot plan is refused as
/// `autopilot mission: item N: reason`. `loiter_speed_mps` times LOITER_TURNS.
pub fn autopilot_mission(
    items: &[AutopilotItem],
    home_at_seq0: bool,
    home: Option<(f64, f64, f64)>,
    loiter_speed_mps: f64,
) -> anyhow::Result<PlannedRoute> {
    Ok(companion_core::route_plan::parse_autopilot_mission(
        items,
        home_at_seq0,
        home,
        loiter_speed_mps,
    )?)
}

/// The speeds a route does not give: the autopilot's parameters as observed
/// (`cruise_speed_mps`, `climb_speed_mps`, `descent_speed_mps`), each one it has not reported
/// from params `[derive]`; the names of those taken from params.
pub fn speeds(
    files: &ParamsFiles,
    obs: &Observations,
) -> anyhow::Result<(DeriveSettings, Vec<&'static str>)> {
    let mut s = companion_core::guarantee::derive_settings(files, DERIVE_MISSION)?;
    let mut fallback = Vec::new();
    for (name, v) in [
        ("cruise_speed_mps", &mut s.cruise_speed_mps),
        ("climb_speed_mps", &mut s.climb_speed_mps),
        ("descent_speed_mps", &mut s.descent_speed_mps),
    ] {
        match obs.values.get(name) {
            Some(&x) if x.is_finite() && x > 0.0 => *v = x,
            _ => fallback.push(name),
        }
    }
    Ok((s, fallback))
}

/// The autopilot's mission derived into activities and planned ([`Derived`]: its `spec` is the
/// PANORAMA mission to guarantee).
pub fn plan(
    files: &ParamsFiles,
    items: &[AutopilotItem],
    home_at_seq0: bool,
    home: Option<(f64, f64, f64)>,
    settings: &DeriveSettings,
) -> anyhow::Result<Derived> {
    let planned = autopilot_mission(items, home_at_seq0, home, settings.cruise_speed_mps)?;
    let activities = companion_core::route_plan::derive_activities(&planned, &[], settings);
    let spec = companion_core::guarantee::derived_mission(files, DERIVE_MISSION, &activities, &[])?;
    Ok(Derived {
        route_file: PathBuf::from(companion_core::route_plan::AUTOPILOT_MISSION),
        zones_file: None,
        activities,
        spec,
    })
}

/// What the ground station is told of a plan: activities, length and the planned energy and
/// time of the pre-flight allocation (or that none meets the goals), and where the speeds came
/// from.
pub fn summary(d: &Derived, fallback: &[&str]) -> String {
    let length: f64 = d.activities.iter().map(|a| a.length_m).sum();
    let plan = match companion_core::guarantee::Guarantee::pre_flight(&d.spec) {
        Ok(ras) => {
            let e = ras.totals.get("energy_j").copied().unwrap_or(f64::NAN);
            let t = ras.totals.get("duration_s").copied().unwrap_or(f64::NAN);
            format!("{:.1} kJ {:.0} s", e / 1000.0, t)
        }
        Err(_) => "no allocation meets the goals".to_string(),
    };
    let speeds = if fallback.is_empty() {
        String::new()
    } else {
        format!(", params speeds: {}", fallback.join(" "))
    };
    format!(
        "{} activities {:.0} m, {plan}{speeds}",
        d.activities.len(),
        length
    )
}
