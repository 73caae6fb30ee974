//! A Parquet table written in bounded batches: rows are pushed as [`Cell`]s, a batch of
//! [`BATCH_ROWS`] rows goes to the writer, and row groups are cut at [`ROW_GROUP_ROWS`], so what
//! the writer holds is one batch and one row group's pages whatever the run's size.

use anyhow::Context;
use arrow::array::{
    ArrayRef, BooleanBuilder, Float64Builder, Int64Builder, ListBuilder, StringBuilder,
};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::record_batch::RecordBatch;
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::file::properties::WriterProperties;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Rows per Arrow batch handed to the Parquet writer.
pub const BATCH_ROWS: usize = 4096;
/// Rows per Parquet row group (the writer buffers one row group's pages).
pub const ROW_GROUP_ROWS: usize = 65_536;

/// The column types the fleet tables use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    F64,
    I64,
    Str,
    Bool,
    /// A list of strings (actions).
    StrList,
}

impl Kind {
    fn data_type(self) -> DataType {
        match self {
            Kind::F64 => DataType::Float64,
            Kind::I64 => DataType::Int64,
            Kind::Str => DataType::Utf8,
            Kind::Bool => DataType::Boolean,
            Kind::StrList => DataType::List(Arc::new(Field::new("item", DataType::Utf8, true))),
        }
    }
}

/// One value of a row; `Null` for a missing one.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    Null,
    F64(f64),
    I64(i64),
    Str(String),
    Bool(bool),
    StrList(Vec<String>),
}

impl From<f64> for Cell {
    fn from(v: f64) -> Self {
        Cell::F64(v)
    }
}
impl From<Option<f64>> for Cell {
    fn from(v: Option<f64>) -> Self {
        v.map_or(Cell::Null, Cell::F64)
    }
}
impl From<i64> for Cell {
    fn from(v: i64) -> Self {
        Cell::I64(v)
    }
}
impl From<u64> for Cell {
    fn from(v: u64) -> Self {
        // Counters and cycle numbers: far below 2^63; saturate rather than wrap.
        Cell::I64(i64::try_from(v).unwrap_or(i64::MAX))
    }
}
impl From<&str> for Cell {
    fn from(v: &str) -> Self {
        Cell::Str(v.to_string())
    }
}
impl From<String> for Cell {
    fn from(v: String) -> Self {
        Cell::Str(v)
    }
}
impl From<Option<String>> for Cell {
    fn from(v: Option<String>) -> Self {
        v.map_or(Cell::Null, Cell::Str)
    }
}
impl From<bool> for Cell {
    fn from(v: bool) -> Self {
        Cell::Bool(v)
    }
}

enum Builder {
    F64(Float64Builder),
    I64(Int64Builder),
    Str(StringBuilder),
    Bool(BooleanBuilder),
    StrList(ListBuilder<StringBuilder>),
}

impl Builder {
    fn new(kind: Kind) -> Self {
        match kind {
            Kind::F64 => Builder::F64(Float64Builder::new()),
            Kind::I64 => Builder::I64(Int64Builder::new()),
            Kind::Str => Builder::Str(StringBuilder::new()),
            Kind::Bool => Builder::Bool(BooleanBuilder::new()),
            Kind::StrList => Builder::StrList(ListBuilder::new(StringBuilder::new())),
        }
    }

    /// Append `c`; a cell of another type than the column's is written as null (the schema is
    /// fixed before the rows, so this is a caller's bug, not an input's).
    fn push(&mut self, c: Cell) {
        match (self, c) {
            (Builder::F64(b), Cell::F64(v)) => b.append_value(v),
            (Builder::F64(b), Cell::I64(v)) => b.append_value(v as f64),
            (Builder::F64(b), _) => b.append_null(),
            (Builder::I64(b), Cell::I64(v)) => b.append_value(v),
            (Builder::I64(b), _) => b.append_null(),
            (Builder::Str(b), Cell::Str(v)) => b.append_value(v),
            (Builder::Str(b), _) => b.append_null(),
            (Builder::Bool(b), Cell::Bool(v)) => b.append_value(v),
            (Builder::Bool(b), _) => b.append_null(),
            (Builder::StrList(b), Cell::StrList(v)) => {
                for s in v {
                    b.values().append_value(s);
                }
                b.append(true);
            }
            (Builder::StrList(b), _) => b.append(false),
        }
    }

    fn finish(&mut self) -> ArrayRef {
        match self {
            Builder::F64(b) => Arc::new(b.finish()),
            Builder::I64(b) => Arc::new(b.finish()),
            Builder::Str(b) => Arc::new(b.finish()),
            Builder::Bool(b) => Arc::new(b.finish()),
            Builder::StrList(b) => Arc::new(b.finish()),
        }
    }
}

/// The schema of `columns` (every column nullable: old logs lack fields).
pub fn schema(columns: &[(String, Kind)]) -> SchemaRef {
    Arc::new(Schema::new(
        columns
            .iter()
            .map(|(n, k)| Field::new(n, k.data_type(), true))
            .collect::<Vec<_>>(),
    ))
}

/// A table being written to one Parquet file.
pub struct TableWriter {
    path: PathBuf,
    schema: SchemaRef,
    builders: Vec<Builder>,
    pending: usize,
    rows: u64,
    writer: ArrowWriter<File>,
}

/// How every Parquet file of the fleet is written: snappy (read by pyarrow, DuckDB, Spark), row
/// groups cut at [`ROW_GROUP_ROWS`].
pub fn writer_properties() -> WriterProperties {
    WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .set_max_row_group_row_count(Some(ROW_GROUP_ROWS))
        .build()
}

impl TableWriter {
    /// Create `path` with `columns`.
    pub fn create(path: &Path, columns: &[(String, Kind)]) -> anyhow::Result<Self> {
        let schema = schema(columns);
        let file = File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let writer = ArrowWriter::try_new(file, schema.clone(), Some(writer_properties()))
            .with_context(|| format!("writing {}", path.display()))?;
        Ok(TableWriter {
            path: path.to_path_buf(),
            builders: columns.iter().map(|(_, k)| Builder::new(*k)).collect(),
            schema,
            pending: 0,
            rows: 0,
            writer,
        })
    }

    /// Append one row, its cells in the columns' order.
    pub fn push(&mut self, row: Vec<Cell>) -> anyhow::Result<()> {
        debug_assert_eq!(row.len(), self.builders.len());
        for (b, c) in self.builders.iter_mut().zip(row) {
            b.push(c);
        }
        self.pending += 1;
        self.rows += 1;
        if self.pending >= BATCH_ROWS {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> anyhow::Result<()> {
        if self.pending == 0 {
            return Ok(());
        }
        let arrays: Vec<ArrayRef> = self.builders.iter_mut().map(Builder::finish).collect();
        let batch = RecordBatch::try_new(self.schema.clone(), arrays)
            .with_context(|| format!("a batch of {}", self.path.display()))?;
        self.writer
            .write(&batch)
            .with_context(|| format!("writing {}", self.path.display()))?;
        self.pending = 0;
        Ok(())
    }

    /// Write what is pending and close the file; the rows written. Not synced: a run's files
    /// are a scratch copy that ingest appends to its batch, and the batch's files are synced
    /// (batch.rs).
    pub fn finish(mut self) -> anyhow::Result<u64> {
        self.flush()?;
        self.writer
            .into_inner()
            .with_context(|| format!("closing {}", self.path.display()))?;
        Ok(self.rows)
    }
}
