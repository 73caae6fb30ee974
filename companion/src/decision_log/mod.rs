//! The decision log: one run folder per run, a JSON Lines file of [`DecisionRecord`]s written by
//! its own thread, a tolerant reader, and a `.tlog` writer for the raw MAVLink stream.
//!
//! Why a separate thread behind a bounded channel: the decision cycle must never wait on a disk.
//! The producer calls [`DecisionLog::record`] (a `try_send`); when the writer falls behind, the
//! record is dropped, counted, and a `{"kind":"loss","dropped":N}` line says so in the file.
//!
//! Layout, schema, rotation and crash safety: docs/decision-log.md.
//!
//! [`DecisionRecord`]: companion_core::record::DecisionRecord

pub mod migration;
mod reader;
mod stream;
mod tlog;
mod writer;

pub(crate) use reader::log_files;
pub use reader::{LogEnd, LogEvent, LogRead, LossMark, ReadError, ReadIssue, read_log};
pub use stream::{LogItem, LogStream, LossReason, MAX_LINE_BYTES, stream_log};
pub(crate) use tlog::frame_len;
pub use tlog::{TlogFrame, TlogWriter, read_tlog};
pub use writer::{
    DEFAULT_MAX_BYTES, DEFAULT_MAX_LINE_BYTES, DecisionLog, LetGo, LogCapError, RESERVE_BYTES,
    RESERVE_FILE, WriterOptions, WriterStats, max_bytes_from_env, parse_max_bytes,
};

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

pub use companion_core::record::SCHEMA_VERSION;

/// File stem of the decision log parts: `decisions.jsonl`, `decisions.1.jsonl`, ...
pub const LOG_STEM: &str = "decisions";

/// Params files larger than this go into the header as a hash instead of their contents.
pub const PARAMS_INLINE_MAX_BYTES: u64 = 64 * 1024;

/// The git revision the binary was built from (`git rev-parse HEAD` at build time, see
/// companion/build.rs), `unknown` when built outside a git checkout or without git.
pub const GIT_REVISION: &str = env!("COMPANION_GIT_REVISION");

/// First line of every log part. Every field defaults when missing so a damaged or foreign
/// header still yields what it has.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Header {
    /// Schema version of the records that follow ([`SCHEMA_VERSION`] when written by this build).
    pub schema: u32,
    /// Always `"header"`.
    pub kind: String,
    /// Start of the run, RFC 3339 UTC (`2025-06-01T12:00:00Z`).
    pub started_utc: String,
    pub git_revision: String,
    /// The command line that started the run.
    pub command: String,
    /// Params file name (relative to the params dir) -> its contents, or
    /// `"fnv1a64:<hex> (<n> bytes)"` when larger than [`PARAMS_INLINE_MAX_BYTES`].
    #[serde(default)]
    pub params: BTreeMap<String, String>,
    /// Decision policy (`safety`, `mission`) when known at start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario: Option<String>,
    /// Decision model of the logged run (`bfm`, `reference`, ...), so `replay` rebuilds the same
    /// core; absent in logs of older builds (replay then reads `--model` from `command`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Nominal seconds per decision cycle (simulate's step length), when there is one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_s: Option<f64>,
    /// Rotation part number: 0 for `decisions.jsonl`, k for `decisions.k.jsonl`.
    #[serde(default)]
    pub part: u32,
    /// The plan the guarantee judged (route, zones, activities, planned energy and duration);
    /// with derived activities, `replay` compiles the mission from them. Absent in logs of
    /// builds before it (the typed mission).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<PlanSummary>,
}

/// Which plan `check`, `simulate` and `fly` judge, for people and the log header: where it came
/// from, how many activities, and the pre-flight allocation's planned energy and duration (with
/// the goals' bounds lifted when they cannot be met, as the flight starts: the plan's own
/// numbers, whatever the pack).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlanSummary {
    /// The PANORAMA mission planned against (tasks, TIOs, goals).
    pub mission: String,
    /// The route the activities were derived from; `None`: the mission's typed `[[activities]]`
    /// (the legacy plan, chosen with `--mission NAME`).
    pub route_file: Option<String>,
    /// The zones file, when any.
    pub zones_file: Option<String>,
    /// Number of activities.
    pub activities: usize,
    /// Planned energy (J), when the mission has an energy goal.
    pub planned_energy_j: Option<f64>,
    /// Planned duration (s), when the mission has a duration goal.
    pub planned_duration_s: Option<f64>,
    /// The derived activities (replay re-compiles the mission from them); empty when typed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub derived: Vec<companion_core::route_plan::DerivedActivity>,
    /// Per activity, in flight order: the pre-flight allocation's IA and its planned energy and
    /// duration (what a flight is compared against, activity by activity).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub planned: Vec<PlannedActivity>,
}

/// One activity's cell of the pre-flight allocation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PlannedActivity {
    /// The activity's name.
    pub name: String,
    /// The IA allocated (its TIO names).
    pub ia: String,
    /// Planned energy (J), when the mission has an energy goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub energy_j: Option<f64>,
    /// Planned duration (s), when the mission has a duration goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub duration_s: Option<f64>,
}

impl Header {
    /// A header for a run started at `started` by `command`, with no params attached yet.
    pub fn new(command: impl Into<String>, started: SystemTime) -> Self {
        Header {
            schema: SCHEMA_VERSION,
            kind: "header".into(),
            started_utc: utc_rfc3339(started),
            git_revision: GIT_REVISION.into(),
            command: command.into(),
            params: BTreeMap::new(),
            policy: None,
            scenario: None,
            model: None,
            seed: None,
            step_s: None,
            part: 0,
            plan: None,
        }
    }

    /// Attach every `*.toml` file under `dir` (recursively), by path relative to `dir`. When
    /// `dir` is a params overlay (`--params FILE`), the files as layered, so that `replay`
    /// rebuilds the model the run flew.
    pub fn with_params_dir(mut self, dir: &Path) -> io::Result<Self> {
        if crate::params_overlay::is_overlay(dir) {
            let files = crate::params::read_params_dir(dir).map_err(io::Error::other)?;
            let base = files.dir().to_path_buf();
            for (path, text) in files.iter() {
                let name = path.strip_prefix(&base).unwrap_or(path);
                let name = name.to_string_lossy().replace('\\', "/");
                let entry = text.map_or_else(|r| format!("unreadable: {r}"), params_entry_of_text);
                self.params.insert(name, entry);
            }
            return Ok(self);
        }
        let mut files = Vec::new();
        collect_toml(dir, &mut files)?;
        files.sort();
        for f in files {
            let name = f
                .strip_prefix(dir)
                .unwrap_or(&f)
                .to_string_lossy()
                .replace('\\', "/");
            self.params.insert(name, params_entry_of_file(&f)?);
        }
        Ok(self)
    }
}

fn collect_toml(dir: &Path, out: &mut Vec<PathBuf>) -> io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            collect_toml(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "toml") && path.is_file() {
            // Only regular files: reading a FIFO named *.toml would block the start.
            out.push(path);
        }
    }
    Ok(())
}

/// [`params_entry`] of the file at `path`, hashing a large file in chunks rather than holding it.
fn params_entry_of_file(path: &Path) -> io::Result<String> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let len = file.metadata()?.len();
    if len <= PARAMS_INLINE_MAX_BYTES {
        let mut bytes = Vec::with_capacity(len as usize);
        file.read_to_end(&mut bytes)?;
        return Ok(params_entry(&bytes));
    }
    let mut h = FNV_OFFSET;
    let mut n = 0u64;
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        let k = file.read(&mut buf)?;
        if k == 0 {
            break;
        }
        h = fnv1a64_update(h, &buf[..k]);
        n += k as u64;
    }
    Ok(format!("fnv1a64:{h:016x} ({n} bytes)"))
}

fn params_entry_of_text(text: &str) -> String {
    params_entry(text.as_bytes())
}

/// Contents as text when small and UTF-8, else a content hash (FNV-1a 64: no crypto needed, it
/// only has to tell two params sets apart).
fn params_entry(bytes: &[u8]) -> String {
    match std::str::from_utf8(bytes) {
        Ok(s) if bytes.len() as u64 <= PARAMS_INLINE_MAX_BYTES => s.to_string(),
        _ => format!("fnv1a64:{:016x} ({} bytes)", fnv1a64(bytes), bytes.len()),
    }
}

pub(crate) fn fnv1a64(bytes: &[u8]) -> u64 {
    fnv1a64_update(FNV_OFFSET, bytes)
}

const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

fn fnv1a64_update(mut h: u64, bytes: &[u8]) -> u64 {
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Calendar date (y, m, d) from days since 1970-01-01 (H. Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (if m <= 2 { y + 1 } else { y }, m, d)
}

fn utc_parts(t: SystemTime) -> (i64, u32, u32, u64, u64, u64) {
    let secs = t
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    let s = secs % 86_400;
    (y, m, d, s / 3600, (s / 60) % 60, s % 60)
}

/// `2025-06-01T12:00:00Z` (whole seconds; times before 1970 clamp to the epoch).
pub fn utc_rfc3339(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s) = utc_parts(t);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}Z")
}

/// Folder-name form without colons (portable to every filesystem): `2025-06-01T12-00-00Z`.
pub fn utc_folder_name(t: SystemTime) -> String {
    let (y, mo, d, h, mi, s) = utc_parts(t);
    format!("{y:04}-{mo:02}-{d:02}T{h:02}-{mi:02}-{s:02}Z")
}

/// Default parent of run folders, relative to the working directory.
pub const DEFAULT_RUNS_DIR: &str = "runs";

/// Create a fresh run folder `<base>/<UTC time>/` (suffix `-1`, `-2`, ... when two runs start in
/// the same second) and return its path for the CLI to print. Never reuses an existing folder.
pub fn create_run_dir(base: &Path, now: SystemTime) -> io::Result<PathBuf> {
    std::fs::create_dir_all(base)?;
    let name = utc_folder_name(now);
    for k in 0..1000u32 {
        let candidate = if k == 0 {
            base.join(&name)
        } else {
            base.join(format!("{name}-{k}"))
        };
        match std::fs::create_dir(&candidate) {
            Ok(()) => return Ok(candidate),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::new(
        io::ErrorKind::AlreadyExists,
        format!(
            "1000 run folders named {name} already exist in {}",
            base.display()
        ),
    ))
}

/// Create a fresh run folder under `base` (see [`create_run_dir`]) and start its decision log.
/// The folder is [`DecisionLog::dir`]; the CLI prints it.
pub fn start_run(
    base: &Path,
    now: SystemTime,
    header: Header,
    opts: WriterOptions,
) -> io::Result<DecisionLog> {
    let dir = create_run_dir(base, now)?;
    DecisionLog::start(&dir, header, opts)
}

/// Path of rotation part `k` in `dir`: part 0 is `decisions.jsonl`, part k is `decisions.k.jsonl`.
pub fn part_path(dir: &Path, k: u32) -> PathBuf {
    if k == 0 {
        dir.join(format!("{LOG_STEM}.jsonl"))
    } else {
        dir.join(format!("{LOG_STEM}.{k}.jsonl"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(secs: u64) -> SystemTime {
        UNIX_EPOCH + Duration::from_secs(secs)
    }

    #[test]
    fn utc_formatting_matches_known_dates() {
        // Hand-checked: the epoch; 2000-02-29 (leap day of a century leap year) is day 11016;
        // 2024-12-31T23:59:59Z = 1735689599 (date -u -d @1735689599).
        assert_eq!(utc_rfc3339(at(0)), "1970-01-01T00:00:00Z");
        assert_eq!(utc_rfc3339(at(11_016 * 86_400)), "2000-02-29T00:00:00Z");
        assert_eq!(utc_rfc3339(at(1_735_689_599)), "2024-12-31T23:59:59Z");
        assert_eq!(utc_folder_name(at(1_735_689_599)), "2024-12-31T23-59-59Z");
        // 2100 is not a leap year: 4107456000 is 2100-02-28 (date -u -d @4107456000), next day March 1.
        assert_eq!(utc_rfc3339(at(4_107_456_000)), "2100-02-28T00:00:00Z");
        assert_eq!(
            utc_rfc3339(at(4_107_456_000 + 86_400)),
            "2100-03-01T00:00:00Z"
        );
    }

    #[test]
    fn run_dirs_never_collide() {
        let tmp = tempfile::tempdir().unwrap();
        let a = create_run_dir(tmp.path(), at(1_735_689_599)).unwrap();
        let b = create_run_dir(tmp.path(), at(1_735_689_599)).unwrap();
        assert_ne!(a, b);
        assert!(a.ends_with("2024-12-31T23-59-59Z"));
        assert!(b.ends_with("2024-12-31T23-59-59Z-1"));
    }

    #[test]
    fn params_dir_is_embedded_small_and_hashed_large() {
        let tmp = tempfile::tempdir().unwrap();
        std::fs::create_dir(tmp.path().join("sub")).unwrap();
        std::fs::write(tmp.path().join("a.toml"), "x = 1\n").unwrap();
        std::fs::write(tmp.path().join("sub/b.toml"), "y = 2\n").unwrap();
        std::fs::write(tmp.path().join("notes.md"), "ignored").unwrap();
        let big = vec![b'#'; (PARAMS_INLINE_MAX_BYTES + 1) as usize];
        std::fs::write(tmp.path().join("big.toml"), &big).unwrap();
        let h = Header::new("companion simulate", at(0))
            .with_params_dir(tmp.path())
            .unwrap();
        assert_eq!(h.params.len(), 3);
        assert_eq!(h.params["a.toml"], "x = 1\n");
        assert_eq!(h.params["sub/b.toml"], "y = 2\n");
        assert!(h.params["big.toml"].starts_with("fnv1a64:"));
        assert!(h.params["big.toml"].ends_with("(65537 bytes)"));
    }

    #[test]
    fn fnv1a64_known_vectors() {
        // Published FNV-1a 64 test vectors (empty string, "a").
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
