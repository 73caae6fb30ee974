//! The core's health rows learned in flight (`--learn-cpt`, docs/calibrate.md): the shell reads
//! and sets them between cycles; the cycle itself stays pure.

use super::Core;

impl Core {
    /// A CPT row of this core's health model (docs/calibrate.md, in-flight learning).
    pub fn cpt_row(&self, node: &str, when: &[(String, String)]) -> Option<Vec<f64>> {
        self.health.cpt_row(node, when)
    }

    /// Set a CPT row of this core's health model, in force from the next cycle (`--learn-cpt`).
    pub fn set_cpt_row(
        &mut self,
        node: &str,
        when: &[(String, String)],
        p: &[f64],
    ) -> Result<(), crate::health::HealthError> {
        self.health.set_cpt_row(node, when, p)
    }
}
