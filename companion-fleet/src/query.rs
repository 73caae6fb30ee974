//! DataFusion over the fleet dataset: each table registered from its runs' Parquet files, with
//! the union of the runs' schemas (a run without a column reads it as null). Embedded: no
//! server, one process.

use anyhow::Context;
use arrow::datatypes::Schema;
use arrow::record_batch::RecordBatch;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::{
    ListingOptions, ListingTable, ListingTableConfig, ListingTableUrl,
};
use datafusion::prelude::SessionContext;
use std::path::Path;
use std::sync::Arc;

/// A session with the dataset's tables registered; `None` when the dataset holds no run.
pub async fn context(dir: &Path) -> anyhow::Result<Option<SessionContext>> {
    let ctx = SessionContext::new();
    let dir = std::path::absolute(dir).with_context(|| format!("{}", dir.display()))?;
    if crate::dataset::batch_dirs(&dir)?.is_empty() {
        return Ok(None);
    }
    for table in crate::export::TABLES {
        let files = crate::dataset::table_files(&dir, table)?;
        if files.is_empty() {
            // A table an older fleet schema did not write (`stretches` before schema 4): not
            // registered, so the commands that check the schema say to re-ingest.
            continue;
        }
        let mut schemas = Vec::with_capacity(files.len());
        let mut urls = Vec::with_capacity(files.len());
        for f in &files {
            let file = std::fs::File::open(f).with_context(|| format!("{}", f.display()))?;
            let meta =
                parquet::arrow::arrow_reader::ArrowReaderMetadata::load(&file, Default::default())
                    .with_context(|| format!("{}: not a readable Parquet file", f.display()))?;
            schemas.push(meta.schema().as_ref().clone());
            urls.push(
                ListingTableUrl::parse(f.to_string_lossy())
                    .with_context(|| format!("{}", f.display()))?,
            );
        }
        let schema = Schema::try_merge(schemas).with_context(|| {
            format!("{table}: the runs' columns disagree in type (docs/fleet.md, Schema)")
        })?;
        let options =
            ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
        let config = ListingTableConfig::new_with_multi_paths(urls)
            .with_listing_options(options)
            .with_schema(Arc::new(schema));
        let provider = ListingTable::try_new(config)?;
        ctx.register_table(table, Arc::new(provider))?;
    }
    Ok(Some(ctx))
}

/// The rows of `sql` over the dataset `dir`.
pub async fn run_sql(dir: &Path, sql: &str) -> anyhow::Result<Vec<RecordBatch>> {
    let Some(ctx) = context(dir).await? else {
        anyhow::bail!(
            "{}: no runs ingested (companion-fleet ingest RUN... --into DIR)",
            dir.display()
        );
    };
    let df = ctx.sql(sql).await.context("the query")?;
    Ok(df.collect().await.context("the query")?)
}

/// Batches as a JSON array of row objects.
pub fn to_json(batches: &[RecordBatch]) -> anyhow::Result<serde_json::Value> {
    let mut w = arrow::json::ArrayWriter::new(Vec::new());
    for b in batches {
        w.write(b)?;
    }
    w.finish()?;
    let bytes = w.into_inner();
    if bytes.is_empty() {
        return Ok(serde_json::Value::Array(vec![]));
    }
    Ok(serde_json::from_slice(&bytes)?)
}

/// Batches as a text table.
pub fn to_text(batches: &[RecordBatch]) -> anyhow::Result<String> {
    if batches.iter().all(|b| b.num_rows() == 0) {
        return Ok("(no rows)".into());
    }
    Ok(arrow::util::pretty::pretty_format_batches(batches)?.to_string())
}

/// `sql DIR "SELECT ..." [--json]`.
pub async fn sql_cli(dir: &Path, sql: &str, json: bool) -> anyhow::Result<()> {
    let batches = run_sql(dir, sql).await?;
    if json {
        println!("{}", to_json(&batches)?);
    } else {
        println!("{}", to_text(&batches)?);
    }
    Ok(())
}
