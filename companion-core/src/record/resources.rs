//! What the resource arbitration degraded or dropped (`ResourcesRecord.degraded`, `.dropped`), as
//! types with their fields, written to the decision log (schema 2) as objects with those fields.
//! `Display` gives the sentence for people (`tracking V3 -> V1: insufficient resources ...`,
//! `tracking V3: ...`); schema-1 logs wrote it, and `companion::decision_log::migration` reads
//! it back into the fields.

use serde::{Deserialize, Serialize};
use std::fmt;

/// A requested variant placed in a lower version.
#[derive(Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Degraded {
    /// The application (`tracking`); empty for a sentence kept whole in `reason`.
    pub app: String,
    /// The version requested.
    pub from: String,
    /// The version placed instead.
    pub to: String,
    /// Why the requested version did not fit.
    pub reason: String,
}

/// A requested application left out of the schedule.
#[derive(Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct Dropped {
    /// The application; empty for a sentence kept whole in `reason`.
    pub app: String,
    /// The version requested, or the last one tried along its degradation path.
    pub version: String,
    /// Why nothing of it fits.
    pub reason: String,
}

impl fmt::Display for Degraded {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.app.is_empty() {
            return f.write_str(&self.reason);
        }
        write!(
            f,
            "{} {} -> {}: {}",
            self.app, self.from, self.to, self.reason
        )
    }
}

impl fmt::Display for Dropped {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.app.is_empty() {
            return f.write_str(&self.reason);
        }
        write!(f, "{} {}: {}", self.app, self.version, self.reason)
    }
}

// Field-wise `clone_from`, so a record reused cycle after cycle keeps the strings' capacity.
impl Clone for Degraded {
    fn clone(&self) -> Self {
        Degraded {
            app: self.app.clone(),
            from: self.from.clone(),
            to: self.to.clone(),
            reason: self.reason.clone(),
        }
    }
    fn clone_from(&mut self, src: &Self) {
        self.app.clone_from(&src.app);
        self.from.clone_from(&src.from);
        self.to.clone_from(&src.to);
        self.reason.clone_from(&src.reason);
    }
}

impl Clone for Dropped {
    fn clone(&self) -> Self {
        Dropped {
            app: self.app.clone(),
            version: self.version.clone(),
            reason: self.reason.clone(),
        }
    }
    fn clone_from(&mut self, src: &Self) {
        self.app.clone_from(&src.app);
        self.version.clone_from(&src.version);
        self.reason.clone_from(&src.reason);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_as_their_fields_and_said_as_the_sentence() {
        let d = Degraded {
            app: "tracking".into(),
            from: "V3".into(),
            to: "V1".into(),
            reason: "insufficient resources (cpu 1.12 > 1.00)".into(),
        };
        assert_eq!(
            d.to_string(),
            "tracking V3 -> V1: insufficient resources (cpu 1.12 > 1.00)"
        );
        let json = serde_json::to_string(&d).unwrap();
        assert_eq!(
            json,
            r#"{"app":"tracking","from":"V3","to":"V1","reason":"insufficient resources (cpu 1.12 > 1.00)"}"#
        );
        assert_eq!(serde_json::from_str::<Degraded>(&json).unwrap(), d);
        let x = Dropped {
            app: "tracking".into(),
            version: "V3".into(),
            reason: "no room".into(),
        };
        assert_eq!(x.to_string(), "tracking V3: no room");
        let json = serde_json::to_string(&x).unwrap();
        assert_eq!(serde_json::from_str::<Dropped>(&json).unwrap(), x);
    }
}
