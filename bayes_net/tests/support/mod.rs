//! Shared by the inference tests: brute-force enumeration (independent of the junction tree)
//! and random networks.
#![allow(dead_code)]

use bayes_net::{Evidence, Finding, Network, NetworkBuilder, NodeId};
use proptest::prelude::*;

/// Posterior marginals by summing the full joint (independent of the junction tree).
pub(crate) fn enumerate(net: &Network, ev: &Evidence) -> Option<Vec<Vec<f64>>> {
    let card: Vec<usize> = net.nodes().iter().map(|n| n.states.len()).collect();
    let mut out: Vec<Vec<f64>> = card.iter().map(|&k| vec![0.0; k]).collect();
    let mut a = vec![0usize; card.len()];
    let total: usize = card.iter().product();
    let mut z = 0.0;
    for _ in 0..total {
        let mut p = 1.0;
        for (i, n) in net.nodes().iter().enumerate() {
            let mut row = 0;
            for q in &n.parents {
                row = row * card[q.0] + a[q.0];
            }
            p *= n.cpt[row * card[i] + a[i]];
        }
        for (id, f) in &ev.findings {
            p *= match f {
                Finding::State(s) => (a[id.0] == *s) as u8 as f64,
                Finding::Likelihood(l) => l[a[id.0]],
            };
        }
        z += p;
        for i in 0..card.len() {
            out[i][a[i]] += p;
        }
        for i in (0..card.len()).rev() {
            a[i] += 1;
            if a[i] < card[i] {
                break;
            }
            a[i] = 0;
        }
    }
    if z <= 0.0 {
        return None;
    }
    for m in &mut out {
        m.iter_mut().for_each(|x| *x /= z);
    }
    Some(out)
}

/// A random network description: states per node, parents (earlier nodes, shuffled order of
/// insertion via a permutation), raw CPT weights, and evidence.
#[derive(Debug, Clone)]
pub(crate) struct Case {
    pub card: Vec<usize>,
    pub parents: Vec<Vec<usize>>,
    pub weights: Vec<f64>,
    pub perm: Vec<usize>,
    pub evidence: Vec<(usize, Option<usize>, Vec<f64>)>,
}

pub(crate) fn case() -> impl Strategy<Value = Case> {
    (1usize..=10).prop_flat_map(|n| {
        let card = prop::collection::vec(2usize..=4, n);
        // Parent candidates: each earlier node with some probability; at most 3 parents.
        let parents = prop::collection::vec(prop::collection::vec(any::<bool>(), n), n);
        let density = 0.0f64..0.6;
        let weights = prop::collection::vec(0.0f64..1.0, 4096);
        let perm = Just((0..n).collect::<Vec<_>>()).prop_shuffle();
        let evidence = prop::collection::vec(
            (
                0..n,
                prop::option::of(0usize..4),
                prop::collection::vec(0.05f64..1.0, 4),
            ),
            0..4,
        );
        (card, parents, density, weights, perm, evidence).prop_map(
            |(card, pmask, density, weights, perm, evidence)| {
                let n = card.len();
                let parents = (0..n)
                    .map(|i| {
                        (0..i)
                            .filter(|&j| {
                                pmask[i][j] && weights[(i * 31 + j * 7) % weights.len()] < density
                            })
                            .rev()
                            .take(3)
                            .collect()
                    })
                    .collect();
                Case {
                    card,
                    parents,
                    weights,
                    perm,
                    evidence,
                }
            },
        )
    })
}

pub(crate) fn build(c: &Case) -> (Network, Vec<NodeId>) {
    let n = c.card.len();
    let name = |i: usize| format!("x{i}");
    let mut b = NetworkBuilder::new();
    let mut ids = vec![NodeId(0); n];
    let mut w = 0usize;
    // Insert nodes in a shuffled order so parents are sometimes added after children.
    for &i in &c.perm {
        let rows: usize = c.parents[i].iter().map(|&p| c.card[p]).product();
        let mut cpt = Vec::with_capacity(rows * c.card[i]);
        for _ in 0..rows {
            let row: Vec<f64> = (0..c.card[i])
                .map(|_| {
                    w += 1;
                    // Some exact zeros to exercise zero-probability paths.
                    let x = c.weights[w % c.weights.len()];
                    if x < 0.08 { 0.0 } else { x }
                })
                .collect();
            let s: f64 = row.iter().sum();
            if s == 0.0 {
                let k = c.card[i] as f64;
                cpt.extend(std::iter::repeat_n(1.0 / k, c.card[i]));
            } else {
                cpt.extend(row.iter().map(|x| x / s));
            }
        }
        // Renormalise the row to sum exactly within tolerance.
        let states: Vec<String> = (0..c.card[i]).map(|s| format!("s{s}")).collect();
        let parents: Vec<String> = c.parents[i].iter().map(|&p| name(p)).collect();
        ids[i] = b.add_node(&name(i), &states, &parents, cpt);
    }
    (b.build().expect("valid random network"), ids)
}

/// Lauritzen & Spiegelhalter (1988) chest clinic ("Asia"), the textbook network.
pub(crate) fn asia() -> Network {
    let yn = ["yes", "no"];
    let none: [&str; 0] = [];
    let mut b = NetworkBuilder::new();
    b.add_node("asia", &yn, &none, vec![0.01, 0.99]);
    b.add_node("smoke", &yn, &none, vec![0.5, 0.5]);
    b.add_node("tub", &yn, &["asia"], vec![0.05, 0.95, 0.01, 0.99]);
    b.add_node("lung", &yn, &["smoke"], vec![0.1, 0.9, 0.01, 0.99]);
    b.add_node("bronc", &yn, &["smoke"], vec![0.6, 0.4, 0.3, 0.7]);
    b.add_node(
        "either",
        &yn,
        &["lung", "tub"],
        vec![1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1.0],
    );
    b.add_node("xray", &yn, &["either"], vec![0.98, 0.02, 0.05, 0.95]);
    b.add_node(
        "dysp",
        &yn,
        &["bronc", "either"],
        vec![0.9, 0.1, 0.8, 0.2, 0.7, 0.3, 0.1, 0.9],
    );
    b.build().unwrap()
}
