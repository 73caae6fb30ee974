//! Learning the health BN's CPT rows the logs can teach (BFM paper sections 4.1 and 8: CPTs
//! "can be updated online by means of learning techniques"), by counting with a Dirichlet prior
//! built from the shipped rows (docs/calibrate.md).
//!
//! A row can be counted when its parents' states and its child's outcome are both in the
//! records. The error nodes of the applications whose outcome the world records are such rows:
//! an error node `U` with context parents (evidence every cycle) is "absent" on a trial that
//! succeeded and "present" on one that failed. `simulate`'s records hold each cycle's world
//! outcome (`vehicle.world_events_after`), so each attempt of the application is one trial:
//!
//! | node (params/health/applications.toml) | trial: the cycle's actions include | success |
//! |---|---|---|
//! | `U_detection_fail` | detect_target at the last waypoint | target detected |
//! | `U_zone_t_fail` | search_zone_t, the zone not yet found | T zone found |
//! | `U_zone_e_fail` | search_emergency_zone, the area not yet found | emergency zone found |
//!
//! Learned row: `(N0 · shipped + counts) / (N0 + n)` with `N0` = [`PRIOR_PSEUDO_COUNTS`]: the
//! shipped row is worth that many trials.

use companion_core::action_role::ActionRole;
use companion_core::mission::{MissionStates, RouteRole};
use companion_core::record::{DecisionRecord, Event};
use companion_core::spec::{ParamsFiles, SpecError};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The shipped row's weight, in trials (pseudo-counts of the Dirichlet prior).
pub const PRIOR_PSEUDO_COUNTS: f64 = 10.0;

/// The health file of the countable rows, relative to the params directory.
pub const APPLICATIONS_FILE: &str = "health/applications.toml";

/// One countable node: its name, the trial's action role and the event that is its success.
struct Countable {
    node: &'static str,
    role: ActionRole,
    success: Event,
}

const COUNTABLE: [Countable; 3] = [
    Countable {
        node: "U_detection_fail",
        role: ActionRole::DetectTarget,
        success: Event::TargetDetected,
    },
    Countable {
        node: "U_zone_t_fail",
        role: ActionRole::SearchZone,
        success: Event::TZoneFound,
    },
    Countable {
        node: "U_zone_e_fail",
        role: ActionRole::SearchEmergencyZone,
        success: Event::EmergencyZoneFound,
    },
];

/// Parent (or error) -> state: one CPT row's condition.
pub type Row = Vec<(String, String)>;
/// (successes, trials) of one row.
type Tally = (u64, u64);

/// Counts per node, per parent-state row: (successes, trials).
#[derive(Default)]
pub struct CptCounts {
    counts: BTreeMap<&'static str, BTreeMap<Row, Tally>>,
    /// Tracking steps per version node and error row: (target kept, steps).
    versions: BTreeMap<(String, Row), Tally>,
    /// Per node: the application has succeeded this run (the world stops trying it).
    done: BTreeMap<&'static str, bool>,
    /// An obstacle was avoided this run: the world searches no T zone after it.
    avoided: bool,
}

/// A learned row and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedRow {
    pub node: String,
    /// Parent -> state.
    pub when: Vec<(String, String)>,
    /// The child's state a success stands for, and its index in the node's states.
    pub success_state: &'static str,
    pub success_index: usize,
    /// P(success state) of the shipped row.
    pub shipped: f64,
    pub successes: u64,
    pub trials: u64,
    /// P(success state) learned.
    pub learned: f64,
}

impl CptCounts {
    /// A new run begins: forget what the last one found.
    pub fn start_run(&mut self) {
        self.done.clear();
        self.avoided = false;
    }

    /// Count the trials of one record, with the parents' states from `parents_of`.
    pub fn add(
        &mut self,
        r: &DecisionRecord,
        states: &MissionStates,
        shipped: &ShippedRows,
        parents_of: &BTreeMap<String, Vec<String>>,
    ) {
        let Some((events, state_after)) = simulated_outcome(r) else {
            return;
        };
        for t in self.trials(r, &events, state_after, states, shipped, parents_of) {
            let tally = match COUNTABLE.iter().find(|c| c.node == t.node) {
                Some(c) => self
                    .counts
                    .entry(c.node)
                    .or_default()
                    .entry(t.when)
                    .or_default(),
                None => self.versions.entry((t.node, t.when)).or_default(),
            };
            tally.0 += u64::from(t.success);
            tally.1 += 1;
        }
    }

    /// The trials one record is, given the events that followed its cycle (`simulate`: the
    /// world's `world_events_after`; `fly`: the next cycle's observed events) and the mission
    /// state after it when known. Remembers what the run has found (a detected target is not
    /// tried again), so records are given in order, each once. `calibrate` and the in-flight
    /// learning (`learn_cpt`) count the same trials.
    pub fn trials(
        &mut self,
        r: &DecisionRecord,
        events: &[Event],
        state_after: Option<&str>,
        states: &MissionStates,
        shipped: &ShippedRows,
        parents_of: &BTreeMap<String, Vec<String>>,
    ) -> Vec<Trial> {
        let mut out = Vec::new();
        let acts: Vec<&str> = r.actions.iter().collect();
        let roles = states.actions();
        let at_last_wp = states.route().is(RouteRole::LastWaypoint, &r.state);
        for c in &COUNTABLE {
            let trial = roles.any(&acts, c.role)
                && !self.done.get(c.node).copied().unwrap_or(false)
                && match c.role {
                    ActionRole::DetectTarget => at_last_wp,
                    ActionRole::SearchZone => !self.avoided,
                    _ => true,
                };
            if !trial {
                continue;
            }
            let Some(parents) = parents_of.get(c.node) else {
                continue;
            };
            let Some(row) = parents
                .iter()
                .map(|p| r.evidence.get(p).map(|s| (p.clone(), s.to_string())))
                .collect::<Option<Vec<_>>>()
            else {
                continue; // a parent without evidence: the row is unknown
            };
            let ok = events.contains(&c.success);
            out.push(Trial {
                node: c.node.to_string(),
                when: row,
                success_state: "absent",
                success_index: 0,
                success: ok,
            });
            if ok {
                self.done.insert(c.node, true);
            }
        }
        if events.contains(&Event::ObstacleAvoided) {
            self.avoided = true;
        }
        out.extend(tracking_trial(r, events, state_after, states, shipped));
        out
    }

    /// The learned rows, each against its shipped row.
    pub fn learn(&self, shipped: &ShippedRows) -> Vec<LearnedRow> {
        let mut out = Vec::new();
        let learned = dirichlet_mean;
        for (node, rows) in &self.counts {
            for (when, &(k, n)) in rows {
                let p0 = shipped.p_absent(node, when);
                out.push(LearnedRow {
                    node: node.to_string(),
                    when: when.clone(),
                    success_state: "absent",
                    success_index: 0,
                    shipped: p0,
                    successes: k,
                    trials: n,
                    learned: learned(p0, k, n),
                });
            }
        }
        for ((node, when), &(k, n)) in &self.versions {
            let p0 = shipped.p_activate(node, when);
            out.push(LearnedRow {
                node: node.clone(),
                when: when.clone(),
                success_state: "activate",
                success_index: 1,
                shipped: p0,
                successes: k,
                trials: n,
                learned: learned(p0, k, n),
            });
        }
        out
    }
}

/// A tracking step with version `Vk` is a trial of `C_Vk`'s row at the errors' states: the
/// target kept (no `target lost`) is `activate`. The errors are hidden; each is taken in the
/// state its shipped noisy-OR row makes more likely under the cycle's context evidence
/// (docs/calibrate.md: hard assignment, an approximation).
fn tracking_trial(
    r: &DecisionRecord,
    events: &[Event],
    state_after: Option<&str>,
    states: &MissionStates,
    shipped: &ShippedRows,
) -> Option<Trial> {
    if !states.is_target_in_sight(&r.state) {
        return None;
    }
    let (_, version) = states.tracking_target(&r.actions)?;
    let node = format!("C_{version}");
    let errors = shipped.version_errors(&node)?;
    // The record's evidence by name, for the noisy-OR rows (a calibration tool: the edge).
    let evidence: BTreeMap<String, String> = (r.evidence.iter())
        .map(|(node, state)| (node.clone(), state.to_string()))
        .collect();
    let row = errors
        .iter()
        .map(|e| {
            shipped
                .map_error_state(e, &evidence)
                .map(|s| (e.clone(), s.to_string()))
        })
        .collect::<Option<Vec<_>>>()?;
    let lost = events.contains(&Event::TargetLost);
    // A step that re-detects a lost target (`simulate`'s world, docs/simulation.md) neither
    // keeps nor loses it: not a trial of the version's row. Kept: the step ended tracking.
    let kept = state_after.map_or(!lost, |after| states.is_tracking(after));
    if !kept && !lost {
        return None;
    }
    Some(Trial {
        node,
        when: row,
        success_state: "activate",
        success_index: 1,
        success: kept,
    })
}

/// A `simulate` record's outcome: the world's events after its cycle and the mission state
/// after it; `None` for a record without them (`fly`).
pub fn simulated_outcome(r: &DecisionRecord) -> Option<(Vec<Event>, Option<&str>)> {
    let after = r.vehicle.get("world_events_after")?.as_array()?;
    // Typed events (schema 2; a schema-1 log is migrated when read); one that does not read is
    // no outcome of this build's world.
    let events = after
        .iter()
        .filter_map(|e| serde_json::from_value(e.clone()).ok())
        .collect();
    let state_after = r
        .vehicle
        .get(companion_core::tracking::STATE_AFTER_KEY)
        .and_then(|v| v.as_str());
    Some((events, state_after))
}

/// One trial of a countable row: the node, the row (parent -> state), whether it succeeded.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    pub node: String,
    pub when: Row,
    /// The child's state a success stands for, and its index in the node's states.
    pub success_state: &'static str,
    pub success_index: usize,
    pub success: bool,
}

/// The Dirichlet (Beta) posterior mean of a two-state row: the prior `p0` worth
/// [`PRIOR_PSEUDO_COUNTS`] trials, then `k` successes in `n` trials.
pub fn dirichlet_mean(p0: f64, k: u64, n: u64) -> f64 {
    (PRIOR_PSEUDO_COUNTS * p0 + k as f64) / (PRIOR_PSEUDO_COUNTS + n as f64)
}

/// The shipped error nodes of the applications health file, to read rows from.
pub struct ShippedRows {
    file: PathBuf,
    nodes: Table,
    /// The FMEA rows: error -> its solutions.
    solutions_of: BTreeMap<String, Vec<String>>,
}

impl ShippedRows {
    /// Read `health/applications.toml` from the params.
    pub fn load(files: &ParamsFiles) -> Result<Self, SpecError> {
        let file = files.dir().join(APPLICATIONS_FILE);
        let t: Table = files
            .text(&file)?
            .parse()
            .map_err(|e| SpecError::new(&file, "-", format!("not TOML: {e}")))?;
        let nodes = t
            .get("node")
            .and_then(Value::as_table)
            .cloned()
            .unwrap_or_default();
        let strs = |v: Option<&Value>| -> Vec<String> {
            v.and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|x| x.as_str().map(String::from))
                        .collect()
                })
                .unwrap_or_default()
        };
        let mut solutions_of: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for row in t
            .get("fmea")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            if let Some(e) = row.get("error").and_then(Value::as_str) {
                solutions_of
                    .entry(e.into())
                    .or_default()
                    .extend(strs(row.get("solutions")));
            }
        }
        Ok(ShippedRows {
            file,
            nodes,
            solutions_of,
        })
    }

    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Each countable node's parents (its FMEA contexts: the keys of its `strength`, in the
    /// file's order; the rows are matched by name, so the order does not matter).
    pub fn parents(&self) -> BTreeMap<String, Vec<String>> {
        COUNTABLE
            .iter()
            .filter_map(|c| {
                let s = self.nodes.get(c.node)?.get("strength")?.as_table()?;
                Some((c.node.to_string(), s.keys().cloned().collect()))
            })
            .collect()
    }

    /// A version node's errors (its parents), when `node` is a version node.
    pub fn version_errors(&self, node: &str) -> Option<Vec<String>> {
        let n = self.nodes.get(node)?;
        if n.get("role").and_then(Value::as_str) != Some("version") {
            return None;
        }
        n.get("errors")?
            .as_array()?
            .iter()
            .map(|e| e.as_str().map(String::from))
            .collect()
    }

    /// The more likely state of error `e` under the contexts in `evidence` (its shipped
    /// noisy-OR row; a context without evidence, `A_small_roi`, weighted by its prior).
    pub fn map_error_state(
        &self,
        e: &str,
        evidence: &BTreeMap<String, String>,
    ) -> Option<&'static str> {
        let parents: Vec<String> = self
            .nodes
            .get(e)?
            .get("strength")?
            .as_table()?
            .keys()
            .cloned()
            .collect();
        let p = self.p_absent_marginal(e, &parents, evidence, &mut Vec::new())?;
        Some(if p >= 0.5 { "absent" } else { "present" })
    }

    fn p_absent_marginal(
        &self,
        e: &str,
        parents: &[String],
        evidence: &BTreeMap<String, String>,
        when: &mut Vec<(String, String)>,
    ) -> Option<f64> {
        let Some((first, rest)) = parents.split_first() else {
            return Some(self.p_absent(e, when));
        };
        if let Some(s) = evidence.get(first) {
            when.push((first.clone(), s.clone()));
            let p = self.p_absent_marginal(e, rest, evidence, when);
            when.pop();
            return p;
        }
        let node = self.nodes.get(first)?;
        let states = node.get("states")?.as_array()?;
        let prior = node.get("prior")?.as_array()?;
        let mut total = 0.0;
        for (s, w) in states.iter().zip(prior) {
            when.push((first.clone(), s.as_str()?.to_string()));
            let p = self.p_absent_marginal(e, rest, evidence, when);
            when.pop();
            total += w.as_float()? * p?;
        }
        Some(total)
    }

    /// P(activate | errors) of a shipped version node: its matching `override` row, else the
    /// version rule (docs/params/health.md): `p_ok · miss^(present errors it does not fix) ·
    /// extra^(its solutions whose error is absent)`.
    pub fn p_activate(&self, node: &str, when: &[(String, String)]) -> f64 {
        let Some(n) = self.nodes.get(node) else {
            return 0.5;
        };
        if let Some(p) = self.override_row(n, when) {
            return p.get(1).copied().unwrap_or(0.5);
        }
        let f = |k: &str, d: f64| n.get(k).and_then(Value::as_float).unwrap_or(d);
        let (p_ok, miss, extra) = (f("p_ok", 0.95), f("miss", 0.1), f("extra", 0.5));
        let sols: Vec<&str> = n
            .get("solutions")
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let fixes = |e: &str| {
            self.solutions_of
                .get(e)
                .is_some_and(|s| s.iter().any(|x| sols.contains(&x.as_str())))
        };
        when.iter()
            .fold(p_ok, |acc, (e, st)| match (st.as_str(), fixes(e)) {
                ("present", false) => acc * miss,
                ("absent", true) => acc * extra,
                _ => acc,
            })
    }

    fn state_index(&self, node: &str, state: &str) -> Option<usize> {
        let states = self.nodes.get(node)?.get("states")?.as_array()?;
        states.iter().position(|s| s.as_str() == Some(state))
    }

    /// P(absent | when) of the shipped node: its matching `override` row, else the noisy-OR
    /// rule (docs/params/health.md): `(1 - leak) · Π (1 - strength.PARENT[state])`.
    pub fn p_absent(&self, node: &str, when: &[(String, String)]) -> f64 {
        let Some(n) = self.nodes.get(node) else {
            return 0.5;
        };
        if let Some(p) = self.override_row(n, when) {
            return p.first().copied().unwrap_or(0.5);
        }
        let leak = n.get("leak").and_then(Value::as_float).unwrap_or(0.01);
        let strength = n.get("strength").and_then(Value::as_table);
        when.iter().fold(1.0 - leak, |acc, (parent, state)| {
            let i = self.state_index(parent, state).unwrap_or(0);
            let s = strength
                .and_then(|t| t.get(parent))
                .and_then(Value::as_array)
                .and_then(|a| a.get(i))
                .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|x| x as f64)))
                .unwrap_or(if i == 0 { 0.0 } else { 0.8 });
            acc * (1.0 - s)
        })
    }

    fn override_row(&self, n: &Value, when: &[(String, String)]) -> Option<Vec<f64>> {
        let rows = n.get("override")?.as_array()?;
        rows.iter().rev().find_map(|r| {
            let w = r.get("when")?.as_table()?;
            let all = w.iter().all(|(p, s)| {
                when.iter()
                    .any(|(wp, ws)| wp == p && Some(ws.as_str()) == s.as_str())
            });
            let p = r.get("p")?.as_array()?;
            all.then(|| p.iter().map(|v| v.as_float()).collect::<Option<Vec<f64>>>())?
        })
    }

    /// The node's `override` list with the learned rows added (replacing a shipped row with the
    /// same `when`), as the overlay writes it.
    pub fn overrides_with(&self, node: &str, learned: &[&LearnedRow]) -> Value {
        let mut rows: Vec<Value> = self
            .nodes
            .get(node)
            .and_then(|n| n.get("override"))
            .and_then(Value::as_array)
            .cloned()
            .unwrap_or_default();
        for l in learned {
            let when: Table = l
                .when
                .iter()
                .map(|(p, s)| (p.clone(), Value::String(s.clone())))
                .collect();
            rows.retain(|r| r.get("when").and_then(Value::as_table) != Some(&when));
            let p = round6(l.learned);
            let q = round6(1.0 - p);
            let pair = if l.success_index == 0 { [p, q] } else { [q, p] };
            let mut row = Table::new();
            row.insert("when".into(), Value::Table(when));
            row.insert("p".into(), Value::Array(pair.map(Value::from).to_vec()));
            rows.push(Value::Table(row));
        }
        Value::Array(rows)
    }
}

fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shipped() -> ShippedRows {
        let mut f = ParamsFiles::new("/p");
        f.insert(
            "/p/health/applications.toml",
            "[node.A_luminosity]\nstates = [\"low\", \"normal\"]\n[node.A_wind]\nstates = [\"calm\", \"strong\"]\n\
             [node.U_zone_t_fail]\nleak = 0.5\nstrength = { A_luminosity = [0.6, 0.0], A_wind = [0.0, 0.3] }\n\
             override = [{ when = { A_luminosity = \"low\", A_wind = \"strong\" }, p = [0.1, 0.9] }]\n",
        );
        ShippedRows::load(&f).unwrap()
    }

    fn w(l: &str, wd: &str) -> Vec<(String, String)> {
        vec![
            ("A_luminosity".into(), l.into()),
            ("A_wind".into(), wd.into()),
        ]
    }

    #[test]
    fn shipped_rows_follow_the_noisy_or_rule_and_overrides() {
        let s = shipped();
        assert!((s.p_absent("U_zone_t_fail", &w("normal", "calm")) - 0.5).abs() < 1e-12);
        assert!((s.p_absent("U_zone_t_fail", &w("normal", "strong")) - 0.35).abs() < 1e-12);
        assert!((s.p_absent("U_zone_t_fail", &w("low", "calm")) - 0.2).abs() < 1e-12);
        assert!((s.p_absent("U_zone_t_fail", &w("low", "strong")) - 0.1).abs() < 1e-12);
    }

    #[test]
    fn learned_row_is_the_dirichlet_posterior_mean() {
        let s = shipped();
        let mut c = CptCounts::default();
        c.counts
            .entry("U_zone_t_fail")
            .or_default()
            .insert(w("normal", "calm"), (45, 50));
        let rows = c.learn(&s);
        assert_eq!(rows.len(), 1);
        // (10 x 0.5 + 45) / (10 + 50)
        assert!((rows[0].learned - 50.0 / 60.0).abs() < 1e-12, "{rows:?}");
        let v = s.overrides_with("U_zone_t_fail", &[&rows[0]]);
        let a = v.as_array().unwrap();
        assert_eq!(a.len(), 2, "the shipped override is kept: {v}");
        assert_eq!(a[1]["p"][0].as_float(), Some(0.833333));
    }
}
