//! The fleet dataset: `DIR/vehicle=V/date=D/run=HEX/<table>.parquet`, one folder per run.
//!
//! Ingest writes a run's tables into a temporary folder inside the dataset (`DIR/.tmp-...`: a
//! reader skips names starting with `.` or `_`, as Hive and Spark do), syncs them, and renames
//! the folder into place: a run killed mid-ingest leaves no partial run, only a temporary
//! folder, which the next ingest removes. A run already there (same content id, whatever its
//! folder's name or vehicle) is not written again.

use crate::export::{RunKey, TABLES, export_run, partition_value, run_key};
use anyhow::Context;
use std::path::{Path, PathBuf};

/// Folder name of a run: `run=` and its content hash in hex.
fn run_folder_name(run_id: &str) -> String {
    format!("run={}", run_id.trim_start_matches("sha256:"))
}

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

/// Every run folder of the dataset `dir`, sorted (temporary folders skipped).
pub fn run_dirs(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut runs = Vec::new();
    for v in sub_dirs(dir, "vehicle=")? {
        for d in sub_dirs(&v, "date=")? {
            runs.extend(sub_dirs(&d, "run=")?);
        }
    }
    Ok(runs)
}

/// The run folder holding `run_id`, if the dataset has it.
fn find_run(dir: &Path, run_id: &str) -> anyhow::Result<Option<PathBuf>> {
    let name = run_folder_name(run_id);
    Ok(run_dirs(dir)?
        .into_iter()
        .find(|p| p.file_name().is_some_and(|n| n.to_string_lossy() == name)))
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

/// What ingesting one run did.
#[derive(Debug)]
pub enum Ingested {
    Added(PathBuf),
    /// The dataset had this run already (at this folder).
    AlreadyThere(PathBuf),
}

/// Add the run in `run` to the dataset `into`.
pub fn ingest_run(run: &Path, into: &Path, vehicle: Option<&str>) -> anyhow::Result<Ingested> {
    let key = run_key(run, vehicle)?;
    if let Some(p) = find_run(into, &key.run_id)? {
        return Ok(Ingested::AlreadyThere(p));
    }
    let tmp = into.join(format!(
        ".tmp-{}-{}",
        key.run_id.trim_start_matches("sha256:"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
    let written = write_and_place(run, into, &tmp, &key);
    if written.is_err() {
        let _ = std::fs::remove_dir_all(&tmp);
    }
    written.map(Ingested::Added)
}

fn write_and_place(run: &Path, into: &Path, tmp: &Path, key: &RunKey) -> anyhow::Result<PathBuf> {
    export_run(run, tmp, key).with_context(|| format!("exporting {}", run.display()))?;
    sync_dir(tmp)?;
    let parent = into
        .join(format!("vehicle={}", partition_value(&key.vehicle)))
        .join(format!("date={}", partition_value(&key.date)));
    std::fs::create_dir_all(&parent).with_context(|| format!("creating {}", parent.display()))?;
    let dest = parent.join(run_folder_name(&key.run_id));
    std::fs::rename(tmp, &dest).with_context(|| {
        format!(
            "moving {} to {} (another ingest of the same run?)",
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

/// `ingest RUN... --into DIR`: each run folder (or folder of run folders) added once.
pub fn ingest(runs: &[PathBuf], into: &Path, vehicle: Option<&str>) -> anyhow::Result<()> {
    std::fs::create_dir_all(into).with_context(|| format!("creating {}", into.display()))?;
    remove_stale_temps(into);
    let runs = companion::calibrate::runs::discover(runs)?;
    let (mut added, mut there) = (0, 0);
    for r in &runs {
        match ingest_run(r, into, vehicle)? {
            Ingested::Added(p) => {
                added += 1;
                eprintln!("{}: added as {}", r.display(), p.display());
            }
            Ingested::AlreadyThere(p) => {
                there += 1;
                eprintln!("{}: already in the dataset ({})", r.display(), p.display());
            }
        }
    }
    println!(
        "{added} run(s) added, {there} already there: {} now holds {} run(s)",
        into.display(),
        run_dirs(into)?.len()
    );
    Ok(())
}

/// The Parquet files of `table` in the dataset, one per run.
pub fn table_files(dir: &Path, table: &str) -> anyhow::Result<Vec<PathBuf>> {
    debug_assert!(TABLES.contains(&table));
    Ok(run_dirs(dir)?
        .into_iter()
        .map(|r| r.join(format!("{table}.parquet")))
        .collect())
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
