//! The primitive actions are named by params/actions.toml, not by the code: a params set whose
//! actions are all renamed (`take_off` -> `renamed_take_off`, ...) everywhere the params name them
//! flies the same simulated missions, decision for decision, under the new names. The world, the
//! shell and the review find what an action does by its `role` (companion_core::action_role).

use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, Model, ModelKind};
use companion_core::mission::{ActionRole, MissionStates};
use companion_core::spec::ParamsFiles;

const PREFIX: &str = "renamed_";

fn shipped() -> ParamsFiles {
    companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap()
}

/// The action ids params/actions.toml declares (read by TOML, not by the code under test).
fn action_ids(files: &ParamsFiles) -> Vec<String> {
    let dir = files.dir().to_path_buf();
    let text = files.text(&dir.join("actions.toml")).unwrap();
    let doc: toml::Table = toml::from_str(text).unwrap();
    doc["action"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["id"].as_str().unwrap().to_string())
        .collect()
}

/// `text` with every quoted action id `"x"` (and the tracking glob `"track_v*"`) renamed, on the
/// lines `keep` accepts; with `tables`, `[x]` table headers too (commands.toml).
fn rename(text: &str, ids: &[String], keep: impl Fn(&str) -> bool, tables: bool) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let mut l = line.to_string();
        if keep(l.trim_start()) {
            for x in ids {
                l = l.replace(&format!("\"{x}\""), &format!("\"{PREFIX}{x}\""));
                if tables && l == format!("[{x}]") {
                    l = format!("[{PREFIX}{x}]");
                }
            }
            l = l.replace("\"track_v*\"", &format!("\"{PREFIX}track_v*\""));
        }
        out.push_str(&l);
        out.push('\n');
    }
    out
}

/// The shipped params with every action renamed where params name actions: their declaration,
/// the MDPs' `does`, the tracking states' `action`, the policies' rules and orders, the commands'
/// tables and the link's precedence. PANORAMA objectives (`objective = "land"`) and route states
/// are not actions and keep their names.
fn renamed_params() -> ParamsFiles {
    let mut files = shipped();
    let ids = action_ids(&files);
    let dir = files.dir().to_path_buf();
    let mdps: Vec<String> = [
        "index",
        "navigation",
        "landing",
        "tracking",
        "monolithic",
        "reference",
    ]
    .iter()
    .map(|m| format!("mdp/{m}.toml"))
    .collect();
    let mut edit = |name: &str, keep: &dyn Fn(&str) -> bool, tables: bool| {
        let path = dir.join(name);
        let text = files.text(&path).unwrap().to_string();
        files.insert(path, rename(&text, &ids, keep, tables));
    };
    edit("actions.toml", &|l| l.starts_with("id ="), false);
    edit("mission.toml", &|l| l.contains("action ="), false);
    edit("policies.toml", &|l| !l.starts_with('#'), false);
    edit("commands.toml", &|l| !l.starts_with('#'), true);
    edit("link.toml", &|l| !l.starts_with('#'), false);
    for m in &mdps {
        edit(m, &|l| l.starts_with("does ="), false);
    }
    files
}

/// A record as JSON with the renamed actions named as before, wherever they appear (lists,
/// keys, sentences).
fn unrenamed_json(r: &companion_core::record::DecisionRecord) -> String {
    serde_json::to_string(r).unwrap().replace(PREFIX, "")
}

#[test]
fn renamed_params_keep_every_role_under_the_new_names() {
    let states = MissionStates::load(&renamed_params()).unwrap();
    let roles = states.actions();
    for role in ActionRole::ALL {
        let a = roles.action(role);
        assert!(a.starts_with(PREFIX), "{role:?} is played by `{a}`");
    }
    assert_eq!(roles.role_of("take_off"), None, "the old name is gone");
    assert_eq!(
        states.tracking_target(&[format!("{PREFIX}track_v3")]),
        Some(("v3", "V3"))
    );
}

#[test]
fn simulate_with_renamed_actions_decides_the_same_records_under_the_new_names() {
    let (old_files, new_files) = (shipped(), renamed_params());
    assert!(!unrenamed_json(&Default::default()).contains(PREFIX));
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
        ("emergency-landing", ModelKind::Bfm, "safety"),
        ("complete-2", ModelKind::Monolithic, "safety"),
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
        // The renamed run really chose the new names, and flew past the take-off.
        assert!(
            new.records
                .iter()
                .any(|r| r.actions.contains_name(&format!("{PREFIX}take_off"))),
            "{case}: no renamed take-off"
        );
        assert!(
            new.records
                .iter()
                .all(|r| r.actions.iter().all(|a| a.starts_with(PREFIX))),
            "{case}: an action kept its old name"
        );
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
