//! `companion`: the command-line edge. Parses arguments, owns I/O and time, calls the pure core.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use companion::decider::CoreDecider;
use companion::fly::FlyArgs;
use companion::params::default_params_dir;
use companion::sim::{self, Scenario};
use companion_core::decision::{ModelKind, Policy};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;

#[derive(Parser)]
#[command(
    name = "companion",
    version,
    about = "BFM flight companion: health BNs from FMEA tables, concurrent MDPs, just-enough variants, PANORAMA margins, MAVLink"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Log level on stderr: error, warn, info, debug, trace, or a filter like
    /// `companion=debug` (default: $RUST_LOG, else info). Colour on a terminal, plain lines
    /// otherwise (systemd's journal).
    #[arg(long, global = true)]
    log_level: Option<String>,
}

/// The `tracing` subscriber for every subcommand: `--log-level`, else `RUST_LOG`, else info;
/// to stderr, with colour only when stderr is a terminal.
fn init_logging(level: Option<&str>) -> Result<()> {
    use tracing_subscriber::EnvFilter;
    let filter = match level {
        Some(l) => EnvFilter::try_new(l).with_context(|| format!("--log-level {l:?}"))?,
        None => EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
    };
    let terminal = std::io::stderr().is_terminal();
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(terminal)
        .with_target(false);
    // The journal stamps each line itself: no second timestamp there.
    if terminal {
        builder.init();
    } else {
        builder.without_time().init();
    }
    Ok(())
}

/// Most `simulate --runs` (each run is a full simulation; the per-run results are kept).
const MAX_RUNS: i64 = 10_000;
/// Most `simulate --steps` (the first run's records are all held and logged).
const MAX_STEPS: i64 = 10_000;

#[derive(clap::Args)]
struct SimulateArgs {
    /// Scenario name in params/scenarios/ or a path to a scenario file.
    #[arg(long, default_value = "complete-1")]
    scenario: String,
    /// Decision policy: a policy of params/policies.toml (safety, mission), checked when the
    /// params load.
    #[arg(long, default_value = "safety")]
    policy: String,
    /// bfm (the three concurrent MDPs), reference (Figure 1), monolithic (section 5), or a
    /// comma-separated list run side by side on the same seeds.
    #[arg(long, default_value = "bfm")]
    model: String,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Runs on seeds seed, seed+1, ...: tracking time reported as mean and 95% CI.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=MAX_RUNS))]
    runs: u32,
    /// Steps per run (the paper's 100; at most 10000).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=MAX_STEPS))]
    steps: Option<u32>,
    /// One JSON object on stdout (schema in docs/simulation.md).
    #[arg(long)]
    json: bool,
    /// Where run folders go (a new `<UTC time>/` inside, printed at the start).
    #[arg(long, default_value = companion::decision_log::DEFAULT_RUNS_DIR)]
    runs_dir: PathBuf,
    /// Do not write a run folder.
    #[arg(long)]
    no_log: bool,
    /// The params directory (default: $COMPANION_PARAMS, else the repository's params/) or a params overlay file
    /// (`companion calibrate --out`, docs/calibrate.md).
    #[arg(long)]
    params: Option<PathBuf>,
    /// A vehicle profile: params/vehicles/NAME.toml, a params overlay made by `companion
    /// calibrate` from that vehicle's flights (docs/calibrate.md); the default is the paper's
    /// mission with its stated assumptions.
    #[arg(long, value_name = "NAME")]
    vehicle: Option<String>,
    /// Learn the health BN's countable CPT rows from each cycle's outcome as the run goes
    /// (bounded by params/learning.toml, logged in `cpt_learned`; docs/calibrate.md).
    #[arg(long)]
    learn_cpt: bool,
    /// The plan the guarantee judges (docs/guarantee.md): a route told by content (a
    /// QGroundControl `.plan`, a WPL 110 file or a route TOML) to derive the activities from, or
    /// a PANORAMA mission (`tracking`: its typed activities, the legacy plan). Default: the
    /// activities derived from params/missions/tracking_route.toml and tracking_zones.geojson.
    #[arg(long)]
    mission: Option<String>,
    /// Zones: a GeoJSON FeatureCollection whose features' `properties.constraints` name
    /// constraint classes; the route's legs are split where they enter or leave one.
    #[arg(long, value_name = "FILE.geojson")]
    zones: Option<PathBuf>,
    /// Home as LAT,LON (degrees), to place a route or zones given relative to home among
    /// absolute ones.
    #[arg(long, value_name = "LAT,LON")]
    home: Option<String>,
    #[command(flatten)]
    live: companion::live::LiveArgs,
    /// With --live: wait at most this long (seconds) for a viewer to subscribe before the first
    /// step, so it sees the whole run (then the run goes on without one).
    #[arg(long, default_value_t = 30.0, requires = "live", value_parser = live_wait_s)]
    live_wait: f64,
}

fn live_wait_s(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(x) if (0.0..=3600.0).contains(&x) => Ok(x),
        _ => Err(format!("`{s}`: seconds from 0 to 3600")),
    }
}

#[derive(Subcommand)]
enum Command {
    /// Fly the paper's tracking mission in a seeded discrete-step world (no autopilot needed).
    Simulate(SimulateArgs),
    /// Validate params/ and print the health managers, MDPs, platform and pre-flight allocation.
    Check(companion::check::CheckArgs),
    /// Fly a real autopilot over MAVLink (ArduPilot or PX4; SITL or hardware).
    Fly(FlyArgs),
    /// Make a MAVLink 2 signing key (mode 0600), provision it on the autopilot with
    /// SETUP_SIGNING, and prove it by a signed exchange; exit 0 only when proven.
    SigningSetup(companion::signing_setup::SigningSetupArgs),
    /// Post-flight review of a run folder or decision log: an HTML report (or --summary).
    Review {
        /// Run folder (runs/<UTC time>/) or a decisions*.jsonl file.
        run_or_log: PathBuf,
        /// Where to write the HTML report (default: report.html in the run folder).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print the summary and timeline in the terminal (no HTML unless --out is given).
        #[arg(long)]
        summary: bool,
        /// Print why cycle N decided what it did (proposals and the probabilities they read,
        /// conflicts, resources, guarantee margins); no HTML unless --out is given.
        #[arg(long, value_name = "N")]
        cycle: Option<u64>,
    },
    /// Export a run's decision records (and its flight.tlog telemetry) for Foxglove or
    /// PlotJuggler: MCAP with JSON-schema channels, or CSV with one row per record.
    Export {
        /// Run folder (runs/<UTC time>/) or a decisions*.jsonl file.
        run_or_log: PathBuf,
        #[arg(long, value_enum)]
        format: companion::export::Format,
        /// Output file (default: export.mcap / export.csv in the run folder).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Fit the mission's power model, the activities' durations and the health BN rows the
    /// logs can teach to flown or simulated runs; print the fit error before and after and
    /// write a params overlay (docs/calibrate.md).
    Calibrate(companion::calibrate::CalibrateArgs),
    /// Feed a run's logged observations to a fresh core built from the params in its log
    /// header, and report the first cycle whose record differs (exit 0 all equal, 1 a cycle
    /// differs, 2 the log cannot be replayed).
    Replay {
        /// Run folder (runs/<UTC time>/) or a decisions*.jsonl file.
        run_folder: PathBuf,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    init_logging(cli.log_level.as_deref())?;
    match cli.command {
        Command::Simulate(mut args) => {
            args.params = profile(args.params.take(), args.vehicle.as_deref())?;
            let params = args.params.clone().unwrap_or_else(default_params_dir);
            simulate(&params, args)
        }
        Command::Check(mut args) => {
            args.params = profile(args.params.take(), args.vehicle.as_deref())?;
            companion::check::run(&args)
        }
        // Names the operator gave (--vehicle, paths, URLs) reach the terminal escaped.
        Command::Fly(mut args) => {
            args.params = profile(args.params.take(), args.vehicle.as_deref()).map_err(escaped)?;
            fly(args).map_err(escaped)
        }
        Command::SigningSetup(args) => companion::signing_setup::run(&args).map_err(escaped),
        Command::Review {
            run_or_log,
            out,
            summary,
            cycle,
        } => {
            // The folder name is the user's: shown escaped, never sent to the terminal raw.
            companion::review::run_with_cycle(&run_or_log, out.as_deref(), summary, cycle)
                .map_err(|e| {
                    anyhow::anyhow!(companion::review::text::escape_controls(
                        &e.to_string(),
                        false
                    ))
                })?;
            Ok(())
        }
        Command::Export {
            run_or_log,
            format,
            out,
        } => companion::export::run_cli(&run_or_log, format, out.as_deref()),
        Command::Calibrate(args) => companion::calibrate::run(&args),
        Command::Replay { run_folder } => {
            std::process::exit(companion::replay::run_cli(&run_folder));
        }
    }
}

/// An error whose text may hold names from the command line or the disk, with every control
/// character escaped: shown, never obeyed by the terminal.
fn escaped(e: anyhow::Error) -> anyhow::Error {
    anyhow::anyhow!(companion::review::text::escape_controls(
        &format!("{e:#}"),
        false
    ))
}

/// `--params` with `--vehicle NAME` applied: the profile's overlay in place of the directory.
fn profile(params: Option<PathBuf>, vehicle: Option<&str>) -> Result<Option<PathBuf>> {
    match vehicle {
        None => Ok(params),
        Some(name) => companion::params::vehicle_profile(params.as_deref(), name).map(Some),
    }
}

fn fly(mut args: FlyArgs) -> Result<()> {
    let params = args.params.clone().unwrap_or_else(default_params_dir);
    // Every params file, as `check` loads it, before any run folder or socket; the plan judged
    // is the route's (docs/guarantee.md).
    let legacy = args
        .legacy_plan
        .then_some(companion::route_input::DERIVE_MISSION);
    // A route relative to home among absolute zones waits for the autopilot's home to be
    // planned (fly::home_plan; no start until then); the route alone stands in meanwhile.
    // `--mission autopilot --zones`: the zones are the autopilot mission's, placed from its own
    // home when it is planned (fly::autopilot_plan), not the default route's.
    let autopilot = args.flies_autopilot_mission();
    args.plan_waits_for_home = !autopilot
        && companion::route_input::plan_needs_home(
            &params,
            args.zones.as_deref(),
            args.route_file(),
            args.home.as_deref(),
        )
        .context("loading params")?;
    let zones = (args.zones.as_deref()).filter(|_| !args.plan_waits_for_home && !autopilot);
    let (loaded, plan) = companion::route_input::load_with_plan(
        &params,
        legacy,
        zones,
        args.route_file(),
        args.home.as_deref(),
    )
    .context("loading params")?;
    if args.plan_waits_for_home {
        println!(
            "plan: waiting for the autopilot's home to place the route among the zones of {} \
            (no start until then; the plan below stands in)",
            args.zones
                .as_deref()
                .map(|z| z.display().to_string())
                .unwrap_or_default()
        );
    }
    println!("{}", companion::route_input::summary_line(&plan));
    tracing::info!("{}", companion::route_input::summary_line(&plan));
    args.plan = Some(plan);
    let model = Arc::new(loaded.model);
    let policy: Policy = model
        .policy(&args.policy)
        .map_err(|e| anyhow::anyhow!("--policy: {e}"))?;
    let learner =
        companion::learn_cpt::OnlineCpt::when(args.learn_cpt, &loaded.files, loaded.learning)?;
    let decider = CoreDecider::new(model, ModelKind::Bfm, policy, learner);
    companion::fly::run(args, decider)
}

/// The params and the plan `simulate` judges (`--mission`, `--zones`, `--home`, as `check`).
fn simulate_plan(
    params: &std::path::Path,
    args: &SimulateArgs,
) -> Result<(
    companion::params::Params,
    companion::route_input::PlanSummary,
)> {
    companion::route_input::load_with_plan(
        params,
        args.mission.as_deref(),
        args.zones.as_deref(),
        None,
        args.home.as_deref(),
    )
    .context("loading params")
}

/// `--model bfm,reference,...`.
fn model_kinds(list: &str) -> Result<Vec<ModelKind>> {
    (list.split(','))
        .map(|m| m.trim().parse::<ModelKind>())
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow::anyhow!("--model: {e}"))
}

/// `simulate --live`: the server, and the wait for a first viewer (bounded, said).
fn simulate_live_start(
    args: &SimulateArgs,
) -> Result<(std::time::SystemTime, Option<companion::live::LiveServer>)> {
    let started = std::time::SystemTime::now();
    let header_start = companion::decision_log::Header::new(String::new(), started).started_utc;
    let start_ns = companion::export::rfc3339_ns(&header_start).unwrap_or(0);
    let Some(live) = companion::live::start(&args.live, start_ns)? else {
        return Ok((started, None));
    };
    eprintln!(
        "live: waiting up to {} s for a viewer to subscribe before the first step",
        args.live_wait
    );
    let wait = std::time::Duration::from_secs_f64(args.live_wait);
    if !live.hub().wait_for_subscriber(wait) {
        eprintln!(
            "live: no viewer subscribed within {} s: simulating without one",
            args.live_wait
        );
    }
    Ok((started, Some(live)))
}

/// `simulate --live`: the first run's records stamped (`live_dropped`) and served, paced by the
/// viewers (at most 1 s each); the records as the log gets them.
fn simulate_live_serve(
    first: sim::RunResult,
    live: Option<companion::live::LiveServer>,
) -> Result<sim::RunResult> {
    let Some(live) = live else {
        return Ok(first);
    };
    let mut sink =
        companion::live::LiveSink::new(Vec::with_capacity(first.records.len()), Some(live.hub()));
    for r in &first.records {
        companion::fly::RecordSink::write(&mut sink, r)?;
        live.hub().wait_for_room(std::time::Duration::from_secs(1));
    }
    eprintln!("companion simulate:{}", companion::live::finish(Some(live)));
    Ok(sim::RunResult {
        records: sink.inner,
        ..first
    })
}

fn simulate(params: &std::path::Path, args: SimulateArgs) -> Result<()> {
    // An unparsable COMPANION_LOG_MAX_BYTES stops the start, before any work.
    let log_opts = companion::decision_log::WriterOptions::from_env()?;
    let (loaded, plan) = simulate_plan(params, &args)?;
    let (started, live) = simulate_live_start(&args)?;
    let world = loaded.world;
    let mut scenario = Scenario::load(&loaded.files, &args.scenario)?;
    if let Some(s) = args.steps {
        scenario.steps = s;
    }
    let kinds = model_kinds(&args.model)?;
    let model = Arc::new(loaded.model);
    let policy: Policy = model
        .policy(&args.policy)
        .map_err(|e| anyhow::anyhow!("--policy: {e}"))?;
    let learner =
        companion::learn_cpt::OnlineCpt::when(args.learn_cpt, &loaded.files, loaded.learning)?;
    // One decider for every run: each run is a new flight (a fresh core of the run's kind, the
    // learner from the loaded rows).
    let mut decider = CoreDecider::new(Arc::clone(&model), ModelKind::Bfm, policy, learner);
    let runs = args.runs.max(1);
    let progress = (!args.json && runs > 1 && std::io::stderr().is_terminal()).then(|| {
        let pb = indicatif::ProgressBar::new(runs as u64 * kinds.len() as u64);
        pb.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} runs {elapsed}").unwrap(),
        );
        pb
    });

    let mut per_model = Vec::new();
    let mut first_records = None;
    let mut first_allocations: Option<(usize, Option<String>)> = None;
    for kind in &kinds {
        let mut steps = Vec::with_capacity(runs as usize);
        for r in 0..runs {
            let seed = args.seed + r as u64;
            decider.new_flight_of(*kind);
            let result = sim::run_cycle(&world, &scenario, seed, &mut decider);
            if first_allocations.is_none() {
                let core = decider.core();
                first_allocations = Some((core.reallocations(), core.allocation_table()));
            }
            steps.push(result.tracking_steps as f64);
            if first_records.is_none() {
                first_records = Some((kind.name(), result));
            }
            if let Some(pb) = &progress {
                pb.inc(1);
            }
        }
        per_model.push((kind.name(), steps));
    }
    if let Some(pb) = progress {
        pb.finish_and_clear();
    }
    let (first_kind, first) = first_records.expect("at least one run");

    let first = simulate_live_serve(first, live)?; // served live, then logged for `review`
    if !args.no_log {
        let command: Vec<String> = std::env::args().collect();
        let mut header = companion::decision_log::Header::new(command.join(" "), started)
            .with_params_dir(params)
            .with_context(|| format!("reading {} for the log header", params.display()))?;
        header.policy = Some(model.policy_name(policy).to_string());
        header.scenario = Some(scenario.name.clone());
        header.model = Some(first_kind.to_string());
        header.seed = Some(args.seed);
        header.step_s = Some(world.step_s);
        header.plan = Some(plan.clone());
        let log = companion::decision_log::start_run(&args.runs_dir, started, header, log_opts)
            .with_context(|| format!("starting a run folder in {}", args.runs_dir.display()))?;
        let dir = log.dir().to_path_buf();
        if args.json {
            eprintln!("run folder: {}", dir.display());
        } else {
            println!("run folder: {}", dir.display());
        }
        for r in &first.records {
            log.record(r.clone());
        }
        let stats = log.close();
        if stats.dropped > 0 {
            eprintln!(
                "warning: the decision log lost {} records (writer behind {}, write failed {}, \
                 size cap {}, too large {})",
                stats.dropped, stats.queue_full, stats.write_failed, stats.capped, stats.too_large
            );
        }
    }

    if args.json {
        let tracking: serde_json::Map<String, serde_json::Value> = per_model
            .iter()
            .map(|(name, xs)| {
                let (mean, ci) = sim::mean_ci95(xs);
                (
                    name.to_string(),
                    serde_json::json!({ "mean": mean, "ci95": ci, "runs": xs }),
                )
            })
            .collect();
        let out = serde_json::json!({
            "scenario": scenario.name,
            "policy": model.policy_name(policy),
            "runs": runs,
            "steps": scenario.steps,
            "seed": args.seed,
            "models": kinds.iter().map(|k| k.name()).collect::<Vec<_>>(),
            "tracking_steps": tracking,
            "first_run": { "model": first_kind, "outcome": first.outcome, "tracking_steps": first.tracking_steps, "battery_pct_end": first.battery_pct_end },
            "plan": companion::route_input::PlanSummary { derived: Vec::new(), ..plan },
            "decisions": first.records,
        });
        println!("{}", serde_json::to_string(&out)?);
        return Ok(());
    }

    println!(
        "scenario {} ({}), policy {}, model {}, seed {}, {} steps",
        scenario.name,
        scenario.description,
        model.policy_name(policy),
        first_kind,
        args.seed,
        scenario.steps
    );
    println!("{}", companion::route_input::summary_line(&plan));
    println!();
    print!(
        "{}",
        companion_core::decision::table(&first.records, &model)
    );
    println!();
    if let Some((n, Some(table))) = &first_allocations
        && *n > 0
    {
        println!();
        println!("PANORAMA allocations ({n} re-allocation(s)):");
        print!("{table}");
    }
    println!(
        "outcome: {:?} after {} steps, battery {:.0}% left; tracking time {} steps",
        first.outcome, first.steps_flown, first.battery_pct_end, first.tracking_steps
    );
    if runs > 1 {
        println!();
        println!(
            "tracking time over {runs} seeds ({}..{}):",
            args.seed,
            args.seed + runs as u64 - 1
        );
        for (name, xs) in &per_model {
            let (mean, ci) = sim::mean_ci95(xs);
            println!("  {name:<11} {mean:6.1} steps  ± {ci:.1} (95% CI)");
        }
    }
    Ok(())
}
