//! PANORAMA resource allocation (Lambert et al., J. Intell. Robot. Syst. 2024), generic over missions.
//!
//! A mission is a sequence of [`Activity`]s; each activity offers implementation alternatives
//! ([`Ia`]), one TIO per robotic task, already filtered by the core-oriented constraints (see
//! [`combine`]). End-oriented [`Goal`]s bound the sum over activities of one indicator (energy J,
//! duration s), `total <= bound`, and are processed in the user's order.
//!
//! * [`allocate`]: the paper's algorithm (section 7.2.2): per goal, sort, start from the highest IA
//!   everywhere, lower by dichotomy from the last activity backwards, reduce the candidate sets;
//!   finally pick in each activity the best remaining IA under a [`Selection`] rule. Returns RAS0 or
//!   [`Infeasible`] naming the goal and the excess.
//! * [`exact`]: branch-and-bound for the same objective (maximise the summed selection score under
//!   every goal), and [`exhaustive`] for tiny instances: the yardsticks for the algorithm's gap.
//! * [`margins`] and [`reallocate`]: section 7.3, margins `M = goal - (measured + remainder)`, drift
//!   `measured - estimated so far`, and the reduced mission scenario after a drift or a failure.
//!
//! Pure: no I/O, no clock, no randomness.
//!
//! # Layout
//!
//! * `lib.rs`: the problem ([`Goal`], [`Ia`], [`Activity`], [`Problem`], [`Selection`]), the
//!   allocation's result ([`Allocation`], [`Infeasible`]) and the yardsticks [`exhaustive`] and
//!   [`nga`].
//! * `search`: the allocation ([`allocate`]) and the exact search ([`exact`]), on buffers a
//!   [`Reallocator`] keeps between calls.
//! * `combine`: implementation alternatives from task implementation options and core-oriented
//!   constraints ([`combine`], [`Tio`], [`Task`], [`CoreConstraint`]).
//! * `margins`: online performance management: [`margins`], drift, and the reduced mission
//!   ([`reallocate`], [`reduced_problem`]).

use serde::{Deserialize, Serialize};

mod combine;
mod margins;
mod search;
pub use combine::{CoreConstraint, Task, Tio, combine};
pub use margins::{
    MarginReport, Measured, Reallocator, SwapCheck, margins, margins_into, reallocate,
    reallocate_or_exact, reduced_problem,
};
pub use search::{Exact, allocate, exact};

/// An end-oriented goal: the mission total of indicator `name` must stay `<= bound`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Goal {
    /// The indicator summed over the mission (`energy`, `duration`).
    pub name: String,
    /// Upper bound on the mission total, in the indicator's unit (J, s).
    pub bound: f64,
}

/// One implementation alternative of an activity: a TIO per task, its estimated cost per goal (same
/// order as [`Problem::goals`]), a capability rank (higher = more capable), and the resources it uses
/// (a failure of any of them removes the IA).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Ia {
    /// Name, unique within its activity.
    pub name: String,
    /// Estimated cost per goal, in [`Problem::goals`] order.
    pub cost: Vec<f64>,
    /// Capability rank: higher is more capable.
    pub capability: f64,
    /// Resources used; the failure of any of them removes this IA.
    #[serde(default)]
    pub resources: Vec<String>,
}

/// A part of the mission flown under constant constraints, with its candidate IAs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Activity {
    /// Name of the mission part.
    pub name: String,
    /// The candidate implementation alternatives.
    pub ias: Vec<Ia>,
}

/// A mission scenario (or a reduced one): activities in flight order and goals in the user's order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Problem {
    /// End-oriented goals, processed in this order.
    pub goals: Vec<Goal>,
    /// Activities in flight order.
    pub activities: Vec<Activity>,
}

/// Which remaining IA to fly in each activity once every goal has reduced the candidate sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Selection {
    /// The IA with the highest capability rank.
    MostCapable,
    /// The IA with the highest cost on goal `i`: the paper's rule for the patrolling robot, where
    /// the most energy-consuming IA is taken as the most capable (section 7.2.3).
    HighestCost(usize),
}

impl Selection {
    /// The per-IA score this rule maximises (also the objective of [`exact`]).
    pub fn score(self, ia: &Ia) -> f64 {
        match self {
            Selection::MostCapable => ia.capability,
            Selection::HighestCost(g) => ia.cost.get(g).copied().unwrap_or(0.0),
        }
    }
}

/// Why no allocation was found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, thiserror::Error)]
pub enum Infeasible {
    /// Even the lowest remaining IAs exceed the goal: `minimum - bound = excess > 0`.
    #[error(
        "goal {goal}: lowest reachable total {minimum:.3} exceeds bound {bound:.3} by {excess:.3}"
    )]
    Goal {
        /// Name of the goal that cannot be met.
        goal: String,
        /// The lowest total the remaining IAs reach.
        minimum: f64,
        /// The goal's bound.
        bound: f64,
        /// `minimum - bound`.
        excess: f64,
    },
    /// An activity has no implementation alternative left (all filtered or all failed).
    #[error("activity {activity}: no implementation alternative left")]
    NoAlternative {
        /// Name of the empty activity.
        activity: String,
    },
}

impl Infeasible {
    /// The constraint that failed: a goal name, or `resources` for an empty activity.
    pub fn constraint(&self) -> &str {
        match self {
            Infeasible::Goal { goal, .. } => goal,
            Infeasible::NoAlternative { .. } => "resources",
        }
    }
}

/// A resource allocation solution: one IA index per activity, its totals per goal, and the
/// candidate sets left after the reductions (indices into each activity's `ias`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Allocation {
    /// The chosen IA per activity (index into its `ias`).
    pub choice: Vec<usize>,
    /// Mission total per goal of the chosen IAs.
    pub totals: Vec<f64>,
    /// Summed selection score of the chosen IAs.
    pub score: f64,
    /// Per activity, the IA indices still allowed after the goals' reductions.
    #[serde(default)]
    pub candidates: Vec<Vec<usize>>,
}

/// `total <= bound`, with a tolerance for summation order (relative 1e-9).
pub fn fits(total: f64, bound: f64) -> bool {
    total <= bound + 1e-9 * bound.abs().max(1.0)
}

/// Number of global alternatives: the product of the per-activity IA counts (paper eq. 6).
/// `None` on overflow of `u128`.
pub fn nga(problem: &Problem) -> Option<u128> {
    problem
        .activities
        .iter()
        .try_fold(1u128, |acc, a| acc.checked_mul(a.ias.len() as u128))
}

impl Problem {
    /// Totals per goal of a full choice, summed in activity order.
    pub fn totals(&self, choice: &[usize]) -> Vec<f64> {
        (0..self.goals.len())
            .map(|g| self.total(choice, g))
            .collect()
    }

    /// True when every goal holds for `choice`.
    pub fn feasible(&self, choice: &[usize]) -> bool {
        (0..self.goals.len()).all(|g| fits(self.total(choice, g), self.goals[g].bound))
    }

    /// Total of goal `g` for a full choice, summed in activity order (as [`Problem::totals`]).
    fn total(&self, choice: &[usize], g: usize) -> f64 {
        self.activities
            .iter()
            .zip(choice)
            .map(|(a, &i)| a.ias[i].cost[g])
            .sum()
    }

    /// Summed selection score of `choice`.
    pub fn score(&self, choice: &[usize], sel: Selection) -> f64 {
        self.activities
            .iter()
            .zip(choice)
            .map(|(a, &i)| sel.score(&a.ias[i]))
            .sum()
    }

    pub(crate) fn allocation(
        &self,
        choice: Vec<usize>,
        sel: Selection,
        candidates: Vec<Vec<usize>>,
    ) -> Allocation {
        Allocation {
            totals: self.totals(&choice),
            score: self.score(&choice, sel),
            choice,
            candidates,
        }
    }

    pub(crate) fn check_nonempty(&self) -> Result<(), Infeasible> {
        match self.activities.iter().find(|a| a.ias.is_empty()) {
            Some(a) => Err(Infeasible::NoAlternative {
                activity: a.name.clone(),
            }),
            None => Ok(()),
        }
    }
}

/// Exhaustive search over all NGA combinations (tiny instances only): the maximum summed score
/// among feasible choices, ties to the lexicographically first choice.
pub fn exhaustive(problem: &Problem, sel: Selection) -> Option<Allocation> {
    if problem.check_nonempty().is_err() {
        return None;
    }
    let n = problem.activities.len();
    let mut choice = vec![0usize; n];
    let mut best: Option<(f64, Vec<usize>)> = None;
    loop {
        if problem.feasible(&choice) {
            let s = problem.score(&choice, sel);
            if best.as_ref().is_none_or(|(b, _)| s > *b) {
                best = Some((s, choice.clone()));
            }
        }
        // Odometer increment.
        let mut j = n;
        loop {
            if j == 0 {
                return best.map(|(_, c)| problem.allocation(c, sel, Vec::new()));
            }
            j -= 1;
            choice[j] += 1;
            if choice[j] < problem.activities[j].ias.len() {
                break;
            }
            choice[j] = 0;
        }
    }
}
