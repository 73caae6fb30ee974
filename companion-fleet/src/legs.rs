//! The `legs` table: the legs, climbs and descents `companion calibrate` reads from a run's
//! `flight.tlog` (companion/src/calibrate/legs.rs), one row each, and the leg model and the
//! vertical rates fitted from SQL sums over it (`companion-fleet calibrate`, docs/fleet.md).
//!
//! Finding them is not an aggregate: a leg is a stretch between two MISSION_ITEM_REACHED of
//! one armed flight in one mode, the climb ends where the first leg starts, the descent starts
//! where the last leg's altitude was left; a state machine over the tlog's messages in order.
//! So ingest runs calibrate's own reader over each tlog and keeps its legs as rows; the fit over
//! them (linear least squares, sums of heights and times) is SQL.
//!
//! A leg whose run commands no speed (no DO_CHANGE_SPEED before it, no cruise parameter in the
//! tlog) takes the fallback calibrate is given, known only when calibrating; whether such a
//! leg is kept also decides the climb (found at the first leg kept) and the descent (from the
//! last kept leg's altitude). So the tlog is read as calibrate reads it both without a fallback
//! and with one (`with_fallback` false and true); calibrate picks its case's rows and puts its
//! fallback speed in the legs whose `commanded_mps` is null.

use crate::calibrate::{f64_at, lit, rows};
use crate::export::RunKey;
use crate::table::{Cell, Kind, TableWriter};
use anyhow::Context;
use arrow::array::{Array, AsArray};
use companion::calibrate::legs::{
    LegCentred, LegFitError, LegFlights, LegModel, LegSums, MIN_LEGS, SpeedSource,
};
use companion::calibrate::write::FittedRate;
use datafusion::prelude::SessionContext;
use std::collections::BTreeMap;
use std::path::Path;

/// The table's columns (docs/fleet.md "legs").
pub fn columns() -> Vec<(String, Kind)> {
    [
        ("run_id", Kind::Str),
        ("vehicle", Kind::Str),
        ("with_fallback", Kind::Bool),
        ("kind", Kind::Str),
        ("idx", Kind::I64),
        ("length_m", Kind::F64),
        ("duration_s", Kind::F64),
        ("commanded_mps", Kind::F64),
        ("source", Kind::Str),
    ]
    .iter()
    .map(|(n, k)| (n.to_string(), *k))
    .collect()
}

fn source_name(s: SpeedSource) -> &'static str {
    match s {
        SpeedSource::MissionItem => "mission_item",
        SpeedSource::AutopilotParam => "autopilot_param",
        SpeedSource::Fallback => "fallback",
    }
}

fn write_flights(
    w: &mut TableWriter,
    key: &RunKey,
    with_fallback: bool,
    f: &LegFlights,
) -> anyhow::Result<u64> {
    let mut n = 0;
    let row = |kind: &str, idx: usize, len: f64, dur: f64, cmd: Cell, src: Cell| {
        vec![
            key.run_id.as_str().into(),
            key.vehicle.as_str().into(),
            with_fallback.into(),
            kind.into(),
            (idx as u64).into(),
            len.into(),
            dur.into(),
            cmd,
            src,
        ]
    };
    for (i, l) in f.legs.iter().enumerate() {
        // The fallback's speed is calibrate's to give: null here.
        let cmd = match l.source {
            SpeedSource::Fallback => Cell::Null,
            _ => l.commanded_mps.into(),
        };
        let src = source_name(l.source).into();
        w.push(row("leg", i, l.length_m, l.duration_s, cmd, src))?;
        n += 1;
    }
    for (kind, v) in [("climb", &f.climbs), ("descent", &f.descents)] {
        for (i, x) in v.iter().enumerate() {
            w.push(row(
                kind,
                i,
                x.height_m,
                x.duration_s,
                Cell::Null,
                Cell::Null,
            ))?;
            n += 1;
        }
    }
    Ok(n)
}

/// Write the legs, climbs and descents of the run in `dir` to `path` (none without a tlog, or
/// with one calibrate refuses: `runs.samples_error` says why and calibrate refuses the run).
pub fn export_legs(dir: &Path, path: &Path, key: &RunKey) -> anyhow::Result<u64> {
    let mut w = TableWriter::create(path, &columns())?;
    let tlog = dir.join("flight.tlog");
    let mut n = 0;
    if tlog.is_file() {
        let mut without = LegFlights::new(None);
        // Any speed: the legs, climbs and descents found do not depend on its value.
        let mut with = LegFlights::new(Some((f64::NAN, String::new())));
        let pin = companion::calibrate::runs::fly_pin(dir);
        let read = companion::calibrate::tlog::for_each_sample(
            &tlog,
            pin,
            |_| {},
            |m| {
                without.on_message(m);
                with.on_message(m);
            },
        );
        if read.is_ok() {
            n += write_flights(&mut w, key, false, &without)?;
            n += write_flights(&mut w, key, true, &with)?;
        }
    }
    w.finish()?;
    Ok(n)
}

/// The legs' rows a calibration reads: legs of its fallback case, with the fallback's speed in
/// those that have none (`x` = L / v_cmd, `t`, `v`, `l`, `source`).
fn legs_sql(fallback: Option<f64>, filter: &str) -> String {
    let (with, v) = match fallback {
        Some(f) => ("true", format!("COALESCE(commanded_mps, {})", lit(f))),
        None => ("false", "commanded_mps".to_string()),
    };
    format!(
        "SELECT length_m / {v} AS x, duration_s AS t, {v} AS v, length_m AS l, source FROM legs \
         WHERE kind = 'leg' AND with_fallback = {with}{filter}"
    )
}

/// The legs, climb and descent fitted from SQL sums, and each query with the sums it gave
/// (`calibrate --statistics`: what another engine runs over the same files and compares).
pub struct SqlLegs {
    pub model: Result<LegModel, LegFitError>,
    pub climb: Option<FittedRate>,
    pub descent: Option<FittedRate>,
    /// Name -> `{"query": SQL, "sums": {column: value}}`, in the order run.
    pub statistics: serde_json::Map<String, serde_json::Value>,
}

impl SqlLegs {
    /// One query's single row of sums (a null sum, over no rows, reads `None`), kept with its
    /// query under `name`.
    async fn sums(
        &mut self,
        ctx: &SessionContext,
        name: &str,
        sql: String,
    ) -> anyhow::Result<BTreeMap<String, Option<f64>>> {
        let b = rows(ctx, &sql).await?;
        let b = b
            .first()
            .with_context(|| format!("no row of sums: {sql}"))?;
        let mut out = BTreeMap::new();
        for f in b.schema().fields() {
            out.insert(f.name().clone(), f64_at(b, f.name(), 0)?);
        }
        self.statistics
            .insert(name.into(), serde_json::json!({"query": sql, "sums": out}));
        Ok(out)
    }
}

fn get(sums: &BTreeMap<String, Option<f64>>, c: &str) -> f64 {
    sums.get(c).copied().flatten().unwrap_or(0.0)
}

/// The leg model from SQL sums in the three passes of companion's `fit_legs` (`LegSums`,
/// `LegCentred`, then the two-parameter fit's residuals), then the climb and descent rates:
/// the same fits on the same runs.
pub async fn fit_sql(
    ctx: &SessionContext,
    fallback: Option<f64>,
    filter: &str,
) -> anyhow::Result<SqlLegs> {
    let mut out = SqlLegs {
        model: Err(LegFitError::TooFew(0)),
        climb: None,
        descent: None,
        statistics: serde_json::Map::new(),
    };
    out.model = fit_legs_sql(ctx, &mut out, fallback, filter).await?;
    out.climb = rate_sql(ctx, &mut out, "climb", fallback, filter).await?;
    out.descent = rate_sql(ctx, &mut out, "descent", fallback, filter).await?;
    Ok(out)
}

async fn fit_legs_sql(
    ctx: &SessionContext,
    out: &mut SqlLegs,
    fallback: Option<f64>,
    filter: &str,
) -> anyhow::Result<Result<LegModel, LegFitError>> {
    let legs = legs_sql(fallback, filter);
    let s = out
        .sums(
            ctx,
            "legs_sums",
            format!(
                "SELECT COUNT(*) AS n, SUM(x) AS sx, SUM(t) AS st, MIN(x) AS x_lo, MAX(x) AS x_hi, \
                   MIN(v) AS v_lo, MAX(v) AS v_hi, MIN(l) AS l_lo, MAX(l) AS l_hi FROM ({legs})"
            ),
        )
        .await?;
    let g = |c: &str| get(&s, c);
    let mut sources = Vec::new();
    for s in rows(ctx, &format!("SELECT DISTINCT source FROM ({legs})")).await? {
        let a = s.column(0).as_string::<i32>();
        for i in 0..a.len() {
            sources.push(match a.value(i) {
                "mission_item" => SpeedSource::MissionItem,
                "autopilot_param" => SpeedSource::AutopilotParam,
                _ => SpeedSource::Fallback,
            });
        }
    }
    sources.sort();
    sources.dedup();
    let sums = LegSums {
        n: g("n").max(0.0) as usize,
        sum_x: g("sx"),
        sum_t: g("st"),
        x_range: (g("x_lo"), g("x_hi")),
        commanded: (g("v_lo"), g("v_hi")),
        lengths: (g("l_lo"), g("l_hi")),
        sources,
    };
    if sums.n < MIN_LEGS {
        return Ok(Err(LegFitError::TooFew(sums.n)));
    }
    let (mx, mt) = sums.means();
    let c1 = sums.overhead_one();
    let centred_sql = format!(
        "SELECT SUM((x - {mx}) * (x - {mx})) AS sxx, SUM((x - {mx}) * (t - {mt})) AS sxt, \
           SUM((t - x - {c1}) * (t - x - {c1})) AS ss_one, SUM((t - x) * (t - x)) AS ss_before \
         FROM ({legs})",
        mx = lit(mx),
        mt = lit(mt),
        c1 = lit(c1),
    );
    let c = out.sums(ctx, "legs_centred", centred_sql).await?;
    let centred = LegCentred {
        sxx: get(&c, "sxx"),
        sxt: get(&c, "sxt"),
        ss_one: get(&c, "ss_one"),
        ss_before: get(&c, "ss_before"),
    };
    let mut ss_two = None;
    if let Some((a, c)) = sums.two(&centred) {
        let sql = format!(
            "SELECT SUM((t - {a} * x - {c}) * (t - {a} * x - {c})) AS ss FROM ({legs})",
            a = lit(a),
            c = lit(c),
        );
        ss_two = Some(get(&out.sums(ctx, "legs_two", sql).await?, "ss"));
    }
    Ok(sums.model(&centred, ss_two))
}

/// A vertical rate (`climb`, `descent`) from SQL sums, as companion's `legs::rate`: total
/// height over total time, and the RMS of each one's time against it (s).
async fn rate_sql(
    ctx: &SessionContext,
    out: &mut SqlLegs,
    kind: &str,
    fallback: Option<f64>,
    filter: &str,
) -> anyhow::Result<Option<FittedRate>> {
    let rows_of = format!(
        "FROM legs WHERE kind = '{kind}' AND with_fallback = {}{filter}",
        fallback.is_some()
    );
    let s = out
        .sums(
            ctx,
            &format!("{kind}_sums"),
            format!("SELECT COUNT(*) AS n, SUM(length_m) AS h, SUM(duration_s) AS t {rows_of}"),
        )
        .await?;
    let n = get(&s, "n");
    let (Some(h), Some(t)) = (s.get("h").copied().flatten(), s.get("t").copied().flatten()) else {
        return Ok(None);
    };
    if n < 1.0 || t <= 0.0 {
        return Ok(None);
    }
    let r = h / t;
    let sql = format!(
        "SELECT SUM((duration_s - length_m / {r}) * (duration_s - length_m / {r})) AS ss {rows_of}",
        r = lit(r)
    );
    let ss = get(
        &out.sums(ctx, &format!("{kind}_residuals"), sql).await?,
        "ss",
    );
    Ok(Some(FittedRate {
        flights: n as usize,
        mean_height_m: h / n,
        rate_mps: r,
        rms_s: (ss / n).sqrt(),
    }))
}

/// The legs, climb and descent fitted, as `--json` gives them.
pub fn legs_json(fit: &SqlLegs) -> serde_json::Value {
    let legs = match &fit.model {
        Ok(m) => serde_json::json!({
            "legs": m.legs,
            "overhead_s": m.overhead_s,
            "speed_fraction": m.speed_fraction,
            "fitted_fraction": m.fitted_fraction,
            "rms_s": m.rms_s,
            "rms_before_s": m.rms_before_s,
            "commanded_mps": [m.commanded.0, m.commanded.1],
            "lengths_m": [m.lengths.0, m.lengths.1],
            "sources": m.sources.iter().map(|s| source_name(*s)).collect::<Vec<_>>(),
        }),
        Err(e) => serde_json::json!({"error": e.to_string()}),
    };
    let rate = |r: &Option<FittedRate>| match r {
        Some(r) => serde_json::json!({"speed_mps": r.rate_mps, "rms_s": r.rms_s}),
        None => serde_json::Value::Null,
    };
    serde_json::json!({"legs": legs, "climb": rate(&fit.climb), "descent": rate(&fit.descent)})
}
