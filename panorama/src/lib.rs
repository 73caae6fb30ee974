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
//!   allocation ([`allocate`], [`Allocation`], [`Infeasible`]) and its yardsticks ([`exact`],
//!   [`exhaustive`], [`nga`]).
//! * `combine`: implementation alternatives from task implementation options and core-oriented
//!   constraints ([`combine`], [`Tio`], [`Task`], [`CoreConstraint`]).
//! * `margins`: online performance management: [`margins`], drift, and the reduced mission
//!   ([`reallocate`], [`reduced_problem`]).

use serde::{Deserialize, Serialize};

mod combine;
mod margins;
pub use combine::{CoreConstraint, Task, Tio, combine};
pub use margins::{
    MarginReport, Measured, Reallocator, SwapCheck, margins, margins_into, reallocate,
    reallocate_or_exact, reduced_problem,
};

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
            .map(|g| {
                self.activities
                    .iter()
                    .zip(choice)
                    .map(|(a, &i)| a.ias[i].cost[g])
                    .sum()
            })
            .collect()
    }

    /// True when every goal holds for `choice`.
    pub fn feasible(&self, choice: &[usize]) -> bool {
        self.totals(choice)
            .iter()
            .zip(&self.goals)
            .all(|(t, g)| fits(*t, g.bound))
    }

    /// Summed selection score of `choice`.
    pub fn score(&self, choice: &[usize], sel: Selection) -> f64 {
        self.activities
            .iter()
            .zip(choice)
            .map(|(a, &i)| sel.score(&a.ias[i]))
            .sum()
    }

    fn allocation(
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

    fn check_nonempty(&self) -> Result<(), Infeasible> {
        match self.activities.iter().find(|a| a.ias.is_empty()) {
            Some(a) => Err(Infeasible::NoAlternative {
                activity: a.name.clone(),
            }),
            None => Ok(()),
        }
    }
}

/// The paper's resource allocation algorithm (section 7.2.2, Fig. 7), iterated over the goals in
/// the user's order (lexicographic-like), then the [`Selection`] rule among the remaining IAs.
///
/// Per goal: sort each activity's candidates by cost (ascending; "highest" = last); start with the
/// highest everywhere; while the total exceeds the bound, walk activities from the last backwards,
/// choosing by binary search the highest IA of that activity that satisfies the goal with the
/// others fixed, or its lowest IA if none does. The candidate set of each activity is then cut to
/// the IAs no costlier than its pivot, so every combination of remaining candidates satisfies the
/// goal; later goals only shrink the sets, hence the final per-activity choice satisfies them all.
pub fn allocate(problem: &Problem, sel: Selection) -> Result<Allocation, Infeasible> {
    problem.check_nonempty()?;
    let n = problem.activities.len();
    let mut cands: Vec<Vec<usize>> = problem
        .activities
        .iter()
        .map(|a| (0..a.ias.len()).collect())
        .collect();
    for (g, goal) in problem.goals.iter().enumerate() {
        let cost = |j: usize, i: usize| problem.activities[j].ias[i].cost[g];
        // Sort ascending by cost; ties by score then index so "highest" is deterministic.
        for (j, c) in cands.iter_mut().enumerate() {
            c.sort_by(|&a, &b| {
                cost(j, a)
                    .total_cmp(&cost(j, b))
                    .then(
                        sel.score(&problem.activities[j].ias[a])
                            .total_cmp(&sel.score(&problem.activities[j].ias[b])),
                    )
                    .then(a.cmp(&b))
            });
        }
        let mut pos: Vec<usize> = cands.iter().map(|c| c.len() - 1).collect();
        let total = |pos: &[usize]| -> f64 { (0..n).map(|j| cost(j, cands[j][pos[j]])).sum() };
        if !fits(total(&pos), goal.bound) {
            for j in (0..n).rev() {
                pos[j] = 0;
                let others: f64 = (0..n)
                    .filter(|&k| k != j)
                    .map(|k| cost(k, cands[k][pos[k]]))
                    .sum();
                if !fits(others + cost(j, cands[j][0]), goal.bound) {
                    continue; // even this activity's lowest IA is not enough: go to the previous one
                }
                // Dichotomy: largest k with others + cost(k) <= bound (cost ascending in k).
                let (mut lo, mut hi) = (0usize, cands[j].len() - 1);
                while lo < hi {
                    let mid = (lo + hi).div_ceil(2);
                    if fits(others + cost(j, cands[j][mid]), goal.bound) {
                        lo = mid;
                    } else {
                        hi = mid - 1;
                    }
                }
                pos[j] = lo;
                break;
            }
            let t = total(&pos);
            if !fits(t, goal.bound) {
                return Err(Infeasible::Goal {
                    goal: goal.name.clone(),
                    minimum: t,
                    bound: goal.bound,
                    excess: t - goal.bound,
                });
            }
        }
        // Reduction: keep the IAs under the pivot line (ties with the pivot included).
        for j in 0..n {
            let pivot = cost(j, cands[j][pos[j]]);
            cands[j].retain(|&i| cost(j, i) <= pivot);
        }
    }
    let choice: Vec<usize> = cands
        .iter()
        .enumerate()
        .map(|(j, c)| best_of(&problem.activities[j], c, sel))
        .collect();
    Ok(problem.allocation(choice, sel, cands))
}

/// The candidate with the highest score; ties go to the lower first-goal cost, then lower index.
fn best_of(a: &Activity, c: &[usize], sel: Selection) -> usize {
    let first = |i: usize| a.ias[i].cost.first().copied().unwrap_or(0.0);
    *c.iter()
        .min_by(|&&x, &&y| {
            sel.score(&a.ias[y])
                .total_cmp(&sel.score(&a.ias[x]))
                .then(first(x).total_cmp(&first(y)))
                .then(x.cmp(&y))
        })
        .expect("non-empty candidate set")
}

/// Outcome of the exact search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Exact {
    /// A feasible allocation with the maximum summed score.
    Optimal(Allocation),
    /// No allocation satisfies every goal.
    Infeasible,
    /// The node budget ran out; the best allocation found so far, if any.
    Aborted(Option<Allocation>),
}

/// Exact maximisation of the summed [`Selection`] score subject to every goal, by depth-first
/// branch-and-bound: IAs dominated within their activity (no better score, no lower cost on any
/// goal) are dropped; a branch is cut when some goal cannot be met even with the cheapest
/// remaining IAs, or when its score cannot beat the incumbent (bounded by the best remaining scores
/// and, for `HighestCost(g)`, by the goal's bound itself). `max_nodes` caps the search.
pub fn exact(problem: &Problem, sel: Selection, max_nodes: u64) -> Exact {
    if problem.check_nonempty().is_err() {
        return Exact::Infeasible;
    }
    let n = problem.activities.len();
    let ng = problem.goals.len();
    // Non-dominated IAs per activity, best score first.
    let opts: Vec<Vec<usize>> = problem
        .activities
        .iter()
        .map(|a| {
            let dominated = |x: usize| {
                (0..a.ias.len()).any(|y| {
                    y != x && {
                        let (ix, iy) = (&a.ias[x], &a.ias[y]);
                        let ge = sel.score(iy) >= sel.score(ix)
                            && (0..ng).all(|g| iy.cost[g] <= ix.cost[g]);
                        let strict = sel.score(iy) > sel.score(ix)
                            || (0..ng).any(|g| iy.cost[g] < ix.cost[g]);
                        ge && (strict || y < x)
                    }
                })
            };
            let mut v: Vec<usize> = (0..a.ias.len()).filter(|&x| !dominated(x)).collect();
            v.sort_by(|&x, &y| {
                sel.score(&a.ias[y])
                    .total_cmp(&sel.score(&a.ias[x]))
                    .then(x.cmp(&y))
            });
            v
        })
        .collect();
    // Suffix bounds: min cost per goal and max score over activities j..n.
    let mut min_rest = vec![vec![0.0; ng]; n + 1];
    let mut max_rest = vec![0.0; n + 1];
    for j in (0..n).rev() {
        let a = &problem.activities[j];
        #[allow(clippy::needless_range_loop)] // reads row j + 1 while writing row j
        for g in 0..ng {
            let m = opts[j]
                .iter()
                .map(|&i| a.ias[i].cost[g])
                .fold(f64::INFINITY, f64::min);
            min_rest[j][g] = min_rest[j + 1][g] + m;
        }
        max_rest[j] = max_rest[j + 1]
            + opts[j]
                .iter()
                .map(|&i| sel.score(&a.ias[i]))
                .fold(f64::NEG_INFINITY, f64::max);
    }
    if (0..ng).any(|g| !fits(min_rest[0][g], problem.goals[g].bound)) {
        return Exact::Infeasible;
    }
    struct S<'a> {
        p: &'a Problem,
        sel: Selection,
        opts: Vec<Vec<usize>>,
        min_rest: Vec<Vec<f64>>,
        max_rest: Vec<f64>,
        cur: Vec<usize>,
        best: Option<(f64, Vec<usize>)>,
        nodes: u64,
        max_nodes: u64,
    }
    impl S<'_> {
        fn cap(&self) -> f64 {
            match self.sel {
                Selection::HighestCost(g) => self.p.goals.get(g).map_or(f64::INFINITY, |x| x.bound),
                Selection::MostCapable => f64::INFINITY,
            }
        }
        fn dfs(&mut self, j: usize, costs: &mut Vec<f64>, score: f64) -> bool {
            self.nodes += 1;
            if self.nodes > self.max_nodes {
                return false;
            }
            let n = self.p.activities.len();
            if j == n {
                if self.best.as_ref().is_none_or(|(b, _)| score > *b) {
                    self.best = Some((score, self.cur.clone()));
                }
                return true;
            }
            let cap = self.cap();
            for k in 0..self.opts[j].len() {
                let i = self.opts[j][k];
                let ia = &self.p.activities[j].ias[i];
                let s = score + self.sel.score(ia);
                let ub = (s + self.max_rest[j + 1]).min(cap + 1e-9 * cap.abs().max(1.0));
                if let Some((b, _)) = &self.best
                    && ub <= *b
                {
                    continue;
                }
                let ok = (0..costs.len()).all(|g| {
                    fits(
                        costs[g] + ia.cost[g] + self.min_rest[j + 1][g],
                        self.p.goals[g].bound,
                    )
                });
                if !ok {
                    continue;
                }
                for (g, c) in costs.iter_mut().enumerate() {
                    *c += ia.cost[g];
                }
                self.cur[j] = i;
                let go = self.dfs(j + 1, costs, s);
                for (g, c) in costs.iter_mut().enumerate() {
                    *c -= ia.cost[g];
                }
                if !go {
                    return false;
                }
            }
            true
        }
    }
    let mut s = S {
        p: problem,
        sel,
        opts,
        min_rest,
        max_rest,
        cur: vec![0; n],
        best: None,
        nodes: 0,
        max_nodes,
    };
    let done = s.dfs(0, &mut vec![0.0; ng], 0.0);
    // Re-check with in-order sums (the incremental sums may differ in the last bits).
    let best = s
        .best
        .take()
        .map(|(_, c)| problem.allocation(c, sel, Vec::new()))
        .filter(|a| problem.feasible(&a.choice));
    match (done, best) {
        (true, Some(a)) => Exact::Optimal(a),
        (true, None) => Exact::Infeasible,
        (false, b) => Exact::Aborted(b),
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
