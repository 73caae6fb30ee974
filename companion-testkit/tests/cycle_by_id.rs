//! Inside the decision cycle observations, probabilities, evidence and actions travel by id
//! (issue 39, item 1): no `BTreeMap<String, _>` and no list of action names is built or filled
//! inside `Core::step_into` or any function of the core it calls. Names are written only at the edges (the record's serialization, the
//! shells). A source test over companion-core's shipped code (`support/shipped_code.rs`, comments
//! and literals blanked), following the calls from `step_into` by name: an over-approximation of
//! the call graph (every core function of a called name is followed), so a map built anywhere a
//! cycle may reach is found.
//!
//! Source guard: it reads the repository's text, not the code as compiled for a target, so
//! scripts/arm.sh leaves it to the host's run.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

#[path = "support/shipped_code.rs"]
mod shipped_code;
use shipped_code::rs_files;

/// One function of the core's shipped code.
struct Function {
    file: PathBuf,
    line: usize,
    name: String,
    /// From `fn` to the end of its body (or its `;`).
    text: String,
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// Every `fn` of `code` (comments and literals already blanked), nested ones included.
fn functions(file: &Path, code: &str, out: &mut Vec<Function>) {
    let b = code.as_bytes();
    let mut i = 0;
    while let Some(p) = code[i..].find("fn ") {
        let at = i + p;
        i = at + 3;
        if at > 0 && is_ident(b[at - 1]) {
            continue;
        }
        let name_end = at + 3 + b[at + 3..].iter().take_while(|&&c| is_ident(c)).count();
        let name = &code[at + 3..name_end];
        if name.is_empty() {
            continue;
        }
        // The body: the first `{` at bracket depth 0 after the name (a `;` first: no body).
        let mut depth = 0i32;
        let mut k = name_end;
        let mut end = b.len();
        while k < b.len() {
            match b[k] {
                b'(' | b'[' | b'<' => depth += 1,
                b')' | b']' => depth -= 1,
                b'>' if b[k - 1] != b'-' && b[k - 1] != b'=' => depth -= 1,
                b';' if depth <= 0 => {
                    end = k + 1;
                    break;
                }
                b'{' if depth <= 0 => {
                    let mut braces = 0i32;
                    for (j, &c) in b.iter().enumerate().skip(k) {
                        match c {
                            b'{' => braces += 1,
                            b'}' => {
                                braces -= 1;
                                if braces == 0 {
                                    end = j + 1;
                                    break;
                                }
                            }
                            _ => {}
                        }
                    }
                    break;
                }
                _ => {}
            }
            k += 1;
        }
        out.push(Function {
            file: file.to_path_buf(),
            line: code[..at].matches('\n').count() + 1,
            name: name.to_string(),
            text: code[at..end].to_string(),
        });
    }
}

/// How a call is written: `self.f(` and `f(` name a function of the caller's own module first;
/// `x.f(` and `T::f(` any function of that name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Call {
    Own,
    Any,
}

/// The names `text` calls: an identifier followed by `(` (or by `::<...>(`), the declared name
/// aside, with how each is written.
fn called(text: &str) -> BTreeSet<(String, Call)> {
    let b = text.as_bytes();
    let mut out = BTreeSet::new();
    let mut i = 0;
    while i < b.len() {
        if is_ident(b[i]) && (i == 0 || !is_ident(b[i - 1])) {
            let end = i + b[i..].iter().take_while(|&&c| is_ident(c)).count();
            let mut k = end;
            if text[k..].starts_with("::<") {
                let close = text[k..].find(">(").map_or(b.len(), |p| k + p + 1);
                k = close;
            }
            let before = text[..i].trim_end();
            let declared = before.ends_with("fn") && text[..i].ends_with(' ');
            if b.get(k) == Some(&b'(') && !b[i].is_ascii_digit() && !declared {
                let own =
                    before.ends_with("self.") || !(before.ends_with('.') || before.ends_with("::"));
                let how = if own { Call::Own } else { Call::Any };
                out.insert((text[i..end].to_string(), how));
            }
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// The module a file is part of: `decision.rs` and `decision/*.rs` are one.
fn module_of(file: &Path) -> PathBuf {
    let stem = file.with_extension("");
    match stem.parent() {
        Some(dir) if stem.file_name().is_some_and(|n| n == "mod") => dir.to_path_buf(),
        Some(dir) if dir.file_name().is_some_and(|n| n != "src") => dir.to_path_buf(),
        _ => stem,
    }
}

/// The core's shipped functions (test-only files and items left out).
impl Function {
    /// Where it is, and the function `step_into` reached it from, for a failure message.
    fn place(&self, from: &str) -> String {
        let (file, line, name) = (self.file.display(), self.line, &self.name);
        format!("{file}:{line} fn {name} (reached from {from})")
    }
}

fn core_functions() -> Vec<Function> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../companion-core/src");
    let mut files = Vec::new();
    rs_files(&root, &mut files);
    let mut out = Vec::new();
    for f in files {
        let name = f.file_name().unwrap().to_string_lossy();
        if name == "tests.rs" || name.ends_with("_tests.rs") {
            continue;
        }
        let text = std::fs::read_to_string(&f).unwrap();
        functions(&f, &shipped_code::code_only(&text), &mut out);
    }
    out
}

/// The functions reachable from `Core::step_into` (by name), each with who reached it first.
fn reached(all: &[Function]) -> BTreeMap<usize, String> {
    let mut by_name: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (k, f) in all.iter().enumerate() {
        by_name.entry(&f.name).or_default().push(k);
    }
    let start = all
        .iter()
        .position(|f| f.name == "step_into" && f.file.ends_with("decision.rs"))
        .expect("Core::step_into in companion-core/src/decision.rs");
    let mut seen = BTreeMap::from([(start, "the cycle".to_string())]);
    let mut todo = vec![start];
    while let Some(k) = todo.pop() {
        let module = module_of(&all[k].file);
        for (name, how) in called(&all[k].text) {
            let of_name = by_name.get(name.as_str()).map_or(&[][..], Vec::as_slice);
            let own: Vec<usize> = (of_name.iter().copied())
                .filter(|&j| module_of(&all[j].file) == module)
                .collect();
            let targets = if how == Call::Own && !own.is_empty() {
                own
            } else {
                of_name.to_vec()
            };
            for j in targets {
                if !seen.contains_key(&j) {
                    seen.insert(j, all[k].name.clone());
                    todo.push(j);
                }
            }
        }
    }
    seen
}

/// Where `text` names a map keyed by strings (spaces ignored).
fn names_a_string_map(text: &str) -> bool {
    let squeezed: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    squeezed.contains("BTreeMap<String") || squeezed.contains("map_clone_from(")
}

#[test]
fn no_string_keyed_map_is_built_inside_the_cycle() {
    let all = core_functions();
    assert!(all.len() > 200, "{} functions", all.len());
    let seen = reached(&all);
    // The cycle reaches its stages: a call graph that stopped at step_into would pass anything.
    for stage in [
        "record_evidence",
        "write_probabilities",
        "decide_slots",
        "arbitrate",
        "resolve_conflict",
    ] {
        assert!(
            seen.keys().any(|&k| all[k].name == stage),
            "step_into does not reach {stage}"
        );
    }
    let mut found = Vec::new();
    let mut known_seen = BTreeSet::new();
    for (&k, from) in &seen {
        let f = &all[k];
        if !names_a_string_map(&f.text) {
            continue;
        }
        let file = f.file.file_name().unwrap().to_string_lossy().to_string();
        let key = (file.as_str(), f.name.as_str());
        if GOAL_MAPS.contains(&key) {
            continue;
        }
        if KNOWN.contains(&key) {
            known_seen.insert(key.1.to_string());
            continue;
        }
        found.push(f.place(from));
    }
    assert!(
        found.is_empty(),
        "string-keyed maps inside the cycle:\n{}",
        found.join("\n")
    );
    for (file, name) in KNOWN {
        assert!(
            known_seen.contains(name),
            "{file} fn {name} no longer builds a string-keyed map in the cycle: take it off KNOWN"
        );
    }
}

/// Maps keyed by the guarantee's goal names (`energy_j`, `duration_s`): neither observations,
/// probabilities nor evidence (the record's margins, goals and drift, and their copy).
const GOAL_MAPS: [(&str, &str); 3] = [
    ("guarantee.rs", "named_into"),
    ("guarantee.rs", "named"),
    ("goal_maps.rs", "clone_goal_maps_from"),
];

/// Left to do: nothing (the snapshot's observations and the vehicle's telemetry are by slot since
/// issue 39 item 1). This list only shrinks: an entry that no longer builds a map fails the test
/// until it is taken off.
const KNOWN: [(&str, &str); 0] = [];

/// Where `text` builds a list of action names: it turns an action id into its name (the
/// catalogue's `actions.name(`, an `ActionIds`' `to_names(`, the old record filler
/// `fill_strings(`), or copies an MDP action's primitives by name (a clone of `does[`, the
/// MDP's `Vec<Vec<String>>`; reading them is not building).
fn builds_action_names(text: &str) -> bool {
    let squeezed: String = text.chars().filter(|c| !c.is_whitespace()).collect();
    let copies_does = squeezed.contains("does[") && squeezed.contains("clone");
    copies_does
        || ["actions.name(", "to_names(", "fill_strings("]
            .iter()
            .any(|p| squeezed.contains(p))
}

/// Inside the cycle actions travel by id (issue 39 item 1): the record's action lists are
/// `ActionIds` over the catalogue's names, and no function `Core::step_into` reaches builds a list
/// of action names (names are written when the record is serialized).
#[test]
fn no_action_name_list_is_built_inside_the_cycle() {
    let all = core_functions();
    let seen = reached(&all);
    for stage in ["propose", "resolve_by", "record_resource_conflicts"] {
        assert!(
            seen.keys().any(|&k| all[k].name == stage),
            "step_into does not reach {stage}"
        );
    }
    let mut found = Vec::new();
    for (&k, from) in &seen {
        let f = &all[k];
        if !builds_action_names(&f.text) {
            continue;
        }
        found.push(f.place(from));
    }
    assert!(
        found.is_empty(),
        "action names built inside the cycle:\n{}",
        found.join("\n")
    );
    // The record's action lists, by their declared type (record.rs, comments blanked).
    let record = Path::new(env!("CARGO_MANIFEST_DIR")).join("../companion-core/src/record.rs");
    let code = shipped_code::code_only(&std::fs::read_to_string(&record).unwrap());
    let squeezed: String = code.chars().filter(|c| !c.is_whitespace()).collect();
    for field in [
        "pubactions:ActionIds,",
        "pubshell_actions:ActionIds,",
        "pubkept:ActionIds,",
        "pubdropped:ActionIds,",
    ] {
        assert_eq!(
            squeezed.matches(field).count(),
            if field == "pubactions:ActionIds," {
                2
            } else {
                1
            },
            "record.rs: `{field}` (a proposal's and the record's actions, the shell's, a \
             conflict's kept and dropped are ids over the catalogue)"
        );
    }
}

#[test]
fn the_guard_sees_a_string_map_and_a_call() {
    let mut fs = Vec::new();
    let code = shipped_code::code_only(
        "fn step_into() { helper::<u8>(x); }\n// fn ghost() { BTreeMap<String, f64> }\n\
         fn helper() { let m: BTreeMap< String , f64> = BTreeMap::new(); s(\"a(\") }\n\
         #[cfg(test)]\nfn tested() { BTreeMap<String, f64> }",
    );
    functions(Path::new("decision.rs"), &code, &mut fs);
    let names: Vec<&str> = fs.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["step_into", "helper"]);
    assert_eq!(
        called(&fs[0].text),
        BTreeSet::from([("helper".to_string(), Call::Own)])
    );
    assert!(names_a_string_map(&fs[1].text));
    assert!(!names_a_string_map(&fs[0].text));
    assert!(builds_action_names("fn f() { let v = list.to_names(); }"));
    assert!(builds_action_names(
        "fn f() { push(model.actions.name(a)) }"
    ));
    assert!(builds_action_names(
        "fn f() { out.clone_from(&self.does[d.action]) }"
    ));
    assert!(!builds_action_names("fn f() { rec.actions.push(a) }"));
    assert!(!builds_action_names(
        "fn primitives(&self, a: usize) { &self.does[a] }"
    ));
    assert_eq!(fs[1].line, 3);
}
