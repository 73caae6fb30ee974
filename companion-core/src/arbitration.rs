//! The arbitration stage (design: behaviour arbitration, then resource arbitration): the MDPs'
//! merged actions lose the antagonistic ones their policy ranks lower (BFM section 6.2), then
//! the application actions are scheduled on the platform (fpga_model) and rewritten to what
//! actually runs.

pub use crate::conflicts::BehaviourConflicts;
use crate::mission::{ActionCatalogue, ActionKind, Policy};
use crate::model::Model;
use crate::readings::{Readings, Slot};
use crate::record::{DecisionRecord, Degraded, Dropped, Event, ResourcesRecord};
use crate::resources::ResourceSpec;
use crate::scratch::Scratch;
use fpga_model::{Implementation, PlatformState, Request, ResourcePolicy};

// ---------------------------------------------------------------- resource arbitration

/// How many distinct recent schedules are remembered: alternating between two action sets
/// (a vibration on/off stream) cycles through a few (state before, requests) pairs.
const SCHEDULE_MEMO: usize = 8;

/// One memoised scheduling decision: `fpga_model::schedule` is a pure function of the policy
/// (fixed per core), the platform state before it and the requests, so the same inputs give
/// the same record and the same platform state after.
#[derive(Default)]
struct ScheduleMemo {
    before: PlatformState,
    /// One [`RequestKey`] per request, in request order.
    key: Vec<RequestKey>,
    after: PlatformState,
    record: ResourcesRecord,
}

/// Recent resource schedules keyed on their exact inputs, with the scheduler's reusable
/// inputs, output and working memory (no allocation once warm).
pub(crate) struct ScheduleCache {
    memos: Vec<ScheduleMemo>,
    next: usize,
    enabled: bool,
    runs: u64,
    requests: Vec<Request>,
    ws: fpga_model::ScheduleWorkspace,
    out: fpga_model::Schedule,
}

impl ScheduleCache {
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

    /// The schedule of the requests `key` from `platform` under `policy` (fixed per core, so
    /// not in the key): remembered, or run and remembered.
    fn schedule(
        &mut self,
        (resources, actions): (&ResourceSpec, &ActionCatalogue),
        policy: &ResourcePolicy,
        platform: &PlatformState,
        key: &[RequestKey],
    ) -> &ScheduleMemo {
        let hit = self.enabled.then(|| {
            self.memos
                .iter()
                .position(|m| m.key == key && same_platform(&m.before, platform))
        });
        let i = match hit.flatten() {
            Some(i) => i,
            None => self.run((resources, actions), policy, platform, key),
        };
        &self.memos[i]
    }

    /// Run the scheduler into a memo slot; returns the slot.
    fn run(
        &mut self,
        (resources, actions): (&ResourceSpec, &ActionCatalogue),
        policy: &ResourcePolicy,
        platform: &PlatformState,
        key: &[RequestKey],
    ) -> usize {
        self.runs += 1;
        fill_requests(&mut self.requests, actions, key);
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
        resources.schedule_with(
            policy,
            platform,
            &self.requests,
            &mut self.ws,
            &mut self.out,
            &mut m.after,
        );
        copy_platform(&mut m.before, platform);
        m.key.clear();
        m.key.extend_from_slice(key);
        crate::resources::to_record_into(&self.out, &mut m.record);
        slot
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

pub(crate) use crate::scratch::RequestKey;

/// The scheduler's requests for `key`, reusing the strings of the previous cycle's requests.
fn fill_requests(dst: &mut Vec<Request>, actions: &ActionCatalogue, key: &[RequestKey]) {
    dst.truncate(key.len());
    for (i, &(variant, planned, fps)) in key.iter().enumerate() {
        let act = actions.by_id(variant);
        let app = act.app.as_deref().unwrap_or_default();
        let version = act.version.as_deref().unwrap_or_default();
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
pub(crate) struct ResourceArbiter {
    pub(crate) schedules: ScheduleCache,
    /// Degradations and drops in force after the last cycle.
    last_degraded: Vec<Degraded>,
    last_dropped: Vec<Dropped>,
}

impl ResourceArbiter {
    pub(crate) fn new() -> Self {
        ResourceArbiter {
            schedules: ScheduleCache::new(),
            last_degraded: Vec::new(),
            last_dropped: Vec::new(),
        }
    }

    /// Request every application action's variant at the rate the situation needs (in the
    /// implementation `plan` names for it, PANORAMA's IA in force for this activity, when it
    /// meets the rate and fits), schedule them under the policy, and rewrite the action set
    /// (`sc.actions`) with what actually runs.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn arbitrate_resources(
        &mut self,
        model: &Model,
        policy: Policy,
        platform: &mut PlatformState,
        sc: &mut Scratch,
        rates: (&[RequiredRate], &Readings),
        plan: Option<&[PlannedVariant]>,
        rec: &mut DecisionRecord,
    ) {
        request_key(model, sc, rates, plan);
        crate::stage_hook::mark(crate::stage_hook::Stage::Arbitration);
        // The resource policy was resolved when the model loaded (every policy has one).
        let m = self.schedules.schedule(
            (&model.resources, &model.actions),
            model.resource_policy(policy),
            platform,
            &sc.key,
        );
        crate::stage_hook::mark(crate::stage_hook::Stage::Scheduler);
        copy_platform(platform, &m.after);
        match &mut rec.resources {
            Some(r) => r.clone_from(&m.record),
            None => rec.resources = Some(m.record.clone()),
        }
        rewrite_actions(model, &m.record, sc);
        degradation_events(
            (&mut self.last_degraded, &mut self.last_dropped),
            &m.record,
            rec,
        );
    }
}

/// The frame rate an application needs now (section 4.3.2 model: the relative speed from the
/// observation params/mission.toml's `rates` names, the formula from params/platform.toml),
/// resolved once per application: 1 fps when params give it no performance need.
#[derive(Debug, Clone, Default)]
pub(crate) struct RequiredRate {
    speed: Option<Slot>,
    performance: Option<fpga_model::Performance>,
}

impl RequiredRate {
    /// The rate `app` needs (none: no application, 1 fps).
    pub(crate) fn of(model: &Model, app: Option<&str>, readings: &mut Readings) -> Self {
        let Some(app) = app else {
            return Self::default();
        };
        RequiredRate {
            speed: model.mission.rates.get(app).map(|obs| readings.slot(obs)),
            performance: model.resources.platform.performance.get(app).cloned(),
        }
    }

    /// The rate with the speed read this cycle (0 m/s when not observed).
    pub(crate) fn fps(&self, readings: &Readings) -> f64 {
        let speed = self.speed.and_then(|s| readings.get(s)).unwrap_or(0.0);
        self.performance
            .as_ref()
            .map_or(1.0, |p| p.required_fps([0.0, 0.0], [speed, 0.0]))
    }
}

/// One application alternative an IA name carries ([`crate::guarantee::ia_variants`]), parsed
/// once when the core starts: `V4.F` in `gps_vision fusion V4.F`.
#[derive(Debug, Clone)]
pub(crate) struct PlannedVariant {
    /// `V4`.
    pub(crate) version: String,
    /// `F`, as the name writes it.
    pub(crate) implementation: String,
    /// `F` parsed (`None`: not an implementation's name).
    pub(crate) parsed: Option<Implementation>,
    /// The application of the catalogue's first variant of this version (`tracking`).
    pub(crate) app: Option<String>,
}

/// The [`PlannedVariant`]s of an IA name, in the name's order.
pub(crate) fn planned_variants(ia: &str, catalogue: &fpga_model::Catalogue) -> Vec<PlannedVariant> {
    crate::guarantee::ia_variants(ia)
        .map(|(version, imp)| PlannedVariant {
            version: version.to_string(),
            implementation: imp.to_string(),
            parsed: imp.parse().ok(),
            app: (catalogue.variants().iter())
                .find(|v| v.version == version)
                .map(|v| v.app.clone()),
        })
        .collect()
}

/// The implementation the IA in force plans for `version`: `F` for `V4` (the first token
/// naming the version decides, as in the IA's name).
fn planned_implementation(
    plan: Option<&[PlannedVariant]>,
    version: &str,
) -> Option<Implementation> {
    plan?
        .iter()
        .find(|p| p.version == version)
        .and_then(|p| p.parsed)
}

/// The requests (`sc.key`) of the kept application actions and the actions asking for them
/// (`sc.owners`): one variant per application, at the rate the observed speed requires, in the
/// implementation the plan names for that version (if it does).
fn request_key(
    model: &Model,
    sc: &mut Scratch,
    (rates, readings): (&[RequiredRate], &Readings),
    plan: Option<&[PlannedVariant]>,
) {
    sc.key.clear();
    sc.owners.clear();
    let actions = &model.actions;
    let app_of = |id| actions.by_id(id).app.as_deref();
    for &a in &sc.kept {
        let act = actions.by_id(a);
        let (Some(app), Some(version)) = (&act.app, &act.version) else {
            continue;
        };
        if sc.key.iter().any(|r| app_of(r.0) == Some(app.as_str())) {
            continue; // one variant per application (target detection shares the tracker)
        }
        let fps = rates.get(a.index()).map_or(1.0, |r| r.fps(readings));
        let planned = planned_implementation(plan, version);
        sc.key.push((actions.variant_id(a), planned, fps.to_bits()));
        sc.owners.push(a);
    }
}

/// Rewrite: an application action stays only if its app is placed, under the placed version.
fn rewrite_actions(model: &Model, record: &ResourcesRecord, sc: &mut Scratch) {
    sc.actions.clear();
    for &a in &sc.kept {
        let act = model.actions.by_id(a);
        match act.app.as_deref() {
            None => sc.actions.push(a),
            Some(app) => {
                let placed = record.placements.iter().find(|p| p.app == app);
                if let Some(p) = placed {
                    // A degraded variant is named by the action that runs it (track_v3 -> track_v1).
                    let same = act.version.as_deref() == Some(p.version.as_str());
                    let id = if same || !sc.owners.contains(&a) {
                        a
                    } else {
                        model
                            .actions
                            .for_variant(app, &p.version, &model.states)
                            .and_then(|x| model.actions.id(&x.id))
                            .unwrap_or(a)
                    };
                    if !sc.actions.contains(&id) {
                        sc.actions.push(id);
                    }
                } else if act.kind == ActionKind::Vehicle {
                    sc.actions.push(a);
                }
            }
        }
    }
}

/// Degradations are events when they start, not on every cycle they last.
fn degradation_events(
    (last_degraded, last_dropped): (&mut Vec<Degraded>, &mut Vec<Dropped>),
    record: &ResourcesRecord,
    rec: &mut DecisionRecord,
) {
    if record.degraded == *last_degraded && record.dropped == *last_dropped {
        return;
    }
    for d in &record.degraded {
        if !last_degraded.contains(d) {
            rec.events.push(Event::Degraded(d.clone()));
        }
    }
    for d in &record.dropped {
        if !last_dropped.contains(d) {
            rec.events.push(Event::Dropped(d.clone()));
        }
    }
    last_degraded.clone_from(&record.degraded);
    last_dropped.clone_from(&record.dropped);
}
