//! `companion calibrate RUN... [--out FILE]`: fit the mission's power model, the activities'
//! durations and the health BN rows the logs can teach to flown or simulated runs, and write a
//! params overlay (docs/calibrate.md).
//!
//! - `runs`: run folders found and streamed, a power sample per `fly` record;
//! - `power_fit`: the rotary-wing and base power fit (nalgebra SVD least squares);
//! - `durations`: how long each activity ran;
//! - `cpt`: CPT rows counted with a Dirichlet prior from the shipped rows;
//! - `tlog`: power samples from a run's `flight.tlog`, when it has one;
//! - `shipped`: the shipped numbers the fit starts from;
//! - `write`: the report and the overlay;
//! - `overlay`: reading an overlay back (`--params FILE`).

pub mod cpt;
pub mod durations;
pub mod overlay;
pub mod power_fit;
pub mod runs;
pub mod shipped;
pub mod tlog;
pub mod write;

use anyhow::Context;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct CalibrateArgs {
    /// Run folders (runs/<UTC time>/, as `fly` and `simulate` write them) or folders of run
    /// folders.
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Where to write the params overlay (for `check`, `simulate` and `fly` `--params FILE`).
    /// Without it, only the report is printed.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The params the fit starts from and reports against (default: $COMPANION_PARAMS or the
    /// workspace's params/); a directory or an overlay.
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// Keep `propulsion.induced_velocity_mps` as shipped and fit the rest with it: for a
    /// vehicle whose power does not fall with speed as the induced power does (ArduCopter
    /// SITL's quad), which leaves v0 unidentifiable.
    #[arg(long, conflicts_with = "polynomial")]
    pub keep_induced_velocity: bool,
    /// Fit a polynomial propulsion model (`model = "polynomial"`, `coefficients_w = [c0, 0, c2,
    /// c3]`) in place of the rotary-wing one: for a vehicle whose power the rotary-wing curve
    /// does not describe.
    #[arg(long)]
    pub polynomial: bool,
}

/// Everything learned from the runs.
pub struct Calibration {
    pub runs: Vec<PathBuf>,
    pub records: u64,
    pub power: Result<power_fit::FitResult, power_fit::FitError>,
    pub durations: durations::Durations,
    pub rows: Vec<cpt::LearnedRow>,
}

/// Read every run once, one record at a time, into the fit's statistics.
pub fn calibrate(
    shipped: &shipped::Shipped,
    runs: Vec<PathBuf>,
    keep_v0: bool,
    polynomial: bool,
) -> anyhow::Result<Calibration> {
    let mut fit = if polynomial {
        power_fit::PowerFit::polynomial(shipped.power)
    } else if keep_v0 {
        power_fit::PowerFit::keeping_v0(shipped.power)
    } else {
        power_fit::PowerFit::new(shipped.power)
    };
    let mut durations = durations::Durations::default();
    let mut counts = cpt::CptCounts::default();
    let parents = shipped.rows.parents();
    let mut records = 0;
    for run in &runs {
        durations.start_run();
        counts.start_run();
        // The tlog has the autopilot's telemetry at its own rate; the records, once a cycle.
        let tlog = run.join("flight.tlog");
        let from_tlog = tlog.is_file() && tlog::for_each_sample(&tlog, |s| fit.add(s))? > 0;
        // Without a current anywhere, the power is the drain of the percentage (runs.rs).
        let mut with_current = false;
        let mut drain = runs::PercentageDrain::default();
        records += runs::for_each_record(run, |r| {
            if !from_tlog {
                match runs::sample_of(r) {
                    Some(s) => {
                        fit.add(s);
                        with_current = true;
                    }
                    None => drain.add(r),
                }
            }
            durations.add(r);
            counts.add(r, &shipped.states, &shipped.rows, &parents);
        })?;
        if !from_tlog && !with_current && drain.for_each_sample(|s| fit.add(s)) > 0 {
            tracing::info!(
                "{}: no current reported; power from the percentage's drain, {:.1} W",
                run.display(),
                drain.power_w().unwrap_or(0.0)
            );
        }
    }
    Ok(Calibration {
        runs,
        records,
        power: fit.solve(),
        durations,
        rows: counts.learn(&shipped.rows),
    })
}

/// The subcommand.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let params = args
        .params
        .clone()
        .unwrap_or_else(crate::params::default_params_dir);
    let shipped = shipped::Shipped::load(&params).context("loading params")?;
    let runs = runs::discover(&args.runs)?;
    let cal = calibrate(&shipped, runs, args.keep_induced_velocity, args.polynomial)?;
    print!("{}", write::report(&shipped, &cal));
    if let Some(out) = &args.out {
        let text = write::overlay(&shipped, &cal, out)?;
        std::fs::write(out, text).with_context(|| format!("writing {}", out.display()))?;
        println!("overlay written: {}", out.display());
    }
    Ok(())
}
