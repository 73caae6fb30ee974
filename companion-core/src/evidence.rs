//! Raw observations to BN evidence: each observation names a node and ordered thresholds
//! (params/observations.toml). A value `v` maps to `states[i]` where `i` counts the thresholds
//! `t <= v` (a value on a threshold goes to the upper state). A missing or non-finite value puts
//! no evidence on its node.

use crate::observations::Observations;
use crate::spec::{SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObservationsFile {
    #[serde(default)]
    observation: Vec<ObservationSpec>,
}

/// One observation and how it discretises.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    /// Observation name, the key in `Observations.values` (`wind_mps`).
    pub name: String,
    /// Unit of the value (`m/s`, `%`, `lx`, ...), for display.
    #[serde(default)]
    pub unit: String,
    /// The BN node (in any health manager) that receives the evidence.
    pub node: String,
    /// Strictly increasing; `states.len() == thresholds.len() + 1`.
    pub thresholds: Vec<f64>,
    /// The node's state for each interval between thresholds, in value order.
    pub states: Vec<String>,
    /// Free text from the file.
    #[serde(default)]
    pub description: String,
}

impl ObservationSpec {
    /// The state a value falls in.
    pub fn state(&self, value: f64) -> Option<&str> {
        if !value.is_finite() {
            return None;
        }
        let i = self.thresholds.iter().filter(|&&t| t <= value).count();
        Some(&self.states[i])
    }
}

/// The validated observation mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservationMap {
    /// File the mapping was read from (params/observations.toml).
    pub file: PathBuf,
    /// Every observation mapped to evidence, in file order.
    pub observations: Vec<ObservationSpec>,
}

impl ObservationMap {
    /// Read and validate the mapping at `path`.
    pub fn load(params: &crate::spec::ParamsFiles, path: &Path) -> Result<Self, SpecError> {
        let f: ObservationsFile = read_toml(params, path)?;
        if f.observation.is_empty() {
            return Err(SpecError::new(
                path,
                "observation",
                "no observations: the health managers would never receive evidence",
            ));
        }
        Self::new(path, f.observation)
    }

    /// Validate: unique names, one observation per node, thresholds strictly increasing and
    /// finite, one more state than thresholds.
    pub fn new(file: &Path, observations: Vec<ObservationSpec>) -> Result<Self, SpecError> {
        let mut names = BTreeMap::new();
        let mut nodes = BTreeMap::new();
        for (i, o) in observations.iter().enumerate() {
            let entry = |k: &str| format!("observation[{i}]({}).{k}", o.name);
            if names.insert(o.name.clone(), i).is_some() {
                return Err(SpecError::new(
                    file,
                    entry("name"),
                    "duplicate observation name",
                ));
            }
            if let Some(j) = nodes.insert(o.node.clone(), i) {
                return Err(SpecError::new(
                    file,
                    entry("node"),
                    format!("node `{}` already receives observation[{j}]", o.node),
                ));
            }
            if let Some(t) = o.thresholds.iter().find(|t| !t.is_finite()) {
                return Err(SpecError::new(
                    file,
                    entry("thresholds"),
                    format!("{t} is not finite"),
                ));
            }
            if let Some(w) = o.thresholds.windows(2).find(|w| w[0] >= w[1]) {
                return Err(SpecError::new(
                    file,
                    entry("thresholds"),
                    format!(
                        "thresholds out of order: {} then {} (must strictly increase)",
                        w[0], w[1]
                    ),
                ));
            }
            if o.states.len() != o.thresholds.len() + 1 {
                return Err(SpecError::new(
                    file,
                    entry("states"),
                    format!(
                        "{} states for {} thresholds (need one more state)",
                        o.states.len(),
                        o.thresholds.len()
                    ),
                ));
            }
        }
        Ok(Self {
            file: file.to_path_buf(),
            observations,
        })
    }

    /// The mapping of the observation named `name`.
    pub fn get(&self, name: &str) -> Option<&ObservationSpec> {
        self.observations.iter().find(|o| o.name == name)
    }

    /// Evidence (node -> state) for every observation present in the snapshot.
    pub fn evidence(&self, obs: &Observations) -> BTreeMap<String, String> {
        let mut out = BTreeMap::new();
        self.evidence_into(obs, &mut out);
        out
    }

    /// As [`ObservationMap::evidence`], into the caller's map. When the same nodes get evidence
    /// as last time (the steady state) the entries are rewritten in place and nothing is
    /// allocated once every state name has fitted in its entry.
    pub fn evidence_into(&self, obs: &Observations, out: &mut BTreeMap<String, String>) {
        self.evidence_with_into(obs, &[], out)
    }

    /// As [`ObservationMap::evidence_into`], with `extra` (name, value) pairs taking the place
    /// of the snapshot's values of those names (values the caller computes itself).
    pub fn evidence_with_into(
        &self,
        obs: &Observations,
        extra: &[(&str, f64)],
        out: &mut BTreeMap<String, String>,
    ) {
        let value = |name: &str| {
            extra
                .iter()
                .find(|(n, _)| *n == name)
                .map(|&(_, v)| v)
                .or_else(|| obs.get(name))
        };
        let mut n = 0;
        let mut same = true;
        for o in &self.observations {
            if let Some(s) = value(&o.name).and_then(|v| o.state(v)) {
                n += 1;
                match out.get_mut(o.node.as_str()) {
                    Some(v) => {
                        v.clear();
                        v.push_str(s);
                    }
                    None => {
                        same = false;
                        break;
                    }
                }
            }
        }
        if same && n == out.len() {
            return;
        }
        out.clear();
        for o in &self.observations {
            if let Some(s) = value(&o.name).and_then(|v| o.state(v)) {
                out.insert(o.node.clone(), s.to_string());
            }
        }
    }
}
