//! Numbers the docs quote that the code produces cannot drift (issue 39 item 5): each such number
//! is written just before a marker `<!-- doc-number NAME -->`, and this test recomputes every
//! marked number by the recipe NAME (below) and compares it at the precision the doc writes
//! (0.63 is checked to two decimals). A marker without a recipe fails, and so does a recipe no
//! doc uses. `scripts/doc_numbers.sh` prints every number (run with `--nocapture`).

mod common;
// The optimality-gap measurement of docs/guarantee.md, as `cargo run -p panorama --example gap`
// runs it.
#[path = "../../panorama/examples/gap.rs"]
#[allow(dead_code)]
mod gap;
use common::shipped_model;
use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, Model, ModelKind};
use companion_core::mission_mdp::MissionMdps;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The docs that carry marked numbers (read at build time: a doc edit rebuilds the test).
const DOCS: [(&str, &str); 3] = [
    (
        "docs/params/mdp.md",
        include_str!("../../docs/params/mdp.md"),
    ),
    (
        "docs/simulation.md",
        include_str!("../../docs/simulation.md"),
    ),
    ("docs/guarantee.md", include_str!("../../docs/guarantee.md")),
];
const MARKER: &str = "<!-- doc-number ";

/// Every marked number: (doc, recipe name, the number as written).
fn marked() -> Vec<(&'static str, String, String)> {
    let mut out = Vec::new();
    for (doc, text) in DOCS {
        for (at, _) in text.match_indices(MARKER) {
            let name = &text[at + MARKER.len()..];
            let name = &name[..name.find(" -->").expect("marker ends with -->")];
            let before = &text[..at];
            let start = before
                .rfind(|c: char| !(c.is_ascii_digit() || c == '.'))
                .map_or(0, |i| i + 1);
            let written = before[start..].to_string();
            assert!(
                written.parse::<f64>().is_ok(),
                "{doc}: marker {name} follows no number (`{written}`)"
            );
            out.push((doc, name.to_string(), written));
        }
    }
    out
}

/// `x` written with as many decimals as `like`.
fn at_precision(x: f64, like: &str) -> String {
    let decimals = like.split_once('.').map_or(0, |(_, d)| d.len());
    format!("{x:.decimals$}")
}

/// The section 7.1 check point of params/mdp/index.toml with `name` set to `value`.
fn check_point(mdps: &MissionMdps, name: &str, value: f64) -> BTreeMap<String, f64> {
    let mut p = mdps.check_point().clone();
    assert!(p.contains_key(name), "{name} is not in the check point");
    p.insert(name.to_string(), value);
    p
}

/// The stage-0 action (horizon 100, as in section 7) of MDP `mdp` in `state`.
fn decision(
    mdps: &mut MissionMdps,
    mdp: &str,
    state: &str,
    probs: &BTreeMap<String, f64>,
    policy: &str,
) -> String {
    let m = mdps.get_mut(mdp).unwrap();
    let s = m.state_index(state).unwrap();
    let mut ws = Default::default();
    let d = m.decide(&mut ws, s, probs, policy, 100).unwrap().unwrap();
    m.action_name(d.action).to_string()
}

/// Where MDP `mdp` in `state` stops choosing `keep` (alone or first of a joint action) as `prob`
/// falls (the other probabilities at
/// the check point): checked to be a single switch on a grid of 101 points, then bisected.
fn switch_point(mdp: &str, state: &str, keep: &str, prob: &str, policy: &str) -> f64 {
    let mut mdps = shipped_model().mdps.clone();
    let mut keeps = |x: f64| {
        let p = check_point(&mdps, prob, x);
        let a = decision(&mut mdps, mdp, state, &p, policy);
        a == keep || a.starts_with(&format!("{keep}+"))
    };
    let grid: Vec<bool> = (0..=100).map(|i| keeps(f64::from(i) / 100.0)).collect();
    let switches = grid.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(
        switches == 1 && !grid[0] && grid[100],
        "{mdp}/{state}/{policy}: `{keep}` is not kept exactly above one value of {prob}: {grid:?}"
    );
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..40 {
        let mid = (lo + hi) / 2.0;
        if keeps(mid) { hi = mid } else { lo = mid }
    }
    hi
}

/// Mean tracking steps of `scenario` under `policy` over seeds 1..=`runs` (as `simulate --runs`
/// numbers them), BFM models, the typed plan of params/missions/tracking.toml (`simulate
/// --mission tracking`); with `binds` false, params/mission.toml's `[guarantee] binds = false`.
fn mean_tracking(scenario: &str, policy: &str, runs: u64, binds: bool) -> f64 {
    let mut files =
        companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap();
    let model = if binds {
        shipped_model()
    } else {
        let path = files.dir().join("mission.toml");
        let text = files.text(&path).unwrap();
        assert_eq!(text.matches("\n[guarantee]\n").count(), 1);
        let text = text.replacen("\n[guarantee]\n", "\n[guarantee]\nbinds = false\n", 1);
        files.insert(&path, text);
        Arc::new(Model::load(&files).unwrap())
    };
    let world = WorldSpec::load(&files).unwrap();
    let scenario = Scenario::load(&files, scenario).unwrap();
    let policy = model.policy(policy).unwrap();
    let xs: Vec<f64> = (1..=runs)
        .map(|seed| {
            let mut core = Core::new(Arc::clone(&model), ModelKind::Bfm, policy);
            sim::run(&world, &scenario, seed, |obs| core.step(obs)).tracking_steps as f64
        })
        .collect();
    sim::mean_ci95(&xs).0
}

/// A value of the optimality-gap table (`cargo run -p panorama --example gap`: seed 2024, 2000
/// instances per family), computed once: `row` as `g1_cost`, `g1_indep`, `g2_cost`, `g2_indep`.
fn gap_value(row: &str, column: &str) -> f64 {
    static ROWS: std::sync::OnceLock<Vec<gap::GapRow>> = std::sync::OnceLock::new();
    let rows = ROWS.get_or_init(|| gap::rows(2024, 2000));
    let r = rows
        .iter()
        .find(|r| {
            row == format!(
                "g{}_{}",
                r.goals,
                if r.correlated { "cost" } else { "indep" }
            )
        })
        .unwrap_or_else(|| panic!("no gap family {row}"));
    match column {
        "solved" => r.solved as f64,
        "optimal" => r.optimal_pct,
        "mean" => r.mean,
        "p95" => r.p95,
        "max" => r.max,
        "missed" => r.missed as f64,
        _ => panic!("no gap column {column}"),
    }
}

/// The recipe of each marker name.
fn compute(name: &str) -> Option<f64> {
    if let Some(rest) = name.strip_prefix("gap.") {
        let (row, column) = rest.split_once('.')?;
        return Some(gap_value(row, column));
    }
    let v = match name {
        "mdp.navigation_wpf.safety" => {
            switch_point("navigation", "wpf", "A11", "P_battery", "safety")
        }
        "mdp.navigation_wpf.mission" => {
            switch_point("navigation", "wpf", "A11", "P_battery", "mission")
        }
        "mdp.tracking_v3.safety" => switch_point("tracking", "v3", "A15", "P_battery", "safety"),
        "mdp.tracking_v3.mission" => switch_point("tracking", "v3", "A15", "P_battery", "mission"),
        "mdp.landing_zone_t_ok.safety" => {
            switch_point("landing", "zone_t_ok", "A5", "P_battery", "safety")
        }
        "mdp.landing_zone_t_ok.mission" => {
            switch_point("landing", "zone_t_ok", "A5", "P_battery", "mission")
        }
        "mdp.monolithic_v3.safety" => {
            switch_point("monolithic", "v3", "A15", "P_battery", "safety")
        }
        "mdp.monolithic_v3.mission" => {
            switch_point("monolithic", "v3", "A15", "P_battery", "mission")
        }
        "mdp.reference_s5.safety" => switch_point("reference", "S5", "A4", "P_track", "safety"),
        "mdp.reference_s5.mission" => switch_point("reference", "S5", "A4", "P_track", "mission"),
        "sim40.complete_1.safety" => mean_tracking("complete-1", "safety", 40, true),
        "sim40.complete_1.mission" => mean_tracking("complete-1", "mission", 40, true),
        "sim40.complete_2.safety" => mean_tracking("complete-2", "safety", 40, true),
        "sim40.complete_2.mission" => mean_tracking("complete-2", "mission", 40, true),
        "sim200.complete_1.safety" => mean_tracking("complete-1", "safety", 200, true),
        "sim200.complete_2.safety" => mean_tracking("complete-2", "safety", 200, true),
        "binds40.nominal.on" => mean_tracking("nominal", "safety", 40, true),
        "binds40.nominal.off" => mean_tracking("nominal", "safety", 40, false),
        "binds40.vibrations.on" => mean_tracking("vibrations", "safety", 40, true),
        "binds40.vibrations.off" => mean_tracking("vibrations", "safety", 40, false),
        "binds40.high_speed.on" => mean_tracking("high-speed", "safety", 40, true),
        "binds40.high_speed.off" => mean_tracking("high-speed", "safety", 40, false),
        _ => return None,
    };
    Some(v)
}

/// Every recipe, so one no doc uses is caught.
const RECIPES: [&str; 22] = [
    "sim40.complete_1.safety",
    "sim40.complete_1.mission",
    "sim40.complete_2.safety",
    "sim40.complete_2.mission",
    "sim200.complete_1.safety",
    "sim200.complete_2.safety",
    "binds40.nominal.on",
    "binds40.nominal.off",
    "binds40.vibrations.on",
    "binds40.vibrations.off",
    "binds40.high_speed.on",
    "binds40.high_speed.off",
    "mdp.monolithic_v3.safety",
    "mdp.monolithic_v3.mission",
    "mdp.navigation_wpf.safety",
    "mdp.navigation_wpf.mission",
    "mdp.tracking_v3.safety",
    "mdp.tracking_v3.mission",
    "mdp.landing_zone_t_ok.safety",
    "mdp.landing_zone_t_ok.mission",
    "mdp.reference_s5.safety",
    "mdp.reference_s5.mission",
];

#[test]
fn every_marked_number_in_the_docs_is_what_the_code_gives() {
    let marked = marked();
    // Each distinct number once, in parallel (the simulations take seconds each in debug).
    let names: std::collections::BTreeSet<&str> =
        marked.iter().map(|(_, n, _)| n.as_str()).collect();
    let values: BTreeMap<&str, f64> = std::thread::scope(|scope| {
        let handles: Vec<_> = names
            .iter()
            .map(|&n| (n, scope.spawn(move || compute(n))))
            .collect();
        handles
            .into_iter()
            .map(|(n, h)| {
                let v = h
                    .join()
                    .unwrap()
                    .unwrap_or_else(|| panic!("no recipe for doc-number {n}"));
                (n, v)
            })
            .collect()
    });
    let mut wrong = Vec::new();
    for (doc, name, written) in &marked {
        let v = values[name.as_str()];
        let code = at_precision(v, written);
        println!("doc-number {name} = {v:.4} (code {code}, {doc} writes {written})");
        if code != *written {
            wrong.push(format!(
                "{doc}: {name} writes {written}, the code gives {code} ({v})"
            ));
        }
    }
    for r in RECIPES {
        assert!(values.contains_key(r), "recipe {r} is marked in no doc");
    }
    let gap_cells = values.keys().filter(|n| n.starts_with("gap.")).count();
    assert_eq!(
        gap_cells, 24,
        "the gap table's 4 rows x 6 columns are marked"
    );
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}
