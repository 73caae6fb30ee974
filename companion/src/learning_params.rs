//! params/learning.toml: the bound of in-flight CPT learning (`--learn-cpt`, `crate::learn_cpt`),
//! read with the rest of the params.

use companion_core::spec::{ParamsFiles, SpecError};

/// The learning settings file, relative to the params directory (optional: defaults apply).
pub const LEARNING_FILE: &str = "learning.toml";

/// The default bound: the most a row moves from its loaded value within one run.
pub const DEFAULT_MAX_CHANGE: f64 = 0.6;

/// params/learning.toml.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearningParams {
    /// The most a learned row may differ from the row as loaded (probability, in (0, 1]).
    pub max_change: f64,
}

impl Default for LearningParams {
    fn default() -> Self {
        LearningParams {
            max_change: DEFAULT_MAX_CHANGE,
        }
    }
}

impl LearningParams {
    /// Read `learning.toml` from the params (absent: the defaults); a malformed, unknown or
    /// out-of-range entry is refused naming the file and the entry.
    pub fn load(files: &ParamsFiles) -> Result<Self, SpecError> {
        let file = files.dir().join(LEARNING_FILE);
        if !files.contains(&file) {
            return Ok(Self::default());
        }
        let t: toml::Table = files.text(&file)?.parse().map_err(|e: toml::de::Error| {
            SpecError::new(&file, "-", format!("not TOML: {}", e.message()))
        })?;
        let mut p = Self::default();
        for (k, v) in &t {
            let toml::Value::Table(cpt) = v else {
                return Err(SpecError::new(&file, k, "unknown entry (known: [cpt])"));
            };
            if k != "cpt" {
                return Err(SpecError::new(&file, k, "unknown entry (known: [cpt])"));
            }
            for (ck, cv) in cpt {
                let entry = format!("cpt.{ck}");
                if ck != "max_change" {
                    return Err(SpecError::new(
                        &file,
                        &entry,
                        "unknown entry (known: max_change)",
                    ));
                }
                let x = cv
                    .as_float()
                    .or_else(|| cv.as_integer().map(|i| i as f64))
                    .ok_or_else(|| {
                        SpecError::new(&file, &entry, format!("{cv} is not a number"))
                    })?;
                if !(x > 0.0 && x <= 1.0) {
                    return Err(SpecError::new(
                        &file,
                        &entry,
                        format!("{x} is not a probability change in (0, 1]"),
                    ));
                }
                p.max_change = x;
            }
        }
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bound_is_refused_out_of_range_naming_the_entry() {
        let mut f = ParamsFiles::new("/p");
        f.insert("/p/learning.toml", "[cpt]\nmax_change = -0.1\n");
        let e = LearningParams::load(&f).unwrap_err().to_string();
        assert!(
            e.contains("learning.toml") && e.contains("cpt.max_change"),
            "{e}"
        );
        let mut f = ParamsFiles::new("/p");
        f.insert("/p/learning.toml", "[cpt]\nmax_change = 0.25\n");
        assert_eq!(LearningParams::load(&f).unwrap().max_change, 0.25);
        assert_eq!(
            LearningParams::load(&ParamsFiles::new("/p")).unwrap(),
            LearningParams::default()
        );
    }
}
