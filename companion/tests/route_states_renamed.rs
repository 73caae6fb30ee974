//! The route's states are named by params/mission.toml `route_states`, not by the code: a params
//! set whose route states are all renamed (`base` -> `r_base`, ...) flies the same simulated
//! missions, decision for decision, under the new names.

use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, Model, ModelKind};
use companion_core::mission::{MissionStates, RouteRole};
use companion_core::spec::ParamsFiles;

/// The shipped route states, in flight order.
const ROUTE: [&str; 6] = ["base", "wp1", "wpi", "wpf", "target", "landing"];

/// The MDPs of every model (params/mdp/): each gets rules projecting a renamed route state onto
/// the MDP state of its old name, so the MDPs see what they saw before.
const MDPS: [&str; 5] = [
    "navigation",
    "landing",
    "tracking",
    "monolithic",
    "reference",
];

fn renamed(x: &str) -> String {
    format!("r_{x}")
}

/// mission.toml with every route state renamed where it names a shared state (the declared
/// states, `route_states`, `guarantee.activity_of_state`, projection rules' `states`); phases and
/// MDP states keep their names. Rules appended last only catch what used to fall back to the
/// shared state's own name.
fn rename_mission(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let mut l = line.to_string();
        let keep = l.starts_with('#') || l.starts_with("phases") || l.starts_with("state =");
        if !keep {
            for x in ROUTE {
                if l.trim_start().starts_with("{ name =") {
                    l = l.replace(
                        &format!("name = \"{x}\""),
                        &format!("name = \"{}\"", renamed(x)),
                    );
                } else {
                    l = l.replace(&format!("\"{x}\""), &format!("\"{}\"", renamed(x)));
                    if l.starts_with("activity_of_state") {
                        l = l.replace(&format!(" {x} = "), &format!(" {} = ", renamed(x)));
                    }
                }
            }
        }
        out.push_str(&l);
        out.push('\n');
    }
    for mdp in MDPS {
        for x in ROUTE {
            out.push_str(&format!(
                "\n[[projection.{mdp}]]\nstates = [\"{}\"]\nstate = \"{x}\"\n",
                renamed(x)
            ));
        }
    }
    out
}

fn shipped() -> ParamsFiles {
    companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap()
}

fn renamed_params() -> ParamsFiles {
    let mut files = shipped();
    let dir = files.dir().to_path_buf();
    let mission = files.text(&dir.join("mission.toml")).unwrap().to_string();
    files.insert(dir.join("mission.toml"), rename_mission(&mission));
    let world = files.text(&dir.join("world.toml")).unwrap().to_string();
    let world = world.replace(
        "initial_state = \"base\"",
        &format!("initial_state = \"{}\"", renamed("base")),
    );
    files.insert(dir.join("world.toml"), world);
    files
}

/// A record as JSON with the renamed route states named as before.
fn unrenamed_json(r: &companion_core::record::DecisionRecord) -> String {
    let mut s = serde_json::to_string(r).unwrap();
    for x in ROUTE {
        s = s.replace(&format!("\"{}\"", renamed(x)), &format!("\"{x}\""));
    }
    s
}

#[test]
fn renamed_params_name_no_route_state_by_its_old_name() {
    let states = MissionStates::load(&renamed_params()).unwrap();
    for (role, x) in RouteRole::ALL.into_iter().zip(ROUTE) {
        assert_eq!(states.route_state(role), renamed(x));
        assert!(!states.has_state(x), "`{x}` still declared");
    }
    // Phases keep their names: scenario triggers (`phase = "wpi"`) still fire.
    assert_eq!(states.phase(&renamed("wpi")), "wpi");
}

#[test]
fn simulate_with_renamed_route_states_decides_the_same_records_under_the_new_names() {
    let (old_files, new_files) = (shipped(), renamed_params());
    let (old_model, new_model) = (
        std::sync::Arc::new(Model::load(&old_files).unwrap()),
        std::sync::Arc::new(Model::load(&new_files).unwrap()),
    );
    let (old_world, new_world) = (
        WorldSpec::load(&old_files).unwrap(),
        WorldSpec::load(&new_files).unwrap(),
    );
    let cases = [
        ("complete-1", ModelKind::Bfm, "safety"),
        ("complete-1", ModelKind::Bfm, "mission"),
        ("complete-1", ModelKind::Reference, "safety"),
        ("complete-1", ModelKind::Monolithic, "mission"),
        ("lidar-failure", ModelKind::Bfm, "safety"),
    ];
    for (scenario, kind, policy) in cases {
        let case = format!("{scenario}/{policy}/{}", kind.name());
        let run = |files: &ParamsFiles, model: &std::sync::Arc<Model>, world: &WorldSpec| {
            let s = Scenario::load(files, scenario).unwrap();
            let mut core = Core::new(
                std::sync::Arc::clone(model),
                kind,
                model.policy(policy).unwrap(),
            );
            sim::run(world, &s, 1, |obs| core.step(obs))
        };
        let old = run(&old_files, &old_model, &old_world);
        let new = run(&new_files, &new_model, &new_world);
        assert_eq!(old.records.len(), new.records.len(), "{case}");
        // The renamed run really moved through the new names.
        assert!(
            new.records.iter().any(|r| r.state == renamed("wpi")),
            "{case}: no record in r_wpi"
        );
        assert!(new.records.iter().all(|r| r.state != "wpi"), "{case}");
        for (i, (o, n)) in old.records.iter().zip(&new.records).enumerate() {
            assert_eq!(
                serde_json::to_string(o).unwrap(),
                unrenamed_json(n),
                "{case}: record {i}"
            );
        }
        assert_eq!(old.outcome, new.outcome, "{case}");
        assert_eq!(old.tracking_steps, new.tracking_steps, "{case}");
    }
}
