//! Re-solving with a warmed-up workspace allocates nothing (counting global allocator; this test
//! binary has only this test so no other thread allocates meanwhile).

use mdp_engine::{Config, MdpBuilder, Workspace};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

// Only the test's own thread is counted: the harness's threads (output capture, the main thread
// waiting on the test) may allocate at any time.
std::thread_local! {
    static COUNTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if COUNTED.with(|c| c.get()) {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn warm_resolves_do_not_allocate() {
    COUNTED.with(|c| c.set(true));
    let mut b = MdpBuilder::new(4, 2);
    b.choice(0, 0, 1.0, &[(1, 0.5), (0, 0.5)])
        .choice(0, 1, 0.5, &[(2, 1.0)])
        .choice(1, 0, 2.0, &[(3, 1.0)])
        .choice(2, 0, 0.0, &[(0, 0.3), (3, 0.7)])
        .choice(2, 1, -1.0, &[(1, 1.0)]);
    let mut m = b.build().unwrap();
    let cfg = Config {
        gamma: 0.9,
        ..Config::default()
    };
    let mut ws = Workspace::new();
    let warm = |ws: &mut Workspace, m: &mdp_engine::Mdp| {
        let d = ws.finite_horizon(m, 100).decision(0);
        let a = ws.value_iteration(m, &cfg).unwrap().action(0);
        let b = ws.policy_iteration(m, &cfg).unwrap().action(0);
        let c = ws.modified_policy_iteration(m, &cfg).unwrap().action(0);
        (d, a, b, c)
    };
    let cold = ALLOCS.load(Ordering::SeqCst);
    warm(&mut ws, &m);
    // The counter works: the first solves grow the empty workspace.
    assert!(ALLOCS.load(Ordering::SeqCst) > cold);
    let before = ALLOCS.load(Ordering::SeqCst);
    for k in 0..10 {
        // New probabilities in place, then every solver again.
        let c = m.choice_index(0, 0).unwrap();
        let r = m.transition_range(c);
        let p = 0.1 + 0.08 * k as f64;
        m.probs_mut()[r.start] = p;
        m.probs_mut()[r.start + 1] = 1.0 - p;
        m.validate().unwrap();
        std::hint::black_box(warm(&mut ws, &m));
    }
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        before,
        "steady-state solves allocated"
    );

    // Alternating with a smaller model reuses the (larger) buffers.
    let mut b = MdpBuilder::new(2, 1);
    b.choice(0, 0, 1.0, &[(1, 1.0)])
        .choice(1, 0, 0.0, &[(0, 0.5), (1, 0.5)]);
    let small = b.build().unwrap();
    let before = ALLOCS.load(Ordering::SeqCst);
    for _ in 0..3 {
        std::hint::black_box(warm(&mut ws, &small));
        std::hint::black_box(warm(&mut ws, &m));
    }
    assert_eq!(
        ALLOCS.load(Ordering::SeqCst),
        before,
        "alternating model sizes allocated"
    );
}
