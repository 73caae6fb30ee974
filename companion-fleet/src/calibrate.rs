//! `companion-fleet calibrate DIR`: the power model fitted from the fit's sufficient statistics,
//! summed as SQL aggregates over the dataset's `samples` (docs/fleet.md "Calibration"), and solved
//! by the companion's own solver: the same model `companion calibrate RUN...` fits to the same
//! runs. The queries are plain SQL over Parquet, so they run on Spark too
//! (scripts/fleet_spark.sh).

use crate::query::context;
use anyhow::Context;
use arrow::array::{Array, AsArray, Float64Array, Int64Array};
use arrow::datatypes::{DataType, Field, Float64Type, Int64Type, Schema};
use arrow::record_batch::RecordBatch;
use companion::calibrate::power_fit::{PowerFit, PowerModel, Statistics};
use datafusion::datasource::MemTable;
use datafusion::prelude::SessionContext;
use std::path::Path;
use std::sync::Arc;

/// A float as a SQL literal that reads back to the same f64 (Rust's shortest round trip).
pub(crate) fn lit(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains(['.', 'e', 'E']) {
        s
    } else {
        format!("{s}.0")
    }
}

/// A string as a SQL literal.
fn quoted(s: &str) -> String {
    format!("'{}'", s.replace('\'', "''"))
}

/// `AND vehicle = '...'` when one vehicle is asked for.
fn vehicle_filter(vehicle: Option<&str>) -> String {
    vehicle.map_or_else(String::new, |v| format!(" AND vehicle = {}", quoted(v)))
}

/// The totals over every sample: counts, Σy, Σy², the shipped model's squared error, and the
/// airborne speeds' range.
pub fn totals_sql(m: &PowerModel, vehicle: Option<&str>) -> String {
    // The shipped model's power, as PowerModel::power computes it (same operations, same order).
    let shipped = format!(
        "CASE WHEN airborne THEN {base} + {p0} * (1.0 + 3.0 * v * v / ({u} * {u})) \
           + {pi} * sqrt(CASE WHEN sqrt(1.0 + r * r / 4.0) - r / 2.0 > 0.0 \
                              THEN sqrt(1.0 + r * r / 4.0) - r / 2.0 ELSE 0.0 END) \
           + {cda} * (0.5 * {rho} * v * v * v) ELSE {base} END",
        base = lit(m.base_w),
        p0 = lit(m.blade_profile_w),
        pi = lit(m.induced_hover_w),
        cda = lit(m.drag_area_m2),
        u = lit(m.tip_speed_mps),
        rho = lit(m.air_density_kgm3),
    );
    format!(
        "SELECT \
           SUM(CASE WHEN airborne THEN 0 ELSE 1 END) AS n_ground, \
           SUM(CASE WHEN airborne THEN 1 ELSE 0 END) AS n_air, \
           SUM(y * y) AS yy, SUM(y) AS sum_y, \
           SUM((y - ({shipped})) * (y - ({shipped}))) AS shipped_sse, \
           MIN(CASE WHEN airborne THEN v END) AS v_min, \
           MAX(CASE WHEN airborne THEN v END) AS v_max \
         FROM (SELECT speed_mps AS v, power_w AS y, airborne, \
                 speed_mps * speed_mps / ({v0} * {v0}) AS r \
               FROM samples WHERE true{filter})",
        v0 = lit(m.induced_velocity_mps),
        filter = vehicle_filter(vehicle),
    )
}

/// The airborne speeds' 0.5 m/s bins.
pub fn bins_sql(vehicle: Option<&str>) -> String {
    format!(
        "SELECT DISTINCT CAST(round(speed_mps / 0.5) AS BIGINT) AS bin FROM samples \
         WHERE airborne{} ORDER BY bin",
        vehicle_filter(vehicle)
    )
}

/// Per candidate v0 (table `grid`: `k`, `v0`), the sums of the airborne regressors' products:
/// a = 1 + 3v²/U² (P0), i = the induced term (Pi), c = ½ρv³ (CdA), and y the power.
pub fn normals_sql(m: &PowerModel, vehicle: Option<&str>) -> String {
    format!(
        "SELECT k, SUM(a) AS sa, SUM(i) AS si, SUM(c) AS sc, \
           SUM(a * a) AS aa, SUM(a * i) AS ai, SUM(a * c) AS ac, \
           SUM(i * i) AS ii, SUM(i * c) AS ic, SUM(c * c) AS cc, \
           SUM(a * y) AS ay, SUM(i * y) AS iy, SUM(c * y) AS cy \
         FROM (SELECT k, y, 1.0 + 3.0 * v * v / ({u} * {u}) AS a, \
                 sqrt(CASE WHEN sqrt(1.0 + r * r / 4.0) - r / 2.0 > 0.0 \
                           THEN sqrt(1.0 + r * r / 4.0) - r / 2.0 ELSE 0.0 END) AS i, \
                 0.5 * {rho} * v * v * v AS c \
               FROM (SELECT g.k, s.speed_mps AS v, s.power_w AS y, \
                       s.speed_mps * s.speed_mps / (g.v0 * g.v0) AS r \
                     FROM samples s CROSS JOIN grid g WHERE s.airborne{filter})) \
         GROUP BY k ORDER BY k",
        u = lit(m.tip_speed_mps),
        rho = lit(m.air_density_kgm3),
        filter = vehicle_filter(vehicle).replace("vehicle", "s.vehicle"),
    )
}

pub(crate) fn f64_at(b: &RecordBatch, col: &str, row: usize) -> anyhow::Result<Option<f64>> {
    let a = b
        .column_by_name(col)
        .with_context(|| format!("no column {col}"))?;
    let a = arrow::compute::cast(a, &DataType::Float64)?;
    let a: &Float64Array = a.as_primitive::<Float64Type>();
    Ok((!a.is_null(row)).then(|| a.value(row)))
}

pub(crate) fn i64_at(b: &RecordBatch, col: &str, row: usize) -> anyhow::Result<Option<i64>> {
    let a = b
        .column_by_name(col)
        .with_context(|| format!("no column {col}"))?;
    let a = arrow::compute::cast(a, &DataType::Int64)?;
    let a: &Int64Array = a.as_primitive::<Int64Type>();
    Ok((!a.is_null(row)).then(|| a.value(row)))
}

pub(crate) async fn rows(ctx: &SessionContext, sql: &str) -> anyhow::Result<Vec<RecordBatch>> {
    ctx.sql(sql)
        .await
        .with_context(|| format!("query: {sql}"))?
        .collect()
        .await
        .with_context(|| format!("query: {sql}"))
}

/// The sufficient statistics of the runs in `ctx` (one vehicle's when given).
pub async fn statistics(
    ctx: &SessionContext,
    m: &PowerModel,
    grid: &[f64],
    vehicle: Option<&str>,
) -> anyhow::Result<Statistics> {
    let schema = Arc::new(Schema::new(vec![
        Field::new("k", DataType::Int64, false),
        Field::new("v0", DataType::Float64, false),
    ]));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(Int64Array::from_iter_values(0..grid.len() as i64)),
            Arc::new(Float64Array::from(grid.to_vec())),
        ],
    )?;
    ctx.register_table(
        "grid",
        Arc::new(MemTable::try_new(schema, vec![vec![batch]])?),
    )?;
    let mut st = Statistics::default();
    for b in rows(ctx, &totals_sql(m, vehicle)).await? {
        for r in 0..b.num_rows() {
            st.n_ground = i64_at(&b, "n_ground", r)?.unwrap_or(0).max(0) as u64;
            st.n_air = i64_at(&b, "n_air", r)?.unwrap_or(0).max(0) as u64;
            st.yy = f64_at(&b, "yy", r)?.unwrap_or(0.0);
            st.sum_y = f64_at(&b, "sum_y", r)?.unwrap_or(0.0);
            st.shipped_sse = f64_at(&b, "shipped_sse", r)?.unwrap_or(0.0);
            st.v_min = f64_at(&b, "v_min", r)?.unwrap_or(f64::INFINITY);
            st.v_max = f64_at(&b, "v_max", r)?.unwrap_or(f64::NEG_INFINITY);
        }
    }
    for b in rows(ctx, &bins_sql(vehicle)).await? {
        for r in 0..b.num_rows() {
            st.speed_bins.extend(i64_at(&b, "bin", r)?);
        }
    }
    let n = (st.n_air + st.n_ground) as f64;
    // Without airborne samples the grid's sums are all zero (the ground's x = [1, 0, 0, 0]).
    st.normals = vec![([[0.0; 4]; 4], [st.sum_y, 0.0, 0.0, 0.0]); grid.len()];
    for nm in &mut st.normals {
        nm.0[0][0] = n;
    }
    for b in rows(ctx, &normals_sql(m, vehicle)).await? {
        for r in 0..b.num_rows() {
            let k = i64_at(&b, "k", r)?.context("k")? as usize;
            let g = |c: &str| f64_at(&b, c, r).map(|v| v.unwrap_or(0.0));
            let (sa, si, sc) = (g("sa")?, g("si")?, g("sc")?);
            let (aa, ai, ac, ii, ic, cc) =
                (g("aa")?, g("ai")?, g("ac")?, g("ii")?, g("ic")?, g("cc")?);
            let ata = [
                [n, sa, si, sc],
                [sa, aa, ai, ac],
                [si, ai, ii, ic],
                [sc, ac, ic, cc],
            ];
            let aty = [st.sum_y, g("ay")?, g("iy")?, g("cy")?];
            if let Some(slot) = st.normals.get_mut(k) {
                *slot = (ata, aty);
            }
        }
    }
    Ok(st)
}

/// The queries and the sums they gave, as JSON (`--statistics`): what another engine (Spark,
/// scripts/fleet_spark.sh) runs over the same files and compares.
fn statistics_json(
    m: &PowerModel,
    grid: &[f64],
    vehicle: Option<&str>,
    st: &Statistics,
    (durations_sql, durations): (&str, &crate::durations::FleetDurations),
) -> serde_json::Value {
    let sums: serde_json::Map<String, serde_json::Value> = (durations.stats.iter())
        .map(|(a, s)| {
            let (n, sum_d, sum_dd) = s.sums();
            (
                a.clone(),
                serde_json::json!({"n": n, "sum_d": sum_d, "sum_dd": sum_dd}),
            )
        })
        .collect();
    serde_json::json!({
        "grid": grid,
        "queries": {
            "totals": totals_sql(m, vehicle),
            "bins": bins_sql(vehicle),
            "normals": normals_sql(m, vehicle),
            "durations": durations_sql,
        },
        "durations": sums,
        "statistics": {
            "n_ground": st.n_ground,
            "n_air": st.n_air,
            "yy": st.yy,
            "sum_y": st.sum_y,
            "shipped_sse": st.shipped_sse,
            "v_min": st.v_min,
            "v_max": st.v_max,
            "bins": st.speed_bins,
            "normals": st.normals,
        },
    })
}

/// `calibrate DIR [--vehicle ID] [--out FILE] [--params DIR] [--json] [--statistics]`.
pub async fn calibrate_cli(
    dir: &Path,
    vehicle: Option<&str>,
    out: Option<&Path>,
    params: Option<&Path>,
    cruise_mps: Option<f64>,
    (json, statistics_only): (bool, bool),
) -> anyhow::Result<()> {
    if let Some(v) = cruise_mps.filter(|v| !(v.is_finite() && *v > 0.0)) {
        anyhow::bail!("--cruise-speed-mps {v}: not a speed (a number above 0 m/s)");
    }
    let Some(ctx) = context(dir).await? else {
        anyhow::bail!(
            "{}: no runs ingested (companion-fleet ingest RUN... --into DIR)",
            dir.display()
        );
    };
    crate::report::refuse_old_runs(&ctx, dir).await?;
    let params = params.map_or_else(companion::params::default_params_dir, Path::to_path_buf);
    let shipped =
        companion::calibrate::shipped::Shipped::load(&params).context("loading params")?;
    // A run calibrate would refuse (a corrupted line, a bad tlog) is refused here too.
    let bad = rows(
        &ctx,
        &format!(
            "SELECT source, samples_error FROM runs WHERE samples_error IS NOT NULL{} ORDER BY source",
            vehicle_filter(vehicle)
        ),
    )
    .await?;
    if let Some(b) = bad.iter().find(|b| b.num_rows() > 0) {
        let src = b.column(0).as_string::<i32>();
        let why = b.column(1).as_string::<i32>();
        anyhow::bail!("run {}: {}", src.value(0), why.value(0));
    }
    let fit = PowerFit::new(shipped.power);
    let st = statistics(&ctx, &shipped.power, fit.grid(), vehicle).await?;
    let durations_sql = crate::durations::durations_sql(&vehicle_filter(vehicle));
    let durations = crate::durations::durations(&ctx, &durations_sql).await?;
    // The legs' fallback commanded speed, as `companion calibrate` takes it (with its words,
    // which the overlay's sources say).
    let fallback = match cruise_mps {
        Some(v) => Some((v, "--cruise-speed-mps".to_string())),
        None => (shipped.cruise_mps).map(|v| {
            (
                v,
                format!("{} [derive].cruise_speed_mps", shipped.mission_file),
            )
        }),
    };
    let legs = crate::legs::fit_sql(
        &ctx,
        fallback.as_ref().map(|f| f.0),
        &vehicle_filter(vehicle),
    )
    .await?;
    if statistics_only {
        let mut stats = statistics_json(
            &shipped.power,
            fit.grid(),
            vehicle,
            &st,
            (&durations_sql, &durations),
        );
        // The BN rows' counts: the fifth query and what it gave.
        let bn_sql = crate::bn_rows::counts_sql(&vehicle_filter(vehicle));
        stats["bn_rows"] = crate::bn_rows::counts_json(&ctx, &bn_sql).await?;
        stats["queries"]["bn_rows"] = bn_sql.into();
        // The legs' and vertical rates' sums: each query (with the last pass's results as
        // literals) and its one row.
        stats["legs"] = legs.statistics.into();
        println!("{stats}");
        return Ok(());
    }
    // A power fit the samples do not determine is said, as `companion calibrate` says it, and
    // the rest is still learned; the command fails only when nothing is.
    let power = fit
        .with_statistics(st)
        .and_then(|f| f.solve().map_err(|e| e.to_string()))
        .map_err(|e| format!("calibrate: {e}"));
    let legs_values = crate::legs::legs_json(&legs);
    let bn_rows = crate::bn_rows::bn_rows(&ctx, &shipped, &vehicle_filter(vehicle)).await?;
    let learned_else = durations.stats.is_empty()
        && legs.model.is_err()
        && bn_rows.as_ref().is_ok_and(Vec::is_empty);
    let (result, mut values) = match power {
        Ok(r) => {
            let v = power_json(&r);
            (Some(r), v)
        }
        Err(e) if learned_else => anyhow::bail!("{e}"),
        Err(e) => (None, serde_json::json!({ "power_error": e })),
    };
    values["durations"] = crate::durations::to_json(&durations);
    for part in ["legs", "climb", "descent"] {
        values[part] = legs_values[part].clone();
    }
    values["bn_rows"] = match &bn_rows {
        Ok(r) => crate::bn_rows::learned_json(r),
        Err(e) => serde_json::json!({ "error": e }),
    };
    if json {
        println!("{values}");
    } else {
        print_text(result.as_ref(), &values, &durations);
    }
    if let Some(out) = out {
        // The BN rows are written only when every run's trials are known, as calibrate
        // refuses a run it cannot count.
        let bn_rows = bn_rows.map_err(|e| anyhow::anyhow!("calibrate --out: BN rows: {e}"))?;
        let parts = companion::calibrate::write::OverlayParts {
            made_by: "companion-fleet calibrate",
            run_ids: run_ids(&ctx, vehicle).await?,
            power: result.as_ref(),
            legs: companion::calibrate::write::FittedLegs {
                fallback: fallback.as_ref().map(|(v, w)| (*v, w.as_str())),
                model: legs.model.ok(),
                climb: legs.climb,
                descent: legs.descent,
            },
            rows: &bn_rows,
        };
        crate::overlay::write_overlay(&shipped, &parts, out)?;
        println!("overlay written: {}", out.display());
    }
    Ok(())
}

/// The fitted power model, at full precision (`--json`).
fn power_json(result: &companion::calibrate::power_fit::FitResult) -> serde_json::Value {
    let m = result.fitted;
    serde_json::json!({
        "samples": result.samples,
        "ground_samples": result.ground_samples,
        "base_w": m.base_w,
        "blade_profile_w": m.blade_profile_w,
        "induced_hover_w": m.induced_hover_w,
        "induced_velocity_mps": m.induced_velocity_mps,
        "drag_area_m2": m.drag_area_m2,
        "rms_w": result.rms_w,
        "shipped_rms_w": result.shipped_rms_w,
        "mean_w": result.mean_w,
        "v0_lower_bound_only": result.v0_lower_bound_only,
    })
}

/// The fit for people: the power model (or why there is none), legs, BN rows, durations.
fn print_text(
    result: Option<&companion::calibrate::power_fit::FitResult>,
    values: &serde_json::Value,
    durations: &crate::durations::FleetDurations,
) {
    match result {
        Some(result) => {
            let m = result.fitted;
            println!(
                "power model from {} samples ({} on the ground), speeds {:.1}..{:.1} m/s:\n  \
                 base.power_w {}\n  propulsion.blade_profile_w {}\n  propulsion.induced_hover_w {}\n  \
                 propulsion.induced_velocity_mps {}\n  propulsion.drag_area_m2 {}\n  \
                 rms {:.3} W (shipped {:.3} W)",
                result.samples,
                result.ground_samples,
                result.v_min,
                result.v_max,
                m.base_w,
                m.blade_profile_w,
                m.induced_hover_w,
                m.induced_velocity_mps,
                m.drag_area_m2,
                result.rms_w,
                result.shipped_rms_w
            );
        }
        None => println!(
            "power model: {}",
            values["power_error"].as_str().unwrap_or_default()
        ),
    }
    println!(
        "  legs {}\n  climb {}\n  descent {}\n  BN rows {}",
        values["legs"], values["climb"], values["descent"], values["bn_rows"]
    );
    for (a, s) in &durations.stats {
        println!(
            "  {a}: {:.1} s (sd {:.1} s, {} runs)",
            s.mean(),
            s.sd(),
            s.n
        );
    }
}

/// The ids of the runs calibrated (the overlay's `[calibration]`).
async fn run_ids(ctx: &SessionContext, vehicle: Option<&str>) -> anyhow::Result<Vec<String>> {
    let ids = rows(
        ctx,
        &format!(
            "SELECT run_id FROM runs WHERE true{} ORDER BY run_id",
            vehicle_filter(vehicle)
        ),
    )
    .await?;
    Ok((ids.iter())
        .flat_map(|b| {
            let a = b.column(0).as_string::<i32>();
            (0..a.len())
                .map(|i| a.value(i).to_string())
                .collect::<Vec<_>>()
        })
        .collect())
}
