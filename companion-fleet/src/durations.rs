//! The activity durations `companion calibrate RUN...` reports (companion/src/calibrate/
//! durations.rs), as one SQL query over `records`: per activity name, the count, Σd and Σd² of
//! its completed runs (the sufficient statistics of the mean and spread), and the count and
//! shortest of those that lasted zero or less. Window functions (LAG, LEAD, a running SUM) cut
//! each run's records into stretches of one activity; Spark SQL runs the same text.
//!
//! The rules are calibrate's: records without an activity are skipped; the clock is
//! `obs_vehicle_time_s` when recorded, else `time_s`; a stretch starts at its first record or at
//! its last disarmed record (`obs_armed` < 0.5), whichever is later; it ends at the next
//! stretch's first record, and the run's last stretch (cut) is not counted.

use crate::calibrate::{f64_at, i64_at, rows};
use anyhow::Context;
use arrow::array::AsArray;
use companion::calibrate::durations::DurationStats;
use datafusion::prelude::SessionContext;
use std::collections::BTreeMap;

/// Per activity name: the completed stretches' statistics, and (count, shortest) of those that
/// lasted zero or less.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct FleetDurations {
    pub stats: BTreeMap<String, DurationStats>,
    pub non_positive: BTreeMap<String, (u64, f64)>,
}

/// The query. `has_vehicle_time` / `has_armed`: whether the dataset has those observation
/// columns at all (a column no run has is not in the table; then no record has the value).
pub fn durations_sql(vehicle_filter: &str, has_vehicle_time: bool, has_armed: bool) -> String {
    let t = if has_vehicle_time {
        "COALESCE(obs_vehicle_time_s, time_s)"
    } else {
        "time_s"
    };
    let disarmed = if has_armed {
        "COALESCE(obs_armed < 0.5, false)"
    } else {
        "false"
    };
    format!(
        "WITH r AS ( \
           SELECT run_id, record_idx, guarantee_activity_name AS a, {t} AS t, {disarmed} AS disarmed \
           FROM records \
           WHERE guarantee_activity_name IS NOT NULL AND guarantee_activity_name <> '' \
             AND {t} IS NOT NULL{vehicle_filter}), \
         s AS ( \
           SELECT *, CASE WHEN a = LAG(a) OVER (PARTITION BY run_id ORDER BY record_idx) \
                          THEN 0 ELSE 1 END AS first_of_stretch \
           FROM r), \
         g AS ( \
           SELECT *, SUM(first_of_stretch) OVER (PARTITION BY run_id ORDER BY record_idx \
                       ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW) AS stretch \
           FROM s), \
         st AS ( \
           SELECT run_id, stretch, MIN(a) AS a, MIN(record_idx) AS first_idx, \
                  MAX(CASE WHEN first_of_stretch = 1 OR disarmed THEN record_idx END) AS start_idx \
           FROM g GROUP BY run_id, stretch), \
         times AS ( \
           SELECT st.run_id, st.stretch, st.a, b.t AS t_start, f.t AS t_first \
           FROM st JOIN g b ON b.run_id = st.run_id AND b.record_idx = st.start_idx \
                   JOIN g f ON f.run_id = st.run_id AND f.record_idx = st.first_idx), \
         d AS ( \
           SELECT a, LEAD(t_first) OVER (PARTITION BY run_id ORDER BY stretch) - t_start AS d \
           FROM times) \
         SELECT a, \
           SUM(CASE WHEN d > 0.0 THEN 1 ELSE 0 END) AS n, \
           SUM(CASE WHEN d > 0.0 THEN d ELSE 0.0 END) AS sum_d, \
           SUM(CASE WHEN d > 0.0 THEN d * d ELSE 0.0 END) AS sum_dd, \
           SUM(CASE WHEN d > 0.0 THEN 0 ELSE 1 END) AS n_non_positive, \
           MIN(CASE WHEN d > 0.0 THEN NULL ELSE d END) AS shortest \
         FROM d WHERE d IS NOT NULL GROUP BY a ORDER BY a"
    )
}

/// Whether the `records` table has a column of that name.
async fn has_column(ctx: &SessionContext, name: &str) -> anyhow::Result<bool> {
    let t = ctx.table("records").await.context("table records")?;
    Ok(t.schema().fields().iter().any(|f| f.name() == name))
}

/// The query for this dataset (its columns decide the clock's and the arming's expressions).
pub async fn query(ctx: &SessionContext, vehicle_filter: &str) -> anyhow::Result<String> {
    Ok(durations_sql(
        vehicle_filter,
        has_column(ctx, "obs_vehicle_time_s").await?,
        has_column(ctx, "obs_armed").await?,
    ))
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
