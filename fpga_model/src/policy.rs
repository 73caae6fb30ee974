//! Resource policies as data: who gives way first when the requested set does not fit, and to
//! which versions an application may be degraded before it is dropped (section 6.3, Tables 4-7).

use crate::{Catalogue, ModelError};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// One policy table of `params/resource_policies.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResourcePolicy {
    /// Filled from the table's key by the loader (`safety`, `mission`).
    #[serde(default)]
    pub name: String,
    /// What the policy is for, in words.
    #[serde(default)]
    pub description: String,
    /// Applications, most important first. The last one gives way first.
    pub priority: Vec<String>,
    /// app -> version -> versions to try instead, in order, before dropping the app.
    #[serde(default)]
    pub degrade: BTreeMap<String, BTreeMap<String, Vec<String>>>,
}

/// The file layout: one table per policy name.
pub type PoliciesFile = BTreeMap<String, ResourcePolicy>;

impl ResourcePolicy {
    /// Check that it ranks every catalogue application exactly once and that degradation paths
    /// name existing versions. `name` is the table key, used in error entries.
    pub fn validate(&self, name: &str, catalogue: &Catalogue) -> Result<(), ModelError> {
        let mut seen = BTreeSet::new();
        for (i, app) in self.priority.iter().enumerate() {
            let entry = format!("{name}.priority[{i}]");
            if !catalogue.has_app(app) {
                return Err(ModelError::new(
                    entry,
                    format!("unknown application {app:?} (not in variants.toml)"),
                ));
            }
            if !seen.insert(app.as_str()) {
                return Err(ModelError::new(
                    entry,
                    format!("application {app:?} ranked twice"),
                ));
            }
        }
        for app in catalogue.apps() {
            if !seen.contains(app) {
                return Err(ModelError::new(
                    format!("{name}.priority"),
                    format!("does not rank application {app:?} of variants.toml"),
                ));
            }
        }
        for (app, paths) in &self.degrade {
            if !catalogue.has_app(app) {
                return Err(ModelError::new(
                    format!("{name}.degrade.{app}"),
                    format!("unknown application {app:?} (not in variants.toml)"),
                ));
            }
            for (from, to) in paths {
                if !catalogue.has_version(app, from) {
                    return Err(ModelError::new(
                        format!("{name}.degrade.{app}.{from}"),
                        format!("unknown version {from:?} of {app}"),
                    ));
                }
                let mut tried = BTreeSet::from([from.as_str()]);
                for (k, v) in to.iter().enumerate() {
                    let entry = format!("{name}.degrade.{app}.{from}[{k}]");
                    if !catalogue.has_version(app, v) {
                        return Err(ModelError::new(
                            entry,
                            format!("unknown version {v:?} of {app}"),
                        ));
                    }
                    if !tried.insert(v.as_str()) {
                        return Err(ModelError::new(
                            entry,
                            format!("version {v:?} repeats in the path"),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// Rank of `app` (0 = most important); unranked apps come after every ranked one.
    pub fn rank(&self, app: &str) -> usize {
        self.priority
            .iter()
            .position(|a| a == app)
            .unwrap_or(self.priority.len())
    }

    /// Versions to try instead of `version`, in order.
    pub fn degradation_path(&self, app: &str, version: &str) -> &[String] {
        self.degrade
            .get(app)
            .and_then(|p| p.get(version))
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }
}
