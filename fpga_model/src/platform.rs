//! The board: tiles, CPU, budget, BN thresholds, reconfiguration time, power, performance needs.

use crate::ModelError;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The mission board. Loaded from `params/platform.toml` (every value cites its source there).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Platform {
    /// Board name (TeraSIC SoCKit).
    pub board: String,
    /// FPGA SoC device on the board.
    pub device: String,
    /// Dynamically reconfigurable FPGA tiles (section 6.3: four).
    pub tiles: u8,
    /// CPU cores (two Cortex-A9).
    pub cpu_cores: u8,
    /// CPU clock in MHz.
    pub cpu_mhz: f64,
    /// Highest allowed CPU utilisation of the online cores (applications plus external load).
    pub cpu_budget: f64,
    /// Thresholds of the resource BN's CPU node, increasing fractions (section 4.3.1: 0.3, 0.8).
    pub cpu_thresholds: Vec<f64>,
    /// Partial reconfiguration time of one tile.
    pub reconfiguration_ms_per_tile: f64,
    /// Board power estimate.
    pub power: PowerModel,
    /// Frame-rate need per application (section 4.3.2), by app name.
    #[serde(default)]
    pub performance: BTreeMap<String, Performance>,
}

/// Board power estimate: `base_w + per_active_tile_w * tiles_used + cpu_full_load_w * cpu_fraction`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PowerModel {
    /// Power of the idle board, W.
    pub base_w: f64,
    /// Extra power per configured, used tile, W.
    pub per_active_tile_w: f64,
    /// Extra power with every core fully loaded; scaled by the fraction of nominal CPU in use.
    pub cpu_full_load_w: f64,
}

/// Section 4.3.2: the rate an application needs depends on the speed of what it watches relative
/// to the drone. Between two frames the watched thing must not move more than
/// `max_shift_fraction` of the app's window on the ground (`window_m`), so
/// `fps = max(min_fps, |v_target - v_drone| / (max_shift_fraction * window_m))`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Performance {
    /// Width of the application's window on the ground, m.
    pub window_m: f64,
    /// Largest fraction of the window the watched thing may move between two frames.
    pub max_shift_fraction: f64,
    /// Floor on the required rate, frames per second.
    pub min_fps: f64,
    /// Where the numbers come from.
    #[serde(default)]
    pub source: String,
}

impl Performance {
    /// Required frames per second for velocities in m/s (ground frame, horizontal). Static
    /// things (obstacles, landing zones) have `target_velocity = [0, 0]`.
    pub fn required_fps(&self, drone_velocity: [f64; 2], target_velocity: [f64; 2]) -> f64 {
        let dx = target_velocity[0] - drone_velocity[0];
        let dy = target_velocity[1] - drone_velocity[1];
        let v_rel = (dx * dx + dy * dy).sqrt();
        (v_rel / (self.max_shift_fraction * self.window_m)).max(self.min_fps)
    }
}

fn positive(entry: &str, x: f64) -> Result<(), ModelError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(ModelError::new(
            entry,
            format!("must be a positive finite number, got {x}"),
        ))
    }
}

fn non_negative(entry: &str, x: f64) -> Result<(), ModelError> {
    if x.is_finite() && x >= 0.0 {
        Ok(())
    } else {
        Err(ModelError::new(
            entry,
            format!("must be a finite number >= 0, got {x}"),
        ))
    }
}

impl Platform {
    /// Check every count and quantity is in range, naming the first bad entry.
    pub fn validate(&self) -> Result<(), ModelError> {
        if self.tiles == 0 {
            return Err(ModelError::new("tiles", "must be at least 1"));
        }
        if self.tiles > 64 {
            return Err(ModelError::new(
                "tiles",
                format!("{} tiles is not a tiled FPGA we model (max 64)", self.tiles),
            ));
        }
        if self.cpu_cores == 0 {
            return Err(ModelError::new("cpu_cores", "must be at least 1"));
        }
        positive("cpu_mhz", self.cpu_mhz)?;
        positive("cpu_budget", self.cpu_budget)?;
        if self.cpu_budget > 1.0 {
            return Err(ModelError::new(
                "cpu_budget",
                format!(
                    "is a fraction of the online cores, must be <= 1, got {}",
                    self.cpu_budget
                ),
            ));
        }
        let mut last = 0.0;
        for (i, &t) in self.cpu_thresholds.iter().enumerate() {
            let entry = format!("cpu_thresholds[{i}]");
            if !(t.is_finite() && t > last && t < 1.0) {
                return Err(ModelError::new(
                    entry,
                    format!("thresholds must increase strictly within (0, 1), got {t}"),
                ));
            }
            last = t;
        }
        non_negative(
            "reconfiguration_ms_per_tile",
            self.reconfiguration_ms_per_tile,
        )?;
        non_negative("power.base_w", self.power.base_w)?;
        non_negative("power.per_active_tile_w", self.power.per_active_tile_w)?;
        non_negative("power.cpu_full_load_w", self.power.cpu_full_load_w)?;
        for (app, p) in &self.performance {
            positive(&format!("performance.{app}.window_m"), p.window_m)?;
            positive(
                &format!("performance.{app}.max_shift_fraction"),
                p.max_shift_fraction,
            )?;
            positive(&format!("performance.{app}.min_fps"), p.min_fps)?;
        }
        Ok(())
    }

    /// Index of the CPU node state for a utilisation: 0 below the first threshold, 1 between the
    /// first and second, ... (with 0.3 and 0.8: low, medium, high).
    pub fn cpu_level(&self, cpu_load: f64) -> usize {
        self.cpu_thresholds
            .iter()
            .filter(|&&t| cpu_load >= t)
            .count()
    }

    /// Required rate of `app` for the given velocities, when params define its performance need.
    pub fn required_fps(
        &self,
        app: &str,
        drone_velocity: [f64; 2],
        target_velocity: [f64; 2],
    ) -> Option<f64> {
        self.performance
            .get(app)
            .map(|p| p.required_fps(drone_velocity, target_velocity))
    }

    /// Estimated board power for `tiles_used` active tiles and a CPU use given as a fraction of
    /// the nominal (all cores) capacity.
    pub fn power_w(&self, tiles_used: u8, cpu_fraction_of_nominal: f64) -> f64 {
        self.power.base_w
            + self.power.per_active_tile_w * f64::from(tiles_used)
            + self.power.cpu_full_load_w * cpu_fraction_of_nominal.clamp(0.0, 1.0)
    }
}
