//! What a companion (re)started next to an armed vehicle in the air does (params/link.toml
//! `[flight] restart_in_air`, docs/mavlink.md "Started in flight").

/// `[flight] restart_in_air`: `handoff` (the default) or `resume_with_consent`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RestartInAir {
    /// Say a flight is in progress and hand the vehicle to the autopilot at once.
    #[default]
    Handoff,
    /// When the companion's own run log proves the flight is its own and the plan still holds,
    /// offer the operator to resume it (a MISSION_START within the consent window); otherwise,
    /// or without consent, hand off.
    ResumeWithConsent,
}

impl RestartInAir {
    /// The value as params/link.toml spells it.
    pub fn name(self) -> &'static str {
        match self {
            RestartInAir::Handoff => "handoff",
            RestartInAir::ResumeWithConsent => "resume_with_consent",
        }
    }
}

/// Read by hand so that a wrong value names the key (the loader adds the file and line).
impl<'de> serde::Deserialize<'de> for RestartInAir {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Words;
        impl serde::de::Visitor<'_> for Words {
            type Value = RestartInAir;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("flight.restart_in_air: \"handoff\" or \"resume_with_consent\"")
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<RestartInAir, E> {
                match v {
                    "handoff" => Ok(RestartInAir::Handoff),
                    "resume_with_consent" => Ok(RestartInAir::ResumeWithConsent),
                    other => Err(E::custom(format!(
                        "flight.restart_in_air: {other:?} is neither \"handoff\" nor \"resume_with_consent\""
                    ))),
                }
            }
        }
        d.deserialize_str(Words)
    }
}

#[cfg(test)]
mod tests {
    use crate::actions::LinkParams;
    use companion_core::spec::ParamsFiles;
    use std::path::Path;

    fn load(value: &str) -> Result<super::RestartInAir, String> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../params");
        let path = dir.join("link.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let text = text.replace(
            "restart_in_air = \"handoff\"",
            &format!("restart_in_air = {value}"),
        );
        let mut files = ParamsFiles::default();
        files.insert(path.clone(), text);
        LinkParams::load(&files, &path)
            .map(|l| l.flight.restart_in_air)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn restart_in_air_is_read_and_a_bad_value_names_file_entry_and_reason() {
        assert_eq!(
            load("\"resume_with_consent\"").unwrap(),
            super::RestartInAir::ResumeWithConsent
        );
        assert_eq!(load("\"handoff\"").unwrap(), super::RestartInAir::Handoff);
        for bad in ["\"resume\"", "3"] {
            let e = load(bad).unwrap_err();
            assert!(
                e.contains("link.toml") && e.contains("restart_in_air") && e.contains("line"),
                "{e}"
            );
        }
    }
}
