//! The BFM flight companion.
//!
//! Pure decision core: `evidence` -> `health` -> `decision` -> `arbitration` -> `guarantee`,
//! driven by `sim` (a seeded discrete-step world) or by `link` (MAVLink). Everything
//! mission-specific is loaded from `params/` by `spec` and the stage modules.

pub mod check;
pub mod evidence;
pub mod fmea;
pub mod health;
pub mod observations;
pub mod record;
pub mod spec;
