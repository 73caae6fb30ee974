//! What the resource arbitration degraded or dropped (`ResourcesRecord.degraded`, `.dropped`), as
//! types with their fields. Each is written to the decision log as the sentence it has always
//! been (`tracking V3 -> V1: insufficient resources ...`, `tracking V3: ...`) and read back from
//! it; a sentence that does not split into the fields (free text, a newer log's wording) is kept
//! whole in `reason`, so reading never fails and writing it again gives the same bytes.

use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::fmt;

/// A requested variant placed in a lower version.
#[derive(Debug, Default, PartialEq, Eq)]
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
#[derive(Debug, Default, PartialEq, Eq)]
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

/// `APP VERSION` split at its one space; None unless both are single words.
fn app_and_version(s: &str) -> Option<(&str, &str)> {
    let (app, version) = s.split_once(' ')?;
    let word = |w: &str| !w.is_empty() && !w.contains(char::is_whitespace);
    (word(app) && word(version)).then_some((app, version))
}

impl From<&str> for Degraded {
    fn from(s: &str) -> Self {
        let parsed = s.split_once(": ").and_then(|(head, reason)| {
            let (app_from, to) = head.split_once(" -> ")?;
            let (app, from) = app_and_version(app_from)?;
            Some(Degraded {
                app: app.into(),
                from: from.into(),
                to: to.into(),
                reason: reason.into(),
            })
        });
        match parsed {
            Some(d) if d.to_string() == s => d,
            _ => Degraded {
                reason: s.into(),
                ..Default::default()
            },
        }
    }
}

impl From<&str> for Dropped {
    fn from(s: &str) -> Self {
        let parsed = s.split_once(": ").and_then(|(head, reason)| {
            let (app, version) = app_and_version(head)?;
            Some(Dropped {
                app: app.into(),
                version: version.into(),
                reason: reason.into(),
            })
        });
        match parsed {
            Some(d) if d.to_string() == s => d,
            _ => Dropped {
                reason: s.into(),
                ..Default::default()
            },
        }
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

macro_rules! sentence_serde {
    ($t:ty) => {
        impl Serialize for $t {
            fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                serializer.collect_str(self)
            }
        }
        impl<'de> Deserialize<'de> for $t {
            fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                let s = <std::borrow::Cow<'de, str>>::deserialize(deserializer)?;
                Ok(Self::from(s.as_ref()))
            }
        }
    };
}

sentence_serde!(Degraded);
sentence_serde!(Dropped);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_logged_sentences_read_as_their_fields() {
        let d = Degraded::from("tracking V3 -> V1: insufficient resources (cpu 1.12 > 1.00)");
        assert_eq!(
            (d.app.as_str(), d.from.as_str(), d.to.as_str()),
            ("tracking", "V3", "V1")
        );
        assert_eq!(d.reason, "insufficient resources (cpu 1.12 > 1.00)");
        let x = Dropped::from(
            "tracking V3: insufficient resources: policy safety ranks tracking 5 of 5",
        );
        assert_eq!((x.app.as_str(), x.version.as_str()), ("tracking", "V3"));
        assert_eq!(
            x.reason,
            "insufficient resources: policy safety ranks tracking 5 of 5"
        );
    }

    #[test]
    fn any_sentence_writes_back_unchanged() {
        for s in [
            "tracking V3 -> V1: insufficient resources (cpu 1.12 > 1.00)",
            "tracking V3: no room",
            "free text",
            "",
            "a b c -> d: e",
            "a  b: two spaces",
            "x -> y: no version",
        ] {
            let (d, x) = (Degraded::from(s), Dropped::from(s));
            assert_eq!(d.to_string(), s);
            assert_eq!(x.to_string(), s);
            let json = serde_json::to_string(&d).unwrap();
            assert_eq!(json, serde_json::to_string(s).unwrap());
            assert_eq!(serde_json::from_str::<Degraded>(&json).unwrap(), d);
            assert_eq!(serde_json::from_str::<Dropped>(&json).unwrap(), x);
        }
        assert!(Degraded::from("free text").app.is_empty());
    }
}
