//! Every kind of bad params input is rejected with a SpecError naming the file, the entry and the
//! reason; nothing panics.

use companion::params::default_params_dir;
use companion_core::health::HealthModel;
use companion_core::spec::SpecError;
use std::path::{Path, PathBuf};

/// Copy params/health, params/observations.toml and the variant catalogue the activation nodes
/// compile from (variants.toml, platform.toml) into a temp dir, apply `edit` to one file.
fn load_edited(
    file: &str,
    edit: impl Fn(String) -> String,
) -> (tempfile::TempDir, Result<HealthModel, SpecError>) {
    let src = default_params_dir();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("health")).unwrap();
    for f in std::fs::read_dir(src.join("health")).unwrap() {
        let p = f.unwrap().path();
        std::fs::copy(&p, dir.path().join("health").join(p.file_name().unwrap())).unwrap();
    }
    for f in ["observations.toml", "variants.toml", "platform.toml"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    let target: PathBuf = dir.path().join(file);
    let text = std::fs::read_to_string(&target).unwrap();
    let edited = edit(text.clone());
    assert_ne!(edited, text, "the edit must change {file}");
    std::fs::write(&target, edited).unwrap();
    let r = companion::params::read_params_dir(dir.path()).and_then(|f| HealthModel::load(&f));
    (dir, r)
}

fn expect_err(file: &str, edit: impl Fn(String) -> String, entry: &str, reason: &str) {
    let (_dir, r) = load_edited(file, edit);
    let e = r.expect_err("must be rejected");
    assert_eq!(e.file.file_name(), Path::new(file).file_name(), "{e}");
    assert_eq!(e.entry, entry, "{e}");
    assert!(e.reason.contains(reason), "{e}");
}

#[test]
fn shipped_params_load() {
    HealthModel::load(
        &companion::params::read_params_dir(&companion::params::default_params_dir()).unwrap(),
    )
    .unwrap();
}

#[test]
fn cpt_row_not_summing_to_one() {
    expect_err(
        "health/sensors.toml",
        |t| {
            t.replace(
                "[0.1, 0.9], [0.5, 0.5], [0.6001",
                "[0.1, 0.8], [0.5, 0.5], [0.6001",
            )
        },
        "node.N_next.cpt[0]",
        "sums to 0.9",
    );
    // A root prior too.
    expect_err(
        "health/applications.toml",
        |t| {
            t.replace(
                "prior = [0.8, 0.2]\n[node.A_vibration]",
                "prior = [0.8, 0.3]\n[node.A_vibration]",
            )
        },
        "node.A_wind.cpt[0]",
        "not 1",
    );
    // An override row.
    expect_err(
        "health/applications.toml",
        |t| t.replace("p = [0.0018, 0.9982]", "p = [0.1, 0.9982]"),
        "node.C_V3.cpt[4]",
        "not 1",
    );
}

#[test]
fn unknown_state_names() {
    // In an override's `when`.
    expect_err(
        "health/applications.toml",
        |t| {
            t.replacen(
                "U_vibration = \"present\", U_point_lost",
                "U_vibration = \"shaking\", U_point_lost",
                1,
            )
        },
        "node.C_V1.override[0].when.U_vibration",
        "no state `shaking`",
    );
    // In a published probability.
    expect_err(
        "health/applications.toml",
        |t| t.replace("P(QoS = high)", "P(QoS = great)"),
        "publish.P_track",
        "no state `great`",
    );
    // In the observation mapping.
    expect_err(
        "observations.toml",
        |t| {
            t.replace(
                "states = [\"calm\", \"strong\"]",
                "states = [\"calm\", \"gale\"]",
            )
        },
        "observation[1](wind_mps).states",
        "no state `gale`",
    );
    // An activation node naming a variant params/variants.toml does not have.
    expect_err(
        "health/resources.toml",
        |t| {
            t.replacen(
                "variant = \"tracking/V0\"\nversion",
                "variant = \"tracking/V9\"\nversion",
                1,
            )
        },
        "node.R_V0.variant",
        "no variant tracking V9",
    );
    // The same for a fit node.
    expect_err(
        "health/resources.toml",
        |t| {
            t.replacen(
                "role = \"fit\"\nvariant = \"tracking/V0\"",
                "role = \"fit\"\nvariant = \"tracking/V9\"",
                1,
            )
        },
        "node.F_V0.variant",
        "no variant tracking V9",
    );
    // An activation node reading the room both through its fit node and itself.
    expect_err(
        "health/resources.toml",
        |t| {
            t.replacen(
                "fit = \"F_V2\"",
                "fit = \"F_V2\"\ntiles = \"A_free_tiles\"",
                1,
            )
        },
        "node.R_V2.tiles",
        "reads the room through it",
    );
}

#[test]
fn cycle() {
    // N_next -> U_gps_error would close a loop with U_gps_error -> N_next.
    expect_err(
        "health/sensors.toml",
        |t| {
            t.replace(
                "[node.U_gps_error]\nleak = 0.01",
                "[node.U_gps_error]\nparents = [\"N_next\"]\nleak = 0.01",
            )
        },
        "node.U_gps_error",
        "cycle",
    );
}

#[test]
fn published_probability_naming_a_missing_node() {
    expect_err(
        "health/system.toml",
        |t| {
            t.replace(
                "P_sys = \"P(U_system_fault = absent)\"",
                "P_sys = \"P(U_system_failure = absent)\"",
            )
        },
        "publish.P_sys",
        "missing node `U_system_failure`",
    );
    expect_err(
        "health/system.toml",
        |t| t.replace("P(U_crash = present)", "U_crash is present"),
        "publish.P_crash",
        "not `P(NODE = STATE)`",
    );
}

#[test]
fn thresholds_out_of_order() {
    expect_err(
        "observations.toml",
        |t| t.replace("thresholds = [0.3, 0.8]", "thresholds = [0.8, 0.3]"),
        "observation[8](cpu_load).thresholds",
        "out of order",
    );
    expect_err(
        "observations.toml",
        |t| {
            t.replace(
                "thresholds = [0.5, 1.5, 2.5, 3.5]",
                "thresholds = [0.5, 1.5, 1.5, 3.5]",
            )
        },
        "observation[9](free_tiles).thresholds",
        "out of order",
    );
    expect_err(
        "observations.toml",
        |t| t.replace("thresholds = [0.3, 0.8]", "thresholds = [0.3]"),
        "observation[8](cpu_load).states",
        "need one more state",
    );
}

#[test]
fn other_structural_errors() {
    // Unknown parent.
    expect_err(
        "health/applications.toml",
        |t| t.replace("parents = [\"A_small_roi\"]", "parents = [\"A_tiny_roi\"]"),
        "node.H_S_motion.parents",
        "unknown node `A_tiny_roi`",
    );
    // Import from a missing manager / node, and with the wrong states.
    expect_err(
        "health/system.toml",
        |t| {
            t.replace(
                "from = \"sensors.U_gps_error\"",
                "from = \"sensor.U_gps_error\"",
            )
        },
        "node.U_gps_error.from",
        "no health manager `sensor`",
    );
    expect_err(
        "health/resources.toml",
        |t| {
            t.replacen(
                "from = \"applications.C_V0\"\nstates = [\"deactivate\", \"activate\"]",
                "from = \"applications.C_V0\"\nstates = [\"off\", \"on\"]",
                1,
            )
        },
        "node.C_V0.from",
        "states differ",
    );
    // A node used with two roles.
    expect_err(
        "health/applications.toml",
        |t| t.replace("monitors = [\"S_IMU\"]", "monitors = [\"A_wind\"]"),
        "fmea[0].contexts",
        "already as monitor",
    );
    // Unknown keys are typos, not silently ignored; so are keys of another role.
    expect_err(
        "health/system.toml",
        |t| t.replace("stay = 0.8476", "stai = 0.8476"),
        "node.E_t1.stai",
        "unknown field",
    );
    expect_err(
        "health/system.toml",
        |t| t.replace("stay = 0.8476", "stay = 0.8476\nleak = 0.1"),
        "node.E_t1.leak",
        "unknown field `leak` for a state node",
    );
    // The same probability published twice.
    expect_err(
        "health/system.toml",
        |t| t.replace("P_crash = ", "P_gps = "),
        "publish.P_gps",
        "also published",
    );
    // Observation aimed at a node no manager has.
    expect_err(
        "observations.toml",
        |t| t.replace("node = \"A_wind\"", "node = \"A_gust\""),
        "observation[1](wind_mps).node",
        "no health manager has a node `A_gust`",
    );
}
