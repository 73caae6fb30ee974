//! Where the simulated world is on a derived plan (`route_activity`, docs/simulation.md): the
//! world flies the paper's abstract route (take-off, first leg, `route.waypoints` intermediate
//! waypoints, the tracking area), not the route's geometry, so its phases are mapped onto the
//! derived activities' kinds in flight order:
//!
//! | world (route role)                   | derived activity                                   |
//! |--------------------------------------|----------------------------------------------------|
//! | on the ground                        | the take-off                                       |
//! | first leg                            | the first leg                                      |
//! | intermediate waypoint k of N         | the leg k/(N+1) of the way through the legs        |
//! | last waypoint (searching)            | the search hold (else tracking, else the last leg) |
//! | target found or tracked              | the tracking hold (else the search)                |
//! | landing                              | the landing (the return, when any, is not flown)   |

use companion_core::mission::RouteRole;
use companion_core::route_plan::ActivityKind;

/// The derived activity (index, flight order) the world is flying; `None` when the plan has
/// none of the kinds the phase maps to (the core then falls back to `activity_of_state`).
pub fn activity_of_phase(
    plan: &[ActivityKind],
    role: Option<RouteRole>,
    tracking: bool,
    waypoint: u32,
    n_waypoints: u32,
) -> Option<usize> {
    let first = |k: ActivityKind| plan.iter().position(|x| *x == k);
    let legs: Vec<usize> = (plan.iter().enumerate())
        .filter(|(_, k)| **k == ActivityKind::Leg)
        .map(|(i, _)| i)
        .collect();
    let role = if tracking {
        Some(RouteRole::TargetFound)
    } else {
        role
    };
    match role? {
        RouteRole::OnGround => first(ActivityKind::TakeOff).or(Some(0)),
        RouteRole::FirstLeg => legs.first().copied(),
        RouteRole::BetweenWaypoints => {
            let progress = f64::from(waypoint.min(n_waypoints)) / f64::from(n_waypoints + 1);
            let k = (progress * legs.len() as f64) as usize;
            legs.get(k.min(legs.len().saturating_sub(1))).copied()
        }
        RouteRole::LastWaypoint => first(ActivityKind::Search)
            .or_else(|| first(ActivityKind::Tracking))
            .or_else(|| legs.last().copied()),
        RouteRole::TargetFound => {
            first(ActivityKind::Tracking).or_else(|| first(ActivityKind::Search))
        }
        RouteRole::Landing => first(ActivityKind::Land).or(plan.len().checked_sub(1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ActivityKind::*;

    /// The default route's plan: take-off, six leg pieces (two legs split by the canyon),
    /// search, tracking, land; the world's phases walk it in order.
    #[test]
    fn the_world_walks_the_derived_activities_in_flight_order() {
        let plan = [
            TakeOff, Leg, Leg, Leg, Leg, Leg, Leg, Leg, Leg, Search, Tracking, Land,
        ];
        let at = |role, tracking, k| activity_of_phase(&plan, Some(role), tracking, k, 3);
        let walk = [
            at(RouteRole::OnGround, false, 0),
            at(RouteRole::FirstLeg, false, 0),
            at(RouteRole::BetweenWaypoints, false, 1),
            at(RouteRole::BetweenWaypoints, false, 2),
            at(RouteRole::BetweenWaypoints, false, 3),
            at(RouteRole::LastWaypoint, false, 4),
            at(RouteRole::TargetFound, false, 4),
            at(RouteRole::LastWaypoint, true, 4),
            at(RouteRole::Landing, false, 4),
        ];
        assert_eq!(
            walk.map(Option::unwrap),
            [0, 1, 3, 5, 7, 9, 10, 10, 11],
            "take-off, legs in order, search, tracking, land"
        );
        // A plan without search or tracking: the last leg, then land.
        let short = [TakeOff, Leg, Land];
        assert_eq!(
            activity_of_phase(&short, Some(RouteRole::LastWaypoint), false, 3, 3),
            Some(1)
        );
        assert_eq!(
            activity_of_phase(&short, Some(RouteRole::TargetFound), false, 3, 3),
            None
        );
        assert_eq!(activity_of_phase(&plan, None, false, 0, 3), None);
    }
}
