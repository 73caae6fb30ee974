//! The runs `calibrate` reads: run folders as `fly` and `simulate` write them, or folders of
//! run folders, read one record at a time (docs/calibrate.md).

use super::power_fit::Sample;
use crate::decision_log::{LOG_STEM, LogItem, stream_log};
use companion_core::record::DecisionRecord;
use std::path::{Path, PathBuf};

/// A run folder holds `decisions.jsonl`.
fn is_run_folder(p: &Path) -> bool {
    p.join(format!("{LOG_STEM}.jsonl")).is_file()
}

/// The run folders named by `args`: each a run folder, or a folder whose subfolders (one level,
/// sorted) are run folders. A name that is neither is an error.
pub fn discover(args: &[PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for a in args {
        if is_run_folder(a) {
            out.push(a.clone());
            continue;
        }
        let entries = std::fs::read_dir(a).map_err(|e| {
            anyhow::anyhow!(
                "{}: not a run folder and cannot be listed: {e}",
                a.display()
            )
        })?;
        let mut runs: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_run_folder(p))
            .collect();
        if runs.is_empty() {
            anyhow::bail!(
                "{}: neither a run folder ({LOG_STEM}.jsonl) nor a folder of run folders",
                a.display()
            );
        }
        runs.sort();
        out.extend(runs);
    }
    Ok(out)
}

/// Call `each` with every record of the run folder `dir`, in order. A corrupted line stops with
/// its file, line and reason; a last line cut off (a run killed while writing) is skipped with
/// a warning.
pub fn for_each_record(dir: &Path, mut each: impl FnMut(&DecisionRecord)) -> anyhow::Result<u64> {
    let stream = stream_log(dir).map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
    let mut n = 0;
    for item in stream {
        let item = item.map_err(|e| anyhow::anyhow!("{}: {e}", dir.display()))?;
        match item {
            LogItem::Record(r, _) => {
                each(&r);
                n += 1;
            }
            LogItem::Corrupted(i) => {
                anyhow::bail!("{}, line {}: {}", i.file.display(), i.line, i.reason)
            }
            LogItem::Truncated(i) => tracing::warn!(
                "{}, line {}: {} (skipped)",
                i.file.display(),
                i.line,
                i.reason
            ),
            _ => {}
        }
    }
    Ok(n)
}

/// The power sample of a `fly` record: pack voltage x current (BATTERY_STATUS, else
/// SYS_STATUS: observations `battery_v`, `battery_current_a`), horizontal speed (VFR_HUD
/// groundspeed: `groundspeed_mps`), armed (HEARTBEAT: `armed`) and, when reported, the
/// altitude above home (`altitude_m`). Armed and above 1 m: in the air; disarmed: on the
/// ground; armed on the ground (spinning up, landed) is neither. `None` without voltage, current
/// and the armed flag, or with a value out of range.
pub fn sample_of(r: &DecisionRecord) -> Option<Sample> {
    let o = &r.observations;
    let v = *o.get("battery_v")?;
    let a = *o.get("battery_current_a")?;
    let armed = *o.get("armed")? > 0.5;
    let speed = o.get("groundspeed_mps").copied();
    let alt = o.get("altitude_m").copied();
    if !(v.is_finite() && a.is_finite() && v > 0.0 && a >= 0.0) {
        return None;
    }
    let airborne = if !armed {
        false
    } else if alt.is_none_or(|h| h > 1.0) {
        true
    } else {
        return None;
    };
    let speed_mps = if airborne { speed? } else { 0.0 };
    if !speed_mps.is_finite() || speed_mps < 0.0 {
        return None;
    }
    Some(Sample {
        speed_mps,
        power_w: v * a,
        airborne,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(obs: &[(&str, f64)]) -> DecisionRecord {
        DecisionRecord {
            observations: obs.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn samples_are_read_from_the_observations() {
        let air = rec(&[
            ("battery_v", 12.0),
            ("battery_current_a", 20.0),
            ("armed", 1.0),
            ("groundspeed_mps", 5.0),
            ("altitude_m", 30.0),
        ]);
        assert_eq!(
            sample_of(&air),
            Some(Sample {
                speed_mps: 5.0,
                power_w: 240.0,
                airborne: true
            })
        );
        let ground = rec(&[
            ("battery_v", 12.0),
            ("battery_current_a", 0.5),
            ("armed", 0.0),
        ]);
        assert_eq!(
            sample_of(&ground),
            Some(Sample {
                speed_mps: 0.0,
                power_w: 6.0,
                airborne: false
            })
        );
        let spinning = rec(&[
            ("battery_v", 12.0),
            ("battery_current_a", 5.0),
            ("armed", 1.0),
            ("groundspeed_mps", 0.0),
            ("altitude_m", 0.2),
        ]);
        assert_eq!(sample_of(&spinning), None);
        let no_current = rec(&[("battery_v", 12.0), ("armed", 1.0)]);
        assert_eq!(sample_of(&no_current), None);
        let bad = rec(&[
            ("battery_v", 12.0),
            ("battery_current_a", -3.0),
            ("armed", 0.0),
        ]);
        assert_eq!(sample_of(&bad), None);
    }
}
