//! PANORAMA P1 and the pre-flight allocation on an operator's mission: a generated 1,000-waypoint
//! QGroundControl `.plan` crossing 50 GeoJSON zones, parsed from text, split into activities and
//! allocated on the shipped tracking mission (target: 50 ms on one core, docs/performance.md).

use companion_core::guarantee::{Guarantee, derive_settings, derived_mission};
use companion_core::route_plan::{derive_activities, parse_plan, parse_zones};
use companion_testkit::route_gen;
use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let files =
        companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap();
    let plan_text = route_gen::plan(1000);
    let zones_text = route_gen::zones(1000, 50);
    let (plan_path, zones_path) = (Path::new("bench.plan"), Path::new("bench.geojson"));
    let settings = derive_settings(&files, "tracking").unwrap();
    let zones = parse_zones(zones_path, &zones_text).unwrap();
    let route = parse_plan(plan_path, &plan_text, settings.cruise_speed_mps).unwrap();
    c.bench_function("route_derive_activities_1000wp_50zones", |b| {
        b.iter(|| derive_activities(black_box(&route), black_box(&zones), &settings))
    });
    c.bench_function("route_parse_derive_and_preflight_1000wp_50zones", |b| {
        b.iter(|| {
            let zones = parse_zones(zones_path, black_box(&zones_text)).unwrap();
            let route =
                parse_plan(plan_path, black_box(&plan_text), settings.cruise_speed_mps).unwrap();
            let acts = derive_activities(&route, &zones, &settings);
            let spec = derived_mission(&files, "tracking", &acts, &[(zones_path, &zones)]).unwrap();
            black_box(Guarantee::pre_flight(&spec).map(|r| r.totals))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
