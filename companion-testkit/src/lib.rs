//! Support for the companion's tests, fuzz targets, benchmarks, soak and stress runs. Never
//! shipped: the release `companion` binary does not link this crate.
//!
//! # Layout
//! - `fuzzing`: the fuzz targets' bodies (MAVLink ingest, params loading), shared with the
//!   corpus replay test.
//! - `leg_tlog`: a generated flight.tlog of a vehicle of known legs, climb and descent (the
//!   calibrate leg tests, the fleet's).
//! - `scripted`: a rule-based decider for the fly loop's link tests.
//! - `sim_link`: a simulated autopilot's byte stream and a minimal responder (ingest bench, soak).
//! - `streams`: observation streams for measuring the decision cycle.
//! - `synthetic`: a synthetic 100-cycle mission's decision records (review and export tests).
//! - `stress`: decision-log and telemetry-log writers for the log-loss tests
//!   (binaries `companion-log-stress`, `companion-tlog-sample`).

#![allow(missing_docs)] // test support, never published

pub mod fuzzing;
pub mod leg_tlog;
pub mod route_gen;
pub mod run_log;
pub mod scripted;
pub mod sim_link;
pub mod streams;
pub mod stress;
pub mod synthetic;
