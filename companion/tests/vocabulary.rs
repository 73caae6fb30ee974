//! The observation and action vocabularies: a name with no producer or no consumer stops the load
//! with file, entry and reason (params edited in memory), and `check --json` lists every
//! observation and action with its producers and consumers, which the tests read instead of
//! copying names.

use companion::params::{Params, default_params_dir, read_params_dir};
use companion_core::spec::SpecError;
use serde_json::Value;

/// The shipped params with `file`'s text edited by `edit`, loaded as `fly` and `simulate` load.
fn load_edited(file: &str, edit: impl Fn(&str) -> String) -> Result<Params, SpecError> {
    let mut files = read_params_dir(&default_params_dir()).unwrap();
    let path = files.dir().join(file);
    let text = edit(files.text(&path).unwrap());
    assert_ne!(text, files.text(&path).unwrap(), "the edit changed nothing");
    files.insert(&path, text);
    Params::from_files(files, None)
}

fn expect_err(file: &str, edit: impl Fn(&str) -> String, entry: &str, reason: &str) {
    let e = match load_edited(file, edit) {
        Ok(_) => panic!("{file}: the edit must be refused"),
        Err(e) => e,
    };
    assert!(e.file.ends_with(file), "{e}");
    assert_eq!(e.entry, entry, "{e}");
    assert!(e.reason.contains(reason), "{e}");
}

fn check_json() -> Value {
    let files = read_params_dir(&default_params_dir()).unwrap();
    let (v, _) =
        companion::check::report_from(files, &companion::check::CheckArgs::default()).unwrap();
    v
}

fn names(list: &Value) -> Vec<&str> {
    list.as_array()
        .unwrap()
        .iter()
        .map(|x| x["name"].as_str().unwrap())
        .collect()
}

#[test]
fn a_world_baseline_observation_nothing_reads_is_refused() {
    expect_err(
        "world.toml",
        |t| {
            t.replace(
                "temperature_c = 20.0",
                "temperature_c = 20.0\nhumidity_pct = 40.0",
            )
        },
        "baseline.humidity_pct",
        "`humidity_pct` is an observation nothing reads",
    );
}

#[test]
fn a_scenario_setting_an_observation_nothing_reads_is_refused() {
    expect_err(
        "scenarios/vibrations.toml",
        |t| t.replace("vibration_mps2 =", "vibrations_mps2 ="),
        "hazard[0].set.vibrations_mps2",
        "`vibrations_mps2` is an observation nothing reads",
    );
}

#[test]
fn a_declared_observation_nothing_produces_is_refused() {
    // The scenario still sets lidar_failed (mission.toml reads it), but the evidence mapping now
    // names an observation neither the world, a scenario, fly nor the core produces.
    expect_err(
        "observations.toml",
        |t| t.replace("name = \"lidar_failed\"", "name = \"lidar_fault\""),
        "observation[21](lidar_fault)",
        "nothing produces it",
    );
}

#[test]
fn a_failure_the_guarantee_reads_that_nothing_produces_is_refused() {
    // The camera's failure report comes from the onboard monitors (params/link.toml
    // [telemetry.onboard] cam_fail); a name nobody reports would leave the guarantee blind.
    expect_err(
        "mission.toml",
        |t| t.replace("camera = \"camera_failed\"", "camera = \"camera_broken\""),
        "guarantee.failures.camera",
        "`camera_broken` is produced by nothing",
    );
}

#[test]
fn an_observation_for_a_node_no_manager_has_is_refused() {
    expect_err(
        "observations.toml",
        |t| t.replace("node = \"A_temperature\"", "node = \"A_humidity\""),
        "observation[18](temperature_c).node",
        "no health manager has a node `A_humidity`",
    );
}

#[test]
fn a_mavlink_mapping_no_mdp_proposes_is_refused() {
    expect_err(
        "commands.toml",
        |t| format!("{t}\n[hover]\nsteps = [{{ mode = \"LOITER\" }}]\n"),
        "hover",
        "no MDP proposes it",
    );
}

#[test]
fn the_resume_entry_without_its_shell_only_marker_is_refused() {
    expect_err(
        "commands.toml",
        |t| t.replace("flown_for = \"follow_trajectory\"\n", ""),
        "follow_trajectory_resume",
        "no MDP proposes it",
    );
}

#[test]
fn a_shell_only_entry_must_be_flown_for_an_entry_of_the_file() {
    expect_err(
        "commands.toml",
        |t| {
            t.replace(
                "flown_for = \"follow_trajectory\"",
                "flown_for = \"follow_route\"",
            )
        },
        "follow_trajectory_resume.flown_for",
        "`follow_route` is not an entry",
    );
}

#[test]
fn mavlink_steps_for_an_application_action_are_refused() {
    expect_err(
        "commands.toml",
        |t| format!("{t}\n[track_v3]\nsteps = [{{ mode = \"GUIDED\" }}]\n"),
        "track_v3",
        "an application action",
    );
}

#[test]
fn an_mdp_action_missing_from_actions_toml_is_refused() {
    expect_err(
        "mdp/landing.toml",
        |t| t.replacen("does = [\"land\"]", "does = [\"land_here\"]", 1),
        "action[4](A7).does[0]",
        "`land_here` is not an action of params/actions.toml",
    );
}

#[test]
fn an_action_no_mdp_proposes_is_refused() {
    expect_err(
        "actions.toml",
        |t| {
            format!(
                "{t}\n[[action]]\nid = \"hover\"\npaper = \"-\"\nkind = \"vehicle\"\nlabel = \"hover\"\nrole = \"detect_obstacles\"\n"
            )
        },
        "action[18](hover)",
        "no MDP proposes it",
    );
}

/// `check --json`'s `observations`: every observation of the evidence mapping (from `health`'s
/// evidence nodes) is listed with its node, a producer and its health manager as a consumer;
/// every name listed has a reader, and every name a scenario sets is listed.
#[test]
fn json_lists_each_observation_with_its_producers_and_readers() {
    let v = check_json();
    let listed = v["observations"].as_array().unwrap();
    let params = Params::load(&default_params_dir(), None).unwrap();
    for o in &params.model.health.observations.observations {
        let entry = listed
            .iter()
            .find(|x| x["name"] == o.name.as_str())
            .unwrap_or_else(|| panic!("{} not listed", o.name));
        assert_eq!(entry["node"], o.node.as_str(), "{}", o.name);
        assert!(
            !entry["producers"].as_array().unwrap().is_empty(),
            "{}",
            o.name
        );
        // The node's managers read it, as `health` shows them.
        for h in v["health"].as_array().unwrap() {
            let has_node = h["nodes"]
                .as_array()
                .unwrap()
                .iter()
                .any(|n| n["name"] == o.node.as_str());
            let reads = entry["consumers"]
                .as_array()
                .unwrap()
                .iter()
                .any(|c| c["kind"] == "health" && c["name"] == h["name"]);
            assert_eq!(has_node, reads, "{} in {}", o.name, h["name"]);
        }
    }
    for x in listed {
        assert!(!x["consumers"].as_array().unwrap().is_empty(), "{x}");
    }
    let set: Vec<&str> = names(&v["observations"]);
    for s in companion::sim::Scenario::names(&default_params_dir()) {
        let sc = companion::sim::Scenario::load(&params.files, &s).unwrap();
        for h in &sc.hazards {
            for k in h.set.keys() {
                assert!(set.contains(&k.as_str()), "{s} sets {k}, not listed");
                let entry = listed.iter().find(|x| x["name"] == k.as_str()).unwrap();
                assert!(
                    entry["producers"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .any(|p| p["kind"] == "scenario" && p["name"] == sc.name.as_str()),
                    "{k} set by {s}"
                );
            }
        }
    }
}

/// `check --json`'s `actions`: every action some MDP does (from `mdps`) is listed and proposed by
/// that MDP; every vehicle action has MAVLink steps (from `fly`), no application action has.
#[test]
fn json_lists_each_action_with_its_mdps_and_mapping() {
    let v = check_json();
    let listed = v["actions"].as_array().unwrap();
    let params = Params::load(&default_params_dir(), None).unwrap();
    for m in params.model.mdps.all() {
        for k in 0..m.n_actions() {
            for p in m.primitives(k) {
                let entry = listed
                    .iter()
                    .find(|x| x["name"] == p.as_str())
                    .unwrap_or_else(|| panic!("{p} not listed"));
                assert!(
                    entry["proposed_by"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .any(|x| x == m.name()),
                    "{p} proposed by {}",
                    m.name()
                );
            }
        }
    }
    let fly: Vec<&str> = v["fly"]["vehicle_actions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_str().unwrap())
        .collect();
    for a in listed {
        let name = a["name"].as_str().unwrap();
        assert!(!a["proposed_by"].as_array().unwrap().is_empty(), "{name}");
        assert_eq!(a["vehicle_steps"], fly.contains(&name), "{name}");
        if a["kind"] == "application" {
            assert_eq!(a["vehicle_steps"], false, "{name}");
            assert!(a["application"].is_object(), "{name}");
        }
    }
    // Every fly entry is an action or flown in place of one.
    for f in &fly {
        assert!(
            listed
                .iter()
                .any(|a| a["name"] == *f
                    || a["flown_as"].as_array().unwrap().iter().any(|x| x == *f)),
            "{f}"
        );
    }
}

/// The world's own observations (`WORLD_OBSERVATIONS` `computes`) are exactly what a step's
/// snapshot holds beyond the baseline and the hazards in force.
#[test]
fn the_world_computes_what_it_declares() {
    // On the default (derived) plan: the world reports `route_activity` too.
    let (params, _) =
        companion::route_input::load_with_plan(&default_params_dir(), None, None, None, None)
            .unwrap();
    let sc = companion::sim::Scenario::load(&params.files, "nominal").unwrap();
    let mut w = companion::sim::World::new(&params.world, &sc, 1);
    let obs = w.observe();
    let mut extra: Vec<&str> = obs
        .values
        .keys()
        .map(String::as_str)
        .filter(|k| !params.world.baseline.contains_key(*k))
        .collect();
    let mut computes: Vec<&str> = companion::sim::WORLD_OBSERVATIONS
        .iter()
        .filter(|(_, w)| *w == "computes")
        .map(|(o, _)| *o)
        .filter(|o| !params.world.baseline.contains_key(*o))
        .collect();
    extra.sort();
    computes.sort();
    assert_eq!(extra, computes);
}

/// `check --json`'s `absent_evidence`: each evidence node with when it goes without evidence;
/// the wind node says an all-zero WIND is no estimate, a node nothing feeds in fly says so, and
/// a node the core computes is never absent.
#[test]
fn json_says_which_evidence_is_absent_when_not_fed() {
    let v = check_json();
    let rows = v["absent_evidence"].as_array().unwrap();
    let row = |node: &str| {
        rows.iter()
            .find(|r| r["node"] == node)
            .unwrap_or_else(|| panic!("{node} not listed"))
    };
    let wind = row("A_wind");
    assert_eq!(wind["observation"], "wind_mps");
    assert!(wind["fly"].as_str().unwrap().contains("all zero"), "{wind}");
    assert!(
        row("A_temperature")["fly"]
            .as_str()
            .unwrap()
            .contains("nothing feeds it in fly")
    );
    assert!(
        row("A_free_tiles")["fly"]
            .as_str()
            .unwrap()
            .starts_with("never absent")
    );
    assert!(
        row("S_lidar_failed")["simulate"]
            .as_str()
            .unwrap()
            .contains("lidar-failure")
    );
    let params = Params::load(&default_params_dir(), None).unwrap();
    assert_eq!(
        rows.len(),
        params.model.health.observations.observations.len()
    );
}

#[test]
fn a_second_shell_only_entry_for_one_action_is_refused() {
    // Two entries flown for follow_trajectory: the shell could fly only one of them.
    expect_err(
        "commands.toml",
        |t| {
            format!(
                "{t}\n[follow_trajectory_again]\nflown_for = \"follow_trajectory\"\nsteps = [{{ mode = \"AUTO\" }}]\n"
            )
        },
        "follow_trajectory_resume.flown_for",
        "`follow_trajectory_again` is already flown for `follow_trajectory`",
    );
}

/// `list` with `from` renamed to `to` (which must be in it).
fn renamed<'a>(list: &[&'a str], from: &str, to: &'a str) -> Vec<&'a str> {
    assert!(list.contains(&from), "{from}");
    list.iter()
        .map(|o| if *o == from { to } else { o })
        .collect()
}

/// The guarantee reads the pack's `consumed_mah`; fly's telemetry writes it. Renamed on either
/// side only, the shipped params no longer load, and the error names both places (in flight the
/// energy goal would silently fall back to the params' pack).
#[test]
fn an_observation_renamed_on_one_side_only_fails_at_load() {
    use companion::vocabulary::{CodeLists, Vocabulary};
    let p = Params::load(&default_params_dir(), None).unwrap();
    let shipped = CodeLists::SHIPPED;
    let v = Vocabulary::compile(&p.sources(), &shipped).unwrap();
    assert!(v.names.iter().any(|n| n == "consumed_mah"));
    // The link side renamed.
    let writes = renamed(shipped.telemetry_writes, "consumed_mah", "consumed_mAh");
    let link_renamed = CodeLists {
        telemetry_writes: &writes,
        ..shipped
    };
    let e = Vocabulary::compile(&p.sources(), &link_renamed).unwrap_err();
    assert_eq!(e.entry, "PACK_OBSERVATIONS[4](consumed_mah)", "{e}");
    assert!(e.file.ends_with("companion-core/src/guarantee.rs"), "{e}");
    assert!(e.reason.contains("TELEMETRY_OBSERVATIONS"), "{e}");
    // The core side renamed.
    let reads = renamed(shipped.pack_reads, "consumed_mah", "consumed_charge_mah");
    let core_renamed = CodeLists {
        pack_reads: &reads,
        ..shipped
    };
    let e = Vocabulary::compile(&p.sources(), &core_renamed).unwrap_err();
    assert_eq!(e.entry, "PACK_OBSERVATIONS[4](consumed_charge_mah)", "{e}");
    assert!(e.reason.contains("companion-link/src/telemetry.rs"), "{e}");
}

/// One vocabulary for the run: the link's telemetry and the simulated world write their
/// snapshots over the `Arc` the load compiled, every name they write in it (nothing in the
/// overflow); an onboard name params do not declare goes to the overflow and is kept in the
/// record's observations, in name order, as before.
#[test]
fn the_link_and_the_world_write_over_the_one_vocabulary() {
    use companion_core::decision::{Core, ModelKind};
    use companion_link::Msg;
    use companion_link::dialect::NAMED_VALUE_FLOAT_DATA;
    use companion_link::modes::Flavor;
    use companion_link::telemetry::Telemetry;
    use std::sync::Arc;
    use std::time::Duration;
    let p = Params::load(&default_params_dir(), None).unwrap();
    let (vocabulary, world_spec) = (&p.vocabulary.clone(), p.world.clone());
    // Every name `check --json` lists as read is in it.
    for name in names(&check_json()["observations"]) {
        assert!(vocabulary.iter().any(|n| n == name), "{name}");
    }
    let mut t = Telemetry::new(p.link.telemetry.clone());
    let frame = |name: &str, value: f32| {
        Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms: 0,
            value,
            name: name.into(),
        })
    };
    t.on_message(Duration::ZERO, &frame("cpu_load", 0.5), Flavor::ArduPilot);
    t.on_message(Duration::ZERO, &frame("esc_temp", 95.0), Flavor::ArduPilot);
    let obs = t.observations(Duration::ZERO, vec![]);
    assert!(Arc::ptr_eq(obs.values.names(), vocabulary));
    assert_eq!(obs.get("cpu_load"), Some(0.5));
    assert!(obs.values.slot_of("armed").is_some());
    let overflow: Vec<&str> = (obs.values.overflow().iter())
        .map(|(n, _)| n.as_str())
        .collect();
    assert_eq!(overflow, ["onboard.esc_temp"]);
    // The core reads it by slot and the record keeps the overflow, serialized as the map.
    let model = Arc::new(p.model);
    let policy = model.policy("safety").unwrap();
    let mut core = Core::new(Arc::clone(&model), ModelKind::Bfm, policy);
    let (_, rec) = core.step(&obs);
    assert!(Arc::ptr_eq(rec.observations.names(), vocabulary));
    let want: std::collections::BTreeMap<&String, &f64> = obs.values.iter().collect();
    assert_eq!(
        serde_json::to_string(&rec.observations).unwrap(),
        serde_json::to_string(&want).unwrap()
    );
    assert!(want.contains_key(&"onboard.esc_temp".to_string()));
    // The simulated world writes every name it produces by slot.
    let files = read_params_dir(&default_params_dir()).unwrap();
    let scenario = companion::sim::Scenario::load(&files, "complete-1").unwrap();
    let mut world = companion::sim::World::new(&world_spec, &scenario, 1);
    let obs = world.observe();
    assert!(Arc::ptr_eq(obs.values.names(), vocabulary));
    assert!(
        obs.values.overflow().is_empty(),
        "{:?}",
        obs.values.overflow()
    );
    assert!(obs.values.len() > 10);
}
