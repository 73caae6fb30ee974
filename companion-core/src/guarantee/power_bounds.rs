//! What no airframe of a mission can be (`[power_bounds]` of a mission file, docs/calibrate.md):
//! the range of hover power per kilogram of the vehicle's mass, the least power at any speed up
//! to the mission's fastest as a fraction of hover, and the largest fit error `calibrate` may
//! write. `calibrate` refuses a fit outside them and loading refuses a `[propulsion]` outside
//! them (a calibrated overlay included), each with the entry and the reason.
//!
//! Every number carries its source beside it (`[power_bounds.sources]`, one entry per number):
//! a bound nobody can trace is no bound.

use super::schema::{ActivityFile, MissionFile, PowerBoundsFile};
use crate::spec::SpecError;
use std::path::Path;

/// The numbers of [`PowerBoundsFile`], checked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerBounds {
    /// Take-off mass (kg).
    pub mass_kg: f64,
    /// Hover power (propulsion at rest, base excluded) per kilogram: (least, most) W/kg.
    pub hover_w_per_kg: (f64, f64),
    /// Propulsion power at every speed up to the mission's fastest is at least this fraction
    /// of hover (so above zero).
    pub min_power_of_hover: f64,
    /// The largest RMS error of a power fit `calibrate` writes, as a fraction of the mean
    /// measured power.
    pub max_fit_rms_fraction: f64,
}

/// Speeds the curve is checked at, this far apart (m/s).
const SPEED_STEP: f64 = 0.1;

impl PowerBoundsFile {
    pub(super) fn check(&self, path: &Path) -> Result<PowerBounds, SpecError> {
        let err = |k: &str, r: String| SpecError::new(path, format!("power_bounds.{k}"), r);
        let positive = |k: &str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                Err(err(k, format!("{x} must be a finite number above zero")))
            }
        };
        positive("mass_kg", self.mass_kg)?;
        let [lo, hi] = self.hover_w_per_kg;
        positive("hover_w_per_kg[0]", lo)?;
        positive("hover_w_per_kg[1]", hi)?;
        if lo >= hi {
            return Err(err(
                "hover_w_per_kg",
                format!("[{lo}, {hi}]: the least must be below the most"),
            ));
        }
        positive("min_power_of_hover", self.min_power_of_hover)?;
        positive("max_fit_rms_fraction", self.max_fit_rms_fraction)?;
        for k in [
            "mass_kg",
            "hover_w_per_kg",
            "min_power_of_hover",
            "max_fit_rms_fraction",
        ] {
            if self.sources.get(k).is_none_or(|s| s.trim().is_empty()) {
                return Err(err(
                    &format!("sources.{k}"),
                    "missing: every bound says where it comes from (a source or ASSUMPTION)".into(),
                ));
            }
        }
        if let Some(k) = self.sources.keys().find(|k| {
            ![
                "mass_kg",
                "hover_w_per_kg",
                "min_power_of_hover",
                "max_fit_rms_fraction",
            ]
            .contains(&k.as_str())
        }) {
            return Err(err(
                &format!("sources.{k}"),
                "names no number of [power_bounds]".into(),
            ));
        }
        Ok(PowerBounds {
            mass_kg: self.mass_kg,
            hover_w_per_kg: (lo, hi),
            min_power_of_hover: self.min_power_of_hover,
            max_fit_rms_fraction: self.max_fit_rms_fraction,
        })
    }
}

/// Why a power curve is no airframe's: the entry (`propulsion`, `base.power_w`) and the reason.
#[derive(Debug, Clone, PartialEq)]
pub struct Unphysical {
    /// The mission file's entry at fault.
    pub entry: &'static str,
    /// Why.
    pub reason: String,
}

/// Check a mission's power: `propulsion(v)` (W, base excluded) at every speed from 0 to
/// `v_max` (m/s, the fastest the mission or the data reach) and the base power `base_w`.
/// Without bounds only a power above zero at every speed is required (a vehicle that moves
/// draws power); with them, hover within the mass's range, every speed at least the stated
/// fraction of hover, and the base below hover.
pub fn check_power_curve(
    bounds: Option<&PowerBounds>,
    propulsion: impl Fn(f64) -> f64,
    base_w: f64,
    v_max: f64,
) -> Result<(), Unphysical> {
    let bad = |entry, reason| Err(Unphysical { entry, reason });
    let hover = propulsion(0.0);
    if let Some(b) = bounds {
        let (lo, hi) = (
            b.hover_w_per_kg.0 * b.mass_kg,
            b.hover_w_per_kg.1 * b.mass_kg,
        );
        if !(hover.is_finite() && hover >= lo && hover <= hi) {
            return bad(
                "propulsion",
                format!(
                    "hover power {hover:.4} W is outside {lo:.1}..{hi:.1} W ([power_bounds] \
                     hover_w_per_kg {}..{} W/kg x mass_kg {}): no airframe of this mission",
                    b.hover_w_per_kg.0, b.hover_w_per_kg.1, b.mass_kg
                ),
            );
        }
        if !base_w.is_finite() || base_w >= hover {
            return bad(
                "base.power_w",
                format!(
                    "{base_w:.4} W is not below the hover power {hover:.4} W ([power_bounds]: \
                     the always-on electronics draw less than the rotors at hover)"
                ),
            );
        }
    }
    let least = bounds.map_or(0.0, |b| b.min_power_of_hover * hover);
    let steps = (v_max.max(0.0) / SPEED_STEP).ceil() as usize;
    for i in 0..=steps {
        let v = (i as f64 * SPEED_STEP).min(v_max.max(0.0));
        let p = propulsion(v);
        if !(p.is_finite() && p > least) {
            let why = match bounds {
                Some(b) => format!(
                    "at least {least:.4} W ([power_bounds] min_power_of_hover {} x hover {hover:.4} W)",
                    b.min_power_of_hover
                ),
                None => "above zero (a vehicle that moves draws power)".to_string(),
            };
            return bad(
                "propulsion",
                format!(
                    "power {p:.4} W at {v:.1} m/s (checked from 0 to {v_max:.1} m/s, the fastest \
                     the mission flies); it must be {why}"
                ),
            );
        }
    }
    Ok(())
}

/// The fastest the mission flies (m/s): each activity's speed cap (its TIOs' when it has none)
/// and hold speed.
pub(super) fn fastest(f: &MissionFile) -> f64 {
    let tio_cap = |a: &ActivityFile| {
        a.tasks
            .iter()
            .filter_map(|t| f.tasks.get(t))
            .flat_map(|t| t.tios.iter().filter_map(|x| x.v_max_mps))
            .fold(0.0, f64::max)
    };
    f.activities
        .iter()
        .map(|a| {
            let moving = if a.length_m > 0.0 {
                a.v_max_mps.unwrap_or_else(|| tio_cap(a))
            } else {
                0.0
            };
            moving.max(a.hold_speed_mps)
        })
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max)
}

/// The power check of the mission file at `path` with the text `text` (an overlay's merged
/// mission): `None` when the text is no mission file (its own loader says why), else what
/// [`check_power_curve`] finds, as the mission file's entry and reason.
pub fn check_mission_text(path: &Path, text: &str) -> Option<Unphysical> {
    let f: MissionFile = crate::spec::parse_toml(path, text).ok()?;
    let bounds = f.power_bounds.as_ref().map(|b| b.check(path));
    let bounds = match bounds {
        Some(Err(e)) => {
            return Some(Unphysical {
                entry: "power_bounds",
                reason: e.reason,
            });
        }
        Some(Ok(b)) => Some(b),
        None => None,
    };
    check_power_curve(
        bounds.as_ref(),
        |v| f.propulsion.power(v),
        f.base.power_w,
        fastest(&f),
    )
    .err()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn b() -> PowerBounds {
        PowerBounds {
            mass_kg: 2.0,
            hover_w_per_kg: (50.0, 500.0),
            min_power_of_hover: 0.25,
            max_fit_rms_fraction: 0.2,
        }
    }

    #[test]
    fn curves_no_airframe_flies_are_named() {
        // ArduCopter SITL's calibrated curve (params/vehicles/arducopter-sitl.toml).
        let sitl = |v: f64| 354.26 + 0.594 * v * v - 0.0339 * v * v * v;
        assert_eq!(check_power_curve(Some(&b()), sitl, 0.0, 12.0), Ok(()));
        let e = check_power_curve(Some(&b()), |_| 1e9, 0.0, 12.0).unwrap_err();
        assert!(e.reason.contains("hover power"), "{e:?}");
        let e = check_power_curve(Some(&b()), |_| 1e-4, 0.0, 12.0).unwrap_err();
        assert!(e.reason.contains("hover power"), "{e:?}");
        // Falling below zero at 15 m/s: -431 W there.
        let falling = |v: f64| 354.0 - 0.2 * v * v - 0.2 * v * v * v;
        let e = check_power_curve(Some(&b()), falling, 0.0, 15.0).unwrap_err();
        assert!(e.reason.contains("m/s"), "{e:?}");
        assert_eq!(check_power_curve(Some(&b()), falling, 0.0, 5.0), Ok(()));
        let e = check_power_curve(Some(&b()), |_| 200.0, 300.0, 12.0).unwrap_err();
        assert_eq!(e.entry, "base.power_w");
        // Without bounds: zero power everywhere is still refused.
        assert!(check_power_curve(None, |_| 0.0, 0.0, 1.0).is_err());
        assert_eq!(
            check_power_curve(None, |v| 0.29 + 7.4 * v, 2.9, 0.56),
            Ok(())
        );
    }
}
