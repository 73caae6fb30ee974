//! The BFM companion's decision core: pure, per cycle, and handed everything it knows.
//!
//! It compiles the mission's params (given as text, never read from disk here) into one
//! [`decision::Model`], and each [`decision::Core::step`] turns one observation snapshot into a
//! decision record: `evidence` -> `health` (BNs from FMEA tables) -> the concurrent MDPs
//! (`mission_mdp`) -> behaviour and resource arbitration -> the PANORAMA `guarantee`. No clock,
//! no file, no socket, no randomness: the shells (the `companion` binary's simulated world and
//! MAVLink flight) own those, so the same observations always give the same record.
//!
//! # Layout
//! - `spec`: the params as data ([`spec::ParamsFiles`]), TOML parsing, the one error type naming
//!   file, entry and reason.
//! - `observations`: one snapshot of what the shell observed.
//! - `evidence`: observations to BN evidence states (thresholds from `observations.toml`).
//! - `fmea`: FMEA tables (`params/health/*.toml`) compiled into Bayesian networks.
//! - `health`: the health managers, evaluated per cycle; the battery as a two-slice DBN.
//! - `mission`: the mission's states, phases and action catalogue (`mission.toml`, `actions.toml`).
//! - `mission_mdp`: the concurrent MDPs built from `params/mdp/`, solved at the projected state.
//! - `resources`: Table 2 (variants), the platform, and resource arbitration onto FPGA tiles and CPU.
//! - `guarantee`: PANORAMA's activities, IAs, pre-flight allocation, margins and re-allocation.
//! - `decision`: the [`decision::Model`] and the per-cycle [`decision::Core`].
//! - `record`: the decision record written for every cycle.
//! - `tracking`: tracking time, shared by the world, the review and the tables.

pub mod decision;
pub mod evidence;
pub mod fmea;
pub mod guarantee;
pub mod health;
pub mod mission;
pub mod mission_mdp;
pub mod observations;
pub mod record;
pub mod resources;
pub mod spec;
pub mod tracking;
