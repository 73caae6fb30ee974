//! The `bn_trials` table: the trials of the health BN's countable CPT rows that `companion
//! calibrate` counts (companion/src/calibrate/cpt.rs), one row each, and the learned rows from
//! their counts as SQL aggregates (`companion-fleet calibrate`, docs/fleet.md "Calibration").
//!
//! Telling a trial is not an aggregate: a record is a trial of a row when its actions attempt the
//! application and the run has not yet succeeded at it (the world stops trying), its row is its
//! parents' evidence (a tracking step's: the errors' more likely states under the shipped
//! noisy-OR rows), and its success is the world's outcome after the cycle; a state machine over
//! the run's records in order, with the params' mission states and health rows. So ingest runs
//! calibrate's own counter (`CptCounts::trials`) over each run's records and keeps its trials;
//! the counts per row (successes, trials) are SQL, and the learned row is calibrate's Dirichlet
//! mean of them with the shipped row as the prior.

use crate::calibrate::{i64_at, rows};
use crate::export::RunKey;
use crate::table::{Kind, TableWriter};
use anyhow::Context;
use arrow::array::AsArray;
use companion::calibrate::cpt::{CptCounts, LearnedRow, Row, dirichlet_mean, simulated_outcome};
use companion::calibrate::shipped::Shipped;
use companion_core::record::DecisionRecord;
use datafusion::prelude::SessionContext;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;

/// The table's columns (docs/fleet.md "bn_trials").
pub fn columns() -> Vec<(String, Kind)> {
    [
        ("run_id", Kind::Str),
        ("vehicle", Kind::Str),
        ("cycle", Kind::I64),
        ("record_idx", Kind::I64),
        ("node", Kind::Str),
        ("parents", Kind::Str),
        ("success_state", Kind::Str),
        ("success", Kind::Bool),
    ]
    .iter()
    .map(|(n, k)| (n.to_string(), *k))
    .collect()
}

/// The params trials are told against: the default params (`$COMPANION_PARAMS`, else the
/// workspace's `params/`), loaded once per process; the error is kept as text for every run.
fn shipped() -> Result<&'static Shipped, &'static str> {
    static SHIPPED: OnceLock<Result<Shipped, String>> = OnceLock::new();
    SHIPPED
        .get_or_init(|| {
            let dir = companion::params::default_params_dir();
            Shipped::load(&dir).map_err(|e| format!("loading params {}: {e}", dir.display()))
        })
        .as_ref()
        .map_err(String::as_str)
}

/// A row (parent -> state, in calibrate's order) as the `parents` column's text: a JSON array of
/// `[parent, state]` pairs, one text per row so SQL groups by it.
fn row_text(row: &Row) -> String {
    serde_json::to_string(row).unwrap_or_default()
}

/// The run's trials, written as its records are read (`add`, in order), then `finish`.
pub struct TrialWriter {
    w: TableWriter,
    /// The params, or why they did not load (then no trial is written: `runs.trials_error`).
    shipped: Result<&'static Shipped, &'static str>,
    parents: BTreeMap<String, Vec<String>>,
    counts: CptCounts,
    failed: Option<String>,
}

impl TrialWriter {
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let shipped = shipped();
        let parents = shipped.map(|s| s.rows.parents()).unwrap_or_default();
        Ok(TrialWriter {
            w: TableWriter::create(path, &columns())?,
            shipped,
            parents,
            counts: CptCounts::default(),
            failed: None,
        })
    }

    /// The trials of the run's `idx`th record (a `simulate` record: its world's outcome).
    pub fn add(&mut self, key: &RunKey, r: &DecisionRecord, idx: u64) -> anyhow::Result<()> {
        let Ok(shipped) = self.shipped else {
            return Ok(());
        };
        let Some((events, after)) = simulated_outcome(r) else {
            return Ok(());
        };
        let trials = (self.counts).trials(
            r,
            &events,
            after,
            &shipped.states,
            &shipped.rows,
            &self.parents,
        );
        for t in trials {
            self.w.push(vec![
                key.run_id.as_str().into(),
                key.vehicle.as_str().into(),
                r.cycle.into(),
                idx.into(),
                t.node.as_str().into(),
                row_text(&t.when).into(),
                t.success_state.into(),
                t.success.into(),
            ])?;
        }
        Ok(())
    }

    /// Mark the run's trials unknown (a corrupted line: calibrate refuses the run).
    pub fn fail(&mut self, why: String) {
        self.failed.get_or_insert(why);
    }

    /// The trials written, or why the run has none calibrate would count.
    pub fn finish(self) -> anyhow::Result<Result<u64, String>> {
        let n = self.w.finish()?;
        Ok(match (self.shipped, self.failed) {
            (Err(e), _) => Err(e.to_string()),
            (_, Some(e)) => Err(e),
            _ => Ok(n),
        })
    }
}

/// The counts per row as SQL: successes and trials per node, row and success state.
pub fn counts_sql(vehicle_filter: &str) -> String {
    format!(
        "SELECT node, parents, success_state, \
           SUM(CASE WHEN success THEN 1 ELSE 0 END) AS successes, COUNT(*) AS trials \
         FROM bn_trials WHERE true{vehicle_filter} \
         GROUP BY node, parents, success_state ORDER BY node, parents, success_state"
    )
}

/// The counts `counts_sql` gives, as JSON rows (`calibrate --statistics`: what another engine
/// compares): `node`, `parents`, `success_state`, `successes`, `trials`.
pub async fn counts_json(ctx: &SessionContext, sql: &str) -> anyhow::Result<serde_json::Value> {
    let mut out = Vec::new();
    for b in rows(ctx, sql).await? {
        let text = |c: usize| b.column(c).as_string::<i32>();
        let (node, row, state) = (text(0), text(1), text(2));
        for r in 0..b.num_rows() {
            out.push(serde_json::json!({
                "node": node.value(r),
                "parents": row.value(r),
                "success_state": state.value(r),
                "successes": i64_at(&b, "successes", r)?.unwrap_or(0),
                "trials": i64_at(&b, "trials", r)?.unwrap_or(0),
            }));
        }
    }
    Ok(serde_json::Value::Array(out))
}

/// The learned rows from the counts `counts_sql` gives, as calibrate learns them: per row, the
/// shipped P(success state) worth the prior's trials, then the counts (its Dirichlet mean); in
/// calibrate's order (the error nodes' rows, then the versions', each by node and row).
pub async fn learned_rows(
    ctx: &SessionContext,
    shipped: &Shipped,
    sql: &str,
) -> anyhow::Result<Vec<LearnedRow>> {
    let mut out = Vec::new();
    for b in rows(ctx, sql).await? {
        let text = |c: usize| b.column(c).as_string::<i32>();
        let (node, row, state) = (text(0), text(1), text(2));
        for r in 0..b.num_rows() {
            let when: Row = serde_json::from_str(row.value(r)).with_context(|| {
                format!(
                    "bn_trials.parents {:?}: not [[parent, state], ...]",
                    row.value(r)
                )
            })?;
            let k = i64_at(&b, "successes", r)?.unwrap_or(0).max(0) as u64;
            let n = i64_at(&b, "trials", r)?.unwrap_or(0).max(0) as u64;
            let (success_state, success_index, p0) = match state.value(r) {
                "absent" => ("absent", 0, shipped.rows.p_absent(node.value(r), &when)),
                _ => ("activate", 1, shipped.rows.p_activate(node.value(r), &when)),
            };
            out.push(LearnedRow {
                node: node.value(r).to_string(),
                when,
                success_state,
                success_index,
                shipped: p0,
                successes: k,
                trials: n,
                learned: dirichlet_mean(p0, k, n),
            });
        }
    }
    out.sort_by(|a, b| {
        (a.success_index, &a.node, &a.when).cmp(&(b.success_index, &b.node, &b.when))
    });
    Ok(out)
}

/// The learned rows as `--json` gives them.
pub fn learned_json(rows: &[LearnedRow]) -> serde_json::Value {
    (rows.iter())
        .map(|r| {
            serde_json::json!({
                "node": r.node,
                "when": r.when,
                "success_state": r.success_state,
                "shipped": r.shipped,
                "successes": r.successes,
                "trials": r.trials,
                "learned": r.learned,
            })
        })
        .collect()
}

/// The learned rows of the runs selected by `vehicle_filter`, or the error naming a run whose
/// trials are unknown (the params did not load at ingest, a corrupted line).
pub async fn bn_rows(
    ctx: &SessionContext,
    shipped: &Shipped,
    vehicle_filter: &str,
) -> anyhow::Result<Result<Vec<LearnedRow>, String>> {
    let bad = rows(
        ctx,
        &format!(
            "SELECT source, trials_error FROM runs WHERE trials_error IS NOT NULL{vehicle_filter} \
             ORDER BY source LIMIT 1"
        ),
    )
    .await?;
    if let Some(b) = bad.iter().find(|b| b.num_rows() > 0) {
        let (src, why) = (
            b.column(0).as_string::<i32>(),
            b.column(1).as_string::<i32>(),
        );
        return Ok(Err(format!("run {}: {}", src.value(0), why.value(0))));
    }
    Ok(Ok(
        learned_rows(ctx, shipped, &counts_sql(vehicle_filter)).await?
    ))
}
