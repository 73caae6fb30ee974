//! The named probabilities (`P_V3`, `P_battery`, ...): who publishes each and who reads it,
//! computed from the loaded model. A name nobody publishes or nobody reads is a params error:
//! an MDP reading an unpublished name is refused by `MissionMdps::load`; the rest is checked
//! here. `companion check --json` lists the result under `probabilities`.

use crate::health::HealthModel;
use crate::mission::MissionFile;
use crate::mission_mdp::MissionMdps;
use crate::spec::SpecError;
use serde::Serialize;
use std::path::Path;

/// One reader of a named probability.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Consumer {
    /// `mdp` (an MDP's transition or reward expressions read it), `guarantee_cap` (capped when
    /// PANORAMA finds no allocation, params/mission.toml `guarantee.capped_probability`) or
    /// `recorded` (kept for the decision record and the review only, params/mission.toml
    /// `recorded_probabilities`).
    pub kind: &'static str,
    /// The MDP's name, or the params entry that names the probability.
    pub name: String,
}

/// One named probability, its publisher and its consumers.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct NamedProbability {
    /// Probability name (`P_V3`).
    pub name: String,
    /// The health manager that publishes it (params/health/).
    pub publisher: String,
    /// Its BN query (`P(R_V3 = ToActivate)`, `1 - P(E_t1 = low)`).
    pub query: String,
    /// Who reads it.
    pub consumers: Vec<Consumer>,
}

/// Every published probability, in the health managers' order, with its consumers.
pub fn named_probabilities(
    health: &HealthModel,
    mdps: &MissionMdps,
    mission: &MissionFile,
) -> Vec<NamedProbability> {
    let mut out = Vec::new();
    for m in &health.managers {
        for p in &m.publish {
            let mut consumers: Vec<Consumer> = mdps
                .all()
                .iter()
                .filter(|x| x.probability_names().contains(&p.name))
                .map(|x| Consumer {
                    kind: "mdp",
                    name: x.name().to_string(),
                })
                .collect();
            if mission.guarantee.capped_probability == p.name {
                consumers.push(Consumer {
                    kind: "guarantee_cap",
                    name: "mission.toml guarantee.capped_probability".into(),
                });
            }
            if mission.recorded_probabilities.contains(&p.name) {
                consumers.push(Consumer {
                    kind: "recorded",
                    name: "mission.toml recorded_probabilities".into(),
                });
            }
            out.push(NamedProbability {
                name: p.name.clone(),
                publisher: m.name.clone(),
                query: p.expr(),
                consumers,
            });
        }
    }
    out
}

/// Refuse a published probability nothing reads, and a name params/mission.toml reads that no
/// health manager publishes. `dir` is the params directory (for the error's file).
pub fn check_vocabulary(
    dir: &Path,
    health: &HealthModel,
    mdps: &MissionMdps,
    mission: &MissionFile,
) -> Result<(), SpecError> {
    let mission_file = dir.join("mission.toml");
    let published = health.publishes();
    let is_published = |n: &str| published.iter().any(|p| p == n);
    if !is_published(&mission.guarantee.capped_probability) {
        return Err(SpecError::new(
            &mission_file,
            "guarantee.capped_probability",
            format!(
                "`{}` is published by no health manager",
                mission.guarantee.capped_probability
            ),
        ));
    }
    for (i, n) in mission.recorded_probabilities.iter().enumerate() {
        if !is_published(n) {
            return Err(SpecError::new(
                &mission_file,
                format!("recorded_probabilities[{i}]"),
                format!("`{n}` is published by no health manager"),
            ));
        }
    }
    for p in named_probabilities(health, mdps, mission) {
        if p.consumers.is_empty() {
            let file = health
                .managers
                .iter()
                .find(|m| m.name == p.publisher)
                .map_or_else(|| dir.join("health"), |m| m.file.clone());
            return Err(SpecError::new(
                file,
                format!("publish.{}", p.name),
                "published but nothing reads it: no MDP, not the guarantee's cap, not in \
                 params/mission.toml `recorded_probabilities`",
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> crate::decision::Model {
        crate::decision::Model::load(&crate::shipped::params()).unwrap()
    }

    #[test]
    fn every_shipped_probability_has_its_publisher_and_a_consumer() {
        let m = model();
        let all = named_probabilities(&m.health, &m.mdps, &m.mission);
        let names: Vec<&str> = all.iter().map(|p| p.name.as_str()).collect();
        let mut published = m.health.publishes();
        published.sort();
        let mut sorted = names.clone();
        sorted.sort();
        assert_eq!(sorted, published);
        for p in &all {
            assert!(!p.consumers.is_empty(), "{}", p.name);
        }
        let v3 = all.iter().find(|p| p.name == "P_V3").unwrap();
        assert_eq!(v3.publisher, "resources");
        assert!(
            v3.consumers
                .iter()
                .any(|c| c.kind == "mdp" && c.name == "tracking")
        );
        let battery = all.iter().find(|p| p.name == "P_battery").unwrap();
        assert!(battery.consumers.iter().any(|c| c.kind == "guarantee_cap"));
    }

    #[test]
    fn a_probability_nothing_reads_is_refused() {
        let files = crate::shipped::params();
        let m = model();
        let mut mission = m.mission.clone();
        mission.recorded_probabilities.retain(|n| n != "P_lidar");
        let e = check_vocabulary(files.dir(), &m.health, &m.mdps, &mission).unwrap_err();
        assert_eq!(e.entry, "publish.P_lidar");
        assert!(e.file.ends_with("health/sensors.toml"), "{e}");
        assert!(e.reason.contains("nothing reads it"), "{e}");
    }

    #[test]
    fn a_probability_no_manager_publishes_is_refused() {
        let files = crate::shipped::params();
        let m = model();
        let mut mission = m.mission.clone();
        mission.recorded_probabilities.push("P_radar".into());
        let e = check_vocabulary(files.dir(), &m.health, &m.mdps, &mission).unwrap_err();
        assert!(e.entry.starts_with("recorded_probabilities["), "{e}");
        let mut mission = m.mission.clone();
        mission.guarantee.capped_probability = "P_fuel".into();
        let e = check_vocabulary(files.dir(), &m.health, &m.mdps, &mission).unwrap_err();
        assert_eq!(e.entry, "guarantee.capped_probability");
    }
}
