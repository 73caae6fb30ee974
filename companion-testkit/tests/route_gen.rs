//! The route benchmark's mission is what it says: 1,000 waypoints whose legs cross each of the
//! 50 zones, and the shipped tracking mission plans the derived activities.

use companion_core::guarantee::{Guarantee, derive_settings, derived_mission};
use companion_core::route_plan::{ActivityKind, derive_activities, parse_plan, parse_zones};
use companion_testkit::route_gen;
use std::path::Path;

#[test]
fn the_generated_plan_crosses_every_zone_and_is_planned() {
    let files =
        companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap();
    let settings = derive_settings(&files, "tracking").unwrap();
    let zones = parse_zones(Path::new("z"), &route_gen::zones(1000, 50)).unwrap();
    let route = parse_plan(
        Path::new("p"),
        &route_gen::plan(1000),
        settings.cruise_speed_mps,
    )
    .unwrap();
    assert_eq!(route.items.len(), 1003);
    let acts = derive_activities(&route, &zones, &settings);
    // Every zone is entered by some leg: a leg piece in it, and the sources name all 50.
    for z in 0..50 {
        let name = format!("in zone z{z}");
        assert!(
            acts.iter()
                .any(|a| a.kind == ActivityKind::Leg && a.source.ends_with(&name)),
            "zone z{z} not crossed"
        );
    }
    let spec = derived_mission(&files, "tracking", &acts, &[(Path::new("z"), &zones)]).unwrap();
    assert_eq!(spec.problem.activities.len(), acts.len());
    // The allocation runs to an answer (feasible or an honest infeasible), without panicking.
    let _ = Guarantee::pre_flight(&spec);
}
