//! Reading a params directory from disk into a [`ParamsFiles`] (the core reads no files): the
//! file helpers `check`, `simulate`, `fly`, `replay` and the world share, kept apart from the
//! params set's checks (params.rs) so that the world can read a scenario file without depending
//! on them.

use companion_core::spec::{MAX_FILE_BYTES, ParamsFiles, SpecError};
use std::path::{Path, PathBuf};

/// Deepest directory level read below the params directory (the shipped tree is two deep).
const MAX_DEPTH: usize = 4;
/// Most files read from a params directory (the shipped tree has about 30).
const MAX_FILES: usize = 1000;

/// Read every `.toml` file below `dir` into a [`ParamsFiles`] for the core to compile. A file
/// that cannot be read (not a regular file, too large, not UTF-8) is kept with its reason and
/// fails the load only if a loader needs it; an unlistable `dir` fails here. `dir` may instead
/// be a params overlay file (`companion calibrate --out`, docs/calibrate.md): its base params
/// directory is read and the overlay layered on it.
pub fn read_params_dir(dir: &Path) -> Result<ParamsFiles, SpecError> {
    if crate::params_overlay::is_overlay(dir) {
        let (base, table) = crate::params_overlay::read_overlay(dir, default_params_dir())?;
        let mut files = read_dir_only(&base)?;
        crate::params_overlay::apply(&mut files, dir, &table)?;
        crate::params_overlay::check_power(&files, dir, &table)?;
        return Ok(files);
    }
    read_dir_only(dir)
}

/// [`read_params_dir`] of a directory (never an overlay: an overlay's base is a directory).
pub(crate) fn read_dir_only(dir: &Path) -> Result<ParamsFiles, SpecError> {
    let mut files = ParamsFiles::new(dir);
    let mut pending = vec![(dir.to_path_buf(), 0usize)];
    let mut n = 0usize;
    while let Some((d, depth)) = pending.pop() {
        let entries = std::fs::read_dir(&d)
            .map_err(|e| SpecError::new(&d, "-", format!("cannot list: {e}")))?;
        let mut paths: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        paths.sort();
        for p in paths {
            if p.is_dir() {
                // Vehicle profiles are overlays on this directory (`--vehicle`), not params files.
                if depth == 0 && p.file_name().is_some_and(|n| n == VEHICLES_DIR) {
                    continue;
                }
                if depth < MAX_DEPTH {
                    pending.push((p, depth + 1));
                }
            } else if p.extension().is_some_and(|x| x == "toml") {
                n += 1;
                if n > MAX_FILES {
                    return Err(SpecError::new(
                        dir,
                        "-",
                        format!("more than {MAX_FILES} params files"),
                    ));
                }
                add_file(&mut files, &p);
            }
        }
    }
    Ok(files)
}

/// Add the file at `path` to `files` as read now (or as unreadable, with the reason).
pub fn add_file(files: &mut ParamsFiles, path: &Path) {
    if let Err(reason) = regular_file(path) {
        files.insert_unreadable(path, reason);
        return;
    }
    match std::fs::metadata(path) {
        Ok(m) if m.len() > MAX_FILE_BYTES as u64 => files.insert_unreadable(
            path,
            format!(
                "{} bytes: a params file is at most {MAX_FILE_BYTES} bytes",
                m.len()
            ),
        ),
        _ => match std::fs::read(path) {
            Ok(bytes) => files.insert_bytes(path, &bytes),
            Err(e) => files.insert_unreadable(path, format!("cannot read: {e}")),
        },
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

/// The folder of vehicle profiles inside a params directory.
pub const VEHICLES_DIR: &str = "vehicles";

/// The overlay of the vehicle profile `name`: `<params>/vehicles/<name>.toml`, where `<params>`
/// is `params` (a directory) or the default params directory. An unknown name is refused with
/// the profiles there; `params` naming an overlay file is refused (a profile is an overlay).
pub fn vehicle_profile(params: Option<&Path>, name: &str) -> anyhow::Result<PathBuf> {
    let dir = match params {
        Some(p) if p.is_file() => anyhow::bail!(
            "--vehicle {name}: --params {} is an overlay file, and a vehicle profile is one too; give --params a directory",
            p.display()
        ),
        Some(p) => p.to_path_buf(),
        None => default_params_dir(),
    };
    let ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    let path = dir.join(VEHICLES_DIR).join(format!("{name}.toml"));
    if ok && path.is_file() {
        return Ok(path);
    }
    let mut known: Vec<String> = std::fs::read_dir(dir.join(VEHICLES_DIR))
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok()?.path().file_stem()?.to_str().map(String::from))
        .collect();
    known.sort();
    anyhow::bail!(
        "--vehicle {name}: no profile {} (profiles: {})",
        path.display(),
        if known.is_empty() {
            "none".into()
        } else {
            known.join(", ")
        }
    )
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
