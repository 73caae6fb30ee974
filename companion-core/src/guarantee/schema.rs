//! The mission file format (params/missions/*.toml) as serde types; docs/guarantee.md
//! describes it.

use panorama::CoreConstraint;
use serde::Deserialize;
use std::collections::BTreeMap;

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MissionFile {
    pub(super) mission: MissionHeader,
    pub(super) goals: BTreeMap<String, GoalFile>,
    #[serde(default)]
    pub(super) battery: Option<BatteryFile>,
    pub(super) propulsion: Propulsion,
    /// Always-on electronics (W).
    #[serde(default)]
    pub(super) base: ResourceFile,
    #[serde(default)]
    pub(super) resources: BTreeMap<String, ResourceFile>,
    #[serde(default)]
    pub(super) compute: Option<ComputeFile>,
    pub(super) tasks: BTreeMap<String, TaskFile>,
    #[serde(default)]
    pub(super) constraints: BTreeMap<String, ConstraintClass>,
    pub(super) activities: Vec<ActivityFile>,
    /// The in-flight power-drift tuning (docs/guarantee.md); defaults when absent.
    #[serde(default)]
    pub(super) guarantee: Option<TuningFile>,
    /// What no airframe of the mission can be (docs/calibrate.md); none for a ground robot.
    #[serde(default)]
    pub(super) power_bounds: Option<PowerBoundsFile>,
    /// How activities derived from a route are planned (`check --mission FILE --zones FILE`).
    #[serde(default)]
    pub(super) derive: Option<DeriveFile>,
}

/// `[power_bounds]`: what no airframe of the mission can be (checked in power_bounds.rs).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct PowerBoundsFile {
    pub(super) mass_kg: f64,
    pub(super) hover_w_per_kg: [f64; 2],
    pub(super) min_power_of_hover: f64,
    pub(super) max_fit_rms_fraction: f64,
    pub(super) sources: BTreeMap<String, String>,
}

/// `[derive]`: what the route and zones cannot give (route_plan, docs/guarantee.md).
#[allow(dead_code)] // `source` documents the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct DeriveFile {
    /// Horizontal speed until a DO_CHANGE_SPEED item (the autopilot's WPNAV_SPEED /
    /// MPC_XY_CRUISE replace it once read over MAVLink).
    pub(super) cruise_speed_mps: f64,
    pub(super) climb_speed_mps: f64,
    pub(super) descent_speed_mps: f64,
    /// Speed while tracking (the target's), 0 to hover.
    #[serde(default)]
    pub(super) tracking_speed_mps: f64,
    /// The vehicle's time per waypoint besides the leg's length at its speed (s); a vehicle
    /// profile's (`calibrate`), 0 without one.
    #[serde(default)]
    pub(super) waypoint_overhead_s: f64,
    /// The fraction of the commanded speed the vehicle reaches on a leg; a vehicle profile's
    /// (`calibrate`), 1 without one.
    #[serde(default = "one")]
    pub(super) speed_fraction: f64,
    /// The autopilot's hover over home before an RTL descends (s; RTL_LOIT_TIME), 0 if none.
    #[serde(default)]
    pub(super) rtl_loiter_s: f64,
    /// The tasks each kind of derived activity runs: `take_off`, `leg`, `loiter`, `search`,
    /// `tracking`, `return`, `land`.
    pub(super) tasks: BTreeMap<String, Vec<String>>,
    #[serde(default)]
    pub(super) source: String,
}

fn one() -> f64 {
    1.0
}

fn fit_headroom() -> f64 {
    super::tuning::FIT_HEADROOM
}

/// `[guarantee]`: how a measured power drift is judged and learned.
#[allow(dead_code)] // `source` documents the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TuningFile {
    pub(super) power_drift_tolerance: f64,
    pub(super) power_drift_min_s: f64,
    pub(super) prior_weight_s: f64,
    pub(super) energy_scale_bounds: [f64; 2],
    #[serde(default = "fit_headroom")]
    pub(super) fit_headroom: f64,
    #[serde(default)]
    pub(super) source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MissionHeader {
    pub(super) name: String,
    #[serde(default)]
    pub(super) description: String,
    #[serde(default)]
    pub(super) source: String,
    pub(super) goal_order: Vec<String>,
    /// `most_capable` or `highest_cost`.
    pub(super) selection: String,
    #[serde(default)]
    pub(super) selection_goal: Option<String>,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GoalFile {
    /// Explicit bound; for `energy_j` it may instead come from `[battery]`.
    #[serde(default)]
    pub(super) bound: Option<f64>,
    #[serde(default)]
    pub(super) from_battery: bool,
    #[serde(default)]
    pub(super) source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct BatteryFile {
    pub(super) capacity_wh: f64,
    pub(super) usable_fraction: f64,
    pub(super) reserve_wh: f64,
    #[serde(default)]
    pub(super) source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum Propulsion {
    /// `P(v) = sum_i c_i v^i` (W), e.g. a ground robot's motion power fitted on measurements.
    Polynomial {
        coefficients_w: Vec<f64>,
        #[serde(default)]
        source: String,
    },
    /// Rotary-wing power (Zeng, Xu, Zhang 2019, eq. 12): blade profile + induced + parasitic.
    /// `P(v) = P0 (1 + 3 v²/U²) + Pi sqrt(sqrt(1 + v⁴/(4 v0⁴)) - v²/(2 v0²)) + ½ ρ CdA v³`.
    RotaryWing {
        blade_profile_w: f64,
        induced_hover_w: f64,
        induced_velocity_mps: f64,
        tip_speed_mps: f64,
        drag_area_m2: f64,
        air_density_kgm3: f64,
        #[serde(default)]
        source: String,
    },
}

impl Propulsion {
    pub(super) fn power(&self, v: f64) -> f64 {
        match self {
            Propulsion::Polynomial { coefficients_w, .. } => {
                coefficients_w.iter().rev().fold(0.0, |acc, c| acc * v + c)
            }
            Propulsion::RotaryWing {
                blade_profile_w: p0,
                induced_hover_w: pi,
                induced_velocity_mps: v0,
                tip_speed_mps: u,
                drag_area_m2: cda,
                air_density_kgm3: rho,
                ..
            } => {
                let r = v * v / (v0 * v0);
                let induced = ((1.0 + r * r / 4.0).sqrt() - r / 2.0).max(0.0).sqrt();
                p0 * (1.0 + 3.0 * v * v / (u * u)) + pi * induced + 0.5 * rho * cda * v * v * v
            }
        }
    }
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ResourceFile {
    pub(super) power_w: f64,
    #[serde(default)]
    pub(super) source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ComputeFile {
    /// Watts per fully loaded core.
    pub(super) cpu_w_per_core: f64,
    /// Watts per active FPGA tile.
    pub(super) tile_w: f64,
    pub(super) cores: f64,
    pub(super) tile_names: Vec<String>,
    #[serde(default)]
    pub(super) source: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TaskFile {
    pub(super) tios: Vec<TioFile>,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct TioFile {
    pub(super) name: String,
    #[serde(default)]
    pub(super) resources: Vec<String>,
    #[serde(default)]
    pub(super) capability: f64,
    /// Speed cap this TIO imposes (sensor range, frame stability).
    #[serde(default)]
    pub(super) v_max_mps: Option<f64>,
    /// Fixed time this TIO adds to the activity (e.g. a search's dwell).
    #[serde(default)]
    pub(super) time_s: f64,
    /// Cores' worth of CPU load while active.
    #[serde(default)]
    pub(super) cpu_load: f64,
    /// FPGA tiles occupied while active.
    #[serde(default)]
    pub(super) tiles: u32,
    /// Variant catalogue reference (app/version/implementation): loaded from a params directory,
    /// `tiles` and `cpu_load` must be that variant's (params/variants.toml is the one Table 2).
    #[serde(default)]
    pub(super) variant: Option<String>,
    #[serde(default)]
    pub(super) description: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ConstraintClass {
    #[serde(default)]
    pub(super) rules: Vec<CoreConstraint>,
    #[serde(default)]
    pub(super) description: String,
}

#[allow(dead_code)] // `source`/`description` fields document the data
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ActivityFile {
    pub(super) name: String,
    #[serde(default)]
    pub(super) objective: String,
    #[serde(default)]
    pub(super) env: String,
    pub(super) tasks: Vec<String>,
    #[serde(default)]
    pub(super) length_m: f64,
    #[serde(default)]
    pub(super) v_max_mps: Option<f64>,
    /// `v_max_mps` is the speed the vehicle is commanded (a derived activity: the route's
    /// DO_CHANGE_SPEED or the autopilot's cruise speed), so the TIOs' caps do not slow it: `fly`
    /// commands no IA's speed (docs/guarantee.md).
    #[serde(default)]
    pub(super) speed_commanded: bool,
    /// Fixed time spent in the activity besides moving (turn, detection, climb, tracking hold).
    #[serde(default)]
    pub(super) hold_s: f64,
    /// Propulsion speed during the hold (0: stationary / hover).
    #[serde(default)]
    pub(super) hold_speed_mps: f64,
    #[serde(default)]
    pub(super) constraints: Vec<String>,
    /// The hold is the mission's search or tracking time (`"search"`, `"tracking"`): the verdict
    /// finds the longest one the pack holds.
    #[serde(default)]
    pub(super) hold_kind: Option<super::HoldKind>,
    #[serde(default)]
    pub(super) x_start_m: Option<f64>,
    #[serde(default)]
    pub(super) x_end_m: Option<f64>,
}
