//! The FMEA file format (params/health/*.toml) as serde types; docs/params/health.md describes it.
//!
//! A node entry (`[node.NAME]`) is parsed in two steps, since its role may come from the FMEA
//! rows rather than its own `role` key: the file is read with each entry as a TOML table, the
//! roles are derived from the rows and the `role` keys, and each entry is then checked against
//! the keys of its role and parsed as that role's variant of [`NodeSpec`].

use super::err;
use super::roles::{Role, RowNodes, assign_roles};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

/// One health manager file.
#[derive(Debug, Clone)]
pub struct HmFile {
    /// Manager name; imports name a node of it as `MANAGER.NODE`.
    pub name: String,
    /// Free text shown by `companion check`.
    pub description: String,
    /// Rows of the FMEA table (paper Table 1).
    pub fmea: Vec<FmeaRow>,
    /// Per-node settings: states, rule parameters, CPT overrides, and nodes outside the FMEA
    /// rows; each parsed as its role.
    pub node: BTreeMap<String, NodeSpec>,
    /// Named probability -> `P(NODE = STATE)` or `1 - P(NODE = STATE)`.
    pub publish: BTreeMap<String, String>,
    /// Dynamic BN: after each evaluation the posterior of `from` becomes the prior of `to`.
    pub carry: Vec<Carry>,
}

/// The file as TOML gives it: [`HmFile`] with the node entries not yet parsed by role.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct HmToml {
    name: String,
    #[serde(default)]
    description: String,
    #[serde(default)]
    fmea: Vec<FmeaRow>,
    #[serde(default)]
    node: BTreeMap<String, toml::Table>,
    #[serde(default)]
    publish: BTreeMap<String, String>,
    #[serde(default)]
    carry: Vec<Carry>,
}

/// Read one health manager file from `params`: each node entry parsed as its role, a key its
/// role does not take refused with the file, the node and the key.
pub fn read_hm(params: &ParamsFiles, path: &Path) -> Result<HmFile, SpecError> {
    let raw: HmToml = read_toml(params, path)?;
    HmFile::from_toml(path, raw)
}

impl HmFile {
    fn from_toml(file: &Path, raw: HmToml) -> Result<HmFile, SpecError> {
        let mut role_keys = Vec::with_capacity(raw.node.len());
        for (name, table) in &raw.node {
            let key = match table.get("role") {
                None => None,
                Some(toml::Value::String(r)) => Some(r.as_str()),
                Some(v) => {
                    return Err(err(
                        file,
                        format!("node.{name}.role"),
                        format!("`role` must be a string, found {}", v.type_str()),
                    ));
                }
            };
            role_keys.push((name.as_str(), key));
        }
        // The same derivation, with the same errors, as the compiler's (which sees the parsed
        // variants): the FMEA rows first, then the `role` keys, which must agree.
        let (roles, _) = assign_roles(file, raw.fmea.iter().map(FmeaRow::nodes), role_keys)?;
        let mut node = BTreeMap::new();
        for (name, table) in raw.node {
            let role = roles[&name];
            let spec = NodeSpec::from_table(file, &name, role, table)?;
            node.insert(name, spec);
        }
        Ok(HmFile {
            name: raw.name,
            description: raw.description,
            fmea: raw.fmea,
            node,
            publish: raw.publish,
            carry: raw.carry,
        })
    }
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

impl FmeaRow {
    /// The nodes the row names, by role.
    pub(super) fn nodes(&self) -> RowNodes<'_> {
        RowNodes {
            error: &self.error,
            monitors: &self.monitors,
            contexts: &self.contexts,
            solutions: &self.solutions,
        }
    }
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

/// The keys every node takes, whatever its role.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct NodeCommon {
    /// State names; required for roles without default states.
    pub states: Option<Vec<String>>,
    /// Extra parents, appended after the ones the role's rule takes (refused on root roles).
    pub parents: Option<Vec<String>>,
    /// Free text shown by `companion check`.
    #[serde(default)]
    pub description: String,
    /// Full CPT, replacing the rule.
    pub cpt: Option<CptSpec>,
    /// Replacements of individual CPT rows (`override = [{ when, p }]`).
    #[serde(default, rename = "override")]
    pub overrides: Vec<RowOverride>,
}

impl NodeCommon {
    /// Keys of [`NodeCommon`], with `role`, which every entry may carry.
    pub const KEYS: &[&str] = &[
        "role",
        "states",
        "parents",
        "description",
        "cpt",
        "override",
    ];
}

/// An `error` or `monitor_health` node: noisy-OR of its parents.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct NoisyOrNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Noisy-OR leak: probability the node is present with no parent active (default 0.01).
    pub leak: Option<f64>,
    /// Noisy-OR strength of each parent, one per parent state (defaults 0 for the first state, 0.8 for the others).
    #[serde(default)]
    pub strength: BTreeMap<String, Vec<f64>>,
}

impl NoisyOrNode {
    const KEYS: &[&str] = &["leak", "strength"];
}

/// A `monitor` node: alarms on the errors of its FMEA rows.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct MonitorNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Probability a monitor alarms per present error it watches (default 0.95).
    pub sensitivity: Option<f64>,
    /// Probability a healthy monitor alarms with no error present (default 0.05).
    pub false_alarm: Option<f64>,
    /// Probability a faulty monitor alarms (default 0.5).
    pub faulty_alarm: Option<f64>,
    /// Monitor-health node (role `monitor_health`) whose `faulty` state makes this monitor unreliable.
    pub health: Option<String>,
}

impl MonitorNode {
    const KEYS: &[&str] = &["sensitivity", "false_alarm", "faulty_alarm", "health"];
}

/// A `context`, `resource` or `solution` node: a root with a prior.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct RootNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Root prior.
    pub prior: Option<Vec<f64>>,
}

impl RootNode {
    const KEYS: &[&str] = &["prior"];
}

/// An `import` node: a root whose prior is the posterior of a node of another manager.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct ImportNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Prior until the first evaluation replaces it.
    pub prior: Option<Vec<f64>>,
    /// Source of an imported node, `MANAGER.NODE`; its posterior replaces this node's prior each evaluation.
    pub from: Option<String>,
}

impl ImportNode {
    const KEYS: &[&str] = &["prior", "from"];
}

/// A `qos` node: the quality of service by number of uncorrected errors.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct QosNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Error nodes the QoS depends on.
    pub errors: Option<Vec<String>>,
    /// QoS rows (high, medium, low) by number of uncorrected present errors; the last row serves larger counts.
    pub by_uncorrected: Option<Vec<Vec<f64>>>,
}

impl QosNode {
    const KEYS: &[&str] = &["errors", "by_uncorrected"];
}

/// A `version` node (paper Table 2): whether a version of the application should run.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct VersionNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Error nodes the version depends on.
    pub errors: Option<Vec<String>>,
    /// Solutions a version applies; it fixes the errors whose FMEA rows list one of them.
    pub solutions: Option<Vec<String>>,
    /// Probability a version activates when no error it leaves unfixed is present (default 0.95).
    pub p_ok: Option<f64>,
    /// Factor per present error the version does not fix (default 0.1).
    pub miss: Option<f64>,
    /// Factor per solution of the version whose error is absent (default 0.5).
    pub extra: Option<f64>,
}

impl VersionNode {
    const KEYS: &[&str] = &["errors", "solutions", "p_ok", "miss", "extra"];
}

/// An `activation` node (paper section 4.3): whether an activated version can be placed.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct ActivationNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
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
    /// A `fit` node (states `no`, `yes`) saying whether the version fits; given it, the node's
    /// parents are `version` and `fit` and it takes no `tiles`, `cpu` or `performance`.
    pub fit: Option<String>,
}

impl ActivationNode {
    const KEYS: &[&str] = &[
        "variant",
        "version",
        "tiles",
        "cpu",
        "performance",
        "implementations",
        "p_fit",
        "p_nofit",
        "fit",
    ];
}

/// A `fit` node: whether a version of the catalogue (`variant`) can be placed beside what runs
/// now. Its table is the bins' answer (headroom and rate nodes as the catalogue-compiled
/// activation rule reads them): `yes` when every value in the bins fits, `no` when none does,
/// `p_unsure` in between; the decision core observes it with the scheduler's own admission check
/// on its exact numbers, which the bins' answer never contradicts.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct FitNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// `app/version` in params/variants.toml (required: the implementations come from it).
    pub variant: Option<String>,
    /// Free-FPGA-tiles node; its states must be tile counts.
    pub tiles: Option<String>,
    /// CPU-headroom node, states named by their lower edges.
    pub cpu: Option<String>,
    /// Required-rate node, states named by their upper edges (fps).
    pub performance: Option<String>,
    /// Compiled from the catalogue (never written in the file).
    #[serde(skip)]
    pub implementations: Vec<Implementation>,
    /// P(yes) when the bins cannot tell (default 0.5).
    pub p_unsure: Option<f64>,
}

impl FitNode {
    const KEYS: &[&str] = &["variant", "tiles", "cpu", "performance", "p_unsure"];
}

/// A `state` node: a level, dynamic (from `previous`) or a root with a prior.
#[derive(Debug, Clone, Default, Deserialize)]
pub struct StateNode {
    /// The keys every role takes.
    #[serde(flatten)]
    pub common: NodeCommon,
    /// Prior of a root state node (no `previous`, no `parents`).
    pub prior: Option<Vec<f64>>,
    /// Previous-slice node of a dynamic state node.
    pub previous: Option<String>,
    /// Probability of staying at the same level from one slice to the next, before `drain`.
    pub stay: Option<f64>,
    /// Per parent, one factor per parent state multiplying `stay` (a drain pushes the level down).
    #[serde(default)]
    pub drain: BTreeMap<String, Vec<f64>>,
}

impl StateNode {
    const KEYS: &[&str] = &["prior", "previous", "stay", "drain"];
}

/// Per-node settings of a health manager file (`[node.NAME]`), one variant per role with the
/// keys that role takes (docs/params/health.md lists them).
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "role", rename_all = "snake_case")]
pub enum NodeSpec {
    /// Quality of service (paper Figure 4's root).
    Qos(QosNode),
    /// Unobservable error (`U_`).
    Error(NoisyOrNode),
    /// Monitor (`S_`).
    Monitor(MonitorNode),
    /// Appearance context (`A_`).
    Context(RootNode),
    /// Health of a monitor (`H_S_`).
    MonitorHealth(NoisyOrNode),
    /// Solution (`C_`).
    Solution(RootNode),
    /// Version of an application (`C_V*`).
    Version(VersionNode),
    /// Resource (free tiles, CPU).
    Resource(RootNode),
    /// Performance demand; no rule, so it gives its `cpt`.
    Performance(NodeCommon),
    /// Activation of a version (ToActivate/ToDeactivate).
    Activation(ActivationNode),
    /// Whether a version fits beside what runs now (no/yes).
    Fit(FitNode),
    /// Node whose prior comes from another manager.
    Import(ImportNode),
    /// Level, static or dynamic.
    State(StateNode),
}

impl NodeSpec {
    /// The settings of a node of role `r` with no `node` entry: every key at its default.
    pub(super) fn empty(r: Role) -> NodeSpec {
        match r {
            Role::Qos => NodeSpec::Qos(QosNode::default()),
            Role::Error => NodeSpec::Error(NoisyOrNode::default()),
            Role::Monitor => NodeSpec::Monitor(MonitorNode::default()),
            Role::Context => NodeSpec::Context(RootNode::default()),
            Role::MonitorHealth => NodeSpec::MonitorHealth(NoisyOrNode::default()),
            Role::Solution => NodeSpec::Solution(RootNode::default()),
            Role::Version => NodeSpec::Version(VersionNode::default()),
            Role::Resource => NodeSpec::Resource(RootNode::default()),
            Role::Performance => NodeSpec::Performance(NodeCommon::default()),
            Role::Activation => NodeSpec::Activation(ActivationNode::default()),
            Role::Fit => NodeSpec::Fit(FitNode::default()),
            Role::Import => NodeSpec::Import(ImportNode::default()),
            Role::State => NodeSpec::State(StateNode::default()),
        }
    }

    /// The node's role.
    pub(super) fn role(&self) -> Role {
        match self {
            NodeSpec::Qos(_) => Role::Qos,
            NodeSpec::Error(_) => Role::Error,
            NodeSpec::Monitor(_) => Role::Monitor,
            NodeSpec::Context(_) => Role::Context,
            NodeSpec::MonitorHealth(_) => Role::MonitorHealth,
            NodeSpec::Solution(_) => Role::Solution,
            NodeSpec::Version(_) => Role::Version,
            NodeSpec::Resource(_) => Role::Resource,
            NodeSpec::Performance(_) => Role::Performance,
            NodeSpec::Activation(_) => Role::Activation,
            NodeSpec::Fit(_) => Role::Fit,
            NodeSpec::Import(_) => Role::Import,
            NodeSpec::State(_) => Role::State,
        }
    }

    /// The role's name as written in the file (`monitor_health`, ...).
    pub fn role_name(&self) -> &'static str {
        self.role().as_str()
    }

    /// The keys every role takes.
    pub fn common(&self) -> &NodeCommon {
        match self {
            NodeSpec::Qos(x) => &x.common,
            NodeSpec::Error(x) | NodeSpec::MonitorHealth(x) => &x.common,
            NodeSpec::Monitor(x) => &x.common,
            NodeSpec::Context(x) | NodeSpec::Solution(x) | NodeSpec::Resource(x) => &x.common,
            NodeSpec::Version(x) => &x.common,
            NodeSpec::Performance(x) => x,
            NodeSpec::Activation(x) => &x.common,
            NodeSpec::Fit(x) => &x.common,
            NodeSpec::Import(x) => &x.common,
            NodeSpec::State(x) => &x.common,
        }
    }

    /// The keys every role takes, to edit (the fitting example does).
    pub fn common_mut(&mut self) -> &mut NodeCommon {
        match self {
            NodeSpec::Qos(x) => &mut x.common,
            NodeSpec::Error(x) | NodeSpec::MonitorHealth(x) => &mut x.common,
            NodeSpec::Monitor(x) => &mut x.common,
            NodeSpec::Context(x) | NodeSpec::Solution(x) | NodeSpec::Resource(x) => &mut x.common,
            NodeSpec::Version(x) => &mut x.common,
            NodeSpec::Performance(x) => x,
            NodeSpec::Activation(x) => &mut x.common,
            NodeSpec::Fit(x) => &mut x.common,
            NodeSpec::Import(x) => &mut x.common,
            NodeSpec::State(x) => &mut x.common,
        }
    }

    /// The keys a node of role `r` takes besides [`NodeCommon::KEYS`].
    pub(super) fn role_keys(r: Role) -> &'static [&'static str] {
        match r {
            Role::Qos => QosNode::KEYS,
            Role::Error | Role::MonitorHealth => NoisyOrNode::KEYS,
            Role::Monitor => MonitorNode::KEYS,
            Role::Context | Role::Resource | Role::Solution => RootNode::KEYS,
            Role::Version => VersionNode::KEYS,
            Role::Performance => &[],
            Role::Activation => ActivationNode::KEYS,
            Role::Fit => FitNode::KEYS,
            Role::Import => ImportNode::KEYS,
            Role::State => StateNode::KEYS,
        }
    }

    /// Parse the entry `node.NAME` as role `role`: every key must be one the role takes (a
    /// key of another role is a mistake, not a setting to ignore), then serde reads the
    /// variant with `role` set.
    fn from_table(
        file: &Path,
        name: &str,
        role: Role,
        mut table: toml::Table,
    ) -> Result<NodeSpec, SpecError> {
        let own = Self::role_keys(role);
        for key in table.keys() {
            if NodeCommon::KEYS.contains(&key.as_str()) || own.contains(&key.as_str()) {
                continue;
            }
            let takers: Vec<&str> = Role::ALL
                .into_iter()
                .filter(|r| Self::role_keys(*r).contains(&key.as_str()))
                .map(Role::as_str)
                .collect();
            let elsewhere = if takers.is_empty() {
                "no role takes it".to_string()
            } else {
                format!("it belongs to {} nodes", takers.join(", "))
            };
            let mut accepted: Vec<&str> = NodeCommon::KEYS.to_vec();
            accepted.extend(own);
            return Err(err(
                file,
                format!("node.{name}.{key}"),
                format!(
                    "unknown field `{key}` for a {role} node ({elsewhere}); a {role} node takes: {}",
                    accepted.join(", ")
                ),
            ));
        }
        let tag = toml::Value::String(role.as_str().into());
        table.insert("role".into(), tag.clone());
        NodeSpec::deserialize(toml::Value::Table(table.clone())).map_err(|e| {
            // The error does not say which key it is about: find the first key that fails on
            // its own (every key of a role is optional, so each parses alone).
            let key = table.iter().find(|(k, v)| {
                let alone = toml::Table::from_iter([
                    ("role".to_string(), tag.clone()),
                    (k.to_string(), (*v).clone()),
                ]);
                NodeSpec::deserialize(toml::Value::Table(alone)).is_err()
            });
            let entry = match key {
                Some((k, _)) => format!("node.{name}.{k}"),
                None => format!("node.{name}"),
            };
            err(file, entry, e.message().to_string())
        })
    }
}
