//! The platform model's room beside the other applications (tiles, CPU, the rate the assessed
//! application needs): the evidence the resource manager reads each cycle.

use super::{Core, FitCheck, ROOM};
use crate::record::DecisionRecord;
use std::collections::BTreeMap;
use std::sync::Arc;

impl Core {
    /// Faults and monitor readings the shell reports, applied to the platform model.
    pub(super) fn update_platform(&mut self) {
        let failed = (self.readings)
            .get(self.read_slots.failed_tiles)
            .unwrap_or(0.0)
            .max(0.0) as usize;
        // The last `failed` tiles are out of service (which ones fail does not matter to the model).
        let n = self.platform.tiles.len();
        for (i, t) in self.platform.tiles.iter_mut().enumerate() {
            t.failed = i >= n.saturating_sub(failed);
        }
        self.platform.external_cpu_load = (self.readings)
            .get(self.read_slots.external_cpu_load)
            .unwrap_or(0.0)
            .max(0.0);
    }

    /// The application the resource manager's activation nodes assess (tracking).
    pub(super) fn assessed_app(&self) -> Option<&str> {
        self.model
            .health
            .activations
            .first()
            .map(|a| a.app.as_str())
    }

    /// Observations of the resource manager from the platform model: healthy tiles and CPU
    /// headroom left beside the applications it must run beside (`others_*`), and the rate the
    /// assessed application needs now. Empty when no activation node assesses an application.
    pub(super) fn platform_room(&self) -> [(&'static str, f64); 3] {
        if self.assessed_app().is_none() {
            return [("", f64::NAN); 3];
        }
        let p = &self.model.resources.platform;
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
            (ROOM[2], self.read_slots.assessed_rate.fps(&self.readings)),
        ]
    }

    /// 1.0 when the scheduler admits some implementation of the check's version at `fps` beside
    /// what the applications in force occupy (`others_*`), else 0.0: fpga_model's own admission
    /// check ([`fpga_model::Room::admits`]) on the core's platform model, so the resource
    /// manager's fit agrees with the scheduler to the last digit.
    pub(super) fn fits(&self, f: &FitCheck, fps: f64) -> f64 {
        let res = &self.model.resources;
        let room = fpga_model::Room::of(&res.platform, &self.platform);
        // `Room::admits_version` over the variants of `app version` found once in `new`.
        let variants = res.catalogue.variants();
        let admitted = f
            .variants
            .iter()
            .any(|&i| room.admits(&variants[i], fps, self.others_tiles, self.others_cpu));
        if admitted { 1.0 } else { 0.0 }
    }

    /// [`Core::platform_room`] and the fit checks written into the evidence.
    pub(super) fn platform_evidence(&self, evidence: &mut BTreeMap<String, String>) {
        let room = self.platform_room();
        for (name, v) in room {
            if !name.is_empty() {
                self.health.observe_into(name, v, evidence);
            }
        }
        for f in &self.fit_checks {
            self.health
                .observe_into(&f.name, self.fits(f, room[2].1), evidence);
        }
    }

    /// Remember what the applications the resource policy ranks above the assessed one occupy
    /// after this cycle's schedule: those it must run beside. The ones ranked below give way to
    /// it (BFM 7.3.2, mission policy: landing search gives way to tracking), so their room
    /// counts as the assessed application's.
    pub(super) fn note_others(&mut self, rec: &DecisionRecord) {
        let model = Arc::clone(&self.model);
        let app = model.health.activations.first().map(|a| a.app.as_str());
        let policy = model.resource_policy(self.policy);
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
}
