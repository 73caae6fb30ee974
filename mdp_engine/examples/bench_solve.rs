//! Solve exported MDPs and time the solve in-process, for the side-by-side comparison with
//! Python peers (`bench/compare`).
//!
//! Reads a plan (JSON file given as the first argument):
//! `{"cases":[{"name","path","solver":"fh"|"vi"|"pi","horizon","gamma","tolerance","reps","budget_s"}]}`
//! and prints one JSON object `{"cases":[{"name","values","policy","iterations","times_ns":[..]}]}`
//! where `values`/`policy` are stage 0 for the finite horizon, `policy` uses -1 for terminal states,
//! and `times_ns` holds one `Instant` measurement around the solve call only per repetition, with a
//! warm workspace (one untimed solve first). Repetitions stop at `reps` or once `budget_s` seconds
//! of timed solving have passed (at least 3). An optional `"threads"` per case: 1 sweeps on one
//! thread, N >= 2 splits every finite-horizon / value-iteration sweep across a pool of N threads
//! (`Workspace::set_parallel_min_transitions(0)`), absent or 0 the engine's default (split from
//! `PARALLEL_MIN_TRANSITIONS` transitions on, on rayon's global pool).
//!
//! Run: `cargo run --release -p mdp_engine --example bench_solve -- plan.json`.
use mdp_engine::{Config, Mdp, Workspace};
use serde_json::{Value, json};
use std::hint::black_box;
use std::time::Instant;

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: bench_solve plan.json");
    let plan: Value = serde_json::from_str(&std::fs::read_to_string(&path).expect("read plan"))
        .expect("plan json");
    let mut out = Vec::new();
    let mut models: std::collections::HashMap<String, Mdp> = Default::default();
    let mut ws = Workspace::new();
    #[cfg(feature = "parallel")]
    let mut pools: std::collections::HashMap<usize, rayon::ThreadPool> = Default::default();
    for case in plan["cases"].as_array().expect("cases") {
        let name = case["name"].as_str().expect("name").to_string();
        let mpath = case["path"].as_str().expect("path").to_string();
        let mdp = models.entry(mpath.clone()).or_insert_with(|| {
            serde_json::from_str(&std::fs::read_to_string(&mpath).expect("read model"))
                .expect("model json")
        });
        let solver = case["solver"].as_str().expect("solver");
        let horizon = case["horizon"].as_u64().unwrap_or(100) as usize;
        let cfg = Config {
            gamma: case["gamma"].as_f64().unwrap_or(0.95),
            tolerance: case["tolerance"].as_f64().unwrap_or(1e-10),
            ..Config::default()
        };
        let reps = case["reps"].as_u64().unwrap_or(100) as usize;
        let budget = case["budget_s"].as_f64().unwrap_or(1.0);
        let threads = case["threads"].as_u64().unwrap_or(0) as usize;
        ws.set_parallel_min_transitions(match threads {
            0 => mdp_engine::PARALLEL_MIN_TRANSITIONS,
            1 => usize::MAX,
            _ => 0,
        });
        // Only a split case runs in a pool of its own: the others time on this thread, as
        // before the split existed (a pool's idle workers would share the cores with it). One
        // pool per thread count for the whole plan, as the companion keeps one: a pool built
        // per case left the last one's threads winding down on the cores while the next timed.
        #[cfg(feature = "parallel")]
        let pool = (threads >= 2).then(|| {
            &*pools.entry(threads).or_insert_with(|| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .expect("thread pool")
            })
        });
        #[cfg(feature = "parallel")]
        let in_pool = |f: &mut (dyn FnMut() + Send)| match &pool {
            Some(p) => p.install(f),
            None => f(),
        };
        #[cfg(not(feature = "parallel"))]
        let in_pool = |f: &mut (dyn FnMut() + Send)| f();
        // One solve untimed, in the pool that times it: sizes the workspace and wakes the
        // pool's threads (the warm state the companion runs in: its pool lives as long as it
        // does; a fresh pool's first split solve took up to twice as long), and gives the
        // answer for the agreement check.
        let mut untimed = None;
        in_pool(&mut || untimed = Some(untimed_solve(&mut ws, mdp, solver, horizon, &cfg)));
        let (values, policy, iterations) = untimed.expect("the untimed solve ran");
        let mut times = Vec::with_capacity(reps);
        let mut spent = 0.0;
        in_pool(&mut || {
            while times.len() < reps && (times.len() < 3 || spent < budget) {
                let t0 = Instant::now();
                match solver {
                    "fh" => {
                        black_box(ws.finite_horizon(black_box(mdp), horizon).decision(0));
                    }
                    "vi" => {
                        black_box(
                            ws.value_iteration(black_box(mdp), &cfg)
                                .map(|s| s.action(0)),
                        )
                        .ok();
                    }
                    _ => {
                        black_box(
                            ws.policy_iteration(black_box(mdp), &cfg)
                                .map(|s| s.action(0)),
                        )
                        .ok();
                    }
                }
                let dt = t0.elapsed();
                spent += dt.as_secs_f64();
                times.push(dt.as_nanos() as u64);
            }
        });
        out.push(json!({
            "name": name,
            "values": values,
            "policy": policy,
            "iterations": iterations,
            "threads": threads,
            "times_ns": times,
        }));
    }
    println!("{}", json!({ "cases": out }));
}

/// One solve's answer: stage-0 (or converged) values, decisions (-1: none) and iterations.
fn untimed_solve(
    ws: &mut Workspace,
    mdp: &Mdp,
    solver: &str,
    horizon: usize,
    cfg: &Config,
) -> (Vec<f64>, Vec<i64>, u32) {
    let n = mdp.n_states();
    match solver {
        "fh" => {
            let s = ws.finite_horizon(mdp, horizon);
            (
                s.values_at(0).to_vec(),
                (0..n)
                    .map(|i| s.decision(i).map_or(-1, |a| a as i64))
                    .collect(),
                s.stats().iterations,
            )
        }
        "vi" | "pi" => {
            let s = if solver == "vi" {
                ws.value_iteration(mdp, cfg)
            } else {
                ws.policy_iteration(mdp, cfg)
            }
            .expect("solve");
            (
                s.values().to_vec(),
                (0..n)
                    .map(|i| s.action(i).map_or(-1, |a| a as i64))
                    .collect(),
                s.stats.iterations,
            )
        }
        other => panic!("unknown solver {other}"),
    }
}
