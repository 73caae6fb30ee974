//! One ingest's runs of one partition (`vehicle=V/date=D`) as one folder of tables: each run is
//! exported on its own (export.rs, into a scratch folder), then its tables' rows are appended to
//! the batch's files, so a partition holds one file per table per ingest, not one per run (the
//! readers' cost grows with the files: docs/performance.md, "Fleet"). A run whose table has
//! other columns than the file being written (its maps' keys differ) starts the table's next
//! file (`records.1.parquet`, ...), so the files stay few when the runs are alike and correct
//! when they are not. Only the batch's files are synced, once, before the folder is renamed into
//! place: the batch is atomic, as a run folder was.

use crate::table::{BATCH_ROWS, writer_properties};
use anyhow::Context;
use arrow::datatypes::SchemaRef;
use parquet::arrow::ArrowWriter;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::fs::File;
use std::path::{Path, PathBuf};

/// The file name of `table`'s `n`th file in a batch folder: `records.parquet`, then
/// `records.1.parquet`, ...
pub fn file_name(table: &str, n: usize) -> String {
    if n == 0 {
        format!("{table}.parquet")
    } else {
        format!("{table}.{n}.parquet")
    }
}

/// Whether `name` is one of `table`'s files (`<table>.parquet` or `<table>.<n>.parquet`).
pub fn is_table_file(name: &str, table: &str) -> bool {
    let Some(rest) = name
        .strip_prefix(table)
        .and_then(|r| r.strip_prefix('.'))
        .and_then(|r| r.strip_suffix("parquet"))
    else {
        return false;
    };
    rest.is_empty()
        || rest
            .strip_suffix('.')
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|c| c.is_ascii_digit()))
}

/// One table's files in the batch: the one being written and its columns.
struct TableFiles {
    table: &'static str,
    current: Option<(SchemaRef, ArrowWriter<File>)>,
    files: usize,
}

/// The batch's tables being written into its (temporary) folder.
pub struct BatchWriter {
    dir: PathBuf,
    tables: Vec<TableFiles>,
}

impl BatchWriter {
    pub fn new(dir: &Path, tables: &[&'static str]) -> Self {
        BatchWriter {
            dir: dir.to_path_buf(),
            tables: (tables.iter())
                .map(|t| TableFiles {
                    table: t,
                    current: None,
                    files: 0,
                })
                .collect(),
        }
    }

    /// Append the tables of one exported run (`run_dir/<table>.parquet`), batch by batch.
    pub fn append_run(&mut self, run_dir: &Path) -> anyhow::Result<()> {
        for t in &mut self.tables {
            let path = run_dir.join(file_name(t.table, 0));
            let file = File::open(&path).with_context(|| format!("{}", path.display()))?;
            let reader = ParquetRecordBatchReaderBuilder::try_new(file)
                .with_context(|| format!("{}: not a readable Parquet file", path.display()))?;
            let schema = reader.schema().clone();
            let rows = reader.metadata().file_metadata().num_rows();
            let same = t.current.as_ref().is_some_and(|(s, _)| *s == schema);
            // A run without rows adds nothing, unless the table has no file yet (every table
            // has one in every batch folder, for the readers).
            if !same && (rows > 0 || t.current.is_none()) {
                t.roll(&self.dir, schema)?;
            }
            if rows == 0 {
                continue;
            }
            let Some((_, w)) = t.current.as_mut() else {
                continue;
            };
            for batch in reader.with_batch_size(BATCH_ROWS).build()? {
                let batch = batch.with_context(|| format!("reading {}", path.display()))?;
                w.write(&batch)
                    .with_context(|| format!("writing the batch's {}", t.table))?;
            }
        }
        Ok(())
    }

    /// Close every file and sync it to disk.
    pub fn finish(self) -> anyhow::Result<()> {
        for mut t in self.tables {
            t.close()?;
        }
        Ok(())
    }
}

impl TableFiles {
    fn close(&mut self) -> anyhow::Result<()> {
        if let Some((_, w)) = self.current.take() {
            let file = w
                .into_inner()
                .with_context(|| format!("closing the batch's {}", self.table))?;
            file.sync_all()
                .with_context(|| format!("syncing the batch's {}", self.table))?;
        }
        Ok(())
    }

    /// Close the file being written and start the table's next one with `schema`.
    fn roll(&mut self, dir: &Path, schema: SchemaRef) -> anyhow::Result<()> {
        self.close()?;
        let path = dir.join(file_name(self.table, self.files));
        let file = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let w = ArrowWriter::try_new(file, schema.clone(), Some(writer_properties()))
            .with_context(|| format!("writing {}", path.display()))?;
        self.current = Some((schema, w));
        self.files += 1;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tables_files_are_told_from_others() {
        assert!(is_table_file("records.parquet", "records"));
        assert!(is_table_file("records.12.parquet", "records"));
        assert!(!is_table_file("records.x.parquet", "records"));
        assert!(!is_table_file("records..parquet", "records"));
        assert!(!is_table_file("runs.parquet", "records"));
        assert!(!is_table_file("recordsx.parquet", "records"));
        assert_eq!(file_name("legs", 0), "legs.parquet");
        assert_eq!(file_name("legs", 2), "legs.2.parquet");
    }
}
