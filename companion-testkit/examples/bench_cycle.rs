//! Time the full decision cycle (observations to plan: evidence, every health BN, the MDPs,
//! behaviour and resource arbitration, the PANORAMA guarantee) in-process and count its heap
//! allocations, for bench/compare's "decision cycle" case (target: 50 us median).
//!
//! Prints one JSON object `{"cases":[{"name","median_us","p99_us","max_us","cycles",
//! "allocations_per_cycle","mdp_solves_per_cycle","scheduler_runs_per_cycle"}]}`. Each case warms
//! a core up for 100 cycles on its stream, then times `Core::step_into` alone, once per cycle
//! (`Instant` around the call), over `cycles` cycles (first argument, default 2000).
//!
//! Cases: `steady` (time and battery move, evidence does not), `changing` (vibration evidence
//! flips every cycle: health probabilities and every MDP's inputs change), `worst` (the changing
//! stream with the memos off: every MDP re-solved and the scheduler re-run every cycle), and
//! `monolithic` (section 5's single MDP on the changing stream).
//!
//! Then, for each case again, where the time goes: the core's stage hook
//! (`companion_core::stage_hook`, installed only after every timed run, so the medians above
//! are of the uninstrumented cycle) reads the clock at every stage boundary over `cycles / 2`
//! cycles; each case's `stages` gives per stage (`evidence`, `health/<manager>`, `health/carry`,
//! `mdp/<name>`, `arbitration`, `scheduler`, `resolve`, `guarantee`, `record`) the mean us per
//! cycle and its share of their sum (which includes the hook's own clock reads, about 20 ns per
//! boundary). `models` gives the sizes: per health manager its BN (nodes, CPT entries, cliques
//! and their table entries), per MDP its states, actions, choices (state-action pairs) and
//! transitions. The same breakdown is printed as a table on stderr.
//!
//! Run: `cargo run --release -p companion-testkit --example bench_cycle -- 2000 [CASE,CASE...]`
//! (the optional second argument keeps only the named cases, e.g. `changing` for a profile).
use companion::params::default_params_dir;
use companion_core::decision::{Core, ModelKind};
use companion_core::record::{DecisionRecord, Plan};
use companion_core::stage_hook::{Stage, set_stage_hook};
use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
use serde_json::json;
use std::cell::{Cell, RefCell};
use std::hint::black_box;
use std::time::{Duration, Instant};

// The same counting allocator as the no-allocation tests (counts this thread's allocations).
#[path = "../tests/support/counting_alloc.rs"]
mod counting_alloc;
use counting_alloc::allocations;

fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i]
}

thread_local! {
    /// The last stage boundary's time, and per stage (in first-seen order) its total and count.
    static LAST: Cell<Option<Instant>> = const { Cell::new(None) };
    /// Per stage: its key (the addresses and length of its group and name: the names are the
    /// model's own strings, so a stage is found without comparing text, which would add to the
    /// times measured), its label and its total.
    #[allow(clippy::type_complexity)]
    static STAGES: RefCell<Vec<((usize, usize, usize), String, Duration)>> = const { RefCell::new(Vec::new()) };
}

/// The stage hook: the time since the last boundary goes to the stage that just ended.
fn on_stage(stage: Stage<'_>) {
    let now = Instant::now();
    let Some(last) = LAST.replace(Some(now)) else {
        return;
    };
    let dt = now - last;
    let (group, name) = match stage {
        Stage::CycleStart => return,
        Stage::Evidence => ("evidence", ""),
        Stage::HealthManager(m) => ("health/", m),
        Stage::HealthCarry => ("health/carry", ""),
        Stage::Mdp(m) => ("mdp/", m),
        Stage::Arbitration => ("arbitration", ""),
        Stage::Scheduler => ("scheduler", ""),
        Stage::Resolve => ("resolve", ""),
        Stage::Guarantee => ("guarantee", ""),
        Stage::Record => ("record", ""),
    };
    let key = (group.as_ptr() as usize, name.as_ptr() as usize, name.len());
    STAGES.with_borrow_mut(|st| match st.iter_mut().find(|(k, _, _)| *k == key) {
        Some((_, _, t)) => *t += dt,
        None => st.push((key, format!("{group}{name}"), dt)),
    });
}

/// BN and MDP sizes of the loaded model.
fn model_sizes(model: &companion_core::decision::Model) -> serde_json::Value {
    let bn: Vec<_> = model
        .health
        .managers
        .iter()
        .map(|m| {
            let e = m.engine();
            let net = e.network();
            let card = |id: bayes_net::NodeId| net.node(id).states.len();
            let cliques = e.cliques();
            let tables: Vec<usize> = cliques
                .iter()
                .map(|c| c.iter().map(|&v| card(v)).product())
                .collect();
            json!({
                "manager": m.name,
                "nodes": net.len(),
                "cpt_entries": net.nodes().iter().map(|n| n.cpt.len()).sum::<usize>(),
                "max_cpt": net.nodes().iter().map(|n| n.cpt.len()).max().unwrap_or(0),
                "cliques": cliques.len(),
                "clique_entries": tables.iter().sum::<usize>(),
                "max_clique": e.max_clique_size(),
            })
        })
        .collect();
    let mdp: Vec<_> = model
        .mdps
        .all()
        .iter()
        .map(|m| {
            let e = m.mdp();
            json!({
                "name": m.name(),
                "states": e.n_states(),
                "actions": e.n_actions(),
                "choices": e.n_choices(),
                "transitions": e.n_transitions(),
            })
        })
        .collect();
    json!({ "bn": bn, "mdp": mdp })
}

fn main() {
    let cycles: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("cycles: a number"))
        .unwrap_or(2000);
    let only: Vec<String> = std::env::args()
        .nth(2)
        .map(|a| a.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    let params = default_params_dir();
    let model = std::sync::Arc::new(companion::params::load_model(&params).expect("params load"));
    let base = tracking_snapshot(&model, &params, "complete-1");
    let mut out = Vec::new();
    let cases: Vec<_> = [
        ("steady", ModelKind::Bfm, Stream::Steady, true),
        ("changing", ModelKind::Bfm, Stream::Changing, true),
        ("worst", ModelKind::Bfm, Stream::Changing, false),
        ("monolithic", ModelKind::Monolithic, Stream::Changing, true),
    ]
    .into_iter()
    .filter(|c| only.is_empty() || only.iter().any(|o| o == c.0))
    .collect();
    let warm_core = |kind, stream, caches| {
        let stream_gen = StreamGen::new(&model, base.clone(), stream);
        let mut core = Core::new(
            std::sync::Arc::clone(&model),
            kind,
            model.policy("safety").unwrap(),
        );
        core.set_caches(caches);
        let mut obs = base.clone();
        let (mut plan, mut rec) = (Plan::default(), DecisionRecord::default());
        for k in 0..100 {
            stream_gen.advance(&mut obs, k);
            core.step_into(&obs, &mut plan, &mut rec);
        }
        (stream_gen, core, obs, plan, rec)
    };
    for &(name, kind, stream, caches) in &cases {
        let (stream_gen, mut core, mut obs, mut plan, mut rec) = warm_core(kind, stream, caches);
        let work0 = core.work_done();
        let mut times = Vec::with_capacity(cycles as usize);
        let mut allocs = 0;
        for k in 100..100 + cycles {
            stream_gen.advance(&mut obs, k);
            let mut dt = Duration::ZERO;
            allocs += allocations(|| {
                let t0 = Instant::now();
                core.step_into(black_box(&obs), &mut plan, &mut rec);
                dt = t0.elapsed();
            });
            black_box(&rec);
            times.push(dt.as_secs_f64() * 1e6);
        }
        let work = core.work_done();
        times.sort_by(f64::total_cmp);
        let per = |x: u64| x as f64 / cycles as f64;
        out.push(json!({
            "name": name,
            "median_us": percentile(&times, 0.5),
            "p99_us": percentile(&times, 0.99),
            "max_us": times[times.len() - 1],
            "cycles": cycles,
            "allocations_per_cycle": allocs as f64 / cycles as f64,
            "mdp_solves_per_cycle": per(work.mdp_solves - work0.mdp_solves),
            "scheduler_runs_per_cycle": per(work.scheduler_runs - work0.scheduler_runs),
        }));
    }
    // Where the time goes: the same cases again with the stage hook installed.
    set_stage_hook(on_stage);
    eprintln!("{:<24} {:>10} {:>7}", "stage", "us/cycle", "share");
    for (&(name, kind, stream, caches), case) in cases.iter().zip(&mut out) {
        let (stream_gen, mut core, mut obs, mut plan, mut rec) = warm_core(kind, stream, caches);
        STAGES.with_borrow_mut(Vec::clear);
        let n = (cycles / 2).max(1);
        for k in 100..100 + n {
            stream_gen.advance(&mut obs, k);
            core.step_into(black_box(&obs), &mut plan, &mut rec);
            LAST.set(None);
        }
        // Labels merged (two keys may name one stage if its name lives in two places).
        let mut stages: Vec<(String, Duration)> = Vec::new();
        STAGES.with_borrow(|st| {
            for (_, label, t) in st {
                match stages.iter_mut().find(|(l, _)| l == label) {
                    Some((_, x)) => *x += *t,
                    None => stages.push((label.clone(), *t)),
                }
            }
        });
        let total: f64 = stages.iter().map(|(_, t)| t.as_secs_f64()).sum();
        eprintln!(
            "case {name}: {:.2} us/cycle in stages",
            total * 1e6 / n as f64
        );
        let rows: Vec<_> = stages
            .iter()
            .map(|(k, t)| {
                let us = t.as_secs_f64() * 1e6 / n as f64;
                let share = t.as_secs_f64() / total;
                eprintln!("  {k:<22} {us:>10.3} {:>6.1}%", share * 100.0);
                json!({ "stage": k, "us_per_cycle": us, "share": share })
            })
            .collect();
        case["stages"] = json!(rows);
    }
    println!("{}", json!({ "cases": out, "models": model_sizes(&model) }));
}
