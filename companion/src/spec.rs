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
        None => std::fs::read_to_string(path)
            .map_err(|e| SpecError::new(path, "-", format!("cannot read: {e}")))?,
    };
    toml::from_str(&text).map_err(|e| {
        let entry = e
            .span()
            .map(|s| {
                // 1-based line of the span start (`lines().count()` is one short at a line start).
                let line = text[..s.start.min(text.len())].matches('\n').count() + 1;
                format!("line {line}")
            })
            .unwrap_or_else(|| "-".into());
        SpecError::new(path, entry, e.message().to_string())
    })
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
