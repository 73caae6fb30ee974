//! The BFM flight companion.
//!
//! Pure decision core: `evidence` -> `health` -> `decision` -> `arbitration` -> `guarantee`,
//! driven by `sim` (a seeded discrete-step world) or by `link` (MAVLink). Everything
//! mission-specific is loaded from `params/` by `spec` and the stage modules.

pub mod check;
pub mod decision;
pub mod decision_log;
pub mod evidence;
pub mod export;
pub mod fmea;
pub mod fuzzing;
pub mod guarantee;
pub mod health;
pub mod link;
pub mod mission;
pub mod mission_mdp;
pub mod observations;
pub mod params;
pub mod record;
pub mod resources;
pub mod review;
pub mod sim;
pub mod sim_link;
pub mod spec;
pub mod streams;
pub mod tracking;
