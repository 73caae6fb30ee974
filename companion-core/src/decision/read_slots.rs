//! What the cycle reads of the snapshot, resolved to slots of [`Readings`] when the core starts:
//! the declared observations first (slot = observation id), then every other name a stage
//! reads. A cycle reads the snapshot once ([`Readings::read`]) and every stage by index.

use crate::arbitration::RequiredRate;
use crate::model::Model;
use crate::readings::{Readings, Slot};

// The pack readings the guarantee's energy goal is reckoned from (docs/guarantee.md, "Energy
// from the autopilot"), in `PackReading`'s field order.
use crate::guarantee::PACK_OBSERVATIONS as PACK;

/// The slots of every name the cycle reads besides the declared observations.
#[derive(Debug, Clone)]
pub(super) struct ReadSlots {
    pub(super) failed_tiles: Slot,
    pub(super) external_cpu_load: Slot,
    pub(super) energy_consumed_j: Slot,
    pub(super) battery_pct: Slot,
    /// [`crate::evidence::ROUTE_ACTIVITY`].
    pub(super) route_activity: Slot,
    pack: [Slot; 7],
    /// The guarantee's resources and the observation reporting each failed, in params order.
    pub(super) failures: Vec<(String, Slot)>,
    /// Per catalogue action (by id): the rate its application needs (none for a vehicle action).
    pub(super) rates: Vec<RequiredRate>,
    /// The rate the application the resource manager assesses needs.
    pub(super) assessed_rate: RequiredRate,
    /// Per MDP of the core (its `mdp_names` order), per projection rule: its observation's slot.
    pub(super) projection: Vec<Vec<Option<Slot>>>,
}

impl ReadSlots {
    /// The readings of `model` (declared observations first) and the slots of the rest.
    pub(super) fn resolve(model: &Model, mdp_names: &[String]) -> (Readings, ReadSlots) {
        let declared = &model.health.observations.observations;
        let mut r = Readings::starting_with(declared.iter().map(|o| o.name.as_str()));
        let assessed = model.health.activations.first().map(|a| a.app.as_str());
        let slots = ReadSlots {
            failed_tiles: r.slot(crate::evidence::FAILED_TILES),
            external_cpu_load: r.slot(crate::evidence::EXTERNAL_CPU_LOAD),
            energy_consumed_j: r.slot("energy_consumed_j"),
            battery_pct: r.slot("battery_pct"),
            route_activity: r.slot(crate::evidence::ROUTE_ACTIVITY),
            pack: PACK.map(|name| r.slot(name)),
            failures: model
                .mission
                .guarantee
                .failures
                .iter()
                .map(|(resource, observation)| (resource.clone(), r.slot(observation)))
                .collect(),
            rates: model
                .actions
                .actions
                .iter()
                .map(|a| RequiredRate::of(model, a.app.as_deref(), &mut r))
                .collect(),
            assessed_rate: RequiredRate::of(model, assessed, &mut r),
            projection: mdp_names
                .iter()
                .map(|name| {
                    let rules = model.mission.projection_rules(name);
                    rules
                        .iter()
                        .map(|rule| rule.observation.as_deref().map(|o| r.slot(o)))
                        .collect()
                })
                .collect(),
        };
        (r, slots)
    }

    /// What the snapshot read says of the pack.
    pub(super) fn pack(&self, r: &Readings) -> crate::guarantee::PackReading {
        let [
            capacity,
            cells,
            voltage,
            current,
            consumed,
            vehicle_time,
            armed,
        ] = self.pack.map(|s| r.get(s));
        crate::guarantee::PackReading {
            capacity_mah: capacity,
            cells,
            voltage_v: voltage,
            current_a: current,
            consumed_mah: consumed,
            vehicle_time_s: vehicle_time,
            armed: armed.map(|a| a > 0.5),
        }
    }
}

/// The guarantee's activity being flown: the shell's [`crate::evidence::ROUTE_ACTIVITY`] when it
/// is the index of one of the `n` activities, else the activity params/mission.toml gives the
/// shared mission state (`guarantee.activity_of_state`), else none.
pub(super) fn activity_index(
    model: &Model,
    slots: &ReadSlots,
    r: &Readings,
    state: &str,
    n: usize,
) -> Option<usize> {
    let routed = r
        .get(slots.route_activity)
        .filter(|v| v.is_finite() && *v >= 0.0 && v.fract() == 0.0 && *v < n as f64);
    match routed {
        Some(v) => Some(v as usize),
        None => model
            .mission
            .guarantee
            .activity_of_state
            .get(state)
            .copied(),
    }
}

/// The state MDP `name` is in ([`crate::mission::MissionFile::project`]), its rules' observations
/// read by slot (`slots`: [`ReadSlots::projection`] of that MDP).
pub(super) fn project<'a>(
    model: &'a Model,
    name: &str,
    slots: &[Option<Slot>],
    r: &Readings,
    state: &'a str,
) -> &'a str {
    model
        .mission
        .projection_rules(name)
        .iter()
        .zip(slots)
        .find(|(rule, slot)| rule.matches_reading(state, slot.and_then(|s| r.get(s))))
        .map_or(state, |(rule, _)| rule.state.as_str())
}
