//! The `companion` binary's shells: everything that touches the world around the pure core.
//!
//! The decision core (`companion-core`) and the MAVLink clients (`companion-link`) do no I/O;
//! this crate owns the files, the clock, the sockets and the randomness: it reads `params/`,
//! runs the seeded simulated world, flies a real autopilot, writes and reads decision logs, and
//! renders the reports.
//!
//! # Layout
//! - `params`: reads a params directory into [`companion_core::spec::ParamsFiles`] and loads it
//!   whole (the model, the world, the link files), for `check`, `simulate` and `fly` alike.
//! - `sim`: the seeded discrete-step world and its scenarios (`simulate`).
//! - `world_spec`: the simulated world's params (world.toml, scenarios), loaded with the params.
//! - `fly`: the MAVLink flight shell (`fly`) and its byte transports (serial, UDP, TCP).
//! - `decision_log`: run folders, the decision-log writer and reader, telemetry logs.
//! - `learning_params`: params/learning.toml, the bound of in-flight CPT learning.
//! - `params_overlay`: the params overlay `calibrate` writes and `--params FILE` reads.
//! - `vocabulary`: the observation and action vocabularies across the params and both shells
//!   (producers, consumers), checked at load and listed by `check`.
//! - `calibrate`: `companion calibrate` (power model, durations and BN rows fitted to runs; the
//!   params overlay `--params FILE` reads).
//! - `check`: `companion check` (params validation and the compiled models, text or JSON).
//! - `review`: `companion review` (HTML report, summary, why of a cycle).
//! - `export`: `companion export` (MCAP or CSV); `decision_channels`: the MCAP channels, shared
//!   with `live`: the Foxglove WebSocket server of `fly --live` / `simulate --live`.
//! - `replay`: `companion replay` (a run's log fed back through a fresh core).
//! - `text`: text leaving the process: HTML-escaped, or cleaned or escaped for a terminal.
//! - `signing_setup`: `companion signing-setup` (a MAVLink 2 signing key made, provisioned, proven).

#![allow(missing_docs)] // the shells are documented per module; their items are not an API

pub mod autopilot_mission;
pub mod calibrate;
pub mod check;
pub mod decider;
pub mod decision_channels;
pub mod decision_log;
pub mod export;
pub mod fly;
pub mod learn_cpt;
pub mod learning_params;
pub mod live;
pub mod operator_mission;
pub mod output_file;
pub mod params;
pub mod params_files;
pub mod params_overlay;
pub mod replay;
pub mod review;
pub mod route_input;
pub mod signing_setup;
pub mod sim;
pub mod sim_plan;
pub mod text;
pub mod vocabulary;
pub mod world_spec;
