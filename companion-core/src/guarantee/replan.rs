//! A mission changed in flight (a ground station uploaded a new one), planned from the point
//! reached: the activities flown keep their allocation and what they spent, the rest is the new
//! mission from where the vehicle is, allocated against what is left of the goals.

use super::{Guarantee, MissionSpec, Ras0, RasRow};
use std::collections::BTreeMap;

impl Guarantee {
    /// A mission changed in flight, re-allocated from the point reached (PANORAMA's reduced
    /// mission): `spec`'s first `flown` activities are those flown (kept as allocated), the rest
    /// the new mission from where the vehicle is. What was spent so far (energy and time, as the
    /// last [`Guarantee::watch`] measured them) is kept: the remaining activities are allocated
    /// against what is left of the goals, the failed resources still avoided, the learned energy
    /// factor still applied. When nothing meets the goals, the most capable allocation (bounds
    /// lifted) stands and the next watch says it cannot; `None` only without an alternative.
    pub fn replan_from(&self, spec: MissionSpec, flown: usize) -> Option<Self> {
        let n = spec.problem.activities.len();
        let flown = flown.min(n.saturating_sub(1));
        let mut init: Vec<usize> = (0..n)
            .map(|j| {
                let kept = (j < flown).then(|| self.choice.get(j).copied()).flatten();
                kept.filter(|&i| i < spec.problem.activities[j].ias.len())
                    .unwrap_or(0)
            })
            .collect();
        let mut problem = spec.problem.clone();
        // The goals' bounds as last reckoned (the autopilot's pack), the same goals by name.
        for g in &mut problem.goals {
            if let Some(old) = self.spec.problem.goals.iter().find(|o| o.name == g.name) {
                g.bound = old.bound;
            }
        }
        let so_far: Vec<f64> = (problem.goals.iter())
            .map(|g| {
                let k = self
                    .spec
                    .problem
                    .goals
                    .iter()
                    .position(|o| o.name == g.name);
                k.and_then(|k| self.scratch.m.so_far.get(k).copied())
                    .unwrap_or(0.0)
            })
            .collect();
        let m = panorama::Measured {
            activity: flown,
            fraction: 0.0,
            so_far,
        };
        let found = panorama::reallocate(&problem, &init, &m, &self.failed, spec.selection)
            .or_else(|_| {
                let mut lifted = problem.clone();
                lifted.goals.iter_mut().for_each(|g| g.bound = f64::MAX);
                panorama::reallocate(&lifted, &init, &m, &self.failed, spec.selection)
            })
            .ok()?;
        init.copy_from_slice(&found);
        let ras = Ras0 {
            choice: init,
            totals: BTreeMap::new(),
            margins: BTreeMap::new(),
            nga: None,
        };
        let mut g = Self::with_ras0(spec, ras, "mission changed in flight");
        // The allocations in force before, over the activities flown; then the re-plan's row.
        g.rows = (self.rows.iter())
            .map(|r| RasRow {
                cells: (0..n)
                    .map(|j| {
                        if j < flown {
                            r.cells.get(j).cloned().flatten()
                        } else {
                            None
                        }
                    })
                    .collect(),
                ..r.clone()
            })
            .collect();
        g.push_row(
            flown,
            "mission changed in flight: re-allocated from the point reached",
        );
        g.reallocations = self.reallocations + 1;
        g.failed.clone_from(&self.failed);
        g.cells_seen = self.cells_seen;
        g.power = self.power.clone();
        g.scratch.m = m;
        g.set_energy_scale(flown, self.energy_scale);
        Some(g)
    }
}
