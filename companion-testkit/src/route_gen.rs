//! Generated operator missions for the route benchmark and its tests: a QGroundControl `.plan` of
//! many waypoints and a GeoJSON zones file whose zones the route crosses.

use std::fmt::Write;

/// Waypoint spacing in longitude (degrees): about 55 m at the equator.
const STEP_DEG: f64 = 0.0005;

/// A `.plan`: take-off to 20 m, a DO_CHANGE_SPEED, `n` waypoints eastwards along the equator
/// zigzagging 20 m north and south, then RTL. Home at 0, 0.
pub fn plan(n: usize) -> String {
    let mut items = String::from(
        r#"{"type":"SimpleItem","command":22,"frame":3,"params":[0,0,0,null,0,0,20],"autoContinue":true},
{"type":"SimpleItem","command":178,"frame":2,"params":[1,8,-1,0,0,0,0],"autoContinue":true}"#,
    );
    for k in 0..n {
        let lat = if k % 2 == 0 { 0.00018 } else { -0.00018 };
        let lon = (k + 1) as f64 * STEP_DEG;
        let _ = write!(
            items,
            ",\n{{\"type\":\"SimpleItem\",\"command\":16,\"frame\":3,\"params\":[0,0,0,null,{lat},{lon},20],\"autoContinue\":true}}"
        );
    }
    items.push_str(",\n{\"type\":\"SimpleItem\",\"command\":20,\"frame\":2,\"params\":[0,0,0,0,0,0,0],\"autoContinue\":true}");
    format!(
        "{{\"fileType\":\"Plan\",\"version\":1,\"groundStation\":\"QGroundControl\",\"mission\":{{\"version\":2,\"plannedHomePosition\":[0,0,0],\"items\":[\n{items}]}}}}"
    )
}

/// `zones` square GPS-degraded zones spread evenly over the route of [`plan`]`(n)`, each
/// straddling the equator, so every one is crossed by the route.
pub fn zones(n: usize, zones: usize) -> String {
    let span = n as f64 * STEP_DEG;
    let pitch = span / zones as f64;
    let mut features = Vec::with_capacity(zones);
    for z in 0..zones {
        let lon0 = z as f64 * pitch + pitch * 0.25;
        let lon1 = lon0 + pitch * 0.5;
        features.push(format!(
            r#"{{"type":"Feature","properties":{{"name":"z{z}","constraints":["gps_degraded"]}},"geometry":{{"type":"Polygon","coordinates":[[[{lon0},-0.001],[{lon1},-0.001],[{lon1},0.001],[{lon0},0.001],[{lon0},-0.001]]]}}}}"#
        ));
    }
    format!(
        "{{\"type\":\"FeatureCollection\",\"features\":[{}]}}",
        features.join(",\n")
    )
}
