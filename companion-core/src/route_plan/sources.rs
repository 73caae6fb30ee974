//! Mission files from the operator's tools, told apart by content, never by extension:
//! QGroundControl `.plan` (JSON, `"fileType": "Plan"`) and WPL 110 (`QGC WPL 110` first line);
//! the project's route TOML (`[[waypoint]]`) and a PANORAMA mission TOML (`[mission]`) are
//! recognised so the shell can hand them to their own loaders.

use super::{Item, ItemKind, PlannedRoute, Position, Zone};
use crate::spec::SpecError;
use std::path::Path;

/// What a `--mission FILE` holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissionSourceKind {
    /// A QGroundControl `.plan`.
    QgcPlan,
    /// A WPL 110 text file (QGroundControl / Mission Planner).
    Wpl110,
    /// The project's route TOML (params/missions/tracking_route.toml's format).
    RouteToml,
    /// A PANORAMA mission TOML (params/missions/tracking.toml's format).
    PanoramaToml,
}

/// Tell a mission file's kind by its content; `Err` names why it is none of them.
pub fn detect_kind(path: &Path, text: &str) -> Result<MissionSourceKind, SpecError> {
    let head = text.trim_start_matches('\u{feff}').trim_start();
    if head.starts_with("QGC WPL") {
        return Ok(MissionSourceKind::Wpl110);
    }
    if head.starts_with('{') {
        return Ok(MissionSourceKind::QgcPlan);
    }
    match toml::from_str::<toml::Table>(text) {
        Ok(t) if t.contains_key("waypoint") => Ok(MissionSourceKind::RouteToml),
        Ok(t) if t.contains_key("mission") => Ok(MissionSourceKind::PanoramaToml),
        Ok(_) => Err(SpecError::new(
            path,
            "-",
            "a TOML file with neither [[waypoint]] (a route) nor [mission] (a PANORAMA mission)",
        )),
        Err(e) => Err(SpecError::new(
            path,
            "-",
            format!(
                "not a QGroundControl .plan (JSON), a WPL 110 file (`QGC WPL 110` first line) \
                 nor TOML: {}",
                e.message()
            ),
        )),
    }
}

use super::mav_cmd::{
    DO_CHANGE_SPEED, NAV_LAND, NAV_LOITER_TIME, NAV_LOITER_TURNS, NAV_LOITER_UNLIM,
    NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF, NAV_WAYPOINT,
};

// MAVLink MAV_FRAME numbers (common.xml).
const FRAME_GLOBAL: u64 = 0;
const FRAME_GLOBAL_RELATIVE_ALT: u64 = 3;
const FRAME_GLOBAL_INT: u64 = 5;
const FRAME_GLOBAL_RELATIVE_ALT_INT: u64 = 6;

/// Loiter radius (m) for LOITER_TURNS items that give none: ArduCopter's default WP_LOITER_RAD
/// is not read yet (ASSUMPTION: 10 m, the autopilot's parameter later).
pub const DEFAULT_LOITER_RADIUS_M: f64 = 10.0;

/// One MAVLink mission item as both formats give it: command, frame, param1..4, x (lat), y (lon),
/// z (alt). `home_alt_m` turns an absolute (AMSL) altitude into one above home.
fn mav_item(
    command: u64,
    frame: u64,
    p: [f64; 7],
    home_alt_m: Option<f64>,
    loiter_speed_mps: f64,
) -> Result<Option<ItemKind>, String> {
    let position = || -> Result<Position, String> {
        let alt_m = match frame {
            FRAME_GLOBAL_RELATIVE_ALT | FRAME_GLOBAL_RELATIVE_ALT_INT => p[6],
            FRAME_GLOBAL | FRAME_GLOBAL_INT => {
                p[6] - home_alt_m.ok_or("an absolute (AMSL) altitude and no home altitude")?
            }
            f => {
                return Err(format!(
                    "frame {f}: only global (0, 5) and relative-altitude (3, 6) frames are planned"
                ));
            }
        };
        let (lat, lon) = (p[4], p[5]);
        if !(lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0) {
            return Err(format!(
                "position ({lat}, {lon}) is not a latitude and longitude"
            ));
        }
        if !alt_m.is_finite() || !(-1000.0..=10_000.0).contains(&alt_m) {
            return Err(format!(
                "altitude {alt_m} m above home is out of -1000..10000"
            ));
        }
        Ok(Position {
            lat_deg: lat,
            lon_deg: lon,
            alt_m,
        })
    };
    // Lat/lon 0,0 on a take-off, land or RTL means "where the vehicle is".
    let here = p[4] == 0.0 && p[5] == 0.0;
    let kind = match u16::try_from(command).unwrap_or(u16::MAX) {
        NAV_WAYPOINT => ItemKind::Waypoint(position()?),
        NAV_TAKEOFF => {
            let alt_m = position()
                .map(|q| q.alt_m)
                .or_else(|e| if here { Ok(p[6]) } else { Err(e) })?;
            if !(alt_m.is_finite() && alt_m > 0.0 && alt_m <= 10_000.0) {
                return Err(format!(
                    "take-off altitude {alt_m} m: expected 0..10000 m above home"
                ));
            }
            ItemKind::TakeOff { alt_m }
        }
        NAV_LOITER_TIME => {
            if !(p[0].is_finite() && p[0] >= 0.0 && p[0] <= 86_400.0) {
                return Err(format!("loiter time {} s: expected 0..86400", p[0]));
            }
            ItemKind::Loiter {
                at: position()?,
                hold_s: p[0],
            }
        }
        NAV_LOITER_TURNS => {
            let radius = if p[2].is_finite() && p[2] != 0.0 {
                p[2].abs()
            } else {
                DEFAULT_LOITER_RADIUS_M
            };
            if !(p[0].is_finite() && p[0] >= 0.0 && p[0] <= 1000.0) {
                return Err(format!("{} turns: expected 0..1000", p[0]));
            }
            let hold_s = p[0] * std::f64::consts::TAU * radius / loiter_speed_mps;
            ItemKind::Loiter {
                at: position()?,
                hold_s,
            }
        }
        NAV_LOITER_UNLIM => {
            return Err(
                "LOITER_UNLIM loiters until the operator acts: no energy plan can hold it \
                        (use LOITER_TIME)"
                    .into(),
            );
        }
        DO_CHANGE_SPEED => {
            // param2 = speed (m/s), -1 or 0 = no change (MAV_CMD_DO_CHANGE_SPEED).
            if p[1] == -1.0 || p[1] == 0.0 {
                return Ok(None);
            }
            if !(p[1].is_finite() && p[1] > 0.0 && p[1] <= 100.0) {
                return Err(format!("speed {} m/s: expected 0..100", p[1]));
            }
            ItemKind::ChangeSpeed { mps: p[1] }
        }
        NAV_RETURN_TO_LAUNCH => ItemKind::ReturnToLaunch,
        NAV_LAND => ItemKind::Land {
            at: if here { None } else { Some(position()?) },
        },
        _ => {
            return Err(format!(
                "command {command} (MAV_CMD) is not one the companion plans: take-off (22), waypoint (16), loiter time/turns (19/18), change speed (178), RTL (20), land (21)"
            ));
        }
    };
    Ok(Some(kind))
}

fn json_f64(v: &serde_json::Value) -> Result<f64, String> {
    match v {
        serde_json::Value::Null => Ok(0.0),
        v => v.as_f64().ok_or_else(|| format!("{v}: expected a number")),
    }
}

/// Parse a QGroundControl `.plan`: its mission items (SimpleItem only), planned home and the
/// geofence polygons tagged as zones (a polygon with a `constraints` list; an untagged fence polygon
/// is the autopilot's fence, not a zone). `loiter_speed_mps` times LOITER_TURNS.
pub fn parse_plan(
    path: &Path,
    text: &str,
    loiter_speed_mps: f64,
) -> Result<PlannedRoute, SpecError> {
    let v: serde_json::Value = serde_json::from_str(text)
        .map_err(|e| SpecError::new(path, "-", format!("not JSON: {e}")))?;
    if v.get("fileType").and_then(|t| t.as_str()) != Some("Plan") {
        return Err(SpecError::new(
            path,
            "fileType",
            "expected \"Plan\" (a QGroundControl .plan)",
        ));
    }
    let mission = v
        .get("mission")
        .ok_or_else(|| SpecError::new(path, "mission", "missing"))?;
    let home = match mission.get("plannedHomePosition") {
        Some(h) => {
            let h: Vec<f64> = h
                .as_array()
                .filter(|a| a.len() == 3)
                .map(|a| a.iter().map(json_f64).collect::<Result<_, _>>())
                .transpose()
                .map_err(|e| SpecError::new(path, "mission.plannedHomePosition", e))?
                .ok_or_else(|| {
                    SpecError::new(
                        path,
                        "mission.plannedHomePosition",
                        "expected [lat, lon, alt]",
                    )
                })?;
            if !(h[0].abs() <= 90.0 && h[1].abs() <= 180.0 && h[2].is_finite()) {
                return Err(SpecError::new(
                    path,
                    "mission.plannedHomePosition",
                    "not a latitude, longitude and altitude",
                ));
            }
            Some((h[0], h[1], h[2]))
        }
        None => None,
    };
    let items_v = mission
        .get("items")
        .and_then(|i| i.as_array())
        .ok_or_else(|| SpecError::new(path, "mission.items", "expected a list of mission items"))?;
    let mut items = Vec::with_capacity(items_v.len());
    for (i, it) in items_v.iter().enumerate() {
        let entry = format!("mission.items[{i}]");
        let kind = plan_item(it, home.map(|h| h.2), loiter_speed_mps)
            .map_err(|r| SpecError::new(path, entry, r))?;
        if let Some(kind) = kind {
            items.push(Item { index: i, kind });
        }
    }
    let zones = plan_zones(path, &v)?;
    Ok(PlannedRoute {
        file: path.to_path_buf(),
        home: home.map(|h| (h.0, h.1)),
        items,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        zones,
    })
}

fn plan_item(
    it: &serde_json::Value,
    home_alt: Option<f64>,
    loiter_speed: f64,
) -> Result<Option<ItemKind>, String> {
    match it.get("type").and_then(|t| t.as_str()) {
        Some("SimpleItem") => {}
        Some("ComplexItem") => {
            return Err(
                "a complex item (survey, corridor scan, structure scan): not planned; \
                        convert it to waypoints in QGroundControl"
                    .into(),
            );
        }
        _ => return Err("expected \"type\": \"SimpleItem\"".into()),
    }
    let command = it
        .get("command")
        .and_then(|c| c.as_u64())
        .ok_or("command: expected a MAV_CMD number")?;
    let frame = it
        .get("frame")
        .and_then(|c| c.as_u64())
        .ok_or("frame: expected a MAV_FRAME number")?;
    let params = it
        .get("params")
        .and_then(|p| p.as_array())
        .filter(|p| p.len() == 7)
        .ok_or("params: expected 7 values")?;
    let mut p = [0.0; 7];
    for (k, x) in params.iter().enumerate() {
        p[k] = json_f64(x).map_err(|e| format!("params[{k}]: {e}"))?;
    }
    mav_item(command, frame, p, home_alt, loiter_speed)
}

fn plan_zones(path: &Path, v: &serde_json::Value) -> Result<Vec<Zone>, SpecError> {
    let Some(polys) = v.get("geoFence").and_then(|g| g.get("polygons")) else {
        return Ok(Vec::new());
    };
    let polys = polys
        .as_array()
        .ok_or_else(|| SpecError::new(path, "geoFence.polygons", "expected a list"))?;
    let mut zones = Vec::new();
    for (i, poly) in polys.iter().enumerate() {
        let entry = format!("geoFence.polygons[{i}]");
        let Some(c) = poly.get("constraints") else {
            continue;
        };
        let err = |r: String| SpecError::new(path, entry.clone(), r);
        let constraints = super::zones::constraint_names(c).map_err(&err)?;
        let corners = poly
            .get("polygon")
            .and_then(|p| p.as_array())
            .ok_or_else(|| err("polygon: expected a list of [lat, lon]".into()))?;
        let mut ring = Vec::with_capacity(corners.len() + 1);
        for c in corners {
            let pair = c
                .as_array()
                .filter(|a| a.len() == 2)
                .and_then(|a| Some((a[0].as_f64()?, a[1].as_f64()?)))
                .ok_or_else(|| err(format!("{c}: expected [lat, lon]")))?;
            ring.push(geo::Coord {
                x: pair.1,
                y: pair.0,
            });
        }
        if let Some(&first) = ring.first() {
            ring.push(first);
        }
        let area =
            geo::MultiPolygon::new(vec![geo::Polygon::new(geo::LineString::new(ring), vec![])]);
        super::zones::check_area(&area).map_err(&err)?;
        let name = poly
            .get("name")
            .and_then(|n| n.as_str())
            .map_or_else(|| entry.clone(), str::to_string);
        zones.push(
            Zone::new(entry.clone(), name, constraints, area)
                .ok_or_else(|| err("empty area".into()))?,
        );
    }
    Ok(zones)
}

/// Parse a WPL 110 file: `QGC WPL 110`, then one item a line, tab- or space-separated: seq,
/// current, frame, command, param1..4, lat, lon, alt, autocontinue. Seq 0 is home (as Mission
/// Planner and ArduPilot write it). `loiter_speed_mps` times LOITER_TURNS.
pub fn parse_wpl(
    path: &Path,
    text: &str,
    loiter_speed_mps: f64,
) -> Result<PlannedRoute, SpecError> {
    let mut lines = text.trim_start_matches('\u{feff}').lines();
    let first = lines.next().unwrap_or("").trim();
    if first != "QGC WPL 110" {
        return Err(SpecError::new(
            path,
            "line 1",
            format!("{first:?}: expected `QGC WPL 110`"),
        ));
    }
    let mut home = None;
    let mut items = Vec::new();
    for (n, line) in lines.enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let entry = format!("line {}", n + 2);
        let err = |r: String| SpecError::new(path, entry.clone(), r);
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() != 12 {
            return Err(err(format!("{} fields: a WPL 110 item has 12", f.len())));
        }
        let int = |k: usize, what: &str| {
            f[k].parse::<u64>()
                .map_err(|_| err(format!("{what} {:?}: expected a whole number", f[k])))
        };
        let seq = int(0, "seq")?;
        let frame = int(2, "frame")?;
        let command = int(3, "command")?;
        let mut p = [0.0; 7];
        for k in 0..7 {
            p[k] = f[4 + k]
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(format!("field {} {:?}: expected a number", 5 + k, f[4 + k])))?;
        }
        if seq == 0 {
            if !(p[4].abs() <= 90.0 && p[5].abs() <= 180.0) {
                return Err(err("home is not a latitude and longitude".into()));
            }
            home = Some((p[4], p[5], p[6]));
            continue;
        }
        let kind = mav_item(command, frame, p, home.map(|h| h.2), loiter_speed_mps)
            .map_err(|r| err(format!("seq {seq}: {r}")))?;
        if let Some(kind) = kind {
            items.push(Item {
                index: seq as usize,
                kind,
            });
        }
    }
    Ok(PlannedRoute {
        file: path.to_path_buf(),
        home: home.map(|h| (h.0, h.1)),
        items,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        zones: Vec::new(),
    })
}

/// What the `file` of an autopilot mission's refusal names: it came from no file.
pub const AUTOPILOT_MISSION: &str = "autopilot mission";

/// One mission item as the autopilot holds it (downloaded over MAVLink), in the numbers the
/// `.plan` and WPL files use: MAV_CMD, MAV_FRAME, param1..4, latitude and longitude (degrees),
/// altitude (m, as the frame says).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutopilotItem {
    /// Sequence number on the autopilot.
    pub seq: usize,
    /// MAV_CMD number.
    pub command: u64,
    /// MAV_FRAME number.
    pub frame: u64,
    /// param1..4, latitude (deg), longitude (deg), altitude (m).
    pub params: [f64; 7],
}

/// The autopilot's mission as a route, by the same rules and refusals as a `.plan` or WPL file
/// (one `mav_item` for all three). `home_at_seq0`: ArduPilot answers its home at seq 0 (not
/// flown; its altitude is the AMSL reference of absolute frames); PX4 keeps none, so `home`
/// (lat, lon, AMSL alt: the autopilot's HOME_POSITION, when known) stands in. A refusal reads
/// `autopilot mission: item N: reason`. `loiter_speed_mps` times LOITER_TURNS.
pub fn parse_autopilot_mission(
    items: &[AutopilotItem],
    home_at_seq0: bool,
    home: Option<(f64, f64, f64)>,
    loiter_speed_mps: f64,
) -> Result<PlannedRoute, SpecError> {
    let path = Path::new(AUTOPILOT_MISSION);
    let mut home = home;
    let mut out = Vec::with_capacity(items.len());
    for it in items {
        let entry = format!("item {}", it.seq);
        let p = it.params;
        if home_at_seq0 && it.seq == 0 {
            // ArduPilot answers 0/0 before it has a home (no GPS fix yet): none then.
            let set = p[4] != 0.0 || p[5] != 0.0;
            if set && !(p[4].abs() <= 90.0 && p[5].abs() <= 180.0 && p[6].is_finite()) {
                return Err(SpecError::new(
                    path,
                    entry,
                    "home is not a latitude and longitude",
                ));
            }
            if set {
                home = Some((p[4], p[5], p[6]));
            }
            continue;
        }
        let kind = mav_item(it.command, it.frame, p, home.map(|h| h.2), loiter_speed_mps)
            .map_err(|r| SpecError::new(path, entry, r))?;
        if let Some(kind) = kind {
            out.push(Item {
                index: it.seq,
                kind,
            });
        }
    }
    Ok(PlannedRoute {
        file: path.to_path_buf(),
        home: home.map(|h| (h.0, h.1)),
        items: out,
        search_time_limit_s: None,
        tracking_time_limit_s: None,
        zones: Vec::new(),
    })
}
