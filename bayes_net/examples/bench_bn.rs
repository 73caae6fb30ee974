//! Time exact inference on the exported health BNs in-process, for the side-by-side comparison
//! with pgmpy and pyAgrum (`bench/compare`).
//!
//! Reads the JSON written by `companion --example export_health_bn` (first argument), compiles
//! each manager's network once with the query nodes as targets, then per repetition answers one
//! evidence set (cycling through the sets, so the evidence changes between queries) with
//! [`Engine::query`] and reads the query nodes' posteriors, as the peers do (pyAgrum's
//! LazyPropagation also keeps its junction tree and answers only what is asked).
//! `times_ns` holds one `Instant` measurement around query + reads per query (warm engine: the
//! plan of each evidence *pattern* is compiled on first sight and reused, the values differ).
//! Also reported, not compared: `cold_times_ns`, the first query of each evidence set on a fresh
//! engine (plan compilation included), and `full_times_ns`, the full-marginal
//! [`Engine::propagate`] (every node's posterior) per query.
//! Prints `{"managers":[{"name","posteriors":[[[p..]..]..],"times_ns":[..],..}]}` where
//! `posteriors[e][q]` is the posterior of query node `q` under evidence set `e`.
//!
//! Run: `cargo run --release -p bayes_net --example bench_bn -- health_bn.json [reps] [budget_s]`.
use bayes_net::{Engine, Evidence, NetworkBuilder, NodeId};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::hint::black_box;
use std::time::Instant;

/// The export's layout (`companion/examples/export_health_bn.rs`).
#[derive(Deserialize)]
struct Export {
    managers: Vec<Manager>,
}

#[derive(Deserialize)]
struct Manager {
    name: String,
    nodes: Vec<Node>,
    query: Vec<String>,
    /// One map node -> observed state per evidence set.
    evidence: Vec<BTreeMap<String, String>>,
}

#[derive(Deserialize)]
struct Node {
    name: String,
    states: Vec<String>,
    parents: Vec<String>,
    cpt: Vec<f64>,
}

#[derive(Serialize)]
struct Out {
    managers: Vec<Timed>,
}

#[derive(Serialize)]
struct Timed {
    name: String,
    posteriors: Vec<Vec<Vec<f64>>>,
    times_ns: Vec<u64>,
    cold_times_ns: Vec<u64>,
    full_times_ns: Vec<u64>,
}

type Res<T> = Result<T, Box<dyn std::error::Error>>;

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .ok_or("usage: bench_bn EXPORT.json [reps] [budget_s]")?;
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let reps: usize = args.get(2).map_or(Ok(10_000), |s| s.parse())?;
    let budget: f64 = args.get(3).map_or(Ok(1.0), |s| s.parse())?;
    let doc: Export = serde_json::from_str(&text).map_err(|e| format!("{path}: {e}"))?;
    let mut out = Out {
        managers: Vec::new(),
    };
    for m in &doc.managers {
        out.managers.push(time_manager(m, reps, budget)?);
    }
    println!("{}", serde_json::to_string(&out)?);
    Ok(())
}

fn time_manager(m: &Manager, reps: usize, budget: f64) -> Res<Timed> {
    let mut b = NetworkBuilder::new();
    for n in &m.nodes {
        b.add_node(&n.name, &n.states, &n.parents, n.cpt.clone());
    }
    let net = b.build().map_err(|e| format!("{}: {e}", m.name))?;
    let query: Vec<NodeId> = m
        .query
        .iter()
        .map(|q| net.id(q).ok_or(format!("{}: no query node {q}", m.name)))
        .collect::<Result<_, _>>()?;
    let mut sets = Vec::with_capacity(m.evidence.len());
    for e in &m.evidence {
        let mut ev = Evidence::new();
        for (k, v) in e {
            let id = net
                .id(k)
                .ok_or(format!("{}: no evidence node {k}", m.name))?;
            let s = net
                .state(id, v)
                .map_err(|e| format!("{}: node {k}: {e}", m.name))?;
            ev.set_state(id, s);
        }
        sets.push(ev);
    }
    let mut engine = net.compile();
    engine
        .set_targets(&query)
        .map_err(|e| format!("{}: {e}", m.name))?;
    let mut cold_times_ns = Vec::with_capacity(sets.len());
    for ev in &sets {
        let mut fresh = engine.clone();
        let t0 = Instant::now();
        fresh
            .query(black_box(ev))
            .map_err(|e| format!("{}: {e}", m.name))?;
        black_box(fresh.marginal(query[0])[0]);
        cold_times_ns.push(t0.elapsed().as_nanos() as u64);
    }
    let mut posteriors = Vec::with_capacity(sets.len());
    for ev in &sets {
        engine.query(ev).map_err(|e| format!("{}: {e}", m.name))?;
        posteriors.push(query.iter().map(|q| engine.marginal(*q).to_vec()).collect());
    }
    let times_ns = time(&mut engine, &sets, &query, reps, budget, Engine::query)
        .map_err(|e| format!("{}: {e}", m.name))?;
    let full_times_ns = time(
        &mut engine,
        &sets,
        &query,
        reps,
        budget / 4.0,
        Engine::propagate,
    )
    .map_err(|e| format!("{}: {e}", m.name))?;
    Ok(Timed {
        name: m.name.clone(),
        posteriors,
        times_ns,
        cold_times_ns,
        full_times_ns,
    })
}

/// Time `run` + reading the query nodes' first posterior entries, cycling through `sets`.
fn time(
    engine: &mut Engine,
    sets: &[Evidence],
    query: &[NodeId],
    reps: usize,
    budget: f64,
    run: fn(&mut Engine, &Evidence) -> Result<(), bayes_net::BnError>,
) -> Result<Vec<u64>, bayes_net::BnError> {
    let mut times_ns = Vec::with_capacity(reps);
    let mut spent = 0.0;
    let mut k = 0;
    while !sets.is_empty() && times_ns.len() < reps && (times_ns.len() < 3 || spent < budget) {
        let ev = &sets[k % sets.len()];
        k += 1;
        let t0 = Instant::now();
        run(engine, black_box(ev))?;
        let mut acc = 0.0;
        for q in query {
            acc += engine.marginal(*q)[0];
        }
        black_box(acc);
        let dt = t0.elapsed();
        spent += dt.as_secs_f64();
        times_ns.push(dt.as_nanos() as u64);
    }
    Ok(times_ns)
}
