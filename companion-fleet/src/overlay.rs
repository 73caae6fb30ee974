//! `calibrate --out FILE`: the fitted power model as a params overlay (docs/calibrate.md), read
//! by `companion check`, `simulate` and `fly` `--params FILE` as `companion calibrate`'s is. Only
//! the power tables: the dataset holds no legs, durations or BN rows yet (docs/fleet.md).

use anyhow::Context;
use companion::calibrate::power_fit::FitResult;
use companion::calibrate::shipped::Shipped;
use std::path::Path;
use toml::{Table, Value};

fn table<'a>(t: &'a mut Table, key: &str) -> &'a mut Table {
    t.entry(key.to_string())
        .or_insert_with(|| Value::Table(Table::new()))
        .as_table_mut()
        .expect("a table")
}

/// Write the overlay of `r` (fitted from `runs`) over `shipped`'s params to `out`.
pub fn write_power_overlay(
    shipped: &Shipped,
    r: &FitResult,
    runs: &[String],
    out: &Path,
) -> anyhow::Result<()> {
    let mut t = Table::new();
    let params = std::fs::canonicalize(&shipped.dir).unwrap_or_else(|_| shipped.dir.clone());
    let c = table(&mut t, "calibration");
    c.insert("made_by".into(), "companion-fleet calibrate".into());
    c.insert("params".into(), params.display().to_string().into());
    c.insert(
        "runs".into(),
        Value::Array(runs.iter().map(|r| Value::from(r.as_str())).collect()),
    );
    let source = format!(
        "companion-fleet calibrate: {} run(s), {} power samples ({} on the ground), speeds \
         {:.1}..{:.1} m/s; fit RMS {:.1} W; the shipped params' RMS {:.1} W",
        runs.len(),
        r.samples,
        r.ground_samples,
        r.v_min,
        r.v_max,
        r.rms_w,
        r.shipped_rms_w
    );
    let mission = table(&mut t, &shipped.mission_file);
    let p = table(mission, "propulsion");
    let m = r.fitted;
    p.insert("blade_profile_w".into(), m.blade_profile_w.into());
    p.insert("induced_hover_w".into(), m.induced_hover_w.into());
    p.insert("induced_velocity_mps".into(), m.induced_velocity_mps.into());
    p.insert("drag_area_m2".into(), m.drag_area_m2.into());
    p.insert("source".into(), source.clone().into());
    let b = table(mission, "base");
    b.insert("power_w".into(), m.base_w.into());
    b.insert("source".into(), source.into());
    let text = toml::to_string(&t).context("the overlay")?;
    let tmp = out.with_extension("tmp");
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, out).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
