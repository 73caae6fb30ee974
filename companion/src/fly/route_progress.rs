//! Which derived activity `fly` is flying (`route_activity`, docs/guarantee.md): from the
//! mission estimate's phase (take-off, search, tracking, landing, as `crate::sim_plan` maps
//! them), and on the route's legs from the mission item being flown (MISSION_CURRENT's seq:
//! the waypoint flown to) and the position (how far along the leg, so which zone piece).

use crate::route_input::PlanSummary;
use companion_core::mission::{MissionStates, RouteRole};
use companion_core::observations::Observations;
use companion_core::route_plan::{ActivityKind, Position, distance_m};
use companion_link::actions::{Route, Waypoint};

/// The derived plan's activities against the route flown.
#[derive(Debug, Clone)]
pub struct RouteProgress {
    kinds: Vec<ActivityKind>,
    /// Per route waypoint (flight order): the leg pieces flying to it, each (activity index,
    /// fraction of the leg at its end).
    legs: Vec<Vec<(usize, f64)>>,
    waypoints: Vec<Waypoint>,
    states: MissionStates,
}

impl RouteProgress {
    /// `None` when the plan is the typed one (no derived activities: the core falls back to
    /// `activity_of_state`).
    pub fn new(plan: &PlanSummary, route: &Route, states: MissionStates) -> Option<Self> {
        if plan.derived.is_empty() {
            return None;
        }
        let label = |w: usize| {
            if w == 0 {
                "home".to_string()
            } else {
                w.to_string()
            }
        };
        let legs = (1..=route.waypoints.len())
            .map(|w| {
                // The derived leg to waypoint w is `leg{w-1}-{w}`, split `.1`, `.2`, ... at zones.
                let base = format!("leg{}-{}", label(w - 1), w);
                let pieces: Vec<(usize, f64)> = (plan.derived.iter().enumerate())
                    .filter(|(_, a)| {
                        a.kind == ActivityKind::Leg
                            && (a.name == base
                                || a.name.strip_prefix(base.as_str()).is_some_and(|r| {
                                    r.starts_with('.') && r[1..].parse::<u32>().is_ok()
                                }))
                    })
                    .map(|(i, a)| (i, a.length_m))
                    .collect();
                let total: f64 = pieces.iter().map(|p| p.1).sum();
                let mut run = 0.0;
                pieces
                    .into_iter()
                    .map(|(i, len)| {
                        run += len;
                        (i, if total > 0.0 { run / total } else { 1.0 })
                    })
                    .collect()
            })
            .collect();
        Some(Self {
            kinds: plan.derived.iter().map(|a| a.kind).collect(),
            legs,
            waypoints: route.waypoints.clone(),
            states,
        })
    }

    /// The activity being flown; `wp1_seq`: the mission seq of the route's first waypoint;
    /// `home`: the autopilot's (HOME_POSITION, lat/lon * 1e7).
    pub fn activity(
        &self,
        obs: &Observations,
        wp1_seq: u16,
        home: Option<(i32, i32, f64)>,
    ) -> Option<usize> {
        let role = self.states.route().role_of(&obs.state);
        let tracking = self.states.is_tracking(&obs.state);
        if tracking
            || !matches!(
                role,
                Some(RouteRole::FirstLeg | RouteRole::BetweenWaypoints)
            )
        {
            return crate::sim_plan::activity_of_phase(&self.kinds, role, tracking, 0, 1);
        }
        let n = self.legs.len();
        let seq = obs
            .get("mission_seq")
            .filter(|s| s.is_finite())
            .unwrap_or(0.0);
        // The waypoint flown to, 1-based (the first leg before MISSION_CURRENT says more).
        let w = ((seq - f64::from(wp1_seq)).max(0.0) as usize + 1).clamp(1, n.max(1));
        let pieces = self.legs.get(w - 1).filter(|p| !p.is_empty())?;
        let along = self.along(w, obs, home).unwrap_or(0.0);
        let piece = pieces.iter().find(|p| along <= p.1).or(pieces.last())?;
        Some(piece.0)
    }

    /// How far (0..1) along the leg to waypoint `w` the vehicle is, by its position.
    fn along(&self, w: usize, obs: &Observations, home: Option<(i32, i32, f64)>) -> Option<f64> {
        let (lat, lon) = (obs.get("lat_deg")?, obs.get("lon_deg")?);
        let (hl, ho, _) = home?;
        let home = (f64::from(hl) / 1e7, f64::from(ho) / 1e7);
        let at = |k: usize| -> (f64, f64) {
            match k.checked_sub(1).and_then(|i| self.waypoints.get(i)) {
                None => home,
                Some(Waypoint::Relative {
                    north_m, east_m, ..
                }) => {
                    let p = Position::offset(home, *north_m, *east_m, 0.0);
                    (p.lat_deg, p.lon_deg)
                }
                Some(Waypoint::Absolute { lat_e7, lon_e7, .. }) => {
                    (f64::from(*lat_e7) / 1e7, f64::from(*lon_e7) / 1e7)
                }
            }
        };
        let (from, to) = (at(w - 1), at(w));
        let leg = distance_m(from, to);
        let left = distance_m((lat, lon), to);
        (leg > 0.0 && left.is_finite()).then(|| (1.0 - left / leg).clamp(0.0, 1.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn progress() -> (RouteProgress, PlanSummary) {
        let params = crate::params::default_params_dir();
        let (loaded, plan) =
            crate::route_input::load_with_plan(&params, None, None, None, None).unwrap();
        let states = loaded.model.states.clone();
        let p = RouteProgress::new(&plan, &loaded.route, states).unwrap();
        (p, plan)
    }

    fn obs(state: &str, seq: f64, pos: Option<(f64, f64)>) -> Observations {
        let mut o = Observations {
            state: state.into(),
            ..Default::default()
        };
        o.set("mission_seq", seq);
        if let Some((lat, lon)) = pos {
            o.set("lat_deg", lat);
            o.set("lon_deg", lon);
        }
        o
    }

    /// On the default route and zones at SITL's home: the mission item flown to picks the leg,
    /// the position picks the zone piece (the canyon 100..160 m north), and the phases give
    /// take-off, search, tracking and landing.
    #[test]
    fn the_mission_item_and_the_position_name_the_leg_piece() {
        let (p, plan) = progress();
        let name = |a: Option<usize>| plan.derived[a.unwrap()].name.clone();
        let home = (-35.363261, 149.165230);
        let h = Some(((home.0 * 1e7) as i32, (home.1 * 1e7) as i32, 584.0));
        let north = |m: f64| {
            let q = Position::offset(home, m, 0.0, 0.0);
            Some((q.lat_deg, q.lon_deg))
        };
        // wp1 is mission seq 2 (take-off at 1).
        assert_eq!(name(p.activity(&obs("base", 0.0, None), 2, h)), "take_off");
        assert_eq!(
            name(p.activity(&obs("wp1", 2.0, north(20.0)), 2, h)),
            "leghome-1"
        );
        assert_eq!(
            name(p.activity(&obs("wpi", 3.0, north(70.0)), 2, h)),
            "leg1-2.1"
        );
        assert_eq!(
            name(p.activity(&obs("wpi", 3.0, north(130.0)), 2, h)),
            "leg1-2.2"
        );
        assert_eq!(
            name(p.activity(&obs("wpi", 3.0, north(180.0)), 2, h)),
            "leg1-2.3"
        );
        // Without a position: the leg's first piece.
        assert_eq!(name(p.activity(&obs("wpi", 3.0, None), 2, h)), "leg1-2.1");
        assert_eq!(
            name(p.activity(&obs("wpi", 4.0, north(200.0)), 2, h)),
            "leg2-3"
        );
        assert_eq!(name(p.activity(&obs("wpf", 5.0, None), 2, h)), "search");
        assert_eq!(
            name(p.activity(&obs("target", 5.0, None), 2, h)),
            "tracking"
        );
        assert_eq!(name(p.activity(&obs("v3", 5.0, None), 2, h)), "tracking");
        assert_eq!(name(p.activity(&obs("landing", 5.0, None), 2, h)), "land");
        // A seq beyond the route, NaN: clamped to the route's legs, never a panic.
        assert_eq!(name(p.activity(&obs("wpi", 99.0, None), 2, h)), "leg3-4.1");
        assert_eq!(
            name(p.activity(&obs("wpi", f64::NAN, None), 2, h)),
            "leghome-1"
        );
    }
}
