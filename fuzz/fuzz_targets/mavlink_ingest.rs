//! MAVLink bytes in, evidence and decisions out: companion_testkit::fuzzing::ingest_one.
#![no_main]

use companion_testkit::fuzzing::{IngestFixture, ingest_one};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn fixture() -> &'static IngestFixture {
    static FX: OnceLock<IngestFixture> = OnceLock::new();
    FX.get_or_init(|| {
        IngestFixture::load(&companion::spec::default_params_dir()).expect("the real params load")
    })
}

fuzz_target!(|data: &[u8]| {
    ingest_one(fixture(), data);
});
