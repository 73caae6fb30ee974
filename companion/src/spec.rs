//! Loading `params/`: the one error type every loader returns, naming the file, the entry and the reason.

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
    let text = std::fs::read_to_string(path)
        .map_err(|e| SpecError::new(path, "-", format!("cannot read: {e}")))?;
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
