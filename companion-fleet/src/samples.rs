//! The `samples` table: the power samples `companion calibrate` fits a run's power model to,
//! chosen as it chooses them (companion/src/calibrate/mod.rs): the tlog's autopilot telemetry
//! when it gives any, else the records' voltage x current, else the drain of the remaining
//! percentage. The fit's sufficient statistics are SQL aggregates over this table
//! (`companion-fleet calibrate`, docs/fleet.md "Calibration").

use crate::export::RunKey;
use crate::table::{Cell, Kind, TableWriter};
use companion::calibrate::power_fit::Sample;
use companion::calibrate::runs;
use std::path::Path;

fn row(key: &RunKey, source: &str, s: Sample) -> Vec<Cell> {
    vec![
        key.run_id.as_str().into(),
        key.vehicle.as_str().into(),
        source.into(),
        s.speed_mps.into(),
        s.power_w.into(),
        s.airborne.into(),
    ]
}

/// Write the samples of the run in `dir` to `path`: the samples written, or why the run gives
/// none that `calibrate` would accept (a corrupted line, a tlog that is not one); the table is
/// then empty and `runs.samples_error` says why, so that `companion-fleet calibrate` refuses the
/// run as `companion calibrate` does, while the run's other tables are still there.
pub fn export_samples(
    dir: &Path,
    path: &Path,
    key: &RunKey,
) -> anyhow::Result<Result<u64, String>> {
    match write_samples(dir, path, key) {
        Ok(n) => Ok(Ok(n)),
        Err(e) => {
            TableWriter::create(path, &columns())?.finish()?;
            Ok(Err(format!("{e:#}")))
        }
    }
}

fn columns() -> Vec<(String, Kind)> {
    [
        ("run_id", Kind::Str),
        ("vehicle", Kind::Str),
        ("source", Kind::Str),
        ("speed_mps", Kind::F64),
        ("power_w", Kind::F64),
        ("airborne", Kind::Bool),
    ]
    .iter()
    .map(|(n, k)| (n.to_string(), *k))
    .collect()
}

fn write_samples(dir: &Path, path: &Path, key: &RunKey) -> anyhow::Result<u64> {
    let mut w = TableWriter::create(path, &columns())?;
    let mut failed: Option<anyhow::Error> = None;
    // Only what PowerFit::add counts: finite, not negative speeds.
    let mut push = |w: &mut TableWriter, source: &str, s: Sample| {
        let counted = s.speed_mps.is_finite() && s.power_w.is_finite() && s.speed_mps >= 0.0;
        if counted
            && failed.is_none()
            && let Err(e) = w.push(row(key, source, s))
        {
            failed = Some(e);
        }
    };
    let tlog = dir.join("flight.tlog");
    let mut from_tlog = false;
    if tlog.is_file() {
        let pin = runs::fly_pin(dir);
        let read = companion::calibrate::tlog::for_each_sample(
            &tlog,
            pin,
            |s| push(&mut w, "tlog", s),
            |_| {},
        )?;
        from_tlog = read.samples > 0;
    }
    if !from_tlog {
        let mut with_current = false;
        let mut drain = runs::PercentageDrain::default();
        runs::for_each_record(dir, |r| match runs::sample_of(r) {
            Some(s) => {
                push(&mut w, "record", s);
                with_current = true;
            }
            None => drain.add(r),
        })?;
        if !with_current {
            drain.for_each_sample(|s| push(&mut w, "drain", s));
        }
    }
    if let Some(e) = failed {
        return Err(e);
    }
    w.finish()
}
