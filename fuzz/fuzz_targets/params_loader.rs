//! One params file replaced by the input, then the whole start-up load:
//! companion_testkit::fuzzing::params_one.
#![no_main]

use companion_testkit::fuzzing::{ParamsFixture, params_one};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn fixture() -> &'static ParamsFixture {
    static FX: OnceLock<ParamsFixture> = OnceLock::new();
    FX.get_or_init(|| {
        ParamsFixture::new(&companion::spec::default_params_dir()).expect("params/ is readable")
    })
}

fuzz_target!(|data: &[u8]| {
    params_one(fixture(), data);
});
