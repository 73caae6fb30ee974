//! `companion`: the command-line edge. Parses arguments, owns I/O and time, calls the pure core.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "companion",
    version,
    about = "BFM flight companion: health BNs, concurrent MDPs, just-enough variants, MAVLink"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fly the paper's tracking mission in a seeded discrete-step world (no autopilot needed).
    Simulate,
    /// Validate params/ and print the health managers, platform and pre-flight allocation.
    Check,
    /// Post-flight review of a run folder or decision log: an HTML report (or --summary).
    Review {
        /// Run folder (runs/<UTC time>/) or a decisions*.jsonl file.
        run_or_log: std::path::PathBuf,
        /// Where to write the HTML report (default: report.html in the run folder).
        #[arg(long)]
        out: Option<std::path::PathBuf>,
        /// Print the summary and timeline in the terminal (no HTML unless --out is given).
        #[arg(long)]
        summary: bool,
    },
    /// Test helper: write decision records into DIR until killed.
    #[command(name = "__log-stress", hide = true)]
    LogStress {
        dir: std::path::PathBuf,
        #[arg(long, default_value_t = 64 * 1024 * 1024)]
        rotate_bytes: u64,
    },
    /// Test helper: write a sample .tlog of N frames.
    #[command(name = "__tlog-sample", hide = true)]
    TlogSample {
        path: std::path::PathBuf,
        #[arg(long, default_value_t = 20)]
        frames: u32,
    },
    /// Fly a real autopilot over MAVLink (ArduPilot or PX4; SITL or hardware).
    Fly(companion::link::fly::FlyArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        // TODO(lead): replace the scripted stand-in with the decision core's `Decider`.
        Command::Fly(args) => {
            let decider = companion::link::fly::ScriptedDecider::from_args(&args)?;
            companion::link::fly::run(args, decider)
        }
        Command::Simulate | Command::Check => {
            anyhow::bail!("not yet implemented")
        }
        Command::Review {
            run_or_log,
            out,
            summary,
        } => {
            companion::review::run(&run_or_log, out.as_deref(), summary)?;
            Ok(())
        }
        Command::LogStress { dir, rotate_bytes } => Ok(
            companion::decision_log::stress::log_stress(&dir, rotate_bytes)?,
        ),
        Command::TlogSample { path, frames } => {
            Ok(companion::decision_log::stress::tlog_sample(&path, frames)?)
        }
    }
}
