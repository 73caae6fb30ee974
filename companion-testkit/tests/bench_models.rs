//! The criterion benches in mdp_engine read the paper MDPs instantiated at the check point
//! (safety policy) from JSON files; this keeps those files in step with params/.

use companion::params::{default_params_dir, read_params_dir};
use companion_core::decision::Model;
use std::fs;
use std::path::Path;

#[test]
fn bench_models_are_current() {
    let files = read_params_dir(&default_params_dir()).unwrap();
    let mut all = Model::load(&files).unwrap().mdps;
    let point = all.check_point().clone();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mdp_engine/benches/models");
    let update = std::env::var_os("UPDATE_BENCH_MODELS").is_some();
    for name in [
        "reference",
        "navigation",
        "landing",
        "tracking",
        "monolithic",
    ] {
        let mdp = all
            .get_mut(name)
            .unwrap()
            .instantiate(&point, "safety")
            .unwrap();
        let json = serde_json::to_string(mdp).unwrap();
        let path = dir.join(format!("{name}.json"));
        if update {
            fs::create_dir_all(&dir).unwrap();
            fs::write(&path, &json).unwrap();
        }
        let on_disk = fs::read_to_string(&path).unwrap_or_default();
        assert!(
            on_disk == json,
            "{} is stale: UPDATE_BENCH_MODELS=1 cargo test -p companion-testkit --test bench_models",
            path.display()
        );
    }
}

/// The core's unit tests use params/ compiled in (`companion-core/src/lib.rs`, module
/// `shipped`): every file of the directory must be in that list, or a core test would load a
/// params set missing a file.
#[test]
fn shipped_params_are_all_compiled_into_the_core_tests() {
    let lib = fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../companion-core/src/lib.rs"),
    )
    .unwrap();
    // rustfmt may break the list's lines anywhere: compare without whitespace.
    let lib: String = lib.chars().filter(|c| !c.is_whitespace()).collect();
    let files = read_params_dir(&default_params_dir()).unwrap();
    let mut n = 0;
    for (path, _) in files.iter() {
        let rel = path
            .strip_prefix(files.dir())
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        let line = format!("(\"{rel}\",include_str!(\"../../params/{rel}\")");
        assert!(
            lib.contains(&line),
            "params/{rel} is missing from companion-core's shipped list"
        );
        n += 1;
    }
    assert_eq!(
        lib.matches("include_str!(\"../../params/").count(),
        n,
        "the list names files params/ does not have"
    );
}
