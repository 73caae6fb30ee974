//! The plan and what runs are one configuration (issue 24 item 1; docs/guarantee.md "One
//! configuration").
//!
//! BFM chooses *which* version runs (the tracking MDP, by the QoS its health manager predicts);
//! PANORAMA chooses *how* (an implementation alternative meeting the energy and duration goals).
//! Two ways bind them each cycle, after the placement:
//! - PANORAMA -> BFM: a version none of whose alternatives in the activity being flown meets the
//!   goals (with the rest of the plan) is infeasible: [`Guarantee::versions_without_alternative`]
//!   lists it and the core caps its probability, so no MDP proposes it.
//! - BFM -> PANORAMA: [`Guarantee::follow`] moves the activity's cell of the plan to the most
//!   capable feasible alternative carrying the versions that run (the models chose another
//!   version), or to the exact implementations that run (the planned one did not fit): the
//!   energy and duration estimates are always those of what runs, and the implementation the
//!   plan names is the one the next cycle requests.

use super::Guarantee;
use crate::record::{GuaranteeRecord, PlacementRecord, ReallocationTrigger};
use std::fmt::Write as _;

/// `(version, implementation)` of an IA token: `V4.F` -> `("V4", Some("F"))`, `lidar` ->
/// `("lidar", None)`.
fn token(t: &str) -> (&str, Option<&str>) {
    match t.split_once('.') {
        Some((v, i)) => (v, Some(i)),
        None => (t, None),
    }
}

/// An activity's alternatives as tokens, parsed once when the guarantee starts (the binding
/// asks them for every alternative and placement every cycle: parsing the names there took 85 %
/// of the cycle).
#[derive(Debug, Clone)]
pub(super) struct ActivityTokens {
    /// Every token any alternative names (`lidar`, `V3`, `zone_t`), in first-seen order.
    named: Vec<String>,
    /// Per alternative: `(index into named, implementation)` per token.
    ias: Vec<Vec<(usize, Option<String>)>>,
    /// Per alternative, the token ids it offers with an implementation, as bits (when the
    /// activity names fewer than 128 tokens; the top bit marks "some alternative is feasible"): the binding's per-cycle check is then a few word
    /// operations per alternative.
    versions: Option<Vec<u128>>,
    /// The union of `versions`: every token some alternative offers with an implementation.
    all_versions: u128,
    /// Per alternative, every token id it names (with an implementation or not), as bits (with
    /// `versions`): whether it carries the running versions is then one word operation.
    named_bits: Option<Vec<u128>>,
}

impl ActivityTokens {
    pub(super) fn of(p: &panorama::Problem) -> Vec<Self> {
        p.activities
            .iter()
            .map(|act| {
                let mut named: Vec<String> = Vec::new();
                let ias = act
                    .ias
                    .iter()
                    .map(|ia| {
                        ia.name
                            .split_whitespace()
                            .map(|t| {
                                let (v, i) = token(t);
                                let id = named.iter().position(|n| n == v).unwrap_or_else(|| {
                                    named.push(v.to_string());
                                    named.len() - 1
                                });
                                (id, i.map(str::to_string))
                            })
                            .collect()
                    })
                    .collect::<Vec<Vec<(usize, Option<String>)>>>();
                let versions = (named.len() < 128).then(|| {
                    ias.iter()
                        .map(|tokens| {
                            tokens
                                .iter()
                                .filter(|(_, imp)| imp.is_some())
                                .fold(0u128, |bits, (id, _)| bits | 1 << id)
                        })
                        .collect()
                });
                let all_versions = versions.iter().flatten().fold(0, |a, b| a | b);
                let named_bits = versions.is_some().then(|| {
                    ias.iter()
                        .map(|tokens| tokens.iter().fold(0u128, |bits, (id, _)| bits | 1 << id))
                        .collect()
                });
                Self {
                    named,
                    ias,
                    versions,
                    all_versions,
                    named_bits,
                }
            })
            .collect()
    }

    /// The token id of version `v`, when some alternative names it.
    fn id(&self, v: &str) -> Option<usize> {
        self.named.iter().position(|n| n == v)
    }

    /// Does alternative `i` carry every running version the activity names, and with the
    /// running implementations? `ids`: `(token id, implementation)` of the placements whose
    /// version the activity names ([`ActivityTokens::running_ids`]), indices into `running`.
    fn carries(
        &self,
        i: usize,
        ids: &[(usize, usize)],
        running: &[PlacementRecord],
    ) -> (bool, bool) {
        let mut versions = true;
        let mut exact = true;
        for (id, k) in ids {
            let imp = running[*k].implementation.as_str();
            match self.ias[i].iter().find(|(t, _)| t == id) {
                None => {
                    versions = false;
                    exact = false;
                }
                Some((_, ti)) => exact &= ti.as_deref().is_none_or(|ti| ti == imp),
            }
        }
        (versions, exact)
    }

    /// The placements whose version the activity names, as `(token id, placement index)`.
    fn running_ids(&self, running: &[PlacementRecord], out: &mut Vec<(usize, usize)>) {
        out.clear();
        out.extend(
            running
                .iter()
                .enumerate()
                .filter_map(|(k, p)| Some((self.id(&p.version)?, k))),
        );
    }
}

impl Guarantee {
    /// True when a row of the history already holds the plan in force from activity `at` on.
    fn in_history(&self, at: usize) -> bool {
        let p = &self.spec.problem;
        self.rows.iter().any(|row| {
            row.from_activity <= at
                && (at..p.activities.len()).all(|j| {
                    row.cells.get(j).and_then(Option::as_deref)
                        == Some(p.activities[j].ias[self.choice[j]].name.as_str())
                })
        })
    }

    /// True when alternative `i` of activity `at`, with the plan for the other activities,
    /// meets every goal from the progress last watched and uses no failed resource.
    fn alternative_feasible(&mut self, at: usize, i: usize) -> bool {
        let p = &self.spec.problem;
        let sc = &mut self.scratch;
        if p.activities[at].ias[i]
            .resources
            .iter()
            .any(|r| sc.failed.contains(r))
        {
            return false;
        }
        // The margins of the plan with this alternative swapped in, goal by goal; the check
        // remembers per goal which costs hold (exact: see `panorama::SwapCheck`). The callers
        // reset it when they start asking about an activity.
        sc.swap.fits(p, &self.choice, &sc.m, at, i)
    }

    /// The versions (`V3`, `zone_t`: tokens with an implementation) offered by some alternative
    /// of activity `at` of which no alternative meets the goals, into `out`. Empty when no
    /// alternative at all is feasible: that is the guarantee's infeasibility, which caps
    /// `P_battery` instead.
    pub fn versions_without_alternative(&mut self, at: usize, out: &mut Vec<String>) {
        out.clear();
        let n = self.spec.problem.activities.len();
        if at >= n {
            return;
        }
        let n_ias = self.spec.problem.activities[at].ias.len();
        let n_tokens = self.tokens[at].named.len();
        self.scratch.swap.reset(self.spec.problem.goals.len());
        if self.tokens[at].versions.is_some() {
            // Bits per token id: the same walk as below, a word per alternative.
            let (mut feasible, mut offered) = (0u128, 0u128);
            let all = self.tokens[at].all_versions;
            for i in 0..n_ias {
                let bits = self.tokens[at].versions.as_ref().map_or(0, |v| v[i]);
                offered |= bits;
                // Feasibility only adds versions: an alternative whose versions are all known
                // feasible already cannot change the answer (exact; most cycles stop early).
                let known = feasible != 0 && bits & !feasible == 0;
                if !known && self.alternative_feasible(at, i) {
                    feasible |= bits | 1 << 127; // the top bit: some alternative is feasible
                }
                // Every version any alternative offers is known feasible: the rest can only
                // offer those again (exact: the answer is already empty).
                if feasible != 0 && all & !feasible == 0 {
                    offered = all;
                    break;
                }
            }
            if feasible != 0 {
                let named = &self.tokens[at].named;
                out.extend(
                    (0..n_tokens)
                        .filter(|&id| offered >> id & 1 == 1 && feasible >> id & 1 == 0)
                        .map(|id| named[id].clone()),
                );
            }
            return;
        }
        // Per token id: some feasible alternative carries it / some alternative offers it with
        // an implementation. Kept between cycles, so a warm cycle allocates nothing.
        let (mut feasible, mut offered) = std::mem::take(&mut self.scratch.version_flags);
        feasible.clear();
        feasible.resize(n_tokens, false);
        offered.clear();
        offered.resize(n_tokens, false);
        let mut any = false;
        for i in 0..n_ias {
            // Feasibility only adds versions: an alternative whose versions are all known
            // feasible already cannot change the answer (exact; most cycles stop early).
            let known = any
                && self.tokens[at].ias[i]
                    .iter()
                    .all(|(id, imp)| imp.is_none() || feasible[*id]);
            let ok = !known && self.alternative_feasible(at, i);
            any |= ok;
            for (id, imp) in &self.tokens[at].ias[i] {
                if imp.is_some() {
                    offered[*id] = true;
                    feasible[*id] |= ok;
                }
            }
        }
        if any {
            let named = &self.tokens[at].named;
            out.extend(
                (0..n_tokens)
                    .filter(|&id| offered[id] && !feasible[id])
                    .map(|id| named[id].clone()),
            );
        }
        self.scratch.version_flags = (feasible, offered);
    }

    /// Bind the plan's cell for activity `at` to what runs (`running`: the placed
    /// `(version, implementation)` pairs). Keeps the cell when it already carries exactly what
    /// runs; otherwise moves it to the most capable feasible alternative carrying the running
    /// versions (when the versions differ) or carrying them with the running implementations
    /// (when only the implementation differs: the planned one did not fit), and writes the
    /// re-allocation into `rec` (margins recomputed for what runs). Placements whose version no
    /// alternative of the activity names (an application the mission file does not allocate)
    /// are ignored. Returns true when the plan changed.
    pub fn follow(
        &mut self,
        at: usize,
        running: &[PlacementRecord],
        rec: &mut GuaranteeRecord,
    ) -> bool {
        if at >= self.spec.problem.activities.len() || rec.infeasible {
            return false;
        }
        let mut ids = std::mem::take(&mut self.scratch.running_ids);
        self.tokens[at].running_ids(running, &mut ids);
        let changed = self.follow_ids(at, &ids, running, rec);
        self.scratch.running_ids = ids;
        changed
    }

    /// [`Guarantee::follow`] with the running versions as token ids.
    fn follow_ids(
        &mut self,
        at: usize,
        ids: &[(usize, usize)],
        running: &[PlacementRecord],
        rec: &mut GuaranteeRecord,
    ) -> bool {
        let (cur_versions, cur_exact) = self.tokens[at].carries(self.choice[at], ids, running);
        if cur_exact {
            return false;
        }
        let want_exact = cur_versions;
        let sel = self.spec.selection;
        let mut best: Option<usize> = None;
        self.scratch.swap.reset(self.spec.problem.goals.len());
        // The running versions' token ids as bits: an alternative not naming all of them carries
        // neither the versions nor the implementations (`carries` would say (false, false)).
        // (Bits only when the activity names fewer than 128 tokens: every id fits.)
        let running_bits = (self.tokens[at].named_bits.as_ref())
            .map(|_| ids.iter().fold(0u128, |bits, &(id, _)| bits | 1 << id));
        for i in 0..self.spec.problem.activities[at].ias.len() {
            let named = self.tokens[at].named_bits.as_ref().map(|b| b[i]);
            if let (Some(running), Some(named)) = (running_bits, named)
                && running & !named != 0
            {
                continue;
            }
            let (v, e) = self.tokens[at].carries(i, ids, running);
            if !(if want_exact { e } else { v }) || !self.alternative_feasible(at, i) {
                continue;
            }
            let ias = &self.spec.problem.activities[at].ias;
            if best.is_none_or(|b| sel.score(&ias[i]) > sel.score(&ias[b])) {
                best = Some(i);
            }
        }
        let Some(b) = best else {
            return false;
        };
        self.choice[at] = b;
        // A re-allocation of this cycle (a negative margin, a failed resource) comes first: one
        // row and one record for the cycle, as the plan now stands (rare: its text allocates).
        let earlier = rec
            .reallocation
            .as_ref()
            .map(|r| (r.trigger, r.reason.clone()));
        let trigger = match &earlier {
            Some((t, _)) => *t,
            None if want_exact => ReallocationTrigger::FollowsPlacement,
            None => ReallocationTrigger::FollowsVersions,
        };
        // Taken out while the record is written (moved back below: no allocation).
        let tokens = std::mem::take(&mut self.tokens);
        let tok = &tokens[at];
        let write = |out: &mut String, p: &panorama::Problem| {
            let ia = &p.activities[at].ias[b].name;
            if let Some((_, r)) = &earlier {
                let _ = write!(out, "{r}; then ");
            }
            if want_exact {
                out.push_str("the planned implementation did not fit, ");
            } else {
                out.push_str("the models run ");
            }
            let mut first = true;
            for r in running.iter().filter(|r| tok.id(&r.version).is_some()) {
                let sep = if first { "" } else { " " };
                let _ = write!(out, "{sep}{}.{}", r.version, r.implementation);
                first = false;
            }
            if want_exact {
                let _ = write!(out, " runs: the plan follows what runs ({ia})");
            } else {
                let _ = write!(
                    out,
                    ": the plan follows with its most capable feasible alternative ({ia})"
                );
            }
        };
        self.write_reallocation(at, trigger, rec, write);
        self.tokens = tokens;
        let p = &self.spec.problem;
        if let Some(r) = &rec.reallocation {
            super::named_into(&p.goals, &self.scratch.alt.margin, &mut rec.margins);
            if earlier.is_some() {
                self.rows.pop();
                let reason = r.reason.clone();
                self.push_row(at, &reason);
            } else {
                // A version flipping back and forth returns to allocations already in the
                // history: counted, not added again (the history stays bounded).
                if !self.in_history(at) {
                    let reason = r.reason.clone();
                    self.push_row(at, &reason);
                }
                self.reallocations += 1;
            }
        }
        true
    }
}
