//! Helpers shared by the companion crate's integration tests (each test binary uses some).
#![allow(dead_code)]

use companion_core::decision::Model;
use std::path::Path;
use std::process::{Command, Output};
use std::sync::{Arc, OnceLock};

/// The shipped model, loaded once per test binary and shared (each core holds its `Arc`).
pub(crate) fn shipped_model() -> Arc<Model> {
    static M: OnceLock<Arc<Model>> = OnceLock::new();
    Arc::clone(M.get_or_init(|| {
        Arc::new(
            companion::params::load_model(&companion::params::default_params_dir())
                .expect("params load"),
        )
    }))
}

/// `BIN ARGS` run to completion (BIN: the test's `env!("CARGO_BIN_EXE_companion")`, named in the
/// test file itself so that scripts/arm.sh sees which tests start the binary), on its built-in
/// params unless the args name others (the environment's `COMPANION_PARAMS` and `RUST_BACKTRACE`
/// removed: messages as users see them).
pub(crate) fn run_companion(bin: &str, args: &[&str]) -> Output {
    Command::new(bin)
        .args(args)
        .env_remove("COMPANION_PARAMS")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("companion runs")
}

/// Its stdout and stderr, as text.
pub(crate) fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Copy the folder `from` (a params set) to `to`, recursively.
pub(crate) fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        let dest = to.join(e.file_name());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// `companion check ARGS` (BIN as for `run_companion`): exit code, stdout, stderr.
pub(crate) fn check_run(bin: &str, args: &[&str]) -> (Option<i32>, String, String) {
    let mut all = vec!["check"];
    all.extend_from_slice(args);
    let out = run_companion(bin, &all);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}
