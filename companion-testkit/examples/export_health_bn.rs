//! Export the health managers' Bayesian networks (as loaded from params/) to JSON for the
//! side-by-side comparison with pgmpy and pyAgrum (`bench/compare`).
//!
//! Per manager: nodes (name, states, parents, CPT row-major over the parents' state combinations,
//! first parent most significant), the published nodes (the query set: what the decision layer
//! reads), and `sets` evidence sets of hard findings on the observable nodes (names starting with
//! `A_` appearance contexts or `S_` monitors, else the leaves), drawn with a fixed LCG and kept
//! only when the evidence has non-zero probability.
//!
//! Run from the workspace root:
//! `cargo run -p companion --example export_health_bn -- [params_dir] [out.json] [sets]`.
use companion_core::health::HealthModel;
use serde_json::{Value, json};
use std::path::Path;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let params = args.get(1).map_or("params", |s| s.as_str());
    let out = args
        .get(2)
        .map_or("bench/out/health_bn.json", |s| s.as_str());
    let sets: usize = args.get(3).map_or(Ok(20), |s| s.parse())?;
    let model = HealthModel::load(&companion::params::read_params_dir(Path::new(params))?)?;
    let mut seed: u64 = 0x5eed_b00c;
    let mut rnd = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut managers = Vec::new();
    for m in &model.managers {
        let net = m.engine().network();
        let nodes: Vec<Value> = net
            .nodes()
            .iter()
            .map(|n| {
                json!({
                    "name": n.name,
                    "states": n.states,
                    "parents": n.parents.iter().map(|p| net.node(*p).name.clone()).collect::<Vec<_>>(),
                    "cpt": n.cpt,
                })
            })
            .collect();
        let mut observable: Vec<usize> = (0..net.len())
            .filter(|&i| {
                let name = &net.nodes()[i].name;
                name.starts_with("A_") || name.starts_with("S_")
            })
            .collect();
        if observable.is_empty() {
            observable = (0..net.len())
                .filter(|&i| {
                    !net.nodes()
                        .iter()
                        .any(|n| n.parents.iter().any(|p| p.0 == i))
                })
                .collect();
        }
        let mut query: Vec<String> = m.publish.iter().map(|p| p.node.clone()).collect();
        query.sort();
        query.dedup();
        let mut engine = net.compile();
        let mut evidence_sets = Vec::new();
        let mut tries = 0;
        while evidence_sets.len() < sets && tries < sets * 50 {
            tries += 1;
            let mut ev = bayes_net::Evidence::new();
            let mut named = serde_json::Map::new();
            for &i in &observable {
                if rnd() < 0.5 {
                    let k = net.nodes()[i].states.len();
                    let s = ((rnd() * k as f64) as usize).min(k - 1);
                    ev.set_state(bayes_net::NodeId(i), s);
                    named.insert(net.nodes()[i].name.clone(), json!(net.nodes()[i].states[s]));
                }
            }
            // Query nodes carry no evidence, so every peer returns a posterior for each.
            if query.iter().any(|q| named.contains_key(q)) {
                continue;
            }
            if engine.propagate(&ev).is_ok() {
                evidence_sets.push(Value::Object(named));
            }
        }
        managers.push(json!({
            "name": m.name,
            "file": m.file,
            "nodes": nodes,
            "query": query,
            "evidence": evidence_sets,
        }));
    }
    if let Some(dir) = Path::new(out).parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(
        out,
        serde_json::to_string(&json!({ "managers": managers }))?,
    )?;
    eprintln!("wrote {out}");
    Ok(())
}
