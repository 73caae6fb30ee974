//! `fly --mission autopilot`: the mission on the vehicle, as a ground station uploaded it, is the
//! one flown and planned. The link downloads it (`companion_link::vehicle::Vehicle::
//! watch_autopilot_mission`); here it becomes a route by the `.plan`/WPL rules
//! (`companion_core::route_plan::parse_autopilot_mission`), its activities are derived with the
//! autopilot's own speeds (params `[derive]` only where the autopilot has not answered, said) and
//! planned on the PANORAMA mission [`crate::route_input::DERIVE_MISSION`].

use crate::route_input::{DERIVE_MISSION, Derived};
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

/// The params fallback of the speeds: [`DERIVE_MISSION`]'s `[derive]` (read once, at start).
pub fn params_speeds(files: &ParamsFiles) -> anyhow::Result<DeriveSettings> {
    Ok(companion_core::guarantee::derive_settings(
        files,
        DERIVE_MISSION,
    )?)
}

/// The speeds a route does not give: the autopilot's parameters as `reported` (observations
/// `cruise_speed_mps`, `climb_speed_mps`, `descent_speed_mps`), each one it has not reported
/// from `params`; the names of those taken from params.
pub fn speeds(
    params: &DeriveSettings,
    reported: impl Fn(&str) -> Option<f64>,
) -> (DeriveSettings, Vec<&'static str>) {
    let mut s = *params;
    let mut fallback = Vec::new();
    for (name, v) in [
        ("cruise_speed_mps", &mut s.cruise_speed_mps),
        ("climb_speed_mps", &mut s.climb_speed_mps),
        ("descent_speed_mps", &mut s.descent_speed_mps),
    ] {
        match reported(name) {
            Some(x) if x.is_finite() && x > 0.0 => *v = x,
            _ => fallback.push(name),
        }
    }
    (s, fallback)
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
        panorama: DERIVE_MISSION.to_string(),
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

#[cfg(test)]
mod tests {
    use super::*;
    use companion_core::route_plan::AutopilotItem;

    fn files() -> ParamsFiles {
        crate::params::read_params_dir(&crate::params::default_params_dir()).unwrap()
    }

    /// ArduPilot's answer: home, take-off to 20 m, a waypoint 0.002 deg east, RTL.
    fn items(second: u64) -> Vec<AutopilotItem> {
        let it = |seq, command, frame, lat, lon, alt| AutopilotItem {
            seq,
            command,
            frame,
            params: [0.0, 0.0, 0.0, 0.0, lat, lon, alt],
        };
        vec![
            it(0, 16, 0, -35.363261, 149.165230, 584.0),
            it(1, 22, 3, 0.0, 0.0, 20.0),
            it(2, second, 3, -35.363261, 149.167230, 20.0),
            it(3, 20, 3, 0.0, 0.0, 0.0),
        ]
    }

    #[test]
    fn the_autopilots_speeds_replace_params_and_a_missing_one_is_named() {
        let params = params_speeds(&files()).unwrap();
        let mut obs = std::collections::BTreeMap::new();
        let (s, fallback) = speeds(&params, |n| obs.get(n).copied());
        assert_eq!(s, params);
        assert_eq!(
            fallback,
            ["cruise_speed_mps", "climb_speed_mps", "descent_speed_mps"]
        );
        obs.insert("cruise_speed_mps", 7.5);
        obs.insert("descent_speed_mps", 0.9);
        obs.insert("climb_speed_mps", f64::NAN);
        let (s, fallback) = speeds(&params, |n| obs.get(n).copied());
        assert_eq!((s.cruise_speed_mps, s.descent_speed_mps), (7.5, 0.9));
        assert_eq!(s.climb_speed_mps, params.climb_speed_mps);
        assert_eq!(fallback, ["climb_speed_mps"]);
    }

    #[test]
    fn the_mission_is_planned_at_the_autopilots_speed_or_refused_naming_the_item() {
        let files = files();
        let cruise = |n: &str| (n == "cruise_speed_mps").then_some(4.0);
        let (s, fallback) = speeds(&params_speeds(&files).unwrap(), cruise);
        let d = plan(&files, &items(16), true, None, &s).unwrap();
        let names: Vec<&str> = d.activities.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["take_off", "leghome-2", "return", "land"]);
        assert_eq!(d.activities[1].speed_mps, 4.0, "WPNAV_SPEED, not [derive]");
        assert_eq!(
            d.spec.problem.activities.len(),
            4,
            "the guarantee plans them"
        );
        let said = summary(&d, &fallback);
        assert!(said.starts_with("4 activities"), "{said}");
        assert!(
            said.contains("params speeds: climb_speed_mps descent_speed_mps"),
            "{said}"
        );
        let e = plan(&files, &items(17), true, None, &s).unwrap_err();
        assert!(
            format!("{e:#}").starts_with("autopilot mission: item 2: LOITER_UNLIM"),
            "{e:#}"
        );
    }
}
