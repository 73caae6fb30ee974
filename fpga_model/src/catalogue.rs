//! The variant catalogue: the BFM paper's Table 2, one row per (application, version, implementation).

use crate::{EPS, ModelError, Platform, fmt_ms};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::fmt;

/// Implementation speed class of Table 2: slow, medium, fast.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Implementation {
    /// Slow.
    S,
    /// Medium.
    M,
    /// Fast.
    F,
}

/// Execution support: CPU only, FPGA only, or CPU with an FPGA coprocessor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Support {
    /// Software on the CPU.
    SW,
    /// Hardware on FPGA tiles.
    HW,
    /// A software part on the CPU with a hardware coprocessor part on FPGA tiles.
    #[serde(rename = "SW-HW")]
    SwHw,
}

impl fmt::Display for Implementation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::S => "S",
            Self::M => "M",
            Self::F => "F",
        })
    }
}

impl std::str::FromStr for Implementation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "S" => Ok(Self::S),
            "M" => Ok(Self::M),
            "F" => Ok(Self::F),
            _ => Err(format!("`{s}` is not an implementation (S, M or F)")),
        }
    }
}

impl fmt::Display for Support {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::SW => "SW",
            Self::HW => "HW",
            Self::SwHw => "SW-HW",
        })
    }
}

/// One Table 2 entry. `ms` lists the per-frame times in the order the paper writes them
/// (`10 + 1`), `parts` says which of them runs in SW and which in HW (only needed for SW-HW;
/// defaults to `[SW, HW]`). The parts run one after the other, so a frame takes their sum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    /// Application name (`tracking`, `obstacle_detection`, ...).
    pub app: String,
    /// Application version (`V0`, `V1`, ...).
    pub version: String,
    /// What this version does, as the paper describes it.
    #[serde(default)]
    pub description: String,
    /// Speed class.
    pub implementation: Implementation,
    /// Where it runs.
    pub support: Support,
    /// Per-part frame times in ms, in the paper's order.
    pub ms: Vec<f64>,
    /// Support of each `ms` entry (only needed for SW-HW).
    #[serde(default)]
    pub parts: Vec<Support>,
    /// FPGA tiles the HW part occupies (rule stated in params/variants.toml).
    pub tiles: u8,
    /// Where the row comes from (the Table 2 cell it encodes).
    #[serde(default)]
    pub source: String,
    /// How the row was read where the paper is ambiguous.
    #[serde(default)]
    pub note: String,
}

impl Variant {
    /// Support of the i-th `ms` entry.
    pub fn part(&self, i: usize) -> Support {
        match (self.parts.get(i), self.support) {
            (Some(&p), _) => p,
            (None, Support::SwHw) => {
                if i == 0 {
                    Support::SW
                } else {
                    Support::HW
                }
            }
            (None, s) => s,
        }
    }

    /// Per-frame time of the software parts, ms.
    pub fn sw_ms(&self) -> f64 {
        self.ms
            .iter()
            .enumerate()
            .filter(|(i, _)| self.part(*i) == Support::SW)
            .map(|(_, m)| m)
            .sum()
    }

    /// Per-frame time of the hardware parts, ms.
    pub fn hw_ms(&self) -> f64 {
        self.ms
            .iter()
            .enumerate()
            .filter(|(i, _)| self.part(*i) == Support::HW)
            .map(|(_, m)| m)
            .sum()
    }

    /// Time to process one frame (SW and HW parts in sequence).
    pub fn ms_per_frame(&self) -> f64 {
        self.ms.iter().sum()
    }

    /// Highest frame rate this implementation reaches.
    pub fn max_fps(&self) -> f64 {
        1000.0 / self.ms_per_frame()
    }

    /// True when it processes `fps` frames per second (frame time within the frame period).
    pub fn meets(&self, fps: f64) -> bool {
        fps * self.ms_per_frame() <= 1000.0 * (1.0 + EPS)
    }

    /// Share of the nominal CPU (all `cores`) used when run at `fps`: the SW part's busy time
    /// per second on one core, over the number of cores.
    pub fn cpu_share_at(&self, fps: f64, cores: u8) -> f64 {
        self.sw_ms() * fps / 1000.0 / f64::from(cores)
    }

    /// Share of the nominal CPU when run back to back (at `max_fps`): the catalogue's CPU share,
    /// an upper bound of `cpu_share_at` for any rate the variant meets.
    pub fn full_duty_cpu_share(&self, cores: u8) -> f64 {
        self.sw_ms() / self.ms_per_frame() / f64::from(cores)
    }

    /// Section 4.3.1 occupancy: whole part = tiles, fractional part = CPU load (full duty).
    pub fn u_app(&self, cores: u8) -> f64 {
        f64::from(self.tiles) + self.full_duty_cpu_share(cores)
    }

    /// Bitstream identity of this variant's HW (one per tile part: `key#k`).
    pub fn key(&self) -> String {
        format!("{}/{}/{}", self.app, self.version, self.implementation)
    }

    /// The paper's notation of its time: `285`, `10 + 1`.
    pub fn ms_label(&self) -> String {
        self.ms
            .iter()
            .map(|&m| fmt_ms(m))
            .collect::<Vec<_>>()
            .join(" + ")
    }
}

/// The file layout of `params/variants.toml`: `[[variant]]` tables.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VariantsFile {
    /// The rows, one `[[variant]]` table each.
    pub variant: Vec<Variant>,
}

/// A validated catalogue.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Catalogue {
    variants: Vec<Variant>,
}

impl Catalogue {
    /// Validate rows against the platform: names present, times positive, parts consistent with
    /// the support, tiles 0 for SW and 1..=platform tiles otherwise, no duplicate implementation.
    pub fn new(variants: Vec<Variant>, platform: &Platform) -> Result<Self, ModelError> {
        if variants.is_empty() {
            return Err(ModelError::new("variant", "the catalogue has no variant"));
        }
        let mut seen = BTreeSet::new();
        for (i, v) in variants.iter().enumerate() {
            let at = |field: &str| format!("variant[{i}].{field}");
            if v.app.trim().is_empty() {
                return Err(ModelError::new(at("app"), "empty application name"));
            }
            if v.version.trim().is_empty() {
                return Err(ModelError::new(at("version"), "empty version name"));
            }
            if v.ms.is_empty() {
                return Err(ModelError::new(at("ms"), "no time per frame given"));
            }
            for (k, &m) in v.ms.iter().enumerate() {
                if !(m.is_finite() && m > 0.0) {
                    return Err(ModelError::new(
                        format!("variant[{i}].ms[{k}]"),
                        format!("time per frame must be a positive finite number of ms, got {m}"),
                    ));
                }
            }
            if !v.parts.is_empty() && v.parts.len() != v.ms.len() {
                return Err(ModelError::new(
                    at("parts"),
                    format!("{} parts for {} times in ms", v.parts.len(), v.ms.len()),
                ));
            }
            if v.parts.contains(&Support::SwHw) {
                return Err(ModelError::new(
                    at("parts"),
                    "each part is SW or HW, not SW-HW",
                ));
            }
            let has_sw = (0..v.ms.len()).any(|k| v.part(k) == Support::SW);
            let has_hw = (0..v.ms.len()).any(|k| v.part(k) == Support::HW);
            let consistent = match v.support {
                Support::SW => !has_hw,
                Support::HW => !has_sw,
                Support::SwHw => has_sw && has_hw,
            };
            if !consistent {
                return Err(ModelError::new(
                    at("parts"),
                    format!(
                        "parts do not match support {} (a SW-HW variant needs one SW and one HW part)",
                        v.support
                    ),
                ));
            }
            match v.support {
                Support::SW if v.tiles != 0 => {
                    return Err(ModelError::new(
                        at("tiles"),
                        format!("a SW variant uses no tile, got {}", v.tiles),
                    ));
                }
                Support::HW | Support::SwHw if v.tiles == 0 => {
                    return Err(ModelError::new(
                        at("tiles"),
                        format!("a {} variant needs at least one tile", v.support),
                    ));
                }
                _ => {}
            }
            if v.tiles > platform.tiles {
                return Err(ModelError::new(
                    at("tiles"),
                    format!("{} tiles but the platform has {}", v.tiles, platform.tiles),
                ));
            }
            if !seen.insert((v.app.clone(), v.version.clone(), v.implementation)) {
                return Err(ModelError::new(
                    at("implementation"),
                    format!(
                        "duplicate {} {} implementation {}",
                        v.app, v.version, v.implementation
                    ),
                ));
            }
        }
        Ok(Self { variants })
    }

    /// Every row, in file order.
    pub fn variants(&self) -> &[Variant] {
        &self.variants
    }

    /// The application names, sorted.
    pub fn apps(&self) -> BTreeSet<&str> {
        self.variants.iter().map(|v| v.app.as_str()).collect()
    }

    /// True when some row is for `app`.
    pub fn has_app(&self, app: &str) -> bool {
        self.variants.iter().any(|v| v.app == app)
    }

    /// True when some row is for version `version` of `app`.
    pub fn has_version(&self, app: &str, version: &str) -> bool {
        self.variants
            .iter()
            .any(|v| v.app == app && v.version == version)
    }

    /// Versions of `app`, in catalogue order.
    pub fn versions(&self, app: &str) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for v in self.variants.iter().filter(|v| v.app == app) {
            if !out.contains(&v.version.as_str()) {
                out.push(&v.version);
            }
        }
        out
    }

    /// Implementations of one version, slowest first (largest time per frame; ties S before F).
    pub fn implementations(&self, app: &str, version: &str) -> Vec<&Variant> {
        let mut out: Vec<&Variant> = self
            .variants
            .iter()
            .filter(|v| v.app == app && v.version == version)
            .collect();
        out.sort_by(|a, b| {
            b.ms_per_frame()
                .total_cmp(&a.ms_per_frame())
                .then(a.implementation.cmp(&b.implementation))
        });
        out
    }
}
