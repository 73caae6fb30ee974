//! FMEA tables (params/health/*.toml) compiled into Bayesian networks with the BFM paper's node
//! roles (section 4.2): QoS, `U_` unobservable errors, `S_` monitors, `A_` appearance contexts,
//! `H_S_` monitor health, `C_` solutions, versions, and the resource-aware activation nodes of
//! section 4.3. The format and the default CPT rules are documented in docs/params/health.md.

mod catalogue;
mod compile;
mod nodes;
mod roles;
mod rules;
mod schema;

pub use catalogue::fill_from_catalogue;
pub use compile::compile_hm;
pub use schema::{
    ActivationNode, Carry, CptSpec, FmeaRow, HmFile, Implementation, ImportNode, MonitorNode,
    NodeCommon, NodeSpec, NoisyOrNode, QosNode, RootNode, RowOverride, StateNode, VersionNode,
    read_hm,
};

use crate::spec::SpecError;
use bayes_net::{BnError, Network};
use std::path::{Path, PathBuf};

/// Most nodes (and most FMEA rows) in one health manager. The shipped managers have under 40.
pub const MAX_NODES: usize = 500;
/// Most parents of one BN node. The shipped health managers use at most 6.
pub const MAX_PARENTS: usize = 16;
/// Most probabilities in one node's table (states times the product of its parents' state
/// counts): 2^16 values, 512 KiB, far above the shipped nodes and far below an allocation that
/// could fail.
pub const MAX_CPT_ENTRIES: usize = 1 << 16;
/// Most probabilities in one junction-tree clique table of a health manager (2^20, 8 MiB; the
/// shipped managers' largest is far smaller).
pub const MAX_CLIQUE_ENTRIES: usize = 1 << 20;

/// Node roles, named as in the paper.
pub const ROLES: &[&str] = &[
    "qos",
    "error",
    "monitor",
    "context",
    "monitor_health",
    "solution",
    "version",
    "resource",
    "performance",
    "activation",
    "fit",
    "import",
    "state",
];

/// A compiled node, for display and for wiring imports.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeInfo {
    /// Node name as written in the FMEA file (`U_vibration`, `A_wind`, ...).
    pub name: String,
    /// Role that chose its CPT rule (`error`, `monitor`, `context`, ...).
    pub role: String,
    /// State names, in CPT order.
    pub states: Vec<String>,
    /// Parents in CPT order: the rule's parents, then the node's extra `parents`.
    pub parents: Vec<String>,
    /// Free text from the file.
    pub description: String,
}

/// A published probability: `P(node = state)`, or its complement.
#[derive(Debug, Clone, PartialEq)]
pub struct Publish {
    /// Probability name the MDPs read (`P_track`, `P_V3`, ...).
    pub name: String,
    /// Node whose posterior gives the value.
    pub node: String,
    /// State of that node.
    pub state: String,
    /// True for `1 - P(node = state)`.
    pub complement: bool,
}

impl Publish {
    /// The expression as written in the file: `P(NODE = STATE)` or `1 - P(NODE = STATE)`.
    pub fn expr(&self) -> String {
        let p = format!("P({} = {})", self.node, self.state);
        if self.complement {
            format!("1 - {p}")
        } else {
            p
        }
    }
}

/// An FMEA file compiled to a network, not yet wired to other managers.
#[derive(Debug, Clone)]
pub struct CompiledHm {
    /// Manager name from the file.
    pub name: String,
    /// Free text from the file.
    pub description: String,
    /// File it was compiled from (named in load errors).
    pub file: PathBuf,
    /// Every node of the network, in the file's order.
    pub nodes: Vec<NodeInfo>,
    /// The Bayesian network the nodes compile to.
    pub network: Network,
    /// The probabilities this manager publishes.
    pub publish: Vec<Publish>,
    /// (local import node, source manager, source node).
    pub imports: Vec<(String, String, String)>,
    /// Dynamic-BN links applied after each evaluation.
    pub carry: Vec<Carry>,
}

fn err(file: &Path, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(file, entry, reason)
}

/// Parse `P(NODE = STATE)` or `1 - P(NODE = STATE)`.
pub fn parse_publish(expr: &str) -> Option<(String, String, bool)> {
    let e = expr.trim();
    let (complement, rest) = match e.strip_prefix("1") {
        Some(r) if r.trim_start().starts_with('-') => (true, r.trim_start()[1..].trim()),
        _ => (false, e),
    };
    let inner = rest.strip_prefix("P(")?.strip_suffix(')')?;
    let (n, s) = inner.split_once('=')?;
    let (n, s) = (n.trim(), s.trim());
    if n.is_empty() || s.is_empty() {
        return None;
    }
    Some((n.to_string(), s.to_string(), complement))
}

fn check_prob(file: &Path, entry: &str, v: f64) -> Result<f64, SpecError> {
    if v.is_finite() && (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(err(
            file,
            entry,
            format!("{v} is not a probability in [0, 1]"),
        ))
    }
}

/// Load and compile one FMEA file.
pub fn load_hm(params: &crate::spec::ParamsFiles, path: &Path) -> Result<CompiledHm, SpecError> {
    let spec = read_hm(params, path)?;
    compile_hm(path, &spec)
}

fn bn_to_spec(file: &Path, e: BnError) -> SpecError {
    let (entry, reason) = match &e {
        BnError::CptRow { node, row, .. } => (format!("node.{node}.cpt[{row}]"), e.to_string()),
        BnError::CptSize { node, .. } | BnError::Probability { node, .. } => {
            (format!("node.{node}.cpt"), e.to_string())
        }
        BnError::UnknownParent { node, .. } | BnError::DuplicateParent { node, .. } => {
            (format!("node.{node}.parents"), e.to_string())
        }
        BnError::Cycle(nodes) => (
            format!("node.{}", nodes.first().cloned().unwrap_or_default()),
            e.to_string(),
        ),
        BnError::DuplicateState { node, .. } => (format!("node.{node}.states"), e.to_string()),
        _ => ("-".to_string(), e.to_string()),
    };
    SpecError::new(file, entry, reason)
}

#[cfg(test)]
mod tests;
