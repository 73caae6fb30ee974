//! The BFM companion's decision core: pure, per cycle, and handed everything it knows.
//!
//! It compiles the mission's params (given as text, never read from disk here) into one
//! [`decision::Model`], and each [`decision::Core::step`] turns one observation snapshot into a
//! decision record: `evidence` -> `health` (BNs from FMEA tables) -> the concurrent MDPs
//! (`mission_mdp`) -> behaviour and resource arbitration -> the PANORAMA `guarantee`. No clock,
//! no file, no socket, no randomness: the shells (the `companion` binary's simulated world and
//! MAVLink flight) own those, so the same observations always give the same record.
//!
//! # Layout
//! - `spec`: the params as data ([`spec::ParamsFiles`]), TOML parsing, the one error type naming
//!   file, entry and reason.
//! - `observations`: one snapshot of what the shell observed.
//! - `evidence`: observations to BN evidence states (thresholds from `observations.toml`).
//! - `fmea`: FMEA tables (`params/health/*.toml`) compiled into Bayesian networks.
//! - `health`: the health managers, evaluated per cycle; the battery as a two-slice DBN.
//! - `mission`: the mission's states, phases and action catalogue (`mission.toml`, `actions.toml`).
//! - `action_role`: what each action does for the code acting on it (`actions.toml` `role`).
//! - `mission_mdp`: the concurrent MDPs built from `params/mdp/`, solved at the projected state.
//! - `resources`: Table 2 (variants), the platform, and resource arbitration onto FPGA tiles and CPU.
//! - `guarantee`: PANORAMA's activities, IAs, pre-flight allocation, margins and re-allocation.
//! - `decision`: the [`decision::Model`] and the per-cycle [`decision::Core`].
//! - `launch`: the launch verdict, whether the models agree to a start ([`launch::verdict`]).
//! - `probabilities`: the named probabilities, their publishers and consumers (checked at load).
//! - `readings`: the snapshot's values the cycle reads, by slot (names resolved once).
//! - `record`: the decision record written for every cycle.
//! - `tracking`: tracking time, shared by the world, the review and the tables.
//! - `stage_hook`: an optional observer of the cycle's stage boundaries (benchmarks' breakdown).

pub mod action_id;
pub mod action_role;
pub mod arbitration;
pub mod conflicts;
pub mod decision;
pub mod evidence;
pub mod fmea;
pub mod guarantee;
pub mod health;
pub mod launch;
pub mod mission;
pub mod mission_mdp;
pub mod model;
pub mod named_slots;
pub mod observation_values;
pub mod observations;
pub mod probabilities;
pub mod readings;
pub mod record;
pub mod report;
pub mod resources;
pub mod route_plan;
pub(crate) mod scratch;
pub mod spec;
pub mod stage_hook;
pub mod tracking;
pub mod vocabulary;

/// The shipped params/ for the unit tests, compiled in (this crate reads no files). The
/// `companion` crate's `shipped_params_are_all_compiled_into_the_core_tests` test keeps this list
/// equal to the directory.
#[cfg(test)]
pub(crate) mod shipped {
    use crate::spec::ParamsFiles;

    /// Every file of params/, relative path and text.
    pub(crate) const FILES: &[(&str, &str)] = &[
        ("actions.toml", include_str!("../../params/actions.toml")),
        ("commands.toml", include_str!("../../params/commands.toml")),
        (
            "health/applications.toml",
            include_str!("../../params/health/applications.toml"),
        ),
        (
            "health/resources.toml",
            include_str!("../../params/health/resources.toml"),
        ),
        (
            "health/sensors.toml",
            include_str!("../../params/health/sensors.toml"),
        ),
        (
            "health/system.toml",
            include_str!("../../params/health/system.toml"),
        ),
        ("learning.toml", include_str!("../../params/learning.toml")),
        ("link.toml", include_str!("../../params/link.toml")),
        (
            "mdp/index.toml",
            include_str!("../../params/mdp/index.toml"),
        ),
        (
            "mdp/landing.toml",
            include_str!("../../params/mdp/landing.toml"),
        ),
        (
            "mdp/monolithic.toml",
            include_str!("../../params/mdp/monolithic.toml"),
        ),
        (
            "mdp/navigation.toml",
            include_str!("../../params/mdp/navigation.toml"),
        ),
        (
            "mdp/reference.toml",
            include_str!("../../params/mdp/reference.toml"),
        ),
        (
            "mdp/tracking.toml",
            include_str!("../../params/mdp/tracking.toml"),
        ),
        ("mission.toml", include_str!("../../params/mission.toml")),
        (
            "missions/patrolling.toml",
            include_str!("../../params/missions/patrolling.toml"),
        ),
        (
            "missions/tracking.toml",
            include_str!("../../params/missions/tracking.toml"),
        ),
        (
            "missions/tracking_route.toml",
            include_str!("../../params/missions/tracking_route.toml"),
        ),
        (
            "missions/tracking_route_long.toml",
            include_str!("../../params/missions/tracking_route_long.toml"),
        ),
        (
            "observations.toml",
            include_str!("../../params/observations.toml"),
        ),
        ("platform.toml", include_str!("../../params/platform.toml")),
        ("policies.toml", include_str!("../../params/policies.toml")),
        (
            "resource_policies.toml",
            include_str!("../../params/resource_policies.toml"),
        ),
        (
            "scenarios/complete-1.toml",
            include_str!("../../params/scenarios/complete-1.toml"),
        ),
        (
            "scenarios/complete-2.toml",
            include_str!("../../params/scenarios/complete-2.toml"),
        ),
        (
            "scenarios/emergency-landing.toml",
            include_str!("../../params/scenarios/emergency-landing.toml"),
        ),
        (
            "scenarios/energy-drift.toml",
            include_str!("../../params/scenarios/energy-drift.toml"),
        ),
        (
            "scenarios/high-speed.toml",
            include_str!("../../params/scenarios/high-speed.toml"),
        ),
        (
            "scenarios/lidar-failure.toml",
            include_str!("../../params/scenarios/lidar-failure.toml"),
        ),
        (
            "scenarios/nominal.toml",
            include_str!("../../params/scenarios/nominal.toml"),
        ),
        (
            "scenarios/vibrations.toml",
            include_str!("../../params/scenarios/vibrations.toml"),
        ),
        (
            "scenarios/wind.toml",
            include_str!("../../params/scenarios/wind.toml"),
        ),
        ("variants.toml", include_str!("../../params/variants.toml")),
        ("world.toml", include_str!("../../params/world.toml")),
    ];

    /// The shipped params as a set rooted at `params`.
    pub(crate) fn params() -> ParamsFiles {
        let mut p = ParamsFiles::new("params");
        for (name, text) in FILES {
            p.insert(p.dir().join(name), *text);
        }
        p
    }
}
