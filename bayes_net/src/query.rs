//! Targeted queries: the posteriors of a fixed set of target nodes only, as aGrUM's
//! LazyPropagation answers them.
//!
//! The structure of a query depends only on which nodes carry evidence (its *pattern*), not on
//! the observed values, so each pattern is compiled once into a [`Plan`] and cached:
//! - barren nodes go (only ancestors of the targets and of evidence matter: the CPTs of the others
//!   sum out to one);
//! - hard evidence is absorbed: an observed variable leaves every table, its CPT factors are read
//!   at the observed slice (a precomputed gather map plus an offset `value * stride`);
//! - d-separation: in the interaction graph of what remains (the moral graph of the ancestral set
//!   minus the observed nodes) only the connected components holding a target matter, the others
//!   are constants;
//! - the remaining factors get their own small junction tree (min-fill), and only the
//!   Shafer-Shenoy messages flowing towards the cliques that hold targets are computed.
//!
//! A run is then flat loops over precompiled index maps into buffers owned by the plan: no index
//! arithmetic beyond a gather, no allocation. Messages are normalised (no underflow); posteriors
//! are exact up to rounding. Evidence whose probability is zero is reported when the zero lies in
//! the part of the network the targets depend on; an impossibility confined to a part that is
//! d-separated from every target (so that cannot change their posteriors) is not looked for.

use crate::engine::{index_map, junction_tree, strided_map};
use crate::{BnError, Finding, Network};
use std::collections::BTreeMap;

/// Evidence patterns kept per engine; past this, plans are replaced oldest first.
pub(crate) const MAX_PLANS: usize = 64;

const NONE: u8 = 0;
const HARD: u8 = 1;
const SOFT: u8 = 2;

/// A span of a flat buffer.
#[derive(Debug, Clone, Copy)]
struct Span {
    off: usize,
    len: usize,
}

impl Span {
    fn of<'a, T>(&self, v: &'a [T]) -> &'a [T] {
        &v[self.off..self.off + self.len]
    }
}

/// Targets, cached plans and per-query scratch, owned by an [`crate::Engine`].
#[derive(Debug, Clone)]
pub(crate) struct Targeted {
    pub(crate) targets: Vec<usize>,
    plans: Vec<Plan>,
    /// Next plan to replace once `MAX_PLANS` are cached.
    evict: usize,
    key: Vec<u8>,
    hard: Vec<usize>,
    lik: Vec<Vec<f64>>,
}

impl Targeted {
    pub(crate) fn new(targets: Vec<usize>, card: &[usize]) -> Targeted {
        Targeted {
            targets,
            plans: Vec::new(),
            evict: 0,
            key: vec![NONE; card.len()],
            hard: vec![0; card.len()],
            lik: card.iter().map(|&k| vec![1.0; k]).collect(),
        }
    }

    pub(crate) fn plans(&self) -> usize {
        self.plans.len()
    }

    /// Posteriors of the targets under already-validated `findings`, written into `marginals`.
    pub(crate) fn run(
        &mut self,
        net: &Network,
        card: &[usize],
        version: u64,
        findings: &[(crate::NodeId, Finding)],
        marginals: &mut [Vec<f64>],
    ) -> Result<(), BnError> {
        // Combine the findings per node: hard states must agree; likelihoods multiply; a
        // likelihood on an observed node is a constant (zero at the observed state: impossible).
        self.key.iter_mut().for_each(|k| *k = NONE);
        for (node, f) in findings {
            if let Finding::State(s) = f {
                let i = node.0;
                if self.key[i] == HARD && self.hard[i] != *s {
                    return Err(BnError::ImpossibleEvidence);
                }
                self.key[i] = HARD;
                self.hard[i] = *s;
            }
        }
        for (node, f) in findings {
            if let Finding::Likelihood(l) = f {
                let i = node.0;
                match self.key[i] {
                    HARD if l[self.hard[i]] > 0.0 => {}
                    HARD => return Err(BnError::ImpossibleEvidence),
                    SOFT => self.lik[i].iter_mut().zip(l).for_each(|(x, y)| *x *= y),
                    _ => {
                        self.key[i] = SOFT;
                        self.lik[i].copy_from_slice(l);
                    }
                }
            }
        }
        for (i, k) in self.key.iter().enumerate() {
            if *k == SOFT && self.lik[i].iter().all(|&x| x <= 0.0) {
                return Err(BnError::ImpossibleEvidence);
            }
        }
        let p = match self.plans.iter().position(|p| p.key == self.key) {
            Some(p) => p,
            None => {
                let plan = Plan::compile(net, card, &self.targets, &self.key);
                if self.plans.len() < MAX_PLANS {
                    self.plans.push(plan);
                    self.plans.len() - 1
                } else {
                    let p = self.evict;
                    self.evict = (self.evict + 1) % MAX_PLANS;
                    self.plans[p] = plan;
                    p
                }
            }
        };
        self.plans[p].run(net, version, &self.hard, &self.lik, marginals)
    }
}
/// Where a factor's numbers come from.
#[derive(Debug, Clone, Copy)]
enum Src {
    /// A node's CPT, read at the observed slice.
    Cpt(usize),
    /// A node's combined soft-evidence likelihood.
    Soft(usize),
    /// A table of the plan computed from CPTs alone (a variable eliminated in advance).
    Derived(Span),
}

/// One factor multiplied into a clique's potential.
#[derive(Debug, Clone)]
struct FactorOp {
    clique: usize,
    src: Src,
    /// Clique entry -> source index (observed parents at state 0); length = clique.
    map: usize,
    /// Observed family members and their CPT strides: offset = sum(state * stride).
    observed: Vec<(usize, usize)>,
    /// Depends on evidence values; else computed only when a CPT changes.
    dynamic: bool,
    /// First factor of its clique in its stage: assign instead of multiply.
    first: bool,
    /// A constant factor of a clique that also has evidence-dependent ones: it goes into the
    /// clique's constant base, which the first evidence-dependent factor starts from.
    base: bool,
}

/// A variable summed out in advance: the product of its (constant) factors over their joint
/// scope, summed onto the scope without it.
#[derive(Debug, Clone)]
struct DeriveOp {
    /// (source, union entry -> source index).
    ins: Vec<(Src, usize)>,
    len: usize,
    out: Span,
    out_map: usize,
}

/// A message from a clique to a neighbour: the clique potential times every other incoming
/// message, summed onto the separator.
#[derive(Debug, Clone)]
struct MsgOp {
    clique: usize,
    /// Depends on evidence values (else recomputed only when a CPT changes).
    dynamic: bool,
    out: Span,
    /// Clique entry -> separator entry.
    out_map: usize,
    /// Incoming messages (spans of `msgs`, earlier in the order) and their clique -> separator maps.
    ins: Vec<(Span, usize)>,
}

/// A clique holding targets: its belief (potential times all incoming messages) marginalised onto
/// each target.
#[derive(Debug, Clone)]
struct BeliefOp {
    clique: usize,
    ins: Vec<(Span, usize)>,
    /// (target node, clique entry -> state map).
    outs: Vec<(usize, usize)>,
}

/// The compiled answer to one evidence pattern.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    key: Vec<u8>,
    maps: Vec<u32>,
    derived: Vec<f64>,
    pots: Vec<f64>,
    base: Vec<f64>,
    cliques: Vec<Span>,
    msgs: Vec<f64>,
    bel: Vec<f64>,
    derives: Vec<DeriveOp>,
    /// Constant factors first, then the evidence-dependent ones.
    factors: Vec<FactorOp>,
    messages: Vec<MsgOp>,
    beliefs: Vec<BeliefOp>,
    /// Targets that are themselves observed: their posterior is the observed state.
    observed_targets: Vec<usize>,
    /// The engine's CPT version the constant parts were computed for.
    version: Option<u64>,
}

/// A factor while planning.
struct Factor {
    scope: Vec<usize>,
    /// Stride of each scope var in the source table.
    strides: Vec<(usize, usize)>,
    observed: Vec<(usize, usize)>,
    src: Src,
    /// The factor is a conditional distribution of these vars (sums to one over them whatever
    /// the others); empty when it is not (soft evidence, an observed node's CPT).
    heads: Vec<usize>,
    dynamic: bool,
}

impl Factor {
    fn size(&self, card: &[usize]) -> usize {
        self.scope.iter().map(|&v| card[v]).product()
    }
    fn stride_in(&self, vars: &[usize]) -> Vec<usize> {
        vars.iter()
            .map(|v| {
                self.strides
                    .iter()
                    .find(|(u, _)| u == v)
                    .map_or(0, |&(_, s)| s)
            })
            .collect()
    }
}

fn push(maps: &mut Vec<u32>, m: Vec<u32>) -> usize {
    let off = maps.len();
    maps.extend(m);
    off
}

/// Plan compilation state: which messages exist, which are constant.
struct Builder<'a> {
    card: &'a [usize],
    cl_vars: &'a [Vec<usize>],
    tree: &'a [Vec<usize>],
    in_clique: &'a [Vec<usize>],
    factors: &'a [Factor],
    dynamic: &'a [bool],
    /// Directed message -> its span and whether it depends on evidence values; `None` for a
    /// constant message.
    done: BTreeMap<(usize, usize), Option<(Span, bool)>>,
    used: Vec<bool>,
    plan: Plan,
}

impl Builder<'_> {
    fn sep(&self, i: usize, j: usize) -> Vec<usize> {
        self.cl_vars[i]
            .iter()
            .copied()
            .filter(|x| self.cl_vars[j].contains(x))
            .collect()
    }

    /// Map from clique `i`'s entries to its separator with `j`.
    fn sep_map(&mut self, i: usize, j: usize) -> usize {
        let sep = self.sep(i, j);
        push(
            &mut self.plan.maps,
            index_map(&self.cl_vars[i], &sep, self.card),
        )
    }

    /// The message from clique `i` to neighbour `j`, planned after the ones it needs; `None`
    /// when it is a constant.
    fn need(&mut self, i: usize, j: usize) -> Option<(Span, bool)> {
        if let Some(s) = self.done.get(&(i, j)) {
            return *s;
        }
        let mut ins = Vec::new();
        let mut dynamic = self.dynamic[i];
        let tree = self.tree;
        for &k in tree[i].iter().filter(|&&k| k != j) {
            if let Some((s, d)) = self.need(k, i) {
                dynamic |= d;
                let map = self.sep_map(i, k);
                ins.push((s, map));
            }
        }
        let sep = self.sep(i, j);
        // Conditional distributions of vars all summed out here (and constant messages in):
        // the sum is one, whatever the separator's values.
        let constant = ins.is_empty()
            && self.in_clique[i].iter().all(|&f| {
                let h = &self.factors[f].heads;
                !h.is_empty() && h.iter().all(|x| !sep.contains(x))
            });
        if constant {
            self.done.insert((i, j), None);
            return None;
        }
        let len: usize = sep.iter().map(|&v| self.card[v]).product();
        let out = Span {
            off: self.plan.msgs.len(),
            len,
        };
        self.plan.msgs.extend(std::iter::repeat_n(0.0, len));
        let out_map = self.sep_map(i, j);
        self.plan.messages.push(MsgOp {
            clique: i,
            dynamic,
            out,
            out_map,
            ins,
        });
        self.used[i] = true;
        self.done.insert((i, j), Some((out, dynamic)));
        Some((out, dynamic))
    }
}

/// Normalise `v` in place; a zero or non-finite total means the evidence is impossible.
#[inline]
fn normalise(v: &mut [f64]) -> Result<(), BnError> {
    let z: f64 = v.iter().sum();
    if z <= 0.0 || !z.is_finite() {
        return Err(BnError::ImpossibleEvidence);
    }
    let r = 1.0 / z;
    v.iter_mut().for_each(|x| *x *= r);
    Ok(())
}

/// The numbers of `src` from `off` on.
#[inline]
fn source<'a>(
    src: Src,
    net: &'a Network,
    lik: &'a [Vec<f64>],
    derived: &'a [f64],
    off: usize,
) -> &'a [f64] {
    match src {
        Src::Cpt(i) => &net.nodes()[i].cpt[off..],
        Src::Soft(i) => &lik[i],
        Src::Derived(s) => s.of(derived),
    }
}

/// Row-major strides of `scope` (last var fastest).
fn row_major(scope: &[usize], card: &[usize]) -> Vec<(usize, usize)> {
    let mut s = 1;
    let mut out: Vec<(usize, usize)> = scope
        .iter()
        .rev()
        .map(|&v| {
            let r = (v, s);
            s *= card[v];
            r
        })
        .collect();
    out.reverse();
    out
}

/// The targets, the evidence and their ancestors (everything else is barren).
fn ancestral(net: &Network, targets: &[usize], key: &[u8]) -> Vec<bool> {
    let n = key.len();
    let mut keep = vec![false; n];
    let mut stack: Vec<usize> = targets
        .iter()
        .copied()
        .chain((0..n).filter(|&i| key[i] != NONE))
        .collect();
    while let Some(i) = stack.pop() {
        if !keep[i] {
            keep[i] = true;
            stack.extend(net.nodes()[i].parents.iter().map(|p| p.0));
        }
    }
    keep
}

/// One factor per kept node's family over its unobserved vars (all-observed families only
/// scale P(evidence) and are left out), and one per soft finding.
fn family_factors(net: &Network, card: &[usize], key: &[u8], keep: &[bool]) -> Vec<Factor> {
    let free = |i: usize| keep[i] && key[i] != HARD;
    let mut factors = Vec::new();
    for i in (0..keep.len()).filter(|&i| keep[i]) {
        let fam: Vec<usize> = net.nodes()[i]
            .parents
            .iter()
            .map(|p| p.0)
            .chain([i])
            .collect();
        let mut stride = 1;
        let mut strides = Vec::new();
        let mut observed = Vec::new();
        for &v in fam.iter().rev() {
            if free(v) {
                strides.push((v, stride));
            } else {
                observed.push((v, stride));
            }
            stride *= card[v];
        }
        // All-observed families are constants (they only scale P(evidence)).
        if !strides.is_empty() {
            factors.push(Factor {
                scope: strides.iter().map(|&(v, _)| v).collect(),
                dynamic: !observed.is_empty(),
                heads: if free(i) { vec![i] } else { Vec::new() },
                strides,
                observed,
                src: Src::Cpt(i),
            });
        }
        if key[i] == SOFT {
            factors.push(Factor {
                scope: vec![i],
                strides: vec![(i, 1)],
                observed: Vec::new(),
                src: Src::Soft(i),
                heads: Vec::new(),
                dynamic: true,
            });
        }
    }
    factors
}

/// Connected components of the unobserved vars: the factors and vars of those holding a
/// target are kept (the vars returned in order).
fn keep_target_components(
    factors: &mut Vec<Factor>,
    n: usize,
    targets: &[usize],
    free: &impl Fn(usize) -> bool,
) -> Vec<usize> {
    let mut uf: Vec<usize> = (0..n).collect();
    fn find(uf: &mut [usize], mut x: usize) -> usize {
        while uf[x] != x {
            uf[x] = uf[uf[x]];
            x = uf[x];
        }
        x
    }
    for f in factors.iter() {
        for w in f.scope.windows(2) {
            let (a, b) = (find(&mut uf, w[0]), find(&mut uf, w[1]));
            uf[a] = b;
        }
    }
    let mut wanted = vec![false; n];
    for &t in targets {
        if free(t) {
            let r = find(&mut uf, t);
            wanted[r] = true;
        }
    }
    factors.retain(|f| {
        let r = find(&mut uf, f.scope[0]);
        wanted[r]
    });
    (0..n)
        .filter(|&i| {
            free(i) && {
                let r = find(&mut uf, i);
                wanted[r]
            }
        })
        .collect()
}

/// Sums out in advance the non-target vars all of whose factors are constant, while that
/// makes no table larger than the ones it replaces (the evidence cannot change them); the
/// largest table built on the way (scratch space the query needs).
fn sum_out_constants(
    plan: &mut Plan,
    factors: &mut Vec<Factor>,
    vars: &mut Vec<usize>,
    targets: &[usize],
    card: &[usize],
) -> usize {
    let mut scratch = 0;
    loop {
        let mut best: Option<(usize, usize, Vec<usize>)> = None;
        for &v in vars.iter().filter(|v| !targets.contains(v)) {
            let inv: Vec<&Factor> = factors.iter().filter(|f| f.scope.contains(&v)).collect();
            if inv.iter().any(|f| f.dynamic) {
                continue;
            }
            let mut union: Vec<usize> = inv.iter().flat_map(|f| f.scope.clone()).collect();
            union.sort_unstable();
            union.dedup();
            let size: usize = union.iter().map(|&u| card[u]).product();
            let largest = inv.iter().map(|f| f.size(card)).max().unwrap_or(0);
            if size <= largest && best.as_ref().is_none_or(|b| size < b.0) {
                best = Some((size, v, union));
            }
        }
        let Some((size, v, union)) = best else { break };
        scratch = scratch.max(size);
        let (inv, rest): (Vec<Factor>, Vec<Factor>) = std::mem::take(factors)
            .into_iter()
            .partition(|f| f.scope.contains(&v));
        *factors = rest;
        let scope: Vec<usize> = union.iter().copied().filter(|&u| u != v).collect();
        let len: usize = scope.iter().map(|&u| card[u]).product();
        let out = Span {
            off: plan.derived.len(),
            len,
        };
        plan.derived.extend(std::iter::repeat_n(0.0, len));
        let ins = inv
            .iter()
            .map(|f| {
                let m = strided_map(&union, card, &f.stride_in(&union));
                (f.src, push(&mut plan.maps, m))
            })
            .collect();
        let out_map = push(&mut plan.maps, index_map(&union, &scope, card));
        plan.derives.push(DeriveOp {
            ins,
            len: size,
            out,
            out_map,
        });
        let mut heads: Vec<usize> = inv.iter().flat_map(|f| f.heads.clone()).collect();
        heads.retain(|&h| h != v);
        vars.retain(|&u| u != v);
        if !scope.is_empty() {
            factors.push(Factor {
                strides: row_major(&scope, card),
                scope,
                observed: Vec::new(),
                src: Src::Derived(out),
                heads,
                dynamic: false,
            });
        }
    }
    scratch
}

impl Plan {
    fn compile(net: &Network, card: &[usize], targets: &[usize], key: &[u8]) -> Plan {
        let n = card.len();
        let keep = ancestral(net, targets, key);
        let free = |i: usize| keep[i] && key[i] != HARD;
        let mut factors = family_factors(net, card, key, &keep);
        let mut vars = keep_target_components(&mut factors, n, targets, &free);
        let mut plan = Plan {
            key: key.to_vec(),
            maps: Vec::new(),
            derived: Vec::new(),
            pots: Vec::new(),
            base: Vec::new(),
            cliques: Vec::new(),
            msgs: Vec::new(),
            bel: Vec::new(),
            derives: Vec::new(),
            factors: Vec::new(),
            messages: Vec::new(),
            beliefs: Vec::new(),
            observed_targets: targets.iter().copied().filter(|&t| !free(t)).collect(),
            version: None,
        };
        let scratch = sum_out_constants(&mut plan, &mut factors, &mut vars, targets, card);
        let scopes: Vec<Vec<usize>> = factors.iter().map(|f| f.scope.clone()).collect();
        let (_, cl_vars, tree) = junction_tree(card, &vars, &scopes, false);
        let size = |c: usize| -> usize { cl_vars[c].iter().map(|&v| card[v]).product() };
        let smallest = |need: &[usize]| -> usize {
            (0..cl_vars.len())
                .filter(|&c| need.iter().all(|x| cl_vars[c].contains(x)))
                .min_by_key(|&c| size(c))
                .expect("running intersection: every scope is in some clique")
        };
        let m = cl_vars.len();
        let home: Vec<usize> = factors.iter().map(|f| smallest(&f.scope)).collect();
        let mut in_clique: Vec<Vec<usize>> = vec![Vec::new(); m];
        let mut dynamic = vec![false; m];
        for (k, f) in factors.iter().enumerate() {
            in_clique[home[k]].push(k);
            dynamic[home[k]] |= f.dynamic;
        }
        plan.bel = vec![0.0; (0..m).map(size).max().unwrap_or(0).max(scratch)];
        for c in 0..m {
            plan.cliques.push(Span {
                off: plan.pots.len(),
                len: size(c),
            });
            // Cliques no factor reaches stay at one.
            plan.pots.extend(std::iter::repeat_n(1.0, size(c)));
        }
        // The constant part of an evidence-dependent clique (one where it has none).
        plan.base = plan.pots.clone();
        let mut b = Builder {
            card,
            cl_vars: &cl_vars,
            tree: &tree,
            in_clique: &in_clique,
            factors: &factors,
            dynamic: &dynamic,
            done: BTreeMap::new(),
            used: vec![false; m],
            plan,
        };
        // Beliefs of the cliques holding targets, from the messages towards them.
        let mut homes: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for &t in targets.iter().filter(|&&t| free(t)) {
            homes.entry(smallest(&[t])).or_default().push(t);
        }
        for (&h, ts) in &homes {
            let mut ins = Vec::new();
            for &k in &tree[h] {
                if let Some((s, _)) = b.need(k, h) {
                    let map = b.sep_map(h, k);
                    ins.push((s, map));
                }
            }
            b.used[h] = true;
            let outs = ts
                .iter()
                .map(|&t| {
                    (
                        t,
                        push(&mut b.plan.maps, index_map(&cl_vars[h], &[t], card)),
                    )
                })
                .collect();
            b.plan.beliefs.push(BeliefOp {
                clique: h,
                ins,
                outs,
            });
        }
        // Factors of the cliques whose potential is read: constant ones first.
        let mut ops = Vec::new();
        for stage in [false, true] {
            for c in (0..m).filter(|&c| b.used[c]) {
                let mut first = true;
                for &k in in_clique[c]
                    .iter()
                    .filter(|&&k| factors[k].dynamic == stage)
                {
                    let f = &factors[k];
                    let map = strided_map(&cl_vars[c], card, &f.stride_in(&cl_vars[c]));
                    ops.push(FactorOp {
                        clique: c,
                        src: f.src,
                        map: push(&mut b.plan.maps, map),
                        observed: f.observed.clone(),
                        dynamic: stage,
                        first,
                        base: !stage && dynamic[c],
                    });
                    first = false;
                }
            }
        }
        b.plan.factors = ops;
        b.plan
    }

    /// Recompute what depends on the evidence values (everything when the CPTs changed since
    /// the last run), then the targets' posteriors.
    fn run(
        &mut self,
        net: &Network,
        version: u64,
        hard: &[usize],
        lik: &[Vec<f64>],
        marginals: &mut [Vec<f64>],
    ) -> Result<(), BnError> {
        let all = self.version != Some(version);
        self.version = None;
        let maps = &self.maps[..];
        if all {
            for d in &self.derives {
                let (before, rest) = self.derived.split_at_mut(d.out.off);
                let out = &mut rest[..d.out.len];
                out.fill(0.0);
                let tmp = &mut self.bel[..d.len];
                tmp.fill(1.0);
                for &(src, mi) in &d.ins {
                    let s = source(src, net, lik, before, 0);
                    for (x, &j) in tmp.iter_mut().zip(&maps[mi..mi + d.len]) {
                        *x *= s[j as usize];
                    }
                }
                for (&x, &j) in tmp.iter().zip(&maps[d.out_map..d.out_map + d.len]) {
                    out[j as usize] += x;
                }
            }
        }
        for f in self.factors.iter().filter(|f| all || f.dynamic) {
            let span = self.cliques[f.clique];
            let map = &maps[f.map..f.map + span.len];
            let off: usize = f.observed.iter().map(|&(v, s)| hard[v] * s).sum();
            let src = source(f.src, net, lik, &self.derived, off);
            if f.base {
                let pot = &mut self.base[span.off..span.off + span.len];
                if f.first {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        *x = src[j as usize];
                    }
                } else {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        *x *= src[j as usize];
                    }
                }
            } else if f.first && f.dynamic {
                let base = &self.base[span.off..span.off + span.len];
                let pot = &mut self.pots[span.off..span.off + span.len];
                for ((x, &b), &j) in pot.iter_mut().zip(base).zip(map) {
                    *x = b * src[j as usize];
                }
            } else {
                let pot = &mut self.pots[span.off..span.off + span.len];
                if f.first {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        *x = src[j as usize];
                    }
                } else {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        *x *= src[j as usize];
                    }
                }
            }
        }
        for m in self.messages.iter().filter(|m| all || m.dynamic) {
            let span = self.cliques[m.clique];
            let pot = span.of(&self.pots);
            let out_map = &maps[m.out_map..m.out_map + span.len];
            let (before, rest) = self.msgs.split_at_mut(m.out.off);
            let out = &mut rest[..m.out.len];
            out.fill(0.0);
            match &m.ins[..] {
                [] => {
                    for (&x, &j) in pot.iter().zip(out_map) {
                        out[j as usize] += x;
                    }
                }
                [(s0, m0)] => {
                    let a = s0.of(before);
                    let ma = &maps[*m0..*m0 + span.len];
                    for ((&x, &j), &k) in pot.iter().zip(out_map).zip(ma) {
                        out[j as usize] += x * a[k as usize];
                    }
                }
                ins => {
                    let bel = &mut self.bel[..span.len];
                    bel.copy_from_slice(pot);
                    for (s, mi) in ins {
                        let a = s.of(before);
                        for (x, &k) in bel.iter_mut().zip(&maps[*mi..*mi + span.len]) {
                            *x *= a[k as usize];
                        }
                    }
                    for (&x, &j) in bel.iter().zip(out_map) {
                        out[j as usize] += x;
                    }
                }
            }
            normalise(out)?;
        }
        for b in &self.beliefs {
            let span = self.cliques[b.clique];
            let bel = &mut self.bel[..span.len];
            bel.copy_from_slice(span.of(&self.pots));
            for (s, mi) in &b.ins {
                let a = s.of(&self.msgs);
                for (x, &k) in bel.iter_mut().zip(&maps[*mi..*mi + span.len]) {
                    *x *= a[k as usize];
                }
            }
            for &(t, mi) in &b.outs {
                let m = &mut marginals[t];
                m.fill(0.0);
                for (&x, &j) in bel.iter().zip(&maps[mi..mi + span.len]) {
                    m[j as usize] += x;
                }
                normalise(m)?;
            }
        }
        for &t in &self.observed_targets {
            let m = &mut marginals[t];
            m.fill(0.0);
            m[hard[t]] = 1.0;
        }
        self.version = Some(version);
        Ok(())
    }
}
