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
                crate::output_file::shown(a)
            )
        })?;
        let mut runs: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_run_folder(p))
            .collect();
        if runs.is_empty() {
            anyhow::bail!(
                "{}: neither a run folder ({LOG_STEM}.jsonl) nor a folder of run folders",
                crate::output_file::shown(a)
            );
        }
        runs.sort();
        out.extend(runs);
    }
    Ok(out)
}

/// The SHA-256 of a run's contents: its decision log (every rotation part) and its
/// `flight.tlog`, whatever names, symlinks or copies lead to them. Two runs with the same hash
/// are one run.
pub fn content_hash(dir: &Path) -> anyhow::Result<[u8; 32]> {
    use sha2::Digest;
    let mut h = sha2::Sha256::new();
    let mut files = crate::decision_log::log_files(dir)
        .map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(dir)))?;
    let tlog = dir.join("flight.tlog");
    if tlog.is_file() {
        files.push(tlog);
    }
    for f in files {
        crate::params_files::regular_file(&f)
            .map_err(|r| anyhow::anyhow!("{}: {r}", crate::output_file::shown(&f)))?;
        let mut rd = std::fs::File::open(&f)
            .map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(&f)))?;
        // The file's name is not hashed (a renamed copy is the same run); its length is, so
        // that the files' boundaries count.
        let (mut buf, mut n) = (vec![0u8; 1 << 16], 0u64);
        loop {
            let k = std::io::Read::read(&mut rd, &mut buf)
                .map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(&f)))?;
            if k == 0 {
                break;
            }
            h.update(&buf[..k]);
            n += k as u64;
        }
        h.update(n.to_le_bytes());
    }
    Ok(h.finalize().into())
}

/// A run's content id as an overlay names it: `sha256:` and [`content_hash`] in hex.
pub fn content_id(dir: &Path) -> anyhow::Result<String> {
    let h = content_hash(dir)?;
    Ok(h.iter().fold(String::from("sha256:"), |mut s, b| {
        use std::fmt::Write;
        let _ = write!(s, "{b:02x}");
        s
    }))
}

/// Run names left out as repeats, each with the run it repeats.
pub type Repeats = Vec<(PathBuf, PathBuf)>;

/// `runs` with each content once (the first name kept, in order), and the names left out with
/// the name of the run they repeat.
pub fn once_each(runs: Vec<PathBuf>) -> anyhow::Result<(Vec<PathBuf>, Repeats)> {
    let mut seen: std::collections::HashMap<[u8; 32], PathBuf> = Default::default();
    let (mut kept, mut repeats) = (Vec::new(), Vec::new());
    for r in runs {
        let h = content_hash(&r)?;
        match seen.get(&h) {
            Some(first) => repeats.push((r, first.clone())),
            None => {
                seen.insert(h, r.clone());
                kept.push(r);
            }
        }
    }
    Ok((kept, repeats))
}

/// The autopilot `fly` was pinned to in this run (`--autopilot-sysid N [--autopilot-compid M]`
/// on the command line its log header records), if it was.
pub fn fly_pin(dir: &Path) -> Option<(u8, u8)> {
    let first = stream_log(dir).ok()?.next()?.ok()?;
    let LogItem::Header(h) = first else {
        return None;
    };
    let words: Vec<&str> = h.command.split_whitespace().collect();
    let value = |flag: &str| -> Option<u8> {
        let eq = format!("{flag}=");
        words
            .iter()
            .enumerate()
            .find_map(|(i, w)| match w.strip_prefix(&eq) {
                Some(v) => v.parse().ok(),
                None if *w == flag => words.get(i + 1)?.parse().ok(),
                None => None,
            })
    };
    let sys = value("--autopilot-sysid").filter(|s| *s > 0)?;
    let comp = value("--autopilot-compid").unwrap_or(companion_link::vehicle::AUTOPILOT_COMPONENT);
    Some((sys, comp))
}

/// Call `each` with every record of the run folder `dir`, in order. A corrupted line stops with
/// its file, line and reason; a last line cut off (a run killed while writing) is skipped with
/// a warning.
pub fn for_each_record(dir: &Path, mut each: impl FnMut(&DecisionRecord)) -> anyhow::Result<u64> {
    let stream =
        stream_log(dir).map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(dir)))?;
    let mut n = 0;
    for item in stream {
        let item = item.map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(dir)))?;
        match item {
            LogItem::Record(r, _) => {
                each(&r);
                n += 1;
            }
            LogItem::Corrupted(i) => {
                anyhow::bail!(
                    "{}, line {}: {}",
                    crate::output_file::shown(&i.file),
                    i.line,
                    i.reason
                )
            }
            LogItem::Truncated(i) => tracing::warn!(
                "{}, line {}: {} (skipped)",
                crate::output_file::shown(&i.file),
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

/// Power from the drain of the remaining percentage, for an autopilot that reports no current
/// (PX4 SIH: its BatterySimulator sends current -1 and drains the percentage linearly while
/// armed, over `SIM_BAT_DRAIN` seconds): the least-squares slope of `battery_pct` against the
/// autopilot's time over the armed, airborne records, times the pack's energy (the record's
/// `guarantee.pack.capacity_j`). One power for the whole run, so the samples it gives carry it
/// at every speed flown (the speed terms come out 0: such a battery does not depend on speed),
/// and 0 W on the ground (such a battery is not drawn while disarmed).
#[derive(Default)]
pub struct PercentageDrain {
    n: f64,
    st: f64,
    sp: f64,
    stt: f64,
    stp: f64,
    capacity_j: Option<f64>,
    airborne_speeds: Vec<f32>,
    ground: u64,
}

/// The fewest airborne records a drain slope is taken from (the percentage is whole numbers).
const MIN_DRAIN_RECORDS: f64 = 30.0;

impl PercentageDrain {
    pub fn add(&mut self, r: &DecisionRecord) {
        let o = &r.observations;
        let Some(armed) = o.get("armed").map(|a| *a > 0.5) else {
            return;
        };
        if !armed {
            self.ground += 1;
            return;
        }
        let (Some(pct), Some(speed)) = (o.get("battery_pct"), o.get("groundspeed_mps")) else {
            return;
        };
        if o.get("altitude_m").is_some_and(|h| *h <= 1.0) {
            return;
        }
        let t = o.get("vehicle_time_s").copied().unwrap_or(r.time_s);
        if !(t.is_finite() && pct.is_finite() && speed.is_finite() && *speed >= 0.0) {
            return;
        }
        if let Some(c) = r
            .guarantee
            .as_ref()
            .and_then(|g| g.pack.as_ref())
            .map(|p| p.capacity_j)
            && c.is_finite()
            && c > 0.0
        {
            self.capacity_j = Some(c);
        }
        self.n += 1.0;
        self.st += t;
        self.sp += pct;
        self.stt += t * t;
        self.stp += t * pct;
        self.airborne_speeds.push(*speed as f32);
    }

    /// The drain power (W), when the run gives one.
    pub fn power_w(&self) -> Option<f64> {
        let c = self.capacity_j?;
        if self.n < MIN_DRAIN_RECORDS {
            return None;
        }
        let var = self.stt - self.st * self.st / self.n;
        if var <= 0.0 {
            return None;
        }
        let slope = (self.stp - self.st * self.sp / self.n) / var;
        let w = -slope / 100.0 * c;
        (w.is_finite() && w > 0.0).then_some(w)
    }

    /// Call `each` with the samples this run gives (none without a drain power).
    pub fn for_each_sample(&self, mut each: impl FnMut(Sample)) -> u64 {
        let Some(w) = self.power_w() else { return 0 };
        for v in &self.airborne_speeds {
            each(Sample {
                speed_mps: f64::from(*v),
                power_w: w,
                airborne: true,
            });
        }
        for _ in 0..self.ground {
            each(Sample {
                speed_mps: 0.0,
                power_w: 0.0,
                airborne: false,
            });
        }
        self.airborne_speeds.len() as u64 + self.ground
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pin_fly_flew_with_is_read_from_the_header() {
        let d = tempfile::tempdir().unwrap();
        let pin_of = |command: &str| {
            let h = crate::decision_log::Header::new(command, std::time::SystemTime::UNIX_EPOCH);
            std::fs::write(
                d.path().join("decisions.jsonl"),
                serde_json::to_string(&h).unwrap() + "\n",
            )
            .unwrap();
            fly_pin(d.path())
        };
        assert_eq!(pin_of("companion fly --connect x"), None);
        assert_eq!(pin_of("companion fly --autopilot-sysid 1"), Some((1, 1)));
        assert_eq!(
            pin_of("companion fly --autopilot-sysid=3 --autopilot-compid 2"),
            Some((3, 2))
        );
        assert_eq!(pin_of("companion fly --autopilot-sysid x"), None);
    }

    #[test]
    fn a_linear_drain_gives_the_pack_over_the_drain_time() {
        use companion_core::record::{GuaranteeRecord, PackRecord};
        // A 266,400 J pack drained 1 % per 36 s (SIM_BAT_DRAIN 3600 s): 74 W.
        let mut d = PercentageDrain::default();
        for i in 0..120 {
            let t = f64::from(i) * 2.0;
            let mut r = DecisionRecord {
                time_s: t,
                ..Default::default()
            };
            let o = &mut r.observations;
            o.insert("armed".into(), 1.0);
            o.insert("altitude_m".into(), 30.0);
            o.insert("groundspeed_mps".into(), f64::from(i % 7));
            // whole percentages, as BATTERY_STATUS gives them
            o.insert("battery_pct".into(), (100.0 - t / 36.0).ceil());
            r.guarantee = Some(GuaranteeRecord {
                pack: Some(PackRecord {
                    capacity_j: 266_400.0,
                    ..Default::default()
                }),
                ..Default::default()
            });
            d.add(&r);
        }
        let w = d.power_w().expect("a drain");
        assert!((w - 74.0).abs() < 74.0 * 0.03, "{w}");
        let mut airborne = 0;
        d.for_each_sample(|s| {
            assert_eq!(s.power_w, w);
            airborne += 1;
        });
        assert_eq!(airborne, 120);
        // Too few records: no drain.
        let short = PercentageDrain {
            capacity_j: Some(1.0),
            ..Default::default()
        };
        assert_eq!(short.power_w(), None);
    }

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
