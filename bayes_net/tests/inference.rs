//! Inference checked against independent answers: brute-force enumeration of the full joint over
//! random DAGs, and published figures of two classic networks.

use bayes_net::{BnError, Evidence, Network, NetworkBuilder, NodeId};
use proptest::prelude::*;

mod support;
use support::{asia, build, case, enumerate};

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]
    #[allow(clippy::needless_range_loop)]
    #[test]
    fn junction_tree_matches_enumeration(c in case()) {
        let (net, ids) = build(&c);
        let mut ev = Evidence::new();
        for (node, hard, lik) in &c.evidence {
            let id = ids[*node];
            let k = c.card[*node];
            match hard {
                Some(s) => { ev.set_state(id, s % k); }
                None => { ev.set_likelihood(id, lik[..k].to_vec()); }
            }
        }
        let mut engine = net.compile();
        let want = enumerate(&net, &ev);
        let got = engine.propagate(&ev);
        match want {
            None => prop_assert_eq!(got, Err(BnError::ImpossibleEvidence)),
            Some(want) => {
                prop_assert!(got.is_ok(), "{:?}", got);
                for i in 0..net.len() {
                    for (g, w) in engine.marginal(NodeId(i)).iter().zip(&want[i]) {
                        prop_assert!((g - w).abs() < 1e-9, "node {} got {:?} want {:?}", i, engine.marginal(NodeId(i)), want[i]);
                    }
                }
                // A second query on the same engine (buffers reused) gives the same answer.
                let first: Vec<Vec<f64>> = (0..net.len()).map(|i| engine.marginal(NodeId(i)).to_vec()).collect();
                engine.propagate(&Evidence::new()).unwrap();
                engine.propagate(&ev).unwrap();
                for (i, f) in first.iter().enumerate() {
                    prop_assert_eq!(engine.marginal(NodeId(i)), &f[..]);
                }
            }
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn set_cpt_matches_rebuilt_network(c in case(), root_w in prop::collection::vec(0.01f64..1.0, 4)) {
        let (net, ids) = build(&c);
        // Replace the first root's CPT in the compiled engine and in a freshly built copy.
        let Some(root) = (0..c.card.len()).find(|&i| c.parents[i].is_empty()) else { return Ok(()) };
        let k = c.card[root];
        let s: f64 = root_w[..k].iter().sum();
        let prior: Vec<f64> = root_w[..k].iter().map(|x| x / s).collect();
        let mut engine = net.compile();
        engine.set_cpt(ids[root], &prior).unwrap();
        let mut b = NetworkBuilder::new();
        for n in net.nodes() {
            let parents: Vec<&str> = n.parents.iter().map(|p| net.node(*p).name.as_str()).collect();
            let cpt = if n.name == format!("x{root}") { prior.clone() } else { n.cpt.clone() };
            b.add_node(&n.name, &n.states, &parents, cpt);
        }
        let net2 = b.build().unwrap();
        let want = enumerate(&net2, &Evidence::new()).unwrap();
        engine.propagate(&Evidence::new()).unwrap();
        for i in 0..net.len() {
            for (g, w) in engine.marginal(NodeId(i)).iter().zip(&want[i]) {
                prop_assert!((g - w).abs() < 1e-9);
            }
        }
    }
}

fn sprinkler() -> Network {
    // Murphy, "A Brief Introduction to Graphical Models and Bayesian Networks" (1998), and the
    // BNT documentation: P(C)=0.5; P(S|C)=0.1, P(S|~C)=0.5; P(R|C)=0.8, P(R|~C)=0.2;
    // P(W|S,R)=0.99, P(W|S,~R)=0.9, P(W|~S,R)=0.9, P(W|~S,~R)=0.
    let mut b = NetworkBuilder::new();
    let tf = ["false", "true"];
    b.add_node(
        "W",
        &tf,
        &["S", "R"],
        vec![1.0, 0.0, 0.1, 0.9, 0.1, 0.9, 0.01, 0.99],
    );
    b.add_node("C", &tf, &[] as &[&str], vec![0.5, 0.5]);
    b.add_node("S", &tf, &["C"], vec![0.5, 0.5, 0.9, 0.1]);
    b.add_node("R", &tf, &["C"], vec![0.8, 0.2, 0.2, 0.8]);
    b.build().unwrap()
}

#[test]
fn sprinkler_published_posteriors() {
    let net = sprinkler();
    let mut e = net.compile();
    let (s, r, w) = (
        net.id("S").unwrap(),
        net.id("R").unwrap(),
        net.id("W").unwrap(),
    );
    e.propagate(&Evidence::new()).unwrap();
    // Murphy: P(W=1) = 0.6471.
    assert!((e.marginal(w)[1] - 0.6471).abs() < 5e-5);
    let ev = net.evidence([("W", "true")]).unwrap();
    e.propagate(&ev).unwrap();
    // Murphy: P(S=1|W=1) = 0.2781/0.6471 = 0.4298, P(R=1|W=1) = 0.4581/0.6471 = 0.7079.
    assert!(
        (e.marginal(s)[1] - 0.4298).abs() < 5e-5,
        "{:?}",
        e.marginal(s)
    );
    assert!(
        (e.marginal(r)[1] - 0.7079).abs() < 5e-5,
        "{:?}",
        e.marginal(r)
    );
    // Explaining away (Murphy): P(S=1|W=1,R=1) = 0.1945.
    let ev = net.evidence([("W", "true"), ("R", "true")]).unwrap();
    assert!((e.posterior(&ev, s).unwrap()[1] - 0.1945).abs() < 5e-5);
}

#[test]
fn asia_prior_marginals() {
    // Lauritzen & Spiegelhalter (1988) chest clinic; prior marginals as printed by Hugin and
    // hand-checked: tub 0.0104, lung 0.055, bronc 0.45, either 0.064828, xray 0.11029, dysp 0.43597.
    let net = asia();
    let mut e = net.compile();
    e.propagate(&Evidence::new()).unwrap();
    for (n, p) in [
        ("tub", 0.0104),
        ("lung", 0.055),
        ("bronc", 0.45),
        ("either", 0.064828),
        ("xray", 0.11029),
        ("dysp", 0.43597),
    ] {
        let got = e.marginal(net.id(n).unwrap())[0];
        assert!((got - p).abs() < 5e-6, "{n}: {got} vs {p}");
    }
    // With a positive x-ray, either = P(xray|either)P(either)/P(xray) = 0.98*0.064828/0.11029004.
    let ev = net.evidence([("xray", "yes")]).unwrap();
    let got = e.posterior(&ev, net.id("either").unwrap()).unwrap()[0];
    assert!((got - 0.98 * 0.064828 / 0.11029004).abs() < 1e-6, "{got}");
    // The deterministic node forces an impossible combination.
    let ev = net.evidence([("either", "no"), ("tub", "yes")]).unwrap();
    assert_eq!(e.propagate(&ev), Err(BnError::ImpossibleEvidence));
}

#[test]
fn soft_evidence_is_a_likelihood() {
    // A root with prior [0.2, 0.8] and virtual evidence [0.9, 0.1]: posterior ∝ [0.18, 0.08].
    let mut b = NetworkBuilder::new();
    let a = b.add_node("a", &["x", "y"], &[] as &[&str], vec![0.2, 0.8]);
    let net = b.build().unwrap();
    let mut e = net.compile();
    let mut ev = Evidence::new();
    ev.set_likelihood(a, vec![0.9, 0.1]);
    let p = e.posterior(&ev, a).unwrap();
    assert!((p[0] - 0.18 / 0.26).abs() < 1e-12);
}

#[test]
fn build_errors() {
    let none: [&str; 0] = [];
    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "y"], &none, vec![0.5, 0.4]);
    assert!(matches!(b.build(), Err(BnError::CptRow { row: 0, .. })));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "y"], &none, vec![0.5, 0.5, 0.5]);
    assert!(matches!(
        b.build(),
        Err(BnError::CptSize {
            expected: 2,
            got: 3,
            ..
        })
    ));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "y"], &["b"], vec![0.5, 0.5, 0.5, 0.5]);
    b.add_node("b", &["x", "y"], &["a"], vec![0.5, 0.5, 0.5, 0.5]);
    b.add_node("c", &["x", "y"], &none, vec![0.5, 0.5]);
    match b.build() {
        Err(BnError::Cycle(nodes)) => assert_eq!(nodes, vec!["a".to_string(), "b".to_string()]),
        other => panic!("{other:?}"),
    }

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "y"], &["nope"], vec![0.5, 0.5, 0.5, 0.5]);
    assert!(matches!(b.build(), Err(BnError::UnknownParent { .. })));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "y"], &none, vec![1.5, -0.5]);
    assert!(matches!(
        b.build(),
        Err(BnError::Probability { index: 0, .. })
    ));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x", "x"], &none, vec![0.5, 0.5]);
    assert!(matches!(b.build(), Err(BnError::DuplicateState { .. })));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &["x"], &none, vec![1.0]);
    b.add_node("a", &["x"], &none, vec![1.0]);
    assert!(matches!(b.build(), Err(BnError::DuplicateNode(_))));

    let mut b = NetworkBuilder::new();
    b.add_node("a", &[] as &[&str], &none, vec![]);
    assert!(matches!(b.build(), Err(BnError::NoStates(_))));
}

#[test]
fn query_errors() {
    let net = sprinkler();
    let mut e = net.compile();
    let s = net.id("S").unwrap();
    assert!(matches!(
        net.evidence([("S", "maybe")]),
        Err(BnError::UnknownState { .. })
    ));
    assert!(matches!(
        net.evidence([("Q", "true")]),
        Err(BnError::UnknownNode(_))
    ));
    let mut ev = Evidence::new();
    ev.set_state(s, 7);
    assert!(matches!(
        e.propagate(&ev),
        Err(BnError::UnknownState { .. })
    ));
    let mut ev = Evidence::new();
    ev.set_likelihood(s, vec![1.0]);
    assert!(matches!(
        e.propagate(&ev),
        Err(BnError::LikelihoodLength {
            expected: 2,
            got: 1,
            ..
        })
    ));
    let mut ev = Evidence::new();
    ev.set_likelihood(s, vec![0.0, 0.0]);
    assert!(matches!(
        e.propagate(&ev),
        Err(BnError::InvalidLikelihood { .. })
    ));
    let mut ev = Evidence::new();
    ev.set_state(NodeId(99), 0);
    assert!(matches!(e.propagate(&ev), Err(BnError::UnknownNode(_))));
    // W=true is impossible when neither S nor R.
    let ev = net
        .evidence([("W", "true"), ("S", "false"), ("R", "false")])
        .unwrap();
    assert_eq!(e.propagate(&ev), Err(BnError::ImpossibleEvidence));
    // set_cpt validates too.
    assert!(matches!(
        e.set_cpt(s, &[0.5, 0.5]),
        Err(BnError::CptSize { .. })
    ));
}
