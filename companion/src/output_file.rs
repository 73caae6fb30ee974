//! An output file of a command that writes (`calibrate --out`, `export --out`, `review --out`,
//! `signing-setup --key`): never one of the command's inputs, never a FIFO, device or other
//! non-regular file, never half written.
//!
//! - An output that is an input is refused by file identity (device and inode), so symlinks and
//!   hard links to an input are seen through;
//! - an existing output that is not a regular file (a FIFO would block for ever without a
//!   reader, a device would take the bytes) is refused; only metadata is read, nothing opened;
//! - a file name with control characters is refused (a name is data: it reaches TOML and
//!   terminals only escaped, and one holding a newline or an escape sequence is a mistake or
//!   an attack);
//! - the bytes go to a temporary file in the same folder (`tempfile`), renamed over the output
//!   only when whole: a symlink at the output is replaced, its target left alone.

use crate::text::escape_controls;
use std::path::{Path, PathBuf};

/// An output refused before anything was written: the name (escaped) and why.
#[derive(Debug, thiserror::Error)]
#[error("{shown}: {reason}")]
pub struct Refused {
    pub path: PathBuf,
    /// The path as a terminal may show it.
    pub shown: String,
    pub reason: String,
}

/// `p` as a terminal may show it (control characters escaped).
pub fn shown(p: &Path) -> String {
    escape_controls(&p.display().to_string(), false)
}

#[cfg(unix)]
fn file_id(m: &std::fs::Metadata) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    Some((m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(_: &std::fs::Metadata) -> Option<(u64, u64)> {
    None
}

/// Whether `b` is the file `a` (with `a`'s metadata): device and inode, canonical paths where
/// there are none, whatever names, symlinks or hard links lead to either.
pub fn same_file(a: &Path, a_meta: &std::fs::Metadata, b: &Path) -> bool {
    let Ok(b_meta) = std::fs::metadata(b) else {
        return false;
    };
    match (file_id(a_meta), file_id(&b_meta)) {
        (Some(x), Some(y)) => x == y,
        _ => match (a.canonicalize(), b.canonicalize()) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        },
    }
}

/// Refuse `out` when its file name holds control characters, when it exists and is not a
/// regular file, or when it is one of `inputs`. The metadata of an existing `out` is returned
/// for further checks of the caller's.
pub fn check(
    out: &Path,
    inputs: &[PathBuf],
    command: &str,
) -> Result<Option<std::fs::Metadata>, Refused> {
    let refuse = |reason: String| Refused {
        path: out.to_path_buf(),
        shown: shown(out),
        reason,
    };
    let name = out.file_name().map(|n| n.to_string_lossy().into_owned());
    let Some(name) = name else {
        return Err(refuse("names no file".into()));
    };
    if name.chars().any(|c| c.is_control()) {
        return Err(refuse(
            "the file name holds control characters (newline, escape, ...): refused, a name is \
             written only as data"
                .into(),
        ));
    }
    let meta = match std::fs::metadata(out) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(refuse(format!("cannot inspect it: {e}"))),
    };
    if !meta.is_file() {
        let what = if meta.is_dir() {
            "a directory"
        } else {
            "not a regular file (a FIFO, device or socket)"
        };
        return Err(refuse(format!(
            "{what}: output is written to a regular file"
        )));
    }
    if let Some(f) = inputs.iter().find(|f| same_file(out, &meta, f)) {
        return Err(refuse(format!(
            "is {} itself (the same file: name, symlink or hard link), an input of this {command}: \
             refusing to overwrite it",
            shown(f)
        )));
    }
    Ok(Some(meta))
}

/// A temporary file beside `out` (same folder, so the final rename is atomic).
pub fn temp_beside(out: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = match out.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    tempfile::Builder::new()
        .prefix(".companion-")
        .suffix(".tmp")
        .tempfile_in(dir)
}

/// Rename the finished temporary file over `out`, with the permissions `mode` (unix).
pub fn persist(tmp: tempfile::NamedTempFile, out: &Path, mode: u32) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file()
            .set_permissions(std::fs::Permissions::from_mode(mode))?;
    }
    #[cfg(not(unix))]
    let _ = mode;
    tmp.as_file().sync_all()?;
    tmp.persist(out).map_err(|e| e.error)?;
    Ok(())
}

/// [`check`] `out` against the inputs of `command`, then write `bytes` to it through a
/// temporary file beside it, with permissions `mode`.
pub fn write(
    out: &Path,
    inputs: &[PathBuf],
    command: &str,
    bytes: &[u8],
    mode: u32,
) -> anyhow::Result<()> {
    check(out, inputs, command)?;
    let written = (|| {
        let mut tmp = temp_beside(out)?;
        std::io::Write::write_all(&mut tmp, bytes)?;
        persist(tmp, out, mode)
    })();
    written.map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", shown(out)))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn inputs_links_fifos_and_control_names_are_refused_and_left_alone() {
        let d = tempfile::tempdir().unwrap();
        let input = d.path().join("in.txt");
        std::fs::write(&input, "input").unwrap();
        let inputs = vec![input.clone()];
        let sym = d.path().join("sym");
        std::os::unix::fs::symlink(&input, &sym).unwrap();
        let hard = d.path().join("hard");
        std::fs::hard_link(&input, &hard).unwrap();
        for out in [&input, &sym, &hard] {
            let e = write(out, &inputs, "test", b"x", 0o644).unwrap_err();
            assert!(e.to_string().contains("an input of this test"), "{e}");
        }
        let e = write(&d.path().join("a\nb"), &inputs, "test", b"x", 0o644).unwrap_err();
        assert!(e.to_string().contains("control characters"), "{e}");
        assert!(!e.to_string().contains('\n'), "{e}");
        let e = write(d.path(), &inputs, "test", b"x", 0o644).unwrap_err();
        assert!(e.to_string().contains("a directory"), "{e}");
        assert_eq!(std::fs::read(&input).unwrap(), b"input");
        // A symlink to another file is replaced, its target kept.
        let other = d.path().join("other");
        std::fs::write(&other, "other").unwrap();
        let link = d.path().join("link");
        std::os::unix::fs::symlink(&other, &link).unwrap();
        write(&link, &inputs, "test", b"new", 0o644).unwrap();
        assert_eq!(std::fs::read(&link).unwrap(), b"new");
        assert_eq!(std::fs::read(&other).unwrap(), b"other");
        assert!(!std::fs::symlink_metadata(&link).unwrap().is_symlink());
    }
}
