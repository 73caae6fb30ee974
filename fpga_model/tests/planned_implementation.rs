//! A request that names the implementation a plan asks for (PANORAMA's `V3.F`) gets it when it
//! meets the rate and fits; otherwise the just-enough choice stands, as without a plan.

mod common;
use common::{params, placed};
use fpga_model::{Implementation::*, *};

fn tracking(fps: f64) -> Request {
    Request::new("tracking", "V3", fps)
}

#[test]
fn without_a_plan_the_slowest_implementation_that_meets_the_rate_runs() {
    let p = params();
    let healthy = PlatformState::new(&p.platform);
    let (s, _) = schedule(
        &p.platform,
        &p.catalogue,
        &p.safety,
        &healthy,
        &[tracking(1.0)],
    );
    assert_eq!(placed(&s, "tracking").unwrap().implementation, S);
}

#[test]
fn a_planned_implementation_that_meets_the_rate_and_fits_runs() {
    let p = params();
    let healthy = PlatformState::new(&p.platform);
    for want in [M, F] {
        let req = [tracking(1.0).preferring(want)];
        let (s, _) = schedule(&p.platform, &p.catalogue, &p.safety, &healthy, &req);
        let t = placed(&s, "tracking").unwrap();
        assert_eq!((t.version.as_str(), t.implementation), ("V3", want));
        assert!(s.degraded.is_empty() && s.dropped.is_empty());
    }
}

#[test]
fn a_planned_implementation_that_does_not_fit_gives_way_to_just_enough() {
    let p = params();
    // One healthy tile: V3 F needs two.
    let mut one_tile = PlatformState::new(&p.platform);
    for t in 1..p.platform.tiles {
        one_tile.fail_tile(t);
    }
    let req = [tracking(1.0).preferring(F)];
    let (s, _) = schedule(&p.platform, &p.catalogue, &p.safety, &one_tile, &req);
    assert_eq!(placed(&s, "tracking").unwrap().implementation, S);
}

#[test]
fn a_planned_implementation_too_slow_for_the_rate_is_not_taken() {
    let p = params();
    let healthy = PlatformState::new(&p.platform);
    // 25 fps: only V3 F (10 ms) is fast enough (Table 2), whatever the plan says.
    let req = [tracking(25.0).preferring(S)];
    let (s, _) = schedule(&p.platform, &p.catalogue, &p.safety, &healthy, &req);
    assert_eq!(placed(&s, "tracking").unwrap().implementation, F);
}
