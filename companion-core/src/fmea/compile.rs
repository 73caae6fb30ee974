//! An FMEA file compiled to a network: each node's role, states and parents, its table from the
//! rule of its role (rules.rs) with the row overrides, then the shared network assembly and the
//! `publish` and `carry` entries checked against it.

use super::nodes::Hm;
use super::roles::{Role, assign_roles};
use super::rules::{NodeCtx, row_rule};
use super::schema::{ActivationNode, FitNode, FmeaRow, HmFile, ImportNode, MonitorNode, NodeSpec};
use super::{
    CompiledHm, MAX_CLIQUE_ENTRIES, MAX_CPT_ENTRIES, MAX_NODES, MAX_PARENTS, NodeInfo, Publish,
    bn_to_spec, err, parse_publish,
};
use crate::spec::SpecError;
use bayes_net::{Network, NetworkBuilder};
use std::collections::BTreeMap;
use std::path::Path;

/// Compile a parsed FMEA file; `file` names it in errors.
pub fn compile_hm(file: &Path, spec: &HmFile) -> Result<CompiledHm, SpecError> {
    check_size(file, spec)?;
    let node_roles = spec
        .node
        .iter()
        .map(|(n, ns)| (n.as_str(), Some(ns.role().as_str())));
    let (role, order) = assign_roles(file, spec.fmea.iter().map(FmeaRow::nodes), node_roles)?;
    let defaults = role
        .iter()
        .filter(|(n, _)| !spec.node.contains_key(*n))
        .map(|(n, r)| (n.clone(), NodeSpec::empty(*r)))
        .collect();
    let mut hm = Hm {
        file,
        spec,
        role,
        order,
        states: BTreeMap::new(),
        solutions_of: solutions_of(spec),
        defaults,
    };
    hm.states = node_states(&hm)?;

    let mut builder = NetworkBuilder::new();
    let mut infos = Vec::new();
    let mut imports = Vec::new();
    for n in &hm.order {
        let r = hm.role[n];
        let spec_n = hm.node(n);
        let parents = parents_of(&hm, n, r, spec_n)?;
        let cpt = node_table(&hm, n, spec_n, &parents)?;
        if let NodeSpec::Import(import) = spec_n {
            imports.push(import_source(file, n, import)?);
        }
        builder.add_node(n, &hm.states[n], &parents, cpt);
        infos.push(NodeInfo {
            name: n.clone(),
            role: r.to_string(),
            states: hm.states[n].clone(),
            parents,
            description: spec_n.common().description.clone(),
        });
    }
    let network = assemble(file, builder)?;
    let publish = compile_publish(&hm)?;
    check_carry(file, spec, &network)?;
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

/// Compiling is quadratic and more in the node count: refuse absurd files before it starts.
fn check_size(file: &Path, spec: &HmFile) -> Result<(), SpecError> {
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
    Ok(())
}

/// Each node's states: given, or the default of its role.
fn node_states(hm: &Hm) -> Result<BTreeMap<String, Vec<String>>, SpecError> {
    let file = hm.file;
    let mut states: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for n in &hm.order {
        let r = hm.role[n];
        let ns = hm.node(n).common();
        let s = match (&ns.states, r.default_states()) {
            (Some(s), _) => s.clone(),
            (None, Some(d)) => d.iter().map(|x| x.to_string()).collect(),
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
        if r.binary_rule() && ns.cpt.is_none() && s.len() != 2 {
            return Err(err(
                file,
                format!("node.{n}.states"),
                format!("the {r} rule needs exactly two states (nominal first), or give `cpt`"),
            ));
        }
        states.insert(n.clone(), s);
    }
    Ok(states)
}

/// Errors fixed by each solution, and the solutions of each error.
fn solutions_of(spec: &HmFile) -> BTreeMap<&str, Vec<String>> {
    let mut solutions_of: BTreeMap<&str, Vec<String>> = BTreeMap::new();
    for row in &spec.fmea {
        let e = solutions_of.entry(row.error.as_str()).or_default();
        for s in &row.solutions {
            if !e.contains(s) {
                e.push(s.clone());
            }
        }
    }
    solutions_of
}

fn push(parents: &mut Vec<String>, p: &str) {
    if !parents.iter().any(|x| x == p) {
        parents.push(p.to_string());
    }
}

/// A node's parents: those its role implies, then its `parents` key; all must exist.
fn parents_of(hm: &Hm, n: &str, r: Role, spec_n: &NodeSpec) -> Result<Vec<String>, SpecError> {
    let mut parents: Vec<String> = Vec::new();
    match spec_n {
        NodeSpec::Error(_) => {
            for row in hm.spec.fmea.iter().filter(|row| row.error == n) {
                row.contexts.iter().for_each(|c| push(&mut parents, c));
            }
        }
        NodeSpec::Monitor(m) => monitor_parents(hm, n, m, &mut parents)?,
        NodeSpec::Qos(q) => error_parents(hm, n, r, q.errors.as_ref(), &mut parents)?,
        NodeSpec::Version(v) => error_parents(hm, n, r, v.errors.as_ref(), &mut parents)?,
        NodeSpec::Activation(a) => activation_parents(hm, n, a, &mut parents)?,
        NodeSpec::Fit(f) => fit_parents(hm, n, f, &mut parents)?,
        NodeSpec::State(s) => {
            if let Some(prev) = &s.previous {
                hm.known(prev, format!("node.{n}.previous"))?;
                if hm.states[prev] != hm.states[n] {
                    return Err(err(
                        hm.file,
                        format!("node.{n}.previous"),
                        "`previous` must have the same states",
                    ));
                }
                push(&mut parents, prev);
            }
        }
        _ => {}
    }
    if let Some(extra) = &spec_n.common().parents {
        if r.is_root() {
            return Err(err(
                hm.file,
                format!("node.{n}.parents"),
                format!("a {r} node is a root"),
            ));
        }
        for p in extra {
            push(&mut parents, p);
        }
    }
    for p in &parents {
        hm.known(p, format!("node.{n}.parents"))?;
    }
    Ok(parents)
}

/// A monitor watches the errors of its FMEA rows, and its `health` node if it has one.
fn monitor_parents(
    hm: &Hm,
    n: &str,
    spec_n: &MonitorNode,
    parents: &mut Vec<String>,
) -> Result<(), SpecError> {
    for row in hm
        .spec
        .fmea
        .iter()
        .filter(|row| row.monitors.iter().any(|m| m == n))
    {
        push(parents, &row.error);
    }
    if let Some(h) = &spec_n.health {
        hm.known(h, format!("node.{n}.health"))?;
        push(parents, h);
    }
    Ok(())
}

/// A QoS or version node depends on its `errors`; a QoS node also on their solutions.
fn error_parents(
    hm: &Hm,
    n: &str,
    r: Role,
    errors: Option<&Vec<String>>,
    parents: &mut Vec<String>,
) -> Result<(), SpecError> {
    let errs = errors.ok_or_else(|| {
        err(
            hm.file,
            format!("node.{n}.errors"),
            format!("a {r} node must list `errors`"),
        )
    })?;
    for e in errs {
        if !hm.has_role(e, Role::Error) {
            return Err(err(
                hm.file,
                format!("node.{n}.errors"),
                format!("`{e}` is not an error node"),
            ));
        }
        push(parents, e);
    }
    if r == Role::Qos {
        for e in errs {
            for s in hm.solutions_of.get(e.as_str()).into_iter().flatten() {
                push(parents, s);
            }
        }
    }
    Ok(())
}

/// An activation node depends on its version and its `fit` node, or on its version, free
/// tiles, CPU and optionally performance.
fn activation_parents(
    hm: &Hm,
    n: &str,
    spec_n: &ActivationNode,
    parents: &mut Vec<String>,
) -> Result<(), SpecError> {
    if let Some(fit) = &spec_n.fit {
        for (key, v) in [
            ("tiles", &spec_n.tiles),
            ("cpu", &spec_n.cpu),
            ("performance", &spec_n.performance),
        ] {
            if v.is_some() {
                return Err(err(
                    hm.file,
                    format!("node.{n}.{key}"),
                    format!("a node with a `fit` parent reads the room through it, not `{key}`"),
                ));
            }
        }
        let version = spec_n.version.as_ref().ok_or_else(|| {
            err(
                hm.file,
                format!("node.{n}.version"),
                "an activation node needs `version`",
            )
        })?;
        hm.known(version, format!("node.{n}.version"))?;
        hm.known(fit, format!("node.{n}.fit"))?;
        push(parents, version);
        push(parents, fit);
        return Ok(());
    }
    for (key, v) in [
        ("version", &spec_n.version),
        ("tiles", &spec_n.tiles),
        ("cpu", &spec_n.cpu),
    ] {
        let v = v.as_ref().ok_or_else(|| {
            err(
                hm.file,
                format!("node.{n}.{key}"),
                format!("an activation node needs `{key}`"),
            )
        })?;
        hm.known(v, format!("node.{n}.{key}"))?;
        push(parents, v);
    }
    if let Some(p) = &spec_n.performance {
        hm.known(p, format!("node.{n}.performance"))?;
        push(parents, p);
    }
    Ok(())
}

/// A fit node depends on free tiles, CPU headroom and the required rate.
fn fit_parents(
    hm: &Hm,
    n: &str,
    spec_n: &FitNode,
    parents: &mut Vec<String>,
) -> Result<(), SpecError> {
    for (key, v) in [
        ("tiles", &spec_n.tiles),
        ("cpu", &spec_n.cpu),
        ("performance", &spec_n.performance),
    ] {
        let v = v.as_ref().ok_or_else(|| {
            err(
                hm.file,
                format!("node.{n}.{key}"),
                format!("a fit node needs `{key}`"),
            )
        })?;
        hm.known(v, format!("node.{n}.{key}"))?;
        push(parents, v);
    }
    Ok(())
}

/// Step `a` (parent state indices) to the next CPT row, last parent fastest.
fn next_row(a: &mut [usize], pstates: &[&Vec<String>]) {
    for i in (0..a.len()).rev() {
        a[i] += 1;
        if a[i] < pstates[i].len() {
            break;
        }
        a[i] = 0;
    }
}

/// A node's table: its `cpt`, or its role's rule row by row; then the row overrides.
fn node_table(
    hm: &Hm,
    n: &str,
    spec_n: &NodeSpec,
    parents: &[String],
) -> Result<Vec<f64>, SpecError> {
    let file = hm.file;
    let k = hm.states[n].len();
    let pstates: Vec<&Vec<String>> = parents.iter().map(|p| &hm.states[p]).collect();
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

    let mut cpt: Vec<f64> = if let Some(c) = &spec_n.common().cpt {
        c.flat()
    } else {
        let node = NodeCtx {
            hm,
            n,
            parents,
            pstates: &pstates,
            k,
        };
        let mut rule = row_rule(&node, spec_n)?;
        let mut cpt = Vec::with_capacity(rows * k);
        let mut a = vec![0usize; parents.len()];
        for _ in 0..rows {
            cpt.extend(rule(&a)?);
            next_row(&mut a, &pstates);
        }
        cpt
    };
    apply_overrides(hm, n, spec_n, parents, &pstates, rows, &mut cpt)?;
    Ok(cpt)
}

/// Replace the rows each `override` matches.
fn apply_overrides(
    hm: &Hm,
    n: &str,
    spec_n: &NodeSpec,
    parents: &[String],
    pstates: &[&Vec<String>],
    rows: usize,
    cpt: &mut [f64],
) -> Result<(), SpecError> {
    let file = hm.file;
    let k = hm.states[n].len();
    for (oi, o) in spec_n.common().overrides.iter().enumerate() {
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
            fixed.push((pos, hm.state_idx(p, s, format!("{oe}.when.{p}"))?));
        }
        if cpt.len() != rows * k {
            break; // reported as a size error below
        }
        let mut a = vec![0usize; parents.len()];
        for row in 0..rows {
            if fixed.iter().all(|&(pos, s)| a[pos] == s) {
                cpt[row * k..(row + 1) * k].copy_from_slice(&o.p);
            }
            next_row(&mut a, pstates);
        }
    }
    Ok(())
}

/// (local import node, source manager, source node) of an import node.
fn import_source(
    file: &Path,
    n: &str,
    spec_n: &ImportNode,
) -> Result<(String, String, String), SpecError> {
    let entry = format!("node.{n}.from");
    let from = spec_n.from.as_ref().ok_or_else(|| {
        err(
            file,
            &entry,
            "an import node needs `from = \"MANAGER.NODE\"`",
        )
    })?;
    let (m, src) = from
        .split_once('.')
        .ok_or_else(|| err(file, &entry, format!("`{from}` is not MANAGER.NODE")))?;
    Ok((n.to_string(), m.to_string(), src.to_string()))
}

/// Build the network and refuse one whose inference tables would be too large.
fn assemble(file: &Path, builder: NetworkBuilder) -> Result<Network, SpecError> {
    let network = builder.build().map_err(|e| bn_to_spec(file, e))?;
    // Small tables per node can still join into a huge clique table: refuse before compiling.
    match network.largest_clique_entries() {
        Some(n) if n <= MAX_CLIQUE_ENTRIES => Ok(network),
        n => Err(err(
            file,
            "node",
            format!(
                "inference would need a table of {} probabilities (at most {MAX_CLIQUE_ENTRIES}): \
                 fewer or less connected nodes",
                n.map_or_else(|| "more than 2^64".to_string(), |n| n.to_string())
            ),
        )),
    }
}

/// The `publish` entries, each naming an existing node and state.
fn compile_publish(hm: &Hm) -> Result<Vec<Publish>, SpecError> {
    let file = hm.file;
    let mut publish = Vec::new();
    for (name, expr) in &hm.spec.publish {
        let entry = format!("publish.{name}");
        let (node, state, complement) = parse_publish(expr).ok_or_else(|| {
            err(
                file,
                &entry,
                format!("`{expr}` is not `P(NODE = STATE)` or `1 - P(NODE = STATE)`"),
            )
        })?;
        if !hm.states.contains_key(&node) {
            return Err(err(
                file,
                &entry,
                format!("publishes from missing node `{node}`"),
            ));
        }
        hm.state_idx(&node, &state, entry)?;
        publish.push(Publish {
            name: name.clone(),
            node,
            state,
            complement,
        });
    }
    Ok(publish)
}

/// Each `carry` joins two nodes with the same states; the receiving node is a root.
fn check_carry(file: &Path, spec: &HmFile, network: &Network) -> Result<(), SpecError> {
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
    Ok(())
}
