//! Write synthetic decision records into DIR until killed (the crash-safety test kills it with
//! SIGKILL mid-write and checks that every line left is whole).

use clap::Parser;
use std::path::PathBuf;

#[derive(Parser)]
#[command(about = "Write decision records into DIR until killed")]
struct Args {
    dir: PathBuf,
    #[arg(long, default_value_t = 64 * 1024 * 1024)]
    rotate_bytes: u64,
}

fn main() -> anyhow::Result<()> {
    let a = Args::parse();
    Ok(companion_testkit::stress::log_stress(
        &a.dir,
        a.rotate_bytes,
    )?)
}
