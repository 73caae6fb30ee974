//! The health model's tests (moved beside it: one concern per file).
use super::*;

/// Evidence maps over every observable node's states, varied so that values and patterns
/// both change between evaluations.
fn evidence_sequence(m: &HealthModel) -> Vec<BTreeMap<String, String>> {
    let obs: Vec<(String, Vec<String>)> = m
        .observations
        .evidence(&Observations::default())
        .keys()
        .chain(m.managers.iter().flat_map(|mg| {
            mg.nodes
                .iter()
                .filter(|n| n.name.starts_with("A_") || n.name.starts_with("S_"))
                .map(|n| &n.name)
        }))
        .filter_map(|name| {
            let mg = m
                .managers
                .iter()
                .find(|mg| mg.engine.network().id(name).is_some())?;
            let net = mg.engine.network();
            Some((name.clone(), net.node(net.id(name)?).states.clone()))
        })
        .collect();
    (0..40)
        .map(|k: usize| {
            obs.iter()
                .enumerate()
                .filter(|(i, _)| !(k * 7 + i * 3).is_multiple_of(5))
                .map(|(i, (n, st))| (n.clone(), st[(k + i) % st.len()].clone()))
                .collect()
        })
        .collect()
}

#[test]
fn targeted_cycle_matches_full_propagation() {
    let params = crate::shipped::params();
    let mut fast = HealthModel::load(&params).unwrap();
    let mut full = HealthModel::load(&params).unwrap();
    let seq = evidence_sequence(&fast);
    let mut out = BTreeMap::new();
    for ev in &seq {
        // Independent answer: every manager propagated in full on a copy of its engine,
        // before the evaluation advances the carried beliefs.
        let mut want = BTreeMap::new();
        for m in &full.managers {
            let mut e = m.engine.clone();
            let net = e.network().clone();
            let mut evd = Evidence::new();
            for (k, v) in ev {
                if let Some(id) = net.id(k) {
                    evd.set_state(id, net.state(id, v).unwrap());
                }
            }
            // Imported priors come from the managers evaluated before (same order).
            for &(local, src_m, src) in &m.imports {
                let p: Vec<f64> = want_marginal(&full, src_m, src, ev);
                let s: f64 = p.iter().sum();
                let p: Vec<f64> = p.iter().map(|x| x / s).collect();
                e.set_cpt(local, &p).unwrap();
            }
            e.propagate(&evd).unwrap();
            for &(k, id, s, c) in &m.published {
                let p = e.marginal(id)[s];
                want.insert(m.publish[k].name.clone(), if c { 1.0 - p } else { p });
            }
        }
        fast.evaluate_into(ev, &mut out).unwrap();
        let slow = full.evaluate(ev).unwrap();
        // The cycle's numbers and the report's are the same, bit for bit.
        assert_eq!(out, slow);
        for (name, w) in &want {
            assert!(
                (out[name] - w).abs() < 1e-12,
                "{name}: {} vs {w}",
                out[name]
            );
        }
    }
}

/// A rejected evidence map (unknown state, unknown node) leaves nothing behind: the cached
/// name resolution of an entry that failed is not reused, and the results afterwards are
/// those of a model that never saw the bad maps.
#[test]
fn rejected_evidence_changes_nothing() {
    let params = crate::shipped::params();
    let mut a = HealthModel::load(&params).unwrap();
    let mut b = HealthModel::load(&params).unwrap();
    let seq = evidence_sequence(&a);
    let (ev0, ev1) = (&seq[0], &seq[1]);
    let (first, _) = ev0.iter().next().unwrap();
    let mut bad_state = ev0.clone();
    bad_state.insert(first.clone(), "no_such_state".into());
    let mut bad_node = ev0.clone();
    bad_node.insert("no_such_node".into(), "x".into());
    let (mut oa, mut ob) = (BTreeMap::new(), BTreeMap::new());
    a.evaluate_into(ev0, &mut oa).unwrap();
    b.evaluate_into(ev0, &mut ob).unwrap();
    assert!(matches!(
        a.evaluate_into(&bad_state, &mut oa),
        Err(HealthError::UnknownState { .. })
    ));
    assert!(matches!(
        a.evaluate_into(&bad_node, &mut oa),
        Err(HealthError::UnknownNode(_))
    ));
    for ev in [ev0, ev1, ev0] {
        a.evaluate_into(ev, &mut oa).unwrap();
        b.evaluate_into(ev, &mut ob).unwrap();
        assert_eq!(oa, ob);
    }
}

/// Marginal of `src` in manager `j` under `ev` by a full propagation on a copy.
fn want_marginal(
    m: &HealthModel,
    j: usize,
    src: NodeId,
    ev: &BTreeMap<String, String>,
) -> Vec<f64> {
    let mut e = m.managers[j].engine.clone();
    let net = e.network().clone();
    let mut evd = Evidence::new();
    for (k, v) in ev {
        if let Some(id) = net.id(k) {
            evd.set_state(id, net.state(id, v).unwrap());
        }
    }
    e.propagate(&evd).unwrap();
    e.marginal(src).to_vec()
}

/// A small deterministic generator (Knuth's MMIX LCG, high bits) for the random cycles below.
fn lcg(mut seed: u64) -> impl FnMut() -> u64 {
    move || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        seed >> 33
    }
}

/// The same names with the same probabilities, bit for bit.
fn assert_same_bits<'a>(
    want: &BTreeMap<String, f64>,
    got: impl IntoIterator<Item = (&'a String, &'a f64)>,
    cycle: usize,
) {
    let got: Vec<(&String, &f64)> = got.into_iter().collect();
    assert_eq!(want.len(), got.len(), "cycle {cycle}");
    for ((kw, vw), (kg, vg)) in want.iter().zip(got) {
        assert_eq!(kw, kg, "cycle {cycle}");
        assert_eq!(vw.to_bits(), vg.to_bits(), "cycle {cycle}: {kw}");
    }
}

/// The cycle's path (evidence by observation state index, probabilities by slot) against the
/// name path (`evaluate_into` on the evidence map): the same published probabilities, bit for
/// bit, cycle after cycle (the carried beliefs and memos evolve alike), over values that move
/// every observation across its thresholds, leave some out, and give some non-finite values.
#[test]
fn evidence_by_state_index_equals_evidence_by_name() {
    let params = crate::shipped::params();
    let mut by_name = HealthModel::load(&params).unwrap();
    let mut by_index = HealthModel::load(&params).unwrap();
    let observations = by_name.observations.clone();
    let mut next = lcg(0x9e37_79b9_7f4a_7c15);
    let (mut states, mut evidence) = (crate::evidence::EvidenceStates::default(), BTreeMap::new());
    let (mut want, mut got) = (BTreeMap::new(), NamedSlots::default());
    let mut non_empty = 0;
    for cycle in 0..300 {
        let mut obs = Observations::default();
        for o in &observations.observations {
            let v = match next() % 8 {
                0 => continue, // absent
                1 => f64::NAN, // no evidence either
                k => {
                    // On, just below or above a threshold, or beyond the last one.
                    let t = o.thresholds.get((k as usize) % (o.thresholds.len() + 1));
                    t.map_or(1e6, |t| t + [0.0, -1e-9, 1e-9][(next() % 3) as usize])
                }
            };
            obs.set(&o.name, v);
        }
        observations.evidence_states_into(&obs, &[], &mut states, &mut evidence);
        non_empty += usize::from(!evidence.is_empty());
        let a = by_name.evaluate_into(&evidence, &mut want);
        let b = by_index.evaluate_states_into(&states, &mut got);
        assert_eq!(a.is_ok(), b.is_ok(), "cycle {cycle}");
        assert_same_bits(&want, &got, cycle);
    }
    assert!(
        non_empty > 250,
        "the values gave evidence in {non_empty} of 300 cycles"
    );
}

/// The evidence built from states is kept while the states repeat, and only then: a by-name
/// evaluation in between (other evidence) is not mistaken for it. Cycle `k`'s snapshot repeats
/// cycle `k - 2`'s when `k % 3 == 2`, and cycle `k % 3 == 1` evaluates by name; every cycle's
/// probabilities equal a by-name reference's, bit for bit.
#[test]
fn evidence_kept_for_repeated_states_is_dropped_by_a_name_evaluation() {
    let params = crate::shipped::params();
    let mut reference = HealthModel::load(&params).unwrap();
    let mut mixed = HealthModel::load(&params).unwrap();
    let observations = reference.observations.clone();
    let mut next = lcg(0x2545_f491_4f6c_dd1d);
    let (mut states, mut evidence) = (crate::evidence::EvidenceStates::default(), BTreeMap::new());
    let (mut want, mut got_by_name) = (BTreeMap::new(), BTreeMap::new());
    let mut got = NamedSlots::default();
    let mut snapshots: Vec<Observations> = Vec::new();
    let (mut differ, mut ok) = (0, 0);
    for cycle in 0..120 {
        let obs = if cycle % 3 == 2 {
            snapshots[cycle - 2].clone()
        } else {
            let mut obs = Observations::default();
            for o in &observations.observations {
                let k = (next() as usize) % (o.thresholds.len() + 2);
                if let Some(t) = o.thresholds.get(k) {
                    obs.set(&o.name, *t);
                } else if k == o.thresholds.len() {
                    obs.set(&o.name, -1e6);
                }
            }
            obs
        };
        snapshots.push(obs.clone());
        observations.evidence_states_into(&obs, &[], &mut states, &mut evidence);
        if cycle % 3 == 1 && snapshots[cycle - 1] != obs {
            differ += 1;
        }
        let a = reference.evaluate_into(&evidence, &mut want);
        let b = if cycle % 3 == 1 {
            let b = mixed.evaluate_into(&evidence, &mut got_by_name);
            if b.is_ok() {
                got = got_by_name.iter().map(|(k, v)| (k.clone(), *v)).collect();
            }
            b
        } else {
            mixed.evaluate_states_into(&states, &mut got)
        };
        // Some random evidence is impossible in a network: then both say so.
        assert_eq!(a.is_ok(), b.is_ok(), "cycle {cycle}");
        ok += usize::from(a.is_ok());
        assert_same_bits(&want, &got, cycle);
    }
    assert!(
        differ > 30,
        "the name evaluations saw other evidence in {differ} of 40 cycles"
    );
    assert!(ok > 60, "{ok} of 120 evaluations succeeded");
}
