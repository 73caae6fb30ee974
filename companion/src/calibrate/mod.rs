//! `companion calibrate RUN... [--out FILE]`: fit the vehicle to flown or simulated runs (its
//! power model, how it flies a leg, climbs and descends) and the health BN rows the logs can
//! teach, and write a params overlay (docs/calibrate.md). Never a route's length or an activity's
//! hold: those are the route's, derived from it (`companion_core::route_plan`).
//!
//! - `runs`: run folders found and streamed, a power sample per `fly` record;
//! - `power_fit`: the rotary-wing and base power fit (nalgebra SVD least squares);
//! - `legs`: legs, climbs and descents from the tlog, and the leg model;
//! - `durations`: how long each activity ran (reported, not written);
//! - `cpt`: CPT rows counted with a Dirichlet prior from the shipped rows;
//! - `tlog`: power samples from a run's `flight.tlog`, when it has one;
//! - `shipped`: the shipped numbers the fit starts from;
//! - `write`: the report and the overlay;
//! - `overlay`: reading an overlay back (`--params FILE`).

pub mod cpt;
pub mod durations;
pub mod legs;
// The overlay is read with the params (`crate::params_overlay`, floor 1); kept here by its old path.
pub use crate::params_overlay as overlay;
pub mod power_fit;
pub mod runs;
pub mod shipped;
pub mod tlog;
mod toml_table;
pub mod write;
mod write_legs;

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
    /// Count the tlog's frames of this autopilot system only (as `fly --autopilot-sysid`);
    /// default: the pin the run's `fly` was given (its log header's command line), else the
    /// autopilot `fly` would choose (component 1 first).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_sysid: Option<u8>,
    /// With --autopilot-sysid: the autopilot's component id.
    #[arg(long, default_value_t = 1, requires = "autopilot_sysid", value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_compid: u8,
    /// The autopilot's cruise speed (m/s) in runs whose tlog does not say it (no WPNAV_SPEED /
    /// MPC_XY_CRUISE PARAM_VALUE, no DO_CHANGE_SPEED item): the commanded speed legs are fitted
    /// against. Default: the mission's `[derive] cruise_speed_mps`.
    #[arg(long, value_parser = positive_speed)]
    pub cruise_speed_mps: Option<f64>,
}

fn positive_speed(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 && v <= 100.0 => Ok(v),
        _ => Err(format!("{s:?}: a speed above 0 and at most 100 m/s")),
    }
}

/// Everything learned from the runs.
pub struct Calibration {
    pub runs: Vec<PathBuf>,
    /// Run names left out as repeats of a run already counted (same content), with that run.
    pub repeats: Vec<(PathBuf, PathBuf)>,
    /// Per run with a tlog: the autopilot its samples are from and the impostors left out.
    pub tlogs: Vec<(PathBuf, tlog::TlogRead)>,
    pub records: u64,
    pub power: Result<power_fit::FitResult, power_fit::FitError>,
    pub durations: durations::Durations,
    pub legs: legs::LegFlights,
    pub rows: Vec<cpt::LearnedRow>,
}

/// Read every run once, one record at a time, into the fit's statistics.
pub fn calibrate(
    shipped: &shipped::Shipped,
    runs: Vec<PathBuf>,
    pin: tlog::Pin,
    keep_v0: bool,
    polynomial: bool,
    cruise: Option<(f64, String)>,
) -> anyhow::Result<Calibration> {
    // Each run once, by content: names, symlinks or copies of one run are one run.
    let (runs, repeats) = runs::once_each(runs)?;
    let mut tlogs = Vec::new();
    let mut fit = if polynomial {
        power_fit::PowerFit::polynomial(shipped.power)
    } else if keep_v0 {
        power_fit::PowerFit::keeping_v0(shipped.power)
    } else {
        power_fit::PowerFit::new(shipped.power)
    };
    let mut durations = durations::Durations::default();
    let mut leg_flights = legs::LegFlights::new(cruise);
    let mut counts = cpt::CptCounts::default();
    let parents = shipped.rows.parents();
    let mut records = 0;
    for run in &runs {
        durations.start_run();
        leg_flights.start_run();
        counts.start_run();
        // The tlog has the autopilot's telemetry at its own rate; the records, once a cycle.
        let tlog = run.join("flight.tlog");
        let mut from_tlog = false;
        if tlog.is_file() {
            // calibrate's own pin, else the one fly flew this run with, else fly's rule.
            let pin = pin.or_else(|| runs::fly_pin(run));
            let read =
                tlog::for_each_sample(&tlog, pin, |s| fit.add(s), |m| leg_flights.on_message(m))?;
            from_tlog = read.samples > 0;
            tlogs.push((run.clone(), read));
        }
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
                crate::output_file::shown(run),
                drain.power_w().unwrap_or(0.0)
            );
        }
    }
    Ok(Calibration {
        runs,
        repeats,
        tlogs,
        records,
        power: fit.solve(),
        durations,
        legs: leg_flights,
        rows: counts.learn(&shipped.rows),
    })
}

/// The subcommand. Its error is one line of text with every control character escaped: it
/// names run folders and files, which are data (a folder named with an escape sequence is shown,
/// not obeyed).
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    calibrate_and_write(args).map_err(|e| {
        anyhow::anyhow!(crate::review::text::escape_controls(
            &format!("{e:#}"),
            false
        ))
    })
}

fn calibrate_and_write(args: &CalibrateArgs) -> anyhow::Result<()> {
    let params = args
        .params
        .clone()
        .unwrap_or_else(crate::params::default_params_dir);
    let shipped = shipped::Shipped::load(&params).context("loading params")?;
    let runs = runs::discover(&args.runs)?;
    // Everything read is an input the overlay may not replace: the runs' logs and tlogs (every
    // name given, repeats included) and the params (an overlay given with --params, the files
    // of its base).
    let mut inputs = shipped.inputs.clone();
    if overlay::is_overlay(&params) {
        inputs.push(params.clone());
    }
    for r in &runs {
        inputs.extend(crate::decision_log::log_files(r).unwrap_or_default());
        inputs.push(r.join("flight.tlog"));
    }
    // Refused before the runs are read: a FIFO as --out never blocks, an input is never
    // touched.
    if let Some(out) = &args.out {
        crate::output_file::check(out, &inputs, "calibration")
            .map_err(|e| anyhow::anyhow!("--out {e}"))?;
    }
    let pin = args.autopilot_sysid.map(|s| (s, args.autopilot_compid));
    let cruise = match args.cruise_speed_mps {
        Some(v) => Some((v, "--cruise-speed-mps".to_string())),
        None => shipped.cruise_mps.map(|v| {
            (
                v,
                format!("{} [derive].cruise_speed_mps", shipped.mission_file),
            )
        }),
    };
    let cal = calibrate(
        &shipped,
        runs,
        pin,
        args.keep_induced_velocity,
        args.polynomial,
        cruise,
    )?;
    print!("{}", write::report(&shipped, &cal));
    let refused = write::refusals(&shipped, &cal);
    if !refused.is_empty() {
        for r in &refused {
            println!("refused: {r}");
        }
        anyhow::bail!(
            "calibrate: refused for the {} reason(s) above; nothing written",
            refused.len()
        );
    }
    if let Some(out) = &args.out {
        let text = write::overlay(&shipped, &cal, out)?;
        crate::output_file::write(out, &inputs, "calibration", text.as_bytes(), 0o644)
            .map_err(|e| anyhow::anyhow!("--out {e}"))?;
        println!("overlay written: {}", crate::output_file::shown(out));
    }
    Ok(())
}
