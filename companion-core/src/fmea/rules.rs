//! The default CPT rule of each role (docs/params/health.md): one function per role, each
//! taking its role's settings, checking the rule parameters and returning its row generator.

use super::nodes::Hm;
use super::roles::Role;
use super::schema::{
    ActivationNode, FitNode, Implementation, MonitorNode, NodeSpec, NoisyOrNode, QosNode,
    StateNode, VersionNode,
};
use super::{check_prob, err};
use crate::spec::SpecError;

/// Generates one CPT row from the parents' state indices.
pub(super) type RowRule = Box<dyn FnMut(&[usize]) -> Result<Vec<f64>, SpecError>>;

/// The node a rule is built for.
pub(super) struct NodeCtx<'a> {
    pub(super) hm: &'a Hm<'a>,
    pub(super) n: &'a str,
    pub(super) parents: &'a [String],
    pub(super) pstates: &'a [&'a Vec<String>],
    /// The node's state count.
    pub(super) k: usize,
}

impl NodeCtx<'_> {
    fn entry(&self, key: &str) -> String {
        format!("node.{}.{key}", self.n)
    }

    fn prob(&self, key: &str, v: f64) -> Result<f64, SpecError> {
        check_prob(self.hm.file, &self.entry(key), v)
    }

    fn err(&self, entry: String, reason: impl Into<String>) -> SpecError {
        err(self.hm.file, entry, reason)
    }
}

/// The row generator of a node without `cpt`: the rule of its role.
pub(super) fn row_rule(c: &NodeCtx, spec: &NodeSpec) -> Result<RowRule, SpecError> {
    match spec {
        NodeSpec::State(s) if s.previous.is_some() => state_transition(c, s),
        NodeSpec::State(s) if c.parents.is_empty() => root_state(c, s),
        NodeSpec::Context(s) | NodeSpec::Resource(s) | NodeSpec::Solution(s) => {
            root_prior(c, spec.role(), s.prior.as_ref())
        }
        NodeSpec::Import(s) => root_prior(c, Role::Import, s.prior.as_ref()),
        NodeSpec::Error(s) | NodeSpec::MonitorHealth(s) => noisy_or(c, s),
        NodeSpec::Monitor(s) => monitor(c, s),
        NodeSpec::Qos(s) => qos(c, s),
        NodeSpec::Version(s) => version(c, s),
        NodeSpec::Activation(s) => activation(c, s),
        NodeSpec::Fit(s) => fit(c, s),
        NodeSpec::State(_) | NodeSpec::Performance(_) => Err(c.err(
            c.entry("cpt"),
            format!("a {} node needs an explicit `cpt`", spec.role()),
        )),
    }
}

/// Per-parent values of a rule table (`drain`, `strength`): one per parent state, each a
/// probability, with `default` for parents not named; every named key must be a parent.
fn per_parent(
    c: &NodeCtx,
    key: &str,
    table: &std::collections::BTreeMap<String, Vec<f64>>,
    skip: usize,
    default: impl Fn(usize) -> Vec<f64>,
) -> Result<Vec<Vec<f64>>, SpecError> {
    let n = c.n;
    let mut out = Vec::new();
    for (p, ps) in c.parents.iter().zip(c.pstates).skip(skip) {
        let d = match table.get(p) {
            Some(d) if d.len() != ps.len() => {
                return Err(c.err(
                    format!("node.{n}.{key}.{p}"),
                    format!("{} values for {} states of `{p}`", d.len(), ps.len()),
                ));
            }
            Some(d) => d.clone(),
            None => default(ps.len()),
        };
        for &v in &d {
            check_prob(c.hm.file, &format!("node.{n}.{key}.{p}"), v)?;
        }
        out.push(d);
    }
    for p in table.keys() {
        if !c.parents[skip..].contains(p) {
            return Err(c.err(
                format!("node.{n}.{key}.{p}"),
                format!("`{p}` is not a parent"),
            ));
        }
    }
    Ok(out)
}

/// A dynamic state: stays with `stay` (times the drain of the other parents), else falls one
/// state; the last state is absorbing.
fn state_transition(c: &NodeCtx, s: &StateNode) -> Result<RowRule, SpecError> {
    let stay = c.prob("stay", s.stay.unwrap_or(0.9))?;
    let drains = per_parent(c, "drain", &s.drain, 1, |len| vec![1.0; len])?;
    let k = c.k;
    Ok(Box::new(move |a| {
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
    }))
}

fn root_state(c: &NodeCtx, s: &StateNode) -> Result<RowRule, SpecError> {
    let prior = s.prior.clone().ok_or_else(|| {
        c.err(
            c.entry("prior"),
            "a root state node needs `prior` (or `cpt`)",
        )
    })?;
    Ok(Box::new(move |_| Ok(prior.clone())))
}

/// Context, resource, solution and import: a root with its `prior` or the role's default.
fn root_prior(c: &NodeCtx, r: Role, prior: Option<&Vec<f64>>) -> Result<RowRule, SpecError> {
    let k = c.k;
    let prior = match (prior, r) {
        (Some(p), _) => p.clone(),
        (None, Role::Solution) => vec![0.9, 0.1],
        (None, _) => {
            // Nominal first: 0.9, the rest share 0.1 (uniform for imports, which are
            // overwritten at every evaluation anyway).
            if r == Role::Import || k == 1 {
                vec![1.0 / k as f64; k]
            } else {
                std::iter::once(0.9)
                    .chain(std::iter::repeat_n(0.1 / (k - 1) as f64, k - 1))
                    .collect()
            }
        }
    };
    Ok(Box::new(move |_| Ok(prior.clone())))
}

/// Error and monitor health: noisy-OR of the parents with a leak.
fn noisy_or(c: &NodeCtx, s: &NoisyOrNode) -> Result<RowRule, SpecError> {
    let leak = c.prob("leak", s.leak.unwrap_or(0.01))?;
    let strengths = per_parent(c, "strength", &s.strength, 0, |len| {
        std::iter::once(0.0)
            .chain(std::iter::repeat_n(0.8, len - 1))
            .collect()
    })?;
    Ok(Box::new(move |a| {
        let off: f64 = (1.0 - leak)
            * a.iter()
                .zip(&strengths)
                .map(|(&s, st)| 1.0 - st[s])
                .product::<f64>();
        Ok(vec![off, 1.0 - off])
    }))
}

/// A monitor alarms on each present error with `sensitivity`, falsely with `false_alarm`, and
/// with `faulty_alarm` when its health node says it is faulty.
fn monitor(c: &NodeCtx, s: &MonitorNode) -> Result<RowRule, SpecError> {
    let sens = c.prob("sensitivity", s.sensitivity.unwrap_or(0.95))?;
    let fa = c.prob("false_alarm", s.false_alarm.unwrap_or(0.05))?;
    let fy = c.prob("faulty_alarm", s.faulty_alarm.unwrap_or(0.5))?;
    let hpos = s
        .health
        .as_ref()
        .and_then(|h| c.parents.iter().position(|p| p == h));
    Ok(Box::new(move |a| {
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
    }))
}

/// QoS: row `by_uncorrected[k]` where k errors are present with none of their solutions active.
fn qos(c: &NodeCtx, s: &QosNode) -> Result<RowRule, SpecError> {
    let (n, k) = (c.n, c.k);
    let table = s.by_uncorrected.clone().unwrap_or_else(|| {
        vec![
            vec![0.90, 0.08, 0.02],
            vec![0.10, 0.50, 0.40],
            vec![0.02, 0.18, 0.80],
        ]
    });
    for (i, row) in table.iter().enumerate() {
        if row.len() != k {
            return Err(c.err(
                format!("node.{n}.by_uncorrected[{i}]"),
                format!("{} values for {k} states", row.len()),
            ));
        }
    }
    if table.is_empty() {
        return Err(c.err(c.entry("by_uncorrected"), "empty table"));
    }
    // Error parent position -> positions of its solution parents.
    let errs = s.errors.clone().unwrap_or_default();
    let fixes: Vec<(usize, Vec<usize>)> = errs
        .iter()
        .map(|e| {
            let sols =
                c.hm.solutions_of
                    .get(e.as_str())
                    .cloned()
                    .unwrap_or_default();
            let ep = c.parents.iter().position(|p| p == e).unwrap_or(0);
            (
                ep,
                sols.iter()
                    .filter_map(|s| c.parents.iter().position(|p| p == s))
                    .collect(),
            )
        })
        .collect();
    Ok(Box::new(move |a| {
        let k = fixes
            .iter()
            .filter(|(e, sols)| a[*e] != 0 && sols.iter().all(|&s| a[s] == 0))
            .count();
        Ok(table[k.min(table.len() - 1)].clone())
    }))
}

/// A version works with `p_ok`, times `miss` per present error none of its solutions fixes and
/// `extra` per solution running for an absent error.
fn version(c: &NodeCtx, s: &VersionNode) -> Result<RowRule, SpecError> {
    let sols = s.solutions.clone().ok_or_else(|| {
        c.err(
            c.entry("solutions"),
            "a version node must list `solutions` (may be empty)",
        )
    })?;
    for sol in &sols {
        if !c.hm.has_role(sol, Role::Solution) {
            return Err(c.err(
                c.entry("solutions"),
                format!("`{sol}` is not a solution node"),
            ));
        }
    }
    let p_ok = c.prob("p_ok", s.p_ok.unwrap_or(0.95))?;
    let miss = c.prob("miss", s.miss.unwrap_or(0.1))?;
    let extra = c.prob("extra", s.extra.unwrap_or(0.5))?;
    // For each error parent: is it fixed by one of this version's solutions?
    let fixed: Vec<bool> = c
        .parents
        .iter()
        .map(|e| {
            c.hm.solutions_of
                .get(e.as_str())
                .is_some_and(|s| s.iter().any(|x| sols.contains(x)))
        })
        .collect();
    let n_fixable = fixed.iter().filter(|&&f| f).count();
    Ok(Box::new(move |a| {
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
    }))
}

/// Whether some implementation fits: (free tiles, CPU state, performance state).
type FitsRule = Box<dyn Fn(u32, usize, usize) -> bool>;

/// Activation (paper section 4.3): an activated version becomes active with `p_fit` when one of
/// its implementations fits the free tiles, the CPU and the required performance, else `p_nofit`.
fn activation(c: &NodeCtx, s: &ActivationNode) -> Result<RowRule, SpecError> {
    let p_fit = c.prob("p_fit", s.p_fit.unwrap_or(1.0))?;
    let p_nofit = c.prob("p_nofit", s.p_nofit.unwrap_or(0.05))?;
    let version_on = 1usize; // `activate` is the second state of a version node.
    if let Some(fit) = &s.fit {
        // Parents (version, fit): the fit node says whether the version can be placed.
        let yes = c.hm.states[fit]
            .iter()
            .position(|x| x == "yes")
            .filter(|_| c.hm.states[fit].len() == 2)
            .ok_or_else(|| {
                c.err(
                    c.entry("fit"),
                    format!("`{fit}` must have the states `no`, `yes`"),
                )
            })?;
        return Ok(Box::new(move |a| {
            let p = match (a[0] == version_on, a[1] == yes) {
                (false, _) => 0.0,
                (true, true) => p_fit,
                (true, false) => p_nofit,
            };
            Ok(vec![1.0 - p, p])
        }));
    }
    if s.implementations.is_empty() {
        return Err(c.err(
            c.entry("implementations"),
            "an activation node needs implementations (or a `variant` of params/variants.toml)",
        ));
    }
    let tiles_node = s.tiles.clone().unwrap_or_default();
    let counts = tile_counts(c, &tiles_node)?;
    let numeric = s.implementations.iter().any(|im| im.cpu_per_fps.is_some());
    let has_perf = s.performance.is_some();
    let fits_rule = if numeric {
        catalogue_fits(
            c,
            s.cpu.as_deref(),
            s.performance.as_deref(),
            &s.implementations,
            Bound::Conservative,
        )?
    } else {
        hand_written_fits(c, s)?
    };
    Ok(Box::new(move |a| {
        if a[0] != version_on {
            return Ok(vec![1.0, 0.0]);
        }
        let perf = if has_perf { a[3] } else { 0 };
        let fits = fits_rule(counts[a[1]], a[2], perf);
        let p = if fits { p_fit } else { p_nofit };
        Ok(vec![1.0 - p, p])
    }))
}

/// Which end of the bins the catalogue check reads.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Bound {
    /// Lowest headroom and highest rate of the states: fits for every value in them.
    Conservative,
    /// Highest headroom and lowest rate of the states: fits for some value in them.
    Optimistic,
}

/// Tile counts of the node's states.
fn tile_counts(c: &NodeCtx, tiles_node: &str) -> Result<Vec<u32>, SpecError> {
    c.hm.states[tiles_node]
        .iter()
        .map(|s| s.parse::<u32>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            c.err(
                c.entry("tiles"),
                format!("states of `{tiles_node}` must be tile counts"),
            )
        })
}

/// Catalogue-compiled: an implementation fits when its tiles are free, it reaches the rate of
/// the required-rate state, and its CPU share at that rate is within the headroom of the
/// headroom state; `bound` says which end of each state is read (a headroom state is named by
/// its lower edge and ends at the next one; a rate state is named by its upper edge and starts
/// at the one before).
fn catalogue_fits(
    c: &NodeCtx,
    cpu_node: Option<&str>,
    perf_node: Option<&str>,
    implementations: &[Implementation],
    bound: Bound,
) -> Result<FitsRule, SpecError> {
    let cpu_node = cpu_node.unwrap_or_default();
    let parse = |node: &str, key: &str| -> Result<Vec<f64>, SpecError> {
        c.hm.states[node]
            .iter()
            .map(|s| s.parse::<f64>().ok().filter(|x| x.is_finite()))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| c.err(c.entry(key), format!("states of `{node}` must be numbers")))
    };
    let lower_headroom = parse(cpu_node, "cpu")?;
    let perf_node = perf_node.ok_or_else(|| {
        c.err(
            c.entry("performance"),
            "a catalogue-compiled node needs a required-rate `performance` node",
        )
    })?;
    let upper_rate = parse(perf_node, "performance")?;
    let (headroom, rate): (Vec<f64>, Vec<f64>) = match bound {
        Bound::Conservative => (lower_headroom, upper_rate),
        Bound::Optimistic => (
            (0..lower_headroom.len())
                .map(|i| lower_headroom.get(i + 1).copied().unwrap_or(f64::INFINITY))
                .collect(),
            (0..upper_rate.len())
                .map(|i| if i == 0 { 0.0 } else { upper_rate[i - 1] })
                .collect(),
        ),
    };
    let impls: Vec<(u32, f64, f64)> = implementations
        .iter()
        .map(|im| {
            (
                im.tiles,
                im.cpu_per_fps.unwrap_or(0.0),
                im.max_fps.unwrap_or(f64::INFINITY),
            )
        })
        .collect();
    Ok(Box::new(move |free, cpu, perf| {
        let fps = rate[perf];
        impls.iter().any(|&(t, per_fps, max_fps)| {
            let share = per_fps * fps;
            free >= t
                && max_fps * (1.0 + 1e-9) >= fps
                && (share <= 0.0 || share <= headroom[cpu] + 1e-9)
        })
    }))
}

/// Fit (no/yes) over (tiles, cpu, performance): `yes` when every value in the states fits
/// (conservative check), `no` when none does (optimistic check fails), `p_unsure` between.
fn fit(c: &NodeCtx, s: &FitNode) -> Result<RowRule, SpecError> {
    let p_unsure = c.prob("p_unsure", s.p_unsure.unwrap_or(0.5))?;
    if s.variant.is_none() || s.implementations.is_empty() {
        return Err(c.err(
            c.entry("variant"),
            "a fit node needs a `variant` of params/variants.toml",
        ));
    }
    if c.hm.states[c.n] != ["no", "yes"] {
        return Err(c.err(c.entry("states"), "a fit node's states are `no`, `yes`"));
    }
    let tiles = tile_counts(c, s.tiles.as_deref().unwrap_or_default())?;
    let (cpu, perf) = (s.cpu.as_deref(), s.performance.as_deref());
    let sure = catalogue_fits(c, cpu, perf, &s.implementations, Bound::Conservative)?;
    let maybe = catalogue_fits(c, cpu, perf, &s.implementations, Bound::Optimistic)?;
    Ok(Box::new(move |a| {
        let free = tiles[a[0]];
        let p = if sure(free, a[1], a[2]) {
            1.0
        } else if maybe(free, a[1], a[2]) {
            p_unsure
        } else {
            0.0
        };
        Ok(vec![1.0 - p, p])
    }))
}

/// Hand-written: each implementation names the highest CPU state it fits in and whether it is
/// fast enough when the performance node demands speed.
fn hand_written_fits(c: &NodeCtx, s: &ActivationNode) -> Result<FitsRule, SpecError> {
    let n = c.n;
    let cpu_node = s.cpu.clone().unwrap_or_default();
    let has_perf = s.performance.is_some();
    let mut impls = Vec::new();
    for (i, im) in s.implementations.iter().enumerate() {
        let cpu = c.hm.state_idx(
            &cpu_node,
            &im.cpu,
            format!("node.{n}.implementations[{i}].cpu"),
        )?;
        impls.push((im.tiles, cpu, im.fast));
    }
    Ok(Box::new(move |free, cpu, perf| {
        let need_fast = has_perf && perf != 0;
        impls
            .iter()
            .any(|&(t, c, fast)| free >= t && cpu <= c && (fast || !need_fast))
    }))
}
