//! The fleet dataset: `DIR/vehicle=V/date=D/batch=HEX/<table>.parquet`, one folder per ingest
//! and partition, holding that ingest's runs of the partition (batch.rs).
//!
//! Ingest writes a batch's tables into a temporary folder inside the dataset (`DIR/.tmp-...`: a
//! reader skips names starting with `.` or `_`, as Hive and Spark do), syncs them, and renames
//! the folder into place: a run killed mid-ingest leaves no partial run, only a temporary
//! folder, which the next ingest removes. A run already there (same content id in a `runs`
//! table, whatever its folder's name or vehicle) is not written again.

use crate::export::{RunKey, TABLES, export_run, partition_value, run_key};
use anyhow::Context;
use arrow::array::AsArray;
use parquet::arrow::ProjectionMask;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

fn hidden(name: &str) -> bool {
    name.starts_with('.') || name.starts_with('_')
}

fn sub_dirs(dir: &Path, prefix: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(anyhow::anyhow!("{}: cannot be listed: {e}", dir.display())),
    };
    for e in entries {
        let e = e.with_context(|| format!("listing {}", dir.display()))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if hidden(&name) || !name.starts_with(prefix) || !e.path().is_dir() {
            continue;
        }
        out.push(e.path());
    }
    out.sort();
    Ok(out)
}

/// Every batch folder of the dataset `dir` (`batch=`, or a run folder `run=` of a dataset
/// written before batches: a batch of one run), sorted (temporary folders skipped).
pub fn batch_dirs(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut batches = Vec::new();
    for v in sub_dirs(dir, "vehicle=")? {
        for d in sub_dirs(&v, "date=")? {
            batches.extend(sub_dirs(&d, "batch=")?);
            batches.extend(sub_dirs(&d, "run=")?);
        }
    }
    batches.sort();
    Ok(batches)
}

/// The run ids the dataset holds (its `runs` tables' `run_id`), each with its batch folder.
fn present_runs(dir: &Path) -> anyhow::Result<HashMap<String, PathBuf>> {
    let mut out = HashMap::new();
    for b in batch_dirs(dir)? {
        for f in files_of(&b, "runs")? {
            let file = std::fs::File::open(&f).with_context(|| format!("{}", f.display()))?;
            let reader = ParquetRecordBatchReaderBuilder::try_new(file)
                .with_context(|| format!("{}: not a readable Parquet file", f.display()))?;
            let mask = ProjectionMask::columns(reader.parquet_schema(), ["run_id"]);
            for batch in reader.with_projection(mask).build()? {
                let batch = batch.with_context(|| format!("reading {}", f.display()))?;
                let ids = batch
                    .column_by_name("run_id")
                    .and_then(|c| c.as_string_opt::<i32>())
                    .with_context(|| format!("{}: no run_id column", f.display()))?;
                for id in ids.iter().flatten() {
                    out.insert(id.to_string(), b.clone());
                }
            }
        }
    }
    Ok(out)
}

/// Remove temporary folders of ingests no longer running (their process id is in the name).
fn remove_stale_temps(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = name.strip_prefix(".tmp-") else {
            continue;
        };
        let pid = rest.rsplit('-').next().and_then(|p| p.parse::<u32>().ok());
        let alive = pid.is_some_and(|p| Path::new(&format!("/proc/{p}")).exists());
        if !alive || pid == Some(std::process::id()) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// A batch's folder name: `batch=` and the SHA-256 of its runs' ids (sorted), so the same runs
/// give the same name and different batches never meet.
fn batch_folder_name(keys: &[(PathBuf, RunKey)]) -> String {
    use sha2::Digest;
    let mut ids: Vec<&str> = keys.iter().map(|(_, k)| k.run_id.as_str()).collect();
    ids.sort_unstable();
    let mut h = sha2::Sha256::new();
    for id in ids {
        h.update(id.as_bytes());
        h.update(b"\n");
    }
    let hex: String = h.finalize().iter().map(|b| format!("{b:02x}")).collect();
    format!("batch={hex}")
}

/// Write the runs of one partition (`vehicle`, `date`) as one batch folder: each run exported
/// into a scratch folder and appended to the batch's tables, then the folder synced and renamed
/// into place (absent until then: a killed ingest leaves only a temporary folder).
fn write_batch(into: &Path, keys: &[(PathBuf, RunKey)]) -> anyhow::Result<PathBuf> {
    let name = batch_folder_name(keys);
    let tmp = into.join(format!(
        ".tmp-{}-{}",
        name.trim_start_matches("batch="),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let written = fill_and_place(into, &tmp, &name, keys);
    if written.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    written
}

fn fill_and_place(
    into: &Path,
    tmp: &Path,
    name: &str,
    keys: &[(PathBuf, RunKey)],
) -> anyhow::Result<PathBuf> {
    let scratch = tmp.join(".run");
    let mut batch = crate::batch::BatchWriter::new(tmp, &TABLES);
    for (run, key) in keys {
        std::fs::create_dir_all(&scratch)
            .with_context(|| format!("creating {}", scratch.display()))?;
        export_run(run, &scratch, key).with_context(|| format!("exporting {}", run.display()))?;
        batch
            .append_run(&scratch)
            .with_context(|| format!("adding {}", run.display()))?;
        std::fs::remove_dir_all(&scratch)
            .with_context(|| format!("removing {}", scratch.display()))?;
    }
    batch.finish()?;
    sync_dir(tmp)?;
    let key = &keys[0].1;
    let parent = into
        .join(format!("vehicle={}", partition_value(&key.vehicle)))
        .join(format!("date={}", partition_value(&key.date)));
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    let dest = parent.join(name);
    std::fs::rename(tmp, &dest).with_context(|| {
        format!(
            "moving {} to {} (another ingest of the same runs?)",
            tmp.display(),
            dest.display()
        )
    })?;
    sync_dir(&parent)?;
    sync_dir(into)?;
    Ok(dest)
}

fn sync_dir(d: &Path) -> anyhow::Result<()> {
    std::fs::File::open(d)
        .and_then(|f| f.sync_all())
        .with_context(|| format!("syncing {}", d.display()))
}

/// `ingest RUN... --into DIR`: each run folder (or folder of run folders) added once, the new
/// runs of each partition (vehicle, date) as one batch folder.
pub fn ingest(runs: &[PathBuf], into: &Path, vehicle: Option<&str>) -> anyhow::Result<()> {
    std::fs::create_dir_all(into).with_context(|| format!("creating {}", into.display()))?;
    remove_stale_temps(into);
    let runs = companion::calibrate::runs::discover(runs)?;
    let mut present = present_runs(into)?;
    let mut there = 0;
    let mut batches: BTreeMap<(String, String), Vec<(PathBuf, RunKey)>> = BTreeMap::new();
    for r in runs {
        let key = run_key(&r, vehicle)?;
        if let Some(p) = present.get(&key.run_id) {
            there += 1;
            eprintln!("{}: already in the dataset ({})", r.display(), p.display());
            continue;
        }
        present.insert(key.run_id.clone(), r.clone());
        let partition = (partition_value(&key.vehicle), partition_value(&key.date));
        batches.entry(partition).or_default().push((r, key));
    }
    let mut added = 0;
    for keys in batches.values() {
        let dest = write_batch(into, keys)?;
        for (r, _) in keys {
            added += 1;
            eprintln!("{}: added in {}", r.display(), dest.display());
        }
    }
    println!(
        "{added} run(s) added, {there} already there: {} now holds {} run(s)",
        into.display(),
        present_runs(into)?.len()
    );
    Ok(())
}

/// `table`'s files in the batch folder `batch`, in order.
fn files_of(batch: &Path, table: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for e in std::fs::read_dir(batch).with_context(|| format!("listing {}", batch.display()))? {
        let e = e.with_context(|| format!("listing {}", batch.display()))?;
        if crate::batch::is_table_file(&e.file_name().to_string_lossy(), table) {
            files.push(e.path());
        }
    }
    files.sort();
    Ok(files)
}

/// The Parquet files of `table` in the dataset: one or a few per batch.
pub fn table_files(dir: &Path, table: &str) -> anyhow::Result<Vec<PathBuf>> {
    debug_assert!(TABLES.contains(&table));
    let mut files = Vec::new();
    for b in batch_dirs(dir)? {
        files.extend(files_of(&b, table)?);
    }
    Ok(files)
}

/// `export RUN --out DIR`: the run's tables in `out` (created; an existing table file is
/// replaced).
pub fn export(run: &Path, out: &Path, vehicle: Option<&str>) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let key = run_key(run, vehicle)?;
    let counts = export_run(run, out, &key)?;
    println!(
        "{}: {} records of run {} written to {}",
        run.display(),
        counts.records,
        key.run_id,
        out.display()
    );
    Ok(())
}
