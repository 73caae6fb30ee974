//! Stamps the git revision into the binary (COMPANION_GIT_REVISION) for the decision-log header.
//! Falls back to "unknown" outside a git checkout or without git, so builds never fail on it.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    Some(String::from_utf8(out.stdout).ok()?.trim().to_string())
}

fn main() {
    // No "-dirty" check: `git status` may rewrite the index, which would re-run this script and
    // rebuild the crate on every build.
    let revision = git(&["rev-parse", "HEAD"])
        .filter(|r| !r.is_empty())
        .unwrap_or_else(|| "unknown".to_string());
    println!("cargo:rustc-env=COMPANION_GIT_REVISION={revision}");
    // Re-run when HEAD moves (commit, checkout) — paths resolved by git so worktrees work too.
    // Only existing files: a missing one (packed refs) would make cargo re-run this every build.
    let mut watch = vec!["HEAD".to_string()];
    if let Some(head_ref) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watch.push(head_ref);
    }
    watch.push("packed-refs".to_string());
    for p in watch {
        if let Some(path) = git(&["rev-parse", "--git-path", &p])
            && std::path::Path::new(&path).exists()
        {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    println!("cargo:rerun-if-changed=build.rs");
}
