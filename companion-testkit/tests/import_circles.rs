//! No import circle among the Rust files of a crate: file A naming `crate::b` (or `super::b`)
//! while b, directly or around a longer circle, names A. A circle means two concerns that cannot
//! be read, changed or tested apart (issue 25). The core has none; the shells' known circles are
//! listed by name until their files are split (none left).
//!
//! Source guard: it reads the repository's text, not the code as compiled for a target, so
//! scripts/arm.sh leaves it to the host's run.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

#[path = "support/module_map.rs"]
mod module_map;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Circles still in the shells: none. (`params` <-> `vocabulary` went when the vocabulary checks
/// read `vocabulary::Sources` instead of `Params`; `actions` <-> `modes` when the route's
/// mission items moved from `modes` to `Route::mission_items`.) A new circle fails; list one
/// here only with the reason it cannot be split yet.
const KNOWN: [(&str, &[&str]); 0] = [];

/// Which modules each module names by `crate::` or `super::` paths (the longest known prefix).
fn edges(mods: &BTreeMap<String, PathBuf>) -> BTreeMap<String, BTreeSet<String>> {
    mods.iter()
        .map(|(m, path)| {
            let text = module_map::code(path);
            let to = module_map::imports(mods, m, &text, &[]);
            (m.clone(), to.into_iter().map(|(_, t)| t).collect())
        })
        .collect()
}

/// The circles: every set of two or more modules each reachable from the others.
fn circles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let reach = |from: &str| {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.to_string()];
        while let Some(m) = todo.pop() {
            for n in &edges[&m] {
                if seen.insert(n.clone()) {
                    todo.push(n.clone());
                }
            }
        }
        seen
    };
    let all: BTreeMap<&String, BTreeSet<String>> = edges.keys().map(|m| (m, reach(m))).collect();
    let mut out: Vec<Vec<String>> = Vec::new();
    for m in edges.keys() {
        let mut c: Vec<String> = all[m]
            .iter()
            .filter(|n| all[n].contains(m))
            .cloned()
            .collect();
        if c.is_empty() {
            continue;
        }
        if !c.contains(m) {
            c.push(m.clone());
        }
        c.sort();
        if !out.contains(&c) {
            out.push(c);
        }
    }
    out
}

#[test]
fn no_import_circle_among_the_files_of_a_crate() {
    for krate in ["companion-core", "companion-link", "companion"] {
        let mods = module_map::modules(&root().join(krate).join("src"));
        assert!(mods.len() > 5, "{krate}: {mods:?}");
        let found = circles(&edges(&mods));
        let known: Vec<Vec<String>> = KNOWN
            .iter()
            .filter(|(k, _)| *k == krate)
            .map(|(_, c)| c.iter().map(|s| s.to_string()).collect())
            .collect();
        let new: Vec<&Vec<String>> = found.iter().filter(|c| !known.contains(c)).collect();
        assert!(new.is_empty(), "{krate}: import circles {new:?}");
    }
}

#[test]
fn a_circle_is_found_through_crate_and_super_paths() {
    let mods: BTreeMap<String, PathBuf> = ["a", "b", "c"]
        .iter()
        .map(|m| (m.to_string(), PathBuf::new()))
        .collect();
    let e = |pairs: &[(&str, &str)]| {
        let mut out: BTreeMap<String, BTreeSet<String>> =
            mods.keys().map(|m| (m.clone(), BTreeSet::new())).collect();
        for (f, t) in pairs {
            out.get_mut(*f).unwrap().insert(t.to_string());
        }
        out
    };
    assert!(circles(&e(&[("a", "b"), ("b", "c")])).is_empty());
    assert_eq!(
        circles(&e(&[("a", "b"), ("b", "c"), ("c", "a")])),
        vec![vec!["a".to_string(), "b".into(), "c".into()]]
    );
}
