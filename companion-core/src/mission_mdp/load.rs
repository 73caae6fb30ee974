//! One MDP file loaded: its shape checked (states, actions), its transition and reward
//! expressions parsed, reachability checked, the engine model compiled, then every row checked
//! to be a distribution at fixed and pseudo-random probability points.

use super::expr::Expr;
use super::schema::MdpFile;
use super::{
    LOAD_SUM_TOLERANCE, MAX_ACTIONS, MAX_STATES, MissionMdp, RANDOM_CHECK_POINTS, Solved, err,
};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use mdp_engine::MdpBuilder;
use std::collections::{BTreeMap, VecDeque};
use std::path::Path;

/// One parsed transition row: state, action, (next state, probability), entry path for errors.
type Row = (usize, usize, Vec<(usize, Expr)>, String);

/// Per policy: its name, the reward expression of each action, the entering reward of each
/// state.
struct Rewards {
    policies: Vec<String>,
    action: Vec<Vec<Expr>>,
    enter: Vec<Vec<Option<Expr>>>,
}

/// The probability names the expressions use, in first-use order; only `known` names get one.
struct Slots<'a> {
    known: &'a [&'a str],
    vars: Vec<String>,
}

impl Slots<'_> {
    fn slot(&mut self, name: &str) -> Option<usize> {
        if !self.known.contains(&name) {
            return None;
        }
        Some(self.vars.iter().position(|v| v == name).unwrap_or_else(|| {
            self.vars.push(name.to_string());
            self.vars.len() - 1
        }))
    }

    fn parse(&mut self, text: &str) -> Result<Expr, String> {
        Expr::parse(text, &mut |n| self.slot(n))
    }
}

/// Load, validate and compile one MDP file.
pub fn load_mdp(
    params: &ParamsFiles,
    path: &Path,
    known: &[&str],
    check_point: &BTreeMap<String, f64>,
) -> Result<MissionMdp, SpecError> {
    let f: MdpFile = read_toml(params, path)?;
    let initial = check_shape(path, &f)?;
    let mut slots = Slots {
        known,
        vars: Vec::new(),
    };
    let rows = parse_transitions(path, &f, &mut slots)?;
    check_reachable(path, &f, initial, &rows)?;
    let rewards = parse_rewards(path, &f, &mut slots)?;
    let mut m = compile(path, &f, initial, slots.vars, &rows, rewards)?;
    check_rows(path, &f, &mut m, &rows, check_point)?;
    Ok(m)
}

fn state(f: &MdpFile, s: &str) -> Option<usize> {
    f.states.iter().position(|x| x == s)
}

fn action(f: &MdpFile, a: &str) -> Option<usize> {
    f.action.iter().position(|x| x.name == a)
}

/// States and actions: present, within bounds, each once; returns the initial state.
fn check_shape(path: &Path, f: &MdpFile) -> Result<usize, SpecError> {
    if f.states.is_empty() {
        return Err(err(path, "states", "no state"));
    }
    // The solver's tables grow with states^2 x actions: bounded before anything is allocated.
    if f.states.len() > MAX_STATES {
        return Err(err(
            path,
            "states",
            format!("{} states: an MDP has at most {MAX_STATES}", f.states.len()),
        ));
    }
    if f.action.len() > MAX_ACTIONS {
        return Err(err(
            path,
            "action",
            format!(
                "{} actions: an MDP has at most {MAX_ACTIONS}",
                f.action.len()
            ),
        ));
    }
    for (i, s) in f.states.iter().enumerate() {
        if f.states[..i].contains(s) {
            return Err(err(
                path,
                format!("states[{i}]"),
                format!("state '{s}' listed twice"),
            ));
        }
    }
    let initial = state(f, &f.initial)
        .ok_or_else(|| err(path, "initial", format!("unknown state '{}'", f.initial)))?;
    if f.action.is_empty() {
        return Err(err(path, "action", "no action"));
    }
    for (i, a) in f.action.iter().enumerate() {
        if f.action[..i].iter().any(|b| b.name == a.name) {
            return Err(err(
                path,
                format!("action[{i}].name"),
                format!("action '{}' declared twice", a.name),
            ));
        }
        if a.does.is_empty() {
            return Err(err(
                path,
                format!("action[{i}].does"),
                "empty: an action must stand for primitive actions",
            ));
        }
    }
    Ok(initial)
}

/// Each `transitions.STATE."ACTION"` table as a row of (next state, probability expression).
fn parse_transitions(path: &Path, f: &MdpFile, slots: &mut Slots) -> Result<Vec<Row>, SpecError> {
    let mut rows: Vec<Row> = Vec::new();
    for (s_name, acts) in &f.transitions {
        let s = state(f, s_name).ok_or_else(|| {
            err(
                path,
                format!("transitions.{s_name}"),
                format!("unknown state '{s_name}'"),
            )
        })?;
        for (a_name, nexts) in acts {
            let entry = format!("transitions.{s_name}.\"{a_name}\"");
            let a = action(f, a_name)
                .ok_or_else(|| err(path, &entry, format!("unknown action '{a_name}'")))?;
            if nexts.is_empty() {
                return Err(err(path, &entry, "action has no transition"));
            }
            let mut tr = Vec::new();
            for (n_name, p) in nexts {
                let n = state(f, n_name).ok_or_else(|| {
                    err(
                        path,
                        format!("{entry}.{n_name}"),
                        format!("unknown state '{n_name}'"),
                    )
                })?;
                let e = slots
                    .parse(&p.text())
                    .map_err(|r| err(path, format!("{entry}.{n_name}"), r))?;
                tr.push((n, e));
            }
            rows.push((s, a, tr, entry));
        }
    }
    Ok(rows)
}

/// Every state is reachable from the initial state (structurally).
fn check_reachable(
    path: &Path,
    f: &MdpFile,
    initial: usize,
    rows: &[Row],
) -> Result<(), SpecError> {
    let mut reach = vec![false; f.states.len()];
    reach[initial] = true;
    let mut queue = VecDeque::from([initial]);
    while let Some(s) = queue.pop_front() {
        for (_, _, tr, _) in rows.iter().filter(|r| r.0 == s) {
            for (n, _) in tr {
                if !reach[*n] {
                    reach[*n] = true;
                    queue.push_back(*n);
                }
            }
        }
    }
    if let Some(u) = reach.iter().position(|r| !r) {
        return Err(err(
            path,
            format!("states[{u}]"),
            format!(
                "state '{}' unreachable from initial state '{}'",
                f.states[u], f.initial
            ),
        ));
    }
    Ok(())
}

/// Each policy's rewards: one per action (all required), entering rewards per state.
fn parse_rewards(path: &Path, f: &MdpFile, slots: &mut Slots) -> Result<Rewards, SpecError> {
    if f.reward.is_empty() {
        return Err(err(path, "reward", "no policy rewards"));
    }
    let mut out = Rewards {
        policies: Vec::new(),
        action: Vec::new(),
        enter: Vec::new(),
    };
    for (pol, spec) in &f.reward {
        let mut ar: Vec<Option<Expr>> = vec![None; f.action.len()];
        for (a_name, r) in &spec.action {
            let entry = format!("reward.{pol}.action.\"{a_name}\"");
            let a = action(f, a_name)
                .ok_or_else(|| err(path, &entry, format!("unknown action '{a_name}'")))?;
            ar[a] = Some(slots.parse(&r.text()).map_err(|r| err(path, &entry, r))?);
        }
        if let Some(a) = ar.iter().position(|x| x.is_none()) {
            return Err(err(
                path,
                format!("reward.{pol}.action"),
                format!("no reward for action '{}'", f.action[a].name),
            ));
        }
        let mut er: Vec<Option<Expr>> = vec![None; f.states.len()];
        for (s_name, r) in &spec.enter {
            let entry = format!("reward.{pol}.enter.{s_name}");
            let s = state(f, s_name)
                .ok_or_else(|| err(path, &entry, format!("unknown state '{s_name}'")))?;
            er[s] = Some(slots.parse(&r.text()).map_err(|r| err(path, &entry, r))?);
        }
        out.policies.push(pol.clone());
        out.action.push(ar.into_iter().flatten().collect());
        out.enter.push(er);
    }
    Ok(out)
}

/// The engine model (probabilities filled per instantiation) and the expressions behind its
/// transitions and choice rewards.
fn compile(
    path: &Path,
    f: &MdpFile,
    initial: usize,
    vars: Vec<String>,
    rows: &[Row],
    rewards: Rewards,
) -> Result<MissionMdp, SpecError> {
    let mut b = MdpBuilder::new(f.states.len(), f.action.len());
    for (s, a, tr, _) in rows {
        let t: Vec<(usize, f64)> = tr.iter().map(|(n, _)| (*n, 0.0)).collect();
        b.choice(*s, *a, 0.0, &t);
    }
    let mdp = b
        .build_unchecked()
        .map_err(|e| err(path, "transitions", e.to_string()))?;
    let mut trans_expr = vec![Expr::constant(0.0); mdp.n_transitions()];
    let mut choice_reward: Vec<Vec<Expr>> =
        vec![vec![Expr::constant(0.0); mdp.n_choices()]; rewards.policies.len()];
    for (s, a, tr, _) in rows {
        let c = mdp.choice_index(*s, *a).expect("built from these rows");
        for (t, (_, e)) in mdp.transition_range(c).zip(tr) {
            trans_expr[t] = e.clone();
        }
        for (p, ar) in rewards.action.iter().enumerate() {
            choice_reward[p][c] = ar[*a].clone();
        }
    }
    let values = vec![0.0; vars.len()];
    let n_vars = vars.len();
    let mut by_name: Vec<usize> = (0..vars.len()).collect();
    by_name.sort_by(|&a, &b| vars[a].cmp(&vars[b]));
    let input_names = (by_name.iter())
        .map(|&k| vars[k].clone())
        .collect::<Vec<_>>()
        .into();
    Ok(MissionMdp {
        name: f.name.clone(),
        file: path.to_path_buf(),
        states: f.states.clone(),
        initial,
        actions: f.action.iter().map(|a| a.name.clone()).collect(),
        does: f.action.iter().map(|a| a.does.clone()).collect(),
        vars,
        by_name,
        input_names,
        values,
        trans_expr,
        policies: rewards.policies,
        choice_reward,
        enter_reward: rewards.enter,
        enter_value: vec![0.0; f.states.len()],
        mdp,
        solved: Solved::new(f.states.len(), n_vars),
    })
}

/// Row sums at: all 0, all 1, the check point (missing names at 0.5), pseudo-random points;
/// rewards finite at each. Leaves the model instantiated at the check point, first policy.
fn check_rows(
    path: &Path,
    f: &MdpFile,
    m: &mut MissionMdp,
    rows: &[Row],
    check_point: &BTreeMap<String, f64>,
) -> Result<(), SpecError> {
    let k = m.vars.len();
    let mut points: Vec<(String, Vec<f64>)> = vec![
        ("all probabilities 0".into(), vec![0.0; k]),
        ("all probabilities 1".into(), vec![1.0; k]),
        (
            "the check point".into(),
            m.vars
                .iter()
                .map(|v| check_point.get(v).copied().unwrap_or(0.5))
                .collect(),
        ),
    ];
    let mut rng = SplitMix64(0x0005_eed0_fb0f_u64);
    for i in 0..RANDOM_CHECK_POINTS {
        points.push((
            format!("random point {i}"),
            (0..k).map(|_| rng.unit()).collect(),
        ));
    }
    for (label, pt) in &points {
        m.values.copy_from_slice(pt);
        for (_, _, tr, entry) in rows {
            check_row(path, f, m, tr, entry, label, pt)?;
        }
        for pi in 0..m.policies.len() {
            m.fill(pi);
            if let Some(c) = m.mdp.rewards().iter().position(|r| !r.is_finite()) {
                return Err(err(
                    path,
                    format!("reward.{}", m.policies[pi]),
                    format!("reward of choice {c} not finite at {label}"),
                ));
            }
        }
    }
    m.values.copy_from_slice(&points[2].1);
    m.fill(0);
    Ok(())
}

/// One row at one point: a distribution (sum 1, each probability in [0, 1]).
fn check_row(
    path: &Path,
    f: &MdpFile,
    m: &MissionMdp,
    tr: &[(usize, Expr)],
    entry: &str,
    label: &str,
    pt: &[f64],
) -> Result<(), SpecError> {
    // Each probability evaluated once per point (this check is most of a params load):
    // the row sum, and the first entry outside [0, 1], reported after the sum as before.
    let mut sum = 0.0;
    let mut outside: Option<(usize, f64)> = None;
    for (n, e) in tr {
        let p = e.eval(pt);
        sum += p;
        if outside.is_none() && !(-LOAD_SUM_TOLERANCE..=1.0 + LOAD_SUM_TOLERANCE).contains(&p) {
            outside = Some((*n, p));
        }
    }
    if (sum - 1.0).abs() > LOAD_SUM_TOLERANCE || !sum.is_finite() {
        return Err(err(
            path,
            entry,
            format!(
                "probabilities sum to {sum} at {label} ({})",
                fmt_point(&m.vars, pt)
            ),
        ));
    }
    if let Some((n, p)) = outside {
        return Err(err(
            path,
            format!("{entry}.{}", f.states[n]),
            format!(
                "probability {p} outside [0, 1] at {label} ({})",
                fmt_point(&m.vars, pt)
            ),
        ));
    }
    Ok(())
}

fn fmt_point(vars: &[String], pt: &[f64]) -> String {
    vars.iter()
        .zip(pt)
        .map(|(n, v)| format!("{n}={v:.3}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Tiny deterministic generator for the load-time check points (fixed seed: reproducible).
struct SplitMix64(u64);
impl SplitMix64 {
    fn unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}
