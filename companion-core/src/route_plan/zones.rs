//! Zones: GeoJSON polygons whose `properties.constraints` name constraint classes of the PANORAMA
//! mission (`gps_degraded`, `obstacle_dense`, ...).

use crate::spec::SpecError;
use geo::{BoundingRect, MultiPolygon, Rect};
use std::path::Path;

/// One zone: an area (lon/lat degrees) and the constraint classes in force inside it.
#[derive(Debug, Clone, PartialEq)]
pub struct Zone {
    /// Where it was read: `feature[i]` of a GeoJSON file, `geoFence.polygons[i]` of a `.plan`.
    pub entry: String,
    /// `properties.name` (or the feature id), else the entry.
    pub name: String,
    /// Constraint class names, as written.
    pub constraints: Vec<String>,
    /// The area; x is longitude, y latitude.
    pub area: MultiPolygon<f64>,
    /// Its bounding box, to skip the zones a leg cannot touch.
    pub bbox: Rect<f64>,
}

impl Zone {
    /// A zone from its parts; `None` when the area is empty.
    pub fn new(
        entry: String,
        name: String,
        constraints: Vec<String>,
        area: MultiPolygon<f64>,
    ) -> Option<Self> {
        let bbox = area.bounding_rect()?;
        Some(Self {
            entry,
            name,
            constraints,
            area,
            bbox,
        })
    }
}

/// The FeatureCollection member that says its coordinates are metres from home
/// (`"frame": "home_relative"`, positions `[east_m, north_m]`), as a route TOML's
/// `frame = "relative"`: the same zones then sit on the same route wherever home is.
pub const HOME_RELATIVE: &str = "home_relative";

/// Positions of a home-relative zones file beyond this (m) from home are refused (a typo of a
/// latitude/longitude for metres, or a file not meant to be relative).
const MAX_RELATIVE_M: f64 = 100_000.0;

/// True when the zones file says `"frame": "home_relative"` (whatever else it holds; the parse
/// names any error).
pub fn zones_home_relative(text: &str) -> bool {
    serde_json::from_str::<serde_json::Value>(text)
        .ok()
        .and_then(|v| v.get("frame")?.as_str().map(|f| f == HOME_RELATIVE))
        .unwrap_or(false)
}

/// Parse a zones file: a GeoJSON FeatureCollection of Polygon / MultiPolygon features, each with
/// a non-empty `properties.constraints` list of strings. `path` names the file in errors. A
/// home-relative file (`"frame": "home_relative"`) is refused here: [`parse_zones_at`] places it.
pub fn parse_zones(path: &Path, text: &str) -> Result<Vec<Zone>, SpecError> {
    parse_zones_at(path, text, None)
}

/// [`parse_zones`], placing a home-relative file's `[east_m, north_m]` positions from `home`
/// (lat, lon degrees; geodesic, WGS84).
pub fn parse_zones_at(
    path: &Path,
    text: &str,
    home: Option<(f64, f64)>,
) -> Result<Vec<Zone>, SpecError> {
    let gj: geojson::GeoJson = text
        .parse()
        .map_err(|e: geojson::Error| SpecError::new(path, "-", format!("not GeoJSON: {e}")))?;
    let geojson::GeoJson::FeatureCollection(fc) = gj else {
        return Err(SpecError::new(
            path,
            "-",
            "expected a FeatureCollection of Polygon / MultiPolygon features",
        ));
    };
    let frame = fc
        .foreign_members
        .as_ref()
        .and_then(|m| m.get("frame"))
        .map(|f| match f.as_str() {
            Some(HOME_RELATIVE) => Ok(()),
            _ => Err(SpecError::new(
                path,
                "frame",
                format!(
                    "{f}: the one frame is \"{HOME_RELATIVE}\" (omit it for longitude/latitude)"
                ),
            )),
        })
        .transpose()?;
    let place = match (frame, home) {
        (None, _) => None,
        (Some(()), Some(h)) => Some(h),
        (Some(()), None) => {
            return Err(SpecError::new(
                path,
                "frame",
                "zones relative to home need home: a route relative to home, --home LAT,LON, \
                 or the autopilot's home",
            ));
        }
    };
    let mut zones = Vec::with_capacity(fc.features.len());
    for (i, f) in fc.features.iter().enumerate() {
        let entry = format!("features[{i}]");
        let err = |reason: String| SpecError::new(path, entry.clone(), reason);
        let geometry = f
            .geometry
            .as_ref()
            .ok_or_else(|| err("no geometry: a zone is a Polygon or MultiPolygon".into()))?;
        let area: MultiPolygon<f64> = match &geometry.value {
            geojson::GeometryValue::Polygon { .. } => MultiPolygon::new(vec![
                geo::Polygon::try_from(geometry).map_err(|e| err(e.to_string()))?,
            ]),
            geojson::GeometryValue::MultiPolygon { .. } => {
                MultiPolygon::try_from(geometry).map_err(|e| err(e.to_string()))?
            }
            _ => return Err(err("geometry is not a Polygon or MultiPolygon".into())),
        };
        let area = match place {
            Some(home) => placed(&area, home).map_err(err)?,
            None => area,
        };
        check_area(&area).map_err(err)?;
        let props = f.properties.as_ref();
        let constraints = props.and_then(|p| p.get("constraints")).ok_or_else(|| {
            err("no properties.constraints: list the constraint classes in force".into())
        })?;
        let constraints = constraint_names(constraints)
            .map_err(|r| SpecError::new(path, format!("{entry}.properties.constraints"), r))?;
        let name = props
            .and_then(|p| p.get("name"))
            .and_then(|n| n.as_str())
            .map(str::to_string)
            .or_else(|| {
                f.id.as_ref().map(|id| match id {
                    geojson::feature::Id::String(s) => s.clone(),
                    geojson::feature::Id::Number(n) => n.to_string(),
                })
            })
            .unwrap_or_else(|| entry.clone());
        let zone = Zone::new(entry.clone(), name, constraints, area)
            .ok_or_else(|| err("empty area".into()))?;
        zones.push(zone);
    }
    Ok(zones)
}

/// A home-relative area (x east, y north, metres) on the globe around `home`.
fn placed(area: &MultiPolygon<f64>, home: (f64, f64)) -> Result<MultiPolygon<f64>, String> {
    use geo::CoordsIter;
    if let Some(c) = area
        .coords_iter()
        .find(|c| !(c.x.is_finite() && c.y.is_finite() && c.x.hypot(c.y) <= MAX_RELATIVE_M))
    {
        return Err(format!(
            "position [{}, {}]: a home-relative position is [east_m, north_m] within {} km of home",
            c.x,
            c.y,
            MAX_RELATIVE_M / 1000.0
        ));
    }
    use geo::MapCoords;
    Ok(area.map_coords(|c| {
        let p = super::Position::offset(home, c.y, c.x, 0.0);
        geo::Coord {
            x: p.lon_deg,
            y: p.lat_deg,
        }
    }))
}

/// A `constraints` value: a non-empty array of non-empty strings.
pub(super) fn constraint_names(v: &serde_json::Value) -> Result<Vec<String>, String> {
    let arr = v
        .as_array()
        .ok_or("expected a list of constraint class names")?;
    if arr.is_empty() {
        return Err("empty: a zone names at least one constraint class".into());
    }
    arr.iter()
        .map(|c| match c.as_str() {
            Some(s) if !s.trim().is_empty() => Ok(s.to_string()),
            _ => Err(format!("{c}: expected a constraint class name")),
        })
        .collect()
}

/// Every ring closed, with at least 3 distinct corners, coordinates finite and on the globe.
pub(super) fn check_area(area: &MultiPolygon<f64>) -> Result<(), String> {
    if area.0.is_empty() {
        return Err("empty MultiPolygon".into());
    }
    for poly in &area.0 {
        for ring in std::iter::once(poly.exterior()).chain(poly.interiors()) {
            if ring.0.len() < 4 {
                return Err(format!(
                    "a ring of {} positions: a polygon ring needs at least 4 (closed)",
                    ring.0.len()
                ));
            }
            for c in &ring.0 {
                if !c.x.is_finite() || !c.y.is_finite() || c.y.abs() > 90.0 || c.x.abs() > 180.0 {
                    return Err(format!(
                        "position [{}, {}]: longitude must be in -180..180 and latitude in -90..90",
                        c.x, c.y
                    ));
                }
            }
        }
    }
    Ok(())
}
