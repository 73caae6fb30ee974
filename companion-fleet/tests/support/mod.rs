//! What the fleet's integration tests share: running the `companion-fleet` binary, and
//! comparing its numbers with calibrate's (1e-9 relative).

#![allow(dead_code)] // each test file uses its part

use companion::decision_log::Header;
use companion::sim::{self, Scenario, WorldSpec};
use companion_core::decision::{Core, ModelKind};
use std::path::Path;

/// The binary under test.
pub(crate) const FLEET: &str = env!("CARGO_BIN_EXE_companion-fleet");

/// Run `companion-fleet ARGS`; its stdout (it must succeed).
pub(crate) fn fleet(args: &[&str]) -> String {
    let o = std::process::Command::new(FLEET)
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "companion-fleet {args:?}\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// `got` equals `want` within 1e-9 relative.
pub(crate) fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-9 * want.abs().max(1e-12)
}

/// The JSON number `got` (the fleet's) equals `want` (calibrate's) within 1e-9 relative.
pub(crate) fn assert_near(got: &serde_json::Value, want: f64, what: &str) {
    let g = got
        .as_f64()
        .unwrap_or_else(|| panic!("{what}: not a number: {got}"));
    assert!(close(g, want), "{what}: fleet {g} vs calibrate {want}");
}

/// A simulated mission's run folder: the header, then its records (with the world's outcome).
pub(crate) fn write_simulated(dir: &Path, scenario: &str, seed: u64) {
    let params = companion::params::default_params_dir();
    let files = companion::params::read_params_dir(&params).unwrap();
    let model = std::sync::Arc::new(companion::params::load_model(&params).unwrap());
    let world = WorldSpec::load(&files).unwrap();
    let s = Scenario::load(&files, scenario).unwrap();
    let mut core = Core::new(
        std::sync::Arc::clone(&model),
        ModelKind::Bfm,
        model.policy("mission").unwrap(),
    );
    let run = sim::run(&world, &s, seed, |obs| core.step(obs));
    let h = Header::new(
        &format!("companion simulate --scenario {scenario} --seed {seed}"),
        std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_750_000_000 + seed * 86_400),
    );
    let mut f = companion_testkit::run_log::RunLog::create(dir, &h);
    for r in &run.records {
        f.record(r);
    }
}
