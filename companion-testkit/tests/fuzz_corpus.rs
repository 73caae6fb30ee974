//! Replays the fuzz corpus (fuzz/corpus/<target>/) and the saved crash reproducers
//! (fuzz/regressions/<target>/) through the same library functions the fuzz targets call
//! (companion_testkit::fuzzing), on stable Rust, in the normal `cargo test`. docs/fuzzing.md.

use companion::params::default_params_dir;
use companion_testkit::fuzzing::{
    self, IngestFixture, IngestInput, ParamsFixture, ingest_one, ingest_seeds, params_one,
};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every file in fuzz/corpus/<target>/ and fuzz/regressions/<target>/, sorted; of the corpus,
/// every `FUZZ_CORPUS_STRIDE`-th file only when that is set (scripts/arm.sh under qemu, where
/// a replay is ~10x slower: the full corpus runs natively with overflow checks in stage 3).
/// The regressions always run whole.
fn inputs(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let stride = std::env::var("FUZZ_CORPUS_STRIDE").map_or(1, |v| {
        v.parse::<usize>()
            .ok()
            .filter(|n| *n > 0)
            .unwrap_or_else(|| panic!("FUZZ_CORPUS_STRIDE={v}: a positive integer expected"))
    });
    let mut out = Vec::new();
    for dir in ["corpus", "regressions"] {
        let d = repo().join("fuzz").join(dir).join(target);
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let mut files: Vec<PathBuf> = rd
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        let keep = if dir == "corpus" { stride } else { 1 };
        for p in files.into_iter().step_by(keep) {
            let bytes = std::fs::read(&p).unwrap();
            out.push((p, bytes));
        }
    }
    out.sort();
    out
}

fn ingest_fixture() -> &'static IngestFixture {
    static FX: OnceLock<IngestFixture> = OnceLock::new();
    FX.get_or_init(|| {
        IngestFixture::load(&companion::params::default_params_dir()).expect("the real params load")
    })
}

fn params_fixture() -> &'static ParamsFixture {
    static FX: OnceLock<ParamsFixture> = OnceLock::new();
    FX.get_or_init(|| ParamsFixture::new(&default_params_dir()).unwrap())
}

#[test]
fn ingest_corpus_replays_without_panic() {
    let fx = ingest_fixture();
    let corpus = inputs("mavlink_ingest");
    assert!(
        corpus.len() >= 8,
        "fuzz/corpus/mavlink_ingest holds the minimised corpus"
    );
    let mut frames = 0;
    for (path, data) in &corpus {
        let r = std::panic::catch_unwind(|| ingest_one(fx, data));
        let out = r.unwrap_or_else(|_| panic!("{} panicked", path.display()));
        frames += out.frames;
    }
    assert!(frames > 0, "the corpus reaches decoded frames");
}

#[test]
fn params_corpus_replays_without_panic() {
    let fx = params_fixture();
    let corpus = inputs("params_loader");
    assert!(
        corpus.len() >= fx.files.len(),
        "fuzz/corpus/params_loader holds at least the real files"
    );
    // Each input loads every params file: the suite's longest test (a minute and a half in
    // debug, three under qemu), so its inputs are shared out over the cores.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let part_len = corpus.len().div_ceil(threads).max(1);
    let rejected: usize = std::thread::scope(|s| {
        let parts: Vec<_> = corpus
            .chunks(part_len)
            .map(|part| {
                s.spawn(move || {
                    let mut rejected = 0;
                    for (path, data) in part {
                        let r = std::panic::catch_unwind(|| params_one(fx, data));
                        let out = r.unwrap_or_else(|_| panic!("{} panicked", path.display()));
                        rejected += usize::from(!out.all_ok());
                    }
                    rejected
                })
            })
            .collect();
        parts
            .into_iter()
            .map(|p| {
                p.join()
                    .expect("an input panicked (its path is printed above)")
            })
            .sum()
    });
    assert!(rejected > 0, "the corpus holds inputs the loaders reject");
}

/// The seeds are the real telemetry the fly loop sees: they must decode completely, reach the
/// autopilot-found state and run decision cycles that command the vehicle.
#[test]
fn ingest_seeds_decode_fully_and_drive_decisions() {
    let fx = ingest_fixture();
    for (name, data) in ingest_seeds() {
        let input = IngestInput::parse(&data);
        let out = ingest_one(fx, &data);
        match name.as_str() {
            // Garbage, refused frames, one stream split across two links, or a reconnect that
            // drops the frame half-received (as it should).
            "noisy"
            | "commands_signing"
            | "telemetry_onboard_mission_policy"
            | "telemetry_link_timeouts_reconnect" => {}
            _ => {
                assert_eq!(
                    out.stats.bytes_unframed() + out.onboard_stats.bytes_unframed(),
                    0,
                    "{name}: every byte is in a frame"
                );
                assert_eq!(out.stats.frames_malformed, 0, "{name}");
                assert_eq!(
                    out.stats.bytes_in + out.onboard_stats.bytes_in,
                    input.stream.len() as u64
                );
                assert!(out.cycles >= 2, "{name}: decision cycles ran");
                assert!(
                    out.messages_out > 0,
                    "{name}: stream requests and commands went out"
                );
            }
        }
    }
}

#[test]
fn signing_seed_refuses_exactly_the_unsigned_and_the_wrongly_signed() {
    let fx = ingest_fixture();
    let (_, data) = ingest_seeds()
        .into_iter()
        .find(|(n, _)| n == "commands_signing")
        .unwrap();
    let out = ingest_one(fx, &data);
    // One unsigned arm command to us, one signed with the right key, three frames with a wrong key.
    assert_eq!(out.stats.unsigned_commands_refused, 1);
    assert_eq!(out.stats.bad_signatures, 3);
    assert_eq!(out.stats.frames_ok, 1);
}

#[test]
fn chunking_follows_the_documented_layout() {
    let data = IngestInput::encode(0x3f, &[2, 3], b"abcdefghij");
    let input = IngestInput::parse(&data);
    assert!(input.signing && input.onboard_odd_chunks && input.reconnect);
    assert_eq!(input.step, std::time::Duration::from_secs(5));
    let chunks: Vec<&[u8]> = input.chunks();
    assert_eq!(chunks, vec![&b"ab"[..], b"cde", b"fg", b"hij"]);
    // Short inputs read missing header bytes as zero: one chunk length of 1.
    assert_eq!(IngestInput::parse(&[]).chunk_lens, vec![1]);
    assert_eq!(IngestInput::parse(&[0, 0]).chunks().len(), 0);
}

/// Each real params file, unchanged, loads everywhere and flies a few steps.
#[test]
fn params_seeds_load() {
    let fx = params_fixture();
    for i in 0..fx.files.len() {
        let out = params_one(fx, &fx.seed(i).unwrap());
        assert!(out.all_ok(), "{}: {:?}", fx.files[i].display(), out.errors);
        assert_eq!(out.cycles, 2 * fuzzing::PARAMS_SIM_STEPS as usize);
    }
}

/// The kinds of bad text the loaders reject, each with the file, an entry and a reason.
#[test]
fn params_bad_inputs_name_file_entry_reason() {
    let fx = params_fixture();
    let idx = |rel: &str| {
        fx.files
            .iter()
            .position(|f| f == Path::new(rel))
            .unwrap_or_else(|| panic!("{rel} in params"))
    };
    let real = |rel: &str| std::fs::read_to_string(default_params_dir().join(rel)).unwrap();
    // The real file with the line `key = ...` replaced by `key = value`.
    let set = |rel: &str, key: &str, value: &str| -> Vec<u8> {
        let text = real(rel);
        let at = text
            .find(&format!("\n{key} ="))
            .unwrap_or_else(|| panic!("{key} in {rel}"))
            + 1;
        let end = text[at..].find('\n').map_or(text.len(), |e| at + e);
        format!("{}{key} = {value}{}", &text[..at], &text[end..]).into_bytes()
    };
    let half = |rel: &str| -> Vec<u8> {
        let text = real(rel);
        let lines: Vec<&str> = text.lines().collect();
        lines[..lines.len() / 2].join("\n").into_bytes()
    };
    let many_parents = {
        let mut t = real("health/system.toml");
        let names: Vec<String> = (0..70).map(|i| format!("C_extra{i}")).collect();
        for n in &names {
            t += &format!(
                "\n[node.{n}]\nrole = \"context\"\nstates = [\"a\", \"b\"]\nprior = [0.5, 0.5]\n"
            );
        }
        let quoted: Vec<String> = names.iter().map(|n| format!("\"{n}\"")).collect();
        t += &format!(
            "\n[node.S_extra]\nrole = \"monitor\"\nstates = [\"ok\", \"bad\"]\nparents = [{}]\n",
            quoted.join(", ")
        );
        t.into_bytes()
    };
    let long_expression = real("mdp/navigation.toml")
        .replacen(
            "A1 = { wp1 = \"P_sys\"",
            &format!("A1 = {{ wp1 = \"P_sys{}\"", "+P_sys".repeat(100_000)),
            1,
        )
        .into_bytes();
    let cases: Vec<(&str, Vec<u8>, &str, &str)> = vec![
        // (file, text, loader that must fail, a piece of the reason)
        ("world.toml", b"\xff\xfe".to_vec(), "world", "cannot read"),
        ("world.toml", b"step_s = ".to_vec(), "world", ""),
        ("link.toml", b"streams = 3".to_vec(), "fly", ""),
        ("health/system.toml", Vec::new(), "model", ""),
        (
            "missions/patrolling.toml",
            b"[[activity]]\nname = 1".to_vec(),
            "mission",
            "",
        ),
        // Numbers that used to pass and panic later in a Duration or a timer.
        (
            "link.toml",
            set("link.toml", "distance_max_age_s", "-2.0"),
            "fly",
            "out of range",
        ),
        (
            "link.toml",
            set("link.toml", "distance_max_age_s", "nan"),
            "fly",
            "not a finite number",
        ),
        (
            "link.toml",
            set("link.toml", "distance_max_age_s", "1e30"),
            "fly",
            "out of range",
        ),
        (
            "link.toml",
            set("link.toml", "decision_period_s", "1e-12"),
            "fly",
            "out of range",
        ),
        (
            "link.toml",
            set("link.toml", "decision_period_s", "1e30"),
            "fly",
            "out of range",
        ),
        (
            "link.toml",
            set("link.toml", "arm_wait_s", "1e30"),
            "fly",
            "out of range",
        ),
        (
            "link.toml",
            set("link.toml", "detection_threshold", "nan"),
            "fly",
            "not a finite number",
        ),
        // Sizes that overflowed the stack or the allocator.
        (
            "mdp/navigation.toml",
            long_expression,
            "model",
            "at most 2000",
        ),
        ("health/system.toml", many_parents, "model", "at most 16"),
        // Empty, cut or inconsistent files that were accepted.
        (
            "observations.toml",
            b"# nothing\n".to_vec(),
            "model",
            "no observations",
        ),
        ("commands.toml", Vec::new(), "fly", "empty"),
        (
            "mdp/index.toml",
            set("mdp/index.toml", "concurrent", "[]"),
            "model",
            "at least one",
        ),
        ("mission.toml", half("mission.toml"), "check", ""),
        ("platform.toml", half("platform.toml"), "model", ""),
        (
            "missions/tracking_route.toml",
            set("missions/tracking_route.toml", "altitude_m", "1e300"),
            "fly",
            "out of range",
        ),
    ];
    for (rel, text, loader, reason) in cases {
        let mut data = vec![idx(rel) as u8];
        data.extend(text);
        let out = params_one(fx, &data);
        let err = out
            .errors
            .iter()
            .find(|(w, _)| *w == loader)
            .and_then(|(_, e)| e.clone())
            .unwrap_or_else(|| panic!("{rel}: {loader} accepted it: {:?}", out.errors));
        assert!(err.file.ends_with(rel), "{err}");
        assert!(err.reason.contains(reason), "{err}");
    }
}

/// Writes the seed corpus into fuzz/corpus/ (`fuzz/seed.sh` runs it; not part of the suite).
#[test]
#[ignore]
fn write_seed_corpus() {
    let ingest = repo().join("fuzz/corpus/mavlink_ingest");
    std::fs::create_dir_all(&ingest).unwrap();
    for (name, data) in ingest_seeds() {
        std::fs::write(ingest.join(format!("seed-{name}")), data).unwrap();
    }
    let params = repo().join("fuzz/corpus/params_loader");
    std::fs::create_dir_all(&params).unwrap();
    let fx = params_fixture();
    for (i, f) in fx.files.iter().enumerate() {
        let name = f.to_string_lossy().replace('/', "-");
        std::fs::write(params.join(format!("seed-{name}")), fx.seed(i).unwrap()).unwrap();
    }
}
