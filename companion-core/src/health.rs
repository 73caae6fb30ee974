//! The health managers (BFM paper section 4): every params/health/*.toml FMEA file compiled to a
//! BN once at load, evaluated together each cycle into the named probabilities the MDPs consume
//! (`P_sys`, `P_V3`, ...).
//!
//! Managers may import another manager's node (its posterior marginal becomes the prior of a
//! local root: sensor and system health feed application health, application suitability feeds
//! the resource-aware versions), so they are evaluated in import order. A dynamic manager carries
//! its slice-t+1 belief into its slice-t prior between calls; that belief is the model's only
//! mutable state, exposed by [`HealthModel::belief`] / [`HealthModel::set_belief`].

use crate::evidence::ObservationMap;
use crate::fmea::{CompiledHm, NodeInfo, Publish};
use crate::named_slots::{NamedSlots, SortedNames};
use crate::observations::Observations;
use crate::spec::SpecError;
use bayes_net::{BnError, Engine, Evidence, NodeId};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// A query failed at run time (only reachable with hand-written evidence).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HealthError {
    /// Evidence names a node no manager has.
    #[error("no health manager has a node `{0}`")]
    UnknownNode(String),
    /// Evidence names a state the node does not have.
    #[error("node `{node}` has no state `{state}` (states: {states})")]
    UnknownState {
        /// Node the evidence names.
        node: String,
        /// State the evidence asks for.
        state: String,
        /// The node's states, comma-separated.
        states: String,
    },
    /// An observation given as text is not a number.
    #[error("observation `{name}`: `{value}` is not a number")]
    BadValue {
        /// Observation name.
        name: String,
        /// The text given for it.
        value: String,
    },
    /// Inference failed in one manager's network (impossible evidence, say).
    #[error("health manager `{manager}`: {error}")]
    Inference {
        /// Manager whose network failed.
        manager: String,
        /// The inference engine's error.
        error: BnError,
    },
}

/// One compiled health manager.
#[derive(Debug, Clone)]
pub struct Manager {
    /// Manager name from its file (`applications`, `sensors`, ...).
    pub name: String,
    /// Free text from the file.
    pub description: String,
    /// File it was compiled from.
    pub file: PathBuf,
    /// Every node of its network, in the file's order.
    pub nodes: Vec<NodeInfo>,
    /// The probabilities it publishes.
    pub publish: Vec<Publish>,
    engine: Engine,
    /// Prior CPTs as loaded, to reset carried beliefs.
    initial: Vec<(NodeId, Vec<f64>)>,
    imports: Vec<(NodeId, usize, NodeId)>,
    carry: Vec<(NodeId, NodeId)>,
    published: Vec<(usize, NodeId, usize, bool)>,
}

impl Manager {
    /// Posterior marginal of a node from the last evaluation (for a node that is not published,
    /// carried or imported: the last [`HealthModel::evaluate`]).
    pub fn marginal(&self, node: &str) -> Option<&[f64]> {
        self.engine
            .network()
            .id(node)
            .map(|id| self.engine.marginal(id))
    }
    /// The inference engine holding the network and its last posteriors.
    pub fn engine(&self) -> &Engine {
        &self.engine
    }
}

/// All health managers plus the observation mapping.
#[derive(Debug, Clone)]
pub struct HealthModel {
    /// The managers, in evaluation (import) order.
    pub managers: Vec<Manager>,
    /// Raw observations -> evidence (params/observations.toml).
    pub observations: ObservationMap,
    /// Activation nodes compiled from the variant catalogue, with what they publish.
    pub activations: Vec<CatalogueActivation>,
    /// Buffers reused by [`HealthModel::evaluate_into`] so a warm evaluation allocates nothing.
    scratch: Scratch,
    /// Per observation id, per state index of it: the (manager, node, state) it sets in every
    /// manager holding its node, resolved at load ([`HealthModel::evaluate_states_into`]).
    observation_hits: Vec<Vec<Vec<(usize, NodeId, usize)>>>,
    /// Every published probability's name, sorted (the order of the published map's keys); a
    /// slot is an index into it. Shared by every record's probabilities.
    slot_names: SortedNames,
    /// Per manager, per entry of its `published`: its slot.
    publish_slots: Vec<Vec<usize>>,
}

/// An activation node compiled from params/variants.toml (`variant = "app/version"`).
#[derive(Debug, Clone, PartialEq)]
pub struct CatalogueActivation {
    /// Manager holding the node.
    pub manager: String,
    /// Activation node name.
    pub node: String,
    /// Application in params/variants.toml.
    pub app: String,
    /// Version of that application the node gates.
    pub version: String,
    /// The probability names published from the node (`P_V3`).
    pub published: Vec<String>,
    /// Its `fit` node (`F_V3`), which the decision core observes with the scheduler's check.
    pub fit: Option<String>,
}

#[derive(Debug, Clone, Default)]
struct Scratch {
    /// Evidence per manager, cleared (capacity kept) each evaluation.
    per: Vec<Evidence>,
    /// The states by observation `per` was built from by [`HealthModel::evaluate_states_into`]
    /// (`None`: built by name): the same states build the same evidence, so it is kept.
    per_states: Option<Vec<Option<u16>>>,
    /// A carried belief being normalised.
    belief: Vec<f64>,
    /// Per manager: the evidence of its last propagation, and whether its marginals are still
    /// those of that evidence under its current CPTs. Propagation is a pure function of the two,
    /// so a manager whose evidence and CPTs (imported priors, carried beliefs) are bit-identical
    /// to last time keeps its marginals instead of propagating again.
    last: Vec<Evidence>,
    fresh: Vec<bool>,
    /// Per manager: every node's marginal is current (not only the query targets').
    full: Vec<bool>,
    /// The last evaluation's evidence entries resolved to (manager, node, state) indices, in
    /// the evidence map's order: an entry whose node and state names are unchanged reuses its
    /// resolution instead of name lookups in every manager's network (a cycle-time hot spot).
    resolved: Vec<Resolved>,
    /// The published probabilities by slot ([`HealthModel::slot_names`]).
    published: Vec<f64>,
}

/// One evidence entry (`node = state`) resolved in every manager that has the node.
#[derive(Debug, Clone, Default)]
struct Resolved {
    /// Empty while being (re)resolved, so an entry that failed never matches.
    node: String,
    state: String,
    hits: Vec<(usize, NodeId, usize)>,
}

/// Manager name -> position in `hms`; a name defined twice is refused.
fn manager_index(hms: &[CompiledHm]) -> Result<BTreeMap<&str, usize>, SpecError> {
    let index: BTreeMap<&str, usize> = hms
        .iter()
        .enumerate()
        .map(|(i, h)| (h.name.as_str(), i))
        .collect();
    if index.len() != hms.len() {
        let mut seen = BTreeMap::new();
        for h in hms {
            if let Some(prev) = seen.insert(h.name.as_str(), &h.file) {
                return Err(SpecError::new(
                    &h.file,
                    "name",
                    format!("manager `{}` is also defined in {}", h.name, prev.display()),
                ));
            }
        }
    }
    Ok(index)
}

/// The managers in evaluation order: each after the ones it imports from (checked: the import
/// names a manager and a node with the same states; no cycle).
fn import_order(
    hms: &[CompiledHm],
    index: &BTreeMap<&str, usize>,
) -> Result<Vec<usize>, SpecError> {
    // Import edges and a topological order over managers.
    let mut deps: Vec<Vec<usize>> = vec![Vec::new(); hms.len()];
    for (i, h) in hms.iter().enumerate() {
        for (local, m, src) in &h.imports {
            let entry = format!("node.{local}.from");
            let &j = index.get(m.as_str()).ok_or_else(|| {
                SpecError::new(&h.file, &entry, format!("no health manager `{m}`"))
            })?;
            let sid = hms[j].network.id(src).ok_or_else(|| {
                SpecError::new(
                    &h.file,
                    &entry,
                    format!("manager `{m}` has no node `{src}`"),
                )
            })?;
            let lid = h.network.id(local).expect("compiled node");
            if hms[j].network.node(sid).states != h.network.node(lid).states {
                return Err(SpecError::new(
                    &h.file,
                    entry,
                    format!(
                        "states differ from `{m}.{src}` ({:?})",
                        hms[j].network.node(sid).states
                    ),
                ));
            }
            deps[i].push(j);
        }
    }
    let mut order = Vec::new();
    let mut mark = vec![0u8; hms.len()];
    fn visit(
        i: usize,
        deps: &[Vec<usize>],
        mark: &mut [u8],
        order: &mut Vec<usize>,
    ) -> Result<(), usize> {
        match mark[i] {
            2 => return Ok(()),
            1 => return Err(i),
            _ => {}
        }
        mark[i] = 1;
        for &j in &deps[i] {
            visit(j, deps, mark, order)?;
        }
        mark[i] = 2;
        order.push(i);
        Ok(())
    }
    for i in 0..hms.len() {
        visit(i, &deps, &mut mark, &mut order).map_err(|j| {
            SpecError::new(
                &hms[j].file,
                "node",
                "imports between health managers form a cycle",
            )
        })?;
    }
    Ok(order)
}

/// Every named probability has one publisher.
fn check_publishers(hms: &[CompiledHm]) -> Result<(), SpecError> {
    let mut publishers: BTreeMap<&str, &str> = BTreeMap::new();
    for h in hms {
        for p in &h.publish {
            if let Some(other) = publishers.insert(&p.name, &h.name) {
                return Err(SpecError::new(
                    &h.file,
                    format!("publish.{}", p.name),
                    format!("also published by manager `{other}`"),
                ));
            }
        }
    }
    Ok(())
}

/// Every observation targets an existing node and its states.
fn check_observations(hms: &[CompiledHm], observations: &ObservationMap) -> Result<(), SpecError> {
    for (i, o) in observations.observations.iter().enumerate() {
        let mut found = false;
        for h in hms {
            if let Some(id) = h.network.id(&o.node) {
                found = true;
                for s in &o.states {
                    if h.network.state(id, s).is_err() {
                        return Err(SpecError::new(
                            &observations.file,
                            format!("observation[{i}]({}).states", o.name),
                            format!(
                                "node `{}` in {} has no state `{s}`",
                                o.node,
                                h.file.display()
                            ),
                        ));
                    }
                }
            }
        }
        if !found {
            return Err(SpecError::new(
                &observations.file,
                format!("observation[{i}]({}).node", o.name),
                format!("no health manager has a node `{}`", o.node),
            ));
        }
    }
    Ok(())
}

/// The managers in evaluation `order`, import sources remapped to positions in it, each
/// engine's targets set to what the cycle reads.
fn build_managers(
    hms: &[CompiledHm],
    index: &BTreeMap<&str, usize>,
    order: &[usize],
) -> Vec<Manager> {
    // Build managers in evaluation order; remap import sources to positions in that order.
    let pos: BTreeMap<usize, usize> = order.iter().enumerate().map(|(p, &i)| (i, p)).collect();
    let mut managers = Vec::new();
    for &i in order {
        let h = &hms[i];
        let net = &h.network;
        let mut engine = net.compile();
        let imports = h
            .imports
            .iter()
            .map(|(local, m, src)| {
                let j = index[m.as_str()];
                (
                    net.id(local).unwrap(),
                    pos[&j],
                    hms[j].network.id(src).unwrap(),
                )
            })
            .collect();
        let carry: Vec<(NodeId, NodeId)> = h
            .carry
            .iter()
            .map(|c| (net.id(&c.from).unwrap(), net.id(&c.to).unwrap()))
            .collect();
        let initial = carry
            .iter()
            .map(|&(_, t)| (t, net.node(t).cpt.clone()))
            .collect();
        let published = h
            .publish
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let id = net.id(&p.node).unwrap();
                (k, id, net.state(id, &p.state).unwrap(), p.complement)
            })
            .collect();
        // Marginals are defined from the start (prior, before any evidence).
        let _ = engine.propagate(&Evidence::new());
        managers.push(Manager {
            name: h.name.clone(),
            description: h.description.clone(),
            file: h.file.clone(),
            nodes: h.nodes.clone(),
            publish: h.publish.clone(),
            engine,
            initial,
            imports,
            carry,
            published,
        });
    }
    // Targeted queries answer what the cycle reads: published nodes, carried beliefs, and the
    // nodes later managers import as priors.
    let mut targets: Vec<Vec<NodeId>> = managers
        .iter()
        .map(|m| {
            m.published
                .iter()
                .map(|&(_, id, _, _)| id)
                .chain(m.carry.iter().map(|&(from, _)| from))
                .collect()
        })
        .collect();
    for m in &managers {
        for &(_, j, src) in &m.imports {
            targets[j].push(src);
        }
    }
    for (m, t) in managers.iter_mut().zip(&targets) {
        m.engine
            .set_targets(t)
            .expect("targets are nodes of the network");
    }
    managers
}

/// True when `cpt` is bit-for-bit node `id`'s current CPT (setting it would change nothing).
fn same_cpt(engine: &Engine, id: NodeId, cpt: &[f64]) -> bool {
    let cur = &engine.network().node(id).cpt;
    cur.len() == cpt.len() && cur.iter().zip(cpt).all(|(a, b)| a.to_bits() == b.to_bits())
}

impl HealthModel {
    /// Load `params_dir/observations.toml` and every `params_dir/health/*.toml`.
    pub fn load(params: &crate::spec::ParamsFiles) -> Result<HealthModel, SpecError> {
        let params_dir = params.dir();
        let dir = params_dir.join("health");
        let files: Vec<PathBuf> = params.files_in(&dir, "toml");
        if files.is_empty() {
            return Err(SpecError::new(
                &dir,
                "-",
                "no health manager files (health/*.toml)",
            ));
        }
        // Activation nodes naming a `variant` take its implementations from the one Table 2
        // (params/variants.toml with params/platform.toml).
        let platform = crate::resources::load_platform(
            params,
            &params_dir.join(crate::resources::PLATFORM_FILE),
        )?;
        let catalogue = crate::resources::load_variants(
            params,
            &params_dir.join(crate::resources::VARIANTS_FILE),
            &platform,
        )?;
        let mut activations = Vec::new();
        let hms = files
            .iter()
            .map(|f| {
                let mut spec = crate::fmea::read_hm(params, f)?;
                crate::fmea::fill_from_catalogue(f, &mut spec, &catalogue, platform.cpu_cores)?;
                for (node, n) in &spec.node {
                    if let crate::fmea::NodeSpec::Activation(n) = n
                        && let Some((app, version)) =
                            n.variant.as_deref().and_then(|v| v.split_once('/'))
                    {
                        let published = spec
                            .publish
                            .iter()
                            .filter(|(_, e)| {
                                crate::fmea::parse_publish(e).is_some_and(|(pn, _, _)| pn == *node)
                            })
                            .map(|(k, _)| k.clone())
                            .collect();
                        activations.push(CatalogueActivation {
                            manager: spec.name.clone(),
                            node: node.clone(),
                            app: app.to_string(),
                            version: version.to_string(),
                            published,
                            fit: n.fit.clone(),
                        });
                    }
                }
                crate::fmea::compile_hm(f, &spec)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let obs = ObservationMap::load(params, &params_dir.join("observations.toml"))?;
        let mut model = Self::from_parts(hms, obs)?;
        model.activations = activations;
        Ok(model)
    }

    /// Wire compiled managers together: resolve imports, order by them, check that publish
    /// names are unique and that every observation targets an existing node and state.
    pub fn from_parts(
        hms: Vec<CompiledHm>,
        observations: ObservationMap,
    ) -> Result<HealthModel, SpecError> {
        let index = manager_index(&hms)?;
        let order = import_order(&hms, &index)?;
        check_publishers(&hms)?;
        check_observations(&hms, &observations)?;
        let managers = build_managers(&hms, &index, &order);
        // Checked above: every observation's node and states exist where the node does.
        let observation_hits = observations
            .observations
            .iter()
            .map(|o| {
                o.states
                    .iter()
                    .map(|state| {
                        managers
                            .iter()
                            .enumerate()
                            .filter_map(|(mi, m)| {
                                let net = m.engine.network();
                                let id = net.id(&o.node)?;
                                Some((mi, id, net.state(id, state).ok()?))
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let mut slot_names: Vec<String> = managers
            .iter()
            .flat_map(|m| m.published.iter().map(|p| m.publish[p.0].name.clone()))
            .collect();
        slot_names.sort();
        slot_names.dedup();
        let publish_slots = managers
            .iter()
            .map(|m| {
                m.published
                    .iter()
                    .map(|p| {
                        let name = m.publish[p.0].name.as_str();
                        slot_names
                            .binary_search_by(|n| n.as_str().cmp(name))
                            .unwrap_or(0)
                    })
                    .collect()
            })
            .collect();
        Ok(HealthModel {
            managers,
            observations,
            activations: Vec::new(),
            scratch: Scratch::default(),
            observation_hits,
            slot_names: slot_names.into(),
            publish_slots,
        })
    }

    /// The observations the decision core computes for the activation nodes' `fit` nodes
    /// (params/observations.toml entries whose node is one), with the activation they serve.
    pub fn fit_observations(&self) -> impl Iterator<Item = (&str, &CatalogueActivation)> {
        self.activations.iter().filter_map(|a| {
            let fit = a.fit.as_deref()?;
            let o = self
                .observations
                .observations
                .iter()
                .find(|o| o.node == fit)?;
            Some((o.name.as_str(), a))
        })
    }

    /// Every named probability, in name order.
    pub fn publishes(&self) -> Vec<String> {
        let mut v: Vec<String> = self
            .managers
            .iter()
            .flat_map(|m| m.publish.iter().map(|p| p.name.clone()))
            .collect();
        v.sort();
        v
    }

    /// The published probabilities' names, sorted: the keys of the map the cycle fills, in order
    /// (a slot is an index into it).
    pub fn slot_names(&self) -> &SortedNames {
        &self.slot_names
    }

    /// The position of the manager named `name` among the managers (resolved once, the cycle
    /// then names it by position), if loaded.
    pub fn manager_position(&self, name: &str) -> Option<usize> {
        self.managers.iter().position(|m| m.name == name)
    }

    /// The manager named `name`, if loaded.
    pub fn manager(&self, name: &str) -> Option<&Manager> {
        self.managers.iter().find(|m| m.name == name)
    }

    /// Discretise a snapshot into evidence (node -> state).
    pub fn evidence(&self, obs: &Observations) -> BTreeMap<String, String> {
        self.observations.evidence(obs)
    }

    /// As [`HealthModel::evidence`], rewriting the caller's map in place.
    pub fn evidence_into(&self, obs: &Observations, out: &mut BTreeMap<String, String>) {
        self.observations.evidence_into(obs, out)
    }

    /// As [`HealthModel::evidence_into`], with `extra` values replacing the snapshot's.
    pub fn evidence_with_into(
        &self,
        obs: &Observations,
        extra: &[(&str, f64)],
        out: &mut BTreeMap<String, String>,
    ) {
        self.observations.evidence_with_into(obs, extra, out)
    }

    /// Set the evidence of the observation `name` at `value` (its node, discretised by
    /// params/observations.toml), replacing what the snapshot gave; false when params have no
    /// such observation or the value is not finite. The decision core uses it for what it
    /// computes itself (the room its platform model leaves, the rate tracking needs).
    pub fn observe_into(
        &self,
        name: &str,
        value: f64,
        evidence: &mut BTreeMap<String, String>,
    ) -> bool {
        let Some(o) = self.observations.get(name) else {
            return false;
        };
        let Some(s) = o.state(value) else {
            return false;
        };
        match evidence.get_mut(o.node.as_str()) {
            Some(v) => {
                v.clear();
                v.push_str(s);
            }
            None => {
                evidence.insert(o.node.clone(), s.to_string());
            }
        }
        true
    }

    /// Evaluate every manager under `evidence` (applied to each manager holding the node) and
    /// return all published probabilities; then advance the dynamic managers by one slice. Every
    /// node's [`Manager::marginal`] is computed (for reports; the cycle uses
    /// [`HealthModel::evaluate_into`]).
    pub fn evaluate(
        &mut self,
        evidence: &BTreeMap<String, String>,
    ) -> Result<BTreeMap<String, f64>, HealthError> {
        let mut out = BTreeMap::new();
        self.evaluate_impl(evidence, &mut out, true)?;
        Ok(out)
    }

    /// As [`HealthModel::evaluate`], filling the caller's map (existing entries are updated in
    /// place: no allocation once the map holds every published name). Only what the cycle reads
    /// is computed (published nodes, carried beliefs, imported priors: [`bayes_net::Engine::query`]);
    /// the other nodes' [`Manager::marginal`]s are those of the last [`HealthModel::evaluate`].
    /// The published probabilities are the same, bit for bit, as [`HealthModel::evaluate`]'s.
    pub fn evaluate_into(
        &mut self,
        evidence: &BTreeMap<String, String>,
        out: &mut BTreeMap<String, f64>,
    ) -> Result<(), HealthError> {
        self.evaluate_impl(evidence, out, false)
    }

    /// As [`HealthModel::evaluate_into`], with the evidence given by observation
    /// ([`ObservationMap::evidence_states_into`]'s state indices) instead of by node and state
    /// name: the same evidence, set in the same (node name) order, so the same probabilities bit
    /// for bit, without a name lookup.
    pub fn evaluate_states_into(
        &mut self,
        states: &crate::evidence::EvidenceStates,
        out: &mut NamedSlots<f64>,
    ) -> Result<(), HealthError> {
        let per = &mut self.scratch.per;
        let same = (self.scratch.per_states.as_ref()).is_some_and(|s| *s == states.state);
        if !same || per.len() != self.managers.len() {
            per.resize_with(self.managers.len(), Evidence::new);
            per.iter_mut().for_each(Evidence::clear);
            for id in self.observations.by_node() {
                let Some(Some(s)) = states.state.get(id.index()) else {
                    continue;
                };
                for &(mi, node, st) in &self.observation_hits[id.index()][usize::from(*s)] {
                    per[mi].set_state(node, st);
                }
            }
            match &mut self.scratch.per_states {
                Some(s) => s.clone_from(&states.state),
                None => self.scratch.per_states = Some(states.state.clone()),
            }
        }
        crate::stage_hook::mark(crate::stage_hook::Stage::Evidence);
        self.propagate(false)?;
        out.reset_over(&self.slot_names);
        for (k, &p) in self.scratch.published.iter().enumerate() {
            out.set(k, p);
        }
        Ok(())
    }

    /// `all`: every node's marginal (for reports), else the targets only.
    fn evaluate_impl(
        &mut self,
        evidence: &BTreeMap<String, String>,
        out: &mut BTreeMap<String, f64>,
        all: bool,
    ) -> Result<(), HealthError> {
        // Resolve everything first so a bad entry changes no state.
        let per = &mut self.scratch.per;
        self.scratch.per_states = None;
        per.resize_with(self.managers.len(), Evidence::new);
        per.iter_mut().for_each(Evidence::clear);
        let resolved = &mut self.scratch.resolved;
        for (k, (node, state)) in evidence.iter().enumerate() {
            if k == resolved.len() {
                resolved.push(Resolved::default());
            }
            let r = &mut resolved[k];
            if r.node.is_empty() || r.node != *node || r.state != *state {
                r.node.clear();
                r.hits.clear();
                for (mi, m) in self.managers.iter().enumerate() {
                    let net = m.engine.network();
                    if let Some(id) = net.id(node) {
                        r.hits.push((mi, id, state_of(net, id, node, state)?));
                    }
                }
                if r.hits.is_empty() {
                    return Err(HealthError::UnknownNode(node.clone()));
                }
                r.node.clone_from(node);
                r.state.clone_from(state);
            }
            for &(mi, id, s) in &r.hits {
                per[mi].set_state(id, s);
            }
        }
        crate::stage_hook::mark(crate::stage_hook::Stage::Evidence);
        self.propagate(all)?;
        write_published(&self.slot_names, &self.scratch.published, out);
        Ok(())
    }

    /// The managers under the evidence in `scratch.per`: imports, queries (or their memo),
    /// published probabilities into `scratch.published` by slot, carried beliefs advanced.
    fn propagate(&mut self, all: bool) -> Result<(), HealthError> {
        let per = &self.scratch.per;
        let n = self.managers.len();
        let (last, fresh, full) = (
            &mut self.scratch.last,
            &mut self.scratch.fresh,
            &mut self.scratch.full,
        );
        last.resize_with(n, Evidence::new);
        fresh.resize(n, false);
        full.resize(n, false);
        #[allow(clippy::needless_range_loop)] // split_at_mut needs the index
        for i in 0..n {
            let (done, rest) = self.managers.split_at_mut(i);
            let m = &mut rest[0];
            for &(local, src_m, src) in &m.imports {
                let prior = done[src_m].engine.marginal(src);
                if same_cpt(&m.engine, local, prior) {
                    continue;
                }
                fresh[i] = false;
                m.engine
                    .set_cpt(local, prior)
                    .or_else(|_| {
                        // Renormalise tiny rounding drift of a marginal.
                        let s: f64 = prior.iter().sum();
                        let p: Vec<f64> = prior.iter().map(|x| x / s).collect();
                        m.engine.set_cpt(local, &p)
                    })
                    .map_err(|error| HealthError::Inference {
                        manager: m.name.clone(),
                        error,
                    })?;
            }
            if !fresh[i] || per[i] != last[i] || (all && !full[i]) {
                fresh[i] = false;
                let err = |error| HealthError::Inference {
                    manager: m.name.clone(),
                    error,
                };
                // Every marginal, then the targets by the cycle's own path (same numbers).
                if all {
                    m.engine.propagate(&per[i]).map_err(err)?;
                }
                m.engine.query(&per[i]).map_err(err)?;
                last[i].findings.clone_from(&per[i].findings);
                fresh[i] = true;
                full[i] = all;
            }
            let values = &mut self.scratch.published;
            values.resize(self.slot_names.len(), 0.0);
            for (j, &(_, id, s, complement)) in m.published.iter().enumerate() {
                let p = m.engine.marginal(id)[s];
                values[self.publish_slots[i][j]] = if complement { 1.0 - p } else { p };
            }
            crate::stage_hook::mark(crate::stage_hook::Stage::HealthManager(&m.name));
        }
        for (i, m) in self.managers.iter_mut().enumerate() {
            for &(from, to) in &m.carry {
                let b = &mut self.scratch.belief;
                b.clear();
                b.extend_from_slice(m.engine.marginal(from));
                let s: f64 = b.iter().sum();
                b.iter_mut().for_each(|x| *x /= s);
                if same_cpt(&m.engine, to, b) {
                    continue;
                }
                self.scratch.fresh[i] = false;
                m.engine
                    .set_cpt(to, b)
                    .map_err(|error| HealthError::Inference {
                        manager: m.name.clone(),
                        error,
                    })?;
            }
        }
        crate::stage_hook::mark(crate::stage_hook::Stage::HealthCarry);
        Ok(())
    }

    /// Let every manager's engine answer the last `slots` distinct queries (evidence and
    /// imported or carried priors, bit for bit) from memory (`Engine::set_query_memo`; 0: off).
    pub fn set_query_memo(&mut self, slots: usize) {
        for m in &mut self.managers {
            m.engine.set_query_memo(slots);
        }
    }

    /// The carried (dynamic) beliefs: (manager, node) -> prior for the next evaluation.
    pub fn belief(&self) -> BTreeMap<(String, String), Vec<f64>> {
        let mut out = BTreeMap::new();
        for m in &self.managers {
            for &(_, to) in &m.carry {
                let net = m.engine.network();
                out.insert(
                    (m.name.clone(), net.node(to).name.clone()),
                    net.node(to).cpt.clone(),
                );
            }
        }
        out
    }

    /// Restore carried beliefs (e.g. from a saved mission state).
    pub fn set_belief(
        &mut self,
        belief: &BTreeMap<(String, String), Vec<f64>>,
    ) -> Result<(), HealthError> {
        self.scratch.fresh.clear();
        for ((mn, node), b) in belief {
            let m = self
                .managers
                .iter_mut()
                .find(|m| &m.name == mn)
                .ok_or_else(|| HealthError::UnknownNode(format!("{mn}.{node}")))?;
            let id = m
                .engine
                .network()
                .id(node)
                .ok_or_else(|| HealthError::UnknownNode(node.clone()))?;
            m.engine
                .set_cpt(id, b)
                .map_err(|error| HealthError::Inference {
                    manager: mn.clone(),
                    error,
                })?;
        }
        Ok(())
    }

    /// Forget carried beliefs: back to the priors in the params files.
    pub fn reset(&mut self) {
        self.scratch.fresh.clear();
        for m in &mut self.managers {
            for (id, cpt) in m.initial.clone() {
                m.engine.set_cpt(id, &cpt).expect("loaded CPT is valid");
            }
        }
    }

    /// Resolve user-typed evidence (`--evidence wind=strong,qos=high,wind_mps=12`): a key is a
    /// node name, a node name without its role prefix (`A_`, `S_`, `U_`, `C_`, `H_S_`), any of
    /// them case-insensitively, or an observation name with a numeric value.
    pub fn resolve_evidence(
        &self,
        pairs: &[(String, String)],
    ) -> Result<BTreeMap<String, String>, HealthError> {
        let mut out = BTreeMap::new();
        for (k, v) in pairs {
            if let Some(o) = self.observations.get(k) {
                let x: f64 = v.parse().map_err(|_| HealthError::BadValue {
                    name: k.clone(),
                    value: v.clone(),
                })?;
                if let Some(s) = o.state(x) {
                    out.insert(o.node.clone(), s.to_string());
                }
                continue;
            }
            let node = self
                .find_node(k)
                .ok_or_else(|| HealthError::UnknownNode(k.clone()))?;
            let states = &node.states;
            let s = states
                .iter()
                .find(|s| s.eq_ignore_ascii_case(v))
                .ok_or_else(|| HealthError::UnknownState {
                    node: node.name.clone(),
                    state: v.clone(),
                    states: states.join(", "),
                })?;
            out.insert(node.name.clone(), s.clone());
        }
        Ok(out)
    }

    fn find_node(&self, key: &str) -> Option<&NodeInfo> {
        let all = || self.managers.iter().flat_map(|m| m.nodes.iter());
        let strip = |n: &str| -> String {
            let l = n.to_ascii_lowercase();
            for p in ["h_s_", "a_h_", "a_", "s_", "u_", "c_"] {
                if let Some(r) = l.strip_prefix(p) {
                    return r.to_string();
                }
            }
            l
        };
        all()
            .find(|n| n.name == key)
            .or_else(|| all().find(|n| n.name.eq_ignore_ascii_case(key)))
            .or_else(|| all().find(|n| strip(&n.name) == key.to_ascii_lowercase()))
    }
}

/// The published probabilities (`values` by slot, `names` sorted) into `out`: when `out` holds
/// exactly those names (every warm cycle) one walk beside them; otherwise each name updated or
/// inserted, other entries left as they were.
fn write_published(names: &[String], values: &[f64], out: &mut BTreeMap<String, f64>) {
    if out.len() == names.len() && out.keys().zip(names).all(|(k, n)| k == n) {
        for (v, x) in out.values_mut().zip(values) {
            *v = *x;
        }
        return;
    }
    for (name, x) in names.iter().zip(values) {
        match out.get_mut(name.as_str()) {
            Some(v) => *v = *x,
            None => {
                out.insert(name.clone(), *x);
            }
        }
    }
}

/// The index of `state` of `node` (found at `id` in `net`), or why the evidence names no state of it.
fn state_of(
    net: &bayes_net::Network,
    id: bayes_net::NodeId,
    node: &str,
    state: &str,
) -> Result<usize, HealthError> {
    net.state(id, state).map_err(|_| HealthError::UnknownState {
        node: node.to_string(),
        state: state.to_string(),
        states: net.node(id).states.join(", "),
    })
}

mod cpt_rows;
mod reevaluate;

#[cfg(test)]
mod tests;
