//! `calibrate --out FILE`: the fits as a params overlay (docs/calibrate.md), written by the
//! companion's own overlay writer from the fits the SQL sums gave (`OverlayParts`): the power
//! model, the legs' `[derive]` entries and the BN rows, as `companion calibrate RUN... --out`
//! writes them from the same runs; read by `companion check`, `simulate` and `fly` `--params
//! FILE`.

use anyhow::Context;
use companion::calibrate::shipped::Shipped;
use companion::calibrate::write::{OverlayParts, overlay_of};
use std::path::Path;

/// Write the overlay of `parts` over `shipped`'s params to `out` (replaced whole: written
/// beside it, then renamed).
pub fn write_overlay(
    shipped: &Shipped,
    parts: &OverlayParts<'_>,
    out: &Path,
) -> anyhow::Result<()> {
    let text = overlay_of(shipped, parts, out).context("the overlay")?;
    let tmp = out.with_extension("tmp");
    std::fs::write(&tmp, text).with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, out).with_context(|| format!("writing {}", out.display()))?;
    Ok(())
}
