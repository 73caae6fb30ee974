//! The params as data: [`ParamsFiles`] (every file's text, handed over by the shell), TOML
//! parsing with the limits every params file obeys, and the one error type every loader
//! returns, naming the file, the entry and the reason.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// A params file was malformed, inconsistent or incomplete.
///
/// `entry` is a dotted path inside the file (`node.U_Vibration.cpt[2]`), or `-` for the whole file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct SpecError {
    /// File the error is in.
    pub file: PathBuf,
    /// Dotted path of the entry inside the file, or `-` for the whole file.
    pub entry: String,
    /// What is wrong with it.
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
    /// An error in `file` at `entry`, saying `reason`.
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

/// The params files as data: each file's text by its path, read by the shell (the
/// `companion` binary from a directory, `replay` from a log header, the fuzzer from memory).
/// The core never opens a file; a loader asks for `dir().join("health/system.toml")` here.
///
/// A file the shell could not read is kept with its reason, so the error appears only if a
/// loader needs that file, and names it the way a read failure would.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParamsFiles {
    dir: PathBuf,
    files: BTreeMap<PathBuf, Result<String, String>>,
}

impl ParamsFiles {
    /// An empty set for the params directory `dir` (a name for joins and messages only).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            files: BTreeMap::new(),
        }
    }

    /// The params directory the loaders join their file names to.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Add or replace the file at `path` (as the loaders join it: `dir().join(name)`, or any
    /// other path a mission or route names).
    pub fn insert(&mut self, path: impl AsRef<Path>, text: impl Into<String>) {
        self.files
            .insert(path.as_ref().to_path_buf(), Ok(text.into()));
    }

    /// Add or replace the file at `path` from raw bytes: text must be UTF-8, else the file
    /// reads as unreadable.
    pub fn insert_bytes(&mut self, path: impl Into<PathBuf>, bytes: &[u8]) {
        let v = match std::str::from_utf8(bytes) {
            Ok(t) => Ok(t.to_string()),
            Err(e) => Err(format!("cannot read: {e}")),
        };
        self.files.insert(path.into(), v);
    }

    /// Record that the file at `path` exists but could not be read, and why (`cannot read: ...`,
    /// `is not a regular file ...`); a loader that needs it fails with this reason.
    pub fn insert_unreadable(&mut self, path: impl Into<PathBuf>, reason: impl Into<String>) {
        self.files.insert(path.into(), Err(reason.into()));
    }

    /// Whether a file (readable or not) is at `path`.
    pub fn contains(&self, path: &Path) -> bool {
        self.files.contains_key(path)
    }

    /// The text of the file at `path`, or the error a loader reports for it.
    pub fn text(&self, path: &Path) -> Result<&str, SpecError> {
        match self.files.get(path) {
            Some(Ok(t)) => Ok(t),
            Some(Err(reason)) => Err(SpecError::new(path, "-", reason.clone())),
            None => Err(SpecError::new(
                path,
                "-",
                "cannot read: no such file in the params set",
            )),
        }
    }

    /// The files directly inside `dir` whose name ends in `.{ext}`, sorted.
    pub fn files_in(&self, dir: &Path, ext: &str) -> Vec<PathBuf> {
        self.files
            .keys()
            .filter(|p| p.parent() == Some(dir) && p.extension().is_some_and(|x| x == ext))
            .cloned()
            .collect()
    }

    /// Every file: path and text (or why it is unreadable).
    pub fn iter(&self) -> impl Iterator<Item = (&Path, Result<&str, &str>)> {
        self.files
            .iter()
            .map(|(p, v)| (p.as_path(), v.as_deref().map_err(String::as_str)))
    }
}

/// Parse the params file at `path` from `params` into `T` (see [`parse_toml`]).
pub fn read_toml<T: serde::de::DeserializeOwned>(
    params: &ParamsFiles,
    path: &Path,
) -> Result<T, SpecError> {
    parse_toml(path, params.text(path)?)
}

/// Parse one params file's text into `T`, mapping syntax errors to a [`SpecError`] with the
/// line, and checking the limits every params file obeys (size, finite numbers, magnitudes,
/// array lengths).
pub fn parse_toml<T: serde::de::DeserializeOwned>(path: &Path, text: &str) -> Result<T, SpecError> {
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
    let value: T = toml::from_str(text).map_err(syntax)?;
    // Typed parsing succeeded, so the text is a valid TOML document: read it again untyped to
    // check every number once, whatever the loader does with it.
    let table: toml::Table = toml::from_str(text).map_err(syntax)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(serde::Deserialize, Debug, PartialEq)]
    struct T {
        x: i32,
    }

    #[test]
    fn files_are_found_by_path_however_joined_and_unreadable_ones_fail_when_read() {
        let mut p = ParamsFiles::new("params");
        p.insert("params/a.toml", "x = 1");
        p.insert("params/sub/b.toml", "x = 2");
        p.insert_bytes("params/c.toml", b"\xff");
        p.insert_unreadable(
            "params/d.toml",
            "is not a regular file (a FIFO, socket or device?)",
        );
        let again = p.dir().join(".").join("a.toml");
        assert_eq!(read_toml::<T>(&p, &again).unwrap(), T { x: 1 });
        assert_eq!(
            read_toml::<T>(&p, Path::new("params/sub/b.toml"))
                .unwrap()
                .x,
            2
        );
        let err = read_toml::<T>(&p, Path::new("params/c.toml")).unwrap_err();
        assert_eq!(
            (err.entry.as_str(), err.file.as_path()),
            ("-", Path::new("params/c.toml"))
        );
        assert!(err.reason.starts_with("cannot read"), "{err}");
        let err = read_toml::<T>(&p, Path::new("params/d.toml")).unwrap_err();
        assert!(err.reason.contains("not a regular file"), "{err}");
        let err = read_toml::<T>(&p, Path::new("params/none.toml")).unwrap_err();
        assert!(err.reason.starts_with("cannot read"), "{err}");
        assert_eq!(
            p.files_in(Path::new("params"), "toml"),
            vec![
                PathBuf::from("params/a.toml"),
                PathBuf::from("params/c.toml"),
                PathBuf::from("params/d.toml")
            ],
            "direct children only, sorted"
        );
    }

    #[test]
    fn syntax_errors_name_the_line() {
        let err = parse_toml::<T>(Path::new("f.toml"), "\n\nx = = 1").unwrap_err();
        assert_eq!(err.entry, "line 3");
    }
}
