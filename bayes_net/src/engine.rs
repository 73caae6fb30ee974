//! The compiled junction tree and Hugin propagation.

use crate::query::Targeted;
use crate::{BnError, Evidence, Finding, Network, NodeId};
use std::collections::BTreeSet;

/// A clique table over `vars` (row-major: last var varies fastest).
#[derive(Debug, Clone, Default)]
struct Clique {
    vars: Vec<usize>,
    /// Product of the CPTs assigned here: the potential before evidence.
    base: Vec<f64>,
    /// Working potential of the current query.
    pot: Vec<f64>,
}

#[derive(Debug, Clone)]
struct Separator {
    /// Tree edge: `child` sends to `parent` in the collect pass.
    child: usize,
    parent: usize,
    /// Clique entry -> separator entry, for the child and the parent clique.
    map_child: Vec<u32>,
    map_parent: Vec<u32>,
    old: Vec<f64>,
    new: Vec<f64>,
}

/// Exact inference over a network compiled once into a junction tree.
///
/// Compilation (in [`Network::compile`]): moralise, triangulate by min-fill (ties: smallest
/// table, then lowest index), keep the maximal cliques, join them by a maximum-weight spanning
/// tree on separator sizes, assign each CPT to a clique holding its family, and precompute every
/// clique-to-separator / clique-to-CPT / clique-to-node index map and every buffer. A query
/// resets the clique potentials from their precomputed bases, multiplies in the findings, and runs
/// one collect and one distribute pass (messages normalised, so no underflow on long chains).
#[derive(Debug, Clone)]
pub struct Engine {
    net: Network,
    card: Vec<usize>,
    order: Vec<usize>,
    cliques: Vec<Clique>,
    /// In breadth-first order from clique 0: collect runs it backwards, distribute forwards.
    seps: Vec<Separator>,
    /// Clique where each node's CPT lives, and clique entry -> CPT index.
    cpt_home: Vec<usize>,
    cpt_map: Vec<Vec<u32>>,
    /// Smallest clique holding each node (evidence goes in, marginals come out), and entry -> state.
    home: Vec<usize>,
    home_map: Vec<Vec<u32>>,
    marginals: Vec<Vec<f64>>,
    /// Targets of [`Engine::query`] and its plans, one per evidence pattern.
    targeted: Targeted,
    /// Bumped by every [`Engine::set_cpt`]: plans recompute their evidence-independent parts.
    cpt_version: u64,
    /// Cliques whose base potential waits for a CPT set since (rebuilt by the next propagate).
    stale_base: Vec<bool>,
    /// Recent [`Engine::query`] answers (see [`Engine::set_query_memo`]).
    memo: QueryMemo,
}

/// Recent targeted queries keyed on their exact inputs: the findings and the CPTs of every node
/// [`Engine::set_cpt`] has changed (the others are as compiled). A query is a pure function of
/// those, so a remembered answer is the one a new run would give, bit for bit.
#[derive(Debug, Clone, Default)]
struct QueryMemo {
    slots: usize,
    entries: Vec<MemoEntry>,
    next: usize,
    /// Nodes whose CPT was set, ascending: their CPTs are part of the key.
    changed: Vec<usize>,
    hits: u64,
}

#[derive(Debug, Clone, Default)]
struct MemoEntry {
    findings: Vec<(NodeId, Finding)>,
    /// The changed nodes' CPTs, concatenated.
    cpts: Vec<f64>,
    /// The targets' posteriors, concatenated in target order.
    marginals: Vec<f64>,
}

fn same_findings(a: &[(NodeId, Finding)], b: &[(NodeId, Finding)]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|((na, fa), (nb, fb))| {
            na == nb
                && match (fa, fb) {
                    (Finding::State(x), Finding::State(y)) => x == y,
                    (Finding::Likelihood(x), Finding::Likelihood(y)) => {
                        x.len() == y.len()
                            && x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits())
                    }
                    _ => false,
                }
        })
}

/// Map each entry of a table over `vars` to its index in a table over `sub` (a subset, any order).
pub(crate) fn index_map(vars: &[usize], sub: &[usize], card: &[usize]) -> Vec<u32> {
    // Stride in the sub-table of each position in `vars` (0 when the var is not in `sub`).
    let mut sub_stride = vec![0usize; vars.len()];
    let mut s = 1;
    for &u in sub.iter().rev() {
        if let Some(pos) = vars.iter().position(|&v| v == u) {
            sub_stride[pos] = s;
        }
        s *= card[u];
    }
    strided_map(vars, card, &sub_stride)
}

/// Map each entry of a table over `vars` (row-major, last var fastest) to
/// `sum(digit[pos] * stride[pos])`: an index into any table that holds some of `vars`.
pub(crate) fn strided_map(vars: &[usize], card: &[usize], stride: &[usize]) -> Vec<u32> {
    let size: usize = vars.iter().map(|&v| card[v]).product();
    let mut out = Vec::with_capacity(size);
    let mut digits = vec![0usize; vars.len()];
    let mut idx = 0usize;
    for _ in 0..size {
        out.push(idx as u32);
        // Increment the mixed-radix counter (last var fastest), updating idx incrementally.
        for pos in (0..vars.len()).rev() {
            digits[pos] += 1;
            idx += stride[pos];
            if digits[pos] < card[vars[pos]] {
                break;
            }
            idx -= stride[pos] * digits[pos];
            digits[pos] = 0;
        }
    }
    out
}

/// Triangulate the interaction graph of `scopes` over `vars` (each scope a set of vars that must
/// share a clique: a CPT family, an evidence factor) by min-fill (ties: smallest table, then lowest
/// index), keep the maximal cliques (vars sorted) and join them by a maximum-weight spanning tree
/// on separator sizes. With `join_empty`, zero-size separators join disconnected parts into one
/// tree; without, the result is a forest. Returns (elimination order, cliques, tree adjacency).
pub(crate) fn junction_tree(
    card: &[usize],
    vars: &[usize],
    scopes: &[Vec<usize>],
    join_empty: bool,
) -> (Vec<usize>, Vec<Vec<usize>>, Vec<Vec<usize>>) {
    let n = card.len();
    // Interaction (moral) graph.
    let mut adj: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); n];
    for fam in scopes {
        for &a in fam {
            for &b in fam {
                if a != b {
                    adj[a].insert(b);
                }
            }
        }
    }
    // Min-fill elimination.
    let mut alive = vec![false; n];
    for &v in vars {
        alive[v] = true;
    }
    let mut order = Vec::with_capacity(vars.len());
    let mut candidates: Vec<Vec<usize>> = Vec::new();
    for _ in 0..vars.len() {
        let mut best: Option<(usize, usize, usize)> = None; // (fill, weight, v)
        for v in (0..n).filter(|&v| alive[v]) {
            let nb: Vec<usize> = adj[v].iter().copied().collect();
            let mut fill = 0;
            for (i, &a) in nb.iter().enumerate() {
                for &b in &nb[i + 1..] {
                    if !adj[a].contains(&b) {
                        fill += 1;
                    }
                }
            }
            let weight = nb.iter().fold(card[v], |w, &u| w.saturating_mul(card[u]));
            if best.is_none_or(|(f, w, _)| (fill, weight) < (f, w)) {
                best = Some((fill, weight, v));
            }
        }
        let (_, _, v) = best.expect("a live node remains");
        let nb: Vec<usize> = adj[v].iter().copied().collect();
        for (i, &a) in nb.iter().enumerate() {
            for &b in &nb[i + 1..] {
                adj[a].insert(b);
                adj[b].insert(a);
            }
        }
        for &a in &nb {
            adj[a].remove(&v);
        }
        alive[v] = false;
        order.push(v);
        let mut c: Vec<usize> = nb;
        c.push(v);
        c.sort_unstable();
        candidates.push(c);
    }
    // Maximal cliques only.
    let mut cl_vars: Vec<Vec<usize>> = Vec::new();
    for (i, c) in candidates.iter().enumerate() {
        let contained = candidates.iter().enumerate().any(|(j, d)| {
            j != i
                && c.len() <= d.len()
                && c.iter().all(|x| d.contains(x))
                && (c.len() < d.len() || j < i)
        });
        if !contained {
            cl_vars.push(c.clone());
        }
    }
    // Maximum-weight spanning tree on separator size (Kruskal).
    let m = cl_vars.len();
    let mut edges = Vec::new();
    for a in 0..m {
        for b in a + 1..m {
            let w = cl_vars[a].iter().filter(|x| cl_vars[b].contains(x)).count();
            if w > 0 || join_empty {
                edges.push((w, a, b));
            }
        }
    }
    edges.sort_by(|x, y| y.0.cmp(&x.0).then((x.1, x.2).cmp(&(y.1, y.2))));
    let mut uf: Vec<usize> = (0..m).collect();
    fn find(uf: &mut [usize], mut x: usize) -> usize {
        while uf[x] != x {
            uf[x] = uf[uf[x]];
            x = uf[x];
        }
        x
    }
    let mut tree: Vec<Vec<usize>> = vec![Vec::new(); m];
    for &(_, a, b) in &edges {
        let (ra, rb) = (find(&mut uf, a), find(&mut uf, b));
        if ra != rb {
            uf[ra] = rb;
            tree[a].push(b);
            tree[b].push(a);
        }
    }
    (order, cl_vars, tree)
}

impl Engine {
    pub(crate) fn new(net: Network) -> Engine {
        let n = net.len();
        let card: Vec<usize> = net.nodes().iter().map(|x| x.states.len()).collect();
        let families: Vec<Vec<usize>> = net
            .nodes()
            .iter()
            .enumerate()
            .map(|(i, x)| x.parents.iter().map(|p| p.0).chain([i]).collect())
            .collect();
        let all: Vec<usize> = (0..n).collect();
        let (order, cl_vars, tree) = junction_tree(&card, &all, &families, true);
        let m = cl_vars.len();
        // Breadth-first from clique 0: separators in BFS order.
        let mut seps = Vec::new();
        let mut seen = vec![false; m];
        let mut queue = std::collections::VecDeque::new();
        if m > 0 {
            seen[0] = true;
            queue.push_back(0);
        }
        while let Some(p) = queue.pop_front() {
            for &c in &tree[p] {
                if !seen[c] {
                    seen[c] = true;
                    queue.push_back(c);
                    let vars: Vec<usize> = cl_vars[c]
                        .iter()
                        .copied()
                        .filter(|x| cl_vars[p].contains(x))
                        .collect();
                    let size: usize = vars.iter().map(|&v| card[v]).product();
                    seps.push(Separator {
                        child: c,
                        parent: p,
                        map_child: index_map(&cl_vars[c], &vars, &card),
                        map_parent: index_map(&cl_vars[p], &vars, &card),
                        old: vec![1.0; size],
                        new: vec![0.0; size],
                    });
                }
            }
        }
        let mut cliques: Vec<Clique> = cl_vars
            .into_iter()
            .map(|vars| {
                let size = vars.iter().map(|&v| card[v]).product();
                Clique {
                    vars,
                    base: vec![1.0; size],
                    pot: vec![1.0; size],
                }
            })
            .collect();
        // Assign CPTs (smallest clique holding the family) and homes (smallest clique holding the node).
        let smallest = |need: &[usize]| -> usize {
            (0..cliques.len())
                .filter(|&c| need.iter().all(|x| cliques[c].vars.contains(x)))
                .min_by_key(|&c| cliques[c].base.len())
                .expect("running intersection: every family is in some clique")
        };
        let mut cpt_home = Vec::with_capacity(n);
        let mut cpt_map = Vec::with_capacity(n);
        let mut home = Vec::with_capacity(n);
        let mut home_map = Vec::with_capacity(n);
        for (i, x) in net.nodes().iter().enumerate() {
            let fam: Vec<usize> = x.parents.iter().map(|p| p.0).chain([i]).collect();
            let c = smallest(&fam);
            cpt_map.push(index_map(&cliques[c].vars, &fam, &card));
            cpt_home.push(c);
            let h = smallest(&[i]);
            home_map.push(index_map(&cliques[h].vars, &[i], &card));
            home.push(h);
        }
        let marginals = card.iter().map(|&k| vec![0.0; k]).collect();
        let mut e = Engine {
            targeted: Targeted::new(Vec::new(), &card),
            cpt_version: 0,
            stale_base: Vec::new(),
            memo: QueryMemo::default(),
            card,
            order,
            cliques: Vec::new(),
            seps,
            cpt_home,
            cpt_map,
            home,
            home_map,
            marginals,
            net,
        };
        for (c, clique) in cliques.iter_mut().enumerate() {
            e.rebuild_base(clique, c);
        }
        e.stale_base = vec![false; cliques.len()];
        e.cliques = cliques;
        e
    }

    fn rebuild_base(&self, clique: &mut Clique, c: usize) {
        clique.base.iter_mut().for_each(|x| *x = 1.0);
        for (i, node) in self.net.nodes().iter().enumerate() {
            if self.cpt_home[i] == c {
                for (x, &j) in clique.base.iter_mut().zip(&self.cpt_map[i]) {
                    *x *= node.cpt[j as usize];
                }
            }
        }
    }

    /// The network this engine was compiled from (CPTs as last set).
    pub fn network(&self) -> &Network {
        &self.net
    }
    /// The min-fill elimination order the cliques came from.
    pub fn elimination_order(&self) -> Vec<NodeId> {
        self.order.iter().map(|&i| NodeId(i)).collect()
    }
    /// Variables of each clique.
    pub fn cliques(&self) -> Vec<Vec<NodeId>> {
        self.cliques
            .iter()
            .map(|c| c.vars.iter().map(|&i| NodeId(i)).collect())
            .collect()
    }
    /// Largest clique table (entries): the cost driver of a query.
    pub fn max_clique_size(&self) -> usize {
        self.cliques.iter().map(|c| c.base.len()).max().unwrap_or(0)
    }

    /// Replace node `id`'s CPT (same shape, validated) without recompiling; used to carry a
    /// dynamic network's belief forward or to load learned parameters.
    pub fn set_cpt(&mut self, id: NodeId, cpt: &[f64]) -> Result<(), BnError> {
        self.net.check_cpt(id, cpt)?;
        self.net.nodes[id.0].cpt.copy_from_slice(cpt);
        self.cpt_version += 1;
        // The junction tree's base potential is rebuilt when propagate needs it: a dynamic
        // network sets CPTs every cycle and mostly answers targeted queries, which read the CPTs.
        self.stale_base[self.cpt_home[id.0]] = true;
        if let Err(k) = self.memo.changed.binary_search(&id.0) {
            // A new part of the key: the remembered answers' keys lack it.
            self.memo.changed.insert(k, id.0);
            self.memo.entries.clear();
            self.memo.next = 0;
        }
        Ok(())
    }

    /// Remember the answers of the last `slots` distinct [`Engine::query`] inputs (findings and
    /// changed CPTs, compared bit for bit) and answer a repeat from memory (0, the default: off).
    /// For a network queried with few distinct inputs, such as evidence flapping across a
    /// threshold, every repeat costs a comparison instead of a run.
    pub fn set_query_memo(&mut self, slots: usize) {
        self.memo.slots = slots;
        self.memo.entries.truncate(slots);
        self.memo.next = 0;
    }

    /// Queries answered from the memo so far.
    pub fn query_memo_hits(&self) -> u64 {
        self.memo.hits
    }

    fn rebuild_stale(&mut self) {
        for c in 0..self.cliques.len() {
            if self.stale_base[c] {
                let mut clique = std::mem::take(&mut self.cliques[c]);
                self.rebuild_base(&mut clique, c);
                self.cliques[c] = clique;
                self.stale_base[c] = false;
            }
        }
    }

    fn check_finding(&self, node: NodeId, f: &Finding) -> Result<(), BnError> {
        let Some(x) = self.net.nodes().get(node.0) else {
            return Err(BnError::UnknownNode(node.to_string()));
        };
        match f {
            Finding::State(s) if *s >= x.states.len() => Err(BnError::UnknownState {
                node: x.name.clone(),
                state: format!("#{s}"),
            }),
            Finding::State(_) => Ok(()),
            Finding::Likelihood(l) if l.len() != x.states.len() => Err(BnError::LikelihoodLength {
                node: x.name.clone(),
                expected: x.states.len(),
                got: l.len(),
            }),
            Finding::Likelihood(l) => {
                if l.iter().all(|v| v.is_finite() && *v >= 0.0) && l.iter().any(|&v| v > 0.0) {
                    Ok(())
                } else {
                    Err(BnError::InvalidLikelihood {
                        node: x.name.clone(),
                    })
                }
            }
        }
    }

    /// Compute the posterior marginal of every node given `evidence`; read them with
    /// [`Engine::marginal`]. Does not allocate.
    pub fn propagate(&mut self, evidence: &Evidence) -> Result<(), BnError> {
        for (node, f) in &evidence.findings {
            self.check_finding(*node, f)?;
        }
        self.rebuild_stale();
        for c in &mut self.cliques {
            c.pot.copy_from_slice(&c.base);
        }
        for (node, f) in &evidence.findings {
            let h = self.home[node.0];
            let map = &self.home_map[node.0];
            let pot = &mut self.cliques[h].pot;
            match f {
                Finding::State(s) => {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        if j as usize != *s {
                            *x = 0.0;
                        }
                    }
                }
                Finding::Likelihood(l) => {
                    for (x, &j) in pot.iter_mut().zip(map) {
                        *x *= l[j as usize];
                    }
                }
            }
        }
        // Collect: children to parents, deepest first.
        for s in (0..self.seps.len()).rev() {
            let sep = &mut self.seps[s];
            sep.new.iter_mut().for_each(|x| *x = 0.0);
            for (&x, &j) in self.cliques[sep.child].pot.iter().zip(&sep.map_child) {
                sep.new[j as usize] += x;
            }
            let z: f64 = sep.new.iter().sum();
            if z <= 0.0 || !z.is_finite() {
                return Err(BnError::ImpossibleEvidence);
            }
            sep.new.iter_mut().for_each(|x| *x /= z);
            for (x, &j) in self.cliques[sep.parent].pot.iter_mut().zip(&sep.map_parent) {
                *x *= sep.new[j as usize];
            }
            std::mem::swap(&mut sep.old, &mut sep.new);
        }
        if let Some(root) = self.cliques.first_mut() {
            let z: f64 = root.pot.iter().sum();
            if z <= 0.0 || !z.is_finite() {
                return Err(BnError::ImpossibleEvidence);
            }
            root.pot.iter_mut().for_each(|x| *x /= z);
        }
        // Distribute: parents to children, shallowest first.
        for sep in &mut self.seps {
            sep.new.iter_mut().for_each(|x| *x = 0.0);
            for (&x, &j) in self.cliques[sep.parent].pot.iter().zip(&sep.map_parent) {
                sep.new[j as usize] += x;
            }
            for (x, &j) in self.cliques[sep.child].pot.iter_mut().zip(&sep.map_child) {
                let old = sep.old[j as usize];
                *x = if old > 0.0 {
                    *x * sep.new[j as usize] / old
                } else {
                    0.0
                };
            }
        }
        for (i, m) in self.marginals.iter_mut().enumerate() {
            m.iter_mut().for_each(|x| *x = 0.0);
            for (&x, &j) in self.cliques[self.home[i]].pot.iter().zip(&self.home_map[i]) {
                m[j as usize] += x;
            }
            let z: f64 = m.iter().sum();
            if z <= 0.0 || !z.is_finite() {
                return Err(BnError::ImpossibleEvidence);
            }
            m.iter_mut().for_each(|x| *x /= z);
        }
        Ok(())
    }

    /// Posterior marginal of `node` from the last successful [`Engine::propagate`] (the prior
    /// marginal before any query has run is not computed: call `propagate(&Evidence::new())`).
    pub fn marginal(&self, node: NodeId) -> &[f64] {
        &self.marginals[node.0]
    }

    /// Choose the nodes [`Engine::query`] computes posteriors for (the plans cached for the
    /// previous targets are dropped). Duplicates are ignored.
    pub fn set_targets(&mut self, targets: &[NodeId]) -> Result<(), BnError> {
        let mut t = Vec::with_capacity(targets.len());
        for id in targets {
            if id.0 >= self.card.len() {
                return Err(BnError::UnknownNode(id.to_string()));
            }
            if !t.contains(&id.0) {
                t.push(id.0);
            }
        }
        self.targeted = Targeted::new(t, &self.card);
        // Remembered answers are for the old targets.
        self.memo.entries.clear();
        self.memo.next = 0;
        Ok(())
    }

    /// The nodes [`Engine::query`] answers for.
    pub fn targets(&self) -> Vec<NodeId> {
        self.targeted.targets.iter().map(|&i| NodeId(i)).collect()
    }

    /// Number of evidence patterns compiled so far for the current targets (at most 64 are kept).
    pub fn cached_plans(&self) -> usize {
        self.targeted.plans()
    }

    /// Compute the posterior marginal of each target (see [`Engine::set_targets`]) given
    /// `evidence`, and nothing else: read them with [`Engine::marginal`]; the other nodes keep
    /// the marginals of the last [`Engine::propagate`]. The work is planned once per evidence
    /// pattern (which nodes carry hard or soft evidence, not their values): barren nodes pruned,
    /// hard evidence absorbed, parts d-separated from the targets skipped, and only the messages
    /// towards the targets' cliques computed (see the `query` module). A pattern seen before
    /// does not allocate. Evidence of probability zero is reported as
    /// [`BnError::ImpossibleEvidence`] when the zero lies where the targets depend on it; an
    /// impossibility confined to a part d-separated from every target is not detected (use
    /// [`Engine::propagate`] for that check).
    pub fn query(&mut self, evidence: &Evidence) -> Result<(), BnError> {
        for (node, f) in &evidence.findings {
            self.check_finding(*node, f)?;
        }
        if self.memo.slots == 0 {
            return self.targeted.run(
                &self.net,
                &self.card,
                self.cpt_version,
                &evidence.findings,
                &mut self.marginals,
            );
        }
        let nodes = &self.net.nodes;
        let key_cpts = || self.memo.changed.iter().flat_map(|&i| nodes[i].cpt.iter());
        let hit = self.memo.entries.iter().position(|e| {
            same_findings(&e.findings, &evidence.findings)
                && e.cpts.len() == key_cpts().count()
                && e.cpts
                    .iter()
                    .zip(key_cpts())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
        });
        if let Some(k) = hit {
            let mut at = 0;
            for &t in &self.targeted.targets {
                let m = &mut self.marginals[t];
                let len = m.len();
                m.copy_from_slice(&self.memo.entries[k].marginals[at..at + len]);
                at += len;
            }
            self.memo.hits += 1;
            return Ok(());
        }
        self.targeted.run(
            &self.net,
            &self.card,
            self.cpt_version,
            &evidence.findings,
            &mut self.marginals,
        )?;
        let memo = &mut self.memo;
        let k = if memo.entries.len() < memo.slots {
            memo.entries.push(MemoEntry::default());
            memo.entries.len() - 1
        } else {
            let k = memo.next;
            memo.next = (k + 1) % memo.slots;
            k
        };
        let e = &mut memo.entries[k];
        e.findings.clone_from(&evidence.findings);
        e.cpts.clear();
        for &i in &memo.changed {
            e.cpts.extend_from_slice(&self.net.nodes[i].cpt);
        }
        e.marginals.clear();
        for &t in &self.targeted.targets {
            e.marginals.extend_from_slice(&self.marginals[t]);
        }
        Ok(())
    }

    /// Propagate and return one node's posterior.
    pub fn posterior(&mut self, evidence: &Evidence, node: NodeId) -> Result<&[f64], BnError> {
        if node.0 >= self.card.len() {
            return Err(BnError::UnknownNode(node.to_string()));
        }
        self.propagate(evidence)?;
        Ok(&self.marginals[node.0])
    }
}
