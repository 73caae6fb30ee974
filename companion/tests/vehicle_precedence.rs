//! The shell's one-motion-at-a-time choice (params/link.toml `vehicle_action_precedence`) must never
//! contradict the behaviour arbitration of params/policies.toml: for every pair of vehicle actions the
//! shell orders, whichever policy is in force, the policy must not drop the action the shell prefers
//! while keeping the other. The shell only orders what the policies leave standing together.

use companion::params::default_params_dir;
use companion_core::arbitration::BehaviourConflicts;
use companion_link::actions::LinkParams;
use companion_link::mission_state::select_vehicle_action;

/// The primitive actions (the names policies.toml patterns match), as `companion check --json`
/// lists them under `actions`.
fn primitives() -> Vec<String> {
    let files = companion::params::read_params_dir(&default_params_dir()).unwrap();
    let (v, _) =
        companion::check::report_from(files, &companion::check::CheckArgs::default()).unwrap();
    v["actions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn precedence_never_overrules_a_policy() {
    let dir = default_params_dir();
    let files = companion::params::read_params_dir(&dir).unwrap();
    let link = LinkParams::load(&files, &dir.join("link.toml")).unwrap();
    let primitives = primitives();
    let names: Vec<&str> = primitives.iter().map(String::as_str).collect();
    let conflicts = BehaviourConflicts::load(&files, &dir.join("policies.toml"), &names).unwrap();
    let order = &link.vehicle_action_precedence;
    assert!(order.len() >= 2, "{order:?}");
    for policy in ["safety", "mission"] {
        for (i, first) in order.iter().enumerate() {
            for second in &order[i + 1..] {
                let (kept, _) = conflicts.resolve(&[second, first], policy).unwrap();
                assert!(
                    kept.contains(first),
                    "{policy}: the shell prefers {first} over {second}, but the policy keeps {kept:?}"
                );
                // And the shell does pick it from what the policy left.
                assert_eq!(
                    select_vehicle_action(&kept, order).map(|a| a.as_str()),
                    Some(first.as_str())
                );
            }
        }
    }
}

#[test]
fn a_precedence_that_contradicts_the_policy_is_caught() {
    // return_to_base before land contradicts both policies' return_vs_landing rule (land wins).
    let dir = default_params_dir();
    let files = companion::params::read_params_dir(&dir).unwrap();
    let primitives = primitives();
    let names: Vec<&str> = primitives.iter().map(String::as_str).collect();
    let conflicts = BehaviourConflicts::load(&files, &dir.join("policies.toml"), &names).unwrap();
    let (kept, _) = conflicts
        .resolve(&["land", "return_to_base"], "safety")
        .unwrap();
    assert_eq!(kept, vec!["land".to_string()]);
}
