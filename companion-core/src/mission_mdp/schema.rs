//! The MDP file formats (params/mdp/*.toml) as serde types; docs/params/mdp.md describes them.

use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct IndexFile {
    /// MDP names (files `params/mdp/<name>.toml`) solved concurrently.
    pub(super) concurrent: Vec<String>,
    #[serde(default)]
    pub(super) monolithic: Option<String>,
    #[serde(default)]
    pub(super) reference: Option<String>,
    /// Named probability values at which rows are also checked (the paper's section 7.1 point).
    #[serde(default)]
    pub(super) check_point: BTreeMap<String, f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MdpFile {
    pub(super) name: String,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) source: Option<String>,
    pub(super) initial: String,
    pub(super) states: Vec<String>,
    pub(super) action: Vec<ActionSpec>,
    /// state -> action -> next state -> probability expression.
    #[serde(default)]
    pub(super) transitions: BTreeMap<String, BTreeMap<String, BTreeMap<String, Num>>>,
    /// policy -> rewards.
    pub(super) reward: BTreeMap<String, RewardSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ActionSpec {
    pub(super) name: String,
    pub(super) does: Vec<String>,
    #[serde(default)]
    #[allow(dead_code)]
    pub(super) note: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RewardSpec {
    /// Action name -> reward expression `R(a)` (same in every state where `a` is admissible).
    pub(super) action: BTreeMap<String, Num>,
    /// State name -> reward for entering it, folded into `R(s,a) += sum p(s'|s,a) enter(s')`.
    #[serde(default)]
    pub(super) enter: BTreeMap<String, Num>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub(super) enum Num {
    Number(f64),
    Text(String),
}

impl Num {
    pub(super) fn text(&self) -> String {
        match self {
            Num::Number(x) => format!("{x}"),
            Num::Text(s) => s.clone(),
        }
    }
}
