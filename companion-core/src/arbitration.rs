//! The arbitration stage (design: behaviour arbitration, then resource arbitration): the MDPs'
//! merged actions lose the antagonistic ones their policy ranks lower (BFM section 6.2), then
//! the application actions are scheduled on the platform (fpga_model) and rewritten to what
//! actually runs.

use crate::decision::{Model, Scratch};
use crate::mission::{ActionKind, Policy};
use crate::mission_mdp::InstantiateError;
use crate::observations::Observations;
use crate::record::{Conflict, DecisionRecord, Event, ResourcesRecord};
use crate::resources::ResourceSpec;
use crate::spec::{ParamsFiles, SpecError, read_toml};
use fpga_model::{Implementation, PlatformState, Request};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

fn err(path: &Path, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(path, entry, reason)
}

// ---------------------------------------------------------------- behaviour conflicts

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PoliciesFile {
    #[serde(default)]
    #[allow(dead_code)]
    source: Option<String>,
    antagonistic: Vec<RuleSpec>,
    /// Policy -> primitive-action patterns, highest priority first.
    priority: BTreeMap<String, Vec<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RuleSpec {
    name: String,
    a: Vec<String>,
    b: Vec<String>,
    #[serde(default)]
    #[allow(dead_code)]
    source: Option<String>,
}

#[derive(Debug, Clone)]
struct Rule {
    name: String,
    groups: [Vec<String>; 2],
}

/// Antagonistic primitive actions (BFM section 6.2) and each policy's priority order.
/// Patterns are primitive action names, or a prefix followed by `*` (`track_v*`).
#[derive(Debug, Clone)]
pub struct BehaviourConflicts {
    rules: Vec<Rule>,
    priority: BTreeMap<String, Vec<String>>,
}

fn pattern_matches(pattern: &str, action: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some(prefix) => action.starts_with(prefix),
        None => pattern == action,
    }
}

impl BehaviourConflicts {
    /// Load `params/policies.toml`. `known_actions` are the primitive actions (e.g.
    /// [`crate::mission_mdp::MissionMdps::primitive_actions`]); every pattern must match at least one.
    pub fn load(
        params: &ParamsFiles,
        path: &Path,
        known_actions: &[&str],
    ) -> Result<Self, SpecError> {
        let f: PoliciesFile = read_toml(params, path)?;
        if f.priority.is_empty() {
            return Err(err(path, "priority", "no policy"));
        }
        let check_pattern = |entry: String, p: &str| -> Result<(), SpecError> {
            if known_actions.iter().any(|a| pattern_matches(p, a)) {
                Ok(())
            } else {
                Err(err(
                    path,
                    entry,
                    format!("'{p}' matches no known primitive action"),
                ))
            }
        };
        let mut rules = Vec::new();
        for (i, r) in f.antagonistic.iter().enumerate() {
            if f.antagonistic[..i].iter().any(|q| q.name == r.name) {
                return Err(err(
                    path,
                    format!("antagonistic[{i}].name"),
                    format!("rule '{}' given twice", r.name),
                ));
            }
            for (g, group) in [("a", &r.a), ("b", &r.b)] {
                if group.is_empty() {
                    return Err(err(path, format!("antagonistic[{i}].{g}"), "empty group"));
                }
                for (j, p) in group.iter().enumerate() {
                    check_pattern(format!("antagonistic[{i}].{g}[{j}]"), p)?;
                    for (pol, order) in &f.priority {
                        if !order.contains(p) {
                            return Err(err(
                                path,
                                format!("priority.{pol}"),
                                format!("'{p}' (rule '{}') not ranked", r.name),
                            ));
                        }
                    }
                }
            }
            if r.a.iter().any(|p| r.b.contains(p)) {
                return Err(err(
                    path,
                    format!("antagonistic[{i}]"),
                    "a pattern is in both groups",
                ));
            }
            rules.push(Rule {
                name: r.name.clone(),
                groups: [r.a.clone(), r.b.clone()],
            });
        }
        for (pol, order) in &f.priority {
            for (j, p) in order.iter().enumerate() {
                check_pattern(format!("priority.{pol}[{j}]"), p)?;
                if order[..j].contains(p) {
                    return Err(err(
                        path,
                        format!("priority.{pol}[{j}]"),
                        format!("'{p}' ranked twice"),
                    ));
                }
            }
        }
        Ok(Self {
            rules,
            priority: f.priority,
        })
    }

    /// Names of the policies params/policies.toml ranks actions for.
    pub fn policies(&self) -> impl Iterator<Item = &str> {
        self.priority.keys().map(String::as_str)
    }

    /// Apply every antagonistic rule in file order: when actions of both groups are present,
    /// the group holding the higher-ranked pattern (under `policy`) keeps its actions and the
    /// other group's actions are dropped. Returns the kept actions (input order) and one
    /// [`Conflict`] per rule that fired.
    pub fn resolve<S: AsRef<str>>(
        &self,
        actions: &[S],
        policy: &str,
    ) -> Result<(Vec<String>, Vec<Conflict>), InstantiateError> {
        let actions: Vec<&str> = actions.iter().map(AsRef::as_ref).collect();
        let mut kept = Vec::new();
        let mut conflicts = Vec::new();
        self.resolve_into(&actions, policy, &mut kept, &mut conflicts)?;
        Ok((kept.into_iter().map(str::to_string).collect(), conflicts))
    }

    /// As [`BehaviourConflicts::resolve`] into reused buffers: `kept` is overwritten, and
    /// `conflicts` is rewritten entry by entry (no allocation once its strings have grown).
    pub fn resolve_into<'a>(
        &self,
        actions: &[&'a str],
        policy: &str,
        kept: &mut Vec<&'a str>,
        conflicts: &mut Vec<Conflict>,
    ) -> Result<(), InstantiateError> {
        let order = self
            .priority
            .get(policy)
            .ok_or_else(|| InstantiateError::UnknownPolicy(policy.to_string()))?;
        kept.clear();
        kept.extend_from_slice(actions);
        let rank = |group: &[String]| {
            group
                .iter()
                .filter_map(|p| order.iter().position(|q| q == p))
                .min()
        };
        let mut fired = 0;
        for rule in &self.rules {
            let in_group = |g: usize, a: &str| rule.groups[g].iter().any(|p| pattern_matches(p, a));
            let present = |g: usize| kept.iter().any(|a| in_group(g, a));
            if !present(0) || !present(1) {
                continue;
            }
            let a_wins = rank(&rule.groups[0]) <= rank(&rule.groups[1]);
            let (win, lose) = if a_wins { (0, 1) } else { (1, 0) };
            if fired == conflicts.len() {
                conflicts.push(Conflict::default());
            }
            let c = &mut conflicts[fired];
            fired += 1;
            c.kept.clear();
            for (i, a) in kept.iter().filter(|a| in_group(win, a)).enumerate() {
                if i > 0 {
                    c.kept.push('+');
                }
                c.kept.push_str(a);
            }
            let mut n = 0;
            for a in kept.iter().filter(|a| in_group(lose, a)) {
                if n == c.dropped.len() {
                    c.dropped.push(String::new());
                }
                c.dropped[n].clear();
                c.dropped[n].push_str(a);
                n += 1;
            }
            c.dropped.truncate(n);
            c.rule.clone_from(&rule.name);
            kept.retain(|a| !in_group(lose, a));
        }
        conflicts.truncate(fired);
        Ok(())
    }

    /// The original list-building form, kept as the reference `resolve_into` is tested against.
    #[cfg(test)]
    pub(crate) fn resolve_reference<S: AsRef<str>>(
        &self,
        actions: &[S],
        policy: &str,
    ) -> Result<(Vec<String>, Vec<Conflict>), InstantiateError> {
        let order = self
            .priority
            .get(policy)
            .ok_or_else(|| InstantiateError::UnknownPolicy(policy.to_string()))?;
        let mut kept: Vec<String> = actions.iter().map(|a| a.as_ref().to_string()).collect();
        let mut conflicts = Vec::new();
        let rank = |group: &[String]| {
            group
                .iter()
                .filter_map(|p| order.iter().position(|q| q == p))
                .min()
        };
        for rule in &self.rules {
            let present = |g: &[String]| -> Vec<String> {
                kept.iter()
                    .filter(|a| g.iter().any(|p| pattern_matches(p, a)))
                    .cloned()
                    .collect()
            };
            let (in_a, in_b) = (present(&rule.groups[0]), present(&rule.groups[1]));
            if in_a.is_empty() || in_b.is_empty() {
                continue;
            }
            let a_wins = rank(&rule.groups[0]) <= rank(&rule.groups[1]);
            let (win, lose) = if a_wins { (in_a, in_b) } else { (in_b, in_a) };
            kept.retain(|a| !lose.contains(a));
            conflicts.push(Conflict {
                kept: win.join("+"),
                dropped: lose,
                rule: rule.name.clone(),
            });
        }
        Ok((kept, conflicts))
    }
}

// ---------------------------------------------------------------- resource arbitration

/// How many distinct recent schedules are remembered: alternating between two action sets
/// (a vibration on/off stream) cycles through a few (state before, requests) pairs.
const SCHEDULE_MEMO: usize = 8;

/// One memoised scheduling decision: `fpga_model::schedule` is a pure function of the policy
/// (fixed per core), the platform state before it and the requests, so the same inputs give
/// the same record and the same platform state after.
#[derive(Default)]
struct ScheduleMemo<'m> {
    before: PlatformState,
    /// One [`RequestKey`] per request, in request order.
    key: Vec<RequestKey<'m>>,
    after: PlatformState,
    record: ResourcesRecord,
}

/// Recent resource schedules keyed on their exact inputs, with the scheduler's reusable
/// inputs, output and working memory (no allocation once warm).
pub(crate) struct ScheduleCache<'m> {
    memos: Vec<ScheduleMemo<'m>>,
    next: usize,
    enabled: bool,
    runs: u64,
    requests: Vec<Request>,
    ws: fpga_model::ScheduleWorkspace,
    out: fpga_model::Schedule,
}

impl<'m> ScheduleCache<'m> {
    pub(crate) fn new() -> Self {
        ScheduleCache {
            memos: Vec::new(),
            next: 0,
            enabled: true,
            runs: 0,
            requests: Vec::new(),
            ws: fpga_model::ScheduleWorkspace::new(),
            out: fpga_model::Schedule::default(),
        }
    }

    /// Off, every lookup runs the scheduler (into one reused slot).
    pub(crate) fn set_enabled(&mut self, on: bool) {
        self.enabled = on;
        self.memos.clear();
    }

    /// Scheduler runs so far (memo misses).
    pub(crate) fn runs(&self) -> u64 {
        self.runs
    }

    /// The schedule of the requests `key` from `platform` under `policy`: remembered, or run and
    /// remembered. Fails when the policy is unknown.
    fn schedule(
        &mut self,
        resources: &ResourceSpec,
        policy: &str,
        platform: &PlatformState,
        key: &[RequestKey<'m>],
    ) -> Result<&ScheduleMemo<'m>, SpecError> {
        let hit = self.enabled.then(|| {
            self.memos
                .iter()
                .position(|m| m.key == key && same_platform(&m.before, platform))
        });
        let i = match hit.flatten() {
            Some(i) => i,
            None => self.run(resources, policy, platform, key)?,
        };
        Ok(&self.memos[i])
    }

    /// Run the scheduler into a memo slot; returns the slot.
    fn run(
        &mut self,
        resources: &ResourceSpec,
        policy: &str,
        platform: &PlatformState,
        key: &[RequestKey<'m>],
    ) -> Result<usize, SpecError> {
        self.runs += 1;
        resources.policy(policy)?;
        fill_requests(&mut self.requests, key);
        // The memo slot is rewritten in place (its buffers kept): with the memos off,
        // the one slot every cycle, so a scheduler run allocates nothing once warm.
        if !self.enabled {
            self.memos.truncate(1);
        }
        let slots = if self.enabled { SCHEDULE_MEMO } else { 1 };
        let slot = if self.memos.len() < slots {
            self.memos.push(ScheduleMemo::default());
            self.memos.len() - 1
        } else if self.enabled {
            let i = self.next;
            self.next = (i + 1) % SCHEDULE_MEMO;
            i
        } else {
            0
        };
        let m = &mut self.memos[slot];
        let ok = resources.schedule_into(
            policy,
            platform,
            &self.requests,
            &mut self.ws,
            &mut self.out,
            &mut m.after,
        );
        debug_assert!(ok.is_ok(), "the policy was looked up above");
        copy_platform(&mut m.before, platform);
        m.key.clear();
        m.key.extend_from_slice(key);
        crate::resources::to_record_into(&self.out, &mut m.record);
        Ok(slot)
    }
}

/// `dst = src.clone()` for a platform state, keeping the tiles' bitstream strings.
fn copy_platform(dst: &mut PlatformState, src: &PlatformState) {
    dst.tiles.truncate(src.tiles.len());
    for (i, t) in src.tiles.iter().enumerate() {
        match dst.tiles.get_mut(i) {
            Some(d) => {
                d.bitstream.clone_from(&t.bitstream);
                d.failed = t.failed;
            }
            None => dst.tiles.push(t.clone()),
        }
    }
    dst.cores_online = src.cores_online;
    dst.external_cpu_load = src.external_cpu_load;
}

/// One resource request as the schedule memo keys it: app, version, the implementation the
/// allocation in force plans for it (if any), required fps bits.
pub(crate) type RequestKey<'m> = (&'m str, &'m str, Option<Implementation>, u64);

/// The scheduler's requests for `key`, reusing the strings of the previous cycle's requests.
fn fill_requests(dst: &mut Vec<Request>, key: &[RequestKey<'_>]) {
    dst.truncate(key.len());
    for (i, &(app, version, planned, fps)) in key.iter().enumerate() {
        if i == dst.len() {
            let mut r = Request::new(app, version, f64::from_bits(fps));
            r.implementation = planned;
            dst.push(r);
            continue;
        }
        let r = &mut dst[i];
        r.app.clear();
        r.app.push_str(app);
        r.version.clear();
        r.version.push_str(version);
        r.required_fps = f64::from_bits(fps);
        r.priority = None;
        r.implementation = planned;
    }
}

/// Bit-exact equality (a `-0.0` load is not the `0.0` one: the record would print it).
fn same_platform(a: &PlatformState, b: &PlatformState) -> bool {
    a.tiles == b.tiles
        && a.cores_online == b.cores_online
        && a.external_cpu_load.to_bits() == b.external_cpu_load.to_bits()
}

/// Resource arbitration: the schedules and the degradations in force between cycles.
pub(crate) struct ResourceArbiter<'m> {
    pub(crate) schedules: ScheduleCache<'m>,
    /// Degradations and drops in force after the last cycle.
    last_degraded: Vec<String>,
}

impl<'m> ResourceArbiter<'m> {
    pub(crate) fn new() -> Self {
        ResourceArbiter {
            schedules: ScheduleCache::new(),
            last_degraded: Vec::new(),
        }
    }

    /// Request every application action's variant at the rate the situation needs (in the
    /// implementation `plan` names for it, PANORAMA's IA in force for this activity, when it
    /// meets the rate and fits), schedule them under the policy, and rewrite the action set
    /// (`sc.actions`) with what actually runs.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn arbitrate_resources(
        &mut self,
        model: &'m Model,
        policy: Policy,
        platform: &mut PlatformState,
        sc: &mut Scratch<'m>,
        obs: &Observations,
        plan: Option<&str>,
        rec: &mut DecisionRecord,
    ) {
        request_key(model, sc, obs, plan);
        crate::stage_hook::mark(crate::stage_hook::Stage::Arbitration);
        let scheduled = self.schedules.schedule(
            &model.resources,
            model.policy_name(policy),
            platform,
            &sc.key,
        );
        crate::stage_hook::mark(crate::stage_hook::Stage::Scheduler);
        let m = match scheduled {
            Ok(m) => m,
            Err(e) => {
                rec.events.push(Event::ResourcesError(e.to_string()));
                rec.resources = None;
                sc.actions.clone_from(&sc.kept);
                return;
            }
        };
        copy_platform(platform, &m.after);
        match &mut rec.resources {
            Some(r) => r.clone_from(&m.record),
            None => rec.resources = Some(m.record.clone()),
        }
        rewrite_actions(model, &m.record, sc);
        degradation_events(&mut self.last_degraded, &m.record, rec);
    }
}

/// The implementation an IA name (`gps_vision fusion V4.F`) plans for `version`: `F` for `V4`.
fn planned_implementation(plan: Option<&str>, version: &str) -> Option<Implementation> {
    crate::guarantee::ia_variants(plan?)
        .find(|(v, _)| *v == version)
        .and_then(|(_, imp)| imp.parse().ok())
}

/// The requests (`sc.key`) of the kept application actions and the actions asking for them
/// (`sc.owners`): one variant per application, at the rate the observed speed requires, in the
/// implementation the plan names for that version (if it does).
fn request_key<'m>(model: &'m Model, sc: &mut Scratch<'m>, obs: &Observations, plan: Option<&str>) {
    sc.key.clear();
    sc.owners.clear();
    for &a in &sc.kept {
        let Some(act) = model.actions.get(a) else {
            continue;
        };
        let (Some(app), Some(version)) = (&act.app, &act.version) else {
            continue;
        };
        if sc.key.iter().any(|r| r.0 == app) {
            continue; // one variant per application (target detection shares the tracker)
        }
        let speed = model
            .mission
            .rates
            .get(app.as_str())
            .and_then(|obs_name| obs.get(obs_name))
            .unwrap_or(0.0);
        let fps = model
            .resources
            .required_fps(app, [0.0, 0.0], [speed, 0.0])
            .unwrap_or(1.0);
        let planned = planned_implementation(plan, version);
        sc.key.push((app, version, planned, fps.to_bits()));
        sc.owners.push(a);
    }
}

/// Rewrite: an application action stays only if its app is placed, under the placed version.
fn rewrite_actions<'m>(model: &'m Model, record: &ResourcesRecord, sc: &mut Scratch<'m>) {
    sc.actions.clear();
    for &a in &sc.kept {
        let act = model.actions.get(a);
        match act.and_then(|x| x.app.as_deref()) {
            None => sc.actions.push(a),
            Some(app) => {
                let placed = record.placements.iter().find(|p| p.app == app);
                if let Some(p) = placed {
                    // A degraded variant is named by the action that runs it (track_v3 -> track_v1).
                    let same = act.and_then(|x| x.version.as_deref()) == Some(p.version.as_str());
                    let id = if same || !sc.owners.contains(&a) {
                        a
                    } else {
                        model
                            .actions
                            .for_variant(app, &p.version, &model.states)
                            .map_or(a, |x| x.id.as_str())
                    };
                    if !sc.actions.contains(&id) {
                        sc.actions.push(id);
                    }
                } else if act.is_some_and(|x| x.kind == ActionKind::Vehicle) {
                    sc.actions.push(a);
                }
            }
        }
    }
}

/// Degradations are events when they start, not on every cycle they last.
fn degradation_events(
    last_degraded: &mut Vec<String>,
    record: &ResourcesRecord,
    rec: &mut DecisionRecord,
) {
    let now = || record.degraded.iter().chain(&record.dropped);
    if !now().eq(last_degraded.iter()) {
        for d in now() {
            if !last_degraded.contains(d) {
                rec.events.push(Event::from(d.as_str()));
            }
        }
        *last_degraded = now().cloned().collect();
    }
}
