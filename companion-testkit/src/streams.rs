//! Observation streams for measuring the decision cycle (benches, examples, allocation tests):
//! a tracking-phase snapshot from the simulated world, then advanced in place cycle by cycle the
//! way flight telemetry moves. Not used by the decision core itself.

use companion::sim::{Scenario, World};
use companion_core::decision::{Core, Model, ModelKind};
use companion_core::observations::Observations;
use std::path::Path;
use std::sync::Arc;

/// The first tracking-phase snapshot (`v0`..`v5`) of `scenario` (seed 1) flown by a safety-first
/// BFM core from take-off.
pub fn tracking_snapshot(model: &Arc<Model>, params: &Path, scenario: &str) -> Observations {
    let files = companion::params::read_params_dir(params).expect("params");
    // The world of the loaded params: its snapshots are written over the run's vocabulary.
    let spec = companion::params::Params::load(params, None)
        .expect("params")
        .world;
    let scenario = Scenario::load(&files, scenario).expect("scenario");
    let mut world = World::new(&spec, &scenario, 1);
    let mut core = Core::new(
        Arc::clone(model),
        ModelKind::Bfm,
        model.policy("safety").unwrap(),
    );
    loop {
        let obs = world.observe();
        if obs.state.starts_with('v') {
            return obs;
        }
        let (plan, rec) = core.step(&obs);
        world.advance(&plan, &rec);
    }
}

/// Which way a stream moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stream {
    /// Time advances, the battery drains slowly (staying in its evidence band): values change,
    /// evidence does not. What a quiet stretch of flight looks like.
    Steady,
    /// As `Steady`, and the vibration reading flips across its threshold every cycle, so the
    /// evidence, the health probabilities and every MDP's inputs change each cycle.
    Changing,
}

/// A stream of observations starting from `base`.
pub struct StreamGen {
    pub base: Observations,
    pub kind: Stream,
    /// The vibration reading on odd cycles of a `Changing` stream: across the first threshold
    /// of `vibration_mps2` in params/observations.toml from the base reading.
    flipped_vibration: f64,
}

impl StreamGen {
    pub fn new(model: &Model, base: Observations, kind: Stream) -> Self {
        let t = model
            .health
            .observations
            .get("vibration_mps2")
            .and_then(|o| o.thresholds.first().copied())
            .expect("params observe vibration_mps2 with a threshold");
        let b = base.get("vibration_mps2").unwrap_or(0.0);
        let flipped_vibration = if b < t { 2.0 * t } else { 0.5 * t };
        Self {
            base,
            kind,
            flipped_vibration,
        }
    }

    /// Move `obs` (a clone of the base) to cycle `k` in place: no allocation.
    pub fn advance(&self, obs: &mut Observations, k: u64) {
        let base = &self.base;
        // 0.1 s per cycle: thousands of cycles stay well inside the mission's duration goal.
        obs.time_s = base.time_s + 0.1 * k as f64;
        if let (Some(b), Some(x)) = (base.get("battery_pct"), obs.values.get_mut("battery_pct")) {
            // 1e-4 % per cycle: ten thousand cycles stay inside one battery band.
            *x = b - 1e-4 * (k % 10_000) as f64;
        }
        let b = base.get("vibration_mps2").unwrap_or(0.0);
        if let Some(v) = obs.values.get_mut("vibration_mps2") {
            *v = if self.kind == Stream::Changing && k % 2 == 1 {
                self.flipped_vibration
            } else {
                b
            };
        }
    }
}
