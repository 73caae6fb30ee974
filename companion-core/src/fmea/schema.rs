//! The FMEA file format (params/health/*.toml) as serde types; docs/params/health.md describes it.

use serde::Deserialize;
use std::collections::BTreeMap;

/// One health manager file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HmFile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Rows of the FMEA table (paper Table 1).
    #[serde(default)]
    pub fmea: Vec<FmeaRow>,
    /// Per-node settings: states, rule parameters, CPT overrides, and nodes outside the FMEA rows.
    #[serde(default)]
    pub node: BTreeMap<String, NodeSpec>,
    /// Named probability -> `P(NODE = STATE)` or `1 - P(NODE = STATE)`.
    #[serde(default)]
    pub publish: BTreeMap<String, String>,
    /// Dynamic BN: after each evaluation the posterior of `from` becomes the prior of `to`.
    #[serde(default)]
    pub carry: Vec<Carry>,
}

/// One FMEA row: an error, how it is monitored, where it appears, what corrects it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FmeaRow {
    #[serde(default)]
    pub application: String,
    pub error: String,
    #[serde(default)]
    pub monitors: Vec<String>,
    #[serde(default)]
    pub contexts: Vec<String>,
    #[serde(default)]
    pub solutions: Vec<String>,
    #[serde(default)]
    pub description: String,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Carry {
    pub from: String,
    pub to: String,
}

/// A CPT written flat or as one list per row.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum CptSpec {
    Flat(Vec<f64>),
    Rows(Vec<Vec<f64>>),
}

impl CptSpec {
    pub(super) fn flat(&self) -> Vec<f64> {
        match self {
            CptSpec::Flat(v) => v.clone(),
            CptSpec::Rows(r) => r.iter().flatten().copied().collect(),
        }
    }
}

/// Replace the CPT rows whose parent states match `when` (parents not named match any state).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RowOverride {
    pub when: BTreeMap<String, String>,
    pub p: Vec<f64>,
}

/// One implementation of a version (paper Table 2) as the activation rule sees it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Implementation {
    pub name: String,
    /// Free FPGA tiles it needs.
    #[serde(default)]
    pub tiles: u32,
    /// Highest CPU-load state in which it still fits (hand-written nodes).
    #[serde(default)]
    pub cpu: String,
    /// Fast enough when the performance node demands high speed (hand-written nodes).
    #[serde(default)]
    pub fast: bool,
    /// Compiled from the variant catalogue (`variant` key of the node): CPU share per frame per
    /// second (SW ms / 1000 / cores). With it the node's `cpu` parent is a headroom node whose
    /// states name their lower edges and its `performance` parent a required-rate node whose
    /// states name their upper edges (fps).
    #[serde(default)]
    pub cpu_per_fps: Option<f64>,
    /// Compiled from the catalogue: highest frame rate the implementation reaches.
    #[serde(default)]
    pub max_fps: Option<f64>,
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    pub role: Option<String>,
    pub states: Option<Vec<String>>,
    pub parents: Option<Vec<String>>,
    #[serde(default)]
    pub description: String,
    /// Root prior (context, resource, solution).
    pub prior: Option<Vec<f64>>,
    /// Full CPT, replacing the rule.
    pub cpt: Option<CptSpec>,
    #[serde(default, rename = "override")]
    pub overrides: Vec<RowOverride>,
    // error / monitor_health: noisy-OR.
    pub leak: Option<f64>,
    #[serde(default)]
    pub strength: BTreeMap<String, Vec<f64>>,
    // monitor.
    pub sensitivity: Option<f64>,
    pub false_alarm: Option<f64>,
    pub faulty_alarm: Option<f64>,
    pub health: Option<String>,
    // qos / version.
    pub errors: Option<Vec<String>>,
    pub by_uncorrected: Option<Vec<Vec<f64>>>,
    pub solutions: Option<Vec<String>>,
    pub p_ok: Option<f64>,
    pub miss: Option<f64>,
    pub extra: Option<f64>,
    // activation.
    /// `app/version` in params/variants.toml: the implementations are compiled from it.
    pub variant: Option<String>,
    pub version: Option<String>,
    pub tiles: Option<String>,
    pub cpu: Option<String>,
    pub performance: Option<String>,
    #[serde(default)]
    pub implementations: Vec<Implementation>,
    pub p_fit: Option<f64>,
    pub p_nofit: Option<f64>,
    // import: "manager.node".
    pub from: Option<String>,
    // state (dynamic): transition from `previous`.
    pub previous: Option<String>,
    pub stay: Option<f64>,
    #[serde(default)]
    pub drain: BTreeMap<String, Vec<f64>>,
}
