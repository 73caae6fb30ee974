//! The platform stage of the cycle (resources, fpga_model): the core's own platform model with
//! the faults and loads the shell reports, the room it leaves beside the other applications
//! (tiles, CPU, the rate the assessed application needs: the evidence the resource manager
//! reads), the fit checks, and the resource arbitration's schedules in force.

use super::read_slots::ReadSlots;
use super::{Model, Policy};
use crate::arbitration::{PlannedVariant, ResourceArbiter};
use crate::evidence::ObservationId;
use crate::readings::Readings;
use crate::record::DecisionRecord;
use crate::scratch::Scratch;
use fpga_model::PlatformState;

/// The observations [`PlatformStage::room`] gives, in its order.
const ROOM: [&str; 3] = [
    crate::evidence::FREE_TILES,
    crate::evidence::CPU_HEADROOM,
    crate::evidence::TRACKING_FPS,
];

/// One fit observation (`tracking_V3_fits`, node `F_V3`): whether the scheduler admits some
/// implementation of `app version` beside the applications in force.
#[derive(Debug, Clone)]
struct FitCheck {
    id: ObservationId,
    /// The observation's name: the fit tests' by-name evidence (the cycle uses `id`).
    #[cfg_attr(not(test), allow(dead_code))]
    name: String,
    /// The catalogue's variants of the activation's `app version` (its implementations), by
    /// index.
    variants: Vec<usize>,
}

/// The platform model, the room it leaves and the resource arbitration.
pub(super) struct PlatformStage {
    pub(super) platform: PlatformState,
    /// What the applications other than the one the resource manager assesses occupied after
    /// the last schedule (tiles, CPU share): the room the resource manager sees before solving.
    pub(super) others_tiles: u32,
    pub(super) others_cpu: f64,
    /// The resource arbitration stage's schedules and degradations in force.
    arbiter: ResourceArbiter,
    /// The ids of [`ROOM`]'s observations (`None`: params do not observe it), and their values
    /// this cycle (capacity kept).
    room_ids: [Option<ObservationId>; 3],
    room_extra: Vec<(ObservationId, f64)>,
    /// The activation nodes' fit observations the core computes with the scheduler's check.
    fit_checks: Vec<FitCheck>,
}

impl PlatformStage {
    /// The model's platform, nothing placed, nothing failed.
    pub(super) fn new(model: &Model) -> Self {
        PlatformStage {
            platform: PlatformState::new(&model.resources.platform),
            others_tiles: 0,
            others_cpu: 0.0,
            arbiter: ResourceArbiter::new(),
            room_ids: ROOM.map(|name| model.health.observations.id(name)),
            room_extra: Vec::with_capacity(ROOM.len() + model.health.activations.len()),
            fit_checks: model
                .health
                .fit_observations()
                .filter_map(|(name, a)| {
                    Some(FitCheck {
                        id: model.health.observations.id(name)?,
                        name: name.to_string(),
                        variants: (model.resources.catalogue.variants().iter())
                            .enumerate()
                            .filter(|(_, v)| v.app == a.app && v.version == a.version)
                            .map(|(i, _)| i)
                            .collect(),
                    })
                })
                .collect(),
        }
    }

    /// Platform scheduler runs actually made (memo hits not counted).
    pub(super) fn scheduler_runs(&self) -> u64 {
        self.arbiter.schedules.runs()
    }

    /// The schedule memo on or off ([`super::Core::set_caches`]).
    pub(super) fn set_caches(&mut self, on: bool) {
        self.arbiter.schedules.set_enabled(on);
    }

    /// Number of tiles of the platform (failed ones included).
    pub(super) fn tiles(&self) -> usize {
        self.platform.tiles.len()
    }

    /// Faults and monitor readings the shell reports, applied to the platform model.
    pub(super) fn update(&mut self, (slots, readings): (&ReadSlots, &Readings)) {
        let failed = readings.get(slots.failed_tiles).unwrap_or(0.0).max(0.0) as usize;
        // The last `failed` tiles are out of service (which ones fail does not matter to the model).
        let n = self.platform.tiles.len();
        for (i, t) in self.platform.tiles.iter_mut().enumerate() {
            t.failed = i >= n.saturating_sub(failed);
        }
        self.platform.external_cpu_load = readings
            .get(slots.external_cpu_load)
            .unwrap_or(0.0)
            .max(0.0);
    }

    /// The core's own evidence values this cycle, by observation: the platform's room and the
    /// fit checks (as `evidence_with_into(obs, &room, ..)`, with the names' ids resolved once in
    /// `new`).
    pub(super) fn room_evidence(
        &mut self,
        model: &Model,
        at: (&ReadSlots, &Readings),
    ) -> &[(ObservationId, f64)] {
        let room = self.room(model, at);
        let mut extra = std::mem::take(&mut self.room_extra);
        extra.clear();
        for ((name, v), id) in room.iter().zip(self.room_ids) {
            if let (false, Some(id)) = (name.is_empty(), id) {
                extra.push((id, *v));
            }
        }
        for f in &self.fit_checks {
            extra.push((f.id, self.fits(model, f, room[2].1)));
        }
        self.room_extra = extra;
        &self.room_extra
    }

    /// Observations of the resource manager from the platform model: healthy tiles and CPU
    /// headroom left beside the applications it must run beside (`others_*`), and the rate the
    /// assessed application needs now. Empty when no activation node assesses an application.
    fn room(
        &self,
        model: &Model,
        (slots, readings): (&ReadSlots, &Readings),
    ) -> [(&'static str, f64); 3] {
        if assessed_app(model).is_none() {
            return [("", f64::NAN); 3];
        }
        let p = &model.resources.platform;
        let healthy = self.platform.tiles.iter().filter(|t| !t.failed).count() as u32;
        let free = healthy.saturating_sub(self.others_tiles);
        let online = self.platform.cores_online.min(p.cpu_cores);
        let headroom = p.cpu_budget * f64::from(online) / f64::from(p.cpu_cores)
            - self.platform.external_cpu_load
            - self.others_cpu;
        [
            (ROOM[0], f64::from(free)),
            (ROOM[1], headroom.max(0.0)),
            // The required rate of the assessed application now (section 4.3.2 model).
            (ROOM[2], slots.assessed_rate.fps(readings)),
        ]
    }

    /// 1.0 when the scheduler admits some implementation of the check's version at `fps` beside
    /// what the applications in force occupy (`others_*`), else 0.0: fpga_model's own admission
    /// check ([`fpga_model::Room::admits`]) on the core's platform model, so the resource
    /// manager's fit agrees with the scheduler to the last digit.
    fn fits(&self, model: &Model, f: &FitCheck, fps: f64) -> f64 {
        let res = &model.resources;
        let room = fpga_model::Room::of(&res.platform, &self.platform);
        // `Room::admits_version` over the variants of `app version` found once in `new`.
        let variants = res.catalogue.variants();
        let admitted = f
            .variants
            .iter()
            .any(|&i| room.admits(&variants[i], fps, self.others_tiles, self.others_cpu));
        if admitted { 1.0 } else { 0.0 }
    }

    /// [`PlatformStage::room`] and the fit checks written into the evidence by name, as
    /// `health` observes them (the fit tests' by-name path; the cycle uses
    /// [`PlatformStage::room_evidence`]).
    #[cfg(test)]
    pub(super) fn platform_evidence(
        &self,
        model: &Model,
        health: &crate::health::HealthModel,
        at: (&ReadSlots, &Readings),
        evidence: &mut std::collections::BTreeMap<String, String>,
    ) {
        let room = self.room(model, at);
        for (name, v) in room {
            if !name.is_empty() {
                health.observe_into(name, v, evidence);
            }
        }
        for f in &self.fit_checks {
            health.observe_into(&f.name, self.fits(model, f, room[2].1), evidence);
        }
    }

    /// Remember what the applications the resource policy ranks above the assessed one occupy
    /// after this cycle's schedule: those it must run beside. The ones ranked below give way to
    /// it (BFM 7.3.2, mission policy: landing search gives way to tracking), so their room
    /// counts as the assessed application's.
    pub(super) fn note_others(&mut self, model: &Model, policy: Policy, rec: &DecisionRecord) {
        let app = assessed_app(model);
        let policy = model.resource_policy(policy);
        let rank = |a: &str| policy.rank(a);
        let limit = app.map_or(usize::MAX, rank);
        let (tiles, cpu) = rec.resources.as_ref().map_or((0, 0.0), |r| {
            r.placements
                .iter()
                .filter(|p| Some(p.app.as_str()) != app && rank(&p.app) < limit)
                .fold((0u32, 0.0), |(t, c), p| {
                    (t + p.tiles.len() as u32, c + p.cpu_share)
                })
        });
        self.others_tiles = tiles;
        self.others_cpu = cpu;
    }

    /// Resource arbitration: the kept actions' applications become variant requests placed on
    /// the platform (`plan`: the implementations the allocation in force names, requested for
    /// the versions the MDPs chose).
    pub(super) fn arbitrate(
        &mut self,
        model: &Model,
        policy: Policy,
        sc: &mut Scratch,
        (slots, readings): (&ReadSlots, &Readings),
        plan: Option<&[PlannedVariant]>,
        rec: &mut DecisionRecord,
    ) {
        self.arbiter.arbitrate_resources(
            model,
            policy,
            &mut self.platform,
            sc,
            (&slots.rates, readings),
            plan,
            rec,
        );
    }
}

/// The application the resource manager's activation nodes assess (tracking).
pub(super) fn assessed_app(model: &Model) -> Option<&str> {
    model.health.activations.first().map(|a| a.app.as_str())
}
