//! The FMEA file format (params/health/*.toml) as serde types; docs/params/health.md describes it.

use serde::Deserialize;
use std::collections::BTreeMap;

/// One health manager file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HmFile {
    /// Manager name; imports name a node of it as `MANAGER.NODE`.
    pub name: String,
    /// Free text shown by `companion check`.
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
    /// Application the row belongs to (a label only).
    #[serde(default)]
    pub application: String,
    /// Name of the unobservable error node (role `error`, `U_` prefix).
    pub error: String,
    /// Monitor nodes (role `monitor`, `S_`) that observe this error.
    #[serde(default)]
    pub monitors: Vec<String>,
    /// Appearance-context nodes (role `context`, `A_`) that cause this error; parents of the error.
    #[serde(default)]
    pub contexts: Vec<String>,
    /// Solution nodes (role `solution`, `C_`) that correct this error.
    #[serde(default)]
    pub solutions: Vec<String>,
    /// Free text shown by `companion check`.
    #[serde(default)]
    pub description: String,
}

/// A dynamic-BN link: after each evaluation the posterior of `from` becomes the prior of `to`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Carry {
    /// Node whose posterior is carried over (same states as `to`).
    pub from: String,
    /// Root node whose prior receives that posterior.
    pub to: String,
}

/// A CPT written flat or as one list per row.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum CptSpec {
    /// One list of probabilities, row-major over the parents' state combinations.
    Flat(Vec<f64>),
    /// One list per parent-state combination, in the same row order.
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
    /// Parent node -> state; the rows whose named parents are in these states are replaced.
    pub when: BTreeMap<String, String>,
    /// Replacement row: one probability per state of the node, summing to 1.
    pub p: Vec<f64>,
}

/// One implementation of a version (paper Table 2) as the activation rule sees it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Implementation {
    /// Implementation label (e.g. `HW`, `SW`), shown in the decision record.
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

/// Per-node settings of a health manager file (`[node.NAME]`); which keys apply depends on the role.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    /// Role, when the FMEA rows do not give it (they must agree when both do).
    pub role: Option<String>,
    /// State names; required for roles without default states.
    pub states: Option<Vec<String>>,
    /// Extra parents, appended after the ones the role's rule takes.
    pub parents: Option<Vec<String>>,
    /// Free text shown by `companion check`.
    #[serde(default)]
    pub description: String,
    /// Root prior (context, resource, solution).
    pub prior: Option<Vec<f64>>,
    /// Full CPT, replacing the rule.
    pub cpt: Option<CptSpec>,
    /// Replacements of individual CPT rows (`override = [{ when, p }]`).
    #[serde(default, rename = "override")]
    pub overrides: Vec<RowOverride>,
    // error / monitor_health: noisy-OR.
    /// Noisy-OR leak: probability the node is present with no parent active (default 0.01).
    pub leak: Option<f64>,
    /// Noisy-OR strength of each parent, one per parent state (defaults 0 for the first state, 0.8 for the others).
    #[serde(default)]
    pub strength: BTreeMap<String, Vec<f64>>,
    // monitor.
    /// Probability a monitor alarms per present error it watches (default 0.95).
    pub sensitivity: Option<f64>,
    /// Probability a healthy monitor alarms with no error present (default 0.05).
    pub false_alarm: Option<f64>,
    /// Probability a faulty monitor alarms (default 0.5).
    pub faulty_alarm: Option<f64>,
    /// Monitor-health node (role `monitor_health`) whose `faulty` state makes this monitor unreliable.
    pub health: Option<String>,
    // qos / version.
    /// Error nodes a `qos` or `version` node depends on.
    pub errors: Option<Vec<String>>,
    /// QoS rows (high, medium, low) by number of uncorrected present errors; the last row serves larger counts.
    pub by_uncorrected: Option<Vec<Vec<f64>>>,
    /// Solutions a version applies; it fixes the errors whose FMEA rows list one of them.
    pub solutions: Option<Vec<String>>,
    /// Probability a version activates when no error it leaves unfixed is present (default 0.95).
    pub p_ok: Option<f64>,
    /// Factor per present error the version does not fix (default 0.1).
    pub miss: Option<f64>,
    /// Factor per solution of the version whose error is absent (default 0.5).
    pub extra: Option<f64>,
    // activation.
    /// `app/version` in params/variants.toml: the implementations are compiled from it.
    pub variant: Option<String>,
    /// Version node this activation node gates.
    pub version: Option<String>,
    /// Free-FPGA-tiles node; its states must be tile counts.
    pub tiles: Option<String>,
    /// CPU node: headroom (compiled implementations) or CPU load (hand-written ones).
    pub cpu: Option<String>,
    /// Performance node: required frame rate (compiled) or demanded speed (hand-written).
    pub performance: Option<String>,
    /// Hand-written implementations, when `variant` does not compile them from the catalogue.
    #[serde(default)]
    pub implementations: Vec<Implementation>,
    /// P(ToActivate) when the version is active and some implementation fits (default 1.0).
    pub p_fit: Option<f64>,
    /// P(ToActivate) when the version is active but no implementation fits (default 0.05).
    pub p_nofit: Option<f64>,
    // import: "manager.node".
    /// Source of an imported node, `MANAGER.NODE`; its posterior replaces this node's prior each evaluation.
    pub from: Option<String>,
    // state (dynamic): transition from `previous`.
    /// Previous-slice node of a dynamic state node.
    pub previous: Option<String>,
    /// Probability of staying at the same level from one slice to the next, before `drain`.
    pub stay: Option<f64>,
    /// Per parent, one factor per parent state multiplying `stay` (a drain pushes the level down).
    #[serde(default)]
    pub drain: BTreeMap<String, Vec<f64>>,
}
