//! Malformed params stop start-up everywhere: each case copies params/ to a temporary folder,
//! breaks one entry, and asserts that the load `simulate` and `fly` start with
//! (`Params::load`), `companion check`'s report and, for the link files, `fly`'s own setup all
//! refuse it with a message naming the file and the entry. docs/params.md, "Limits".

mod common;
use common::copy_dir;
use companion::check::{self, CheckArgs};
use companion::fly::{FlyArgs, FlySetup};
use companion::params::Params;
use companion::params::default_params_dir;
use std::path::Path;

/// A fresh copy of the real params.
fn params_copy() -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    copy_dir(&default_params_dir(), d.path());
    d
}

fn edit(dir: &Path, rel: &str, f: impl FnOnce(String) -> String) {
    let p = dir.join(rel);
    let text = std::fs::read_to_string(&p).unwrap();
    let new = f(text.clone());
    assert_ne!(new, text, "{rel}: the edit changed nothing");
    std::fs::write(&p, new).unwrap();
}

/// Replace the line starting with `key =` (first match) by `key = value`.
fn set(dir: &Path, rel: &str, key: &str, value: &str) {
    edit(dir, rel, |t| {
        let mut done = false;
        t.lines()
            .map(|l| {
                if !done && l.trim_start().starts_with(&format!("{key} =")) {
                    done = true;
                    format!("{key} = {value}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n")
    });
}

fn fly_args(dir: &Path) -> FlyArgs {
    let mut args =
        FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"]).unwrap();
    args.params = Some(dir.to_path_buf());
    args
}

/// Params::load, check's report and (for the files fly reads itself) FlySetup::load all fail,
/// each message naming `rel` and containing `entry` and `reason`.
fn refused_everywhere(dir: &Path, rel: &str, entry: &str, reason: &str) {
    refused(dir, rel, entry, reason, true)
}

/// As [`refused_everywhere`] for a check between files: `fly` runs it in `Params::load` before
/// its own setup, which reads the link files alone.
fn refused_by_cross_check(dir: &Path, rel: &str, entry: &str, reason: &str) {
    refused(dir, rel, entry, reason, false)
}

fn refused(dir: &Path, rel: &str, entry: &str, reason: &str, fly_setup_too: bool) {
    let want = |what: &str, msg: String| {
        assert!(
            msg.contains(rel) && msg.contains(entry) && msg.contains(reason),
            "{what}: expected {rel} / {entry} / {reason:?} in: {msg}"
        );
    };
    let e = Params::load(dir, None)
        .err()
        .unwrap_or_else(|| panic!("{rel} {entry}: simulate and fly (Params::load) accepted it"));
    assert!(e.file.ends_with(rel), "{e}");
    want("Params::load", e.to_string());
    let args = CheckArgs {
        params: Some(dir.to_path_buf()),
        ..Default::default()
    };
    let e = check::report(&args)
        .err()
        .unwrap_or_else(|| panic!("{rel} {entry}: check accepted it"));
    want("check", format!("{e:#}"));
    if fly_setup_too
        && ["link.toml", "commands.toml", "missions/tracking_route.toml"].contains(&rel)
    {
        let e = FlySetup::load(&fly_args(dir))
            .err()
            .unwrap_or_else(|| panic!("{rel} {entry}: fly's setup accepted it"));
        want("FlySetup::load", format!("{e:#}"));
    }
}

fn case(rel: &str, key: &str, value: &str, entry: &str, reason: &str) {
    let d = params_copy();
    set(d.path(), rel, key, value);
    refused_everywhere(d.path(), rel, entry, reason);
}

#[test]
fn the_real_params_load_everywhere() {
    let d = params_copy();
    Params::load(d.path(), None).unwrap();
    check::report(&CheckArgs {
        params: Some(d.path().to_path_buf()),
        ..Default::default()
    })
    .unwrap();
    FlySetup::load(&fly_args(d.path())).unwrap();
}

#[test]
fn distance_max_age_negative_nan_or_huge_is_refused() {
    for v in ["-2.0", "nan", "1e30", "1e5"] {
        case(
            "link.toml",
            "distance_max_age_s",
            v,
            "telemetry.distance_max_age_s",
            "",
        );
    }
}

#[test]
fn decision_period_tiny_or_huge_is_refused() {
    for v in ["1e-12", "1e30", "0.0"] {
        case("link.toml", "decision_period_s", v, "decision_period_s", "");
    }
}

#[test]
fn arm_wait_huge_is_refused() {
    for v in ["1e30", "7200.0", "inf"] {
        case("link.toml", "arm_wait_s", v, "arm_wait_s", "");
    }
}

#[test]
fn detection_threshold_nan_is_refused() {
    case(
        "link.toml",
        "detection_threshold",
        "nan",
        "telemetry.detection_threshold",
        "not a finite number",
    );
    case(
        "link.toml",
        "detection_threshold",
        "1.5",
        "telemetry.detection_threshold",
        "0..=1",
    );
}

#[test]
fn broken_link_toml_is_refused_naming_the_line() {
    case("link.toml", "arm_wait_s", "[60", "line", "");
}

#[test]
fn commands_toml_syntax_error_is_refused_naming_the_file() {
    case("commands.toml", "steps", "[ { mode = ", "line", "");
}

#[test]
fn empty_commands_toml_is_refused() {
    let d = params_copy();
    std::fs::write(d.path().join("commands.toml"), "").unwrap();
    refused_everywhere(d.path(), "commands.toml", "-", "empty");
    std::fs::write(d.path().join("commands.toml"), "# only a comment\n").unwrap();
    refused_everywhere(d.path(), "commands.toml", "-", "no vehicle actions");
}

#[test]
fn commands_toml_missing_a_vehicle_action_is_refused() {
    let d = params_copy();
    // The entry removed (a renamed one is refused sooner, as naming no action).
    edit(d.path(), "commands.toml", |t| {
        let at = t.find("[return_to_base]").unwrap();
        let end = t[at..].find("]\n\n").map_or(t.len(), |e| at + e + 3);
        format!("{}{}", &t[..at], &t[end..])
    });
    refused_by_cross_check(
        d.path(),
        "commands.toml",
        "return_to_base",
        "no MAVLink steps",
    );
}

#[test]
fn commands_toml_entry_naming_no_action_is_refused() {
    let d = params_copy();
    edit(d.path(), "commands.toml", |t| {
        t.replace("[return_to_base]", "[return_to_base_renamed]")
    });
    refused_everywhere(
        d.path(),
        "commands.toml",
        "return_to_base_renamed",
        "not an action of params/actions.toml",
    );
}

#[test]
fn empty_observations_toml_is_refused() {
    let d = params_copy();
    std::fs::write(d.path().join("observations.toml"), "# nothing\n").unwrap();
    refused_everywhere(
        d.path(),
        "observations.toml",
        "observation",
        "no observations",
    );
}

#[test]
fn no_concurrent_mdps_is_refused() {
    case(
        "mdp/index.toml",
        "concurrent",
        "[]",
        "concurrent",
        "at least one",
    );
}

/// The first half of the file's lines.
fn cut_in_half(dir: &Path, rel: &str) {
    edit(dir, rel, |t| {
        let lines: Vec<&str> = t.lines().collect();
        lines[..lines.len() / 2].join("\n")
    });
}

#[test]
fn mission_toml_cut_in_half_is_refused() {
    let d = params_copy();
    cut_in_half(d.path(), "mission.toml");
    refused_everywhere(d.path(), "mission.toml", "", "");
}

#[test]
fn platform_toml_cut_in_half_is_refused() {
    let d = params_copy();
    cut_in_half(d.path(), "platform.toml");
    refused_everywhere(d.path(), "platform.toml", "line", "missing field");
    // Cut where the TOML stays valid: the frame-rate models after the first one are gone.
    let d = params_copy();
    edit(d.path(), "platform.toml", |t| {
        let at = t.find("[performance.landing_search]").unwrap();
        t[..at].to_string()
    });
    refused_by_cross_check(
        d.path(),
        "platform.toml",
        "performance.",
        "no frame-rate model",
    );
}

#[test]
fn route_altitude_absurd_is_refused() {
    case(
        "missions/tracking_route.toml",
        "altitude_m",
        "1e300",
        "altitude_m",
        "out of range",
    );
}

#[test]
fn route_of_70000_waypoints_is_refused() {
    let many =
        |n: usize| move |t: String| t + &"\n[[waypoint]]\nnorth_m = 1.0\neast_m = 1.0\n".repeat(n);
    let rel = "missions/tracking_route.toml";
    // 70,000 waypoints are over the params file size limit before any parsing.
    let d = params_copy();
    edit(d.path(), rel, many(70_000));
    refused_everywhere(d.path(), rel, "-", "a params file is at most");
    // Under it, the route limit.
    let d = params_copy();
    edit(d.path(), rel, many(5_000));
    refused_everywhere(d.path(), rel, "waypoint", "a route holds at most 1000");
}

#[test]
fn broken_route_file_is_refused() {
    let d = params_copy();
    edit(d.path(), "missions/tracking_route.toml", |t| {
        t + "\n[[waypoint]\n"
    });
    refused_everywhere(d.path(), "missions/tracking_route.toml", "line", "");
}

#[test]
fn mdp_expression_of_100000_terms_is_refused_not_a_stack_overflow() {
    let d = params_copy();
    let long = format!("P_sys{}", "+P_sys".repeat(100_000));
    edit(d.path(), "mdp/navigation.toml", |t| {
        t.replacen(
            "A1 = { wp1 = \"P_sys\"",
            &format!("A1 = {{ wp1 = \"{long}\""),
            1,
        )
    });
    refused_everywhere(d.path(), "mdp/navigation.toml", "A1", "at most 2000");
}

#[test]
fn mdp_expression_of_300_terms_is_refused_by_size() {
    let d = params_copy();
    let long = format!("P_sys{}", "*P_sys".repeat(300));
    edit(d.path(), "mdp/navigation.toml", |t| {
        t.replacen(
            "A1 = { wp1 = \"P_sys\"",
            &format!("A1 = {{ wp1 = \"{long}\""),
            1,
        )
    });
    refused_everywhere(d.path(), "mdp/navigation.toml", "A1", "at most 256");
}

/// `n` binary context nodes and one monitor node with all of them as parents.
fn node_with_parents(dir: &Path, n: usize, states: usize) {
    edit(dir, "health/system.toml", |mut t| {
        let names: Vec<String> = (0..n).map(|i| format!("C_extra{i}")).collect();
        let st: Vec<String> = (0..states).map(|i| format!("\"s{i}\"")).collect();
        let prior = vec![format!("{}", 1.0 / states as f64); states];
        for name in &names {
            t += &format!(
                "\n[node.{name}]\nrole = \"context\"\nstates = [{}]\nprior = [{}]\n",
                st.join(", "),
                prior.join(", ")
            );
        }
        let parents: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
        t += &format!(
            "\n[node.S_extra]\nrole = \"monitor\"\nstates = [\"ok\", \"bad\"]\nparents = [{}]\n",
            parents.join(", ")
        );
        t
    });
}

#[test]
fn health_node_with_22_or_70_parents_is_refused_without_allocating() {
    for n in [22, 40, 70] {
        let d = params_copy();
        node_with_parents(d.path(), n, 2);
        refused_everywhere(
            d.path(),
            "health/system.toml",
            "node.S_extra.parents",
            "at most 16",
        );
    }
}

#[test]
fn health_node_table_over_the_size_limit_is_refused() {
    // 12 parents of 4 states: 4^12 * 2 = 33 M probabilities.
    let d = params_copy();
    node_with_parents(d.path(), 12, 4);
    refused_everywhere(
        d.path(),
        "health/system.toml",
        "node.S_extra.parents",
        "more than 65536",
    );
}

#[test]
fn any_non_finite_or_huge_number_is_refused_with_its_entry() {
    case(
        "platform.toml",
        "cpu_mhz",
        "inf",
        "cpu_mhz",
        "not a finite number",
    );
    case("world.toml", "step_s", "1e30", "step_s", "out of range");
}

#[test]
fn a_fifo_as_a_params_file_is_refused_not_read() {
    let d = params_copy();
    let f = d.path().join("link.toml");
    std::fs::remove_file(&f).unwrap();
    let ok = std::process::Command::new("mkfifo")
        .arg(&f)
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!("mkfifo unavailable: skipped");
        return;
    }
    refused_everywhere(d.path(), "link.toml", "-", "not a regular file");
}

#[test]
fn health_manager_whose_small_tables_join_into_a_huge_clique_is_refused() {
    // 24 binary contexts and a two-parent monitor for every pair of them: each table has 8
    // probabilities, but inference would join all 24 contexts into one table of 2^24.
    let d = params_copy();
    edit(d.path(), "health/system.toml", |mut t| {
        let n = 24;
        for i in 0..n {
            t += &format!(
                "\n[node.C_extra{i}]\nrole = \"context\"\nstates = [\"a\", \"b\"]\nprior = [0.5, 0.5]\n"
            );
        }
        for i in 0..n {
            for j in i + 1..n {
                t += &format!(
                    "\n[node.S_pair{i}_{j}]\nrole = \"monitor\"\nstates = [\"ok\", \"bad\"]\n\
                     parents = [\"C_extra{i}\", \"C_extra{j}\"]\n\
                     cpt = [[0.5, 0.5], [0.5, 0.5], [0.5, 0.5], [0.5, 0.5]]\n"
                );
            }
        }
        t
    });
    refused_everywhere(d.path(), "health/system.toml", "node", "at most 1048576");
}

#[test]
fn health_manager_of_600_nodes_is_refused_before_compiling() {
    let d = params_copy();
    edit(d.path(), "health/system.toml", |mut t| {
        for i in 0..600 {
            t += &format!(
                "\n[node.C_extra{i}]\nrole = \"context\"\nstates = [\"a\", \"b\"]\nprior = [0.5, 0.5]\n"
            );
        }
        t
    });
    refused_everywhere(d.path(), "health/system.toml", "node", "at most 500");
}

#[test]
fn mdp_of_5000_states_is_refused_before_its_tables_are_allocated() {
    let d = params_copy();
    let many: Vec<String> = (0..5000).map(|i| format!("\"s{i}\"")).collect();
    edit(d.path(), "mdp/navigation.toml", |t| {
        let at = t.find("\nstates = [").unwrap() + 1;
        let end = at + t[at..].find(']').unwrap() + 1;
        let states = &t[at..end];
        let grown = states.replacen('[', &format!("[{}, ", many.join(", ")), 1);
        t.replacen(states, &grown, 1)
    });
    refused_everywhere(d.path(), "mdp/navigation.toml", "states", "at most 256");
}

#[test]
fn mdp_horizon_of_a_billion_steps_is_refused() {
    case(
        "mission.toml",
        "horizon",
        "1000000000",
        "horizon",
        "1..=10000",
    );
}

/// An edit of one mission state of params/mission.toml, refused by every loader with `entry`
/// and `reason`; `fly`'s own setup (its mission-state estimator reads the states) too.
fn mission_state_refused(from: &str, to: &str, entry: &str, reason: &str) {
    let d = params_copy();
    edit(d.path(), "mission.toml", |t| t.replacen(from, to, 1));
    refused_everywhere(d.path(), "mission.toml", entry, reason);
    let e = FlySetup::load(&fly_args(d.path()))
        .err()
        .unwrap_or_else(|| panic!("{entry}: fly's setup accepted it"));
    let msg = format!("{e:#}");
    assert!(
        msg.contains("mission.toml") && msg.contains(entry) && msg.contains(reason),
        "{msg}"
    );
}

#[test]
fn mission_state_in_an_unknown_phase_is_refused() {
    mission_state_refused(
        r#"{ name = "wpf", phase = "wpf" }"#,
        r#"{ name = "wpf", phase = "cruise" }"#,
        "states[3]",
        "unknown phase `cruise`",
    );
}

#[test]
fn duplicate_mission_state_is_refused() {
    mission_state_refused(
        r#"{ name = "wp1", phase = "wp1" }"#,
        r#"{ name = "base", phase = "wp1" }"#,
        "states[1]",
        "duplicate state `base`",
    );
}

#[test]
fn tracking_state_kept_by_an_unknown_or_missing_action_is_refused() {
    mission_state_refused(
        r#"action = "track_v5""#,
        r#"action = "track_v9""#,
        "states[10].action",
        "`track_v9` is not an application action",
    );
    mission_state_refused(
        r#"{ name = "v2", phase = "tracking", action = "track_v2" }"#,
        r#"{ name = "v2", phase = "tracking" }"#,
        "states[7]",
        "names no `action`",
    );
}

#[test]
fn projection_naming_an_undeclared_state_is_refused() {
    mission_state_refused(
        r#"states = ["target", "v0", "v1", "v2", "v3", "v4", "v5"]"#,
        r#"states = ["target", "v0", "v1", "v2", "v3", "v4", "v6"]"#,
        "projection.navigation[2].states",
        "`v6` is not a declared state",
    );
}

#[test]
fn route_state_missing_undeclared_or_playing_two_roles_is_refused() {
    mission_state_refused(
        "between_waypoints = \"wpi\"\n",
        "",
        "route_states.between_waypoints",
        "missing",
    );
    mission_state_refused(
        r#"last_waypoint = "wpf""#,
        r#"last_waypoint = "wp_final""#,
        "route_states.last_waypoint",
        "`wp_final` is not a declared state",
    );
    mission_state_refused(
        r#"landing = "landing""#,
        r#"landing = "base""#,
        "route_states.landing",
        "`base` already plays the route role `on_ground`",
    );
    mission_state_refused(
        r#"on_ground = "base""#,
        "on_ground = \"base\"\nhover = \"wpf\"",
        "route_states.hover",
        "not a route role",
    );
}

#[test]
fn scenario_triggered_in_an_unknown_phase_is_refused() {
    let d = params_copy();
    edit(d.path(), "scenarios/complete-1.toml", |t| {
        t.replacen(r#"phase = "tracking""#, r#"phase = "trackng""#, 1)
    });
    let files = companion::params::read_params_dir(d.path()).unwrap();
    let e = companion::sim::Scenario::load(&files, "complete-1").unwrap_err();
    assert!(e.file.ends_with("scenarios/complete-1.toml"), "{e}");
    assert_eq!(e.entry, "hazard[0].trigger.phase");
    assert!(e.reason.contains("`trackng` is not a phase"), "{e}");
}
