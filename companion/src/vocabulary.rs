//! The observation and action vocabularies across every params file and both shells: who
//! produces each observation (the simulated world, its scenarios, fly's telemetry and onboard
//! monitors, the decision core) and who reads it (a health manager's node, a mission.toml
//! projection, rate or failure, the core's platform model, the world), and which MDPs propose
//! each action and how fly maps it. `Params::load` refuses a name with no producer or no
//! consumer ([`check`]); `companion check --json` lists both under `observations` and `actions`.
//!
//! The core checks what it sees alone (an observation's node, MDP actions against
//! params/actions.toml); the checks needing a shell's producers live here, because the core must
//! not depend on the shells.

use crate::world_spec::WorldSpec;
use crate::world_spec::{Scenario, WORLD_OBSERVATIONS};
use companion_core::decision::Model;
use companion_core::evidence::{CORE_COMPUTES, CORE_READS};
use companion_core::guarantee::PACK_OBSERVATIONS;
use companion_core::named_slots::{SortedNames, sorted_names};
use companion_core::spec::{ParamsFiles, SpecError};
use companion_core::vocabulary::NamedAction;
use companion_link::actions::{ActionTable, Flown, LinkParams};
use companion_link::telemetry::{LINK_READS, TELEMETRY_OBSERVATIONS};
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What the vocabulary is checked across: the loaded params files (`Params::vocabulary`).
#[derive(Clone, Copy)]
pub struct Sources<'a> {
    /// The params directory (files are named under it in errors).
    pub dir: &'a Path,
    /// The files as read.
    pub files: &'a ParamsFiles,
    /// The decision core's model.
    pub model: &'a Model,
    /// The simulated world.
    pub world: &'a WorldSpec,
    /// The MAVLink link settings.
    pub link: &'a LinkParams,
    /// Vehicle actions as MAVLink steps.
    pub commands: &'a ActionTable,
}

/// The observations the fly shell derives and adds to the telemetry's
/// (`fly::cycle::complete_observations`): here, with the rest of the vocabulary, so the shell
/// reads the list and the vocabulary check imports nothing of the shell.
pub const DERIVED_OBSERVATIONS: [&str; 3] = [
    "drone_speed_mps",
    "waypoints_remaining",
    companion_core::evidence::ROUTE_ACTIVITY,
];
/// One producer or consumer of an observation.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub struct Role {
    /// Producers: `world` (params/world.toml baseline, or the world's own bookkeeping),
    /// `scenario` (a hazard's `set`), `fly_telemetry` (the autopilot's messages), `fly_onboard`
    /// (a NAMED_VALUE_FLOAT of params/link.toml `[telemetry.onboard]`), `fly` (derived by the fly
    /// shell), `core` (the decision core's platform model). Consumers: `health` (a manager with
    /// the node), `projection` (params/mission.toml, per MDP), `rate` (mission.toml `rates`, per
    /// application), `failure` (mission.toml `guarantee.failures`, per resource), `core`, `world`.
    pub kind: &'static str,
    /// Which one: the manager, MDP, application, resource, scenario or source.
    pub name: String,
}

/// One observation of the vocabulary: a name something reads.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct NamedObservation {
    /// Observation name (`vibration_mps2`).
    pub name: String,
    /// The BN node it gives evidence to (params/observations.toml), if any.
    pub node: Option<String>,
    /// Who produces it.
    pub producers: Vec<Role>,
    /// Who reads it.
    pub consumers: Vec<Role>,
}

fn role(kind: &'static str, name: impl Into<String>) -> Role {
    Role {
        kind,
        name: name.into(),
    }
}

/// Every scenario file of the params set (params/scenarios/*.toml), loaded, with its file.
fn scenarios(p: &Sources) -> Result<Vec<(PathBuf, Scenario)>, SpecError> {
    let dir = p.dir.join("scenarios");
    p.files
        .files_in(&dir, "toml")
        .into_iter()
        .map(|f| {
            let s = Scenario::load(p.files, &f.display().to_string())?;
            Ok((f, s))
        })
        .collect()
}

/// Consumers of every name something reads, by name.
fn consumers(p: &Sources) -> BTreeMap<String, Vec<Role>> {
    let mut out: BTreeMap<String, Vec<Role>> = BTreeMap::new();
    let mut add = |name: &str, r: Role| {
        let v = out.entry(name.to_string()).or_default();
        if !v.contains(&r) {
            v.push(r);
        }
    };
    let health = &p.model.health;
    for o in &health.observations.observations {
        for m in &health.managers {
            if m.nodes.iter().any(|n| n.name == o.node) {
                add(&o.name, role("health", &m.name));
            }
        }
    }
    let mission = &p.model.mission;
    for (mdp, rules) in &mission.projection {
        for r in rules {
            if let Some(o) = &r.observation {
                add(o, role("projection", mdp));
            }
        }
    }
    for (app, o) in &mission.rates {
        add(o, role("rate", app));
    }
    for (resource, o) in &mission.guarantee.failures {
        add(o, role("failure", resource));
    }
    for o in CORE_READS {
        add(o, role("core", "platform model"));
    }
    for (o, what) in WORLD_OBSERVATIONS {
        if what == "reads" {
            add(o, role("world", "simulated world"));
        }
    }
    for (ctx, rule) in &p.world.truth.contexts {
        add(
            &rule.observation,
            role("world", format!("truth.contexts.{ctx}")),
        );
    }
    out
}

/// Producers of every name something produces, by name.
fn producers(p: &Sources, scenarios: &[(PathBuf, Scenario)]) -> BTreeMap<String, Vec<Role>> {
    let mut out: BTreeMap<String, Vec<Role>> = BTreeMap::new();
    let mut add = |name: &str, r: Role| {
        let v = out.entry(name.to_string()).or_default();
        if !v.contains(&r) {
            v.push(r);
        }
    };
    for o in p.world.baseline.keys() {
        add(o, role("world", "world.toml baseline"));
    }
    for (o, what) in WORLD_OBSERVATIONS {
        if what == "computes" {
            add(o, role("world", "simulated world"));
        }
    }
    for (_, s) in scenarios {
        for h in &s.hazards {
            for o in h.set.keys() {
                add(o, role("scenario", &s.name));
            }
        }
    }
    for o in TELEMETRY_OBSERVATIONS {
        add(o, role("fly_telemetry", "autopilot"));
    }
    for (nvf, o) in &p.link.telemetry.onboard {
        add(o, role("fly_onboard", nvf));
    }
    for o in DERIVED_OBSERVATIONS {
        add(o, role("fly", "derived"));
    }
    for o in CORE_COMPUTES {
        add(o, role("core", "platform model"));
    }
    for (o, _) in p.model.health.fit_observations() {
        add(o, role("core", "scheduler admission"));
    }
    out
}

/// Every name something reads, sorted, with its node, producers and consumers.
pub fn named_observations(p: &Sources) -> Result<Vec<NamedObservation>, SpecError> {
    let scenarios = scenarios(p)?;
    let producers = producers(p, &scenarios);
    Ok(consumers(p)
        .into_iter()
        .map(|(name, consumers)| NamedObservation {
            node: p
                .model
                .health
                .observations
                .get(&name)
                .map(|o| o.node.clone()),
            producers: producers.get(&name).cloned().unwrap_or_default(),
            name,
            consumers,
        })
        .collect())
}

/// Refuse a world baseline or scenario hazard that sets a name nothing reads, and an observation
/// of params/observations.toml that neither the world, its scenarios, fly nor the core produces.
pub fn check_observations(p: &Sources) -> Result<(), SpecError> {
    let scenarios = scenarios(p)?;
    let consumers = consumers(p);
    let unread = |o: &str| {
        format!(
            "`{o}` is an observation nothing reads: not in params/observations.toml, not in \
             params/mission.toml (projection, rates, guarantee.failures), not read by the decision \
             core ({}) or the world ({})",
            CORE_READS.join(", "),
            WORLD_OBSERVATIONS
                .iter()
                .filter(|(_, w)| *w == "reads")
                .map(|(o, _)| *o)
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    for o in p.world.baseline.keys() {
        if !consumers.contains_key(o) {
            return Err(SpecError::new(
                p.dir.join("world.toml"),
                format!("baseline.{o}"),
                unread(o),
            ));
        }
    }
    for (file, s) in &scenarios {
        for (i, h) in s.hazards.iter().enumerate() {
            for o in h.set.keys() {
                if !consumers.contains_key(o) {
                    return Err(SpecError::new(
                        file,
                        format!("hazard[{i}].set.{o}"),
                        unread(o),
                    ));
                }
            }
        }
    }
    let producers = producers(p, &scenarios);
    // What params/mission.toml reads (projections, rates, failures) must come from somewhere.
    for (name, readers) in &consumers {
        let from_mission = readers
            .iter()
            .find(|r| matches!(r.kind, "projection" | "rate" | "failure"));
        if let Some(r) = from_mission
            && !producers.contains_key(name)
        {
            let entry = match r.kind {
                "failure" => format!("guarantee.failures.{}", r.name),
                "rate" => format!("rates.{}", r.name),
                _ => format!("projection.{}", r.name),
            };
            return Err(SpecError::new(
                p.dir.join("mission.toml"),
                entry,
                format!(
                    "`{name}` is produced by nothing: not the simulated world, a scenario, fly                      (telemetry, params/link.toml [telemetry.onboard], derived) or the core"
                ),
            ));
        }
    }
    let obs = &p.model.health.observations;
    for (i, o) in obs.observations.iter().enumerate() {
        if !producers.contains_key(&o.name) {
            return Err(SpecError::new(
                &obs.file,
                format!("observation[{i}]({})", o.name),
                "nothing produces it: not the simulated world (params/world.toml baseline, its \
                 own bookkeeping, a scenario's `set`), not fly (the autopilot's telemetry, \
                 params/link.toml [telemetry.onboard], its derived values), not the decision core",
            ));
        }
    }
    Ok(())
}

/// One primitive action with the MDPs that propose it and how fly maps it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ActionEntry {
    /// The action, its application and the MDPs proposing it (the core's view).
    #[serde(flatten)]
    pub action: NamedAction,
    /// Whether params/commands.toml maps it to MAVLink steps (every vehicle action must).
    pub vehicle_steps: bool,
    /// The shell-only params/commands.toml entries flown in its place (`flown_for`).
    pub flown_as: Vec<String>,
}

/// Every primitive action, in params/actions.toml order.
pub fn actions(p: &Sources) -> Vec<ActionEntry> {
    companion_core::vocabulary::named_actions(&p.model.actions, &p.model.mdps)
        .into_iter()
        .map(|a| {
            let id = p.model.actions.id(&a.name);
            ActionEntry {
                vehicle_steps: id.is_some_and(|id| p.commands.steps(Flown::Action(id)).is_some()),
                flown_as: id
                    .and_then(|id| p.commands.in_place_of(id))
                    .map(|f| p.commands.name(f).to_string())
                    .into_iter()
                    .collect(),
                action: a,
            }
        })
        .collect()
}

/// The vocabulary's load check (the commands' entries are checked against the action catalogue
/// when params/commands.toml loads: `ActionTable::load`).
pub fn check(p: &Sources) -> Result<(), SpecError> {
    Vocabulary::compile(p, &CodeLists::SHIPPED).map(|_| ())
}

/// The observation names written into the code of the link and the core, beside the params':
/// what fly's telemetry writes and what the guarantee reads of the pack (a test renames one).
#[derive(Clone, Copy)]
pub struct CodeLists<'a> {
    /// companion-link's `TELEMETRY_OBSERVATIONS` (kept equal to what the telemetry writes by its
    /// test).
    pub telemetry_writes: &'a [&'a str],
    /// companion-core's `PACK_OBSERVATIONS`.
    pub pack_reads: &'a [&'a str],
}

impl CodeLists<'static> {
    /// The lists of this build.
    pub const SHIPPED: CodeLists<'static> = CodeLists {
        telemetry_writes: &TELEMETRY_OBSERVATIONS,
        pack_reads: &PACK_OBSERVATIONS,
    };
}

/// The observation vocabulary, compiled once at load: every name a producer of the params and
/// the shells writes or a consumer reads, sorted. The link's telemetry and the simulated world
/// write their snapshots by its slots and the core reads them by the same slots (one `Arc`,
/// `Params::load` hands it to both), so a snapshot copies no name; a name outside it (an onboard
/// monitor's that params do not declare) goes to the snapshot's overflow.
#[derive(Debug, Clone)]
pub struct Vocabulary {
    /// The names, sorted.
    pub names: SortedNames,
}

impl Vocabulary {
    /// Check the producers and consumers across the params, the shells and `code`, and compile
    /// the names; a name one side writes and the other does not read (or reads and nothing
    /// writes) stops the load naming both places.
    pub fn compile(p: &Sources, code: &CodeLists) -> Result<Self, SpecError> {
        check_observations(p)?;
        let consumers = consumers(p);
        check_link_writes(p, &consumers)?;
        check_pack_written(code.telemetry_writes, code.pack_reads)?;
        let scenarios = scenarios(p)?;
        let producers = producers(p, &scenarios);
        let code_names = (code.telemetry_writes.iter().chain(code.pack_reads))
            .chain(&LINK_READS)
            .map(|o| o.to_string());
        let names = sorted_names(
            (consumers.into_keys())
                .chain(producers.into_keys())
                .chain(code_names)
                .chain(p.link.telemetry.recorded_only.iter().cloned()),
        );
        Ok(Vocabulary { names })
    }
}

/// Refuse an onboard monitor's observation (params/link.toml `[telemetry.onboard]`) that nothing
/// of fly reads: one side renamed, the frame would give evidence to nothing, even where the
/// simulated world still produces the old name (so `check_observations` finds a producer).
pub fn check_link_writes(
    p: &Sources,
    consumers: &BTreeMap<String, Vec<Role>>,
) -> Result<(), SpecError> {
    let t = &p.link.telemetry;
    for (i, o) in t.recorded_only.iter().enumerate() {
        if !t.onboard.values().any(|m| m == o) {
            return Err(SpecError::new(
                p.dir.join("link.toml"),
                format!("telemetry.recorded_only[{i}]"),
                format!("`{o}` is no observation of [telemetry.onboard]"),
            ));
        }
    }
    for (nvf, o) in &t.onboard {
        if !consumers.contains_key(o)
            && !LINK_READS.contains(&o.as_str())
            && !t.recorded_only.contains(o)
        {
            return Err(SpecError::new(
                p.dir.join("link.toml"),
                format!("telemetry.onboard.{nvf}"),
                format!(
                    "`{o}` is written by the link and nothing reads it: not params/observations.toml, \
                     not params/mission.toml (projection, rates, guarantee.failures), not the decision \
                     core ({}), not the link's own steps ({}), not [telemetry] recorded_only",
                    CORE_READS.join(", "),
                    LINK_READS.join(", ")
                ),
            ));
        }
    }
    Ok(())
}

/// Refuse a build whose guarantee reads a pack observation fly's telemetry does not write
/// (`writes`: companion-link's `TELEMETRY_OBSERVATIONS`, kept equal to what the telemetry writes
/// by its test; `pack`: companion-core's `PACK_OBSERVATIONS`): renamed on one side only, the
/// energy goal would silently fall back to the params' pack in flight.
pub fn check_pack_written(writes: &[&str], pack: &[&str]) -> Result<(), SpecError> {
    match pack.iter().position(|o| !writes.contains(o)) {
        None => Ok(()),
        Some(i) => Err(SpecError::new(
            "companion-core/src/guarantee.rs",
            format!("PACK_OBSERVATIONS[{i}]({})", pack[i]),
            format!(
                "the guarantee reads the pack's `{}` and fly's telemetry writes no such observation \
                 (companion-link/src/telemetry.rs TELEMETRY_OBSERVATIONS): one side was renamed",
                pack[i]
            ),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_pack_is_written_by_the_telemetry() {
        assert_eq!(
            check_pack_written(&TELEMETRY_OBSERVATIONS, &PACK_OBSERVATIONS),
            Ok(())
        );
    }
    // Renamed on one side only: companion/tests/vocabulary.rs, through `Vocabulary::compile`.
}
