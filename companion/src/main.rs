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
    Check,
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
    }
}
