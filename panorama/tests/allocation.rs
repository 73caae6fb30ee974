//! The allocation algorithm against hand computations, a linear-scan reference, exhaustive search
//! and the branch-and-bound optimum; margins and re-allocation by hand.

use panorama::*;
use proptest::prelude::*;

fn ia(name: &str, cost: &[f64], cap: f64, res: &[&str]) -> Ia {
    Ia {
        name: name.into(),
        cost: cost.to_vec(),
        capability: cap,
        resources: res.iter().map(|s| s.to_string()).collect(),
    }
}

fn act(name: &str, ias: Vec<Ia>) -> Activity {
    Activity {
        name: name.into(),
        ias,
    }
}

/// Three activities, one goal (energy <= 10). Highest everywhere: 4+5+6 = 15 > 10.
/// Backwards: last activity alone cannot fix it (4+5+1 = 10 fits!) -> dichotomy in A3 picks the
/// highest IA with 4+5+c <= 10, i.e. c = 1.
fn three() -> Problem {
    Problem {
        goals: vec![Goal {
            name: "energy_j".into(),
            bound: 10.0,
        }],
        activities: vec![
            act(
                "A1",
                vec![ia("a", &[1.0], 1.0, &[]), ia("b", &[4.0], 2.0, &["lidar"])],
            ),
            act(
                "A2",
                vec![ia("a", &[2.0], 1.0, &[]), ia("b", &[5.0], 2.0, &["lidar"])],
            ),
            act(
                "A3",
                vec![
                    ia("a", &[1.0], 1.0, &[]),
                    ia("b", &[3.0], 2.0, &[]),
                    ia("c", &[6.0], 3.0, &["lidar"]),
                ],
            ),
        ],
    }
}

#[test]
fn hand_computed_three_activities() {
    let p = three();
    let a = allocate(&p, Selection::MostCapable).unwrap();
    assert_eq!(a.choice, vec![1, 1, 0]);
    assert_eq!(a.totals, vec![10.0]);
    // Tighter bound 7: A3 lowest (1) still gives 10 > 7; then A2: 4 + c + 1 <= 7 -> c = 2.
    let mut p7 = p.clone();
    p7.goals[0].bound = 7.0;
    let a = allocate(&p7, Selection::MostCapable).unwrap();
    assert_eq!(a.choice, vec![1, 0, 0]);
    // Bound 3 < 1 + 2 + 1 = 4: infeasible by exactly 1.
    p7.goals[0].bound = 3.0;
    match allocate(&p7, Selection::MostCapable) {
        Err(Infeasible::Goal {
            goal,
            minimum,
            bound,
            excess,
        }) => {
            assert_eq!(goal, "energy_j");
            assert_eq!((minimum, bound, excess), (4.0, 3.0, 1.0));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn goals_in_user_order_reduce_candidates() {
    // Duration first (<= 10) forces A2 off its slow IA; energy (<= 9) then works on what is left.
    let p = Problem {
        goals: vec![
            Goal {
                name: "duration_s".into(),
                bound: 10.0,
            },
            Goal {
                name: "energy_j".into(),
                bound: 9.0,
            },
        ],
        activities: vec![
            act(
                "A1",
                vec![
                    ia("x", &[3.0, 2.0], 1.0, &[]),
                    ia("y", &[4.0, 5.0], 2.0, &[]),
                ],
            ),
            act(
                "A2",
                vec![
                    ia("x", &[5.0, 3.0], 1.0, &[]),
                    ia("y", &[6.0, 1.0], 0.0, &[]),
                    ia("z", &[9.0, 1.0], 3.0, &[]),
                ],
            ),
        ],
    };
    let a = allocate(&p, Selection::MostCapable).unwrap();
    // Duration: highest 4+9 = 13 > 10; A2 dichotomy: 4 + c <= 10 -> c = 6 (y). Cands A2 = {x, y}.
    // Energy: highest by energy: A1 y (5), A2 x (3) = 8 <= 9. Cands unchanged. Most capable: A1 y, A2 x.
    assert_eq!(a.choice, vec![1, 0]);
    assert_eq!(a.candidates[1].len(), 2);
    assert!(p.feasible(&a.choice));
}

#[test]
fn nga_is_exact_product() {
    assert_eq!(nga(&three()), Some(12));
    let big = Problem {
        goals: vec![],
        activities: (0..40)
            .map(|k| {
                act(
                    &format!("A{k}"),
                    (0..10).map(|i| ia(&i.to_string(), &[], 0.0, &[])).collect(),
                )
            })
            .collect(),
    };
    assert_eq!(nga(&big), None, "10^40 overflows u128");
}

#[test]
fn empty_activity_is_reported() {
    let mut p = three();
    p.activities[1].ias.clear();
    assert_eq!(
        allocate(&p, Selection::MostCapable),
        Err(Infeasible::NoAlternative {
            activity: "A2".into()
        })
    );
}

#[test]
fn margins_and_drift_by_hand() {
    let p = three();
    let choice = vec![1, 1, 0]; // 4 + 5 + 1 = 10
    // Half-way through A2, measured 7.5 (plan said 4 + 2.5 = 6.5): drift 1, remainder 2.5 + 1.
    let m = Measured {
        activity: 1,
        fraction: 0.5,
        so_far: vec![7.5],
    };
    let r = margins(&p, &choice, &m);
    assert_eq!(r.estimated_so_far, vec![6.5]);
    assert_eq!(r.drift, vec![1.0]);
    assert_eq!(r.remainder, vec![3.5]);
    assert_eq!(r.margin, vec![10.0 - 11.0]);
    // Re-allocation: remaining budget 2.5 for half of A2 (a: 1, b: 2.5) and A3 (1, 3, 6).
    // Highest: 2.5 + 6 > 2.5; A3 lowest 1 -> 3.5 still > 2.5; A2 dichotomy: c + 1 <= 2.5 -> a (1).
    let c = reallocate(&p, &choice, &m, &[], Selection::MostCapable).unwrap();
    assert_eq!(c, vec![1, 0, 0]);
    let after = margins(&p, &c, &m);
    assert!(after.margin[0] >= 0.0, "{after:?}");
    assert_eq!(after.margin, vec![10.0 - (7.5 + 1.0 + 1.0)]);
}

#[test]
fn failed_resource_removes_ias() {
    let p = three();
    let m = Measured {
        activity: 1,
        fraction: 0.0,
        so_far: vec![4.0],
    };
    let (rp, map) = reduced_problem(&p, &m, &["lidar".to_string()]);
    assert_eq!(rp.activities.len(), 2);
    assert_eq!(map, vec![vec![0], vec![0, 1]]);
    assert_eq!(rp.goals[0].bound, 6.0);
    let c = reallocate(
        &p,
        &[1, 1, 0],
        &m,
        &["lidar".to_string()],
        Selection::MostCapable,
    )
    .unwrap();
    assert_eq!(c, vec![1, 0, 1]); // 4 + 2 + 3 = 9, no lidar after A1
    // Everything of A2 failed: reported, not hidden.
    let mut q = p.clone();
    q.activities[1].ias[0].resources.push("lidar".into());
    assert_eq!(
        reallocate(
            &q,
            &[1, 1, 0],
            &m,
            &["lidar".to_string()],
            Selection::MostCapable
        ),
        Err(Infeasible::NoAlternative {
            activity: "A2".into()
        })
    );
}

/// Two goals where the first goal's reduction cuts away the only feasible allocation: g1 lowers A2
/// to d, then g2 finds nothing; (a, c) satisfies both. The fallback finds it.
#[test]
fn exact_fallback_when_the_greedy_misses() {
    let p = Problem {
        goals: vec![
            Goal {
                name: "g1".into(),
                bound: 4.0,
            },
            Goal {
                name: "g2".into(),
                bound: 10.0,
            },
        ],
        activities: vec![
            act(
                "A1",
                vec![
                    ia("a", &[1.0, 5.0], 1.0, &[]),
                    ia("b", &[3.0, 1.0], 2.0, &[]),
                ],
            ),
            act(
                "A2",
                vec![
                    ia("c", &[3.0, 1.0], 1.0, &[]),
                    ia("d", &[1.0, 10.0], 2.0, &[]),
                ],
            ),
        ],
    };
    assert!(
        matches!(allocate(&p, Selection::MostCapable), Err(Infeasible::Goal { ref goal, .. }) if goal == "g2")
    );
    let m = Measured {
        activity: 0,
        fraction: 0.0,
        so_far: vec![0.0, 0.0],
    };
    let (c, used_exact) =
        reallocate_or_exact(&p, &[1, 1], &m, &[], Selection::MostCapable, 1000).unwrap();
    assert_eq!((c, used_exact), (vec![0, 0], true));
    // Really infeasible: the paper's error comes back.
    let mut q = p.clone();
    q.goals[1].bound = 5.0;
    assert!(reallocate_or_exact(&q, &[1, 1], &m, &[], Selection::MostCapable, 1000).is_err());
}

/// Reference for one goal: the same backwards search written as a linear scan from the top.
fn reference_one_goal(p: &Problem, sel: Selection) -> Option<Vec<usize>> {
    let n = p.activities.len();
    let bound = p.goals[0].bound;
    let sorted: Vec<Vec<usize>> = p
        .activities
        .iter()
        .map(|a| {
            let mut v: Vec<usize> = (0..a.ias.len()).collect();
            v.sort_by(|&x, &y| {
                a.ias[x].cost[0]
                    .total_cmp(&a.ias[y].cost[0])
                    .then(sel.score(&a.ias[x]).total_cmp(&sel.score(&a.ias[y])))
                    .then(x.cmp(&y))
            });
            v
        })
        .collect();
    let mut pos: Vec<usize> = sorted.iter().map(|v| v.len() - 1).collect();
    let total = |pos: &[usize]| -> f64 {
        (0..n)
            .map(|j| p.activities[j].ias[sorted[j][pos[j]]].cost[0])
            .sum()
    };
    for j in (0..n).rev() {
        if fits(total(&pos), bound) {
            break;
        }
        while pos[j] > 0 && !fits(total(&pos), bound) {
            pos[j] -= 1;
        }
    }
    if !fits(total(&pos), bound) {
        return None;
    }
    Some(
        (0..n)
            .map(|j| {
                let a = &p.activities[j];
                let piv = a.ias[sorted[j][pos[j]]].cost[0];
                let mut best: Option<usize> = None;
                for i in 0..a.ias.len() {
                    if a.ias[i].cost[0] > piv {
                        continue;
                    }
                    best = match best {
                        None => Some(i),
                        Some(b) => {
                            let (sb, si) = (sel.score(&a.ias[b]), sel.score(&a.ias[i]));
                            if si > sb || (si == sb && a.ias[i].cost[0] < a.ias[b].cost[0]) {
                                Some(i)
                            } else {
                                Some(b)
                            }
                        }
                    }
                }
                best.unwrap()
            })
            .collect(),
    )
}

fn arb_problem(max_goals: usize) -> impl Strategy<Value = Problem> {
    (1..=max_goals, 1usize..=5).prop_flat_map(|(ng, na)| {
        let ia = (prop::collection::vec(0u32..20, ng), 0u32..10).prop_map(|(c, cap)| (c, cap));
        let acts = prop::collection::vec(prop::collection::vec(ia, 1..=5), na);
        let bounds = prop::collection::vec(0u32..80, ng);
        (acts, bounds).prop_map(move |(acts, bounds)| Problem {
            goals: bounds
                .iter()
                .enumerate()
                .map(|(g, b)| Goal {
                    name: format!("g{g}"),
                    bound: *b as f64,
                })
                .collect(),
            activities: acts
                .into_iter()
                .enumerate()
                .map(|(j, ias)| Activity {
                    name: format!("A{j}"),
                    ias: ias
                        .into_iter()
                        .enumerate()
                        .map(|(i, (c, cap))| Ia {
                            name: format!("ia{i}"),
                            cost: c.iter().map(|&x| x as f64).collect(),
                            capability: cap as f64,
                            resources: vec![],
                        })
                        .collect(),
                })
                .collect(),
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// One goal: the dichotomy agrees with a linear scan, and the algorithm finds a solution exactly
    /// when one exists (the lowest IAs everywhere are its last resort).
    #[test]
    fn one_goal_matches_reference_and_exhaustive(p in arb_problem(1), by_cost in any::<bool>()) {
        let sel = if by_cost { Selection::HighestCost(0) } else { Selection::MostCapable };
        let got = allocate(&p, sel).ok().map(|a| a.choice);
        prop_assert_eq!(got.clone(), reference_one_goal(&p, sel));
        prop_assert_eq!(got.is_some(), exhaustive(&p, sel).is_some());
    }

    /// Any number of goals: RAS0 is feasible, never beats the optimum, and branch-and-bound finds
    /// the exhaustive optimum.
    #[test]
    fn ras0_is_feasible_and_bounded_by_the_optimum(p in arb_problem(3), by_cost in any::<bool>()) {
        let sel = if by_cost { Selection::HighestCost(0) } else { Selection::MostCapable };
        let brute = exhaustive(&p, sel);
        let bb = exact(&p, sel, u64::MAX);
        match (&brute, &bb) {
            (Some(b), Exact::Optimal(o)) => {
                prop_assert!((b.score - o.score).abs() < 1e-9);
                prop_assert!(p.feasible(&o.choice));
            }
            (None, Exact::Infeasible) => {}
            _ => prop_assert!(false, "exhaustive {:?} vs exact {:?}", brute, bb),
        }
        match allocate(&p, sel) {
            Ok(a) => {
                prop_assert!(p.feasible(&a.choice));
                let b = brute.expect("RAS0 exists so the optimum exists");
                prop_assert!(a.score <= b.score + 1e-9);
            }
            Err(Infeasible::Goal { minimum, bound, excess, .. }) => {
                prop_assert!(excess > 0.0);
                prop_assert!((minimum - bound - excess).abs() < 1e-9);
            }
            Err(e) => prop_assert!(false, "{e:?}"),
        }
    }

    /// A re-allocation, when it succeeds, restores every margin to >= 0.
    #[test]
    fn reallocation_restores_margins(p in arb_problem(2), at in 0usize..5, frac in 0.0f64..1.0, extra in 0.0f64..30.0) {
        if let Ok(a) = allocate(&p, Selection::MostCapable) {
            let at = at.min(p.activities.len() - 1);
            let r0 = margins(&p, &a.choice, &Measured { activity: at, fraction: frac, so_far: vec![0.0; p.goals.len()] });
            let m = Measured { activity: at, fraction: frac, so_far: r0.estimated_so_far.iter().map(|e| e + extra).collect() };
            if let Ok(c) = reallocate(&p, &a.choice, &m, &[], Selection::MostCapable) {
                let r = margins(&p, &c, &m);
                for (x, g) in r.margin.iter().zip(&p.goals) {
                    prop_assert!(*x >= -1e-9 * g.bound.abs().max(1.0), "{:?}", r);
                }
                prop_assert_eq!(&c[..at], &a.choice[..at]);
            }
        }
    }
}

/// What [`SwapCheck`] must equal: the margins of the swapped plan, each judged by `fits`.
fn swapped_fits(p: &Problem, choice: &[usize], m: &Measured, at: usize, i: usize) -> bool {
    let mut c = choice.to_vec();
    c[at] = i;
    let r = margins(p, &c, m);
    r.margin
        .iter()
        .zip(&p.goals)
        .all(|(x, g)| fits(g.bound - x, g.bound))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    /// The swap check answers as the full margins do, bit for bit, whatever order the
    /// alternatives are asked in, costs with fractions (rounding) and on the threshold, the
    /// swapped activity before, at or after the one being flown.
    #[test]
    fn swap_check_equals_the_full_margins(
        p in arb_problem(3),
        denom in prop::sample::select(vec![1.0f64, 3.0, 7.0, 10.0]),
        at in 0usize..5,
        flown in 0usize..5,
        frac in prop::sample::select(vec![0.0f64, 0.1, 0.25, 1.0 / 3.0, 0.5, 0.9, 1.0]),
        so_far in prop::collection::vec(0u32..40, 3),
        order_seed in any::<u64>(),
        choice_seed in any::<u64>(),
    ) {
        let mut p = p;
        for a in &mut p.activities {
            for ia in &mut a.ias {
                ia.cost.iter_mut().for_each(|c| *c /= denom);
            }
        }
        let n = p.activities.len();
        let (at, flown) = (at % n, flown % n);
        let choice: Vec<usize> = p
            .activities
            .iter()
            .enumerate()
            .map(|(j, a)| ((choice_seed >> (4 * j)) as usize) % a.ias.len())
            .collect();
        let m = Measured {
            activity: flown,
            fraction: frac,
            so_far: so_far.iter().take(p.goals.len()).map(|&x| x as f64 / denom).collect(),
        };
        let k = p.activities[at].ias.len();
        let mut order: Vec<usize> = (0..k).collect();
        order.rotate_left((order_seed as usize) % k);
        if order_seed & 1 == 1 {
            order.reverse();
        }
        let mut check = SwapCheck::default();
        check.reset(p.goals.len());
        // Every alternative twice: the second answers come from what the first ones learnt.
        for &i in order.iter().chain(&order) {
            prop_assert_eq!(
                check.fits(&p, &choice, &m, at, i),
                swapped_fits(&p, &choice, &m, at, i),
                "alternative {} of activity {}", i, at
            );
        }
    }
}

/// The re-allocation written out from the public pieces (the paper's algorithm on the reduced
/// mission, then the bounded exact search): the reference the kept reallocator must equal.
fn reference_reallocate_or_exact(
    p: &Problem,
    choice: &[usize],
    m: &Measured,
    failed: &[String],
    sel: Selection,
    max_nodes: u64,
) -> Result<(Vec<usize>, bool), Infeasible> {
    let e = match reallocate(p, choice, m, failed, sel) {
        Ok(c) => return Ok((c, false)),
        Err(e) => e,
    };
    let (rp, map) = reduced_problem(p, m, failed);
    let a = match exact(&rp, sel, max_nodes) {
        Exact::Optimal(a) | Exact::Aborted(Some(a)) => a,
        _ => return Err(e),
    };
    let from = p.activities.len() - rp.activities.len();
    let mut out = choice.to_vec();
    for (k, &i) in a.choice.iter().enumerate() {
        out[from + k] = map[k][i];
    }
    Ok((out, true))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The kept reallocator answers as the re-allocation written out from the public pieces, call after call on one instance
    /// (its reduced mission rebuilt in place over missions of other sizes, failed resources and
    /// fractions, a finished activity included).
    #[test]
    fn reallocator_equals_reallocate_or_exact(
        cases in prop::collection::vec(
            (arb_problem(2), 0usize..5, prop::sample::select(vec![0.0f64, 0.3, 1.0]), 0.0f64..20.0, any::<bool>()),
            1..6,
        ),
    ) {
        let mut r = Reallocator::default();
        for (mut p, at, frac, extra, fail) in cases {
            // A resource on every other IA, failed or not.
            for a in &mut p.activities {
                for (i, ia) in a.ias.iter_mut().enumerate() {
                    if i % 2 == 1 {
                        ia.resources = vec!["lidar".into()];
                    }
                }
            }
            let failed: Vec<String> = if fail { vec!["lidar".into()] } else { vec![] };
            let choice = vec![0; p.activities.len()];
            let at = at % p.activities.len();
            let m = Measured { activity: at, fraction: frac, so_far: vec![extra; p.goals.len()] };
            for sel in [Selection::MostCapable, Selection::HighestCost(0)] {
                let want = reference_reallocate_or_exact(&p, &choice, &m, &failed, sel, 10_000);
                let got = r
                    .reallocate_or_exact(&p, &choice, &m, &failed, sel, 10_000)
                    .map_err(Infeasible::clone);
                prop_assert_eq!(got, want);
            }
        }
    }
}
