//! One scheduling decision for the full application set (tracking, landing search, obstacle
//! detection, obstacle avoidance, path planning), with and without a failed tile (the failure
//! forces the policy's degrade/drop resolution); `schedule` (fresh outputs) and `schedule_into`
//! (reused workspace, as the decision cycle calls it).

use criterion::{Criterion, criterion_group, criterion_main};
use fpga_model::*;
use std::hint::black_box;

fn setup() -> (Platform, Catalogue, PoliciesFile) {
    let platform: Platform = toml::from_str(include_str!("../../params/platform.toml")).unwrap();
    let file: VariantsFile = toml::from_str(include_str!("../../params/variants.toml")).unwrap();
    let catalogue = Catalogue::new(file.variant, &platform).unwrap();
    let mut policies: PoliciesFile =
        toml::from_str(include_str!("../../params/resource_policies.toml")).unwrap();
    for (name, p) in policies.iter_mut() {
        p.name = name.clone();
    }
    (platform, catalogue, policies)
}

fn bench(c: &mut Criterion) {
    let (platform, catalogue, policies) = setup();
    let requests = vec![
        Request::new("tracking", "V3", 25.0),
        Request::new("landing_search", "emergency", 5.0),
        Request::new("obstacle_detection", "lidar", 10.0),
        Request::new("obstacle_avoidance", "right_turn", 1.0),
        Request::new("path_planning", "ga", 0.5),
    ];
    let healthy = PlatformState::new(&platform);
    let mut faulty = healthy.clone();
    faulty.fail_tile(3);
    for (label, state) in [("healthy", &healthy), ("tile_failed", &faulty)] {
        for policy in ["safety", "mission"] {
            let pol = &policies[policy];
            c.bench_function(&format!("schedule/full_set/{label}/{policy}"), |b| {
                b.iter(|| {
                    schedule(
                        &platform,
                        &catalogue,
                        pol,
                        black_box(state),
                        black_box(&requests),
                    )
                })
            });
            // The decision cycle's path: reused workspace and outputs (no allocation).
            let mut ws = ScheduleWorkspace::new();
            let mut out = Schedule::default();
            let mut next = PlatformState::default();
            c.bench_function(&format!("schedule_into/full_set/{label}/{policy}"), |b| {
                b.iter(|| {
                    schedule_into(
                        &platform,
                        &catalogue,
                        pol,
                        black_box(state),
                        black_box(&requests),
                        &mut ws,
                        &mut out,
                        &mut next,
                    );
                    black_box(out.free_tiles)
                })
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
