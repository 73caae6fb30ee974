//! A tiny rule-based stand-in for the decision core, for link tests: take off, fly the route,
//! sidestep obstacles, return on low battery, land when the route is done. Test support, moved
//! out of the shipped binary (issue 25).

use companion::fly::{Decider, FlyArgs, FlySetup};
use companion_core::action_id::ActionIds;
use companion_core::launch::LaunchRefusal;
use companion_core::mission::{Action, ActionCatalogue, ActionKind, ActionRoles};
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};

/// Where the scripted decider is in its script (its own steps, not the mission's states: it
/// reads no params).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Script {
    OnGround,
    Route,
    Sidestep,
    Return,
    Landing,
}

impl Script {
    /// The step's name in the record's `state`.
    fn name(self) -> &'static str {
        match self {
            Script::OnGround => "scripted: on the ground",
            Script::Route => "scripted: route",
            Script::Sidestep => "scripted: sidestep",
            Script::Return => "scripted: return",
            Script::Landing => "scripted: landing",
        }
    }
}

/// A tiny rule-based stand-in for the decision core, for link tests: take off, fly the route,
/// sidestep obstacles, return on low battery, land when the route is done.
pub struct ScriptedDecider {
    pub takeoff_alt_m: f64,
    /// Mission seq of the last waypoint.
    pub last_seq: u16,
    pub low_battery_pct: f64,
    pub policy: String,
    phase: Script,
    avoid_until: f64,
    /// The script's own five actions (the plan's ids index it).
    actions: ActionCatalogue,
}

/// The actions the script plays, by the shipped names the link's commands table maps.
const SCRIPT_ACTIONS: [&str; 5] = [
    "take_off",
    "follow_trajectory",
    "avoid_obstacle",
    "land",
    "return_to_base",
];

/// A catalogue of the script's actions only (vehicle actions; roles by the pre-roles rule).
fn script_catalogue() -> ActionCatalogue {
    let action = |(i, id): (usize, &str)| Action {
        id: id.to_string(),
        paper: format!("S{i}"),
        kind: ActionKind::Vehicle,
        label: id.to_string(),
        app: None,
        version: None,
        role: None,
    };
    ActionCatalogue::new(
        SCRIPT_ACTIONS.into_iter().enumerate().map(action).collect(),
        ActionRoles::undeclared(),
    )
}

impl ScriptedDecider {
    pub fn new(takeoff_alt_m: f64, last_seq: u16, policy: &str) -> Self {
        Self {
            takeoff_alt_m,
            last_seq,
            low_battery_pct: 20.0,
            policy: policy.to_string(),
            phase: Script::OnGround,
            avoid_until: 0.0,
            actions: script_catalogue(),
        }
    }

    /// Built from the route the fly arguments name.
    pub fn from_args(args: &FlyArgs) -> anyhow::Result<Self> {
        let setup = FlySetup::load(args)?;
        let last = setup.route.last_waypoint_seq();
        Ok(Self::new(setup.route.altitude_m, last, &args.policy))
    }
}

impl Decider for ScriptedDecider {
    fn actions(&self) -> &ActionCatalogue {
        &self.actions
    }

    /// The script agrees to a start when it proposes to take off (it has no guarantee).
    fn launch_verdict(&self, rec: &DecisionRecord) -> Result<(), LaunchRefusal> {
        if rec.actions.contains_name("take_off") {
            Ok(())
        } else {
            Err(LaunchRefusal::NoTakeOff {
                actions: rec.actions.join("+"),
            })
        }
    }

    fn new_flight(&mut self) {
        self.phase = Script::OnGround;
        self.avoid_until = 0.0;
    }

    fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        let alt = obs.get("altitude_m").unwrap_or(0.0);
        let battery = obs.get("battery_pct").unwrap_or(100.0);
        let seq = obs.get("mission_seq").unwrap_or(0.0) as u16;
        let speed = obs.get("groundspeed_mps").unwrap_or(0.0);
        let obstacle = obs.events.iter().any(|e| e == "obstacle detected");
        let airborne = alt > 0.8 * self.takeoff_alt_m;
        let action = if battery <= self.low_battery_pct && self.phase != Script::Landing {
            self.phase = Script::Return;
            "return_to_base"
        } else {
            match self.phase {
                Script::OnGround if airborne => {
                    self.phase = Script::Route;
                    "follow_trajectory"
                }
                Script::OnGround => "take_off",
                Script::Route if obstacle => {
                    self.phase = Script::Sidestep;
                    self.avoid_until = obs.time_s + 5.0;
                    "avoid_obstacle"
                }
                Script::Route if seq >= self.last_seq && speed < 1.0 => {
                    self.phase = Script::Landing;
                    "land"
                }
                Script::Route => "follow_trajectory",
                Script::Sidestep if obs.time_s >= self.avoid_until => {
                    self.phase = Script::Route;
                    "follow_trajectory"
                }
                Script::Sidestep => "avoid_obstacle",
                Script::Return => "return_to_base",
                Script::Landing => "land",
            }
        };
        let id = self
            .actions
            .id(action)
            .expect("the script plays only its own actions");
        let plan = Plan {
            vehicle_actions: vec![id],
            applications: vec![],
        };
        let rec = DecisionRecord {
            state: self.phase.name().to_string(),
            actions: {
                let mut a = ActionIds::over(self.actions.names());
                a.push(id);
                a
            },
            events: obs.events.clone(),
            observations: obs.values.clone(),
            ..Default::default()
        };
        (plan, rec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(t: f64, vals: &[(&str, f64)], events: &[&str]) -> Observations {
        let mut o = Observations {
            time_s: t,
            ..Default::default()
        };
        for (k, v) in vals {
            o.set(k, *v);
        }
        o.events = events
            .iter()
            .map(|s| companion::decision_log::migration::event(s))
            .collect();
        o
    }

    #[test]
    fn scripted_decider_flies_the_tracking_pattern() {
        let mut d = ScriptedDecider::new(10.0, 6, "safety");
        let act = |d: &mut ScriptedDecider, o: Observations| {
            let id = d.step(&o).0.vehicle_actions[0];
            d.actions.name(id).to_string()
        };
        assert_eq!(
            act(&mut d, obs(0.0, &[("altitude_m", 0.0)], &[])),
            "take_off"
        );
        assert_eq!(
            act(&mut d, obs(5.0, &[("altitude_m", 9.5)], &[])),
            "follow_trajectory"
        );
        assert_eq!(
            act(
                &mut d,
                obs(6.0, &[("altitude_m", 20.0)], &["obstacle detected"])
            ),
            "avoid_obstacle"
        );
        assert_eq!(
            act(&mut d, obs(8.0, &[("altitude_m", 20.0)], &[])),
            "avoid_obstacle"
        );
        assert_eq!(
            act(&mut d, obs(11.0, &[("altitude_m", 20.0)], &[])),
            "follow_trajectory"
        );
        assert_eq!(
            act(
                &mut d,
                obs(
                    50.0,
                    &[
                        ("altitude_m", 20.0),
                        ("mission_seq", 6.0),
                        ("groundspeed_mps", 0.2)
                    ],
                    &[]
                )
            ),
            "land"
        );
        let mut d = ScriptedDecider::new(10.0, 6, "safety");
        assert_eq!(
            act(&mut d, obs(0.0, &[("battery_pct", 15.0)], &[])),
            "return_to_base"
        );
    }
}
