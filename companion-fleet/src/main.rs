//! `companion-fleet`: the ground side's view of a fleet's flights (docs/fleet.md). Run folders
//! become a Hive-partitioned Parquet dataset; reports, SQL and calibration run on an embedded
//! DataFusion. The onboard `companion` links none of this.

// A binary: `pub` marks what a module offers the others.
#![allow(unreachable_pub)]

mod batch;
mod bn_rows;
mod calibrate;
mod dataset;
mod durations;
mod export;
mod legs;
mod overlay;
mod query;
mod report;
mod samples;
mod table;
mod telemetry;

use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(name = "companion-fleet", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Write one run folder's tables (runs, records, proposals, events, commands, telemetry,
    /// samples, legs, bn_trials, stretches) as Parquet files into DIR.
    Export {
        /// A run folder (decisions.jsonl, flight.tlog).
        run: PathBuf,
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// The vehicle's id (default: sysid<N> of the autopilot fly was pinned to, `sim` for a
        /// simulated run, else `unknown`).
        #[arg(long)]
        vehicle: Option<String>,
    },
    /// Add runs to the dataset DIR (vehicle=.../date=.../batch=.../): once each by content,
    /// atomically.
    Ingest {
        /// Run folders, or folders of run folders.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        #[arg(long, value_name = "DIR")]
        into: PathBuf,
        /// The vehicle's id for every run given (default as for export).
        #[arg(long)]
        vehicle: Option<String>,
    },
    /// Per vehicle and route: flights, hours, refused starts, planned vs flown energy and
    /// duration, drift events, command failures, versions, link losses.
    Report {
        dir: PathBuf,
        /// Also write the report as an HTML page to FILE.
        #[arg(long, value_name = "FILE")]
        html: Option<PathBuf>,
        /// One JSON object: section name -> array of row objects.
        #[arg(long)]
        json: bool,
    },
    /// Run a SQL query over the tables records, proposals, events, commands, telemetry, runs,
    /// samples, legs, bn_trials, stretches.
    Sql {
        dir: PathBuf,
        query: String,
        /// Print an array of row objects.
        #[arg(long)]
        json: bool,
    },
    /// Fit the power model from the dataset's sufficient statistics (SQL aggregates), as
    /// `companion calibrate RUN...` fits it from the same runs.
    Calibrate {
        dir: PathBuf,
        /// Only this vehicle's runs.
        #[arg(long)]
        vehicle: Option<String>,
        /// Write the fits (power, legs, BN rows) as a params overlay to FILE, as `companion
        /// calibrate --out` writes it (read by --params FILE).
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
        /// The params the fit starts from (default: $COMPANION_PARAMS or the workspace's params/).
        #[arg(long)]
        params: Option<PathBuf>,
        /// The commanded speed of legs whose run says none (m/s), as `companion calibrate
        /// --cruise-speed-mps`; default: the params' `[derive].cruise_speed_mps`.
        #[arg(long, value_name = "MPS")]
        cruise_speed_mps: Option<f64>,
        /// Print the fitted model as one JSON object (full precision).
        #[arg(long)]
        json: bool,
        /// Print only the SQL queries and the sufficient statistics they gave (JSON), for
        /// another engine to compare (scripts/fleet_spark.sh).
        #[arg(long)]
        statistics: bool,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("companion-fleet: cannot start the runtime: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    let result = rt.block_on(async {
        match cli.command {
            Command::Export { run, out, vehicle } => {
                dataset::export(&run, &out, vehicle.as_deref())
            }
            Command::Ingest {
                runs,
                into,
                vehicle,
            } => dataset::ingest(&runs, &into, vehicle.as_deref()),
            Command::Report { dir, html, json } => {
                report::report_cli(&dir, html.as_deref(), json).await
            }
            Command::Sql { dir, query, json } => query::sql_cli(&dir, &query, json).await,
            Command::Calibrate {
                dir,
                vehicle,
                out,
                params,
                cruise_speed_mps,
                json,
                statistics,
            } => {
                calibrate::calibrate_cli(
                    &dir,
                    vehicle.as_deref(),
                    out.as_deref(),
                    params.as_deref(),
                    cruise_speed_mps,
                    (json, statistics),
                )
                .await
            }
        }
    });
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("companion-fleet: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
