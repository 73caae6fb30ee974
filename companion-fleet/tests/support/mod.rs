//! What the fleet's integration tests share: running the `companion-fleet` binary, and
//! comparing its numbers with calibrate's (1e-9 relative).

#![allow(dead_code)] // each test file uses its part

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
