//! The allocation ([`allocate`], the paper's algorithm) and the exact search ([`exact`]), both on
//! a [`Search`] of buffers that a [`Reallocator`](crate::Reallocator) keeps between calls: while
//! the guarantee cannot be met it asks every cycle, and fresh candidate lists per call were most
//! of such a cycle's allocations.

use crate::{Activity, Allocation, Infeasible, Problem, Selection, fits};

/// Why [`Search::allocate`] found nothing, by index: the names go into an [`Infeasible`] only
/// when one is asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Failure {
    /// Goal `g` is exceeded even at the lowest reachable total `minimum`.
    Goal { g: usize, minimum: f64 },
    /// Activity `j` has no implementation alternative.
    NoAlternative { j: usize },
}

impl Failure {
    /// This failure as the [`Infeasible`] that names it, written over `out` (its strings reused).
    pub(crate) fn write_into(self, p: &Problem, out: &mut Infeasible) {
        match (self, out) {
            (
                Failure::Goal { g, minimum },
                Infeasible::Goal {
                    goal,
                    minimum: m,
                    bound,
                    excess,
                },
            ) => {
                let x = &p.goals[g];
                goal.clone_from(&x.name);
                (*m, *bound, *excess) = (minimum, x.bound, minimum - x.bound);
            }
            (Failure::NoAlternative { j }, Infeasible::NoAlternative { activity }) => {
                activity.clone_from(&p.activities[j].name);
            }
            (failure, out) => *out = failure.to_infeasible(p),
        }
    }

    fn to_infeasible(self, p: &Problem) -> Infeasible {
        match self {
            Failure::Goal { g, minimum } => Infeasible::Goal {
                goal: p.goals[g].name.clone(),
                minimum,
                bound: p.goals[g].bound,
                excess: minimum - p.goals[g].bound,
            },
            Failure::NoAlternative { j } => Infeasible::NoAlternative {
                activity: p.activities[j].name.clone(),
            },
        }
    }
}

/// How [`Search::exact`] ended: `done` when the search space was covered within the node
/// budget; `found` when [`Search::best`] holds a feasible choice.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ExactEnd {
    pub(crate) done: bool,
    pub(crate) found: bool,
}

/// The buffers of both searches. Only grown: after the first call on a mission of a given size,
/// neither search allocates.
#[derive(Debug, Clone, Default)]
pub(crate) struct Search {
    /// [`Search::allocate`]: per activity, the candidates left (IA indices).
    cands: Vec<Vec<usize>>,
    /// [`Search::allocate`]: per activity, the position of its IA in its sorted candidates.
    pos: Vec<usize>,
    /// [`Search::allocate`]'s answer: the chosen IA per activity.
    pub(crate) choice: Vec<usize>,
    /// [`Search::exact`]: per activity, the non-dominated IAs, best score first.
    opts: Vec<Vec<usize>>,
    /// [`Search::exact`]: per activity `j` (row-major, `goals` wide), the least total of each
    /// goal over activities `j..`, and the best summed score.
    min_rest: Vec<f64>,
    max_rest: Vec<f64>,
    /// [`Search::exact`]: the branch being explored and its totals per goal.
    cur: Vec<usize>,
    costs: Vec<f64>,
    /// [`Search::exact`]'s answer: the best feasible choice found.
    pub(crate) best: Vec<usize>,
}

/// The first `n` lists of `lists`, grown to `n` if needed (never shrunk: their buffers stay).
fn lists(lists: &mut Vec<Vec<usize>>, n: usize) -> &mut [Vec<usize>] {
    if lists.len() < n {
        lists.resize_with(n, Vec::new);
    }
    &mut lists[..n]
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
    let mut s = Search::default();
    match s.allocate(problem, sel) {
        Ok(()) => {
            let mut cands = s.cands;
            cands.truncate(problem.activities.len());
            Ok(problem.allocation(s.choice, sel, cands))
        }
        Err(f) => Err(f.to_infeasible(problem)),
    }
}

/// Outcome of the exact search.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
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
    let mut s = Search::default();
    let end = s.exact(problem, sel, max_nodes);
    let best = end
        .found
        .then(|| problem.allocation(s.best, sel, Vec::new()));
    match (end.done, best) {
        (true, Some(a)) => Exact::Optimal(a),
        (true, None) => Exact::Infeasible,
        (false, b) => Exact::Aborted(b),
    }
}

impl Search {
    /// [`allocate`] into [`Search::choice`].
    pub(crate) fn allocate(&mut self, problem: &Problem, sel: Selection) -> Result<(), Failure> {
        if let Some(j) = problem.activities.iter().position(|a| a.ias.is_empty()) {
            return Err(Failure::NoAlternative { j });
        }
        let n = problem.activities.len();
        let cands = lists(&mut self.cands, n);
        for (c, a) in cands.iter_mut().zip(&problem.activities) {
            c.clear();
            c.extend(0..a.ias.len());
        }
        let pos = &mut self.pos;
        for (g, goal) in problem.goals.iter().enumerate() {
            let cost = |j: usize, i: usize| problem.activities[j].ias[i].cost[g];
            // Ascending by cost; ties by score then index so "highest" is deterministic. A total
            // order, so the unstable sort (no buffer) gives the stable one's order.
            for (j, c) in cands.iter_mut().enumerate() {
                let ias = &problem.activities[j].ias;
                c.sort_unstable_by(|&a, &b| {
                    cost(j, a)
                        .total_cmp(&cost(j, b))
                        .then(sel.score(&ias[a]).total_cmp(&sel.score(&ias[b])))
                        .then(a.cmp(&b))
                });
            }
            pos.clear();
            pos.extend(cands.iter().map(|c| c.len() - 1));
            let total = |pos: &[usize]| -> f64 { (0..n).map(|j| cost(j, cands[j][pos[j]])).sum() };
            if !fits(total(pos), goal.bound) {
                for j in (0..n).rev() {
                    pos[j] = 0;
                    let others: f64 = (0..n)
                        .filter(|&k| k != j)
                        .map(|k| cost(k, cands[k][pos[k]]))
                        .sum();
                    if !fits(others + cost(j, cands[j][0]), goal.bound) {
                        continue; // even this activity's lowest IA is not enough: the previous one
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
                let t = total(pos);
                if !fits(t, goal.bound) {
                    return Err(Failure::Goal { g, minimum: t });
                }
            }
            // Reduction: keep the IAs under the pivot line (ties with the pivot included).
            for j in 0..n {
                let pivot = cost(j, cands[j][pos[j]]);
                cands[j].retain(|&i| cost(j, i) <= pivot);
            }
        }
        self.choice.clear();
        self.choice.extend(
            cands
                .iter()
                .zip(&problem.activities)
                .map(|(c, a)| best_of(a, c, sel)),
        );
        Ok(())
    }

    /// [`exact`] into [`Search::best`].
    pub(crate) fn exact(&mut self, problem: &Problem, sel: Selection, max_nodes: u64) -> ExactEnd {
        let infeasible = ExactEnd {
            done: true,
            found: false,
        };
        if problem.activities.iter().any(|a| a.ias.is_empty()) {
            return infeasible;
        }
        let (n, ng) = (problem.activities.len(), problem.goals.len());
        let opts = lists(&mut self.opts, n);
        for (v, a) in opts.iter_mut().zip(&problem.activities) {
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
            v.clear();
            v.extend((0..a.ias.len()).filter(|&x| !dominated(x)));
            // Best score first, ties by index: a total order, so unstable is stable.
            v.sort_unstable_by(|&x, &y| {
                sel.score(&a.ias[y])
                    .total_cmp(&sel.score(&a.ias[x]))
                    .then(x.cmp(&y))
            });
        }
        // Suffix bounds: min cost per goal and max score over activities j..n.
        let (min_rest, max_rest) = (&mut self.min_rest, &mut self.max_rest);
        min_rest.clear();
        min_rest.resize((n + 1) * ng, 0.0);
        max_rest.clear();
        max_rest.resize(n + 1, 0.0);
        for j in (0..n).rev() {
            let a = &problem.activities[j];
            for g in 0..ng {
                let m = opts[j]
                    .iter()
                    .map(|&i| a.ias[i].cost[g])
                    .fold(f64::INFINITY, f64::min);
                min_rest[j * ng + g] = min_rest[(j + 1) * ng + g] + m;
            }
            max_rest[j] = max_rest[j + 1]
                + opts[j]
                    .iter()
                    .map(|&i| sel.score(&a.ias[i]))
                    .fold(f64::NEG_INFINITY, f64::max);
        }
        if (0..ng).any(|g| !fits(min_rest[g], problem.goals[g].bound)) {
            return infeasible;
        }
        self.cur.clear();
        self.cur.resize(n, 0);
        self.costs.clear();
        self.costs.resize(ng, 0.0);
        let mut b = BranchAndBound {
            p: problem,
            sel,
            opts,
            min_rest,
            max_rest,
            cur: &mut self.cur,
            best: &mut self.best,
            best_score: None,
            nodes: 0,
            max_nodes,
        };
        let done = b.dfs(0, &mut self.costs, 0.0);
        // Re-check with in-order sums (the incremental sums may differ in the last bits).
        let found = b.best_score.is_some() && problem.feasible(&self.best);
        ExactEnd { done, found }
    }
}

/// The depth-first search of [`Search::exact`], over the search's buffers.
struct BranchAndBound<'a> {
    p: &'a Problem,
    sel: Selection,
    opts: &'a [Vec<usize>],
    min_rest: &'a [f64],
    max_rest: &'a [f64],
    cur: &'a mut [usize],
    best: &'a mut Vec<usize>,
    best_score: Option<f64>,
    nodes: u64,
    max_nodes: u64,
}

impl BranchAndBound<'_> {
    fn cap(&self) -> f64 {
        match self.sel {
            Selection::HighestCost(g) => self.p.goals.get(g).map_or(f64::INFINITY, |x| x.bound),
            Selection::MostCapable => f64::INFINITY,
        }
    }

    fn dfs(&mut self, j: usize, costs: &mut [f64], score: f64) -> bool {
        self.nodes += 1;
        if self.nodes > self.max_nodes {
            return false;
        }
        let n = self.p.activities.len();
        if j == n {
            if self.best_score.is_none_or(|b| score > b) {
                self.best_score = Some(score);
                self.best.clear();
                self.best.extend_from_slice(self.cur);
            }
            return true;
        }
        let (cap, ng) = (self.cap(), costs.len());
        for k in 0..self.opts[j].len() {
            let i = self.opts[j][k];
            let ia = &self.p.activities[j].ias[i];
            let s = score + self.sel.score(ia);
            let ub = (s + self.max_rest[j + 1]).min(cap + 1e-9 * cap.abs().max(1.0));
            if let Some(b) = self.best_score
                && ub <= b
            {
                continue;
            }
            let rest = &self.min_rest[(j + 1) * ng..(j + 2) * ng];
            let ok = (0..ng).all(|g| fits(costs[g] + ia.cost[g] + rest[g], self.p.goals[g].bound));
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
