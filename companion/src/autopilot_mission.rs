//! `fly --mission autopilot`: the mission on the vehicle, as a ground station uploaded it, is the
//! one flown and planned. The link downloads it (`companion_link::vehicle::Vehicle::
//! watch_autopilot_mission`); here it becomes a route by the `.plan`/WPL rules
//! (`companion_core::route_plan::parse_autopilot_mission`), its activities are derived with the
//! autopilot's own speeds (params `[derive]` only where the autopilot has not answered, said) and
//! planned on the PANORAMA mission [`crate::route_input::DERIVE_MISSION`].

use crate::route_input::{DERIVE_MISSION, Derived};
use companion_core::route_plan::{AutopilotItem, DeriveSettings, PlannedRoute, Zone};
use companion_core::spec::{ParamsFiles, SpecError};
use std::path::{Path, PathBuf};

/// The `--mission` value that flies the autopilot's own mission.
pub const AUTOPILOT: &str = "autopilot";

/// `fly --mission autopilot --zones FILE`: the zones the autopilot's mission is planned among,
/// read and checked at start (a malformed file stops `fly` before any socket, naming file, item
/// and reason) and placed at each plan from the mission's home (home-relative zones) or as they
/// are (absolute ones).
#[derive(Clone, Debug)]
pub struct MissionZones {
    file: PathBuf,
    text: String,
}

impl MissionZones {
    /// Read and check `file` (a home-relative file is checked placed at 0, 0).
    pub fn load(files: &ParamsFiles, file: &Path) -> Result<Self, SpecError> {
        let mut files = files.clone();
        crate::params::add_file(&mut files, file);
        let text = files.text(file)?.to_string();
        companion_core::route_plan::parse_zones_at(file, &text, Some((0.0, 0.0)))?;
        Ok(Self {
            file: file.to_path_buf(),
            text,
        })
    }

    /// The zones placed from `home` (lat, lon): the mission's, for home-relative ones.
    fn at(&self, home: Option<(f64, f64)>) -> Result<Vec<Zone>, SpecError> {
        companion_core::route_plan::parse_zones_at(&self.file, &self.text, home)
    }
}

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

/// The speeds' params fallback ([`DERIVE_MISSION`]'s `[derive]`, read once at start) and which
/// of its rates a vehicle profile fitted (what the airframe does, not a default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamsSpeeds {
    pub derive: DeriveSettings,
    /// The profile's `[derive].climb_speed_mps` is a fitted rate.
    pub fitted_climb: bool,
    /// The profile's `[derive].descent_speed_mps` is a fitted rate.
    pub fitted_descent: bool,
}

/// [`ParamsSpeeds`] from `files` (the overlay already applied) and `params` (`--params` after
/// `--vehicle`: a profile's overlay file says which rates it fitted).
pub fn params_speeds(files: &ParamsFiles, params: Option<&Path>) -> anyhow::Result<ParamsSpeeds> {
    let derive = companion_core::guarantee::derive_settings(files, DERIVE_MISSION)?;
    let fitted = |name: &str| -> anyhow::Result<bool> {
        let Some(p) = params.filter(|p| crate::params_overlay::is_overlay(p)) else {
            return Ok(false);
        };
        let table = crate::params_overlay::read_overlay_table(p)?;
        let mission = format!("missions/{DERIVE_MISSION}.toml");
        Ok(table
            .get(&mission)
            .and_then(|m| m.get("derive"))
            .and_then(|d| d.get(name))
            .is_some())
    };
    Ok(ParamsSpeeds {
        derive,
        fitted_climb: fitted("climb_speed_mps")?,
        fitted_descent: fitted("descent_speed_mps")?,
    })
}

/// The speeds a route does not give: the autopilot's parameters as `reported` (observations
/// `cruise_speed_mps`, `climb_speed_mps`, `descent_speed_mps`), each one it has not reported
/// from `params`; the names of those taken from params. A climb or descent rate the vehicle
/// profile fitted caps the autopilot's: WPNAV_SPEED_UP/_DN (MPC_Z_V_AUTO_UP/_DN) are commanded
/// maxima, and the vehicle cannot climb faster than it does (ArduCopter SITL: 2.5 m/s commanded,
/// 1.43 m/s flown).
pub fn speeds(
    params: &ParamsSpeeds,
    reported: impl Fn(&str) -> Option<f64>,
) -> (DeriveSettings, Vec<&'static str>) {
    let mut s = params.derive;
    let mut fallback = Vec::new();
    for (name, v, fitted) in [
        ("cruise_speed_mps", &mut s.cruise_speed_mps, false),
        (
            "climb_speed_mps",
            &mut s.climb_speed_mps,
            params.fitted_climb,
        ),
        (
            "descent_speed_mps",
            &mut s.descent_speed_mps,
            params.fitted_descent,
        ),
    ] {
        match reported(name) {
            Some(x) if x.is_finite() && x > 0.0 => *v = if fitted { x.min(*v) } else { x },
            _ => fallback.push(name),
        }
    }
    (s, fallback)
}

/// The autopilot's mission derived into activities and planned ([`Derived`]: its `spec` is the
/// PANORAMA mission to guarantee), among `zones` when given (placed from the mission's home).
pub fn plan(
    files: &ParamsFiles,
    items: &[AutopilotItem],
    home_at_seq0: bool,
    home: Option<(f64, f64, f64)>,
    settings: &DeriveSettings,
    zones: Option<&MissionZones>,
) -> anyhow::Result<Derived> {
    let planned = autopilot_mission(items, home_at_seq0, home, settings.cruise_speed_mps)?;
    let placed = zones.map(|z| z.at(planned.home)).transpose()?;
    let placed = placed.unwrap_or_default();
    let activities = companion_core::route_plan::derive_activities(&planned, &placed, settings);
    derived(files, activities, zones, &placed)
}

/// The PANORAMA mission planned on `activities` (the zones' classes checked against it).
fn derived(
    files: &ParamsFiles,
    activities: Vec<companion_core::route_plan::DerivedActivity>,
    zones: Option<&MissionZones>,
    placed: &[Zone],
) -> anyhow::Result<Derived> {
    let sets: Vec<(&Path, &[Zone])> = zones
        .map(|z| (z.file.as_path(), placed))
        .into_iter()
        .collect();
    let spec =
        companion_core::guarantee::derived_mission(files, DERIVE_MISSION, &activities, &sets)?;
    Ok(Derived {
        panorama: DERIVE_MISSION.to_string(),
        route_file: PathBuf::from(companion_core::route_plan::AUTOPILOT_MISSION),
        zones_file: zones.map(|z| z.file.clone()),
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
    zones: Option<&MissionZones>,
) -> anyhow::Result<Derived> {
    use companion_core::route_plan::ItemKind;
    let mut rest = route.clone();
    rest.items
        .retain(|i| i.index >= current_seq || matches!(i.kind, ItemKind::ChangeSpeed { .. }));
    let placed = zones.map(|z| z.at(route.home)).transpose()?;
    let placed = placed.unwrap_or_default();
    let mut activities = flown.to_vec();
    for mut a in
        companion_core::route_plan::derive_activities_from(&rest, &placed, settings, Some(here))
    {
        if flown.iter().any(|f| f.name == a.name) {
            a.name = format!("new:{}", a.name);
        }
        activities.push(a);
    }
    derived(files, activities, zones, &placed)
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
    use companion_core::route_plan::Position;

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
        let params = params_speeds(&files(), None).unwrap();
        assert!(!params.fitted_climb && !params.fitted_descent, "no profile");
        let mut obs = std::collections::BTreeMap::new();
        let (s, fallback) = speeds(&params, |n| obs.get(n).copied());
        assert_eq!(s, params.derive);
        assert_eq!(
            fallback,
            ["cruise_speed_mps", "climb_speed_mps", "descent_speed_mps"]
        );
        obs.insert("cruise_speed_mps", 7.5);
        obs.insert("descent_speed_mps", 0.9);
        obs.insert("climb_speed_mps", f64::NAN);
        let (s, fallback) = speeds(&params, |n| obs.get(n).copied());
        assert_eq!((s.cruise_speed_mps, s.descent_speed_mps), (7.5, 0.9));
        assert_eq!(s.climb_speed_mps, params.derive.climb_speed_mps);
        assert_eq!(fallback, ["climb_speed_mps"]);
    }

    /// With a vehicle profile (arducopter-sitl: climb 1.43, descent 0.66 m/s fitted), the
    /// autopilot's commanded maxima (WPNAV_SPEED_UP 2.5, _DN 1.5) do not plan a faster take-off
    /// or landing than the vehicle flies; a slower commanded rate still plans slower.
    #[test]
    fn a_profiles_fitted_climb_and_descent_cap_the_autopilots_commanded_maxima() {
        let overlay = crate::params::vehicle_profile(None, "arducopter-sitl").unwrap();
        let profiled = crate::params::read_params_dir(&overlay).unwrap();
        let params = params_speeds(&profiled, Some(&overlay)).unwrap();
        assert!(params.fitted_climb && params.fitted_descent);
        let (climb, descent) = (
            params.derive.climb_speed_mps,
            params.derive.descent_speed_mps,
        );
        assert!(climb < 2.5 && descent < 1.5, "{params:?}");
        let ardupilot = |n: &str| match n {
            "cruise_speed_mps" => Some(10.0),
            "climb_speed_mps" => Some(2.5),
            "descent_speed_mps" => Some(1.5),
            _ => None,
        };
        let (s, fallback) = speeds(&params, ardupilot);
        assert!(fallback.is_empty());
        assert_eq!((s.climb_speed_mps, s.descent_speed_mps), (climb, descent));
        let d = plan(&profiled, &items(16), true, None, &s, None).unwrap();
        let (take_off, land) = (&d.activities[0], d.activities.last().unwrap());
        let duration = |a: &companion_core::route_plan::DerivedActivity| a.length_m / a.speed_mps;
        assert_eq!(
            (take_off.name.as_str(), land.name.as_str()),
            ("take_off", "land")
        );
        // 20 m up at the fitted 1.43 m/s: 14 s, not the 8 s at 2.5 m/s commanded.
        assert!(
            (duration(take_off) - 20.0 / climb).abs() < 1e-9,
            "{take_off:?}"
        );
        assert!(
            (duration(land) - land.length_m / descent).abs() < 1e-9,
            "{land:?}"
        );
        // A commanded rate below the fitted one is what the vehicle flies: it plans.
        let slow = |n: &str| (n == "climb_speed_mps").then_some(1.0);
        let (s, _) = speeds(&params, slow);
        assert_eq!(s.climb_speed_mps, 1.0);
        // Without a profile the autopilot's rates plan as reported.
        let plain = params_speeds(&files(), None).unwrap();
        let (s, _) = speeds(&plain, ardupilot);
        assert_eq!((s.climb_speed_mps, s.descent_speed_mps), (2.5, 1.5));
    }

    /// `--zones` reaches the autopilot's mission: a home-relative band across its leg (placed from
    /// the mission's home, seq 0) splits the leg and the return into pieces and the piece inside
    /// carries the zone's class, in the plan from home and in a re-plan from the point reached;
    /// an absolute file the same; a malformed file is refused at start naming file and reason.
    #[test]
    fn zones_split_the_autopilots_mission_and_its_replan() {
        let files = files();
        let dir = tempfile::tempdir().unwrap();
        let band = |frame: &str, coords: &str| {
            format!(
                r#"{{"type":"FeatureCollection",{frame}"features":[{{"type":"Feature",
                "properties":{{"name":"band","constraints":["gps_degraded"]}},
                "geometry":{{"type":"Polygon","coordinates":[[{coords}]]}}}}]}}"#
            )
        };
        // East 60..120 m, north -50..50 m of home; the waypoint is 0.002 deg (182 m) east.
        let relative = dir.path().join("band.geojson");
        std::fs::write(
            &relative,
            band(
                r#""frame":"home_relative","#,
                "[60,-50],[120,-50],[120,50],[60,50],[60,-50]",
            ),
        )
        .unwrap();
        let (w, e) = (
            149.165230 + 0.002 * 60.0 / 182.0,
            149.165230 + 0.002 * 120.0 / 182.0,
        );
        let absolute = dir.path().join("band_abs.geojson");
        std::fs::write(
            &absolute,
            band(
                "",
                &format!(
                    "[{w},-35.3637],[{e},-35.3637],[{e},-35.3628],[{w},-35.3628],[{w},-35.3637]"
                ),
            ),
        )
        .unwrap();
        let (s, _) = speeds(&params_speeds(&files, None).unwrap(), |_| None);
        for z in [&relative, &absolute] {
            let zones = MissionZones::load(&files, z).unwrap();
            let d = plan(&files, &items(16), true, None, &s, Some(&zones)).unwrap();
            let names: Vec<&str> = d.activities.iter().map(|a| a.name.as_str()).collect();
            assert_eq!(
                names,
                [
                    "take_off",
                    "leghome-2.1",
                    "leghome-2.2",
                    "leghome-2.3",
                    "return.1",
                    "return.2",
                    "return.3",
                    "land"
                ],
                "{}",
                z.display()
            );
            assert_eq!(d.activities[2].constraints, ["gps_degraded"]);
            assert!(
                d.activities[2].source.contains("in zone band"),
                "{:?}",
                d.activities[2]
            );
            assert!(d.activities[1].constraints.is_empty());
            assert_eq!(d.zones_file.as_deref(), Some(z.as_path()));
            assert_eq!(
                d.spec.problem.activities.len(),
                8,
                "the guarantee plans the pieces"
            );
            // Changed in flight at 90 m east (inside the band), on the way to the waypoint.
            let route = autopilot_mission(&items(16), true, None, s.cruise_speed_mps).unwrap();
            let here = Position::offset((-35.363261, 149.165230), 0.0, 90.0, 20.0);
            let part = from_point_reached(
                &files,
                &d.activities[..1],
                &route,
                2,
                here,
                &s,
                Some(&zones),
            )
            .unwrap();
            let names: Vec<&str> = part.activities.iter().map(|a| a.name.as_str()).collect();
            assert_eq!(
                names[..3],
                ["take_off", "leghere-2.1", "leghere-2.2"],
                "{names:?}"
            );
            assert_eq!(
                part.activities[1].constraints,
                ["gps_degraded"],
                "{names:?}"
            );
            assert!(part.activities[2].constraints.is_empty());
        }
        // Without --zones, as before: one leg, one return.
        let d = plan(&files, &items(16), true, None, &s, None).unwrap();
        assert_eq!(d.activities.len(), 4);
        let broken = dir.path().join("broken.geojson");
        std::fs::write(
            &broken,
            r#"{"type":"FeatureCollection","features":[{"type":"Feature"}]}"#,
        )
        .unwrap();
        let e = MissionZones::load(&files, &broken).unwrap_err();
        assert!(e.to_string().contains("broken.geojson"), "{e}");
    }

    #[test]
    fn the_mission_is_planned_at_the_autopilots_speed_or_refused_naming_the_item() {
        let files = files();
        let cruise = |n: &str| (n == "cruise_speed_mps").then_some(4.0);
        let (s, fallback) = speeds(&params_speeds(&files, None).unwrap(), cruise);
        let d = plan(&files, &items(16), true, None, &s, None).unwrap();
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
        let e = plan(&files, &items(17), true, None, &s, None).unwrap_err();
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
        let files = files();
        let (s, _) = speeds(&params_speeds(&files, None).unwrap(), |_| None);
        let old = plan(&files, &items(16), true, None, &s, None).unwrap();
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
        let part =
            from_point_reached(&files, &old.activities[..1], &route, 2, here, &s, None).unwrap();
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
