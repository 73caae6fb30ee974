//! `companion-fleet report DIR`: the fleet's figures per vehicle and route, each section one SQL
//! query over the dataset (docs/fleet.md "Report" defines every figure).

use crate::query::{context, to_json, to_text};
use anyhow::Context;
use std::path::Path;

/// The command outcomes that count as failures, by their kind: the vehicle refused, the command
/// failed, or it went unanswered (`companion review`'s red marks). A schema-1 log's `FAILED
/// (Cancelled(..))` was a cancel: the log reader's migration reads it as `CANCELLED`.
pub const FAILURE_SQL: &str = "c.kind IN ('DENIED', 'UNSUPPORTED', 'TEMPORARILY_REJECTED', \
     'NOT_READY', 'TIMEOUT', 'FAILED')";

/// The operator gate's refusal of a start: its typed event (record schema 2, an `operator` event
/// of kind `start_refused`; a schema-1 log's sentence is read as one by the log reader's
/// migration), never its text.
const REFUSED_SQL: &str = "e.source = 'record' AND e.kind = 'operator' \
     AND e.operator = 'start_refused'";

/// Per vehicle and route: flights, hours, refusals, drift, failures, link losses, versions and
/// planned against flown energy and duration.
fn summary_sql() -> String {
    format!(
        "WITH dur AS (SELECT run_id, MAX(time_s) AS t_end FROM records GROUP BY run_id), \
         e AS (SELECT run_id, last_value(goal_energy_j - margin_energy_j ORDER BY record_idx) AS flown \
               FROM records WHERE goal_energy_j IS NOT NULL AND margin_energy_j IS NOT NULL GROUP BY run_id), \
         d AS (SELECT run_id, last_value(goal_duration_s - margin_duration_s ORDER BY record_idx) AS flown \
               FROM records WHERE goal_duration_s IS NOT NULL AND margin_duration_s IS NOT NULL GROUP BY run_id), \
         drift AS (SELECT run_id, COUNT(*) AS n FROM records WHERE power_drift_began GROUP BY run_id), \
         realloc AS (SELECT run_id, COUNT(*) AS n FROM records \
               WHERE guarantee_reallocation_trigger IS NOT NULL GROUP BY run_id), \
         refused AS (SELECT e.run_id, COUNT(*) AS n FROM events e WHERE {REFUSED_SQL} GROUP BY e.run_id), \
         fails AS (SELECT c.run_id, COUNT(*) AS n FROM commands c WHERE {FAILURE_SQL} GROUP BY c.run_id), \
         links AS (SELECT run_id, COUNT(*) AS n FROM events \
               WHERE source = 'link' AND kind = 'lost' GROUP BY run_id) \
         SELECT r.vehicle, r.route, COUNT(*) AS flights, \
           SUM(COALESCE(dur.t_end, 0.0)) / 3600.0 AS hours, \
           SUM(r.records) AS records, \
           COUNT(DISTINCT r.git_revision) AS versions, \
           SUM(COALESCE(refused.n, 0)) AS refused_starts, \
           SUM(COALESCE(drift.n, 0)) AS drift_events, \
           SUM(COALESCE(realloc.n, 0)) AS reallocations, \
           SUM(COALESCE(fails.n, 0)) AS command_failures, \
           SUM(COALESCE(links.n, 0)) AS link_losses, \
           AVG(r.planned_energy_j) AS planned_energy_j, \
           AVG(e.flown) AS flown_energy_j, \
           AVG(e.flown - r.planned_energy_j) AS energy_error_j, \
           AVG(r.planned_duration_s) AS planned_duration_s, \
           AVG(d.flown) AS flown_duration_s, \
           AVG(d.flown - r.planned_duration_s) AS duration_error_s \
         FROM runs r \
           LEFT JOIN dur ON dur.run_id = r.run_id \
           LEFT JOIN e ON e.run_id = r.run_id \
           LEFT JOIN d ON d.run_id = r.run_id \
           LEFT JOIN drift ON drift.run_id = r.run_id \
           LEFT JOIN realloc ON realloc.run_id = r.run_id \
           LEFT JOIN refused ON refused.run_id = r.run_id \
           LEFT JOIN fails ON fails.run_id = r.run_id \
           LEFT JOIN links ON links.run_id = r.run_id \
         GROUP BY r.vehicle, r.route ORDER BY r.vehicle, r.route"
    )
}

fn refusals_sql() -> String {
    format!(
        "SELECT r.vehicle, r.route, \
           e.start_by AS refused_by, e.why AS reason, \
           COUNT(*) AS starts \
         FROM events e JOIN runs r ON e.run_id = r.run_id WHERE {REFUSED_SQL} \
         GROUP BY 1, 2, 3, 4 ORDER BY 1, 2, 3, 4"
    )
}

fn failures_sql() -> String {
    format!(
        "SELECT r.vehicle, r.route, c.command, c.kind, \
           COUNT(*) AS failures \
         FROM commands c JOIN runs r ON c.run_id = r.run_id WHERE {FAILURE_SQL} \
         GROUP BY 1, 2, 3, 4 ORDER BY 1, 2, 3, 4"
    )
}

const VERSIONS_SQL: &str = "SELECT vehicle, route, git_revision, COUNT(*) AS flights FROM runs \
     GROUP BY 1, 2, 3 ORDER BY 1, 2, 3";

/// The report's sections: name and query.
pub fn sections() -> Vec<(&'static str, String)> {
    vec![
        ("summary", summary_sql()),
        ("refused_starts", refusals_sql()),
        ("command_failures", failures_sql()),
        ("versions", VERSIONS_SQL.to_string()),
    ]
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn html_table(rows: &serde_json::Value) -> String {
    let rows = rows.as_array().cloned().unwrap_or_default();
    let Some(first) = rows.first().and_then(|r| r.as_object()) else {
        return "<p>none</p>\n".into();
    };
    let cols: Vec<String> = first.keys().cloned().collect();
    let mut out = String::from("<table>\n<tr>");
    for c in &cols {
        out += &format!("<th>{}</th>", html_escape(c));
    }
    out += "</tr>\n";
    for r in &rows {
        out += "<tr>";
        for c in &cols {
            let v = match &r[c] {
                serde_json::Value::String(s) => s.clone(),
                serde_json::Value::Null => String::new(),
                other => other.to_string(),
            };
            out += &format!("<td>{}</td>", html_escape(&v));
        }
        out += "</tr>\n";
    }
    out + "</table>\n"
}

/// A run ingested by an older fleet schema lacks columns the report counts by (fleet schema 3:
/// the operator events' fields, the BN trials; 4: the stretches calibrate times): its figures
/// would read as zero, so the report and calibrate refuse it.
pub async fn refuse_old_runs(
    ctx: &datafusion::prelude::SessionContext,
    dir: &Path,
) -> anyhow::Result<()> {
    let sql = format!(
        "SELECT source, fleet_schema FROM runs WHERE fleet_schema IS NULL OR fleet_schema <> {} \
         ORDER BY source LIMIT 3",
        crate::export::FLEET_SCHEMA
    );
    let old = to_json(&ctx.sql(&sql).await?.collect().await?)?;
    if old.as_array().is_some_and(|rows| !rows.is_empty()) {
        anyhow::bail!(
            "{}: runs ingested by another fleet schema than {} ({old}): re-ingest them into a new \
             dataset (docs/fleet.md, Schema)",
            dir.display(),
            crate::export::FLEET_SCHEMA
        );
    }
    Ok(())
}

/// `report DIR [--html FILE] [--json]`.
pub async fn report_cli(dir: &Path, html: Option<&Path>, json: bool) -> anyhow::Result<()> {
    let Some(ctx) = context(dir).await? else {
        anyhow::bail!(
            "{}: no runs ingested (companion-fleet ingest RUN... --into DIR)",
            dir.display()
        );
    };
    refuse_old_runs(&ctx, dir).await?;
    let mut out = serde_json::Map::new();
    let mut text = String::new();
    for (name, sql) in sections() {
        let batches = ctx
            .sql(&sql)
            .await
            .with_context(|| format!("report section {name}"))?
            .collect()
            .await
            .with_context(|| format!("report section {name}"))?;
        text += &format!("{name}\n{}\n\n", to_text(&batches)?);
        out.insert(name.to_string(), to_json(&batches)?);
    }
    if let Some(path) = html {
        let mut page = format!(
            "<!doctype html>\n<html><head><meta charset=\"utf-8\"><title>Fleet report</title>\
             <style>table{{border-collapse:collapse}}td,th{{border:1px solid #999;padding:2px 6px}}</style>\
             </head><body>\n<h1>Fleet report: {}</h1>\n",
            html_escape(&dir.display().to_string())
        );
        for (name, rows) in &out {
            page += &format!("<h2>{}</h2>\n{}", html_escape(name), html_table(rows));
        }
        page += "</body></html>\n";
        std::fs::write(path, page).with_context(|| format!("writing {}", path.display()))?;
    }
    if json {
        println!("{}", serde_json::Value::Object(out));
    } else if html.is_none() {
        print!("{text}");
    }
    Ok(())
}
