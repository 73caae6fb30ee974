//! The activity durations `companion calibrate RUN...` reports (companion/src/calibrate/
//! durations.rs): ingest writes each run's completed stretches of one activity, with how long
//! each lasted, as the table `stretches` (its rules are a state machine over the run's records
//! in order, as `bn_trials`' are), and the statistics are one SQL aggregate over that table: per
//! activity name, the count, Σd and Σd² of the stretches that lasted more than zero (the
//! sufficient statistics of the mean and spread), and the count and shortest of the others.
//! Spark SQL runs the same text.
//!
//! Why a table and not windows over `records` (LAG/LEAD per run, as until fleet schema 4): the
//! windows sort every record of the fleet by run and index, and that sort's memory grew with
//! the fleet (docs/performance.md, "Fleet"); the aggregate over `stretches` holds a few rows.
//!
//! The rules are calibrate's own, run here at ingest ([`Stretches`], which `Durations::add` feeds
//! on): records without an activity, or whose clock is not finite, are skipped; the clock is
//! `vehicle_time_s` when recorded, else `time_s`; a stretch starts at its first record and again
//! at each of its disarmed records (`armed` < 0.5), it ends at the next stretch's first record,
//! and the run's last stretch (cut) is not counted.

use crate::calibrate::{f64_at, i64_at, rows};
use crate::export::RunKey;
use crate::table::{Cell, Kind, TableWriter};
use arrow::array::AsArray;
use companion::calibrate::durations::{DurationStats, Stretches};
use companion_core::record::DecisionRecord;
use datafusion::prelude::SessionContext;
use std::collections::BTreeMap;
use std::path::Path;

/// Per activity name: the completed stretches' statistics, and (count, shortest) of those that
/// lasted zero or less.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct FleetDurations {
    pub stats: BTreeMap<String, DurationStats>,
    pub non_positive: BTreeMap<String, (u64, f64)>,
}

/// The `stretches` table's columns (docs/fleet.md "stretches").
fn columns() -> Vec<(String, Kind)> {
    [
        ("run_id", Kind::Str),
        ("vehicle", Kind::Str),
        ("cycle", Kind::I64),
        ("activity", Kind::Str),
        ("duration_s", Kind::F64),
    ]
    .iter()
    .map(|(n, k)| (n.to_string(), *k))
    .collect()
}

/// One run's completed stretches, fed its records in order.
pub struct StretchWriter {
    w: TableWriter,
    stretches: Stretches,
}

impl StretchWriter {
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        Ok(StretchWriter {
            w: TableWriter::create(path, &columns())?,
            stretches: Stretches::default(),
        })
    }

    pub fn add(&mut self, key: &RunKey, r: &DecisionRecord) -> anyhow::Result<()> {
        let Some((activity, duration_s)) = self.stretches.next(r) else {
            return Ok(());
        };
        let row: Vec<Cell> = vec![
            key.run_id.as_str().into(),
            key.vehicle.as_str().into(),
            (r.cycle as i64).into(),
            activity.as_str().into(),
            duration_s.into(),
        ];
        self.w.push(row)
    }

    /// Close the table (the run's last stretch, cut, is not written); the rows written.
    pub fn finish(self) -> anyhow::Result<u64> {
        self.w.finish()
    }
}

/// The query over `stretches` (`vehicle_filter`: `""` or `" AND vehicle = '...'"`).
pub fn durations_sql(vehicle_filter: &str) -> String {
    format!(
        "SELECT activity AS a, \
           SUM(CASE WHEN duration_s > 0.0 THEN 1 ELSE 0 END) AS n, \
           SUM(CASE WHEN duration_s > 0.0 THEN duration_s ELSE 0.0 END) AS sum_d, \
           SUM(CASE WHEN duration_s > 0.0 THEN duration_s * duration_s ELSE 0.0 END) AS sum_dd, \
           SUM(CASE WHEN duration_s > 0.0 THEN 0 ELSE 1 END) AS n_non_positive, \
           MIN(CASE WHEN duration_s > 0.0 THEN NULL ELSE duration_s END) AS shortest \
         FROM stretches WHERE duration_s IS NOT NULL{vehicle_filter} \
         GROUP BY activity ORDER BY activity"
    )
}

/// The durations of the runs in `ctx`.
pub async fn durations(ctx: &SessionContext, sql: &str) -> anyhow::Result<FleetDurations> {
    let mut out = FleetDurations::default();
    for b in rows(ctx, sql).await? {
        let names = arrow::compute::cast(b.column(0), &arrow::datatypes::DataType::Utf8)?;
        let names = names.as_string::<i32>();
        for r in 0..b.num_rows() {
            let a = names.value(r).to_string();
            let n = i64_at(&b, "n", r)?.unwrap_or(0).max(0) as u64;
            if n > 0 {
                let sum = f64_at(&b, "sum_d", r)?.unwrap_or(0.0);
                let sum_sq = f64_at(&b, "sum_dd", r)?.unwrap_or(0.0);
                out.stats
                    .insert(a.clone(), DurationStats::from_sums(n, sum, sum_sq));
            }
            let k = i64_at(&b, "n_non_positive", r)?.unwrap_or(0).max(0) as u64;
            if k > 0 {
                let shortest = f64_at(&b, "shortest", r)?.unwrap_or(0.0);
                out.non_positive.insert(a, (k, shortest));
            }
        }
    }
    Ok(out)
}

/// As JSON: per activity, `n`, `mean_s`, `sd_s` (calibrate's report), and the non-positive ones.
pub fn to_json(d: &FleetDurations) -> serde_json::Value {
    let stats: serde_json::Map<String, serde_json::Value> = (d.stats.iter())
        .map(|(a, s)| {
            (
                a.clone(),
                serde_json::json!({"n": s.n, "mean_s": s.mean(), "sd_s": s.sd()}),
            )
        })
        .collect();
    let non_positive: serde_json::Map<String, serde_json::Value> = (d.non_positive.iter())
        .map(|(a, (n, shortest))| {
            (
                a.clone(),
                serde_json::json!({"n": n, "shortest_s": shortest}),
            )
        })
        .collect();
    serde_json::json!({"activities": stats, "non_positive": non_positive})
}
