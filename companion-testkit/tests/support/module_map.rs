//! The module map the import guards share (`import_circles.rs`, `floors.rs`): a crate's modules by
//! path, the shipped code of each file, and the modules each line names by `crate::`, `super::`
//! (or, in the binary, `companion::`) paths.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

// Only the code-only text of each file: the module map walks the tree its own way.
#[allow(dead_code)]
#[path = "shipped_code.rs"]
mod shipped_code;

/// Module path (`fmea::compile`) -> source file, for the crate's `src/` (`lib` and `main` left out).
pub(crate) fn modules(src: &Path) -> BTreeMap<String, PathBuf> {
    fn walk(dir: &Path, src: &Path, out: &mut BTreeMap<String, PathBuf>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                walk(&p, src, out);
            } else if p.extension().is_some_and(|x| x == "rs") {
                let rel = p.strip_prefix(src).unwrap().with_extension("");
                let mut name = rel.to_string_lossy().replace(['/', '\\'], "::");
                if let Some(parent) = name.strip_suffix("::mod") {
                    name = parent.to_string();
                }
                if name != "lib" && name != "main" {
                    out.insert(name, p);
                }
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(src, src, &mut out);
    out
}

/// A file only tests compile (`tests.rs`, `fit_tests.rs`, anything under a `tests/` folder).
#[allow(dead_code)] // floors.rs only
pub(crate) fn test_only(path: &Path) -> bool {
    path.file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.ends_with("tests.rs"))
        || path.components().any(|c| c.as_os_str() == "tests")
}

/// The shipped code of a file (its `#[cfg(test)]` items blanked), comment lines blanked: line
/// numbers kept.
pub(crate) fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let shipped = shipped_code::shipped(&text);
    shipped
        .lines()
        .map(|l| {
            if l.trim_start().starts_with("//") {
                ""
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn path_chars(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_' || c == ':'
}

/// The paths written after `at` in `text`: `a::b::C`, or each item of a group `{a::B, c}`.
fn paths_after(text: &str) -> Vec<String> {
    let head: String = text.chars().take_while(|&c| path_chars(c)).collect();
    let rest = &text[head.len()..];
    if !rest.starts_with('{') {
        return vec![head];
    }
    // A group: its items at depth 0 (nested groups keep their first segment, enough for a map
    // keyed by module).
    let mut out = Vec::new();
    let (mut depth, mut item) = (0usize, String::new());
    for c in rest[1..].chars() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => out.push(std::mem::take(&mut item)),
            _ if depth == 0 && path_chars(c) => item.push(c),
            _ => {}
        }
    }
    out.push(item);
    out.into_iter().map(|i| format!("{head}{i}")).collect()
}

/// Each module that module `m` of `mods` names in `text`, with the 1-based line: `crate::` paths
/// (and `extra` prefixes, e.g. the binary's `companion::`) from the crate root, `super::` from the
/// parent; the longest known prefix wins; `m` itself is left out.
pub(crate) fn imports(
    mods: &BTreeMap<String, PathBuf>,
    m: &str,
    text: &str,
    extra: &[&str],
) -> Vec<(usize, String)> {
    let segments: Vec<&str> = m.split("::").collect();
    let parent = segments[..segments.len().saturating_sub(1)].join("::");
    let mut out = Vec::new();
    let roots = ["crate::"].iter().chain(extra).map(|p| (*p, String::new()));
    for (prefix, base) in roots.chain([("super::", parent)]) {
        for (i, _) in text.match_indices(prefix) {
            // `foo_crate::x` or `super::super` is not this prefix at a path's start.
            let before = text[..i].chars().next_back();
            if before.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') {
                continue;
            }
            let line = text[..i].matches('\n').count() + 1;
            for path in paths_after(&text[i + prefix.len()..]) {
                let parts: Vec<&str> = path.split("::").filter(|p| !p.is_empty()).collect();
                let found = (1..=parts.len()).rev().find_map(|k| {
                    let name = parts[..k].join("::");
                    let full = if base.is_empty() {
                        name
                    } else {
                        format!("{base}::{name}")
                    };
                    mods.contains_key(&full).then_some(full)
                });
                if let Some(f) = found.filter(|f| f != m) {
                    out.push((line, f));
                }
            }
        }
    }
    out
}
