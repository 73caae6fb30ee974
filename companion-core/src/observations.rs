//! One timestamped snapshot of everything observed: autopilot telemetry and onboard monitors.
//! The shell (simulation world or MAVLink) fills it; the pure core only reads it.

pub use crate::observation_values::ObservationValues;
use serde::{Deserialize, Serialize};

/// Observation names and units are data (params/observations.toml, documented in docs/params.md):
/// `vibration_mps2`, `wind_mps`, `battery_pct`, `gps_fix`, `gps_sats`, `luminosity_lux`,
/// `target_speed_rel`, `cpu_load`, `free_tiles`, `obstacle_m`, `target_detected`, ...
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Observations {
    /// Time of the snapshot (s since the run started).
    pub time_s: f64,
    /// The mission state as the shell observes it (GPS waypoint reached, MISSION_CURRENT, target
    /// detected/tracked by the onboard application): `base`, `wp1`, `wpi`, `wpf`, `target`, `v3`, ...
    #[serde(default)]
    pub state: String,
    /// Raw observations by slot over the run's vocabulary (units in docs/params/health.md).
    pub values: ObservationValues,
    /// Discrete happenings since the last snapshot (`target detected`, `obstacle detected`).
    pub events: Vec<crate::record::Event>,
}

impl Observations {
    /// The observation named `name`, if present.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.values.get(name).copied()
    }
    /// Set (or replace) the observation named `name`.
    pub fn set(&mut self, name: &str, value: f64) {
        self.values.set(name, value);
    }
}
