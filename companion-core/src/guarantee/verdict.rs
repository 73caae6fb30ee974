//! The verdict in the operator's terms (issue 36 item 4): what the plan needs against what the
//! pack and the time limit give, and what would fit (the longest search or tracking hold the
//! pack holds, the cheaper allocation, or nothing). Pure: computed on the compiled mission.
//!
//! **Why bisection over a hold is valid.** Each IA's estimates are affine in its activity's
//! hold with non-negative slopes (energy: the hold's propulsion power plus the payload's, J/s;
//! duration: 1 s/s; compile.rs), so lengthening a hold never lowers any allocation's total on
//! any goal: the set of allocations meeting every goal only shrinks. "Some allocation fits" is
//! therefore monotone (true up to some hold, false beyond), which is what bisection needs. The
//! predicate is exact feasibility (the paper's algorithm, else the exact search, as the in-flight
//! re-allocation), not the paper's greedy alone, which with two goals can miss a feasible
//! allocation and is not monotone.

use super::{DURATION, ENERGY, MissionSpec};
use crate::record::{Lowered, Verdict};
use panorama::{Exact, Problem, Selection};
use serde::{Deserialize, Serialize};

/// What an activity's hold is, for the verdict: the mission's search or tracking time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HoldKind {
    /// The search time limit (route_plan's `search`; a typed activity's `hold_kind = "search"`).
    Search,
    /// The tracking time limit (route_plan's `tracking`; `hold_kind = "tracking"`).
    Tracking,
}

/// Node budget of the exact search behind each feasibility question (the shipped missions need
/// a few hundred; bounded so a refused start costs a bounded time each cycle).
const EXACT_NODES: u64 = 50_000;

/// The verdict on `spec` (its goals' bounds as they stand: `fly` sets the energy goal from the
/// pack), with `spent` per goal already used (the energy the pack no longer holds, the time
/// elapsed; zeros for `check`) and the pack's remaining percentage. The whole mission is judged,
/// as before the flight.
pub fn judge(spec: &MissionSpec, spent: &[f64], battery_pct: Option<f64>) -> Verdict {
    let mut p = spec.problem.clone();
    for (g, s) in p.goals.iter_mut().zip(spent) {
        g.bound -= s;
    }
    let goal = |name: &str| p.goals.iter().position(|g| g.name == name);
    let (e, d) = (goal(ENERGY), goal(DURATION));
    let at = |totals: &[f64], g: Option<usize>| g.map(|g| totals[g]);
    let mut v = Verdict {
        available_energy_j: e.map(|e| p.goals[e].bound),
        available_duration_s: d.map(|d| p.goals[d].bound),
        battery_pct,
        planned_search_s: planned_hold(spec, HoldKind::Search),
        planned_tracking_s: planned_hold(spec, HoldKind::Tracking),
        ..Verdict::default()
    };
    if let Some(choice) = fitting(&p, spec.selection) {
        let totals = p.totals(&choice);
        v.fits = true;
        v.planned_energy_j = at(&totals, e);
        v.planned_duration_s = at(&totals, d);
        let best = most_capable(&p, spec.selection);
        if !p.feasible(&best) {
            v.most_capable_energy_j = at(&p.totals(&best), e);
            v.lowered = (0..p.activities.len())
                .filter(|&j| choice[j] != best[j])
                .map(|j| Lowered {
                    activity: p.activities[j].name.clone(),
                    planned: p.activities[j].ias[choice[j]].name.clone(),
                    most_capable: p.activities[j].ias[best[j]].name.clone(),
                })
                .collect();
        }
        return v;
    }
    let lowest = lowest_totals(&p);
    v.planned_energy_j = at(&lowest, e);
    v.planned_duration_s = at(&lowest, d);
    // What is named as fitting fits with the headroom, not at the edge (tuning.rs, FIT_HEADROOM).
    let mut room = p.clone();
    for g in &mut room.goals {
        g.bound -= g.bound.abs() * spec.tuning.fit_headroom;
    }
    v.longest_search_s = longest_hold(spec, &room, HoldKind::Search);
    v.longest_tracking_s = longest_hold(spec, &room, HoldKind::Tracking);
    if v.longest_search_s.is_none() && v.longest_tracking_s.is_none() {
        let route = with_holds(
            spec,
            &p,
            &[(HoldKind::Search, 0.0), (HoldKind::Tracking, 0.0)],
        );
        let lowest = lowest_totals(&route);
        v.route_energy_j = at(&lowest, e);
        v.route_duration_s = at(&lowest, d);
    }
    v
}

/// An allocation meeting every goal of `p`, if any: the paper's algorithm, else the bounded
/// exact search (its best so far when the budget runs out).
fn fitting(p: &Problem, sel: Selection) -> Option<Vec<usize>> {
    if let Ok(a) = panorama::allocate(p, sel) {
        return Some(a.choice);
    }
    match panorama::exact(p, sel, EXACT_NODES) {
        Exact::Optimal(a) | Exact::Aborted(Some(a)) => Some(a.choice),
        Exact::Infeasible | Exact::Aborted(None) => None,
    }
}

/// Per activity, its most capable IA by the mission's selection rule (the first of equals).
fn most_capable(p: &Problem, sel: Selection) -> Vec<usize> {
    p.activities
        .iter()
        .map(|a| {
            let mut best = 0;
            for (i, ia) in a.ias.iter().enumerate() {
                if sel.score(ia) > sel.score(&a.ias[best]) {
                    best = i;
                }
            }
            best
        })
        .collect()
}

/// Per goal, the lowest total any allocation reaches (each goal minimised on its own).
fn lowest_totals(p: &Problem) -> Vec<f64> {
    (0..p.goals.len())
        .map(|g| {
            p.activities
                .iter()
                .map(|a| {
                    a.ias
                        .iter()
                        .map(|ia| ia.cost[g])
                        .fold(f64::INFINITY, f64::min)
                })
                .sum()
        })
        .collect()
}

/// The hold of the activities of `kind` as planned (the longest when several), if any.
fn planned_hold(spec: &MissionSpec, kind: HoldKind) -> Option<f64> {
    spec.activities
        .iter()
        .filter(|a| a.hold_kind == Some(kind))
        .map(|a| a.hold_s)
        .reduce(f64::max)
}

/// `p` with every activity of each listed kind held the given seconds instead of its planned
/// hold: each IA's estimates moved along their slopes (energy `ia_hold_w`, duration 1).
fn with_holds(spec: &MissionSpec, p: &Problem, holds: &[(HoldKind, f64)]) -> Problem {
    let goal = |name: &str| p.goals.iter().position(|g| g.name == name);
    let (e, d) = (goal(ENERGY), goal(DURATION));
    let mut out = p.clone();
    for (info, a) in spec.activities.iter().zip(&mut out.activities) {
        let Some(&(_, h)) = holds.iter().find(|(k, _)| Some(*k) == info.hold_kind) else {
            continue;
        };
        let dh = h - info.hold_s;
        for (ia, w) in a.ias.iter_mut().zip(&info.ia_hold_w) {
            if let Some(e) = e {
                ia.cost[e] = (ia.cost[e] + dh * w).max(0.0);
            }
            if let Some(d) = d {
                ia.cost[d] = (ia.cost[d] + dh).max(0.0);
            }
        }
    }
    out
}

/// The longest whole number of seconds the activities of `kind` may hold with which some
/// allocation of `p` (which does not fit as planned) fits, the other activities as planned;
/// `None` when the mission has no such hold or even none does not fit. Bisection over
/// `[0, ceil(planned)]` (monotone: the module's comment), exact to 1 s.
fn longest_hold(spec: &MissionSpec, p: &Problem, kind: HoldKind) -> Option<f64> {
    let planned = planned_hold(spec, kind)?;
    let fits = |h: f64| fitting(&with_holds(spec, p, &[(kind, h)]), spec.selection).is_some();
    if !fits(0.0) {
        return None;
    }
    // Invariant: `lo` fits, `hi` does not (the planned hold does not, nor anything longer).
    let (mut lo, mut hi) = (0u64, planned.max(0.0).ceil() as u64);
    if fits(hi as f64) {
        return Some(hi as f64); // only a fraction of a second over: the whole planned seconds fit
    }
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if fits(mid as f64) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(lo as f64)
}

#[cfg(test)]
mod tests;
