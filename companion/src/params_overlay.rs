//! The params overlay `companion calibrate` writes and `check`, `simulate` and `fly` read with
//! `--params FILE` (docs/calibrate.md): a TOML file whose top-level tables are params files
//! (by path relative to the params directory) holding the entries that replace the shipped ones.
//!
//! ```toml
//! [calibration]                      # not a params file: what made the overlay, and sources
//! params = "../params"               # base params directory (relative to this file); optional
//! ["missions/tracking.toml".base]
//! power_w = 9.4
//! ["missions/tracking.toml".activities.tracking_area]   # array element by its `name`
//! hold_s = 612.0
//! ```
//!
//! Tables merge key by key, except that a table whose `model` differs from the shipped one's
//! replaces it whole (`[propulsion]` from rotary_wing to polynomial); an array of tables (the mission's `activities`) is addressed by its
//! elements' `name`; any other value replaces the shipped one. An entry naming a file the params
//! set does not hold, an array element that does not exist, a table where a value is (or the
//! reverse), or a number that is not finite stops the load with the overlay's file, the entry
//! and the reason. What the merged file then means is checked by its own loader, as any params
//! file (unknown keys, ranges).

use companion_core::spec::{MAX_FILE_BYTES, ParamsFiles, SpecError};
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The overlay's own table (not a params file).
pub const CALIBRATION_TABLE: &str = "calibration";

/// Whether `path` is an overlay file rather than a params directory (`--params` takes either).
pub fn is_overlay(path: &Path) -> bool {
    path.is_file()
}

/// The overlay at `overlay`, parsed, and its base params directory (its `calibration.params`,
/// relative to the overlay's folder, else `default_dir`); the caller reads the base and layers
/// the overlay on it with [`apply`] (`params_files::read_params_dir`).
pub fn read_overlay(overlay: &Path, default_dir: PathBuf) -> Result<(PathBuf, Table), SpecError> {
    let table = read_overlay_table(overlay)?;
    let base = match table.get(CALIBRATION_TABLE).and_then(|c| c.get("params")) {
        None => default_dir,
        Some(Value::String(p)) => overlay.parent().unwrap_or(Path::new(".")).join(p),
        Some(_) => {
            return Err(SpecError::new(
                overlay,
                "calibration.params",
                "must be a string: the params directory (relative to the overlay's folder)",
            ));
        }
    };
    Ok((base, table))
}

/// Parse the overlay file (a regular file, at most [`MAX_FILE_BYTES`], TOML).
pub fn read_overlay_table(overlay: &Path) -> Result<Table, SpecError> {
    match std::fs::metadata(overlay) {
        Ok(m) if m.is_file() => {}
        Ok(_) => return Err(SpecError::new(overlay, "-", "is not a regular file")),
        Err(e) => return Err(SpecError::new(overlay, "-", format!("cannot read: {e}"))),
    }
    let len = std::fs::metadata(overlay).map(|m| m.len()).unwrap_or(0);
    if len > MAX_FILE_BYTES as u64 {
        return Err(SpecError::new(
            overlay,
            "-",
            format!("{len} bytes: an overlay is at most {MAX_FILE_BYTES} bytes"),
        ));
    }
    let text = std::fs::read_to_string(overlay)
        .map_err(|e| SpecError::new(overlay, "-", format!("cannot read: {e}")))?;
    text.parse::<Table>()
        .map_err(|e| SpecError::new(overlay, "-", format!("not TOML: {e}")))
}

/// Layer `overlay` (read from the file `overlay_file`) onto `files`.
pub fn apply(
    files: &mut ParamsFiles,
    overlay_file: &Path,
    overlay: &Table,
) -> Result<(), SpecError> {
    let dir = files.dir().to_path_buf();
    for (name, entries) in overlay {
        if name == CALIBRATION_TABLE {
            continue;
        }
        let err = |entry: &str, reason: String| SpecError::new(overlay_file, entry, reason);
        let Value::Table(entries) = entries else {
            return Err(err(
                name,
                "must be a table of the params file's entries".into(),
            ));
        };
        let path = dir.join(name);
        let text = files.text(&path).map_err(|e| {
            err(
                name,
                format!("not a params file of {}: {}", dir.display(), e.reason),
            )
        })?;
        let mut target: Table = text
            .parse()
            .map_err(|e| err(name, format!("the params file is not TOML: {e}")))?;
        merge_table(&mut target, entries, name, &|e, r| err(e, r))?;
        let merged = toml::to_string(&target)
            .map_err(|e| err(name, format!("cannot write the merged file: {e}")))?;
        files.insert(&path, merged);
    }
    Ok(())
}

/// The missions `overlay` changed, checked against their `[power_bounds]` (and, without any, for
/// a power above zero at every speed flown): an overlay's curve no airframe flies (zero power
/// everywhere, a hover of 1e9 W) is refused naming the overlay, the entry and the reason.
pub fn check_power(
    files: &ParamsFiles,
    overlay_file: &Path,
    overlay: &Table,
) -> Result<(), SpecError> {
    for name in overlay.keys().filter(|n| *n != CALIBRATION_TABLE) {
        let path = files.dir().join(name);
        let Ok(text) = files.text(&path) else {
            continue;
        };
        if let Some(u) = companion_core::guarantee::power_bounds::check_mission_text(&path, text) {
            return Err(SpecError::new(
                overlay_file,
                format!("{name}.{}", u.entry),
                u.reason,
            ));
        }
    }
    Ok(())
}

type ErrFn<'a> = dyn Fn(&str, String) -> SpecError + 'a;

fn merge_table(dst: &mut Table, src: &Table, at: &str, err: &ErrFn) -> Result<(), SpecError> {
    for (k, v) in src {
        let entry = format!("{at}.{k}");
        check_finite(v, &entry, err)?;
        match (dst.get_mut(k), v) {
            // A different `model` is a different table (the mission's `[propulsion]`): whole.
            (Some(Value::Table(d)), Value::Table(s))
                if s.get("model").is_some_and(|m| Some(m) != d.get("model")) =>
            {
                *d = s.clone();
            }
            (Some(Value::Table(d)), Value::Table(s)) => merge_table(d, s, &entry, err)?,
            (Some(Value::Array(d)), Value::Table(s)) if is_named_array(d) => {
                merge_named(d, s, &entry, err)?;
            }
            (Some(Value::Table(_)), _) => {
                return Err(err(
                    &entry,
                    "the params file has a table here, the overlay a value".into(),
                ));
            }
            (Some(d), Value::Table(_)) if !matches!(d, Value::Table(_)) => {
                return Err(err(
                    &entry,
                    "the params file has a value here, the overlay a table".into(),
                ));
            }
            (Some(d), v) if !same_kind(d, v) => {
                return Err(err(
                    &entry,
                    format!(
                        "the params file has {} here, the overlay {}",
                        kind(d),
                        kind(v)
                    ),
                ));
            }
            _ => {
                dst.insert(k.clone(), v.clone());
            }
        }
    }
    Ok(())
}

/// Numbers are numbers (an integer where a float was is fine); otherwise the same TOML type.
fn same_kind(a: &Value, b: &Value) -> bool {
    let num = |v: &Value| matches!(v, Value::Integer(_) | Value::Float(_));
    (num(a) && num(b)) || std::mem::discriminant(a) == std::mem::discriminant(b)
}

fn kind(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "a string",
        Value::Integer(_) | Value::Float(_) => "a number",
        Value::Boolean(_) => "a boolean",
        Value::Datetime(_) => "a date",
        Value::Array(_) => "an array",
        Value::Table(_) => "a table",
    }
}

/// An array of tables each with a string `name` (the mission's `activities`).
fn is_named_array(a: &[Value]) -> bool {
    !a.is_empty()
        && a.iter().all(|e| {
            e.as_table()
                .is_some_and(|t| t.get("name").is_some_and(Value::is_str))
        })
}

fn merge_named(dst: &mut [Value], src: &Table, at: &str, err: &ErrFn) -> Result<(), SpecError> {
    for (name, v) in src {
        let entry = format!("{at}.{name}");
        let Some(Value::Table(d)) = dst
            .iter_mut()
            .find(|e| e.get("name").and_then(Value::as_str) == Some(name.as_str()))
        else {
            return Err(err(
                &entry,
                format!("no element named `{name}` in the params file"),
            ));
        };
        let Value::Table(s) = v else {
            return Err(err(
                &entry,
                "must be a table of the element's entries".into(),
            ));
        };
        merge_table(d, s, &entry, err)?;
    }
    Ok(())
}

fn check_finite(v: &Value, entry: &str, err: &ErrFn) -> Result<(), SpecError> {
    match v {
        Value::Float(x) if !x.is_finite() => Err(err(entry, format!("{x} is not a finite number"))),
        Value::Array(a) => a.iter().try_for_each(|x| check_finite(x, entry, err)),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files() -> ParamsFiles {
        let mut f = ParamsFiles::new("/p");
        f.insert(
            "/p/m.toml",
            "[base]\npower_w = 8.0\nsource = \"A\"\n[[activities]]\nname = \"a\"\nhold_s = 1.0\n[[activities]]\nname = \"b\"\nhold_s = 2.0\n",
        );
        f
    }

    fn apply_text(f: &mut ParamsFiles, text: &str) -> Result<(), SpecError> {
        apply(f, Path::new("/o.toml"), &text.parse().unwrap())
    }

    #[test]
    fn merges_tables_and_named_array_elements() {
        let mut f = files();
        apply_text(
            &mut f,
            "[calibration]\nruns = 1\n[\"m.toml\".base]\npower_w = 9.5\n[\"m.toml\".activities.b]\nhold_s = 7.0\n",
        )
        .unwrap();
        let t: Table = f.text(Path::new("/p/m.toml")).unwrap().parse().unwrap();
        assert_eq!(t["base"]["power_w"].as_float(), Some(9.5));
        assert_eq!(t["base"]["source"].as_str(), Some("A"));
        assert_eq!(t["activities"][0]["hold_s"].as_float(), Some(1.0));
        assert_eq!(t["activities"][1]["hold_s"].as_float(), Some(7.0));
    }

    #[test]
    fn a_table_of_another_model_replaces_the_shipped_one_whole() {
        let mut f = ParamsFiles::new("/p");
        f.insert(
            "/p/m.toml",
            "[propulsion]\nmodel = \"rotary_wing\"\ntip_speed_mps = 80.0\n",
        );
        apply_text(
            &mut f,
            "[\"m.toml\".propulsion]\nmodel = \"polynomial\"\ncoefficients_w = [1.0, 0.0]\n",
        )
        .unwrap();
        let t: Table = f.text(Path::new("/p/m.toml")).unwrap().parse().unwrap();
        assert_eq!(t["propulsion"]["model"].as_str(), Some("polynomial"));
        assert!(t["propulsion"].get("tip_speed_mps").is_none(), "{t}");
    }

    #[test]
    fn malformed_overlays_name_entry_and_reason() {
        let cases = [
            (
                "[\"x.toml\".base]\npower_w = 1.0\n",
                "x.toml",
                "not a params file",
            ),
            (
                "[\"m.toml\".activities.c]\nhold_s = 1.0\n",
                "m.toml.activities.c",
                "no element named",
            ),
            ("[\"m.toml\"]\nbase = 3.0\n", "m.toml.base", "a table here"),
            (
                "[\"m.toml\".base]\npower_w = nan\n",
                "m.toml.base.power_w",
                "not a finite",
            ),
            (
                "[\"m.toml\".base.power_w]\nx = 1\n",
                "m.toml.base.power_w",
                "a value here",
            ),
            (
                "[\"m.toml\".base]\npower_w = \"9\"\n",
                "m.toml.base.power_w",
                "a number here, the overlay a string",
            ),
        ];
        for (text, entry, reason) in cases {
            let e = apply_text(&mut files(), text).unwrap_err();
            assert_eq!(e.file, Path::new("/o.toml"), "{text}");
            assert_eq!(e.entry, entry, "{text}");
            assert!(e.reason.contains(reason), "{text}: {}", e.reason);
        }
    }
}
