//! Write a sample `.tlog` of N frames (the pymavlink read-back test reads it).

use clap::Parser;
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "Write a sample .tlog of N frames")]
struct Args {
    path: PathBuf,
    #[arg(long, default_value_t = 20)]
    frames: u32,
}

fn main() -> anyhow::Result<()> {
    let a = Args::parse();
    Ok(companion_testkit::stress::tlog_sample(&a.path, a.frames)?)
}
