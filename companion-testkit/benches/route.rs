//! PANORAMA P1 and the pre-flight allocation on an operator's mission: a generated 1,000-waypoint
//! QGroundControl `.plan` crossing 50 GeoJSON zones, parsed from text, split into activities and
//! allocated on the shipped tracking mission; and the re-plan in flight from the middle (the mission
//! changed there: the rest re-derived from the point reached and re-allocated from it). Target: 50 ms
//! on one core each, docs/performance.md.

use companion_core::guarantee::{
    Guarantee, PackReading, Progress, derive_settings, derived_mission,
};
use companion_core::route_plan::{
    ItemKind, derive_activities, derive_activities_from, parse_plan, parse_zones,
};
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
    // In flight at the middle waypoint, the ground station changes the mission (the same one
    // here: the work is the same): re-derive the rest from the point reached, splice it after the
    // activities flown, compile, and re-allocate from there with what was spent kept.
    let acts = derive_activities(&route, &zones, &settings);
    let spec = derived_mission(&files, "tracking", &acts, &[(zones_path, &zones)]).unwrap();
    let mut g = Guarantee::start_or_unbounded(spec).unwrap();
    let nav: Vec<_> = (route.items.iter())
        .filter_map(|i| match i.kind {
            ItemKind::Waypoint(p) => Some((i.index, p)),
            _ => None,
        })
        .collect();
    let (mid_index, here) = nav[nav.len() / 2];
    let flown = (acts.iter())
        .position(|a| {
            a.name.ends_with(&format!("-{mid_index}")) || a.name.contains(&format!("-{mid_index}."))
        })
        .unwrap();
    let _ = g.watch(Progress {
        activity_index: flown,
        activity_fraction: 0.0,
        energy_used_j: None,
        battery_remaining_pct: Some(55.0),
        elapsed_s: 600.0,
        failed_resources: &[],
        pack: PackReading::default(),
    });
    c.bench_function("route_replan_from_middle_1000wp_50zones", |b| {
        b.iter(|| {
            let mut rest = route.clone();
            rest.items
                .retain(|i| i.index >= mid_index || matches!(i.kind, ItemKind::ChangeSpeed { .. }));
            let mut spliced = acts[..flown].to_vec();
            spliced.extend(derive_activities_from(&rest, &zones, &settings, Some(here)));
            let spec =
                derived_mission(&files, "tracking", &spliced, &[(zones_path, &zones)]).unwrap();
            black_box(g.replan_from(spec, flown).map(|g| g.choice().len()))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
