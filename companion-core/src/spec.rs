//! Loading `params/`: the one error type every loader returns, naming the file, the entry and the reason.

use std::cell::RefCell;
use std::fmt;
use std::path::{Path, PathBuf};

/// A params file was malformed, inconsistent or incomplete.
///
/// `entry` is a dotted path inside the file (`node.U_Vibration.cpt[2]`), or `-` for the whole file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct SpecError {
    pub file: PathBuf,
    pub entry: String,
    pub reason: String,
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {}: {}",
            self.file.display(),
            self.entry,
            self.reason
        )
    }
}

impl SpecError {
    pub fn new(
        file: impl AsRef<Path>,
        entry: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            file: file.as_ref().to_path_buf(),
            entry: entry.into(),
            reason: reason.into(),
        }
    }
}

/// Read and parse one TOML file into `T`, mapping I/O and syntax errors to a [`SpecError`].
pub fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, SpecError> {
    let text = match overlay_text(path) {
        Some(t) => t?,
        None => {
            regular_file(path).map_err(|reason| SpecError::new(path, "-", reason))?;
            std::fs::read_to_string(path)
                .map_err(|e| SpecError::new(path, "-", format!("cannot read: {e}")))?
        }
    };
    if text.len() > MAX_FILE_BYTES {
        return Err(SpecError::new(
            path,
            "-",
            format!(
                "{} bytes: a params file is at most {MAX_FILE_BYTES} bytes",
                text.len()
            ),
        ));
    }
    let syntax = |e: toml::de::Error| {
        let entry = e
            .span()
            .map(|s| {
                // 1-based line of the span start (`lines().count()` is one short at a line start).
                let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}")
            })
            .unwrap_or_else(|| "-".into());
        SpecError::new(path, entry, e.message().to_string())
    };
    if text.trim().is_empty() {
        return Err(SpecError::new(path, "-", "the file is empty"));
    }
    let value: T = toml::from_str(&text).map_err(syntax)?;
    // Typed parsing succeeded, so the text is a valid TOML document: read it again untyped to
    // check every number once, whatever the loader does with it.
    let table: toml::Table = toml::from_str(&text).map_err(syntax)?;
    check_leaves(path, "", &toml::Value::Table(table))?;
    Ok(value)
}

/// Largest params file read (bytes). The shipped files are all under 20 KB.
pub const MAX_FILE_BYTES: usize = 1024 * 1024;
/// Largest magnitude of any number in a params file. The shipped files stay under 10^4; nothing
/// the companion models (metres, seconds, joules, hertz, tiles) needs more than 10^9, and a
/// bigger value is a typo or an attack that would overflow a duration or a cast downstream.
pub const MAX_NUMBER_MAGNITUDE: f64 = 1e9;
/// Most entries in any one array of a params file (the largest shipped array has under 100).
pub const MAX_ARRAY_LEN: usize = 10_000;

/// Every number finite and within [`MAX_NUMBER_MAGNITUDE`], every array within [`MAX_ARRAY_LEN`].
fn check_leaves(path: &Path, entry: &str, v: &toml::Value) -> Result<(), SpecError> {
    let name = |e: &str| {
        if e.is_empty() {
            "-".to_string()
        } else {
            e.to_string()
        }
    };
    match v {
        toml::Value::Float(x) => {
            if !x.is_finite() {
                return Err(SpecError::new(
                    path,
                    name(entry),
                    format!("{x} is not a finite number"),
                ));
            }
            if x.abs() > MAX_NUMBER_MAGNITUDE {
                return Err(SpecError::new(
                    path,
                    name(entry),
                    format!("{x} is out of range (magnitude at most {MAX_NUMBER_MAGNITUDE:e})"),
                ));
            }
        }
        toml::Value::Integer(i) => {
            if i.unsigned_abs() as f64 > MAX_NUMBER_MAGNITUDE {
                return Err(SpecError::new(
                    path,
                    name(entry),
                    format!("{i} is out of range (magnitude at most {MAX_NUMBER_MAGNITUDE:e})"),
                ));
            }
        }
        toml::Value::Array(a) => {
            if a.len() > MAX_ARRAY_LEN {
                return Err(SpecError::new(
                    path,
                    name(entry),
                    format!(
                        "{} entries: an array holds at most {MAX_ARRAY_LEN}",
                        a.len()
                    ),
                ));
            }
            for (i, x) in a.iter().enumerate() {
                check_leaves(path, &format!("{entry}[{i}]"), x)?;
            }
        }
        toml::Value::Table(t) => {
            for (k, x) in t {
                let e = if entry.is_empty() {
                    k.clone()
                } else {
                    format!("{entry}.{k}")
                };
                check_leaves(path, &e, x)?;
            }
        }
        toml::Value::String(_) | toml::Value::Boolean(_) | toml::Value::Datetime(_) => {}
    }
    Ok(())
}

/// `value` finite and in `min..=max`, else a [`SpecError`] naming `file` and `entry`; the
/// loaders call it for each number with a physical range (durations, altitudes, probabilities).
pub fn check_range(
    file: &Path,
    entry: impl Into<String>,
    value: f64,
    min: f64,
    max: f64,
    unit: &str,
) -> Result<f64, SpecError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(value)
    } else {
        Err(SpecError::new(
            file,
            entry,
            format!("{value} is out of range: must be in {min}..={max}{unit}"),
        ))
    }
}

/// As [`check_range`] with `min` excluded (a duration or period that must be positive).
pub fn check_positive(
    file: &Path,
    entry: impl Into<String>,
    value: f64,
    max: f64,
    unit: &str,
) -> Result<f64, SpecError> {
    if value.is_finite() && value > 0.0 && value <= max {
        Ok(value)
    } else {
        Err(SpecError::new(
            file,
            entry,
            format!("{value} is out of range: must be positive and at most {max}{unit}"),
        ))
    }
}

/// Ok when `path` is a regular file (following symlinks), else why not. Opening a FIFO or a
/// device where a file is expected would block or read forever.
pub fn regular_file(path: &Path) -> Result<(), String> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(m) if m.is_dir() => Err("is a directory, not a file".into()),
        Ok(_) => Err("is not a regular file (a FIFO, socket or device?)".into()),
        Err(e) => Err(format!("cannot read: {e}")),
    }
}

thread_local! {
    /// See [`with_overlay`]; `None` outside it.
    static OVERLAY: RefCell<Option<(PathBuf, Vec<u8>)>> = const { RefCell::new(None) };
}

/// Run `f` with the contents of the file at `path` replaced, for every [`read_toml`] on this
/// thread, by `bytes` (which need not be UTF-8: invalid text fails as an unreadable file does).
///
/// Why: the params fuzzer (companion::fuzzing, fuzz/) mutates one file per input and runs the
/// whole start-up load; an in-memory overlay spares a file write per input. `path` must be
/// spelled as the loaders join it (`params.join("health/system.toml")`). Loaders that only list
/// a directory still see the real files; the overlay changes contents, not names. Not reentrant:
/// the inner call's overlay wins until it returns.
pub fn with_overlay<R>(path: &Path, bytes: &[u8], f: impl FnOnce() -> R) -> R {
    /// Restores the previous overlay even when `f` unwinds.
    struct Restore(Option<(PathBuf, Vec<u8>)>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let prev = self.0.take();
            OVERLAY.with(|o| *o.borrow_mut() = prev);
        }
    }
    let prev = OVERLAY.with(|o| o.replace(Some((path.to_path_buf(), bytes.to_vec()))));
    let _restore = Restore(prev);
    f()
}

/// The overlay's text when `path` is the overlaid file.
fn overlay_text(path: &Path) -> Option<Result<String, SpecError>> {
    OVERLAY.with(|o| {
        let o = o.borrow();
        let (p, bytes) = o.as_ref()?;
        (p == path).then(|| {
            String::from_utf8(bytes.clone())
                .map_err(|e| SpecError::new(path, "-", format!("cannot read: {e}")))
        })
    })
}

/// The params directory: `$COMPANION_PARAMS`, else `params/` next to the workspace root this
/// binary was built from, else `./params`.
pub fn default_params_dir() -> PathBuf {
    if let Ok(p) = std::env::var("COMPANION_PARAMS") {
        return PathBuf::from(p);
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join("../params");
    if built.is_dir() {
        return built;
    }
    PathBuf::from("params")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, Debug, PartialEq)]
    struct T {
        x: i32,
    }

    #[test]
    fn overlay_replaces_one_file_and_is_removed_after_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.toml"), dir.path().join("b.toml"));
        std::fs::write(&a, "x = 1").unwrap();
        std::fs::write(&b, "x = 2").unwrap();
        with_overlay(&a, b"x = 7", || {
            assert_eq!(read_toml::<T>(&a).unwrap(), T { x: 7 });
            assert_eq!(
                read_toml::<T>(&b).unwrap(),
                T { x: 2 },
                "other files are real"
            );
            // Joined differently, same components: still the overlaid file.
            let again = dir.path().join(".").join("a.toml");
            assert_eq!(read_toml::<T>(&again).map(|t| t.x).ok(), Some(7));
        });
        let err = with_overlay(&a, b"\xff", || read_toml::<T>(&a).unwrap_err());
        assert_eq!((err.entry.as_str(), err.file.as_path()), ("-", a.as_path()));
        assert!(err.reason.starts_with("cannot read"), "{err}");
        let r = std::panic::catch_unwind(|| with_overlay(&a, b"x = 9", || panic!("inside")));
        assert!(r.is_err());
        assert_eq!(read_toml::<T>(&a).unwrap(), T { x: 1 }, "overlay gone");
    }
}
