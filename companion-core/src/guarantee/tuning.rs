//! How a measured power drift is judged and learned: a mission's `[guarantee]` section, and its
//! defaults (docs/guarantee.md, "Power measured, prediction confronted").

/// A measured power this far from the prediction (as a fraction of it) is a performance drift.
pub const POWER_DRIFT_TOLERANCE: f64 = 0.25;
/// An activity's power is judged only after this long in it (s): take-off and mode changes draw
/// short peaks that are no drift.
pub const POWER_DRIFT_MIN_S: f64 = 10.0;
/// The params' power model counts as this many seconds of measurement when a drift is learned:
/// the factor is `(W x 1 + t x ratio) / (W + t)` after `t` seconds in the drifting activity, so a
/// short transient (a climb) moves it little and a sustained drift moves it most of the way.
pub const PRIOR_WEIGHT_S: f64 = 60.0;
/// The factor learned from a drift is kept within these bounds.
pub const ENERGY_SCALE_BOUNDS: (f64, f64) = (0.5, 2.0);
/// What a refusal names as fitting (the longest search or tracking hold) fits within this
/// fraction less than the available energy and time, not at the edge: in flight the margin is
/// judged from readings with their own steps and noise, and a plan named at the edge is cut at
/// the first one (docs/guarantee.md, "The verdict").
pub(crate) const FIT_HEADROOM: f64 = 0.05;

/// The power-drift tuning of a mission: its `[guarantee]` section, else the constants above
/// (which are its defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tuning {
    /// A measured power this far from the prediction (fraction of it) is a drift.
    pub power_drift_tolerance: f64,
    /// Seconds in an activity before its power is judged.
    pub power_drift_min_s: f64,
    /// The params' power model counts as this many seconds of measurement.
    pub prior_weight_s: f64,
    /// The learned energy factor is kept within these bounds.
    pub energy_scale_bounds: (f64, f64),
    /// A hold a refusal names fits within this fraction below the available energy and time.
    pub fit_headroom: f64,
}

impl Default for Tuning {
    fn default() -> Self {
        Tuning {
            power_drift_tolerance: POWER_DRIFT_TOLERANCE,
            power_drift_min_s: POWER_DRIFT_MIN_S,
            prior_weight_s: PRIOR_WEIGHT_S,
            energy_scale_bounds: ENERGY_SCALE_BOUNDS,
            fit_headroom: FIT_HEADROOM,
        }
    }
}
