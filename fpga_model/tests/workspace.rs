//! The reusable-workspace scheduler (`schedule_into`) against the scheduler as it was before it
//! (tests/common/reference.rs, kept verbatim): same schedule and same platform state after, on
//! random inputs well outside the params (unknown variants, duplicates, bad rates, random
//! priorities and degradation paths, foreign bitstreams, wrong tile counts), with one workspace
//! reused across a sequence of calls; and a warm run allocates nothing.

mod common;
// Shared with the companion tests, whose crate lints it; `pub` is how they reach it.
#[allow(unreachable_pub)]
#[path = "../../companion-testkit/tests/support/counting_alloc.rs"]
mod counting_alloc;

use common::params;
use common::reference::reference_schedule;
use fpga_model::*;
use proptest::prelude::*;

const APPS: [&str; 6] = [
    "tracking",
    "landing_search",
    "obstacle_detection",
    "obstacle_avoidance",
    "path_planning",
    "unknown_app",
];

/// Every version name of the catalogue plus one that exists nowhere.
fn versions() -> Vec<String> {
    let mut v: Vec<String> = params()
        .catalogue
        .variants()
        .iter()
        .map(|v| v.version.clone())
        .collect();
    v.sort();
    v.dedup();
    v.push("V9".into());
    v
}

/// Every bitstream tag of the catalogue plus a foreign one.
fn tags() -> Vec<String> {
    let mut t: Vec<String> = params()
        .catalogue
        .variants()
        .iter()
        .flat_map(|v| (0..v.tiles.max(1)).map(move |k| format!("{}#{k}", v.key())))
        .collect();
    t.push("foreign/bitstream/F#0".into());
    t
}

#[derive(Debug, Clone)]
struct Input {
    policy: ResourcePolicy,
    state: PlatformState,
    requests: Vec<Request>,
}

fn arb_fps() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => (-1.6f64..2.4).prop_map(|e| 10f64.powf(e)),
        1 => Just(f64::NAN),
        1 => Just(0.0),
        1 => Just(-3.0),
        1 => Just(f64::INFINITY),
    ]
}

fn arb_input() -> impl Strategy<Value = Input> {
    let nv = versions().len();
    let nt = tags().len();
    let request = (
        0..APPS.len(),
        0..nv,
        arb_fps(),
        prop::option::weighted(0.2, 0u32..7),
    );
    let tile = (prop::option::of(0..nt), prop::bool::weighted(0.2));
    // app -> from version -> path (indices into versions()).
    let degrade = prop::collection::vec(
        (0..APPS.len(), 0..nv, prop::collection::vec(0..nv, 0..4)),
        0..8,
    );
    (
        prop::collection::vec(request, 0..8),
        prop::collection::vec(tile, 0..7),
        0u8..=3,
        prop_oneof![Just(0.0), 0.0f64..1.2, Just(f64::NAN), Just(-0.5)],
        degrade,
        Just(APPS[..5].to_vec()).prop_shuffle(),
        any::<bool>(),
    )
        .prop_map(
            move |(reqs, tiles, cores, external, degrade, priority, from_params)| {
                let vs = versions();
                let ts = tags();
                let p = params();
                let mut policy = if from_params {
                    p.safety.clone()
                } else {
                    ResourcePolicy {
                        name: "random".into(),
                        description: String::new(),
                        priority: priority.iter().map(|s| s.to_string()).collect(),
                        degrade: Default::default(),
                    }
                };
                for (a, from, path) in degrade {
                    policy
                        .degrade
                        .entry(APPS[a].to_string())
                        .or_default()
                        .insert(
                            vs[from].clone(),
                            path.iter().map(|&i| vs[i].clone()).collect(),
                        );
                }
                let requests = reqs
                    .into_iter()
                    .map(|(a, v, fps, prio)| Request {
                        app: APPS[a].into(),
                        version: vs[v].clone(),
                        required_fps: fps,
                        priority: prio,
                        implementation: None,
                    })
                    .collect();
                let state = PlatformState {
                    tiles: tiles
                        .into_iter()
                        .map(|(b, failed)| Tile {
                            bitstream: b.map(|i| ts[i].clone()),
                            failed,
                        })
                        .collect(),
                    cores_online: cores,
                    external_cpu_load: external,
                };
                Input {
                    policy,
                    state,
                    requests,
                }
            },
        )
}

/// NaN-tolerant equality through the serialised form (NaN != NaN would fail `==` on equal
/// schedules, e.g. an `invalid required rate NaN fps` drop does not carry the NaN, but rates do).
fn same<T: std::fmt::Debug>(a: &T, b: &T) -> bool {
    format!("{a:?}") == format!("{b:?}")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]
    #[test]
    fn workspace_path_equals_the_reference(inputs in prop::collection::vec(arb_input(), 1..5)) {
        let p = params();
        let mut ws = ScheduleWorkspace::new();
        let mut out = Schedule::default();
        let mut next = PlatformState::default();
        for inp in &inputs {
            let (want, want_next) =
                reference_schedule(&p.platform, &p.catalogue, &inp.policy, &inp.state, &inp.requests);
            schedule_into(&p.platform, &p.catalogue, &inp.policy, &inp.state, &inp.requests,
                &mut ws, &mut out, &mut next);
            prop_assert!(same(&out, &want), "\n got {out:?}\nwant {want:?}");
            prop_assert!(same(&next, &want_next), "\n got {next:?}\nwant {want_next:?}");
            // The allocating wrapper is the same function.
            let (s, n) = schedule(&p.platform, &p.catalogue, &inp.policy, &inp.state, &inp.requests);
            prop_assert!(same(&s, &want) && same(&n, &want_next));
        }
    }
}

/// The reference really differs between inputs that the property compares (so agreement is not
/// two constant answers): a failed tile changes the full set's schedule.
#[test]
fn the_reference_is_not_constant() {
    let p = params();
    let reqs = full_set();
    let healthy = PlatformState::new(&p.platform);
    let mut one_failed = healthy.clone();
    one_failed.fail_tile(0);
    let (a, _) = reference_schedule(&p.platform, &p.catalogue, &p.safety, &healthy, &reqs);
    let (b, _) = reference_schedule(&p.platform, &p.catalogue, &p.safety, &one_failed, &reqs);
    assert_ne!(a, b);
}

fn full_set() -> Vec<Request> {
    vec![
        Request::new("tracking", "V3", 25.0),
        Request::new("landing_search", "emergency", 5.0),
        Request::new("obstacle_detection", "lidar", 10.0),
        Request::new("obstacle_avoidance", "right_turn", 1.0),
        Request::new("path_planning", "ga", 0.5),
    ]
}

/// Warm runs allocate nothing: the full set on a healthy board, then with failed tiles (the
/// policy degrades and drops: reasons are written), alternating, as the cycle does when a
/// tile fault comes and goes.
#[test]
fn a_warm_scheduler_run_allocates_nothing() {
    let p = params();
    let reqs = full_set();
    let mut states = vec![PlatformState::new(&p.platform)];
    for failed in 1..=3u8 {
        let mut s = PlatformState::new(&p.platform);
        for t in 0..failed {
            s.fail_tile(t);
        }
        states.push(s);
    }
    let mut ws = ScheduleWorkspace::new();
    let mut out = Schedule::default();
    let mut next = PlatformState::default();
    let mut run = |st: &PlatformState, policy: &ResourcePolicy| {
        schedule_into(
            &p.platform,
            &p.catalogue,
            policy,
            st,
            &reqs,
            &mut ws,
            &mut out,
            &mut next,
        );
        (out.degraded.len(), out.dropped.len())
    };
    // Warm up on every input (a few rounds: spare strings change hands between records, and
    // each keeps the largest capacity it was given), then count one more round.
    let mut shapes = Vec::new();
    for _ in 0..3 {
        shapes.clear();
        for st in &states {
            for policy in [&p.safety, &p.mission] {
                shapes.push(run(st, policy));
            }
        }
    }
    assert!(
        shapes.iter().any(|&(d, x)| d + x > 0),
        "some input must degrade or drop, or the test does not cover reasons: {shapes:?}"
    );
    let n = counting_alloc::allocations(|| {
        for st in &states {
            for policy in [&p.safety, &p.mission] {
                std::hint::black_box(run(st, policy));
            }
        }
    });
    assert_eq!(n, 0, "allocations in 8 warm scheduler runs");
}
