//! Targeted queries ([`Engine::query`]) checked against brute-force enumeration of the full joint
//! and against the full junction-tree propagation, over random networks, random hard and soft
//! evidence, random target sets and random evidence-change sequences on one engine (so cached
//! plans are reused with new values, and new patterns appear mid-sequence).

use bayes_net::{BnError, Engine, Evidence, Network, NetworkBuilder, NodeId};
use proptest::prelude::*;

mod support;
use support::{asia, build, case, enumerate};

/// One step of an evidence sequence: (node, hard state or soft, likelihood) findings, or `None`
/// to keep the previous step's pattern (same nodes, same kinds) with this step's values.
type Step = (
    Option<Vec<(usize, Option<usize>)>>,
    Vec<usize>,
    Vec<Vec<f64>>,
);

fn step() -> impl Strategy<Value = Step> {
    (
        prop::option::weighted(
            0.5,
            prop::collection::vec((0usize..10, prop::option::of(0usize..4)), 0..5),
        ),
        prop::collection::vec(0usize..4, 10),
        prop::collection::vec(prop::collection::vec(0.0f64..1.0, 4), 10),
    )
}

/// The evidence of a step on a network of `card`, given the previous pattern.
fn evidence(
    card: &[usize],
    ids: &[NodeId],
    pattern: &mut Vec<(usize, bool)>,
    s: &Step,
) -> Evidence {
    if let Some(f) = &s.0 {
        *pattern = f
            .iter()
            .map(|&(n, h)| (n % card.len(), h.is_some()))
            .collect();
    }
    let mut ev = Evidence::new();
    for (k, &(n, hard)) in pattern.iter().enumerate() {
        if hard {
            ev.set_state(ids[n], s.1[k % 10] % card[n]);
        } else {
            // Likelihoods with exact zeros now and then (zero-probability paths), never all zero.
            let mut l: Vec<f64> = s.2[k % 10][..card[n]]
                .iter()
                .map(|&x| if x < 0.1 { 0.0 } else { x })
                .collect();
            l[0] += 0.05;
            ev.set_likelihood(ids[n], l);
        }
    }
    ev
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn query_matches_enumeration_over_evidence_sequences(
        c in case(),
        tmask in prop::collection::vec(any::<bool>(), 10),
        steps in prop::collection::vec(step(), 1..8),
    ) {
        let (net, ids) = build(&c);
        let n = c.card.len();
        let targets: Vec<NodeId> = (0..n).filter(|&i| tmask[i]).map(|i| ids[i]).collect();
        let mut engine = net.compile();
        engine.set_targets(&targets).unwrap();
        let mut full = net.compile();
        full.propagate(&Evidence::new()).unwrap();
        engine.propagate(&Evidence::new()).unwrap();
        let prior: Vec<Vec<f64>> = (0..n).map(|i| engine.marginal(NodeId(i)).to_vec()).collect();
        let mut pattern = Vec::new();
        for s in &steps {
            let ev = evidence(&c.card, &ids, &mut pattern, s);
            let want = enumerate(&net, &ev);
            let got = engine.query(&ev);
            match want {
                // Impossible evidence: reported unless the zero is d-separated from every target.
                None => prop_assert!(
                    matches!(got, Ok(()) | Err(BnError::ImpossibleEvidence)),
                    "{:?}", got
                ),
                Some(want) => {
                    prop_assert!(got.is_ok(), "{:?}", got);
                    full.propagate(&ev).unwrap();
                    for &t in &targets {
                        let g = engine.marginal(t);
                        prop_assert!(close(g, &want[t.0], 1e-9),
                            "target {} got {:?} want {:?}", t, g, want[t.0]);
                        prop_assert!(close(g, full.marginal(t), 1e-12),
                            "target {} got {:?} propagate {:?}", t, g, full.marginal(t));
                    }
                }
            }
            // Nodes that are not targets keep the last full propagation's marginals.
            for i in (0..n).filter(|&i| !targets.contains(&NodeId(i))) {
                prop_assert_eq!(engine.marginal(NodeId(i)), &prior[i][..]);
            }
        }
        prop_assert!(engine.cached_plans() <= steps.len());
    }

    #[test]
    fn query_follows_set_cpt(c in case(), root_w in prop::collection::vec(0.01f64..1.0, 4)) {
        let (net, ids) = build(&c);
        let Some(root) = (0..c.card.len()).find(|&i| c.parents[i].is_empty()) else { return Ok(()) };
        let ev = evidence(&c.card, &ids, &mut Vec::new(),
            &(Some(c.evidence.iter().map(|e| (e.0, e.1)).collect()), vec![1; 10], vec![vec![0.5; 4]; 10]));
        let all: Vec<NodeId> = ids.clone();
        let mut engine = net.compile();
        engine.set_targets(&all).unwrap();
        // Plan the pattern first, then change a CPT: the plan must read the new numbers.
        let _ = engine.query(&ev);
        let k = c.card[root];
        let s: f64 = root_w[..k].iter().sum();
        let prior: Vec<f64> = root_w[..k].iter().map(|x| x / s).collect();
        engine.set_cpt(ids[root], &prior).unwrap();
        let mut full = engine.clone();
        match full.propagate(&ev) {
            Err(e) => prop_assert_eq!(e, BnError::ImpossibleEvidence),
            Ok(()) => {
                engine.query(&ev).unwrap();
                for &t in &all {
                    prop_assert!(close(engine.marginal(t), full.marginal(t), 1e-12));
                }
            }
        }
    }
}

fn binary(b: &mut NetworkBuilder, name: &str, parents: &[&str], cpt: Vec<f64>) -> NodeId {
    b.add_node(name, &["no", "yes"], parents, cpt)
}

/// Eight binary nodes, each with the previous two as parents (numbers arbitrary, no zeros).
fn ladder() -> Network {
    let mut b = NetworkBuilder::new();
    binary(&mut b, "x0", &[], vec![0.3, 0.7]);
    binary(&mut b, "x1", &["x0"], vec![0.6, 0.4, 0.2, 0.8]);
    for i in 2..8 {
        let p1 = format!("x{}", i - 1);
        let p2 = format!("x{}", i - 2);
        let mut cpt = Vec::new();
        for r in 0..4 {
            let p = 0.1 + 0.2 * r as f64 + 0.03 * i as f64;
            cpt.extend([p, 1.0 - p]);
        }
        binary(&mut b, &format!("x{i}"), &[&p1, &p2], cpt);
    }
    b.build().unwrap()
}

#[test]
fn more_patterns_than_the_cache_holds() {
    let net = ladder();
    let mut e = net.compile();
    let t = [net.id("x0").unwrap(), net.id("x7").unwrap()];
    e.set_targets(&t).unwrap();
    // Every subset of x1..x6 observed (64 patterns) plus soft evidence on x3 (64 more), twice.
    for round in 0..2 {
        for mask in 0u32..128 {
            let mut ev = Evidence::new();
            for i in 1..7 {
                if mask & (1 << (i - 1)) != 0 {
                    ev.set_state(NodeId(i), ((mask >> i) as usize + round) % 2);
                }
            }
            if mask & 64 != 0 {
                ev.set_likelihood(NodeId(3), vec![0.25, 0.9]);
            }
            let want = enumerate(&net, &ev).unwrap();
            e.query(&ev).unwrap();
            for id in t {
                assert!(close(e.marginal(id), &want[id.0], 1e-9), "mask {mask}");
            }
            assert!(e.cached_plans() <= 64);
        }
    }
    assert_eq!(e.cached_plans(), 64);
}

fn target(net: &Network, names: &[&str]) -> Engine {
    let mut e = net.compile();
    let ids: Vec<NodeId> = names.iter().map(|n| net.id(n).unwrap()).collect();
    e.set_targets(&ids).unwrap();
    e
}

#[test]
fn asia_targeted_posteriors_by_hand() {
    let net = asia();
    let mut e = target(&net, &["either", "bronc"]);
    // No evidence: the published prior marginals (Lauritzen & Spiegelhalter 1988).
    e.query(&Evidence::new()).unwrap();
    assert!((e.marginal(net.id("either").unwrap())[0] - 0.064828).abs() < 5e-7);
    assert!((e.marginal(net.id("bronc").unwrap())[0] - 0.45).abs() < 1e-12);
    // Positive x-ray: either = 0.98 * 0.064828 / 0.11029004 (Bayes by hand).
    let ev = net.evidence([("xray", "yes")]).unwrap();
    e.query(&ev).unwrap();
    let got = e.marginal(net.id("either").unwrap())[0];
    assert!((got - 0.98 * 0.064828 / 0.11029004).abs() < 1e-6, "{got}");
    // Smoking, x-ray and dyspnoea observed: bronc still depends on dysp (explaining away
    // through either), so against enumeration.
    let ev = net
        .evidence([("smoke", "yes"), ("xray", "yes"), ("dysp", "no")])
        .unwrap();
    e.query(&ev).unwrap();
    let want = enumerate(&net, &ev).unwrap();
    let b = net.id("bronc").unwrap();
    assert!(close(e.marginal(b), &want[b.0], 1e-12));
    let ev = net.evidence([("smoke", "yes")]).unwrap();
    e.query(&ev).unwrap();
    // Smoking alone observed: bronc's posterior is its CPT row.
    assert!(close(e.marginal(b), &[0.6, 0.4], 1e-12));
}

#[test]
fn observed_targets_and_conflicting_evidence() {
    let net = asia();
    let mut e = target(&net, &["tub", "lung"]);
    let tub = net.id("tub").unwrap();
    let lung = net.id("lung").unwrap();
    // An observed target's posterior is its observed state.
    let ev = net.evidence([("tub", "no")]).unwrap();
    e.query(&ev).unwrap();
    assert_eq!(e.marginal(tub), &[0.0, 1.0]);
    // Two different states on one node, or a likelihood zero at the observed state: impossible.
    let ev = net.evidence([("tub", "no"), ("tub", "yes")]).unwrap();
    assert_eq!(e.query(&ev), Err(BnError::ImpossibleEvidence));
    let mut ev = net.evidence([("tub", "no")]).unwrap();
    ev.set_likelihood(tub, vec![1.0, 0.0]);
    assert_eq!(e.query(&ev), Err(BnError::ImpossibleEvidence));
    // Likelihoods whose product is zero everywhere: impossible.
    let mut ev = Evidence::new();
    ev.set_likelihood(lung, vec![1.0, 0.0]);
    ev.set_likelihood(lung, vec![0.0, 1.0]);
    assert_eq!(e.query(&ev), Err(BnError::ImpossibleEvidence));
    // The deterministic node: tub=yes forces either=yes, so either=no is impossible, and lung
    // depends on that zero.
    let ev = net.evidence([("either", "no"), ("tub", "yes")]).unwrap();
    assert_eq!(e.query(&ev), Err(BnError::ImpossibleEvidence));
    // Bad findings are rejected as by propagate.
    let mut ev = Evidence::new();
    ev.set_state(tub, 5);
    assert!(matches!(e.query(&ev), Err(BnError::UnknownState { .. })));
    let mut ev = Evidence::new();
    ev.set_likelihood(tub, vec![1.0]);
    assert!(matches!(
        e.query(&ev),
        Err(BnError::LikelihoodLength { .. })
    ));
    assert!(matches!(
        e.set_targets(&[NodeId(99)]),
        Err(BnError::UnknownNode(_))
    ));
}

#[test]
fn impossibility_d_separated_from_the_targets_is_not_looked_for() {
    // a is independent of (b -> c) where c copies b: observing b=0 and c=1 is impossible, but a's
    // posterior cannot depend on it, so the targeted query answers a's prior (documented).
    let mut b = NetworkBuilder::new();
    binary(&mut b, "a", &[], vec![0.25, 0.75]);
    binary(&mut b, "b", &[], vec![0.5, 0.5]);
    binary(&mut b, "c", &["b"], vec![1.0, 0.0, 0.0, 1.0]);
    let net = b.build().unwrap();
    let ev = net.evidence([("b", "no"), ("c", "yes")]).unwrap();
    let mut e = target(&net, &["a"]);
    e.query(&ev).unwrap();
    assert_eq!(e.marginal(net.id("a").unwrap()), &[0.25, 0.75]);
    assert_eq!(e.propagate(&ev), Err(BnError::ImpossibleEvidence));
    // c copies b.
    let mut e = target(&net, &["a", "c"]);
    let ev = net.evidence([("b", "no")]).unwrap();
    e.query(&ev).unwrap();
    assert_eq!(e.marginal(net.id("c").unwrap()), &[1.0, 0.0]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The query memo (`set_query_memo`) answers exactly as a run: over sequences drawn from a
    /// few evidence sets and two priors of a root node (so inputs repeat, as evidence flapping
    /// across a threshold does), every target's posterior is bit for bit the memo-less engine's,
    /// and repeats are answered from memory.
    #[test]
    fn query_memo_answers_exactly_as_a_run(
        c in case(),
        pool in prop::collection::vec(step(), 1..4),
        seq in prop::collection::vec((0usize..4, any::<bool>()), 1..24),
        slots in 1usize..5,
        root_w in prop::collection::vec(0.01f64..1.0, 4),
    ) {
        let (net, ids) = build(&c);
        let mut plain = net.compile();
        plain.set_targets(&ids).unwrap();
        let mut memo = plain.clone();
        memo.set_query_memo(slots);
        let root = (0..c.card.len()).find(|&i| c.parents[i].is_empty());
        let priors: Vec<Vec<f64>> = root.map_or(vec![], |r| {
            let k = c.card[r];
            let s: f64 = root_w[..k].iter().sum();
            vec![net.node(ids[r]).cpt.clone(), root_w[..k].iter().map(|x| x / s).collect()]
        });
        // Each pool entry's own pattern (a `None` pattern keeps none: no findings).
        let evs: Vec<Evidence> = pool.iter().map(|s| evidence(&c.card, &ids, &mut Vec::new(), s)).collect();
        for &(k, alt) in &seq {
            if let Some(r) = root {
                let p = &priors[usize::from(alt)];
                plain.set_cpt(ids[r], p).unwrap();
                memo.set_cpt(ids[r], p).unwrap();
            }
            let ev = &evs[k % evs.len()];
            let (a, b) = (plain.query(ev), memo.query(ev));
            prop_assert_eq!(&a, &b);
            if a.is_ok() {
                for &t in &ids {
                    let (x, y) = (plain.marginal(t), memo.marginal(t));
                    prop_assert!(x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()),
                        "target {} memo {:?} run {:?}", t, y, x);
                }
            }
        }
        prop_assert_eq!(plain.query_memo_hits(), 0);
    }
}

/// Evidence alternating between two values is run twice, then answered from memory.
#[test]
fn query_memo_serves_flapping_evidence() {
    let net = asia();
    let mut e = target(&net, &["lung", "bronc"]);
    e.set_query_memo(2);
    let xray = net.id("xray").unwrap();
    let mut evs = [Evidence::new(), Evidence::new()];
    evs[0].set_state(xray, 0);
    evs[1].set_state(xray, 1);
    for k in 0..10 {
        e.query(&evs[k % 2]).unwrap();
    }
    assert_eq!(e.query_memo_hits(), 8);
}
