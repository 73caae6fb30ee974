//! The two state machines at the centre each have their whole `impl` in one file (issue 39 item
//! 3): `impl Core` in companion-core/src/decision.rs, `impl Vehicle` in
//! companion-link/src/vehicle/mod.rs. The rest of their behaviour lives in the stage and
//! executor types beside them, each with its own state; a second `impl Core` block in another
//! file would spread the core's state back over the files.
//!
//! Source guard: it reads the repository's text, not the code as compiled for a target, so
//! scripts/arm.sh leaves it to the host's run.

use std::path::{Path, PathBuf};

// Only the code-only text of two named files: not the tree walk the other guards use.
#[allow(dead_code)]
#[path = "support/shipped_code.rs"]
mod shipped_code;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The files of `crate_dir`'s sources holding an `impl <ty>` block in shipped code (tests
/// blanked), as paths relative to the repository.
fn files_implementing(crate_dir: &str, ty: &str) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(&root().join(crate_dir).join("src"), &mut files);
    files.sort();
    let open = format!("impl {ty} {{");
    files
        .iter()
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            shipped_code::shipped(&text)
                .lines()
                .any(|l| l.trim_start() == open)
        })
        .map(|p| {
            let rel = p.strip_prefix(root()).unwrap_or(p);
            rel.to_string_lossy().trim_start_matches("../").to_string()
        })
        .collect()
}

#[test]
fn impl_core_lives_in_decision_rs_only() {
    assert_eq!(
        files_implementing("companion-core", "Core"),
        ["companion-core/src/decision.rs"]
    );
}

#[test]
fn impl_vehicle_lives_in_vehicle_mod_rs_only() {
    assert_eq!(
        files_implementing("companion-link", "Vehicle"),
        ["companion-link/src/vehicle/mod.rs"]
    );
}
