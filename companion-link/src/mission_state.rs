//! The shared mission state (`base`, `wp1`, `wpi`, `wpf`, `target`, `v0`..`v5`, `landing`) as
//! the fly shell observes it, for `Observations.state`. Those are the shipped names: the estimator
//! reports whichever states params/mission.toml `[route_states]` names for each point of the route
//! (`RouteRole`), and the tracking states the mission declares.
//!
//! Why in the shell: the decision core is pure and learns where the mission is only from its
//! observations; the simulation world computes the state from its own bookkeeping
//! (companion/src/sim.rs), the real vehicle from telemetry and route progress. The rules follow
//! the simulation's phase transitions (docs/simulation.md) so the same core flies both:
//! `base` until airborne; `wp1` while flying to the route's first waypoint; `wpi` through the
//! intermediate ones; `wpf` once the last one is reached (the tracking area); `target` when the
//! onboard tracker reports the target there, `vN` while the last plan ran `track_vN` on it;
//! `landing` (sticky) once a landing action was commanded, the autopilot flies LAND/RTL, or the
//! vehicle is back on the ground disarmed after a flight.
//!
//! Landing is a phase with its own action, not a dead end: the MDPs see `landing` as terminal,
//! so while the vehicle is still in the air the shell keeps flying the landing action chosen
//! (after an avoidance sidestep, a refused or timed-out LAND, ...), see
//! [`MissionState::landing_action`]. The flight is over only when the vehicle reports itself on
//! the ground and disarmed for `landed_confirm_s` over at least two cycles: a disarmed heartbeat
//! at altitude (spoofed or corrupt) neither starts the landing nor ends the flight.

use super::actions::Route;
use super::modes::FlightMode;
use companion_core::mission::{ActionCatalogue, ActionRole, MissionStates, RouteRole};
use companion_core::observations::Observations;
use companion_core::vocabulary::ActionId;

/// Inputs that are not observations (telemetry the estimator needs besides `Observations`).
#[derive(Debug, Clone, Default)]
pub struct Extra<'a> {
    /// The flight mode the autopilot reports, when it is one the companion speaks of.
    pub mode: Option<FlightMode>,
    /// EXTENDED_SYS_STATE landed state (`ON_GROUND`, `IN_AIR`, `TAKEOFF`, `LANDING`), once
    /// reported.
    pub landed_state: Option<&'a str>,
    /// How long every autopilot frame has agreed that the vehicle is disarmed on the ground
    /// (s; 0 when the last one disagreed), when the caller watches frames (the fly shell). The
    /// flight then ends only after `landed_confirm_s` of it: a frame in between that says
    /// otherwise restarts the wait, so spoofed "landed" frames between the autopilot's own
    /// cannot end a flight.
    pub down_for_s: Option<f64>,
}

/// Mission-state estimator; one per flight.
#[derive(Debug, Clone)]
pub struct MissionState {
    /// Mission sequence number of the route's first waypoint (`wp1`).
    pub wp1_seq: u16,
    /// Mission sequence number of the last waypoint (`wpf`).
    pub last_seq: u16,
    /// Altitude above home from which the take-off counts as done (m).
    pub airborne_m: f64,
    /// `target_detected` above this is a detection.
    pub detection_threshold: f64,
    /// Below this ground speed at the last waypoint the route is finished (m/s).
    pub arrived_speed_mps: f64,
    /// While the autopilot still flies *to* the last waypoint (MISSION_CURRENT is its seq), slow
    /// counts as arrived only after this long (s, the autopilot's clock): the turn at the
    /// waypoint before also slows it, just after MISSION_CURRENT moved on (PX4 SIH: 1.1-1.9 m/s
    /// at a 90-degree corner in six flights, 2.4 m/s a second later; a CI rehearsal's run dipped
    /// below 1 m/s there and started the search 30 m short). A mission that ends at its last
    /// waypoint hovers there for good. Past the last waypoint's seq (the mission's own end
    /// items) slow is arrived at once.
    pub arrived_hold_s: f64,
    /// Mission end: land after tracking this long (s); see the route file.
    pub tracking_time_limit_s: Option<f64>,
    /// Mission end: land when the target is not found this long after reaching wpf (s).
    pub search_time_limit_s: Option<f64>,
    state: String,
    flown: bool,
    landing: bool,
    finished: bool,
    /// AUTO was seen after take-off: the route is on the vehicle (resume instead of re-upload).
    auto_seen: bool,
    /// Tracking version the last plan ran (`v3` for `track_v3`).
    tracking: Option<String>,
    wpf_at: Option<f64>,
    /// Since when (the autopilot's clock) the vehicle has been slow with MISSION_CURRENT on the
    /// last waypoint's seq, without a break.
    slow_at_last_since: Option<f64>,
    tracking_since: Option<f64>,
    /// Why the shell ended the mission, once.
    end_reason: Option<MissionEnd>,
    /// On the ground and disarmed this long (s, shell clock) ends the flight.
    pub landed_confirm_s: f64,
    /// Without a landed state: disarmed below this altitude (m) is on the ground.
    pub ground_altitude_m: f64,
    /// Since when (shell clock) and in how many cycles the vehicle has reported itself on the
    /// ground and disarmed without a break.
    ground_since: Option<(f64, u32)>,
    landing_action: Option<ActionId>,
    /// The mission's states and phases (params/mission.toml).
    states: MissionStates,
    /// The action catalogue the shell's ids index (params/actions.toml).
    actions: ActionCatalogue,
    /// The role of each action of `actions`, by id.
    roles: Vec<Option<ActionRole>>,
    /// The tracking state each action of `actions` keeps (`track_v3` keeps `v3`), by id.
    keeping: Vec<Option<String>>,
}

impl MissionState {
    /// Mission-state estimator for `route`; armed at or above 0.8 * `takeoff_alt_m` (m above
    /// home) counts as airborne. Actions are ids of `actions`.
    pub fn new(
        route: &Route,
        takeoff_alt_m: f64,
        states: MissionStates,
        actions: &ActionCatalogue,
    ) -> Self {
        let roles = actions
            .actions
            .iter()
            .map(|a| states.actions().role_of(&a.id))
            .collect();
        let keeping = (actions.actions.iter())
            .map(|a| {
                states
                    .tracking_target([&a.id])
                    .map(|(kept, _)| kept.to_string())
            })
            .collect();
        let first = route.first_waypoint_seq();
        // The mission's own end (search loiter, RTL or LAND) follows wpf: past it the vehicle is
        // still at or beyond the last waypoint (`seq >= last_seq`).
        let last = route.last_waypoint_seq();
        Self {
            wp1_seq: first,
            last_seq: last.max(first),
            airborne_m: 0.8 * takeoff_alt_m,
            detection_threshold: 0.5,
            arrived_speed_mps: 1.0,
            arrived_hold_s: 2.0,
            tracking_time_limit_s: route.tracking_time_limit_s,
            search_time_limit_s: route.search_time_limit_s,
            state: states.route_state(RouteRole::OnGround).to_string(),
            flown: false,
            landing: false,
            finished: false,
            auto_seen: false,
            tracking: None,
            wpf_at: None,
            slow_at_last_since: None,
            tracking_since: None,
            end_reason: None,
            landed_confirm_s: 3.0,
            ground_altitude_m: 1.0,
            ground_since: None,
            landing_action: None,
            states,
            actions: actions.clone(),
            roles,
            keeping,
        }
    }

    /// The mission's states and phases this estimator moves through.
    pub fn states(&self) -> &MissionStates {
        &self.states
    }

    /// The landing action the shell keeps flying in the landing phase (the roles land, replan
    /// and land, return to base): the last one chosen, or the one matching the landing mode the
    /// vehicle entered. None before the landing phase.
    pub fn landing_action(&self) -> Option<ActionId> {
        if self.landing && !self.finished {
            self.landing_action
        } else {
            None
        }
    }

    /// The role action `id` plays (params/actions.toml).
    pub fn role(&self, id: ActionId) -> Option<ActionRole> {
        self.roles.get(id.index()).copied().flatten()
    }

    /// Whether action `id` ends the flight ([`ActionRole::ends_flight`]: land, replan and land,
    /// return to base).
    pub fn is_landing_action(&self, id: ActionId) -> bool {
        self.role(id).is_some_and(ActionRole::ends_flight)
    }

    /// The action playing `role` (the first in file order for a role several play).
    pub fn action(&self, role: ActionRole) -> Option<ActionId> {
        let at = self.roles.iter().position(|r| *r == Some(role))?;
        self.actions.id(&self.actions.actions[at].id)
    }

    /// The action catalogue whose ids this estimator speaks.
    pub fn actions(&self) -> &ActionCatalogue {
        &self.actions
    }

    /// The tracking state the action set `actions` (ids of [`MissionState::actions`]) aims at:
    /// the one the first action keeping a tracking state keeps (`track_v3` keeps `v3`).
    pub fn tracking_target(&self, actions: impl IntoIterator<Item = ActionId>) -> Option<&str> {
        (actions.into_iter()).find_map(|a| self.keeping.get(a.index()).and_then(Option::as_deref))
    }

    /// The name of action `id`, for a record.
    pub fn name(&self, id: ActionId) -> &str {
        self.actions.name(id)
    }

    /// On the ground and disarmed now: EXTENDED_SYS_STATE says ON_GROUND (when the autopilot
    /// reports it), else the altitude is below `ground_altitude_m`.
    fn on_ground(&self, obs: &Observations, extra: &Extra) -> bool {
        let armed = obs.get("armed").unwrap_or(0.0) > 0.5;
        let low = match extra.landed_state {
            Some(s) => s == "ON_GROUND",
            None => obs
                .get("altitude_m")
                .is_some_and(|a| a <= self.ground_altitude_m),
        };
        !armed && low
    }

    /// The shared mission state as estimated now (`base`, `wp1`, `target`, ...).
    pub fn state(&self) -> &str {
        &self.state
    }

    /// Flew, then landed and disarmed: the run is over.
    pub fn finished(&self) -> bool {
        self.finished
    }

    /// The vehicle has been airborne in this flight (armed at or above `airborne_m`).
    pub fn flown(&self) -> bool {
        self.flown
    }

    /// The route was uploaded and flown in AUTO once.
    pub fn route_on_vehicle(&self) -> bool {
        self.auto_seen
    }

    /// Whether the vehicle is at the last waypoint, slow: past its seq (the mission's own end
    /// items, the search loiter at wpf) at once, on its seq after [`MissionState::arrived_hold_s`].
    fn arrived(&mut self, seq: Option<u16>, speed: f64, clock: f64) -> bool {
        let slow = speed < self.arrived_speed_mps;
        let on_last = slow && seq == Some(self.last_seq);
        self.slow_at_last_since = if on_last {
            Some(self.slow_at_last_since.unwrap_or(clock))
        } else {
            None
        };
        (slow && seq.is_some_and(|s| s > self.last_seq))
            || (self.slow_at_last_since).is_some_and(|t0| clock - t0 >= self.arrived_hold_s)
    }

    /// Update from one snapshot; returns the state for `obs.state`.
    pub fn update(&mut self, obs: &Observations, extra: &Extra) -> &str {
        let clock = mission_clock(obs);
        let armed = obs.get("armed").unwrap_or(0.0) > 0.5;
        let alt = obs.get("altitude_m").unwrap_or(0.0);
        let seq = obs.get("mission_seq").map(|s| s as u16);
        let speed = obs.get("groundspeed_mps").unwrap_or(f64::INFINITY);
        let detected = obs.get("target_detected").unwrap_or(0.0) > self.detection_threshold;
        let mode = extra.mode;
        if armed && alt >= self.airborne_m {
            self.flown = true;
        }
        if self.flown && mode == Some(FlightMode::Auto) {
            self.auto_seen = true;
        }
        if self.flown && matches!(mode, Some(FlightMode::Land | FlightMode::Rtl)) {
            self.landing = true;
            if self.landing_action.is_none() {
                let role = if mode == Some(FlightMode::Rtl) {
                    ActionRole::ReturnToBase
                } else {
                    ActionRole::Land
                };
                self.landing_action = self.action(role);
            }
        }
        let t = obs.time_s;
        self.ground_since = if self.on_ground(obs, extra) {
            let (since, n) = self.ground_since.unwrap_or((t, 0));
            Some((since, n + 1))
        } else {
            None
        };
        let frames_agree = extra.down_for_s.is_none_or(|d| d >= self.landed_confirm_s);
        if self.flown
            && frames_agree
            && let Some((since, n)) = self.ground_since
            && n >= 2
            && t - since >= self.landed_confirm_s
        {
            self.landing = true;
            self.finished = true;
        }
        let arrived = self.arrived(seq, speed, clock);
        let route = self.states.route();
        let named = |role: RouteRole| route.state(role).to_string();
        if self.landing {
            self.state = named(RouteRole::Landing);
            return &self.state;
        }
        // Reached the last waypoint once: the rest of the flight is in the tracking area.
        let past = route.is(RouteRole::LastWaypoint, &self.state)
            || self.states.is_target_in_sight(&self.state);
        self.state = if !self.flown {
            named(RouteRole::OnGround)
        } else if past || arrived {
            self.wpf_at.get_or_insert(clock);
            if detected {
                self.tracking_since.get_or_insert(clock);
                self.tracking
                    .clone()
                    .unwrap_or_else(|| named(RouteRole::TargetFound))
            } else {
                self.tracking = None;
                named(RouteRole::LastWaypoint)
            }
        } else if seq.is_some_and(|s| s > self.wp1_seq) {
            named(RouteRole::BetweenWaypoints)
        } else {
            named(RouteRole::FirstLeg)
        };
        &self.state
    }

    /// Waypoints not yet reached (the `waypoints_remaining` observation).
    pub fn waypoints_remaining(&self, obs: &Observations) -> f64 {
        match self.states.route().role_of(&self.state) {
            Some(RouteRole::OnGround | RouteRole::FirstLeg) => {
                (self.last_seq - self.wp1_seq + 1) as f64
            }
            Some(RouteRole::BetweenWaypoints) => {
                let seq = obs.get("mission_seq").unwrap_or(0.0) as u16;
                (self.last_seq + 1).saturating_sub(seq.max(self.wp1_seq)) as f64
            }
            _ => 0.0,
        }
    }

    /// After the core's decision: remember the tracking version it runs and whether it chose to
    /// land. `actions` are ids of this estimator's catalogue ([`MissionState::actions`]).
    pub fn after_plan(&mut self, actions: impl IntoIterator<Item = ActionId> + Clone) {
        let keeping = |a: ActionId| self.keeping.get(a.index()).and_then(Option::as_deref);
        match actions.clone().into_iter().find_map(keeping) {
            Some(kept) if self.tracking.as_deref() != Some(kept) => {
                self.tracking = Some(kept.to_string());
            }
            Some(_) => {}
            None => self.tracking = None,
        }
        if self.flown
            && let Some(a) = (actions.into_iter()).find(|&a| self.is_landing_action(a))
        {
            self.landing = true;
            self.landing_action = Some(a);
        }
    }

    /// The mission's own end (not a decision of the core, which tracks for as long as it can):
    /// after tracking for `tracking_time_limit_s`, or searching at wpf for `search_time_limit_s`
    /// without a target, the mission script lands. Returns the reason once. Times are on the
    /// mission clock (see [`mission_clock`]).
    pub fn mission_end(&mut self, obs: &Observations) -> Option<MissionEnd> {
        let time_s = mission_clock(obs);
        if self.landing || self.end_reason.is_some() {
            return None;
        }
        let reason = match (self.tracking_since, self.wpf_at) {
            (Some(t0), _) if self.tracking_time_limit_s.is_some_and(|l| time_s - t0 >= l) => {
                MissionEnd::TrackingTimeLimit(self.tracking_time_limit_s.unwrap_or(0.0))
            }
            (None, Some(t0)) if self.search_time_limit_s.is_some_and(|l| time_s - t0 >= l) => {
                MissionEnd::SearchTimeLimit(self.search_time_limit_s.unwrap_or(0.0))
            }
            _ => return None,
        };
        self.end_reason = Some(reason.clone());
        Some(reason)
    }

    /// Why the shell ended this flight's mission, once it did.
    pub fn end(&self) -> Option<&MissionEnd> {
        self.end_reason.as_ref()
    }
}

/// Why the mission script ended the mission (the shell then lands).
#[derive(Debug, Clone, PartialEq)]
pub enum MissionEnd {
    /// Tracked for the route's `tracking_time_limit_s` (the limit, s).
    TrackingTimeLimit(f64),
    /// Searched at the last waypoint for `search_time_limit_s` without a target (the limit, s).
    SearchTimeLimit(f64),
}

impl std::fmt::Display for MissionEnd {
    /// The decision record's sentence (docs/decision-log.md).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MissionEnd::TrackingTimeLimit(l) => {
                write!(f, "mission: tracking time limit {l:.0} s reached")
            }
            MissionEnd::SearchTimeLimit(l) => write!(
                f,
                "mission: search time limit {l:.0} s reached without a target"
            ),
        }
    }
}

/// The autopilot's clock (`vehicle_time_s`, from SYSTEM_TIME.time_boot_ms) when known, so a
/// SITL running faster than real time flies the same mission; else the shell's clock.
pub fn mission_clock(obs: &Observations) -> f64 {
    obs.get("vehicle_time_s").unwrap_or(obs.time_s)
}

/// One motion at a time: the autopilot flies one vehicle action, so when the core's plan holds
/// several (its behaviour arbitration leaves e.g. `return_to_base` with `follow_trajectory`), the
/// first in `precedence` (params/link.toml `vehicle_action_precedence`) wins; actions not listed
/// come after, in plan order.
/// Actions and precedence are ids in the fly shell (the precedence resolved once), names in tests.
pub fn select_vehicle_action<'a, A: PartialEq>(
    actions: &'a [A],
    precedence: &[A],
) -> Option<&'a A> {
    precedence
        .iter()
        .find_map(|p| actions.iter().find(|a| *a == p))
        .or_else(|| actions.first())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn states() -> MissionStates {
        let dir = crate::test_support::default_params_dir();
        let mut files = companion_core::spec::ParamsFiles::new(&dir);
        for name in ["mission.toml", "actions.toml"] {
            files.insert(
                dir.join(name),
                std::fs::read_to_string(dir.join(name)).unwrap(),
            );
        }
        MissionStates::load(&files).unwrap()
    }

    fn catalogue() -> ActionCatalogue {
        crate::test_support::catalogue()
    }

    /// The ids of `names` in `m`'s catalogue.
    fn ids(m: &MissionState, names: &[&str]) -> Vec<ActionId> {
        names.iter().map(|n| m.actions().id(n).unwrap()).collect()
    }

    /// The landing action's name.
    fn landing(m: &MissionState) -> Option<&str> {
        m.landing_action().map(|a| m.name(a))
    }

    fn route() -> Route {
        crate::test_support::disk(Route::load)(
            &crate::test_support::default_params_dir().join("missions/tracking_route.toml"),
        )
        .unwrap()
    }

    fn obs(t: f64, vals: &[(&str, f64)]) -> Observations {
        let mut o = Observations {
            time_s: t,
            ..Default::default()
        };
        for (k, v) in vals {
            o.set(k, *v);
        }
        o
    }

    #[test]
    fn follows_the_simulation_phases_on_the_default_route() {
        // Default route: seq 0 home, 1 take-off, 2 wp1, 3 and 4 intermediate, 5 wpf.
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        let none = Extra::default();
        let auto = Extra {
            mode: Some(FlightMode::Auto),
            ..Extra::default()
        };
        assert_eq!((m.wp1_seq, m.last_seq), (2, 5));
        assert_eq!(m.update(&obs(0.0, &[("armed", 0.0)]), &none), "base");
        assert_eq!(
            m.update(&obs(1.0, &[("armed", 1.0), ("altitude_m", 5.0)]), &none),
            "base"
        );
        let fly = |seq: f64, spd: f64, det: f64| {
            [
                ("armed", 1.0),
                ("altitude_m", 20.0),
                ("mission_seq", seq),
                ("groundspeed_mps", spd),
                ("target_detected", det),
            ]
        };
        assert_eq!(m.update(&obs(2.0, &fly(1.0, 0.0, 0.0)), &auto), "wp1");
        assert_eq!(m.update(&obs(3.0, &fly(2.0, 5.0, 1.0)), &auto), "wp1");
        assert_eq!(m.update(&obs(4.0, &fly(3.0, 5.0, 1.0)), &auto), "wpi");
        assert_eq!(m.waypoints_remaining(&obs(4.0, &fly(3.0, 5.0, 1.0))), 3.0);
        // flying the last leg is not arriving
        assert_eq!(m.update(&obs(5.0, &fly(5.0, 5.0, 1.0)), &auto), "wpi");
        // slow on the last waypoint's seq: a turn or the arrival; arrived once it lasts 2 s
        assert_eq!(m.update(&obs(6.0, &fly(5.0, 0.2, 0.0)), &auto), "wpi");
        assert_eq!(m.update(&obs(8.0, &fly(5.0, 0.2, 0.0)), &auto), "wpf");
        assert_eq!(m.update(&obs(9.0, &fly(5.0, 0.2, 1.0)), &auto), "target");
        m.after_plan(ids(&m, &["detect_obstacles_lidar", "track_v3"]));
        assert_eq!(m.update(&obs(10.0, &fly(5.0, 0.2, 1.0)), &auto), "v3");
        assert_eq!(m.mission_end(&obs(10.0, &[])), None);
        m.after_plan(ids(&m, &["track_v2"]));
        assert_eq!(m.update(&obs(11.0, &fly(5.0, 0.2, 1.0)), &auto), "v2");
        // lost target: back to searching at wpf
        assert_eq!(m.update(&obs(12.0, &fly(5.0, 0.2, 0.0)), &auto), "wpf");
        assert!(m.route_on_vehicle());
        let limit = m.tracking_time_limit_s.unwrap();
        // the autopilot's clock wins over the shell's
        let at = |shell: f64, vehicle: f64| obs(shell, &[("vehicle_time_s", vehicle)]);
        assert_eq!(m.mission_end(&at(9.0 + limit, 0.0)), None);
        assert!(m.mission_end(&at(0.0, 9.0 + limit)).is_some());
        assert_eq!(
            m.mission_end(&at(9.0 + limit + 1.0, 0.0)),
            None,
            "reported once"
        );
        m.after_plan(ids(&m, &["land"]));
        assert_eq!(m.update(&obs(30.0, &fly(5.0, 0.0, 1.0)), &auto), "landing");
        assert_eq!(landing(&m), Some("land"));
        assert!(!m.finished());
        let down = [("armed", 0.0), ("altitude_m", 0.1)];
        assert_eq!(m.update(&obs(40.0, &down), &none), "landing");
        assert!(!m.finished(), "on the ground for one cycle only");
        assert_eq!(m.update(&obs(43.0, &down), &none), "landing");
        assert!(m.finished());
        assert_eq!(landing(&m), None);
    }

    /// The uploaded mission goes on past wpf (the search loiter at wpf, then RTL or LAND): the
    /// loiter item flown at wpf is arriving there, the end items are still past it, and they
    /// count no waypoint.
    #[test]
    fn the_missions_own_end_after_wpf_is_still_the_tracking_area() {
        let r = route();
        let mut m = MissionState::new(&r, 10.0, states(), &catalogue());
        let items = r.items((473_977_420, 85_455_940));
        assert_eq!(m.last_seq, 5);
        assert_eq!(
            items[6].command,
            crate::dialect::MavCmd::MAV_CMD_NAV_LOITER_TIME
        );
        let auto = Extra {
            mode: Some(FlightMode::Auto),
            ..Extra::default()
        };
        let fly = |seq: f64, spd: f64| {
            [
                ("armed", 1.0),
                ("altitude_m", 20.0),
                ("mission_seq", seq),
                ("groundspeed_mps", spd),
            ]
        };
        assert_eq!(m.update(&obs(1.0, &fly(4.0, 5.0)), &auto), "wpi");
        // ArduCopter makes the loiter current as it reaches wpf, still moving: not arrived yet.
        assert_eq!(m.update(&obs(2.0, &fly(6.0, 4.0)), &auto), "wpi");
        assert_eq!(m.update(&obs(3.0, &fly(6.0, 0.1)), &auto), "wpf");
        assert_eq!(m.waypoints_remaining(&obs(3.0, &fly(6.0, 0.1))), 0.0);
        assert_eq!(m.update(&obs(4.0, &fly(7.0, 6.0)), &auto), "wpf");
    }

    /// PX4 makes the last waypoint current as it turns at the one before, where it slows (SIH:
    /// 1.1-1.9 m/s at a 90-degree corner): a dip below the arrival speed there is not wpf,
    /// hovering on the last waypoint's seq is, after `arrived_hold_s`; the hold restarts when the
    /// vehicle speeds up again.
    #[test]
    fn slowing_in_the_turn_before_the_last_waypoint_is_not_arriving() {
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        let auto = Extra {
            mode: Some(FlightMode::Auto),
            ..Extra::default()
        };
        let at = |t: f64, seq: f64, spd: f64| {
            let vals = [
                ("armed", 1.0),
                ("altitude_m", 20.0),
                ("mission_seq", seq),
                ("groundspeed_mps", spd),
                ("vehicle_time_s", t),
            ];
            obs(100.0, &vals)
        };
        assert_eq!((m.last_seq, m.arrived_hold_s), (5, 2.0));
        assert_eq!(m.update(&at(10.0, 4.0, 2.0), &auto), "wpi");
        // the turn: MISSION_CURRENT moved on, the vehicle slowest just after
        assert_eq!(m.update(&at(10.5, 5.0, 0.6), &auto), "wpi");
        assert_eq!(m.update(&at(11.5, 5.0, 0.9), &auto), "wpi");
        assert_eq!(m.update(&at(12.0, 5.0, 2.4), &auto), "wpi");
        // slow again later (a gust, a slow-down): the hold counts from here, by the vehicle's clock
        assert_eq!(m.update(&at(13.0, 5.0, 0.5), &auto), "wpi");
        assert_eq!(m.update(&at(14.9, 5.0, 0.2), &auto), "wpi");
        assert_eq!(m.update(&at(15.0, 5.0, 0.1), &auto), "wpf");
        assert_eq!(
            m.update(&at(16.0, 5.0, 3.0), &auto),
            "wpf",
            "wpf reached stays"
        );
    }

    fn flying() -> [(&'static str, f64); 3] {
        [("armed", 1.0), ("altitude_m", 20.0), ("mission_seq", 3.0)]
    }

    #[test]
    fn one_disarmed_heartbeat_at_altitude_neither_lands_nor_ends_the_flight() {
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        let auto = Extra {
            mode: Some(FlightMode::Auto),
            landed_state: Some("IN_AIR"),
            ..Extra::default()
        };
        assert_eq!(m.update(&obs(1.0, &flying()), &auto), "wpi");
        // One heartbeat says disarmed; altitude and landed state say flying.
        let spoofed = [("armed", 0.0), ("altitude_m", 20.0), ("mission_seq", 3.0)];
        for t in [2.0, 2.5, 6.0] {
            assert_eq!(m.update(&obs(t, &spoofed), &auto), "wpi");
            assert!(!m.finished());
        }
        assert_eq!(landing(&m), None);
        assert_eq!(m.update(&obs(7.0, &flying()), &auto), "wpi");
    }

    #[test]
    fn the_flight_ends_only_after_ground_and_disarm_hold_for_the_confirm_time() {
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        let in_air = Extra {
            mode: Some(FlightMode::Land),
            landed_state: Some("IN_AIR"),
            ..Extra::default()
        };
        let on_ground = Extra {
            mode: Some(FlightMode::Land),
            landed_state: Some("ON_GROUND"),
            ..Extra::default()
        };
        m.update(&obs(1.0, &flying()), &in_air);
        assert_eq!(landing(&m), Some("land"), "LAND mode is the landing phase");
        let down = [("armed", 0.0), ("altitude_m", 0.0)];
        // Disarmed but the autopilot says in the air: not over.
        m.update(&obs(2.0, &down), &in_air);
        m.update(&obs(9.0, &down), &in_air);
        assert!(!m.finished());
        // ON_GROUND and disarmed, then a break (armed again), then held long enough.
        m.update(&obs(10.0, &down), &on_ground);
        m.update(
            &obs(11.0, &[("armed", 1.0), ("altitude_m", 0.0)]),
            &on_ground,
        );
        m.update(&obs(12.0, &down), &on_ground);
        m.update(&obs(14.0, &down), &on_ground);
        assert!(!m.finished(), "the confirm time restarts after a break");
        m.update(&obs(15.0, &down), &on_ground);
        assert!(m.finished());
        // Without a landed state, the altitude decides.
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        m.update(&obs(1.0, &flying()), &Extra::default());
        let high = [("armed", 0.0), ("altitude_m", 15.0)];
        m.update(&obs(2.0, &high), &Extra::default());
        m.update(&obs(9.0, &high), &Extra::default());
        assert!(!m.finished());
        m.update(&obs(10.0, &down), &Extra::default());
        m.update(&obs(13.0, &down), &Extra::default());
        assert!(m.finished());
    }

    #[test]
    fn landed_snapshots_end_the_flight_only_when_every_frame_agreed_for_the_confirm_time() {
        // Spoofed "disarmed on the ground" frames make every snapshot look landed, but the
        // autopilot's own armed heartbeats in between keep the frame window short.
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        m.update(&obs(1.0, &flying()), &Extra::default());
        let down = [("armed", 0.0), ("altitude_m", 0.0)];
        let spoofed = |d: f64| Extra {
            landed_state: Some("ON_GROUND"),
            down_for_s: Some(d),
            ..Extra::default()
        };
        for (i, t) in [2.0, 3.0, 4.0, 5.0, 6.0, 7.0].into_iter().enumerate() {
            m.update(&obs(t, &down), &spoofed(0.2 * i as f64 % 0.9));
            assert!(!m.finished(), "at {t} s");
        }
        m.update(&obs(8.0, &down), &spoofed(3.0));
        assert!(m.finished());
    }

    #[test]
    fn autopilot_landing_modes_and_disarm_mean_landing() {
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        let flying = [("armed", 1.0), ("altitude_m", 15.0), ("mission_seq", 2.0)];
        assert_eq!(m.update(&obs(1.0, &flying), &Extra::default()), "wp1");
        let rtl = Extra {
            mode: Some(FlightMode::Rtl),
            ..Extra::default()
        };
        assert_eq!(m.update(&obs(2.0, &flying), &rtl), "landing");
        assert_eq!(landing(&m), Some("return_to_base"));
        // a disarmed vehicle that never flew is at base, not landing
        let mut m = MissionState::new(&route(), 10.0, states(), &catalogue());
        assert_eq!(m.update(&obs(1.0, &[("armed", 0.0)]), &rtl), "base");
        assert!(!m.finished());
    }

    /// The shipped mission states with every route state (and its phase) renamed `r_NAME`.
    fn renamed_states() -> MissionStates {
        let dir = crate::test_support::default_params_dir();
        let mut text = std::fs::read_to_string(dir.join("mission.toml")).unwrap();
        for x in ["base", "wp1", "wpi", "wpf", "target", "landing"] {
            text = text
                .replace(&format!("\"{x}\""), &format!("\"r_{x}\""))
                .replace(&format!(" {x} = "), &format!(" r_{x} = "));
        }
        let mut files = companion_core::spec::ParamsFiles::new(&dir);
        files.insert(dir.join("mission.toml"), text);
        files.insert(
            dir.join("actions.toml"),
            std::fs::read_to_string(dir.join("actions.toml")).unwrap(),
        );
        MissionStates::load(&files).unwrap()
    }

    #[test]
    fn the_estimator_names_the_route_states_the_params_give() {
        let renamed = renamed_states();
        assert!(!renamed.has_state("wpf") && renamed.has_state("r_wpf"));
        let (mut old, mut new) = (
            MissionState::new(&route(), 10.0, states(), &catalogue()),
            MissionState::new(&route(), 10.0, renamed, &catalogue()),
        );
        assert_eq!((old.state(), new.state()), ("base", "r_base"));
        let auto = Extra {
            mode: Some(FlightMode::Auto),
            ..Extra::default()
        };
        let fly = |t: f64, seq: f64, spd: f64, det: f64| {
            obs(
                t,
                &[
                    ("armed", 1.0),
                    ("altitude_m", 20.0),
                    ("mission_seq", seq),
                    ("groundspeed_mps", spd),
                    ("target_detected", det),
                ],
            )
        };
        // (snapshot, plan after it, the shipped state expected)
        let flight: Vec<(Observations, Vec<&str>, &str)> = vec![
            (obs(0.0, &[("armed", 0.0)]), vec![], "base"),
            (fly(1.0, 1.0, 0.0, 0.0), vec![], "wp1"),
            (fly(2.0, 3.0, 5.0, 0.0), vec![], "wpi"),
            // the search loiter at wpf (seq 6) is current: arrived
            (fly(3.0, 6.0, 0.2, 0.0), vec![], "wpf"),
            (fly(4.0, 6.0, 0.2, 1.0), vec!["track_v3"], "target"),
            (fly(5.0, 6.0, 0.2, 1.0), vec![], "v3"),
            (fly(6.0, 6.0, 0.2, 1.0), vec!["land"], "target"),
            (fly(7.0, 6.0, 0.2, 1.0), vec![], "landing"),
        ];
        for (o, plan, expected) in flight {
            let (a, b) = (
                old.update(&o, &auto).to_string(),
                new.update(&o, &auto).to_string(),
            );
            assert_eq!(a, expected, "shipped names at t={}", o.time_s);
            let want = if expected.starts_with('v') {
                expected.to_string()
            } else {
                format!("r_{expected}")
            };
            assert_eq!(b, want, "renamed at t={}", o.time_s);
            assert_eq!(old.waypoints_remaining(&o), new.waypoints_remaining(&o));
            old.after_plan(ids(&old, &plan));
            new.after_plan(ids(&new, &plan));
        }
        assert_eq!(landing(&new), Some("land"));
    }

    #[test]
    fn precedence_picks_one_motion() {
        let p: Vec<String> = ["avoid_obstacle", "return_to_base", "follow_trajectory"]
            .map(String::from)
            .to_vec();
        let a = |xs: &[&str]| xs.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            select_vehicle_action(&a(&["follow_trajectory", "return_to_base"]), &p)
                .map(String::as_str),
            Some("return_to_base")
        );
        assert_eq!(
            select_vehicle_action(&a(&["follow_trajectory", "avoid_obstacle"]), &p)
                .map(String::as_str),
            Some("avoid_obstacle")
        );
        assert_eq!(
            select_vehicle_action(&a(&["take_off"]), &p).map(String::as_str),
            Some("take_off")
        );
        assert_eq!(select_vehicle_action(&[], &p), None::<&String>);
    }
}
