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

/// A mission changed in flight, planned from the point reached: the activities already flown
/// (`flown`: the old plan's, before the one being flown), then the new mission from `here` (the
/// vehicle's position, altitude above home) on, from its item `current_seq` (MISSION_CURRENT
/// after the change; the speed in force is its last DO_CHANGE_SPEED before it). A new activity
/// named as a flown one is prefixed `new:`. The PANORAMA mission of the whole (`Derived::spec`)
/// is what the guarantee re-allocates from activity `flown.len()` on
/// (`companion_core::decision::Core::replan_from`).
pub fn from_point_reached(
    files: &ParamsFiles,
    flown: &[companion_core::route_plan::DerivedActivity],
    route: &PlannedRoute,
    current_seq: usize,
    here: companion_core::route_plan::Position,
    settings: &DeriveSettings,
) -> anyhow::Result<Derived> {
    use companion_core::route_plan::ItemKind;
    let mut rest = route.clone();
    rest.items
        .retain(|i| i.index >= current_seq || matches!(i.kind, ItemKind::ChangeSpeed { .. }));
    let mut activities = flown.to_vec();
    for mut a in
        companion_core::route_plan::derive_activities_from(&rest, &[], settings, Some(here))
    {
        if flown.iter().any(|f| f.name == a.name) {
            a.name = format!("new:{}", a.name);
        }
        activities.push(a);
    }
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

    /// A mission changed in flight is planned from the point reached: the activities flown
    /// kept (and their allocation), the new mission's items from MISSION_CURRENT on derived from
    /// where the vehicle is (`leghere-N`), and the guarantee re-allocates only from there, with
    /// what was spent kept and a RAS row saying why.
    #[test]
    fn a_mission_changed_in_flight_is_planned_from_the_point_reached() {
        use companion_core::guarantee::{Guarantee, PackReading, Progress};
        use companion_core::route_plan::Position;
        let files = files();
        let (s, _) = speeds(&params_speeds(&files).unwrap(), |_| None);
        let old = plan(&files, &items(16), true, None, &s).unwrap();
        let mut g = Guarantee::start_or_unbounded(old.spec.clone()).unwrap();
        // Flying leg home-2 (activity 1), 40 % of the pack gone.
        let progress = Progress {
            activity_index: 1,
            activity_fraction: 0.5,
            energy_used_j: None,
            battery_remaining_pct: Some(60.0),
            elapsed_s: 30.0,
            failed_resources: &[],
            pack: PackReading::default(),
        };
        let _ = g.watch(progress);
        // The ground station moves the waypoint further east; the vehicle is half-way.
        let mut new = items(16);
        new[2].params[5] = 149.169230;
        let planned: Vec<_> = new.clone();
        let route = autopilot_mission(&planned, true, None, s.cruise_speed_mps).unwrap();
        let here = Position::offset((-35.363261, 149.165230), 0.0, 90.0, 20.0);
        let part = from_point_reached(&files, &old.activities[..1], &route, 2, here, &s).unwrap();
        let names: Vec<&str> = part.activities.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(names, ["take_off", "leghere-2", "return", "land"]);
        let to = Position::offset((-35.363261, 149.165230), 0.0, 0.0, 20.0);
        let wp = Position {
            lon_deg: 149.169230,
            ..to
        };
        let expect = companion_core::route_plan::leg_length_m(here, wp);
        assert!((part.activities[1].length_m - expect).abs() < 1e-6);
        assert_eq!(
            part.activities[0], old.activities[0],
            "the flown activity kept as planned"
        );
        let g2 = g.replan_from(part.spec.clone(), 1).unwrap();
        assert_eq!(
            g2.choice()[0],
            g.choice()[0],
            "the flown activity keeps its allocation"
        );
        assert_eq!(g2.reallocations(), g.reallocations() + 1);
        let row = g2.ras_rows().last().unwrap();
        assert_eq!(row.from_activity, 1);
        assert!(
            row.reason.contains("mission changed in flight"),
            "{}",
            row.reason
        );
        assert!(row.cells[0].is_none() && row.cells[1].is_some());
        assert_eq!(g2.ras_rows()[0].cells[0], g.ras_rows()[0].cells[0]);
    }
}
