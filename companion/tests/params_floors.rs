//! Params that load but cannot work are refused at start (issue 26 item 7): a stream rate below
//! the floor of one message per 10 s (`1e-40` Hz was accepted) and an onboard monitor name longer
//! than NAMED_VALUE_FLOAT's 10-character `name` (the mapping could never fire). Each refusal is
//! seen by every loader (`Params::load`, `check`, `fly`'s setup) and names the file, the entry
//! and the reason. docs/params.md, "Limits".

mod common;
use common::copy_dir;
use companion::check::{self, CheckArgs};
use companion::fly::{FlyArgs, FlySetup};
use companion::params::{Params, default_params_dir};
use std::path::Path;

/// A copy of the shipped params with `link.toml` edited by `f`.
fn link_edited(f: impl FnOnce(String) -> String) -> tempfile::TempDir {
    let d = tempfile::tempdir().unwrap();
    copy_dir(&default_params_dir(), d.path());
    let p = d.path().join("link.toml");
    let text = std::fs::read_to_string(&p).unwrap();
    let new = f(text.clone());
    assert_ne!(new, text, "the edit changed nothing");
    std::fs::write(&p, new).unwrap();
    d
}

fn refused(dir: &Path, entry: &str, reason: &str) {
    let want = |what: &str, msg: String| {
        assert!(
            msg.contains("link.toml") && msg.contains(entry) && msg.contains(reason),
            "{what}: expected link.toml / {entry} / {reason:?} in: {msg}"
        );
    };
    let Err(e) = Params::load(dir, None) else {
        panic!("Params::load accepted it")
    };
    want("Params::load", e.to_string());
    let args = CheckArgs {
        params: Some(dir.to_path_buf()),
        ..Default::default()
    };
    let Err(e) = check::report(&args) else {
        panic!("check accepted it")
    };
    want("check", format!("{e:#}"));
    let mut fa = FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"]).unwrap();
    fa.params = Some(dir.to_path_buf());
    let Err(e) = FlySetup::load(&fa) else {
        panic!("fly's setup accepted it")
    };
    want("FlySetup::load", format!("{e:#}"));
}

#[test]
fn stream_rates_below_the_floor_are_refused() {
    for v in ["1e-40", "0.05", "0.0999"] {
        let d = link_edited(|t| t.replace("WIND = 1.0", &format!("WIND = {v}")));
        refused(d.path(), "streams.WIND", "0.1");
    }
}

#[test]
fn stream_rate_at_the_floor_loads() {
    let d = link_edited(|t| t.replace("WIND = 1.0", "WIND = 0.1"));
    Params::load(d.path(), None).unwrap();
}

#[test]
fn onboard_name_longer_than_named_value_float_is_refused() {
    // 11 characters: one more than NAMED_VALUE_FLOAT.name holds.
    let d = link_edited(|t| t.replace("tgt_det = ", "tgt_detect1 = "));
    refused(d.path(), "telemetry.onboard.tgt_detect1", "1 to 10");
}

#[test]
fn onboard_name_of_ten_characters_loads() {
    let d = link_edited(|t| t.replace("tgt_det = ", "tgt_detect = "));
    Params::load(d.path(), None).unwrap();
}
