//! Discrete Bayesian networks with exact inference compiled once.
//!
//! Build a [`Network`] with [`NetworkBuilder`] (validated: CPT sizes, rows summing to 1, unknown
//! parents, cycles), then [`Network::compile`] it into an [`Engine`]: a junction tree whose
//! cliques come from a min-fill elimination order, with every index map and buffer allocated at
//! compile time. A query ([`Engine::propagate`]) is two Hugin passes over that fixed structure and
//! computes the posterior marginal of every node at once; it does not allocate.
//!
//! CPT layout: row-major over the parents' state combinations (first parent most significant),
//! one row of `states.len()` probabilities per combination. A root node's CPT is its prior.
//!
//! # Layout
//!
//! * `lib.rs`: the model: [`NetworkBuilder`], [`Network`], [`Node`], [`NodeId`], [`Evidence`] with
//!   its [`Finding`]s, and [`BnError`].
//! * `engine`: [`Engine`], the compiled junction tree (min-fill elimination order, clique and
//!   separator tables, index maps) and Hugin propagation over it.
//! * `query`: targeted queries ([`Engine::set_targets`], [`Engine::query`]): one plan per evidence
//!   pattern (barren nodes pruned, hard evidence absorbed, d-separated parts dropped), cached.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;

mod engine;
mod query;
pub use engine::Engine;

/// Tolerance on a CPT row sum.
pub const ROW_TOLERANCE: f64 = 1e-9;

/// Index of a node in its [`Network`] (insertion order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NodeId(pub usize);

impl fmt::Display for NodeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{}", self.0)
    }
}

/// Everything that can be wrong with a network or a query.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BnError {
    /// Two nodes share a name.
    #[error("duplicate node name `{0}`")]
    DuplicateNode(String),
    /// A node has an empty state list.
    #[error("node `{0}` has no states")]
    NoStates(String),
    /// A node lists the same state name twice.
    #[error("node `{node}` lists state `{state}` twice")]
    DuplicateState {
        /// The node.
        node: String,
        /// The repeated state name.
        state: String,
    },
    /// A node names a parent that is not in the network.
    #[error("node `{node}` names unknown parent `{parent}`")]
    UnknownParent {
        /// The child node.
        node: String,
        /// The parent name that matches no node.
        parent: String,
    },
    /// A node lists the same parent twice.
    #[error("node `{node}` lists parent `{parent}` twice")]
    DuplicateParent {
        /// The child node.
        node: String,
        /// The repeated parent.
        parent: String,
    },
    /// The parent links form a cycle; the names are the nodes on it.
    #[error("cycle through nodes {0:?}")]
    Cycle(Vec<String>),
    /// A CPT's length is not rows x states.
    #[error(
        "node `{node}`: CPT has {got} entries, expected {expected} ({rows} rows x {states} states)"
    )]
    CptSize {
        /// The node whose CPT is wrong.
        node: String,
        /// `rows * states`.
        expected: usize,
        /// The CPT's actual length.
        got: usize,
        /// Number of parent state combinations.
        rows: usize,
        /// Number of the node's states.
        states: usize,
    },
    /// A CPT row does not sum to 1 within [`ROW_TOLERANCE`].
    #[error("node `{node}`: CPT row {row} sums to {sum}, not 1")]
    CptRow {
        /// The node whose CPT is wrong.
        node: String,
        /// Index of the row (parent state combination).
        row: usize,
        /// The row's actual sum.
        sum: f64,
    },
    /// A CPT entry is NaN or outside `[0, 1]`.
    #[error("node `{node}`: CPT entry {index} is {value}, not a probability")]
    Probability {
        /// The node whose CPT is wrong.
        node: String,
        /// Index of the entry in the flat CPT.
        index: usize,
        /// The rejected entry.
        value: f64,
    },
    /// A node name or id that is not in the network.
    #[error("unknown node {0}")]
    UnknownNode(String),
    /// A state name (or index) the node does not have.
    #[error("node `{node}` has no state `{state}`")]
    UnknownState {
        /// The node.
        node: String,
        /// The state name or index asked for.
        state: String,
    },
    /// A soft finding's likelihood does not have one entry per state.
    #[error("node `{node}`: likelihood has {got} entries, expected {expected}")]
    LikelihoodLength {
        /// The observed node.
        node: String,
        /// The node's state count.
        expected: usize,
        /// The likelihood's length.
        got: usize,
    },
    /// A soft finding's likelihood is negative, not finite, or all zero.
    #[error("node `{node}`: likelihood must be finite, non-negative and not all zero")]
    InvalidLikelihood {
        /// The observed node.
        node: String,
    },
    /// The findings contradict each other or the model (their joint probability is 0).
    #[error("the evidence has probability zero")]
    ImpossibleEvidence,
}

/// One node: name, state names, parents and CPT.
#[derive(Debug, Clone, PartialEq)]
pub struct Node {
    /// Unique name in the network.
    pub name: String,
    /// State names; a state is referred to by its index here.
    pub states: Vec<String>,
    /// Parents, in CPT order (first parent most significant).
    pub parents: Vec<NodeId>,
    /// Row-major CPT, one row of `states.len()` probabilities per parent combination.
    pub cpt: Vec<f64>,
}

impl Node {
    /// Number of parent state combinations (CPT rows).
    pub fn rows(&self, net: &Network) -> usize {
        self.parents
            .iter()
            .map(|p| net.nodes[p.0].states.len())
            .product()
    }
}

struct PendingNode {
    name: String,
    states: Vec<String>,
    parents: Vec<String>,
    cpt: Vec<f64>,
}

/// Collects nodes in any order; [`NetworkBuilder::build`] resolves and validates them.
#[derive(Default)]
pub struct NetworkBuilder {
    pending: Vec<PendingNode>,
}

impl NetworkBuilder {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Add a node. Parents are named, so they may be added later; the returned id is the
    /// insertion index, which is the node's [`NodeId`] in the built network.
    pub fn add_node<S: AsRef<str>, P: AsRef<str>>(
        &mut self,
        name: &str,
        states: &[S],
        parents: &[P],
        cpt: Vec<f64>,
    ) -> NodeId {
        self.pending.push(PendingNode {
            name: name.to_string(),
            states: states.iter().map(|s| s.as_ref().to_string()).collect(),
            parents: parents.iter().map(|s| s.as_ref().to_string()).collect(),
            cpt,
        });
        NodeId(self.pending.len() - 1)
    }

    /// Resolve parent names and validate every node; see [`BnError`] for what is rejected.
    pub fn build(self) -> Result<Network, BnError> {
        let mut index = BTreeMap::new();
        for (i, p) in self.pending.iter().enumerate() {
            if index.insert(p.name.clone(), i).is_some() {
                return Err(BnError::DuplicateNode(p.name.clone()));
            }
            if p.states.is_empty() {
                return Err(BnError::NoStates(p.name.clone()));
            }
            let mut seen = BTreeSet::new();
            for s in &p.states {
                if !seen.insert(s) {
                    return Err(BnError::DuplicateState {
                        node: p.name.clone(),
                        state: s.clone(),
                    });
                }
            }
        }
        let mut nodes = Vec::with_capacity(self.pending.len());
        for p in &self.pending {
            let mut parents = Vec::with_capacity(p.parents.len());
            for q in &p.parents {
                let id = *index.get(q).ok_or_else(|| BnError::UnknownParent {
                    node: p.name.clone(),
                    parent: q.clone(),
                })?;
                if parents.contains(&NodeId(id)) {
                    return Err(BnError::DuplicateParent {
                        node: p.name.clone(),
                        parent: q.clone(),
                    });
                }
                parents.push(NodeId(id));
            }
            nodes.push(Node {
                name: p.name.clone(),
                states: p.states.clone(),
                parents,
                cpt: p.cpt.clone(),
            });
        }
        let net = Network {
            index,
            order: Vec::new(),
            nodes,
        };
        for i in 0..net.nodes.len() {
            net.check_cpt(NodeId(i), &net.nodes[i].cpt)?;
        }
        let order = net.topological_order()?;
        Ok(Network { order, ..net })
    }
}

/// A validated, acyclic discrete Bayesian network.
#[derive(Debug, Clone, PartialEq)]
pub struct Network {
    nodes: Vec<Node>,
    index: BTreeMap<String, usize>,
    order: Vec<NodeId>,
}

impl Network {
    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }
    /// True for a network without nodes.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    /// All nodes, indexed by [`NodeId`].
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }
    /// The node with id `id` (panics when out of range).
    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.0]
    }
    /// The id of the node named `name`, if any.
    pub fn id(&self, name: &str) -> Option<NodeId> {
        self.index.get(name).map(|&i| NodeId(i))
    }
    /// Parents before children.
    pub fn topological(&self) -> &[NodeId] {
        &self.order
    }
    /// Index of `state` in node `id`.
    pub fn state(&self, id: NodeId, state: &str) -> Result<usize, BnError> {
        let n = self
            .nodes
            .get(id.0)
            .ok_or_else(|| BnError::UnknownNode(id.to_string()))?;
        n.states
            .iter()
            .position(|s| s == state)
            .ok_or_else(|| BnError::UnknownState {
                node: n.name.clone(),
                state: state.to_string(),
            })
    }

    /// Hard evidence from `(node name, state name)` pairs.
    pub fn evidence<'a>(
        &self,
        pairs: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Evidence, BnError> {
        let mut ev = Evidence::new();
        for (n, s) in pairs {
            let id = self
                .id(n)
                .ok_or_else(|| BnError::UnknownNode(n.to_string()))?;
            ev.set_state(id, self.state(id, s)?);
        }
        Ok(ev)
    }

    /// Validate a CPT for node `id` against its shape.
    pub fn check_cpt(&self, id: NodeId, cpt: &[f64]) -> Result<(), BnError> {
        let n = self
            .nodes
            .get(id.0)
            .ok_or_else(|| BnError::UnknownNode(id.to_string()))?;
        let k = n.states.len();
        let rows: usize = n
            .parents
            .iter()
            .map(|p| self.nodes[p.0].states.len())
            .product();
        if cpt.len() != rows * k {
            return Err(BnError::CptSize {
                node: n.name.clone(),
                expected: rows * k,
                got: cpt.len(),
                rows,
                states: k,
            });
        }
        for (i, &v) in cpt.iter().enumerate() {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(BnError::Probability {
                    node: n.name.clone(),
                    index: i,
                    value: v,
                });
            }
        }
        for (r, row) in cpt.chunks(k).enumerate() {
            let sum: f64 = row.iter().sum();
            if (sum - 1.0).abs() > ROW_TOLERANCE {
                return Err(BnError::CptRow {
                    node: n.name.clone(),
                    row: r,
                    sum,
                });
            }
        }
        Ok(())
    }

    fn topological_order(&self) -> Result<Vec<NodeId>, BnError> {
        let n = self.nodes.len();
        let mut indeg: Vec<usize> = self.nodes.iter().map(|x| x.parents.len()).collect();
        let mut children = vec![Vec::new(); n];
        for (i, x) in self.nodes.iter().enumerate() {
            for p in &x.parents {
                children[p.0].push(i);
            }
        }
        let mut ready: Vec<usize> = (0..n).filter(|&i| indeg[i] == 0).rev().collect();
        let mut order = Vec::with_capacity(n);
        while let Some(i) = ready.pop() {
            order.push(NodeId(i));
            for &c in &children[i] {
                indeg[c] -= 1;
                if indeg[c] == 0 {
                    ready.push(c);
                }
            }
        }
        if order.len() < n {
            let cyc = (0..n)
                .filter(|&i| indeg[i] > 0)
                .map(|i| self.nodes[i].name.clone())
                .collect();
            return Err(BnError::Cycle(cyc));
        }
        Ok(order)
    }

    /// Compile the junction tree once (min-fill elimination order); see [`Engine`].
    pub fn compile(&self) -> Engine {
        Engine::new(self.clone())
    }

    /// Entries of the largest clique table [`Network::compile`] would allocate, by the same
    /// elimination, without allocating any table; `None` when the count overflows `usize`.
    /// Lets a loader refuse a network whose tables would not fit in memory.
    pub fn largest_clique_entries(&self) -> Option<usize> {
        let card: Vec<usize> = self.nodes.iter().map(|x| x.states.len()).collect();
        let families: Vec<Vec<usize>> = self
            .nodes
            .iter()
            .enumerate()
            .map(|(i, x)| x.parents.iter().map(|p| p.0).chain([i]).collect())
            .collect();
        let all: Vec<usize> = (0..card.len()).collect();
        let (_, cliques, _) = engine::junction_tree(&card, &all, &families, true);
        cliques.iter().try_fold(0usize, |most, c| {
            let size = c.iter().try_fold(1usize, |a, &v| a.checked_mul(card[v]))?;
            Some(most.max(size))
        })
    }
}

/// What is known about one node.
#[derive(Debug, Clone, PartialEq)]
pub enum Finding {
    /// Hard evidence: the node is in this state.
    State(usize),
    /// Soft (virtual) evidence: a likelihood per state, `P(observation | state)` up to a factor.
    Likelihood(Vec<f64>),
}

/// A set of findings. Several findings on one node multiply.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Evidence {
    /// The findings in the order given; a node may appear more than once.
    pub findings: Vec<(NodeId, Finding)>,
}

impl Evidence {
    /// No findings.
    pub fn new() -> Self {
        Self::default()
    }
    /// Add hard evidence: `node` is in state index `state`.
    pub fn set_state(&mut self, node: NodeId, state: usize) -> &mut Self {
        self.findings.push((node, Finding::State(state)));
        self
    }
    /// Add soft evidence on `node`: a likelihood per state.
    pub fn set_likelihood(&mut self, node: NodeId, likelihood: Vec<f64>) -> &mut Self {
        self.findings.push((node, Finding::Likelihood(likelihood)));
        self
    }
    /// Remove every finding (keeps the allocation).
    pub fn clear(&mut self) {
        self.findings.clear();
    }
    /// True when there is no finding.
    pub fn is_empty(&self) -> bool {
        self.findings.is_empty()
    }
}
