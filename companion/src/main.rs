//! `companion`: the command-line edge. Parses arguments, owns I/O and time, calls the pure core.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "companion", version, about = "BFM flight companion: health BNs, concurrent MDPs, just-enough variants, MAVLink")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fly the paper's tracking mission in a seeded discrete-step world (no autopilot needed).
    Simulate,
    /// Validate params/ and print the health managers, platform and pre-flight allocation.
    Check(companion::check::CheckArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Check(args) => companion::check::run(&args),
        Command::Simulate => {
            anyhow::bail!("not yet implemented")
        }
    }
}
