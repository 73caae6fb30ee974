//! Model of the BFM paper's mission board (TeraSIC SoCKit, Cyclone V SoC): four dynamically
//! reconfigurable FPGA tiles, a dual Cortex-A9 at 925 MHz with a load budget, the Table 2 variant
//! catalogue, and the "just enough" scheduler that places requested application variants and
//! resolves resource conflicts by a policy given as data (section 6.3, Tables 4-7).
//!
//! Pure: no I/O, no clock, no randomness. Every type is serde so `companion` loads it from
//! `params/` (`platform.toml`, `variants.toml`, `resource_policies.toml`) and validates it here.
//!
//! # Layout
//!
//! * `lib.rs`: [`ModelError`] and the millisecond formatting shared by the reports ([`fmt_ms`]).
//! * `platform`: the board ([`Platform`]): tiles, CPU budget, reconfiguration time, power and
//!   performance needs.
//! * `catalogue`: the Table 2 variant catalogue ([`Catalogue`], [`Variant`], [`Implementation`]).
//! * `policy`: resource policies as data ([`ResourcePolicy`]): priorities and degradation paths.
//! * `schedule`: the "just enough" scheduler ([`schedule`], [`schedule_into`],
//!   [`ScheduleWorkspace`]) and its result ([`Schedule`], [`Placement`], [`Degradation`]).

mod catalogue;
mod platform;
mod policy;
mod schedule;

pub use catalogue::{Catalogue, Implementation, Support, Variant, VariantsFile};
pub use platform::{Performance, Platform, PowerModel};
pub use policy::{PoliciesFile, ResourcePolicy};
pub use schedule::{
    Degradation, Dropped, Placement, PlatformState, Request, Room, Schedule, ScheduleWorkspace,
    Tile, schedule, schedule_into,
};

/// A model input that is inconsistent. `entry` is a dotted path inside the params file it came
/// from (`variant[3].tiles`), so the loader can name file, entry and reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{entry}: {reason}")]
pub struct ModelError {
    /// Dotted path of the offending entry inside its params file.
    pub entry: String,
    /// What is wrong with it.
    pub reason: String,
}

impl ModelError {
    /// An error at `entry` for `reason`.
    pub fn new(entry: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            entry: entry.into(),
            reason: reason.into(),
        }
    }
}

/// Milliseconds as the paper writes them: `10`, `0.5`, `1000`.
pub fn fmt_ms(ms: f64) -> String {
    FmtMs(ms).to_string()
}

/// [`fmt_ms`] as a `Display`, for writing into a reused string without allocating.
#[derive(Debug, Clone, Copy)]
pub struct FmtMs(pub f64);

impl std::fmt::Display for FmtMs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ms = self.0;
        if ms.fract() == 0.0 && ms.abs() < 1e15 {
            write!(f, "{ms:.0}")
        } else {
            write!(f, "{ms}")
        }
    }
}

/// Relative tolerance for rate and budget comparisons (floating sums of table values).
pub(crate) const EPS: f64 = 1e-9;
