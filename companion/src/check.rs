//! `companion check`: load every params file exactly as `fly` and `simulate` do
//! ([`crate::params::Params::load`]) and show what it compiles to.
//!
//! The report is a list of sections, each a JSON value under its key plus a human rendering.
//! Adding a section (platform, variants, guarantee) is one line in [`SECTIONS`].

use anyhow::Context;
use companion_core::health::HealthModel;
use serde_json::{Value, json};
use std::path::PathBuf;

#[derive(Debug, Clone, Default, clap::Args)]
pub struct CheckArgs {
    /// Print the report as JSON (`{"health": [...], ...}`).
    #[arg(long)]
    pub json: bool,
    /// Evidence for the health BNs: `NAME=STATE` or `OBSERVATION=VALUE`, comma-separated.
    /// NAME is a node name, case-insensitive, with or without its role prefix
    /// (`wind=strong,target_speed=high,qos=high`; `luminosity_lux=20`).
    #[arg(long)]
    pub evidence: Option<String>,
    /// The params directory (default: $COMPANION_PARAMS or the workspace's params/) or a params overlay file
    /// (`companion calibrate --out`, docs/calibrate.md).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// A vehicle profile: params/vehicles/NAME.toml, a params overlay made by `companion
    /// calibrate` from that vehicle's flights (docs/calibrate.md); the default is the paper's
    /// mission with its stated assumptions.
    #[arg(long, value_name = "NAME")]
    pub vehicle: Option<String>,
    /// PANORAMA mission for the pre-flight allocation: a name in params/missions/ (`tracking`,
    /// `patrolling`) or a path; or a route to derive the activities from, told by content: a
    /// QGroundControl `.plan`, a WPL 110 file or a route TOML (docs/guarantee.md).
    #[arg(long)]
    pub mission: Option<String>,
    /// Zones: a GeoJSON FeatureCollection of Polygon / MultiPolygon features whose
    /// `properties.constraints` name constraint classes of the mission; the route's legs are split
    /// where they enter or leave one.
    #[arg(long, value_name = "FILE.geojson")]
    pub zones: Option<PathBuf>,
    /// Home as LAT,LON (degrees), to place a route given relative to home among the zones.
    #[arg(long, value_name = "LAT,LON")]
    pub home: Option<String>,
    /// The route file `fly --mission FILE` would fly (default params/missions/tracking_route.toml).
    #[arg(long)]
    pub route: Option<PathBuf>,
}

/// What a section builder gets.
pub struct CheckContext<'a> {
    pub params: &'a companion_core::spec::ParamsFiles,
    pub args: &'a CheckArgs,
    /// Everything loaded and cross-checked from `params`.
    pub loaded: &'a crate::params::Params,
    /// Activities derived from `--mission FILE` / `--zones FILE`, when given.
    pub derived: Option<&'a crate::route_input::Derived>,
}

/// A section: its JSON value and its human text.
pub type SectionFn = fn(&CheckContext) -> anyhow::Result<(Value, String)>;

/// The report sections, in order.
pub const SECTIONS: &[(&str, SectionFn)] = &[
    ("health", health_section),
    ("mdps", mdp_section),
    ("probabilities", probabilities_section),
    ("observations", observations_section),
    ("absent_evidence", absent_evidence_section),
    ("actions", actions_section),
    ("platform", platform_section),
    ("variants", variants_section),
    ("resource_policies", resource_policies_section),
    ("guarantee", guarantee_section),
    ("fly", fly_section),
];

/// What `fly` loads besides the model: the link settings, the vehicle actions' MAVLink steps and
/// the route.
pub fn fly_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    let (link, commands, route, route_file) = crate::params::load_fly_files(
        cx.params,
        cx.args.route.as_deref(),
        &cx.loaded.model.actions,
    )?;
    let actions = commands.entry_names();
    let text = format!(
        "\nfly: decision period {} s, {} streams; vehicle actions: {}\n  route {}: {} waypoints at {} m\n",
        link.decision_period_s,
        link.streams.len(),
        actions.join(", "),
        route_file.display(),
        route.waypoints.len(),
        route.altitude_m
    );
    let v = json!({
        "decision_period_s": link.decision_period_s,
        "streams": link.streams,
        "vehicle_actions": actions,
        "route": {
            "file": route_file.display().to_string(),
            "waypoints": route.waypoints.len(),
            "altitude_m": route.altitude_m,
        },
    });
    Ok((v, text))
}

/// The MDPs the decision layer loads (states, actions, probabilities named), validated against
/// the health managers' published names.
pub fn mdp_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let health = HealthModel::load(cx.params)?;
    let names = health.publishes();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let mdps = companion_core::mission_mdp::MissionMdps::load(cx.params, &refs)?;
    let mut text = String::from("\nMDPs (params/mdp/):\n");
    let mut arr = Vec::new();
    for m in mdps.all() {
        let _ = writeln!(
            text,
            "  {:<11} {:>2} states x {:>2} actions; probabilities: {}",
            m.name(),
            m.n_states(),
            m.n_actions(),
            m.probability_names().join(", ")
        );
        arr.push(json!({
            "name": m.name(),
            "states": m.states(),
            "actions": m.action_names(),
            "probabilities": m.probability_names(),
        }));
    }
    let _ = writeln!(text, "  concurrent: {}", mdps.concurrent().join(", "));
    Ok((Value::Array(arr), text))
}

/// Every named probability with the health manager that publishes it and what reads it (MDPs,
/// the guarantee's cap, the record only), as the model load checks them.
pub fn probabilities_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let health = HealthModel::load(cx.params)?;
    let names = health.publishes();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let mdps = companion_core::mission_mdp::MissionMdps::load(cx.params, &refs)?;
    let mission = companion_core::mission::MissionFile::load(cx.params)?;
    let all = companion_core::probabilities::named_probabilities(&health, &mdps, &mission);
    let mut text = String::from("\nNamed probabilities (publisher -> readers):\n");
    for p in &all {
        let readers: Vec<String> = p
            .consumers
            .iter()
            .map(|c| format!("{} {}", c.kind, c.name))
            .collect();
        let _ = writeln!(
            text,
            "  {:<10} {:<12} -> {}",
            p.name,
            p.publisher,
            readers.join(", ")
        );
    }
    Ok((serde_json::to_value(&all)?, text))
}

/// Every observation something reads, with its BN node, who produces it (world, scenarios, fly,
/// core) and who reads it, as the load checks them.
pub fn observations_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let all = crate::vocabulary::named_observations(&cx.loaded.sources())?;
    let roles = |rs: &[crate::vocabulary::Role]| {
        rs.iter()
            .map(|r| format!("{} {}", r.kind, r.name))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut text = String::from("\nObservations (producers -> readers):\n");
    for o in &all {
        let _ = writeln!(
            text,
            "  {:<20} {:<22} {} -> {}",
            o.name,
            o.node.as_deref().unwrap_or("-"),
            roles(&o.producers),
            roles(&o.consumers)
        );
    }
    Ok((serde_json::to_value(&all)?, text))
}

/// Absent is not zero: for every BN evidence node, what feeds it in `fly` and in `simulate`, and
/// so when the node gets no evidence (the record's `absent_evidence`): a sensor never heard, an
/// onboard monitor that does not run, the autopilot not estimating the wind.
pub fn absent_evidence_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let all = crate::vocabulary::named_observations(&cx.loaded.sources())?;
    let mut rows = Vec::new();
    let mut text = String::from("\nEvidence absent when not fed (the record's absent_evidence):\n");
    for o in &all {
        let Some(node) = &o.node else { continue };
        let kinds = |ks: &[&str]| -> Vec<String> {
            o.producers
                .iter()
                .filter(|r| ks.contains(&r.kind))
                .map(|r| match r.kind {
                    "fly_telemetry" => "the autopilot's telemetry".to_string(),
                    "fly_onboard" => format!("onboard NAMED_VALUE_FLOAT `{}`", r.name),
                    "fly" => "the fly shell (derived)".to_string(),
                    k => format!("{k} {}", r.name),
                })
                .collect()
        };
        let computed = o.producers.iter().any(|r| r.kind == "core");
        let fly = if computed {
            "never absent: the decision core computes it".to_string()
        } else {
            let from = kinds(&["fly_telemetry", "fly_onboard", "fly"]);
            let mut t = if from.is_empty() {
                "absent on every cycle: nothing feeds it in fly".to_string()
            } else {
                format!("absent until heard from {}", from.join(" or "))
            };
            if o.name == "wind_mps" {
                t.push_str(
                    ", and while WIND / WIND_COV read all zero (the autopilot not estimating the wind; docs/mavlink.md)",
                );
            }
            t
        };
        let simulate = if computed {
            "never absent".to_string()
        } else if o.producers.iter().any(|r| r.kind == "world") {
            "fed by the simulated world".to_string()
        } else {
            let from = kinds(&["scenario"]);
            if from.is_empty() {
                "absent on every cycle".to_string()
            } else {
                format!("absent except in {}", from.join(", "))
            }
        };
        let _ = writeln!(
            text,
            "  {node:<22} {:<20} fly: {fly}; simulate: {simulate}",
            o.name
        );
        rows.push(serde_json::json!({
            "node": node,
            "observation": o.name,
            "fly": fly,
            "simulate": simulate,
        }));
    }
    Ok((Value::from(rows), text))
}

/// Every primitive action with the MDPs that propose it, its application variant and whether fly
/// maps it to MAVLink steps (params/commands.toml).
pub fn actions_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let all = crate::vocabulary::actions(&cx.loaded.sources());
    let mut text = String::from("\nActions (proposed by; application or MAVLink steps):\n");
    for a in &all {
        let runs = match &a.action.application {
            Some(app) => format!("{}/{}", app.app, app.version),
            None if a.vehicle_steps => "steps".to_string(),
            None => "-".to_string(),
        };
        let _ = writeln!(
            text,
            "  {:<24} {:<4} {:<11} {:<20} {}{}",
            a.action.name,
            a.action.paper,
            a.action.kind,
            runs,
            a.action.proposed_by.join(", "),
            if a.flown_as.is_empty() {
                String::new()
            } else {
                format!(" (also flown as {})", a.flown_as.join(", "))
            }
        );
    }
    Ok((serde_json::to_value(&all)?, text))
}

fn resources_json(cx: &CheckContext) -> anyhow::Result<Value> {
    Ok(companion_core::report::resources::check_json(cx.params)?)
}

/// The SoC platform (tiles, CPU) from params/platform.toml.
pub fn platform_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    let spec = companion_core::resources::ResourceSpec::load(cx.params)?;
    let text = format!("\n{}", companion_core::report::resources::check_text(&spec));
    Ok((resources_json(cx)?["platform"].clone(), text))
}

/// The variant catalogue (the BFM paper's Table 2); printed with the platform.
pub fn variants_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    Ok((resources_json(cx)?["variants"].clone(), String::new()))
}

pub fn resource_policies_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    Ok((
        resources_json(cx)?["resource_policies"].clone(),
        String::new(),
    ))
}

/// PANORAMA: activities, RAS0 (Table 6 shape), NGA and initial margins of `--mission`.
pub fn guarantee_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    if let Some(d) = cx.derived {
        let v = companion_core::report::guarantee::check_json_spec(&d.spec);
        let text = format!(
            "\n{}",
            companion_core::report::guarantee::check_text_spec(&d.spec)
        );
        return Ok((v["guarantee"].clone(), text));
    }
    let mission = cx.args.mission.as_deref().unwrap_or("tracking");
    let v = companion_core::report::guarantee::check_json(cx.params, mission)?;
    let text = format!(
        "\n{}",
        companion_core::report::guarantee::check_text(cx.params, mission)?
    );
    Ok((v["guarantee"].clone(), text))
}

/// Parse `a=b,c=d`.
pub fn parse_pairs(s: &str) -> anyhow::Result<Vec<(String, String)>> {
    s.split(',')
        .filter(|x| !x.trim().is_empty())
        .map(|kv| {
            let (k, v) = kv
                .split_once('=')
                .with_context(|| format!("`{kv}` is not NAME=VALUE"))?;
            Ok((k.trim().to_string(), v.trim().to_string()))
        })
        .collect()
}

/// Build the whole report as JSON plus human text.
pub fn report(args: &CheckArgs) -> anyhow::Result<(Value, String)> {
    let params = args
        .params
        .clone()
        .unwrap_or_else(crate::params::default_params_dir);
    // Everything `fly` and `simulate` load, cross-checks included, before any section: a file
    // either of them would refuse fails here with its file, entry and reason.
    let mut files = crate::params::read_params_dir(&params)?;
    // `--mission`, `--zones`, `--route` may name files outside the params directory; the
    // default zones are not `.toml`.
    crate::route_input::add_plan_files(
        &mut files,
        args.mission.as_deref(),
        args.zones.as_deref(),
        args.route.as_deref(),
    );
    report_from(files, args)
}

/// [`report`] on params already read.
pub fn report_from(
    files: companion_core::spec::ParamsFiles,
    args: &CheckArgs,
) -> anyhow::Result<(Value, String)> {
    let loaded = crate::params::Params::from_files(files, args.route.as_deref())?;
    let derived = crate::route_input::derive(
        &loaded.files,
        args.mission.as_deref(),
        args.zones.as_deref(),
        args.route.as_deref(),
        args.home.as_deref(),
    )?;
    let cx = CheckContext {
        params: &loaded.files,
        args,
        loaded: &loaded,
        derived: derived.as_ref(),
    };
    let mut obj = serde_json::Map::new();
    let mut text = String::new();
    let typed = match &derived {
        Some(_) => None,
        None => Some(companion_core::guarantee::load_mission(
            &loaded.files,
            args.mission
                .as_deref()
                .unwrap_or(crate::route_input::DERIVE_MISSION),
        )?),
    };
    let plan = crate::route_input::summary(
        derived.as_ref(),
        typed.as_ref().unwrap_or(&loaded.model.guarantee),
    );
    text.push_str(&format!("\n{}\n", crate::route_input::summary_line(&plan)));
    let mut plan_json = serde_json::to_value(&plan)?;
    if let Some(o) = plan_json.as_object_mut() {
        // `activities` below lists them.
        o.remove("derived");
    }
    obj.insert("plan".into(), plan_json);
    if let Some(d) = &derived {
        obj.insert("activities".into(), crate::route_input::activities_json(d));
        text.push_str(&crate::route_input::activities_text(d));
    }
    for (key, f) in SECTIONS {
        let (v, t) = f(&cx).with_context(|| format!("check {key}"))?;
        obj.insert(key.to_string(), v);
        text.push_str(&t);
    }
    Ok((Value::Object(obj), text))
}

/// `companion check` as the CLI runs it. The report and any error are escaped for the
/// terminal: params strings and folder names are the user's, and a control character in one is
/// shown, not sent (JSON escapes them itself).
pub fn run(args: &CheckArgs) -> anyhow::Result<()> {
    use crate::review::text::escape_controls;
    // A refused input (a bad `--evidence` value, a params error) is one line on stderr and exit
    // code 2: the user's mistake, not a fault to trace (main's error path would print a
    // backtrace under RUST_BACKTRACE=1).
    let (v, text) = match report(args) {
        Ok(r) => r,
        Err(e) => {
            let line = format!("{e:#}").replace('\n', " ");
            eprintln!("error: {}", escape_controls(&line, true));
            std::process::exit(2);
        }
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", escape_controls(&text, true));
    }
    Ok(())
}

fn fmt_dist(states: &[String], p: &[f64]) -> String {
    states
        .iter()
        .zip(p)
        .map(|(s, x)| format!("{s} {x:.4}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Health managers: nodes with roles, states and posteriors; published probabilities.
pub fn health_section(cx: &CheckContext) -> anyhow::Result<(Value, String)> {
    use std::fmt::Write;
    let mut model = HealthModel::load(cx.params)?;
    let pairs = match &cx.args.evidence {
        Some(s) => parse_pairs(s)?,
        None => Vec::new(),
    };
    let evidence = model.resolve_evidence(&pairs)?;
    let values = model.evaluate(&evidence)?;
    let mut text = String::new();
    let mut items = Vec::new();
    if !evidence.is_empty() {
        let ev: Vec<String> = evidence.iter().map(|(k, v)| format!("{k}={v}")).collect();
        writeln!(text, "evidence: {}", ev.join(", "))?;
    }
    for m in &model.managers {
        writeln!(
            text,
            "health manager `{}` ({}): {}",
            m.name,
            m.file.display(),
            m.description
        )?;
        let mut nodes = Vec::new();
        for n in &m.nodes {
            let post = m.marginal(&n.name).unwrap_or(&[]);
            let observed = evidence.get(&n.name);
            writeln!(
                text,
                "  {:<22} {:<15} [{}]{}",
                n.name,
                n.role,
                fmt_dist(&n.states, post),
                observed
                    .map(|s| format!("  <- evidence {s}"))
                    .unwrap_or_default()
            )?;
            nodes.push(json!({
                "name": n.name,
                "role": n.role,
                "states": n.states,
                "parents": n.parents,
                "posterior": post,
                "evidence": observed,
            }));
        }
        let mut publishes = Vec::new();
        for p in &m.publish {
            let v = values.get(&p.name).copied().unwrap_or(f64::NAN);
            writeln!(text, "  publishes {:<10} = {:.4}   {}", p.name, v, p.expr())?;
            publishes.push(json!({ "name": p.name, "query": p.expr(), "value": v }));
        }
        items.push(json!({
            "name": m.name,
            "file": m.file.display().to_string(),
            "description": m.description,
            "nodes": nodes,
            "publishes": publishes,
        }));
    }
    Ok((Value::Array(items), text))
}
