//! Which derived activity `fly` is flying (`route_activity`, docs/guarantee.md): from the
//! mission estimate's phase (take-off, search, tracking, landing, as `crate::sim_plan` maps
//! them), and on the mission's legs from the mission item being flown (MISSION_CURRENT's seq:
//! the item flown to) and the position (how far along the leg, so which zone piece). The same
//! for every mission: the route TOML, an operator's `.plan` or WPL file, the autopilot's own.

use crate::route_input::PlanSummary;
use companion_core::mission::{MissionStates, RouteRole};
use companion_core::observations::Observations;
use companion_core::route_plan::{
    ActivityKind, DerivedActivity, Item, ItemKind, Position, distance_m,
};
use companion_link::actions::{Route, Waypoint};

/// Where a leg ends, as the vehicle will find it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Place {
    /// The autopilot's home (RTL).
    Home,
    /// Metres north and east of the autopilot's home (a relative route TOML).
    Relative { north_m: f64, east_m: f64 },
    /// Latitude and longitude (degrees).
    Absolute { lat_deg: f64, lon_deg: f64 },
}

/// One item the mission flies to: its mission seq, where it is, and the leg pieces flying to it
/// (activity index, fraction of the leg at the piece's end).
#[derive(Debug, Clone)]
struct Target {
    seq: u16,
    place: Place,
    pieces: Vec<(usize, f64)>,
    /// An item after the last waypoint (RTL, LAND at a point): followed whatever the phase.
    after_route: bool,
}

/// The derived plan's activities against the mission flown.
#[derive(Debug, Clone)]
pub struct RouteProgress {
    kinds: Vec<ActivityKind>,
    targets: Vec<Target>,
    /// Where the first leg starts (home; a re-plan's point reached).
    start: Place,
    states: MissionStates,
    /// The last activity found: the flight goes forward (an autopilot's MISSION_CURRENT that
    /// falls back after its RTL never takes the plan back to a leg flown), until on the ground.
    last: Option<usize>,
    /// The mission's take-off item's seq: while MISSION_CURRENT is on it the vehicle is still
    /// climbing (the shell took off lower, the item climbs the rest), the `take_off` activity.
    takeoff_seq: Option<u16>,
}

/// EXTENDED_SYS_STATE's landed state while the autopilot descends to land (ArduCopter's RTL
/// final descent and LAND, PX4's land): the plan's `land`, whatever item or phase it is in (an
/// RTL item lands at home with the mission estimate still at the last waypoint).
const LANDING: &str = "LANDING";

/// The leg pieces of `derived` (from activity `from` on) flying to the item labelled `label`
/// (`leg{a}-{label}`, split `.1`, `.2`, ... at zones; `return` for RTL), with the fraction of
/// the leg at each piece's end.
fn pieces(derived: &[DerivedActivity], from: usize, label: &str, rtl: bool) -> Vec<(usize, f64)> {
    let unsplit = |n: &str| -> String {
        // A re-plan's activity named as a flown one is `new:`-prefixed.
        let n = n.strip_prefix("new:").unwrap_or(n);
        match n.rsplit_once('.') {
            Some((base, k)) if k.parse::<u32>().is_ok() => base.to_string(),
            _ => n.to_string(),
        }
    };
    let found: Vec<(usize, f64)> = (derived.iter().enumerate().skip(from))
        .filter(|(_, a)| {
            let base = unsplit(&a.name);
            if rtl {
                a.kind == ActivityKind::Return
            } else {
                a.kind == ActivityKind::Leg
                    && base
                        .strip_prefix("leg")
                        .and_then(|r| r.rsplit_once('-'))
                        .is_some_and(|(_, to)| to == label)
            }
        })
        .map(|(i, a)| (i, a.length_m))
        .collect();
    let total: f64 = found.iter().map(|p| p.1).sum();
    let mut run = 0.0;
    found
        .into_iter()
        .map(|(i, len)| {
            run += len;
            (i, if total > 0.0 { run / total } else { 1.0 })
        })
        .collect()
}

impl RouteProgress {
    /// The project's route TOML: waypoint w (1-based) at seq w (+1 after a take-off item).
    /// `None` when the plan is the typed one (no derived activities: the core falls back to
    /// `activity_of_state`).
    pub fn new(plan: &PlanSummary, route: &Route, states: MissionStates) -> Option<Self> {
        if plan.derived.is_empty() {
            return None;
        }
        let wp1 = route.first_waypoint_seq();
        let targets = (route.waypoints.iter().enumerate())
            .map(|(k, w)| Target {
                seq: wp1 + k as u16,
                place: match *w {
                    Waypoint::Relative {
                        north_m, east_m, ..
                    } => Place::Relative { north_m, east_m },
                    Waypoint::Absolute { lat_e7, lon_e7, .. } => Place::Absolute {
                        lat_deg: f64::from(lat_e7) / 1e7,
                        lon_deg: f64::from(lon_e7) / 1e7,
                    },
                },
                pieces: pieces(&plan.derived, 0, &(k + 1).to_string(), false),
                after_route: false,
            })
            .collect();
        Some(Self {
            kinds: plan.derived.iter().map(|a| a.kind).collect(),
            targets,
            start: Place::Home,
            states,
            last: None,
            takeoff_seq: None,
        })
    }

    /// Any mission as planned items (a `.plan`, a WPL file, the autopilot's mission): each item
    /// flying to a position with its mission seq (`seq_of` its file index; `None`: not
    /// uploaded), the activities derived from it (`derived[from..]`; those before are flown
    /// already, a re-plan's), the first leg starting at `start` (lat, lon; home when `None`).
    pub fn for_items(
        derived: &[DerivedActivity],
        from: usize,
        items: &[Item],
        seq_of: impl Fn(usize) -> Option<u16>,
        start: Option<(f64, f64)>,
        states: MissionStates,
    ) -> Option<Self> {
        if derived.is_empty() {
            return None;
        }
        let mut targets = Vec::new();
        let mut route_over = false;
        let takeoff_seq = (items.iter())
            .find(|i| matches!(i.kind, ItemKind::TakeOff { .. }))
            .and_then(|i| seq_of(i.index));
        for it in items {
            let (place, rtl) = match it.kind {
                ItemKind::Waypoint(p)
                | ItemKind::Loiter { at: p, .. }
                | ItemKind::Land { at: Some(p) } => (absolute(p), false),
                ItemKind::ReturnToLaunch => (Place::Home, true),
                _ => continue,
            };
            let after_route = route_over || rtl || matches!(it.kind, ItemKind::Land { .. });
            route_over = after_route;
            let Some(seq) = seq_of(it.index) else {
                continue;
            };
            targets.push(Target {
                seq,
                place,
                pieces: pieces(derived, from, &it.index.to_string(), rtl),
                after_route,
            });
        }
        Some(Self {
            kinds: derived.iter().map(|a| a.kind).collect(),
            targets,
            start: start.map_or(Place::Home, |(lat_deg, lon_deg)| Place::Absolute {
                lat_deg,
                lon_deg,
            }),
            states,
            last: None,
            takeoff_seq,
        })
    }

    /// The activity being flown; `home`: the autopilot's (HOME_POSITION, lat/lon * 1e7).
    pub fn activity(&mut self, obs: &Observations, home: Option<(i32, i32, f64)>) -> Option<usize> {
        self.activity_landing(obs, home, None)
    }

    /// [`Self::activity`] with the autopilot's landed state (EXTENDED_SYS_STATE): `LANDING` is
    /// the plan's `land`.
    pub fn activity_landing(
        &mut self,
        obs: &Observations,
        home: Option<(i32, i32, f64)>,
        landed_state: Option<&str>,
    ) -> Option<usize> {
        let land = (self.kinds.iter()).rposition(|k| *k == ActivityKind::Land);
        let found = match land {
            Some(l) if landed_state == Some(LANDING) => Some(l),
            _ => self.found(obs, home),
        };
        let on_ground = self.states.route().role_of(&obs.state) == Some(RouteRole::OnGround);
        let kept = match (found, self.last) {
            (Some(a), Some(l)) if a < l && !on_ground => Some(l),
            (a, _) => a,
        };
        self.last = kept;
        kept
    }

    fn found(&self, obs: &Observations, home: Option<(i32, i32, f64)>) -> Option<usize> {
        let role = self.states.route().role_of(&obs.state);
        let tracking = self.states.is_tracking(&obs.state);
        let seq = obs
            .get("mission_seq")
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(0.0);
        // The item flown to: the first at or after MISSION_CURRENT's seq (the first leg before
        // MISSION_CURRENT says more; a seq beyond the mission: its last item).
        let k = (self.targets.iter())
            .position(|t| f64::from(t.seq) >= seq)
            .unwrap_or(self.targets.len().saturating_sub(1));
        let target = self.targets.get(k);
        let on_legs = matches!(
            role,
            Some(RouteRole::FirstLeg | RouteRole::BetweenWaypoints)
        );
        // Before the mission's take-off item is done (MISSION_CURRENT on it, or still 0 while
        // the shell's own take-off ends and the mission starts) the vehicle is taking off.
        let climbing = self.takeoff_seq.is_some_and(|t| seq <= f64::from(t));
        if climbing && on_legs {
            return (self.kinds.iter()).position(|k| *k == ActivityKind::TakeOff);
        }
        // An RTL or a LAND at a point after the last waypoint is flown as a leg whatever the
        // mission estimate's phase says (until the landing itself).
        let after = target.is_some_and(|t| t.after_route && f64::from(t.seq) == seq)
            && !matches!(role, Some(RouteRole::Landing));
        if tracking || !(on_legs || after) {
            return crate::sim_plan::activity_of_phase(&self.kinds, role, tracking, 0, 1);
        }
        let t = target.filter(|t| !t.pieces.is_empty())?;
        let from = match k.checked_sub(1) {
            Some(j) => self.targets[j].place,
            None => self.start,
        };
        let along = self.along(from, t.place, obs, home).unwrap_or(0.0);
        let piece = t.pieces.iter().find(|p| along <= p.1).or(t.pieces.last())?;
        Some(piece.0)
    }

    /// How far (0..1) along the leg `from -> to` the vehicle is, by its position.
    fn along(
        &self,
        from: Place,
        to: Place,
        obs: &Observations,
        home: Option<(i32, i32, f64)>,
    ) -> Option<f64> {
        let (lat, lon) = (obs.get("lat_deg")?, obs.get("lon_deg")?);
        let (hl, ho, _) = home?;
        let home = (f64::from(hl) / 1e7, f64::from(ho) / 1e7);
        let at = |p: Place| -> (f64, f64) {
            match p {
                Place::Home => home,
                Place::Relative { north_m, east_m } => {
                    let q = Position::offset(home, north_m, east_m, 0.0);
                    (q.lat_deg, q.lon_deg)
                }
                Place::Absolute { lat_deg, lon_deg } => (lat_deg, lon_deg),
            }
        };
        let (from, to) = (at(from), at(to));
        let leg = distance_m(from, to);
        let left = distance_m((lat, lon), to);
        (leg > 0.0 && left.is_finite()).then(|| (1.0 - left / leg).clamp(0.0, 1.0))
    }
}

fn absolute(p: Position) -> Place {
    Place::Absolute {
        lat_deg: p.lat_deg,
        lon_deg: p.lon_deg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The progress without its memory of the last activity (each query on its own).
    pub(super) fn fresh(p: &mut RouteProgress) -> &mut RouteProgress {
        p.last = None;
        p
    }

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
        let (mut p, plan) = progress();
        let name = |a: Option<usize>| plan.derived[a.unwrap()].name.clone();
        let home = (-35.363261, 149.165230);
        let h = Some(((home.0 * 1e7) as i32, (home.1 * 1e7) as i32, 584.0));
        let north = |m: f64| {
            let q = Position::offset(home, m, 0.0, 0.0);
            Some((q.lat_deg, q.lon_deg))
        };
        // wp1 is mission seq 2 (take-off at 1).
        assert_eq!(
            name(fresh(&mut p).activity(&obs("base", 0.0, None), h)),
            "take_off"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 2.0, north(20.0)), h)),
            "leghome-1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 3.0, north(70.0)), h)),
            "leg1-2.1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 3.0, north(130.0)), h)),
            "leg1-2.2"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 3.0, north(180.0)), h)),
            "leg1-2.3"
        );
        // Without a position: the leg's first piece.
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 3.0, None), h)),
            "leg1-2.1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 4.0, north(200.0)), h)),
            "leg2-3"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpf", 5.0, None), h)),
            "search"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("target", 5.0, None), h)),
            "tracking"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("v3", 5.0, None), h)),
            "tracking"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("landing", 5.0, None), h)),
            "land"
        );
        // A seq beyond the route, NaN: clamped to the route's legs, never a panic.
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 99.0, None), h)),
            "leg3-4.1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", f64::NAN, None), h)),
            "leghome-1"
        );
    }
}

#[cfg(test)]
mod operator_tests {
    use super::tests::fresh;
    use super::*;
    use companion_core::route_plan::{parse_plan, parse_zones};
    use std::path::Path;

    /// A zone over lon 0.001..0.002 on the equator: the leg to lon 0.003 crosses it in thirds.
    const ZONES: &str = r#"{"type":"FeatureCollection","features":[{"type":"Feature",
     "properties":{"name":"canyon","constraints":["gps_degraded"]},
     "geometry":{"type":"Polygon","coordinates":[[[0.001,-0.001],[0.002,-0.001],[0.002,0.001],[0.001,0.001],[0.001,-0.001]]]}}]}"#;

    /// Take-off, a speed change, a waypoint east across the zone, one north, RTL.
    const PLAN: &str = r#"{"fileType":"Plan","version":1,"mission":{"plannedHomePosition":[0,0,0],"items":[
     {"type":"SimpleItem","command":22,"frame":3,"params":[0,0,0,null,0,0,20]},
     {"type":"SimpleItem","command":178,"frame":2,"params":[1,5,-1,0,0,0,0]},
     {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0,0.003,20]},
     {"type":"SimpleItem","command":16,"frame":3,"params":[0,0,0,null,0.001,0.003,20]},
     {"type":"SimpleItem","command":20,"frame":2,"params":[0,0,0,0,0,0,0]}]}}"#;

    fn obs(state: &str, seq: f64, lat: f64, lon: f64) -> Observations {
        let mut o = Observations {
            state: state.into(),
            ..Default::default()
        };
        o.set("mission_seq", seq);
        o.set("lat_deg", lat);
        o.set("lon_deg", lon);
        o
    }

    /// An operator's `.plan` uploaded by `fly`: MISSION_CURRENT's seq (item k at seq k + 1)
    /// picks the leg, the position the zone piece; the RTL item is the return, followed as a
    /// leg after the last waypoint.
    #[test]
    fn an_operator_plans_items_are_followed_by_their_upload_seq_and_the_position() {
        let files = crate::params::read_params_dir(&crate::params::default_params_dir()).unwrap();
        let s = companion_core::guarantee::derive_settings(&files, "tracking").unwrap();
        let planned = parse_plan(Path::new("m.plan"), PLAN, s.cruise_speed_mps).unwrap();
        let zones = parse_zones(Path::new("z.geojson"), ZONES).unwrap();
        let derived = companion_core::route_plan::derive_activities(&planned, &zones, &s);
        let (route, seqs) = crate::operator_mission::operator_route(
            &planned,
            companion_link::actions::RouteEnd::ReturnToLaunch,
        );
        assert_eq!(route.operator_items.len(), 5);
        assert_eq!(seqs, [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]);
        let seq_of = |i: usize| seqs.iter().find(|x| x.0 == i).map(|x| x.1);
        let states = companion_core::mission::MissionStates::load(&files).unwrap();
        let mut p =
            RouteProgress::for_items(&derived, 0, &planned.items, seq_of, None, states).unwrap();
        let name = |a: Option<usize>| derived[a.unwrap()].name.clone();
        let h = Some((0, 0, 0.0));
        assert_eq!(
            name(fresh(&mut p).activity(&obs("base", 0.0, 0.0, 0.0), h)),
            "take_off"
        );
        // Flying to item 2 (seq 3): the piece by the position.
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 3.0, 0.0, 0.0005), h)),
            "leghome-2.1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 3.0, 0.0, 0.0015), h)),
            "leghome-2.2"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 3.0, 0.0, 0.0025), h)),
            "leghome-2.3"
        );
        // The shell took off lower: MISSION_CURRENT on the take-off item (seq 1), or still 0
        // before the mission starts, is the climb.
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 1.0, 0.0, 0.0), h)),
            "take_off"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 0.0, 0.0, 0.0), h)),
            "take_off"
        );
        // The speed change (seq 2) is flown on the way to item 2.
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wp1", 2.0, 0.0, 0.0), h)),
            "leghome-2.1"
        );
        assert_eq!(
            name(fresh(&mut p).activity(&obs("wpi", 4.0, 0.0005, 0.003), h)),
            "leg2-3"
        );
        // After the last waypoint the RTL (seq 5) is the return, split by the zone too.
        let back = fresh(&mut p).activity(&obs("wpf", 5.0, 0.0005, 0.0025), h);
        assert!(name(back).starts_with("return"), "{}", name(back));
        assert_eq!(
            name(fresh(&mut p).activity(&obs("landing", 5.0, 0.0, 0.0), h)),
            "land"
        );
        // The RTL item's own descent at home, the mission estimate still at the last waypoint:
        // the autopilot's LANDING is the land.
        let over_home = obs("wpf", 5.0, 0.0, 0.0);
        assert!(name(fresh(&mut p).activity(&over_home, h)).starts_with("return"));
        assert_eq!(
            name(fresh(&mut p).activity_landing(&over_home, h, Some("LANDING"))),
            "land"
        );
        // Forward only: once on the return, an autopilot's MISSION_CURRENT falling back (after
        // its RTL) keeps the return, not a leg flown; on the ground the next flight starts over.
        let back = fresh(&mut p).activity(&obs("wpf", 5.0, 0.0005, 0.0025), h);
        assert_eq!(p.activity(&obs("wpf", 0.0, 0.0, 0.0), h), back);
        assert_eq!(name(p.activity(&obs("base", 0.0, 0.0, 0.0), h)), "take_off");
    }
}
