//! The decision record: one per decision cycle, every stage in order. This is the schema of the
//! decision log (docs/decision-log.md); bump [`SCHEMA_VERSION`] on any incompatible change.

use crate::action_id::{ActionId, ActionIds};
use crate::named_slots::{Label, NamedSlots};
use crate::observation_values::ObservationValues;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

mod events;
mod goal_maps;
mod resources;
#[cfg(any(test, feature = "test-support"))]
pub mod strategies;
mod verdict;
pub use events::{
    CommandOutcome, Event, LinkEvent, MAX_LINK_EVENTS, OperatorEvent, ROUTE_REPLANNED,
    STARTED_IN_FLIGHT, StartBy, StopEvent, coalesce_link_events, dedupe_capped,
};
pub use resources::{Degraded, Dropped};
pub use verdict::{FIT_LINE_MAX, Lowered, PLAN_LINE_MAX, Verdict};

/// Version of the decision-log schema, written in each log's header.
pub const SCHEMA_VERSION: u32 = 2;

/// One MDP's view of the cycle.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MdpProposal {
    /// MDP name from params (`navigation`, `landing`, `tracking`, `monolithic`, `reference`).
    pub mdp: String,
    /// This MDP's local state.
    pub state: String,
    /// The chosen MDP action (as named in params) and the primitive actions it stands for.
    pub action: String,
    /// Primitive actions the chosen MDP action stands for (`take_off`, `track_v3`, ...), by id
    /// over the catalogue (named when written).
    pub actions: ActionIds,
    /// Optimal expected value at `state` under the active policy's rewards.
    pub value: f64,
    /// Stages the finite-horizon solver computed by backward induction (at most `horizon`: the
    /// rest extrapolated under its certified early stop), the paper's Table 9 count.
    pub iterations: u32,
    /// The horizon solved for (params/mission.toml `horizon`, the paper's 100).
    #[serde(default)]
    pub horizon: u32,
    /// The named probabilities the solve read, with their values (`P_V3`: 0.91); by slot over
    /// the MDP's sorted variables, named when written.
    #[serde(default)]
    pub inputs: NamedSlots<f64>,
    /// Empty for the cycle's first solve; for a re-solve within the cycle, why (the resource
    /// conflict that made the MDP's earlier choice impossible).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub reason: String,
}

/// A behaviour conflict between primitive actions and how the policy resolved it.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Conflict {
    /// Primitive actions kept, by id (written as their names joined by `+`).
    #[serde(with = "crate::action_id::joined")]
    pub kept: ActionIds,
    /// Primitive actions dropped in their favour, by id (written as the list of names).
    pub dropped: ActionIds,
    /// The rule from params/policies.toml that decided it.
    pub rule: String,
}

/// One application variant placed on the platform.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlacementRecord {
    /// Application name (`tracking`, `detection`, ...), as in params/variants.toml.
    pub app: String,
    /// Version name (paper Table 2: `V0`..`V5`).
    pub version: String,
    /// S, M or F.
    pub implementation: String,
    /// SW, HW or SW-HW.
    pub support: String,
    /// FPGA tiles it occupies, by tile index (empty in software).
    pub tiles: Vec<u8>,
    /// Share of the CPU budget it takes (1.0 = the whole budget).
    pub cpu_share: f64,
    /// Processing time per frame (ms).
    pub ms_per_frame: f64,
}

/// What the resource arbitration did this cycle.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ResourcesRecord {
    /// Every variant placed this cycle.
    pub placements: Vec<PlacementRecord>,
    /// Share of the CPU budget in use (1.0 = full).
    pub cpu_load: f64,
    /// FPGA tiles in use.
    pub tiles_used: u8,
    /// Tile reconfigurations this cycle.
    pub reconfigurations: u32,
    /// Variants placed in a lower version; written as
    /// "tracking V3 -> V1: insufficient resources (cpu 1.12 > 1.00)".
    pub degraded: Vec<Degraded>,
    /// Applications dropped for lack of resources; written as "tracking V3: REASON".
    pub dropped: Vec<Dropped>,
    /// The paper's Resources column: "10 + 5 + 394 ms".
    pub summary: String,
    /// Resource policy that resolved conflicts (`safety`, `mission`).
    #[serde(default)]
    pub policy: String,
    /// Healthy tiles left unused after placement (the resource BN's `free_tiles`).
    #[serde(default)]
    pub free_tiles: u8,
    /// Tiles that are out of service this cycle.
    #[serde(default)]
    pub failed_tiles: Vec<u8>,
    /// Partial reconfiguration time spent this cycle.
    #[serde(default)]
    pub reconfiguration_ms: f64,
    /// Estimated board power (params/platform.toml power model).
    #[serde(default)]
    pub power_w: f64,
}

/// PANORAMA margins and re-allocation this cycle.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct GuaranteeRecord {
    /// Activity being flown (index and name).
    pub activity: usize,
    /// Name of the activity at index `activity`.
    pub activity_name: String,
    /// goal - (measured so far + estimated remainder), per end-oriented goal name (`energy_j`, `duration_s`).
    pub margins: BTreeMap<String, f64>,
    /// Goal value per end-oriented goal name (`energy_j` in J, `duration_s` in s).
    pub goals: BTreeMap<String, f64>,
    /// measured - estimated so far, per goal.
    pub drift: BTreeMap<String, f64>,
    /// Set when this cycle re-allocated the remaining activities.
    pub reallocation: Option<Reallocation>,
    /// True when no allocation of the remaining activities meets every goal.
    pub infeasible: bool,
    /// When `infeasible`: why (trigger, failing goal and excess).
    #[serde(default)]
    pub infeasible_reason: Option<String>,
    /// Resources reported failed so far (their IAs are excluded from re-allocations).
    #[serde(default)]
    pub failed_resources: Vec<String>,
    /// Where the allocation in force plans another variant than the one placed this cycle, and
    /// why (PANORAMA's alternative is its cost estimate; the BFM chooses what runs).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub plan_differs: Vec<String>,
    /// Where the energy counted as used came from; omitted when it is the autopilot's remaining
    /// battery percentage (`battery_remaining`), else `energy_consumed` or `estimate`.
    #[serde(default, skip_serializing_if = "EnergySource::is_battery_remaining")]
    pub energy_source: EnergySource,
    /// The pack the energy goal was reckoned from, and where each number came from; present when
    /// the autopilot says anything of its pack beyond the percentage (fly), absent in `simulate`
    /// and in logs written before it existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pack: Option<PackRecord>,
    /// The whole activity in force's energy estimate (J) in the allocation in force (before any
    /// re-allocation, the pre-flight plan's cell), 0 without an energy goal.
    pub planned_j: f64,
    /// The whole activity in force's duration estimate (s) in the allocation in force.
    pub planned_s: f64,
    /// The activity in force: its predicted power against the power and energy measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub power: Option<PowerRecord>,
    /// Before the flight, when no allocation meets the goals: planned against available and
    /// what would fit (docs/guarantee.md, "The verdict"); the start refusal words it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verdict: Option<Verdict>,
}

/// The pack behind the energy goal (docs/guarantee.md, "Energy from the autopilot").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PackRecord {
    /// Where the capacity came from.
    pub capacity_source: CapacitySource,
    /// The capacity the autopilot reports (mAh; zero or negative: not set), when it reported one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub capacity_mah: Option<f64>,
    /// The full pack's energy (J): capacity (mAh) x 3.6 x nominal voltage, or params' `[battery]`.
    pub capacity_j: f64,
    /// Nominal pack voltage (V): cells x 3.7 V, when the capacity is the autopilot's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal_v: Option<f64>,
    /// Cells in series, and where that came from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cells: Option<f64>,
    /// Where the cell count came from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cells_source: Option<CellsSource>,
    /// Energy in the pack now (J), when the autopilot reports its state of charge.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub left_j: Option<f64>,
    /// Never planned to be drawn (J): the never-drawn part and the reserve of params'
    /// `[battery]`, as fractions of this pack's capacity.
    pub kept_back_j: f64,
    /// What the mission may still spend (J): `left_j - kept_back_j`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spendable_j: Option<f64>,
}

/// Where the pack's capacity came from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CapacitySource {
    /// The autopilot's capacity parameter (`BATT_CAPACITY`, `BAT1_CAPACITY`).
    Autopilot,
    /// The mission's `[battery]`: the autopilot reported none, or none usable (-1 or 0, or no
    /// voltage to turn mAh into joules).
    #[default]
    Params,
}

/// Where the pack's cell count came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CellsSource {
    /// The autopilot's cell-count parameter (PX4 `BAT1_N_CELLS`).
    Autopilot,
    /// The first pack voltage heard, at most 4.25 V a cell (a charged LiPo is 4.2 V).
    FirstVoltage,
}

/// Predicted against measured power of the activity in force (docs/guarantee.md, "Power
/// measured").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PowerRecord {
    /// Predicted power of the activity in force (W): its implementation alternative's energy
    /// estimate over its duration estimate.
    pub predicted_w: f64,
    /// Measured power now (W): pack voltage x current, when the autopilot reports both.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_w: Option<f64>,
    /// Time in the activity so far (s).
    pub activity_s: f64,
    /// Predicted energy of the activity so far (J): `predicted_w x activity_s`.
    pub predicted_j: f64,
    /// Measured energy of the activity so far (J): the autopilot's consumed energy since the
    /// activity began, or measured power integrated over the cycles when it reports none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measured_j: Option<f64>,
    /// `measured_j / predicted_j`, once the activity has run long enough to judge.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ratio: Option<f64>,
    /// The ratio is beyond the tolerance: PANORAMA's performance drift.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub drift: bool,
    /// Set on the cycle a drift is first seen in this activity (the record's events say it).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub drift_began: bool,
    /// The factor the guarantee applies to the remaining activities' energy estimates, learned
    /// from the measured ratio (1: the params' model as is).
    pub energy_scale: f64,
}

/// Where the energy counted as used against the energy goal came from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EnergySource {
    /// The autopilot's remaining battery percentage (of the full pack) with the mission's
    /// `[battery]` capacity: the energy actually left. The usual case, so the record omits it.
    #[default]
    BatteryRemaining,
    /// The energy the autopilot reports consumed since its boot (BATTERY_STATUS), larger than
    /// what the percentage says (or no percentage reported).
    EnergyConsumed,
    /// No battery telemetry: the plan's estimate of the activities flown so far.
    Estimate,
    /// The charge the autopilot reports consumed (BATTERY_STATUS.current_consumed, mAh) against
    /// its pack's capacity, smaller than what the percentage says.
    CurrentConsumed,
}

impl EnergySource {
    /// True for the default ([`EnergySource::BatteryRemaining`]), which the record omits.
    pub fn is_battery_remaining(&self) -> bool {
        *self == EnergySource::BatteryRemaining
    }
}

/// How PANORAMA re-allocated the remaining activities on one cycle.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Reallocation {
    /// What triggered it, for programs (review, tests); `reason` says it for people. Logs
    /// written before the field read as [`ReallocationTrigger::Margin`].
    pub trigger: ReallocationTrigger,
    /// What triggered the re-allocation.
    pub reason: String,
    /// Activity name -> chosen implementation alternative, for the remaining activities.
    pub allocation: Vec<(String, String)>,
    /// Margin per goal after the re-allocation, in the goal's unit.
    pub margins_after: BTreeMap<String, f64>,
}

/// What made the guarantee change the plan (docs/guarantee.md).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReallocationTrigger {
    /// A goal's margin went negative (PANORAMA P3: drift).
    #[default]
    Margin,
    /// A resource the remaining plan uses failed (PANORAMA P3: failure), with or without a
    /// negative margin.
    Failure,
    /// The models run other versions than the plan names: the plan follows them (issue 24's
    /// binding, BFM -> PANORAMA).
    FollowsVersions,
    /// The planned implementation did not fit the platform: the plan follows the placement.
    FollowsPlacement,
}

impl ReallocationTrigger {
    /// True for the plan following what runs (not a re-allocation for a margin or a failure).
    pub fn is_follow(self) -> bool {
        matches!(self, Self::FollowsVersions | Self::FollowsPlacement)
    }
}

/// A vehicle command and what became of it (fly only; simulate records the intent).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CommandRecord {
    /// Primitive action that caused it (`take_off`, `return_to_base`, ...).
    pub action: String,
    /// MAVLink command or protocol step (`MAV_CMD_NAV_TAKEOFF`, `MISSION_UPLOAD`, `SET_MODE GUIDED`).
    pub command: String,
    /// `ACCEPTED`, `DENIED`, `FAILED`, `TIMEOUT`, `PENDING`, `SIMULATED`, ...
    pub result: CommandOutcome,
    /// Sends it took (retries included).
    pub attempts: u32,
    /// Time from the first send to the final answer (ms); `None` when no answer came.
    pub latency_ms: Option<f64>,
}

/// Everything one decision cycle saw and decided, in stage order.
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DecisionRecord {
    /// Decision cycle number, from 0.
    pub cycle: u64,
    /// Seconds since the run started (simulate: step index times the step length).
    pub time_s: f64,
    /// Mission (shared) state: `base`, `wp1`, `wpi`, `wpf`, `target`, `v3`, `landing`, ...
    pub state: String,
    /// What triggered or happened at this cycle (`target detected`, `obstacle detected`, ...).
    pub events: Vec<Event>,
    /// Raw observations by slot over the run's vocabulary, with the overflow (units in
    /// docs/params.md); written as the `name -> value` map.
    pub observations: ObservationValues,
    /// BN evidence: node -> state (by slot over the evidence nodes, named when written).
    pub evidence: NamedSlots<Label>,
    /// The evidence nodes of params/observations.toml that received no evidence this cycle (in
    /// file order): their observation was absent from the snapshot (a sensor never heard, an
    /// estimator not estimating: WIND all zero) or not finite. Their BN nodes keep their priors.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub absent_evidence: Vec<String>,
    /// Named probabilities published by the health managers (by slot over the published names,
    /// named when written).
    pub probabilities: NamedSlots<f64>,
    /// One proposal per MDP solve (re-solves included).
    pub proposals: Vec<MdpProposal>,
    /// Behaviour conflicts and how the policy resolved them.
    pub conflicts: Vec<Conflict>,
    /// Final primitive action set after behaviour and resource arbitration, by id over the
    /// catalogue (named when written).
    pub actions: ActionIds,
    /// Vehicle actions the fly shell flew this cycle on its own safety rules, not on a model's
    /// proposal: the flight's end ("land" once the mission is over) and a landing kept up until
    /// the vehicle is down. Kept apart from `actions`, which hold only what the MDPs chose; the
    /// record's events say why. Empty in `simulate`.
    #[serde(skip_serializing_if = "ActionIds::is_empty")]
    pub shell_actions: ActionIds,
    /// Resource arbitration result; `None` when it did not run.
    pub resources: Option<ResourcesRecord>,
    /// PANORAMA margins; `None` without a guarantee.
    pub guarantee: Option<GuaranteeRecord>,
    /// Vehicle commands issued this cycle and their outcome.
    pub commands: Vec<CommandRecord>,
    /// MAVLink link happenings this cycle.
    pub link_events: Vec<LinkEvent>,
    /// Telemetry worth plotting that is not an observation (altitude_m, battery_pct, mode): by
    /// slot over the names the shell wrote (kept from cycle to cycle), written as the map.
    pub vehicle: NamedSlots<serde_json::Value>,
    /// Wall-clock time of the record, microseconds since the Unix epoch (UTC), the unit and
    /// clock of the tlog's timestamps, so records and telemetry line up. `fly` only (the
    /// simulated world has no wall clock): absent in `simulate` records.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub utc_us: Option<u64>,
    /// How long the decision itself took (ms, wall clock: the snapshot, the core's step and the
    /// commands, not the sending): `fly` only, a shell measurement like `utc_us`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decide_ms: Option<f64>,
    /// In-flight CPT learning (`--learn-cpt`, docs/calibrate.md): the BN rows this record's
    /// outcome updated, in force from the next cycle. Absent when learning is off.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cpt_learned: Vec<CptUpdate>,
    /// With `--live` only: messages the live viewers lost so far in this run (a slow or stalled
    /// viewer's bounded queue overflowed), summed over the viewers; absent without `--live`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub live_dropped: Option<u64>,
}

/// One CPT row learned in flight: which row, its counts, the value before and after.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct CptUpdate {
    /// The BN node (`C_V3`, `U_detection_fail`).
    pub node: String,
    /// The row: parent -> state.
    pub when: BTreeMap<String, String>,
    /// The child's state a success stands for (`activate`, `absent`).
    pub success_state: String,
    /// Successes counted this run for the row (this record's trial included).
    pub successes: u64,
    /// Trials counted this run for the row (this record's trial included).
    pub trials: u64,
    /// P(success state) of the row as loaded (the Dirichlet prior's mean).
    pub prior: f64,
    /// P(success state) before this record's trial.
    pub old: f64,
    /// P(success state) after it, in force from the next cycle.
    pub new: f64,
    /// The Dirichlet mean lay beyond `prior ± max_change` and was held at the bound.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub bounded: bool,
}

/// What the core asks the shell to do this cycle.
#[derive(Debug, Default, PartialEq)]
pub struct Plan {
    /// Primitive vehicle actions (roles take-off, follow route, avoid obstacle, land, ...), by
    /// id in the deciding core's catalogue; the shell maps them to MAVLink by params/commands.toml.
    pub vehicle_actions: Vec<ActionId>,
    /// Application variants to run on the modeled platform.
    pub applications: Vec<PlacementRecord>,
}

impl Plan {
    /// The plan as JSON writes it: actions by name (`name_of` is the deciding catalogue's
    /// [`crate::mission::ActionCatalogue::name`]).
    pub fn named<'a>(&'a self, name_of: impl Fn(ActionId) -> &'a str) -> NamedPlan<'a> {
        NamedPlan {
            vehicle_actions: self.vehicle_actions.iter().map(|&a| name_of(a)).collect(),
            applications: &self.applications,
        }
    }
}

/// A [`Plan`] with its actions resolved to names, for writing.
#[derive(Debug, Serialize)]
pub struct NamedPlan<'a> {
    /// The vehicle actions' names.
    pub vehicle_actions: Vec<&'a str>,
    /// Application variants to run on the modeled platform.
    pub applications: &'a [PlacementRecord],
}

// ---------------------------------------------------------------- buffer reuse
//
// `Clone` is written out so that `clone_from` goes field by field: a record reused cycle after
// cycle (`Core::step_into`) then keeps the capacity of its strings, vectors and maps, and copying
// one of the same shape allocates nothing. `clone()` is the plain field-wise clone.

/// `dst = src.clone()`, reusing `dst`'s nodes and values when both have the same keys (the
/// steady state: same observation names, same published probabilities); rebuilt otherwise.
pub fn map_clone_from<K: Ord + Clone, V: Clone>(dst: &mut BTreeMap<K, V>, src: &BTreeMap<K, V>) {
    if dst.len() == src.len() && dst.keys().zip(src.keys()).all(|(a, b)| a == b) {
        for (d, s) in dst.values_mut().zip(src.values()) {
            d.clone_from(s);
        }
    } else {
        *dst = src.clone();
    }
}

macro_rules! reuse_clone {
    ($t:ident { $($f:ident),* }) => {
        impl Clone for $t {
            fn clone(&self) -> Self {
                Self { $($f: self.$f.clone(),)* }
            }
            fn clone_from(&mut self, src: &Self) {
                $(self.$f.clone_from(&src.$f);)*
            }
        }
    };
    // `$also(dst, src)` copies the fields not listed (`clone` starts them at their default).
    ($t:ident { $($f:ident),* } then $also:path) => {
        impl Clone for $t {
            fn clone(&self) -> Self {
                let mut c = Self { $($f: self.$f.clone(),)* ..Default::default() };
                $also(&mut c, self);
                c
            }
            fn clone_from(&mut self, src: &Self) {
                $(self.$f.clone_from(&src.$f);)*
                $also(self, src);
            }
        }
    };
}

reuse_clone!(MdpProposal {
    mdp,
    state,
    action,
    actions,
    value,
    iterations,
    horizon,
    reason,
    inputs
});
reuse_clone!(Conflict {
    kept,
    dropped,
    rule
});
reuse_clone!(PlacementRecord {
    app,
    version,
    implementation,
    support,
    tiles,
    cpu_share,
    ms_per_frame
});
reuse_clone!(ResourcesRecord {
    placements,
    cpu_load,
    tiles_used,
    reconfigurations,
    degraded,
    dropped,
    summary,
    policy,
    free_tiles,
    failed_tiles,
    reconfiguration_ms,
    power_w
});
reuse_clone!(GuaranteeRecord {
    activity, activity_name, reallocation, infeasible, infeasible_reason, failed_resources,
    plan_differs, energy_source, pack, power, planned_j, planned_s, verdict
} then goal_maps::clone_goal_maps_from);
// The observations and the vehicle's telemetry are by slot (`ObservationValues`, `NamedSlots`):
// their `clone_from` keeps the buffers and shares the names.
reuse_clone!(DecisionRecord {
    cycle,
    time_s,
    state,
    events,
    proposals,
    conflicts,
    actions,
    resources,
    guarantee,
    commands,
    link_events,
    utc_us,
    decide_ms,
    shell_actions,
    absent_evidence,
    cpt_learned,
    live_dropped,
    evidence,
    probabilities,
    observations,
    vehicle
});
reuse_clone!(Plan {
    vehicle_actions,
    applications
});

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(keys: &[&str], x: f64, n_props: usize) -> DecisionRecord {
        DecisionRecord {
            cycle: x as u64,
            state: format!("s{x}"),
            events: keys.iter().map(|k| Event::Other(k.to_string())).collect(),
            observations: keys.iter().map(|k| (k.to_string(), x)).collect(),
            evidence: keys
                .iter()
                .map(|k| (k.to_string(), Label::from(format!("st{x}"))))
                .collect(),
            probabilities: keys.iter().map(|k| (format!("P_{k}"), x / 10.0)).collect(),
            proposals: (0..n_props)
                .map(|i| MdpProposal {
                    mdp: format!("m{i}"),
                    actions: ActionIds::from_names(vec![format!("a{x}"); i]),
                    value: x + i as f64,
                    ..Default::default()
                })
                .collect(),
            resources: n_props.is_multiple_of(2).then(|| ResourcesRecord {
                placements: vec![PlacementRecord {
                    app: format!("app{x}"),
                    tiles: vec![1, 2],
                    ..Default::default()
                }],
                degraded: vec![Degraded {
                    reason: format!("d{x}"),
                    ..Default::default()
                }],
                ..Default::default()
            }),
            guarantee: Some(GuaranteeRecord {
                margins: keys.iter().map(|k| (k.to_string(), -x)).collect(),
                failed_resources: vec!["lidar".into()],
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    /// `clone_from` gives exactly `clone()` whatever the destination held: same keys (in-place
    /// path), different keys, more or fewer entries, `Some` over `None` and back.
    #[test]
    fn clone_from_equals_clone_for_any_previous_content() {
        let shapes = [
            rec(&["a", "b"], 1.0, 2),
            rec(&["a", "b"], 2.0, 3),
            rec(&["a", "c"], 3.0, 1),
            rec(&["a", "b", "c"], 4.0, 0),
            rec(&[], 5.0, 4),
            DecisionRecord::default(),
        ];
        for dst0 in &shapes {
            for src in &shapes {
                let mut dst = dst0.clone();
                dst.clone_from(src);
                assert_eq!(&dst, src);
                assert_eq!(
                    serde_json::to_string(&dst).unwrap(),
                    serde_json::to_string(src).unwrap()
                );
            }
        }
    }
}
