//! FMEA tables (params/health/*.toml) compiled into Bayesian networks with the BFM paper's node
//! roles (section 4.2): QoS, `U_` unobservable errors, `S_` monitors, `A_` appearance contexts,
//! `H_S_` monitor health, `C_` solutions, versions, and the resource-aware activation nodes of
//! section 4.3. The format and the default CPT rules are documented in docs/params/health.md.

use crate::spec::{SpecError, read_toml};
use bayes_net::{BnError, Network, NetworkBuilder};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
    fn flat(&self) -> Vec<f64> {
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

/// Generates one CPT row from the parents' state indices.
type RowRule = Box<dyn FnMut(&[usize]) -> Result<Vec<f64>, SpecError>>;

/// Node roles, named as in the paper.
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
    "import",
    "state",
];

/// A compiled node, for display and for wiring imports.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeInfo {
    pub name: String,
    pub role: String,
    pub states: Vec<String>,
    pub parents: Vec<String>,
    pub description: String,
}

/// A published probability: `P(node = state)`, or its complement.
#[derive(Debug, Clone, PartialEq)]
pub struct Publish {
    pub name: String,
    pub node: String,
    pub state: String,
    pub complement: bool,
}

impl Publish {
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
    pub name: String,
    pub description: String,
    pub file: PathBuf,
    pub nodes: Vec<NodeInfo>,
    pub network: Network,
    pub publish: Vec<Publish>,
    /// (local import node, source manager, source node).
    pub imports: Vec<(String, String, String)>,
    pub carry: Vec<Carry>,
}

fn err(file: &Path, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(file, entry, reason)
}

fn default_states(role: &str) -> Option<Vec<String>> {
    let s: &[&str] = match role {
        "qos" => &["high", "medium", "low"],
        "error" => &["absent", "present"],
        "monitor" => &["ok", "alarm"],
        "monitor_health" => &["ok", "faulty"],
        "solution" | "version" => &["deactivate", "activate"],
        "activation" => &["ToDeactivate", "ToActivate"],
        _ => return None,
    };
    Some(s.iter().map(|x| x.to_string()).collect())
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
    let spec: HmFile = read_toml(params, path)?;
    compile_hm(path, &spec)
}

/// Fill the implementations of every activation node that names a `variant` (`app/version`)
/// from the variant catalogue (params/variants.toml): tiles, CPU share per fps on `cpu_cores`
/// cores, highest rate. A node naming a variant must not list implementations of its own.
pub fn fill_from_catalogue(
    file: &Path,
    spec: &mut HmFile,
    catalogue: &fpga_model::Catalogue,
    cpu_cores: u8,
) -> Result<(), SpecError> {
    for (n, node) in spec.node.iter_mut() {
        let Some(v) = &node.variant else { continue };
        let entry = format!("node.{n}.variant");
        if !node.implementations.is_empty() {
            return Err(err(
                file,
                format!("node.{n}.implementations"),
                "a node naming a `variant` takes its implementations from params/variants.toml",
            ));
        }
        let Some((app, version)) = v.split_once('/') else {
            return Err(err(file, entry, format!("`{v}` is not `app/version`")));
        };
        let impls = catalogue.implementations(app, version);
        if impls.is_empty() {
            return Err(err(
                file,
                entry,
                format!("no variant {app} {version} in params/variants.toml"),
            ));
        }
        node.implementations = impls
            .iter()
            .map(|x| Implementation {
                name: x.implementation.to_string(),
                tiles: u32::from(x.tiles),
                cpu: String::new(),
                fast: false,
                cpu_per_fps: Some(x.cpu_share_at(1.0, cpu_cores)),
                max_fps: Some(x.max_fps()),
            })
            .collect();
    }
    Ok(())
}

/// Compile a parsed FMEA file; `file` names it in errors.
pub fn compile_hm(file: &Path, spec: &HmFile) -> Result<CompiledHm, SpecError> {
    // Compiling is quadratic and more in the node count: refuse absurd files before it starts.
    if spec.node.len() > MAX_NODES || spec.fmea.len() > MAX_NODES {
        return Err(err(
            file,
            "node",
            format!(
                "{} nodes and {} FMEA rows: a health manager has at most {MAX_NODES} of each",
                spec.node.len(),
                spec.fmea.len()
            ),
        ));
    }
    // 1. Roles: from the FMEA rows, then explicit `role` keys (which must agree).
    let mut role: BTreeMap<String, String> = BTreeMap::new();
    let mut order: Vec<String> = Vec::new();
    fn assign(
        file: &Path,
        role: &mut BTreeMap<String, String>,
        order: &mut Vec<String>,
        name: &str,
        r: &str,
        entry: String,
    ) -> Result<(), SpecError> {
        match role.get(name) {
            Some(old) if old != r => Err(err(
                file,
                entry,
                format!("node `{name}` is used as {r} but already as {old}"),
            )),
            Some(_) => Ok(()),
            None => {
                role.insert(name.to_string(), r.to_string());
                order.push(name.to_string());
                Ok(())
            }
        }
    }
    for (i, row) in spec.fmea.iter().enumerate() {
        assign(
            file,
            &mut role,
            &mut order,
            &row.error,
            "error",
            format!("fmea[{i}].error"),
        )?;
        for m in &row.monitors {
            assign(
                file,
                &mut role,
                &mut order,
                m,
                "monitor",
                format!("fmea[{i}].monitors"),
            )?;
        }
        for c in &row.contexts {
            assign(
                file,
                &mut role,
                &mut order,
                c,
                "context",
                format!("fmea[{i}].contexts"),
            )?;
        }
        for s in &row.solutions {
            assign(
                file,
                &mut role,
                &mut order,
                s,
                "solution",
                format!("fmea[{i}].solutions"),
            )?;
        }
    }
    for (name, ns) in &spec.node {
        let entry = format!("node.{name}.role");
        match (&ns.role, role.get(name)) {
            (Some(r), _) if !ROLES.contains(&r.as_str()) => {
                return Err(err(
                    file,
                    entry,
                    format!("unknown role `{r}` (one of {})", ROLES.join(", ")),
                ));
            }
            (Some(r), _) => assign(file, &mut role, &mut order, name, r, entry)?,
            (None, Some(_)) => {}
            (None, None) => {
                return Err(err(file, entry, "node is in no FMEA row and has no `role`"));
            }
        }
    }
    let empty = NodeSpec::default();
    let ns = |n: &str| spec.node.get(n).unwrap_or(&empty);

    // 2. States.
    let mut states: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for n in &order {
        let r = &role[n];
        let s = match (&ns(n).states, default_states(r)) {
            (Some(s), _) => s.clone(),
            (None, Some(d)) => d,
            (None, None) => {
                return Err(err(
                    file,
                    format!("node.{n}.states"),
                    format!("a {r} node must list its states"),
                ));
            }
        };
        if s.is_empty() {
            return Err(err(file, format!("node.{n}.states"), "no states"));
        }
        let binary_rule = matches!(
            r.as_str(),
            "error" | "monitor" | "monitor_health" | "version" | "activation"
        ) && ns(n).cpt.is_none();
        if binary_rule && s.len() != 2 {
            return Err(err(
                file,
                format!("node.{n}.states"),
                format!("the {r} rule needs exactly two states (nominal first), or give `cpt`"),
            ));
        }
        states.insert(n.clone(), s);
    }
    let state_idx = |node: &str, st: &str, entry: String| -> Result<usize, SpecError> {
        let s = states
            .get(node)
            .ok_or_else(|| err(file, entry.clone(), format!("unknown node `{node}`")))?;
        s.iter().position(|x| x == st).ok_or_else(|| {
            err(
                file,
                entry,
                format!(
                    "node `{node}` has no state `{st}` (states: {})",
                    s.join(", ")
                ),
            )
        })
    };
    let known = |node: &str, entry: String| -> Result<(), SpecError> {
        if states.contains_key(node) {
            Ok(())
        } else {
            Err(err(file, entry, format!("unknown node `{node}`")))
        }
    };

    // Errors fixed by each solution, and the solutions of each error.
    let mut solutions_of: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for row in &spec.fmea {
        let e = solutions_of.entry(row.error.as_str()).or_default();
        for s in &row.solutions {
            if !e.contains(s) {
                e.push(s.clone());
            }
        }
    }

    // 3. Parents and CPT per node.
    let mut builder = NetworkBuilder::new();
    let mut infos = Vec::new();
    let mut imports = Vec::new();
    for n in &order {
        let r = role[n].as_str();
        let spec_n = ns(n);
        let k = states[n].len();
        let mut parents: Vec<String> = Vec::new();
        let push = |parents: &mut Vec<String>, p: &str| {
            if !parents.iter().any(|x| x == p) {
                parents.push(p.to_string());
            }
        };
        match r {
            "error" => {
                for row in spec.fmea.iter().filter(|row| &row.error == n) {
                    row.contexts.iter().for_each(|c| push(&mut parents, c));
                }
            }
            "monitor" => {
                for row in spec.fmea.iter().filter(|row| row.monitors.contains(n)) {
                    push(&mut parents, &row.error);
                }
                if let Some(h) = &spec_n.health {
                    known(h, format!("node.{n}.health"))?;
                    push(&mut parents, h);
                }
            }
            "qos" | "version" => {
                let errs = spec_n.errors.as_ref().ok_or_else(|| {
                    err(
                        file,
                        format!("node.{n}.errors"),
                        format!("a {r} node must list `errors`"),
                    )
                })?;
                for e in errs {
                    if role.get(e).map(String::as_str) != Some("error") {
                        return Err(err(
                            file,
                            format!("node.{n}.errors"),
                            format!("`{e}` is not an error node"),
                        ));
                    }
                    push(&mut parents, e);
                }
                if r == "qos" {
                    for e in errs {
                        for s in solutions_of.get(e.as_str()).into_iter().flatten() {
                            push(&mut parents, s);
                        }
                    }
                }
            }
            "activation" => {
                for (key, v) in [
                    ("version", &spec_n.version),
                    ("tiles", &spec_n.tiles),
                    ("cpu", &spec_n.cpu),
                ] {
                    let v = v.as_ref().ok_or_else(|| {
                        err(
                            file,
                            format!("node.{n}.{key}"),
                            format!("an activation node needs `{key}`"),
                        )
                    })?;
                    known(v, format!("node.{n}.{key}"))?;
                    push(&mut parents, v);
                }
                if let Some(p) = &spec_n.performance {
                    known(p, format!("node.{n}.performance"))?;
                    push(&mut parents, p);
                }
            }
            "state" => {
                if let Some(prev) = &spec_n.previous {
                    known(prev, format!("node.{n}.previous"))?;
                    if states[prev] != states[n] {
                        return Err(err(
                            file,
                            format!("node.{n}.previous"),
                            "`previous` must have the same states",
                        ));
                    }
                    push(&mut parents, prev);
                }
            }
            _ => {}
        }
        if let Some(extra) = &spec_n.parents {
            if matches!(r, "context" | "resource" | "solution" | "import") {
                return Err(err(
                    file,
                    format!("node.{n}.parents"),
                    format!("a {r} node is a root"),
                ));
            }
            for p in extra {
                push(&mut parents, p);
            }
        }
        for p in &parents {
            known(p, format!("node.{n}.parents"))?;
        }
        let pstates: Vec<&Vec<String>> = parents.iter().map(|p| &states[p]).collect();
        let entry = |key: &str| format!("node.{n}.{key}");
        if parents.len() > MAX_PARENTS {
            return Err(err(
                file,
                entry("parents"),
                format!(
                    "{} parents: a node has at most {MAX_PARENTS} (its table grows with the \
                     product of the parents' state counts)",
                    parents.len()
                ),
            ));
        }
        // Checked: 70 binary parents would wrap a plain product to a small, accepted size.
        let rows = pstates
            .iter()
            .try_fold(1usize, |acc, s| acc.checked_mul(s.len()))
            .filter(|&r| r.checked_mul(k).is_some_and(|e| e <= MAX_CPT_ENTRIES));
        let Some(rows) = rows else {
            return Err(err(
                file,
                entry("parents"),
                format!(
                    "the table would hold more than {MAX_CPT_ENTRIES} probabilities \
                     ({k} states times the product of {} parents' state counts)",
                    parents.len()
                ),
            ));
        };

        // Row generator: parent state indices -> distribution.
        let mut cpt: Vec<f64> = if let Some(c) = &spec_n.cpt {
            c.flat()
        } else {
            let mut rule: RowRule = match r {
                "state" if spec_n.previous.is_some() => {
                    let stay = check_prob(file, &entry("stay"), spec_n.stay.unwrap_or(0.9))?;
                    let mut drains = Vec::new();
                    for (p, ps) in parents.iter().zip(&pstates).skip(1) {
                        let d = match spec_n.drain.get(p) {
                            Some(d) if d.len() != ps.len() => {
                                return Err(err(
                                    file,
                                    format!("node.{n}.drain.{p}"),
                                    format!("{} values for {} states of `{p}`", d.len(), ps.len()),
                                ));
                            }
                            Some(d) => d.clone(),
                            None => vec![1.0; ps.len()],
                        };
                        for &v in &d {
                            check_prob(file, &format!("node.{n}.drain.{p}"), v)?;
                        }
                        drains.push(d);
                    }
                    for p in spec_n.drain.keys() {
                        if !parents[1..].contains(p) {
                            return Err(err(
                                file,
                                format!("node.{n}.drain.{p}"),
                                format!("`{p}` is not a parent"),
                            ));
                        }
                    }
                    Box::new(move |a| {
                        let s = stay
                            * a[1..]
                                .iter()
                                .zip(&drains)
                                .map(|(&x, d)| d[x])
                                .product::<f64>();
                        let mut row = vec![0.0; k];
                        if a[0] + 1 >= k {
                            row[k - 1] = 1.0;
                        } else {
                            row[a[0]] = s;
                            row[a[0] + 1] = 1.0 - s;
                        }
                        Ok(row)
                    })
                }
                "state" if parents.is_empty() => {
                    let prior = spec_n.prior.clone().ok_or_else(|| {
                        err(
                            file,
                            entry("prior"),
                            "a root state node needs `prior` (or `cpt`)",
                        )
                    })?;
                    Box::new(move |_| Ok(prior.clone()))
                }
                "context" | "resource" | "solution" | "import" => {
                    let prior = match (&spec_n.prior, r) {
                        (Some(p), _) => p.clone(),
                        (None, "solution") => vec![0.9, 0.1],
                        (None, _) => {
                            // Nominal first: 0.9, the rest share 0.1 (uniform for imports, which are
                            // overwritten at every evaluation anyway).
                            if r == "import" || k == 1 {
                                vec![1.0 / k as f64; k]
                            } else {
                                std::iter::once(0.9)
                                    .chain(std::iter::repeat_n(0.1 / (k - 1) as f64, k - 1))
                                    .collect()
                            }
                        }
                    };
                    Box::new(move |_| Ok(prior.clone()))
                }
                "error" | "monitor_health" => {
                    let leak = check_prob(file, &entry("leak"), spec_n.leak.unwrap_or(0.01))?;
                    let mut strengths = Vec::new();
                    for (p, ps) in parents.iter().zip(&pstates) {
                        let s = match spec_n.strength.get(p) {
                            Some(s) if s.len() != ps.len() => {
                                return Err(err(
                                    file,
                                    format!("node.{n}.strength.{p}"),
                                    format!("{} values for {} states of `{p}`", s.len(), ps.len()),
                                ));
                            }
                            Some(s) => s.clone(),
                            None => std::iter::once(0.0)
                                .chain(std::iter::repeat_n(0.8, ps.len() - 1))
                                .collect(),
                        };
                        for &v in &s {
                            check_prob(file, &format!("node.{n}.strength.{p}"), v)?;
                        }
                        strengths.push(s);
                    }
                    for p in spec_n.strength.keys() {
                        if !parents.contains(p) {
                            return Err(err(
                                file,
                                format!("node.{n}.strength.{p}"),
                                format!("`{p}` is not a parent"),
                            ));
                        }
                    }
                    Box::new(move |a| {
                        let off: f64 = (1.0 - leak)
                            * a.iter()
                                .zip(&strengths)
                                .map(|(&s, st)| 1.0 - st[s])
                                .product::<f64>();
                        Ok(vec![off, 1.0 - off])
                    })
                }
                "monitor" => {
                    let sens = check_prob(
                        file,
                        &entry("sensitivity"),
                        spec_n.sensitivity.unwrap_or(0.95),
                    )?;
                    let fa = check_prob(
                        file,
                        &entry("false_alarm"),
                        spec_n.false_alarm.unwrap_or(0.05),
                    )?;
                    let fy = check_prob(
                        file,
                        &entry("faulty_alarm"),
                        spec_n.faulty_alarm.unwrap_or(0.5),
                    )?;
                    let hpos = spec_n
                        .health
                        .as_ref()
                        .and_then(|h| parents.iter().position(|p| p == h));
                    Box::new(move |a| {
                        if let Some(h) = hpos
                            && a[h] != 0
                        {
                            return Ok(vec![1.0 - fy, fy]);
                        }
                        let present = a
                            .iter()
                            .enumerate()
                            .filter(|(i, s)| Some(*i) != hpos && **s != 0)
                            .count();
                        let ok = (1.0 - fa) * (1.0 - sens).powi(present as i32);
                        Ok(vec![ok, 1.0 - ok])
                    })
                }
                "qos" => {
                    let table = spec_n.by_uncorrected.clone().unwrap_or_else(|| {
                        vec![
                            vec![0.90, 0.08, 0.02],
                            vec![0.10, 0.50, 0.40],
                            vec![0.02, 0.18, 0.80],
                        ]
                    });
                    for (i, row) in table.iter().enumerate() {
                        if row.len() != k {
                            return Err(err(
                                file,
                                format!("node.{n}.by_uncorrected[{i}]"),
                                format!("{} values for {k} states", row.len()),
                            ));
                        }
                    }
                    if table.is_empty() {
                        return Err(err(file, entry("by_uncorrected"), "empty table"));
                    }
                    // Error parent position -> positions of its solution parents.
                    let errs = spec_n.errors.clone().unwrap_or_default();
                    let fixes: Vec<(usize, Vec<usize>)> = errs
                        .iter()
                        .map(|e| {
                            let sols = solutions_of.get(e.as_str()).cloned().unwrap_or_default();
                            let ep = parents.iter().position(|p| p == e).unwrap_or(0);
                            (
                                ep,
                                sols.iter()
                                    .filter_map(|s| parents.iter().position(|p| p == s))
                                    .collect(),
                            )
                        })
                        .collect();
                    Box::new(move |a| {
                        let k = fixes
                            .iter()
                            .filter(|(e, sols)| a[*e] != 0 && sols.iter().all(|&s| a[s] == 0))
                            .count();
                        Ok(table[k.min(table.len() - 1)].clone())
                    })
                }
                "version" => {
                    let sols = spec_n.solutions.clone().ok_or_else(|| {
                        err(
                            file,
                            entry("solutions"),
                            "a version node must list `solutions` (may be empty)",
                        )
                    })?;
                    for s in &sols {
                        if role.get(s).map(String::as_str) != Some("solution") {
                            return Err(err(
                                file,
                                entry("solutions"),
                                format!("`{s}` is not a solution node"),
                            ));
                        }
                    }
                    let p_ok = check_prob(file, &entry("p_ok"), spec_n.p_ok.unwrap_or(0.95))?;
                    let miss = check_prob(file, &entry("miss"), spec_n.miss.unwrap_or(0.1))?;
                    let extra = check_prob(file, &entry("extra"), spec_n.extra.unwrap_or(0.5))?;
                    // For each error parent: is it fixed by one of this version's solutions?
                    let fixed: Vec<bool> = parents
                        .iter()
                        .map(|e| {
                            solutions_of
                                .get(e.as_str())
                                .is_some_and(|s| s.iter().any(|x| sols.contains(x)))
                        })
                        .collect();
                    let n_fixable = fixed.iter().filter(|&&f| f).count();
                    Box::new(move |a| {
                        let uncorrected = a
                            .iter()
                            .zip(&fixed)
                            .filter(|(s, f)| **s != 0 && !**f)
                            .count();
                        let used = a
                            .iter()
                            .zip(&fixed)
                            .filter(|(s, f)| **s != 0 && **f)
                            .count();
                        // Solutions running for an error that is absent cost resources for nothing.
                        let unneeded = n_fixable - used;
                        let p = p_ok * miss.powi(uncorrected as i32) * extra.powi(unneeded as i32);
                        Ok(vec![1.0 - p, p])
                    })
                }
                "activation" => {
                    let p_fit = check_prob(file, &entry("p_fit"), spec_n.p_fit.unwrap_or(1.0))?;
                    let p_nofit =
                        check_prob(file, &entry("p_nofit"), spec_n.p_nofit.unwrap_or(0.05))?;
                    if spec_n.implementations.is_empty() {
                        return Err(err(
                            file,
                            entry("implementations"),
                            "an activation node needs implementations (or a `variant` of params/variants.toml)",
                        ));
                    }
                    let version_on = 1usize; // `activate` is the second state of a version node.
                    let tiles_node = spec_n.tiles.clone().unwrap_or_default();
                    let cpu_node = spec_n.cpu.clone().unwrap_or_default();
                    let tile_counts: Vec<u32> = states[&tiles_node]
                        .iter()
                        .map(|s| s.parse::<u32>())
                        .collect::<Result<_, _>>()
                        .map_err(|_| {
                            err(
                                file,
                                entry("tiles"),
                                format!("states of `{tiles_node}` must be tile counts"),
                            )
                        })?;
                    let numeric = spec_n
                        .implementations
                        .iter()
                        .any(|im| im.cpu_per_fps.is_some());
                    let has_perf = spec_n.performance.is_some();
                    let fits_rule: Box<dyn Fn(u32, usize, usize) -> bool> = if numeric {
                        // Catalogue-compiled: an implementation fits when its tiles are free, it
                        // reaches the highest rate of the required-rate state, and its CPU share
                        // at that rate is within the lowest headroom of the headroom state.
                        let parse = |node: &str, key: &str| -> Result<Vec<f64>, SpecError> {
                            states[node]
                                .iter()
                                .map(|s| s.parse::<f64>().ok().filter(|x| x.is_finite()))
                                .collect::<Option<Vec<f64>>>()
                                .ok_or_else(|| {
                                    err(
                                        file,
                                        entry(key),
                                        format!("states of `{node}` must be numbers"),
                                    )
                                })
                        };
                        let headroom = parse(&cpu_node, "cpu")?;
                        let perf_node = spec_n.performance.clone().ok_or_else(|| {
                            err(
                                file,
                                entry("performance"),
                                "a catalogue-compiled activation node needs a required-rate `performance` node",
                            )
                        })?;
                        let rate = parse(&perf_node, "performance")?;
                        let impls: Vec<(u32, f64, f64)> = spec_n
                            .implementations
                            .iter()
                            .map(|im| {
                                (
                                    im.tiles,
                                    im.cpu_per_fps.unwrap_or(0.0),
                                    im.max_fps.unwrap_or(f64::INFINITY),
                                )
                            })
                            .collect();
                        Box::new(move |free, cpu, perf| {
                            let fps = rate[perf];
                            impls.iter().any(|&(t, per_fps, max_fps)| {
                                let share = per_fps * fps;
                                free >= t
                                    && max_fps * (1.0 + 1e-9) >= fps
                                    && (share <= 0.0 || share <= headroom[cpu] + 1e-9)
                            })
                        })
                    } else {
                        let mut impls = Vec::new();
                        for (i, im) in spec_n.implementations.iter().enumerate() {
                            let c = state_idx(
                                &cpu_node,
                                &im.cpu,
                                format!("node.{n}.implementations[{i}].cpu"),
                            )?;
                            impls.push((im.tiles, c, im.fast));
                        }
                        Box::new(move |free, cpu, perf| {
                            let need_fast = has_perf && perf != 0;
                            impls
                                .iter()
                                .any(|&(t, c, fast)| free >= t && cpu <= c && (fast || !need_fast))
                        })
                    };
                    Box::new(move |a| {
                        if a[0] != version_on {
                            return Ok(vec![1.0, 0.0]);
                        }
                        let perf = if has_perf { a[3] } else { 0 };
                        let fits = fits_rule(tile_counts[a[1]], a[2], perf);
                        let p = if fits { p_fit } else { p_nofit };
                        Ok(vec![1.0 - p, p])
                    })
                }
                _ => {
                    return Err(err(
                        file,
                        entry("cpt"),
                        format!("a {r} node needs an explicit `cpt`"),
                    ));
                }
            };
            let mut cpt = Vec::with_capacity(rows * k);
            let mut a = vec![0usize; parents.len()];
            for _ in 0..rows {
                cpt.extend(rule(&a)?);
                for i in (0..a.len()).rev() {
                    a[i] += 1;
                    if a[i] < pstates[i].len() {
                        break;
                    }
                    a[i] = 0;
                }
            }
            cpt
        };
        // Row overrides.
        for (oi, o) in spec_n.overrides.iter().enumerate() {
            let oe = format!("node.{n}.override[{oi}]");
            if o.p.len() != k {
                return Err(err(
                    file,
                    format!("{oe}.p"),
                    format!("{} values for {k} states", o.p.len()),
                ));
            }
            let mut fixed = Vec::new();
            for (p, s) in &o.when {
                let pos = parents.iter().position(|x| x == p).ok_or_else(|| {
                    err(
                        file,
                        format!("{oe}.when.{p}"),
                        format!("`{p}` is not a parent of `{n}`"),
                    )
                })?;
                fixed.push((pos, state_idx(p, s, format!("{oe}.when.{p}"))?));
            }
            if cpt.len() != rows * k {
                break; // reported as a size error below
            }
            let mut a = vec![0usize; parents.len()];
            for row in 0..rows {
                if fixed.iter().all(|&(pos, s)| a[pos] == s) {
                    cpt[row * k..(row + 1) * k].copy_from_slice(&o.p);
                }
                for i in (0..a.len()).rev() {
                    a[i] += 1;
                    if a[i] < pstates[i].len() {
                        break;
                    }
                    a[i] = 0;
                }
            }
        }
        if r == "import" {
            let from = spec_n.from.as_ref().ok_or_else(|| {
                err(
                    file,
                    entry("from"),
                    "an import node needs `from = \"MANAGER.NODE\"`",
                )
            })?;
            let (m, src) = from
                .split_once('.')
                .ok_or_else(|| err(file, entry("from"), format!("`{from}` is not MANAGER.NODE")))?;
            imports.push((n.clone(), m.to_string(), src.to_string()));
        }
        builder.add_node(n, &states[n], &parents, cpt);
        infos.push(NodeInfo {
            name: n.clone(),
            role: r.to_string(),
            states: states[n].clone(),
            parents: parents.clone(),
            description: spec_n.description.clone(),
        });
    }
    let network = builder.build().map_err(|e| bn_to_spec(file, e))?;
    // Small tables per node can still join into a huge clique table: refuse before compiling.
    match network.largest_clique_entries() {
        Some(n) if n <= MAX_CLIQUE_ENTRIES => {}
        n => {
            return Err(err(
                file,
                "node",
                format!(
                    "inference would need a table of {} probabilities (at most {MAX_CLIQUE_ENTRIES}): \
                     fewer or less connected nodes",
                    n.map_or_else(|| "more than 2^64".to_string(), |n| n.to_string())
                ),
            ));
        }
    }

    let mut publish = Vec::new();
    for (name, expr) in &spec.publish {
        let entry = format!("publish.{name}");
        let (node, state, complement) = parse_publish(expr).ok_or_else(|| {
            err(
                file,
                &entry,
                format!("`{expr}` is not `P(NODE = STATE)` or `1 - P(NODE = STATE)`"),
            )
        })?;
        if !states.contains_key(&node) {
            return Err(err(
                file,
                &entry,
                format!("publishes from missing node `{node}`"),
            ));
        }
        state_idx(&node, &state, entry)?;
        publish.push(Publish {
            name: name.clone(),
            node,
            state,
            complement,
        });
    }
    for (i, c) in spec.carry.iter().enumerate() {
        let e = format!("carry[{i}]");
        let (Some(f), Some(t)) = (network.id(&c.from), network.id(&c.to)) else {
            return Err(err(
                file,
                e,
                format!("unknown node in `{}` -> `{}`", c.from, c.to),
            ));
        };
        if network.node(f).states != network.node(t).states {
            return Err(err(file, e, "`from` and `to` must have the same states"));
        }
        if !network.node(t).parents.is_empty() {
            return Err(err(
                file,
                e,
                format!("`{}` must be a root to receive a carried belief", c.to),
            ));
        }
    }
    Ok(CompiledHm {
        name: spec.name.clone(),
        description: spec.description.clone(),
        file: file.to_path_buf(),
        nodes: infos,
        network,
        publish,
        imports,
        carry: spec.carry.clone(),
    })
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
