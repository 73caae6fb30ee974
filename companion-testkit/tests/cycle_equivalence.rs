//! The fast decision cycle changes no output: `step_into` with reused buffers equals `step`, and
//! the memos (MDP solves, resource schedules) equal re-solving every cycle, record for record and
//! bit for bit (compared as the decision log's JSON, which round-trips f64 exactly), over whole
//! simulated missions of every scenario, model kind and policy.

use companion::params::default_params_dir;
use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, Model, ModelKind, Policy};
use companion_core::observations::Observations;
use companion_core::record::{DecisionRecord, Plan};
use std::sync::{Arc, OnceLock};

/// The shipped model, loaded once per test binary and shared (each core holds its `Arc`).
fn model() -> Arc<Model> {
    static M: OnceLock<Arc<Model>> = OnceLock::new();
    Arc::clone(M.get_or_init(|| {
        Arc::new(
            companion::params::load_model(&companion::params::default_params_dir())
                .expect("params load"),
        )
    }))
}

/// The policies by name (params/policies.toml).
fn safety() -> Policy {
    model().policy("safety").unwrap()
}

fn mission() -> Policy {
    model().policy("mission").unwrap()
}

/// The plan (actions by name, as every core of the shipped model names them) and the record.
fn json(plan: &Plan, rec: &DecisionRecord) -> String {
    let m = model();
    format!(
        "{}\n{}",
        serde_json::to_string(&plan.named(|a| m.actions.name(a))).unwrap(),
        serde_json::to_string(rec).unwrap()
    )
}

/// Every (scenario, kind, policy, seed) mission, observations as the reference core saw them.
fn missions() -> Vec<(String, ModelKind, Policy, u64)> {
    let params = default_params_dir();
    let mut out = Vec::new();
    for s in Scenario::names(&params) {
        for kind in [ModelKind::Bfm, ModelKind::Monolithic, ModelKind::Reference] {
            for policy in [safety(), mission()] {
                for seed in [1, 7] {
                    out.push((s.clone(), kind, policy, seed));
                }
            }
        }
    }
    assert!(
        out.len() >= 8 * 3 * 2 * 2,
        "scenarios missing: {}",
        out.len()
    );
    out
}

/// Fly one mission with a reference core (caches off, fresh buffers through `step`), and feed the
/// same observations to `candidate`, comparing each cycle.
fn compare(
    name: &str,
    kind: ModelKind,
    policy: Policy,
    seed: u64,
    mut candidate: impl FnMut(&Observations) -> String,
) -> usize {
    let params = default_params_dir();
    let files = companion::params::read_params_dir(&params).unwrap();
    let world = WorldSpec::load(&files).unwrap();
    let scenario = Scenario::load(&files, name).unwrap();
    let mut reference = Core::new(model(), kind, policy);
    reference.set_caches(false);
    let mut cycles = 0;
    let result = sim::run(&world, &scenario, seed, |obs| {
        let (plan, rec) = reference.step(obs);
        let want = json(&plan, &rec);
        let got = candidate(obs);
        assert_eq!(
            got, want,
            "{name} {kind:?} {policy:?} seed {seed} cycle {}",
            rec.cycle
        );
        cycles += 1;
        (plan, rec)
    });
    assert_eq!(cycles, result.records.len());
    cycles
}

#[test]
fn step_into_with_reused_buffers_equals_step_without_caches() {
    let mut total = 0;
    // Buffers start out holding another mission's last cycle: step_into must overwrite it all.
    let mut plan = Plan::default();
    let mut rec = DecisionRecord::default();
    for (name, kind, policy, seed) in missions() {
        let mut core = Core::new(model(), kind, policy);
        total += compare(&name, kind, policy, seed, |obs| {
            core.step_into(obs, &mut plan, &mut rec);
            json(&plan, &rec)
        });
    }
    assert!(total > 1000, "only {total} cycles compared");
}

#[test]
fn cached_step_equals_uncached_step() {
    for (name, kind, policy, seed) in missions() {
        let mut core = Core::new(model(), kind, policy);
        compare(&name, kind, policy, seed, |obs| {
            let (plan, rec) = core.step(obs);
            json(&plan, &rec)
        });
    }
}

/// The memos are exercised, not bypassed: on a steady tracking stream the carried battery belief
/// settles (bit-exactly, within a hundred cycles here) and then no MDP is re-solved and the
/// scheduler is not re-run; when the vibration evidence flips every cycle, the two input points
/// of each MDP are remembered, so after the first flips nothing is re-solved either; with the
/// memos off all three MDPs are re-solved every cycle.
#[test]
fn memos_hit_on_a_settled_stream_and_miss_when_evidence_flips() {
    use companion_testkit::streams::{Stream, StreamGen, tracking_snapshot};
    let params = default_params_dir();
    let base = tracking_snapshot(&model(), &params, "complete-1");
    for (stream, memos, solves_per_cycle) in [
        (Stream::Steady, true, 0),
        (Stream::Changing, true, 0),
        (Stream::Changing, false, 3),
    ] {
        let stream_gen = StreamGen::new(&model(), base.clone(), stream);
        let mut core = Core::new(model(), ModelKind::Bfm, safety());
        core.set_caches(memos);
        let mut obs = base.clone();
        for k in 0..200 {
            stream_gen.advance(&mut obs, k);
            core.step(&obs);
        }
        let w0 = core.work_done();
        for k in 200..300 {
            stream_gen.advance(&mut obs, k);
            core.step(&obs);
        }
        let w = core.work_done();
        assert_eq!(w.cycles - w0.cycles, 100);
        assert_eq!(
            w.mdp_solves - w0.mdp_solves,
            100 * solves_per_cycle,
            "{stream:?} memos {memos}"
        );
        if memos {
            assert_eq!(
                w.scheduler_runs, w0.scheduler_runs,
                "{stream:?}: same requests"
            );
        }
    }
}
