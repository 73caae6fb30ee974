//! Online performance management (paper section 7.3): margins, drift and the reduced mission.

use crate::search::Search;
use crate::{Activity, Goal, Infeasible, Problem, Selection, allocate};
use serde::{Deserialize, Serialize};

/// What has been measured so far: the activity being flown (index into the problem), the fraction
/// of it already flown (0 at its start, 1 at its end; 0 is the conservative choice when unknown),
/// and the measured total per goal since the mission started.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Measured {
    /// Index of the activity being flown.
    pub activity: usize,
    /// Fraction of that activity already flown, in `[0, 1]`.
    pub fraction: f64,
    /// Measured total per goal since the mission started, in the problem's goal order.
    pub so_far: Vec<f64>,
}

/// Per goal (same order as the problem's goals).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MarginReport {
    /// What the plan expected to have spent by now.
    pub estimated_so_far: Vec<f64>,
    /// What the plan expects to spend from now to the end.
    pub remainder: Vec<f64>,
    /// `goal - (measured so far + remainder)`: paper eq. 7 with `FPerf(MS)(t)` = measured + remainder.
    pub margin: Vec<f64>,
    /// `measured so far - estimated so far`.
    pub drift: Vec<f64>,
}

fn split(p: &Problem, choice: &[usize], m: &Measured, g: usize) -> (f64, f64) {
    let f = m.fraction.clamp(0.0, 1.0);
    let mut before = 0.0;
    let mut after = 0.0;
    for (j, (a, &i)) in p.activities.iter().zip(choice).enumerate() {
        let c = a.ias[i].cost[g];
        match j.cmp(&m.activity) {
            std::cmp::Ordering::Less => before += c,
            std::cmp::Ordering::Equal => {
                before += f * c;
                after += (1.0 - f) * c;
            }
            std::cmp::Ordering::Greater => after += c,
        }
    }
    (before, after)
}

/// Margins and drift of allocation `choice` given the measurements.
pub fn margins(p: &Problem, choice: &[usize], m: &Measured) -> MarginReport {
    let mut r = MarginReport {
        estimated_so_far: vec![],
        remainder: vec![],
        margin: vec![],
        drift: vec![],
    };
    margins_into(p, choice, m, &mut r);
    r
}

/// As [`margins`], overwriting a reused report (no allocation once it has held this many goals).
pub fn margins_into(p: &Problem, choice: &[usize], m: &Measured, r: &mut MarginReport) {
    r.estimated_so_far.clear();
    r.remainder.clear();
    r.margin.clear();
    r.drift.clear();
    for (g, goal) in p.goals.iter().enumerate() {
        let (before, after) = split(p, choice, m, g);
        let measured = m.so_far.get(g).copied().unwrap_or(0.0);
        r.estimated_so_far.push(before);
        r.remainder.push(after);
        r.margin.push(goal.bound - (measured + after));
        r.drift.push(measured - before);
    }
}

/// Whether activity `at` flown with its alternative `i` instead of `choice[at]` keeps every goal,
/// as [`margins_into`] on the swapped choice and [`crate::fits`] on each margin would say, bit for
/// bit, but fast when asked of many alternatives of one activity.
///
/// Why it can be fast and still exact: with the rest of the plan and the measurements fixed, a
/// goal's margin depends on the alternative only through its cost `c`, through
/// `bound - (measured + ((1 - f)·c + c_next + ...))`, and IEEE rounding is monotone, so "the goal
/// holds" is monotone in `c`: it holds for every cost up to some threshold and for none above.
/// The check remembers, per goal, the largest cost seen to hold and the smallest seen to fail, and
/// evaluates (in [`margins_into`]'s own order of operations) only costs between the two.
///
/// Valid for one problem, plan, measurement and `at`: [`SwapCheck::reset`] before asking about
/// another.
#[derive(Debug, Clone, Default)]
pub struct SwapCheck {
    /// Per goal: the largest cost known to hold, the smallest known to fail.
    known: Vec<(f64, f64)>,
}

impl SwapCheck {
    /// Forget what was learnt (a new plan, measurement or activity).
    pub fn reset(&mut self, goals: usize) {
        self.known.clear();
        self.known.resize(goals, (f64::NEG_INFINITY, f64::INFINITY));
    }

    /// Does alternative `i` of activity `at`, with `choice` for the other activities, meet every
    /// goal from measurement `m`? (Resources are the caller's business.)
    pub fn fits(
        &mut self,
        p: &Problem,
        choice: &[usize],
        m: &Measured,
        at: usize,
        i: usize,
    ) -> bool {
        if self.known.len() != p.goals.len() {
            self.reset(p.goals.len());
        }
        for g in 0..p.goals.len() {
            let c = p.activities[at].ias[i].cost[g];
            let (ok_max, bad_min) = self.known[g];
            let holds = if c <= ok_max {
                true
            } else if c >= bad_min {
                false
            } else {
                let holds = goal_holds(p, choice, m, g, at, c);
                // A NaN anywhere breaks the monotonicity: remember nothing from it.
                if !c.is_nan() {
                    if holds {
                        self.known[g].0 = c;
                    } else {
                        self.known[g].1 = c;
                    }
                }
                holds
            };
            if !holds {
                return false;
            }
        }
        true
    }
}

/// Goal `g`'s margin for `choice` with activity `at` costing `c`, judged by [`crate::fits`]: the
/// operations of [`margins_into`] (`split`'s `after`, then `bound - (measured + after)`) in the same
/// order, so the same bits.
fn goal_holds(p: &Problem, choice: &[usize], m: &Measured, g: usize, at: usize, c: f64) -> bool {
    let f = m.fraction.clamp(0.0, 1.0);
    let mut after = 0.0;
    for (j, (a, &k)) in p.activities.iter().zip(choice).enumerate() {
        let cj = if j == at { c } else { a.ias[k].cost[g] };
        match j.cmp(&m.activity) {
            std::cmp::Ordering::Less => {}
            std::cmp::Ordering::Equal => after += (1.0 - f) * cj,
            std::cmp::Ordering::Greater => after += cj,
        }
    }
    let bound = p.goals[g].bound;
    let measured = m.so_far.get(g).copied().unwrap_or(0.0);
    let margin = bound - (measured + after);
    crate::fits(bound - margin, bound)
}

/// The reduced mission scenario from the current activity: goals lowered by what was measured,
/// the current activity's costs scaled by its unflown fraction, IAs using a failed resource
/// removed. Returns the problem and, per reduced activity, the original IA index of each IA.
/// A finished current activity (`fraction >= 1`) is not part of the reduced mission.
pub fn reduced_problem(p: &Problem, m: &Measured, failed: &[String]) -> (Problem, Vec<Vec<usize>>) {
    let m = &start_of_rest(m);
    let f = m.fraction.clamp(0.0, 1.0);
    let goals = p
        .goals
        .iter()
        .enumerate()
        .map(|(g, goal)| Goal {
            name: goal.name.clone(),
            bound: goal.bound - m.so_far.get(g).copied().unwrap_or(0.0),
        })
        .collect();
    let mut map = Vec::new();
    let activities = p
        .activities
        .iter()
        .enumerate()
        .skip(m.activity)
        .map(|(j, a)| {
            let keep: Vec<usize> = (0..a.ias.len())
                .filter(|&i| !a.ias[i].resources.iter().any(|r| failed.contains(r)))
                .collect();
            let scale = if j == m.activity { 1.0 - f } else { 1.0 };
            let ias = keep
                .iter()
                .map(|&i| {
                    let mut ia = a.ias[i].clone();
                    ia.cost.iter_mut().for_each(|c| *c *= scale);
                    ia
                })
                .collect();
            map.push(keep);
            Activity {
                name: a.name.clone(),
                ias,
            }
        })
        .collect();
    (Problem { goals, activities }, map)
}

/// A new RAS for the reduced mission (paper section 7.3.2): the same allocation algorithm on
/// [`reduced_problem`]. Returns the full-length choice (activities already flown keep theirs).
pub fn reallocate(
    p: &Problem,
    choice: &[usize],
    m: &Measured,
    failed: &[String],
    sel: Selection,
) -> Result<Vec<usize>, Infeasible> {
    let (rp, map) = reduced_problem(p, m, failed);
    let a = allocate(&rp, sel)?;
    let from = start_of_rest(m).activity;
    let mut out = choice.to_vec();
    for (k, &i) in a.choice.iter().enumerate() {
        out[from + k] = map[k][i];
    }
    Ok(out)
}

fn start_of_rest(m: &Measured) -> Measured {
    if m.fraction >= 1.0 {
        Measured {
            activity: m.activity + 1,
            fraction: 0.0,
            so_far: m.so_far.clone(),
        }
    } else {
        m.clone()
    }
}

/// [`reallocate_or_exact`] with its reduced mission and the searches' buffers kept between calls,
/// rebuilt in place: while the guarantee cannot be met, the watch asks every cycle, and building
/// the reduced mission afresh (every IA's name, costs and resources cloned, twice) was most of a
/// cycle. A call that finds nothing allocates nothing once the buffers have their size.
#[derive(Debug, Clone)]
pub struct Reallocator {
    reduced: Problem,
    map: Vec<Vec<usize>>,
    search: Search,
    /// The last call's reason for finding nothing, its strings rewritten in place.
    failure: Infeasible,
}

impl Default for Reallocator {
    fn default() -> Self {
        Self {
            reduced: Problem {
                goals: Vec::new(),
                activities: Vec::new(),
            },
            map: Vec::new(),
            search: Search::default(),
            failure: Infeasible::NoAlternative {
                activity: String::new(),
            },
        }
    }
}

impl Reallocator {
    /// [`reallocate_or_exact`] (which makes a fresh one per call): the paper's algorithm on the
    /// reduced mission, then the bounded exact search when it finds nothing. The reason for
    /// finding nothing is borrowed from the reallocator (kept to be rewritten by the next call).
    pub fn reallocate_or_exact(
        &mut self,
        p: &Problem,
        choice: &[usize],
        m: &Measured,
        failed: &[String],
        sel: Selection,
        max_nodes: u64,
    ) -> Result<(Vec<usize>, bool), &Infeasible> {
        reduced_problem_into(p, m, failed, &mut self.reduced, &mut self.map);
        let rp = &self.reduced;
        let from = p.activities.len() - rp.activities.len();
        let expand = |reduced: &[usize]| {
            let mut out = choice.to_vec();
            for (k, &i) in reduced.iter().enumerate() {
                out[from + k] = self.map[k][i];
            }
            out
        };
        let failure = match self.search.allocate(rp, sel) {
            Ok(()) => return Ok((expand(&self.search.choice), false)),
            Err(f) => f,
        };
        // Optimal, or the budget ran out with an allocation in hand: either is one.
        if self.search.exact(rp, sel, max_nodes).found {
            return Ok((expand(&self.search.best), true));
        }
        failure.write_into(rp, &mut self.failure);
        Err(&self.failure)
    }
}

/// [`reduced_problem`] into `out` and `map`, their strings and vectors reused.
fn reduced_problem_into(
    p: &Problem,
    m: &Measured,
    failed: &[String],
    out: &mut Problem,
    map: &mut Vec<Vec<usize>>,
) {
    // `start_of_rest` without its copy of the measurements.
    let (from, fraction) = if m.fraction >= 1.0 {
        (m.activity + 1, 0.0)
    } else {
        (m.activity, m.fraction)
    };
    let f = fraction.clamp(0.0, 1.0);
    out.goals.truncate(p.goals.len());
    for (g, goal) in p.goals.iter().enumerate() {
        let bound = goal.bound - m.so_far.get(g).copied().unwrap_or(0.0);
        match out.goals.get_mut(g) {
            Some(dst) => {
                dst.name.clone_from(&goal.name);
                dst.bound = bound;
            }
            None => out.goals.push(Goal {
                name: goal.name.clone(),
                bound,
            }),
        }
    }
    let rest = p.activities.len().saturating_sub(from);
    out.activities.truncate(rest);
    map.truncate(rest);
    for (k, (j, a)) in p.activities.iter().enumerate().skip(from).enumerate() {
        if k == out.activities.len() {
            out.activities.push(Activity {
                name: String::new(),
                ias: Vec::new(),
            });
            map.push(Vec::new());
        }
        let dst = &mut out.activities[k];
        dst.name.clone_from(&a.name);
        let keep = &mut map[k];
        keep.clear();
        let scale = if j == from { 1.0 - f } else { 1.0 };
        let mut n = 0;
        for (i, ia) in a.ias.iter().enumerate() {
            if ia.resources.iter().any(|r| failed.contains(r)) {
                continue;
            }
            keep.push(i);
            if n == dst.ias.len() {
                dst.ias.push(ia.clone());
            } else {
                let d = &mut dst.ias[n];
                d.name.clone_from(&ia.name);
                d.cost.clone_from(&ia.cost);
                d.capability = ia.capability;
                d.resources.clone_from(&ia.resources);
            }
            dst.ias[n].cost.iter_mut().for_each(|c| *c *= scale);
            n += 1;
        }
        dst.ias.truncate(n);
    }
}

/// [`reallocate`], and when the paper's algorithm finds nothing, a bounded [`exact`] search on the
/// same reduced mission (its greedy reduction per goal can cut away what a later goal needs).
/// Returns the choice and whether the exact search produced it; the paper's [`Infeasible`] when
/// neither finds an allocation.
pub fn reallocate_or_exact(
    p: &Problem,
    choice: &[usize],
    m: &Measured,
    failed: &[String],
    sel: Selection,
    max_nodes: u64,
) -> Result<(Vec<usize>, bool), Infeasible> {
    Reallocator::default()
        .reallocate_or_exact(p, choice, m, failed, sel, max_nodes)
        .map_err(Infeasible::clone)
}
