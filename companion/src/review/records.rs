//! Values read out of decision records and the log header (mode, position, policy, the
//! mission states the run declared), for the review's aggregates.

use companion_core::record::DecisionRecord;

/// Metres between two (longitude, latitude) points in degrees (haversine, mean Earth radius:
/// well under a metre off at the distances of one flight).
pub fn distance_m(a: (f64, f64), b: (f64, f64)) -> f64 {
    let (lon1, lat1) = (a.0.to_radians(), a.1.to_radians());
    let (lon2, lat2) = (b.0.to_radians(), b.1.to_radians());
    let h = ((lat2 - lat1) / 2.0).sin().powi(2)
        + lat1.cos() * lat2.cos() * ((lon2 - lon1) / 2.0).sin().powi(2);
    2.0 * 6_371_008.8 * h.sqrt().min(1.0).asin()
}

/// A failsafe is named in free text (the autopilot's STATUSTEXT, a mode, a note), so it is
/// found in the written sentence.
pub(super) fn is_failsafe(text: &str) -> bool {
    text.to_ascii_lowercase().contains("failsafe")
}

pub(super) fn mode(r: &DecisionRecord) -> Option<String> {
    r.vehicle.get("mode").map(|m| match m.as_str() {
        Some(s) => s.to_string(),
        None => m.to_string(),
    })
}

pub(super) fn vehicle_f64(r: &DecisionRecord, key: &str) -> Option<f64> {
    r.vehicle.get(key).and_then(|v| v.as_f64())
}

/// A position value from the vehicle telemetry or, as fly records them, the observations.
pub(super) fn position(r: &DecisionRecord) -> Option<(f64, f64)> {
    let get = |k: &str| vehicle_f64(r, k).or_else(|| r.observations.get(k).copied());
    let (lat, lon) = (get("lat_deg")?, get("lon_deg")?);
    let valid = lat.is_finite()
        && lon.is_finite()
        && (-90.0..=90.0).contains(&lat)
        && (-180.0..=180.0).contains(&lon)
        && !(lat == 0.0 && lon == 0.0);
    valid.then_some((lon, lat))
}

pub fn policy_from_command(cmd: &str) -> Option<String> {
    let mut it = cmd.split_whitespace();
    while let Some(w) = it.next() {
        if w == "--policy" {
            return it.next().map(str::to_string);
        }
        if let Some(p) = w.strip_prefix("--policy=") {
            return Some(p.to_string());
        }
    }
    None
}
