//! Floors that hold (issue 39): within a crate, no module imports one on a higher floor. The
//! floors are docs/architecture.md's table ("Floors"), read here, so the page and the code cannot
//! drift: a module missing from the table, or a table entry with no module, fails too. An import
//! is a `crate::`/`super::` path (the binary's `companion::` too) in the shipped code; each module
//! is on its top-level module's floor. Same-floor imports are allowed (`import_circles.rs` keeps
//! them from going round).
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

const CRATES: [&str; 3] = ["companion-core", "companion-link", "companion"];

/// The floors of docs/architecture.md: crate -> top-level module -> floor. Rows of the form
/// ``| `crate` | floor | `a`, `b` | concern |``.
fn floors(doc: &str) -> BTreeMap<String, BTreeMap<String, u32>> {
    let mut out: BTreeMap<String, BTreeMap<String, u32>> = BTreeMap::new();
    for line in doc.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 5 || !cells[0].is_empty() {
            continue;
        }
        let krate = cells[1].trim_matches('`');
        let Ok(floor) = cells[2].parse::<u32>() else {
            continue;
        };
        if !CRATES.contains(&krate) {
            continue;
        }
        for m in cells[3].split(',').map(|m| m.trim().trim_matches('`')) {
            let prev = out
                .entry(krate.to_string())
                .or_default()
                .insert(m.to_string(), floor);
            assert!(prev.is_none(), "{krate}: `{m}` on two floors in the table");
        }
    }
    out
}

/// Every import from a module to one on a higher floor, as `file:line: from (floor a) imports
/// to (floor b)`; a module on no floor is reported as such.
fn violations(
    mods: &BTreeMap<String, PathBuf>,
    texts: &BTreeMap<String, String>,
    floor_of: &BTreeMap<String, u32>,
    extra: &[&str],
) -> Vec<String> {
    let top = |m: &str| m.split("::").next().unwrap_or(m).to_string();
    let mut out = Vec::new();
    for (m, text) in texts {
        let Some(&own) = floor_of.get(&top(m)) else {
            out.push(format!(
                "`{}` is on no floor (give it one in the table)",
                top(m)
            ));
            continue;
        };
        for (line, to) in module_map::imports(mods, m, text, extra) {
            let Some(&theirs) = floor_of.get(&top(&to)) else {
                continue; // reported as its own module
            };
            if theirs > own {
                let file = mods.get(m).map_or("?".into(), |p| {
                    p.strip_prefix(root())
                        .unwrap_or(p)
                        .to_string_lossy()
                        .replace('\\', "/")
                });
                out.push(format!(
                    "{file}:{line}: `{}` (floor {own}) imports `{}` (floor {theirs})",
                    top(m),
                    top(&to)
                ));
            }
        }
    }
    out.sort();
    out.dedup();
    out
}

#[test]
fn no_import_runs_from_a_lower_floor_to_a_higher_one() {
    let doc = std::fs::read_to_string(root().join("docs/architecture.md")).unwrap();
    let floors = floors(&doc);
    let mut found = Vec::new();
    for krate in CRATES {
        let src = root().join(krate).join("src");
        let mut mods = module_map::modules(&src);
        assert!(mods.len() > 5, "{krate}: {mods:?}");
        let floor_of = floors
            .get(krate)
            .unwrap_or_else(|| panic!("docs/architecture.md gives no floors for `{krate}`"));
        // The binary is a module of its own (`main`), naming the library as `companion::`.
        let main = src.join("main.rs");
        let extra: &[&str] = if main.exists() {
            mods.insert("main".into(), main);
            &["companion::"]
        } else {
            &[]
        };
        let tops: BTreeSet<String> = mods
            .keys()
            .map(|m| m.split("::").next().unwrap().to_string())
            .collect();
        for listed in floor_of.keys() {
            if !tops.contains(listed) {
                found.push(format!(
                    "{krate}: the table lists `{listed}`, no such module"
                ));
            }
        }
        let texts: BTreeMap<String, String> = mods
            .iter()
            .filter(|(_, p)| !module_map::test_only(p))
            .map(|(m, p)| (m.clone(), module_map::code(p)))
            .collect();
        found.extend(
            violations(&mods, &texts, floor_of, extra)
                .into_iter()
                .map(|v| format!("{krate}: {v}")),
        );
    }
    assert!(
        found.is_empty(),
        "imports running up a floor (docs/architecture.md, Floors):\n{}",
        found.join("\n")
    );
}

#[test]
fn an_import_up_a_floor_is_found_through_crate_super_and_group_paths() {
    let mods: BTreeMap<String, PathBuf> = ["low", "low::part", "high", "high::part"]
        .iter()
        .map(|m| (m.to_string(), PathBuf::from(format!("{m}.rs"))))
        .collect();
    let floor_of: BTreeMap<String, u32> = [("low".to_string(), 1), ("high".to_string(), 2)].into();
    let check = |m: &str, text: &str| {
        let texts = BTreeMap::from([(m.to_string(), text.to_string())]);
        violations(&mods, &texts, &floor_of, &["companion::"])
    };
    // Down a floor, or within one: fine.
    assert!(check("high", "use crate::low::X;").is_empty());
    assert!(check("low::part", "use super::X;\nuse crate::low::Y;").is_empty());
    // Up a floor, written three ways: found, with the line.
    for text in [
        "\nuse crate::high::X;",
        "\nuse crate::{low::A, high::part::B};",
        "\nfn f() { companion::high::g() }",
    ] {
        assert_eq!(
            check("low", text),
            ["low.rs:2: `low` (floor 1) imports `high` (floor 2)"],
            "{text}"
        );
    }
    // A module on no floor is named.
    let texts = BTreeMap::from([("other".to_string(), String::new())]);
    assert_eq!(
        violations(&mods, &texts, &floor_of, &[]),
        ["`other` is on no floor (give it one in the table)"]
    );
}
