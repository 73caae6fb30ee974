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

/// One factor multiplied into a clique's potential: a CPT read at the observed slice, or a
/// soft-evidence likelihood.
#[derive(Debug, Clone)]
struct FactorOp {
    clique: usize,
    node: usize,
    soft: bool,
    /// First factor of its clique: assign instead of multiply.
    first: bool,
    /// Clique entry -> CPT index (observed parents at state 0) or state index; length = clique.
    map: usize,
    /// Observed family members and their CPT strides: offset = sum(state * stride).
    observed: Vec<(usize, usize)>,
}

/// A message from a clique to a neighbour: the clique potential times every other incoming
/// message, summed onto the separator.
#[derive(Debug, Clone)]
struct MsgOp {
    clique: usize,
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
    pots: Vec<f64>,
    cliques: Vec<Span>,
    msgs: Vec<f64>,
    bel: Vec<f64>,
    factors: Vec<FactorOp>,
    messages: Vec<MsgOp>,
    beliefs: Vec<BeliefOp>,
    /// Targets that are themselves observed: their posterior is the observed state.
    observed_targets: Vec<usize>,
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
        self.plans[p].run(net, &self.hard, &self.lik, marginals)
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

impl Plan {
    fn compile(net: &Network, card: &[usize], targets: &[usize], key: &[u8]) -> Plan {
        let n = card.len();
        // Ancestral set of the targets and the evidence (everything else is barren).
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
        let free = |i: usize| keep[i] && key[i] != HARD;
        // Factors over the unobserved vars: (node, soft, scope, observed (node, stride)).
        struct Factor {
            node: usize,
            soft: bool,
            scope: Vec<usize>,
            strides: Vec<(usize, usize)>,
            observed: Vec<(usize, usize)>,
        }
        let mut factors = Vec::new();
        for i in (0..n).filter(|&i| keep[i]) {
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
                    node: i,
                    soft: false,
                    scope: strides.iter().map(|&(v, _)| v).collect(),
                    strides,
                    observed,
                });
            }
            if key[i] == SOFT {
                factors.push(Factor {
                    node: i,
                    soft: true,
                    scope: vec![i],
                    strides: vec![(i, 1)],
                    observed: Vec::new(),
                });
            }
        }
        // Connected components of the unobserved vars; keep those holding a target.
        let mut uf: Vec<usize> = (0..n).collect();
        fn find(uf: &mut [usize], mut x: usize) -> usize {
            while uf[x] != x {
                uf[x] = uf[uf[x]];
                x = uf[x];
            }
            x
        }
        for f in &factors {
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
        let mut vars: Vec<usize> = (0..n)
            .filter(|&i| {
                free(i) && {
                    let r = find(&mut uf, i);
                    wanted[r]
                }
            })
            .collect();
        vars.sort_unstable();
        let scopes: Vec<Vec<usize>> = factors.iter().map(|f| f.scope.clone()).collect();
        let (_, cl_vars, tree) = junction_tree(card, &vars, &scopes, false);
        let size = |c: usize| -> usize { cl_vars[c].iter().map(|&v| card[v]).product() };
        let smallest = |need: &[usize]| -> usize {
            (0..cl_vars.len())
                .filter(|&c| need.iter().all(|x| cl_vars[c].contains(x)))
                .min_by_key(|&c| size(c))
                .expect("running intersection: every scope is in some clique")
        };
        let mut plan = Plan {
            key: key.to_vec(),
            maps: Vec::new(),
            pots: Vec::new(),
            cliques: Vec::new(),
            msgs: Vec::new(),
            bel: Vec::new(),
            factors: Vec::new(),
            messages: Vec::new(),
            beliefs: Vec::new(),
            observed_targets: targets.iter().copied().filter(|&t| !free(t)).collect(),
        };
        for c in 0..cl_vars.len() {
            plan.cliques.push(Span {
                off: plan.pots.len(),
                len: size(c),
            });
            // Cliques no factor reaches stay at one.
            plan.pots.extend(std::iter::repeat_n(1.0, size(c)));
        }
        plan.bel = vec![0.0; (0..cl_vars.len()).map(size).max().unwrap_or(0)];
        fn push(maps: &mut Vec<u32>, m: Vec<u32>) -> usize {
            let off = maps.len();
            maps.extend(m);
            off
        }
        let mut ops: Vec<FactorOp> = factors
            .iter()
            .map(|f| {
                let c = smallest(&f.scope);
                let vars = &cl_vars[c];
                let stride: Vec<usize> = vars
                    .iter()
                    .map(|v| {
                        f.strides
                            .iter()
                            .find(|(u, _)| u == v)
                            .map_or(0, |&(_, s)| s)
                    })
                    .collect();
                FactorOp {
                    clique: c,
                    node: f.node,
                    soft: f.soft,
                    first: false,
                    map: push(&mut plan.maps, strided_map(vars, card, &stride)),
                    observed: f.observed.clone(),
                }
            })
            .collect();
        ops.sort_by_key(|f| f.clique);
        for k in 0..ops.len() {
            ops[k].first = k == 0 || ops[k - 1].clique != ops[k].clique;
        }
        plan.factors = ops;
        // Messages towards every clique holding a target, each computed once.
        let mut done: BTreeMap<(usize, usize), Span> = BTreeMap::new();
        #[allow(clippy::too_many_arguments)]
        fn need(
            i: usize,
            j: usize,
            tree: &[Vec<usize>],
            cl_vars: &[Vec<usize>],
            card: &[usize],
            done: &mut BTreeMap<(usize, usize), Span>,
            plan: &mut Plan,
        ) -> Span {
            if let Some(s) = done.get(&(i, j)) {
                return *s;
            }
            let mut ins = Vec::new();
            for &k in tree[i].iter().filter(|&&k| k != j) {
                let s = need(k, i, tree, cl_vars, card, done, plan);
                let sep: Vec<usize> = cl_vars[i]
                    .iter()
                    .copied()
                    .filter(|x| cl_vars[k].contains(x))
                    .collect();
                ins.push((s, push(&mut plan.maps, index_map(&cl_vars[i], &sep, card))));
            }
            let sep: Vec<usize> = cl_vars[i]
                .iter()
                .copied()
                .filter(|x| cl_vars[j].contains(x))
                .collect();
            let len: usize = sep.iter().map(|&v| card[v]).product();
            let out = Span {
                off: plan.msgs.len(),
                len,
            };
            plan.msgs.extend(std::iter::repeat_n(0.0, len));
            let out_map = push(&mut plan.maps, index_map(&cl_vars[i], &sep, card));
            plan.messages.push(MsgOp {
                clique: i,
                out,
                out_map,
                ins,
            });
            done.insert((i, j), out);
            out
        }
        let mut homes: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for &t in targets.iter().filter(|&&t| free(t)) {
            homes.entry(smallest(&[t])).or_default().push(t);
        }
        for (&h, ts) in &homes {
            let mut ins = Vec::new();
            for &k in &tree[h] {
                let s = need(k, h, &tree, &cl_vars, card, &mut done, &mut plan);
                let sep: Vec<usize> = cl_vars[h]
                    .iter()
                    .copied()
                    .filter(|x| cl_vars[k].contains(x))
                    .collect();
                ins.push((s, push(&mut plan.maps, index_map(&cl_vars[h], &sep, card))));
            }
            let outs = ts
                .iter()
                .map(|&t| (t, push(&mut plan.maps, index_map(&cl_vars[h], &[t], card))))
                .collect();
            plan.beliefs.push(BeliefOp {
                clique: h,
                ins,
                outs,
            });
        }
        plan
    }

    fn run(
        &mut self,
        net: &Network,
        hard: &[usize],
        lik: &[Vec<f64>],
        marginals: &mut [Vec<f64>],
    ) -> Result<(), BnError> {
        let maps = &self.maps[..];
        for f in &self.factors {
            let span = self.cliques[f.clique];
            let pot = &mut self.pots[span.off..span.off + span.len];
            let map = &maps[f.map..f.map + span.len];
            let src: &[f64] = if f.soft {
                &lik[f.node]
            } else {
                let off: usize = f.observed.iter().map(|&(v, s)| hard[v] * s).sum();
                &net.nodes()[f.node].cpt[off..]
            };
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
        for m in &self.messages {
            let span = self.cliques[m.clique];
            let pot = span.of(&self.pots);
            let out_map = &maps[m.out_map..m.out_map + span.len];
            let (before, rest) = self.msgs.split_at_mut(m.out.off);
            let out = &mut rest[..m.out.len];
            out.iter_mut().for_each(|x| *x = 0.0);
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
                m.iter_mut().for_each(|x| *x = 0.0);
                for (&x, &j) in bel.iter().zip(&maps[mi..mi + span.len]) {
                    m[j as usize] += x;
                }
                normalise(m)?;
            }
        }
        for &t in &self.observed_targets {
            let m = &mut marginals[t];
            m.iter_mut().for_each(|x| *x = 0.0);
            m[hard[t]] = 1.0;
        }
        Ok(())
    }
}
