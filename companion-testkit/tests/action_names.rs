//! The shells know actions by their role, never by name: no action id params/actions.toml
//! declares appears as a string literal in the non-test code of `companion/` or
//! `companion-link/` (the world, the flight shell, the link, the review). Renaming an action is an
//! edit of params alone (companion/tests/actions_renamed.rs flies it).
//!
//! Source guard: it reads the repository's text, not the code as compiled for a target, so
//! scripts/arm.sh leaves it to the host's run.

use std::path::{Path, PathBuf};

#[path = "support/shipped_code.rs"]
mod shipped_code;
use shipped_code::rs_files;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Files not yet moved to roles, each with why: none now (the fly shell asks the role since its
/// split; the scripted decider is test support in companion-testkit).
const NOT_YET: [(&str, &str); 0] = [];

/// The action ids of params/actions.toml.
fn action_ids() -> Vec<String> {
    let text = std::fs::read_to_string(root().join("params/actions.toml")).unwrap();
    let doc: toml::Table = toml::from_str(&text).unwrap();
    doc["action"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["id"].as_str().unwrap().to_string())
        .collect()
}

/// The shipped part of a source file: every `#[cfg(test)]` item blanked wherever it sits
/// (`support/shipped_code.rs`), comment lines blanked (line numbers kept). None for a test-only file.
fn shipped_lines(path: &Path, text: &str) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    if name == "tests.rs" || path.components().any(|c| c.as_os_str() == "tests") {
        return None;
    }
    let code = shipped_code::shipped(text);
    Some(
        code.lines()
            .map(|l| {
                if l.trim_start().starts_with("//") {
                    ""
                } else {
                    l
                }
            })
            .collect::<Vec<_>>()
            .join("\n"),
    )
}

/// Every `"id"` literal of the shipped code under `dirs` (relative to the repository), as
/// `file:line: id`, skipping the [`NOT_YET`] files.
fn literals(dirs: &[&str], ids: &[String]) -> Vec<String> {
    let mut found = Vec::new();
    for dir in dirs {
        let mut files = Vec::new();
        rs_files(&root().join(dir), &mut files);
        assert!(!files.is_empty(), "no source under {dir}");
        for f in files {
            let rel = f
                .strip_prefix(root())
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            if NOT_YET.iter().any(|(p, _)| rel.starts_with(p)) {
                continue;
            }
            let text = std::fs::read_to_string(&f).unwrap();
            let Some(code) = shipped_lines(&f, &text) else {
                continue;
            };
            for (n, line) in code.lines().enumerate() {
                for id in ids {
                    if line.contains(&format!("\"{id}\"")) {
                        found.push(format!("{rel}:{}: {id}", n + 1));
                    }
                }
            }
        }
    }
    found
}

#[test]
fn no_action_name_literal_in_the_shells_code() {
    let ids = action_ids();
    assert!(
        ids.len() > 10 && ids.iter().any(|i| i == "take_off"),
        "{ids:?}"
    );
    let found = literals(&["companion/src", "companion-link/src"], &ids);
    assert!(
        found.is_empty(),
        "action names in shipped code (ask the role, companion_core::action_role):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_search_finds_a_literal_and_skips_tests_and_comments() {
    let f = Path::new("companion/src/x.rs");
    let code = "let a = \"take_off\";\n// \"take_off\"\n#[cfg(test)]\nmod tests { \"take_off\" }";
    let shipped = shipped_lines(f, code).unwrap();
    assert!(
        shipped.starts_with("let a = \"take_off\";\n"),
        "{shipped:?}"
    );
    assert_eq!(shipped.matches("take_off").count(), 1, "{shipped:?}");
    assert_eq!(
        shipped.lines().count(),
        code.lines().count(),
        "line numbers kept"
    );
    assert!(shipped_lines(Path::new("companion/src/tests.rs"), code).is_none());
    // No file is excepted any more.
    assert!(NOT_YET.is_empty());
}
