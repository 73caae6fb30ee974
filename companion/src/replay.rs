//! `companion replay RUN_FOLDER`: rebuild the model from the params embedded in the run's log
//! header, feed each logged cycle's inputs to a fresh decision core, and compare what the core
//! produces with what the log says it produced, cycle by cycle, exactly.
//!
//! What a record holds, by origin (see `Core::step_into`, `fly::decide`/`finish_record`, `sim::run`):
//! - inputs: `time_s`, `state`, `observations`, and the observed events (the head of `events`);
//! - the core's output: `evidence`, `probabilities`, `proposals`, `conflicts`, `actions`,
//!   `resources`, `guarantee`, the events the core appended after the observed ones, and in
//!   `simulate` the `cycle` number (`fly` numbers cycles itself);
//! - the shell's additions: `shell_actions`, `commands`, `link_events`, `vehicle`, `utc_us`, and in
//!   `fly` the events of its own decisions appended last (`...: land`, `landing: ...`).
//!
//! - with `--learn-cpt` in the header's command: `cpt_learned`, re-derived from the logged records
//!   by the same learner (`learn_cpt`), compared, and applied to the replayed core.
//!
//! The core does not read the observed events, so it is stepped with none: its record's events
//! are then exactly the ones it added, and [`split_events`] finds them in the logged list.

use crate::decision_log::{Header, SCHEMA_VERSION};
use companion_core::decision::{Core, Model, ModelKind, Policy};
use companion_core::observations::Observations;
use companion_core::record::DecisionRecord;
use companion_core::record::Event;
use companion_core::spec::ParamsFiles;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Record fields the core computes from its inputs and its own state (compared exactly, in this
/// order; `events` and `cycle` are compared apart).
pub const CORE_FIELDS: [&str; 7] = [
    "evidence",
    "probabilities",
    "proposals",
    "conflicts",
    "actions",
    "resources",
    "guarantee",
];

/// The longest log line read (the reader's bound).
const MAX_LINE_BYTES: usize = crate::decision_log::MAX_LINE_BYTES;

/// Which shell wrote the log (from the header's command line).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    Simulate,
    Fly,
}

/// How a replay ended when the log could be replayed.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// Every record equals the fresh core's.
    AllEqual {
        cycles: u64,
        /// A cut-off last line (the process was killed while writing it), not replayed.
        truncated: Option<(PathBuf, usize)>,
    },
    /// The first record that differs; `equal` records before it matched.
    Differs(Box<Difference>),
}

/// Where and how a logged record differs from the replayed one.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    pub file: PathBuf,
    pub line: usize,
    pub cycle: u64,
    /// Path of the first differing value (`probabilities.P_V3`, `proposals[0].action`).
    pub field: String,
    /// Both values as JSON (`(absent)` when one side has none).
    pub logged: String,
    pub replayed: String,
    pub equal: u64,
}

impl std::fmt::Display for Difference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "cycle {} differs ({}:{}): {}: logged {}, replayed {} ({} cycles before it equal)",
            self.cycle,
            self.file.display(),
            self.line,
            self.field,
            self.logged,
            self.replayed,
            self.equal
        )
    }
}

/// Why a log cannot be replayed, with where.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {reason}", file.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
pub struct Refusal {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub reason: String,
}

fn refuse(file: &Path, line: Option<usize>, reason: impl Into<String>) -> Refusal {
    Refusal {
        file: file.to_path_buf(),
        line,
        reason: reason.into(),
    }
}

/// Replay the run folder or log file at `path`.
pub fn replay(path: &Path) -> Result<Outcome, Refusal> {
    // The parts in order, as the reader lists them (nothing is read yet).
    let files = crate::decision_log::stream_log(path)
        .map_err(|e| refuse(path, None, e.to_string()))?
        .files()
        .to_vec();
    let mut run: Option<Run> = None;
    // The header's schema: a schema-1 record (sentences) is migrated before it is compared.
    let mut schema: Option<u32> = None;
    let mut equal = 0u64;
    let n_files = files.len();
    for (k, file) in files.iter().enumerate() {
        let f = std::fs::File::open(file).map_err(|e| refuse(file, None, e.to_string()))?;
        let mut reader = BufReader::new(f);
        let mut buf = Vec::new();
        let mut line_no = 0usize;
        loop {
            buf.clear();
            let n = (&mut reader)
                .take(MAX_LINE_BYTES as u64 + 1)
                .read_until(b'\n', &mut buf)
                .map_err(|e| refuse(file, Some(line_no + 1), e.to_string()))?;
            if n == 0 {
                break;
            }
            line_no += 1;
            let at = Some(line_no);
            let complete = buf.ends_with(b"\n");
            if !complete && n > MAX_LINE_BYTES {
                return Err(refuse(file, at, "line longer than the reader's bound"));
            }
            let text = std::str::from_utf8(&buf).map_err(|_| refuse(file, at, "not UTF-8"))?;
            if text.trim().is_empty() {
                continue;
            }
            let mut value: Value = match serde_json::from_str(text) {
                Ok(v) => v,
                // A cut-off last line: the process was killed while writing it.
                Err(_) if !complete && k + 1 == n_files => {
                    if run.is_none() {
                        return Err(refuse(file, at, "cut off before any record"));
                    }
                    return Ok(Outcome::AllEqual {
                        cycles: equal,
                        truncated: Some((file.clone(), line_no)),
                    });
                }
                Err(e) => return Err(refuse(file, at, format!("not JSON: {e}"))),
            };
            match value.get("kind").and_then(Value::as_str) {
                Some("header") => {
                    if run.is_none() {
                        if line_no != 1 || k != 0 {
                            return Err(refuse(file, at, "the header is not the first line"));
                        }
                        let (model, setup, learner) = Run::from_header(&value, file)?;
                        schema = value
                            .get("schema")
                            .and_then(Value::as_u64)
                            .and_then(|v| u32::try_from(v).ok());
                        let mut r = Run::new(Arc::new(model), setup);
                        r.learner = learner;
                        r.route_plan = Run::route_plan(&value, file);
                        run = Some(r);
                    }
                    // A rotated part repeats the header: nothing new.
                }
                Some("event" | "end") => {}
                Some("loss") => {
                    return Err(refuse(
                        file,
                        at,
                        format!(
                            "records were lost here ({} cycles before it replayed equal): the \
                             core's state after the missing cycles is unknown",
                            equal
                        ),
                    ));
                }
                Some(other) => {
                    return Err(refuse(file, at, format!("unknown line kind `{other}`")));
                }
                None => {
                    let Some(run) = run.as_mut() else {
                        return Err(refuse(
                            file,
                            at,
                            "a record before any header: no params to rebuild the model from",
                        ));
                    };
                    if crate::decision_log::migration::needs_migration(schema) {
                        crate::decision_log::migration::record_v1(&mut value);
                    }
                    if let Some(mut d) = run.replay_record(&value, file, line_no)? {
                        d.equal = equal;
                        return Ok(Outcome::Differs(Box::new(d)));
                    }
                    equal += 1;
                }
            }
        }
        if run.is_none() {
            return Err(refuse(
                file,
                None,
                "no header line: no params to rebuild the model from",
            ));
        }
    }
    Ok(Outcome::AllEqual {
        cycles: equal,
        truncated: None,
    })
}

/// What the header says about the run besides its params.
#[derive(Clone, Copy)]
struct Setup {
    kind: ModelKind,
    policy: Policy,
    source: Source,
}

/// The model rebuilt from a header, and the core being replayed.
struct Run {
    model: Arc<Model>,
    setup: Setup,
    core: Core,
    /// The run learned its CPT rows (`--learn-cpt`): re-derived here from the logged records.
    learner: Option<crate::learn_cpt::OnlineCpt>,
    /// The header's route plan, to plan again where `fly` re-planned its route at the
    /// autopilot's cruise speed (`fly/route_replan.rs`).
    route_plan: Option<RoutePlan>,
    /// The mission the run's core plans since such a re-plan (a new flight's core takes it).
    mission: Option<companion_core::guarantee::MissionSpec>,
}

/// The plan of the companion's own route as the header gives it.
struct RoutePlan {
    files: ParamsFiles,
    mission: String,
    derived: Vec<companion_core::route_plan::DerivedActivity>,
}

impl RoutePlan {
    /// The route's activities at cruise speed `cruise` (m/s): its legs and return at `cruise`
    /// through the profile's speed fraction, as `fly` derives a route TOML (which has no
    /// DO_CHANGE_SPEED), and the PANORAMA mission on them.
    fn at_cruise(&self, cruise: f64) -> anyhow::Result<companion_core::guarantee::MissionSpec> {
        use companion_core::route_plan::ActivityKind;
        let fraction =
            companion_core::guarantee::derive_settings(&self.files, &self.mission)?.speed_fraction;
        let mut acts = self.derived.clone();
        for a in &mut acts {
            if matches!(a.kind, ActivityKind::Leg | ActivityKind::Return) {
                a.speed_mps = cruise * fraction;
            }
        }
        Ok(companion_core::guarantee::derived_mission(
            &self.files,
            &self.mission,
            &acts,
            &[],
        )?)
    }
}

/// The cruise speed of a route re-plan among a record's events.
fn replanned_cruise(events: &[Event]) -> Option<f64> {
    events.iter().find_map(|e| match e {
        Event::RouteReplanned { cruise_mps, .. } => Some(*cruise_mps),
        _ => None,
    })
}

impl Run {
    fn new(model: Arc<Model>, setup: Setup) -> Self {
        Run {
            core: Core::new(Arc::clone(&model), setup.kind, setup.policy),
            model,
            setup,
            learner: None,
            route_plan: None,
            mission: None,
        }
    }

    /// The header's plan when it is derived from the companion's own route.
    fn route_plan(value: &Value, file: &Path) -> Option<RoutePlan> {
        let header: Header = serde_json::from_value(value.clone()).ok()?;
        let plan = header.plan.as_ref().filter(|p| !p.derived.is_empty())?;
        plan.route_file.as_ref()?;
        Some(RoutePlan {
            files: params_files(&header, file).ok()?,
            mission: plan.mission.clone(),
            derived: plan.derived.clone(),
        })
    }

    /// The model and the run's setup from the header line.
    fn from_header(
        value: &Value,
        file: &Path,
    ) -> Result<(Model, Setup, Option<crate::learn_cpt::OnlineCpt>), Refusal> {
        let at = Some(1);
        let header: Header = serde_json::from_value(value.clone())
            .map_err(|e| refuse(file, at, format!("not a log header: {e}")))?;
        if header.schema > SCHEMA_VERSION {
            return Err(refuse(
                file,
                at,
                format!(
                    "schema {} is newer than this build's {SCHEMA_VERSION}",
                    header.schema
                ),
            ));
        }
        let source = source_of(&header.command).ok_or_else(|| {
            refuse(
                file,
                at,
                format!(
                    "the header's command `{}` is neither `simulate` nor `fly`",
                    header.command
                ),
            )
        })?;
        let kind = match (&header.model, source) {
            (Some(m), _) => m
                .parse()
                .map_err(|e: String| refuse(file, at, format!("header model: {e}")))?,
            // Logs of older builds name no model: `fly` runs the three concurrent MDPs;
            // `simulate` logs the first run of its first `--model`.
            (None, Source::Fly) => ModelKind::Bfm,
            (None, Source::Simulate) => simulate_model(&header.command)
                .parse()
                .map_err(|e: String| refuse(file, at, format!("header command: {e}")))?,
        };
        let policy_name = header
            .policy
            .as_deref()
            .ok_or_else(|| refuse(file, at, "the header names no policy"))?;
        if header.params.is_empty() {
            return Err(refuse(file, at, "the header holds no params"));
        }
        let files = params_files(&header, file)?;
        let mut model = Model::load(&files).map_err(|e| {
            refuse(
                file,
                at,
                format!("the model cannot be rebuilt from the header's params: {e}"),
            )
        })?;
        // The plan the run judged: its derived activities on the header's PANORAMA mission.
        if let Some(plan) = header.plan.as_ref().filter(|p| !p.derived.is_empty()) {
            model.guarantee = companion_core::guarantee::derived_mission(
                &files,
                &plan.mission,
                &plan.derived,
                &[],
            )
            .map_err(|e| refuse(file, at, format!("the header's plan: {e}")))?;
        }
        // Policy names are the params' own: resolved against the model the header rebuilds.
        let policy: Policy = model
            .policy(policy_name)
            .map_err(|e| refuse(file, at, format!("header policy: {e}")))?;
        let learner = learns_cpt(&header.command)
            .then(|| {
                crate::learn_cpt::LearningParams::load(&files)
                    .and_then(|p| crate::learn_cpt::OnlineCpt::new(&files, p))
                    .map_err(|e| refuse(file, at, format!("--learn-cpt: {e}")))
            })
            .transpose()?;
        Ok((
            model,
            Setup {
                kind,
                policy,
                source,
            },
            learner,
        ))
    }

    /// Step the core on one logged record's inputs; `Some` when its output differs.
    fn replay_record(
        &mut self,
        value: &Value,
        file: &Path,
        line: usize,
    ) -> Result<Option<Difference>, Refusal> {
        let at = Some(line);
        let logged: DecisionRecord = serde_json::from_value(value.clone()).map_err(|e| {
            refuse(
                file,
                at,
                format!("not a decision record the core can have produced: {e}"),
            )
        })?;
        for name in ["time_s", "state", "observations"] {
            if value.get(name).is_none() {
                return Err(refuse(file, at, format!("the record has no `{name}`")));
            }
        }
        let source = self.setup.source;
        // `fly` queues Event::NewFlight for the first cycle after a flight ended landed and
        // disarmed, when it starts a fresh core for the next flight: replay restarts its core there.
        // `fly` re-planned its route at the autopilot's cruise speed before this cycle.
        if source == Source::Fly
            && let Some(cruise) = replanned_cruise(&logged.events)
            && let Some(plan) = &self.route_plan
        {
            let spec = plan.at_cruise(cruise).map_err(|e| {
                refuse(
                    file,
                    at,
                    format!("the route re-planned at {cruise} m/s: {e:#}"),
                )
            })?;
            self.mission = Some(spec.clone());
            self.core.replace_mission(spec);
        }
        if source == Source::Fly && logged.events.contains(&Event::NewFlight) {
            self.core = Core::new(Arc::clone(&self.model), self.setup.kind, self.setup.policy);
            if let Some(spec) = &self.mission {
                self.core.replace_mission(spec.clone());
            }
            if let Some(l) = self.learner.as_mut() {
                l.start_run();
            }
        }
        let obs = Observations {
            time_s: logged.time_s,
            state: logged.state.clone(),
            values: logged.observations.clone(),
            events: Vec::new(),
        };
        let (_, replayed) = self.core.step(&obs);
        let differs = |field: String, logged: String, replayed: String| Difference {
            file: file.to_path_buf(),
            line,
            cycle: logged_cycle(value),
            field,
            logged,
            replayed,
            equal: 0,
        };
        let replayed_value = serde_json::to_value(&replayed).expect("a decision record serialises");
        if source == Source::Simulate {
            let fields = ["cycle"];
            if let Some(d) = first_difference(&fields, value, &replayed_value) {
                return Ok(Some(differs(d.0, d.1, d.2)));
            }
        }
        if let Some(d) = first_difference(&CORE_FIELDS, value, &replayed_value) {
            return Ok(Some(differs(d.0, d.1, d.2)));
        }
        let Some((observed, _, _)) = split_events(&logged.events, &replayed.events, source) else {
            return Ok(Some(differs(
                "events".into(),
                json(&logged.events),
                format!("the observed events followed by {}", json(&replayed.events)),
            )));
        };
        // The rows learned from this record's outcome, re-derived from the logged record (its
        // core fields just replayed equal; its outcome is the world's, or the observed events).
        let learned = match (self.learner.as_mut(), source) {
            (None, _) => Vec::new(),
            (Some(l), Source::Simulate) => l.learn_simulated(&mut self.core, &logged),
            (Some(l), Source::Fly) => l.learn_flown(&mut self.core, &logged, observed),
        };
        // As the record serialises it: no field when nothing was learned.
        let learned = if learned.is_empty() {
            serde_json::json!({})
        } else {
            serde_json::json!({ "cpt_learned": learned })
        };
        if let Some(d) = first_difference(&["cpt_learned"], value, &learned) {
            return Ok(Some(differs(d.0, d.1, d.2)));
        }
        Ok(None)
    }
}

/// Split a logged record's events into (observed, core-added, shell-added), given what the core
/// adds for the same inputs; `None` when the logged list cannot hold them in that order. The
/// shell's own events come last and only in `fly` logs.
pub fn split_events<'a>(
    logged: &'a [Event],
    core_added: &[Event],
    source: Source,
) -> Option<(&'a [Event], &'a [Event], &'a [Event])> {
    let is_shell = |e: &Event| source == Source::Fly && e.is_shell();
    // The shell's events are a tail of recognisable sentences after the core's: take the
    // fewest that leave a head ending with the core's.
    let mut end = logged.len();
    loop {
        if ends_with_core(&logged[..end], core_added) {
            let observed = end - core_added.len();
            return Some((&logged[..observed], &logged[observed..end], &logged[end..]));
        }
        if end == 0 || !is_shell(&logged[end - 1]) {
            return None;
        }
        end -= 1;
    }
}

/// Whether `head` ends with the core's events: each equal, or logged as text saying the same
/// sentence (a schema-1 sentence whose numbers are rounded, a performance drift, stays text in
/// the migration; the core now says it typed).
fn ends_with_core(head: &[Event], core: &[Event]) -> bool {
    let same = |logged: &Event, ours: &Event| {
        logged == ours || matches!(logged, Event::Other(text) if ours == text.as_str())
    };
    head.len() >= core.len()
        && (head[head.len() - core.len()..].iter())
            .zip(core)
            .all(|(l, c)| same(l, c))
}

/// The first of `fields` whose JSON differs between the logged line and the replayed record:
/// (path of the first differing value, logged, replayed).
fn first_difference(
    fields: &[&str],
    logged: &Value,
    replayed: &Value,
) -> Option<(String, String, String)> {
    fields.iter().find_map(|f| {
        let a = logged.get(*f).unwrap_or(&Value::Null);
        let b = replayed.get(*f).unwrap_or(&Value::Null);
        diff_value(f, a, b)
    })
}

/// Descend to the first differing value. Values are compared by their JSON text, so `0.0` and
/// `-0.0` differ, and every float must be bit-equal to print the same.
fn diff_value(path: &str, a: &Value, b: &Value) -> Option<(String, String, String)> {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let keys: std::collections::BTreeSet<&String> = x.keys().chain(y.keys()).collect();
            keys.into_iter().find_map(|k| {
                let p = format!("{path}.{k}");
                match (x.get(k), y.get(k)) {
                    (Some(u), Some(v)) => diff_value(&p, u, v),
                    (u, v) => Some((p, opt_json(u), opt_json(v))),
                }
            })
        }
        (Value::Array(x), Value::Array(y)) => {
            let n = x.len().max(y.len());
            (0..n).find_map(|i| {
                let p = format!("{path}[{i}]");
                match (x.get(i), y.get(i)) {
                    (Some(u), Some(v)) => diff_value(&p, u, v),
                    (u, v) => Some((p, opt_json(u), opt_json(v))),
                }
            })
        }
        _ => {
            let (sa, sb) = (json(a), json(b));
            (sa != sb).then(|| (path.to_string(), sa, sb))
        }
    }
}

fn json<T: serde::Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_else(|e| format!("(unprintable: {e})"))
}

fn opt_json(v: Option<&Value>) -> String {
    v.map_or_else(|| "(absent)".to_string(), json)
}

fn logged_cycle(value: &Value) -> u64 {
    value.get("cycle").and_then(Value::as_u64).unwrap_or(0)
}

/// The params set the header embeds, under a virtual directory named after the log. A file
/// logged only by its hash (too large or not UTF-8) is kept as unreadable: the model load fails
/// naming it if the model needs it.
fn params_files(header: &Header, file: &Path) -> Result<ParamsFiles, Refusal> {
    let dir = file.with_file_name("<header params>");
    let mut files = ParamsFiles::new(&dir);
    for (rel, text) in &header.params {
        let rel_path = Path::new(rel);
        if rel_path.is_absolute()
            || rel_path
                .components()
                .any(|c| !matches!(c, std::path::Component::Normal(_)))
        {
            return Err(refuse(
                file,
                Some(1),
                format!("params entry `{rel}` is not a relative file name"),
            ));
        }
        if is_hashed(text) {
            files.insert_unreadable(
                dir.join(rel),
                format!("the log header holds only its hash ({text}), not its text"),
            );
        } else {
            files.insert(dir.join(rel), text.as_str());
        }
    }
    Ok(files)
}

/// `fnv1a64:<16 hex> (<n> bytes)`, the header's stand-in for a file it does not inline.
fn is_hashed(text: &str) -> bool {
    text.strip_prefix("fnv1a64:").is_some_and(|rest| {
        rest.len() > 16
            && rest[..16].bytes().all(|b| b.is_ascii_hexdigit())
            && rest[16..].starts_with(" (")
            && rest.ends_with(" bytes)")
    })
}

/// The subcommand in a logged command line.
fn source_of(command: &str) -> Option<Source> {
    command.split_whitespace().skip(1).find_map(|w| match w {
        "simulate" => Some(Source::Simulate),
        "fly" => Some(Source::Fly),
        _ => None,
    })
}

/// The logged command learned CPT rows in flight (`--learn-cpt`).
fn learns_cpt(command: &str) -> bool {
    command.split_whitespace().any(|w| w == "--learn-cpt")
}

/// The model kind `simulate` logged: the first of `--model a,b` (default `bfm`).
fn simulate_model(command: &str) -> &str {
    let words: Vec<&str> = command.split_whitespace().collect();
    let mut found = None;
    for (i, w) in words.iter().enumerate() {
        if *w == "--model" {
            found = words.get(i + 1).copied();
        } else if let Some(v) = w.strip_prefix("--model=") {
            found = Some(v);
        }
    }
    found
        .and_then(|m| m.split(',').next())
        .map_or("bfm", str::trim)
}

/// `companion replay`: print the outcome; the process exit code (0 all equal, 1 a cycle differs,
/// 2 cannot replay).
pub fn run_cli(path: &Path) -> i32 {
    match replay(path) {
        Ok(Outcome::AllEqual { cycles, truncated }) => {
            if let Some((file, line)) = truncated {
                eprintln!(
                    "replay: {}:{line}: last line cut off (the process was killed while writing it): not replayed",
                    file.display()
                );
            }
            println!("replay: all {cycles} cycles equal");
            0
        }
        Ok(Outcome::Differs(d)) => {
            println!("replay: {d}");
            1
        }
        Err(r) => {
            eprintln!("replay: cannot replay: {r}");
            2
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: &[&str]) -> Vec<Event> {
        v.iter()
            .map(|x| crate::decision_log::migration::event(x))
            .collect()
    }

    #[test]
    fn split_events_finds_the_core_added_tail_after_the_observed_ones() {
        let logged = s(&["mode GUIDED", "navigation: state `x` unknown to this MDP"]);
        let core = s(&["navigation: state `x` unknown to this MDP"]);
        let (o, c, sh) = split_events(&logged, &core, Source::Simulate).unwrap();
        assert_eq!((o, c, sh.len()), (&logged[..1], &logged[1..], 0));
        // The core added something the log does not end with: not this core's record.
        assert!(split_events(&logged, &s(&["health: x"]), Source::Simulate).is_none());
        // A core that added nothing fits any observed list.
        assert_eq!(
            split_events(&logged, &[], Source::Simulate).unwrap().0,
            &logged[..]
        );
    }

    #[test]
    fn split_events_puts_fly_shell_events_after_the_core_ones() {
        let logged = s(&[
            "mode AUTO",
            "guarantee: no allocation meets the goals",
            "mission over: land",
            "landing: land again (the landing was interrupted or not done)",
        ]);
        let core = s(&["guarantee: no allocation meets the goals"]);
        let (o, c, sh) = split_events(&logged, &core, Source::Fly).unwrap();
        assert_eq!(o, &logged[..1]);
        assert_eq!(c, &logged[1..2]);
        assert_eq!(sh, &logged[2..]);
        // In a simulate log nothing comes after the core's events.
        assert!(split_events(&logged, &core, Source::Simulate).is_none());
    }

    #[test]
    fn the_model_of_a_simulate_command_is_its_first_model() {
        assert_eq!(simulate_model("companion simulate --scenario x"), "bfm");
        assert_eq!(
            simulate_model("c simulate --model reference,bfm --runs 3"),
            "reference"
        );
        assert_eq!(
            simulate_model("c simulate --model=monolithic"),
            "monolithic"
        );
        assert_eq!(
            source_of("/a/companion --log-level info simulate"),
            Some(Source::Simulate)
        );
        assert_eq!(
            source_of("companion fly --connect tcp:x"),
            Some(Source::Fly)
        );
        assert_eq!(source_of("companion review x"), None);
    }

    #[test]
    fn a_hashed_params_entry_is_told_from_file_text() {
        assert!(is_hashed("fnv1a64:0123456789abcdef (70000 bytes)"));
        assert!(!is_hashed("fnv1a64 is a hash\n"));
        assert!(!is_hashed("name = 'fnv1a64:'"));
    }

    #[test]
    fn the_first_difference_names_the_deepest_differing_value() {
        let a = serde_json::json!({"probabilities": {"P_a": 0.5, "P_b": 0.25}, "actions": ["x"]});
        let b = serde_json::json!({"probabilities": {"P_a": 0.5, "P_b": 0.5}, "actions": ["x"]});
        let d = first_difference(&["actions", "probabilities"], &a, &b).unwrap();
        assert_eq!(d, ("probabilities.P_b".into(), "0.25".into(), "0.5".into()));
        let z = serde_json::json!({"v": -0.0});
        let p = serde_json::json!({"v": 0.0});
        assert!(
            first_difference(&["v"], &z, &p).is_some(),
            "-0.0 is not 0.0"
        );
        assert!(first_difference(&["actions"], &a, &b).is_none());
    }
}
