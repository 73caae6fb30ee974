//! The crate boundaries hold: the core reads no files and depends on no I/O, runtime, CLI or
//! randomness crate (directly or through its dependencies), and the binary does not link the
//! testkit (its hidden-subcommand check is in companion/tests/cli_refused.rs).
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

#[test]
fn no_file_of_the_core_names_std_fs() {
    let mut files = Vec::new();
    rs_files(&root().join("companion-core"), &mut files);
    assert!(files.len() > 10, "{files:?}");
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        assert!(!text.contains("std::fs"), "{} names std::fs", f.display());
    }
}

/// The normal dependencies of `krate` in the workspace, transitively, from `cargo metadata`.
fn normal_deps(krate: &str) -> Vec<String> {
    let out = std::process::Command::new(env!("CARGO"))
        .args([
            "tree",
            "-p",
            krate,
            "-e",
            "normal",
            "--prefix",
            "none",
            "--offline",
        ])
        .current_dir(root())
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

#[test]
#[cfg_attr(
    not(target_arch = "x86_64"),
    ignore = "runs cargo, a host binary (the cross-built tests run under qemu)"
)]
fn the_core_depends_on_no_io_runtime_cli_or_randomness_crate() {
    let deps = normal_deps("companion-core");
    assert!(deps.iter().any(|d| d == "bayes_net"), "{deps:?}");
    for banned in ["tokio", "mavlink", "rand", "clap", "anyhow"] {
        assert!(
            !deps.iter().any(|d| d == banned),
            "companion-core depends on {banned}"
        );
    }
    let link = normal_deps("companion-link");
    assert!(link.iter().any(|d| d == "mavlink"), "{link:?}");
    assert!(
        !link.iter().any(|d| d == "tokio"),
        "companion-link depends on tokio"
    );
    let bin = normal_deps("companion");
    assert!(
        !bin.iter().any(|d| d == "companion-testkit"),
        "the binary links the testkit"
    );
}

/// The fleet's query engine is ground side only (issue 38): the onboard binary links no
/// DataFusion, Arrow or Parquet crate, while `companion-fleet` does (so the names are right).
#[test]
#[cfg_attr(
    not(target_arch = "x86_64"),
    ignore = "runs cargo, a host binary (the cross-built tests run under qemu)"
)]
fn the_onboard_binary_links_no_query_engine() {
    let engine = |d: &String| {
        ["datafusion", "arrow", "parquet"]
            .iter()
            .any(|e| d.starts_with(e))
    };
    let fleet = normal_deps("companion-fleet");
    for e in ["datafusion", "arrow", "parquet"] {
        assert!(
            fleet.iter().any(|d| d == e),
            "companion-fleet without {e}: {fleet:?}"
        );
    }
    let onboard: Vec<String> = normal_deps("companion")
        .into_iter()
        .filter(|d| engine(d))
        .collect();
    assert!(
        onboard.is_empty(),
        "the onboard companion links {onboard:?}"
    );
}

/// The workspace members' `src/` folders (every crate the workspace builds).
fn crate_src_dirs() -> Vec<PathBuf> {
    let manifest = std::fs::read_to_string(root().join("Cargo.toml")).unwrap();
    let doc: toml::Table = manifest.parse().unwrap();
    let members = doc["workspace"]["members"].as_array().unwrap();
    members
        .iter()
        .map(|m| root().join(m.as_str().unwrap()).join("src"))
        .collect()
}

/// A test file, by this workspace's convention: named `tests.rs` or `*_tests.rs`, or under a
/// `tests/` folder (a module's tests live beside it: `foo.rs` + `foo/tests.rs`).
fn is_test_file(p: &Path) -> bool {
    let name = p.file_name().unwrap().to_string_lossy();
    name == "tests.rs"
        || name.ends_with("_tests.rs")
        || p.strip_prefix(root())
            .unwrap_or(p)
            .components()
            .any(|c| c.as_os_str() == "tests")
}

/// The shipped (non-test) Rust files under the crates' `src/`.
fn shipped_rs_files() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in crate_src_dirs() {
        rs_files(&dir, &mut files);
    }
    files.retain(|f| !is_test_file(f));
    files
}

/// One concern per file (issue 25): a shipped file over 1,000 lines holds several; split it by
/// concern, and move its inline tests beside it (`foo/tests.rs`).
#[test]
fn no_shipped_rust_file_is_over_1000_lines() {
    const MAX_LINES: usize = 1000;
    let files = shipped_rs_files();
    assert!(
        files
            .iter()
            .any(|f| f.ends_with("companion-link/src/vehicle/mod.rs")),
        "{files:?}"
    );
    let long: Vec<String> = files
        .iter()
        .filter_map(|f| {
            let n = std::fs::read_to_string(f).unwrap().lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", f.display()))
        })
        .collect();
    assert!(
        long.is_empty(),
        "shipped files over {MAX_LINES} lines: {long:?}"
    );
}

/// The modules that build what goes into a decision record (command records, events, link
/// events, the record itself), relative to the workspace root; a folder stands for every
/// shipped file in it.
const RECORD_BUILDERS: &[&str] = &[
    "companion-link/src/vehicle",
    "companion-link/src/command.rs",
    "companion-link/src/mission.rs",
    "companion-link/src/telemetry.rs",
    "companion-link/src/operator.rs",
    "companion-link/src/mission_state.rs",
    "companion-link/src/readiness.rs",
    "companion-core/src/record.rs",
    "companion-core/src/record",
    "companion/src/fly/cycle.rs",
    "companion/src/sim.rs",
];

/// Types from producer to consumer (issue 25): no value reaches a record through its `Debug`
/// text (`{:?}`, `{x:?}`, `{:#?}`), which is no contract and changes with a derive or a crate
/// upgrade. MAVLink enums are named with `companion_link::mavlink_name`, our types with their
/// `Display` or a named field; text from the link is quoted with `companion_link::quoted`.
#[test]
fn no_debug_formatting_in_the_modules_that_build_records() {
    let mut files = Vec::new();
    for entry in RECORD_BUILDERS {
        let p = root().join(entry);
        if p.is_dir() {
            rs_files(&p, &mut files);
        } else {
            assert!(
                p.is_file(),
                "{} is gone: update RECORD_BUILDERS",
                p.display()
            );
            files.push(p);
        }
    }
    files.retain(|f| !is_test_file(f));
    let mut found = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        // Inline tests (`#[cfg(test)]` items) may print what they like.
        let shipped = shipped_code::shipped(&text);
        for (n, line) in shipped.lines().enumerate() {
            if line.contains(":?}") || line.contains(":#?}") {
                found.push(format!("{}:{}: {}", f.display(), n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "Debug formatting into a record: {found:#?}"
    );
}

/// The link is sans-IO (issue 25): it is handed bytes and params as data and reads no file;
/// the shell reads them (the signing key: `fly::link_security::load_signing_key`). Test code
/// (test files, and `#[cfg(test)]` items wherever they sit) may use the disk.
#[test]
fn no_shipped_file_of_the_link_names_std_fs() {
    let mut files = Vec::new();
    rs_files(&root().join("companion-link/src"), &mut files);
    files.retain(|f| !is_test_file(f));
    assert!(files.len() > 10, "{files:?}");
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let shipped = shipped_code::shipped(&text);
        assert!(
            !shipped.contains("std::fs"),
            "{} names std::fs",
            f.display()
        );
    }
}

/// The guards read the whole file (issue 39 item 4): a `#[cfg(test)]` item is blanked where it
/// sits, and what follows it is still read. Each case here is one the old cut (everything after
/// the first `#[cfg(test)]`) or a naive brace count gets wrong.
#[test]
fn shipped_code_blanks_only_the_test_items() {
    let keep = |src: &str, wanted: &[&str], gone: &[&str]| {
        let out = shipped_code::shipped(src);
        assert_eq!(out.lines().count(), src.lines().count(), "{out:?}");
        for w in wanted {
            assert!(out.contains(w), "{w} lost in {out:?}");
        }
        for g in gone {
            assert!(!out.contains(g), "{g} kept in {out:?}");
        }
    };
    // An out-of-line test module near the top: the rest of the file is shipped.
    keep(
        "mod a;\n#[cfg(test)]\nmod tests;\npub fn after() { \"std::fs\" }\n",
        &["mod a;", "pub fn after()", "std::fs"],
        &["mod tests"],
    );
    // A test module in the middle, with braces in strings, chars and comments inside it.
    keep(
        "fn a() {}\n#[cfg(test)]\nmod tests {\n  fn t() { let s = \"}\"; let c = '}'; /* } */ // }\n  }\n}\nfn b() {}\n",
        &["fn a()", "fn b()"],
        &["fn t()", "mod tests"],
    );
    // A raw string and a lifetime inside the test item.
    keep(
        "#[cfg(test)]\nfn t<'a>(x: &'a str) { let r = r#\"}}\"#; }\nfn shipped() {}\n",
        &["fn shipped()"],
        &["fn t", "r#"],
    );
    // A gated `use` and an attribute after the cfg.
    keep(
        "#[cfg(test)]\nuse std::fs;\n#[cfg(test)]\n#[allow(dead_code)]\nmod m { }\nuse std::io;\n",
        &["use std::io;"],
        &["std::fs", "mod m", "allow"],
    );
    // The text `#[cfg(test)]` in a string or comment gates nothing.
    keep(
        "const S: &str = \"#[cfg(test)]\";\n// #[cfg(test)]\nfn real() {}\n",
        &["fn real()", "const S"],
        &[],
    );
    // Escaped quotes in chars and strings.
    keep(
        "let q = '\\''; let s = \"\\\"}\";\n#[cfg(test)]\nmod t { }\nfn z() {}\n",
        &["fn z()", "let q"],
        &["mod t"],
    );
}
