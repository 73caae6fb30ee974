//! Behaviour arbitration's rules (params/policies.toml): the antagonistic primitive actions and
//! each policy's priority order (BFM section 6.2), loaded with the model and applied each cycle
//! by the arbitration stage.

use crate::action_id::{ActionId, ActionIds, ActionNames};
use crate::mission_mdp::InstantiateError;
use crate::record::Conflict;
use crate::spec::{ParamsFiles, SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;

fn err(path: &Path, entry: impl Into<String>, reason: impl Into<String>) -> SpecError {
    SpecError::new(path, entry, reason)
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PoliciesFile {
    #[serde(default)]
    #[allow(dead_code)]
    source: Option<String>,
    antagonistic: Vec<RuleSpec>,
    /// Policy -> primitive-action patterns, highest priority first.
    priority: BTreeMap<String, Vec<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RuleSpec {
    name: String,
    a: Vec<String>,
    b: Vec<String>,
    #[serde(default)]
    #[allow(dead_code)]
    source: Option<String>,
}

#[derive(Debug, Clone)]
struct Rule {
    name: String,
    groups: [Vec<String>; 2],
}

/// Antagonistic primitive actions (BFM section 6.2) and each policy's priority order.
/// Patterns are primitive action names, or a prefix followed by `*` (`track_v*`).
#[derive(Debug, Clone)]
pub struct BehaviourConflicts {
    rules: Vec<Rule>,
    /// Policy name and its order, in name order (the order of [`BehaviourConflicts::policies`],
    /// so a policy's position is its [`crate::mission::Policy`] index).
    priority: Vec<(String, Vec<String>)>,
}

fn pattern_matches(pattern: &str, action: &str) -> bool {
    match pattern.strip_suffix('*') {
        Some(prefix) => action.starts_with(prefix),
        None => pattern == action,
    }
}

impl BehaviourConflicts {
    /// Load `params/policies.toml`. `known_actions` are the primitive actions (e.g.
    /// [`crate::mission_mdp::MissionMdps::primitive_actions`]); every pattern must match at least one.
    pub fn load(
        params: &ParamsFiles,
        path: &Path,
        known_actions: &[&str],
    ) -> Result<Self, SpecError> {
        let f: PoliciesFile = read_toml(params, path)?;
        if f.priority.is_empty() {
            return Err(err(path, "priority", "no policy"));
        }
        let check_pattern = |entry: String, p: &str| -> Result<(), SpecError> {
            if known_actions.iter().any(|a| pattern_matches(p, a)) {
                Ok(())
            } else {
                Err(err(
                    path,
                    entry,
                    format!("'{p}' matches no known primitive action"),
                ))
            }
        };
        let mut rules = Vec::new();
        for (i, r) in f.antagonistic.iter().enumerate() {
            if f.antagonistic[..i].iter().any(|q| q.name == r.name) {
                return Err(err(
                    path,
                    format!("antagonistic[{i}].name"),
                    format!("rule '{}' given twice", r.name),
                ));
            }
            for (g, group) in [("a", &r.a), ("b", &r.b)] {
                if group.is_empty() {
                    return Err(err(path, format!("antagonistic[{i}].{g}"), "empty group"));
                }
                for (j, p) in group.iter().enumerate() {
                    check_pattern(format!("antagonistic[{i}].{g}[{j}]"), p)?;
                    for (pol, order) in &f.priority {
                        if !order.contains(p) {
                            return Err(err(
                                path,
                                format!("priority.{pol}"),
                                format!("'{p}' (rule '{}') not ranked", r.name),
                            ));
                        }
                    }
                }
            }
            if r.a.iter().any(|p| r.b.contains(p)) {
                return Err(err(
                    path,
                    format!("antagonistic[{i}]"),
                    "a pattern is in both groups",
                ));
            }
            rules.push(Rule {
                name: r.name.clone(),
                groups: [r.a.clone(), r.b.clone()],
            });
        }
        for (pol, order) in &f.priority {
            for (j, p) in order.iter().enumerate() {
                check_pattern(format!("priority.{pol}[{j}]"), p)?;
                if order[..j].contains(p) {
                    return Err(err(
                        path,
                        format!("priority.{pol}[{j}]"),
                        format!("'{p}' ranked twice"),
                    ));
                }
            }
        }
        Ok(Self {
            rules,
            priority: f.priority.into_iter().collect(),
        })
    }

    /// Names of the policies params/policies.toml ranks actions for.
    pub fn policies(&self) -> impl Iterator<Item = &str> {
        self.priority.iter().map(|(name, _)| name.as_str())
    }

    /// Position of the policy named `policy` among [`BehaviourConflicts::policies`].
    pub fn policy_position(&self, policy: &str) -> Result<usize, InstantiateError> {
        self.priority
            .iter()
            .position(|(name, _)| name == policy)
            .ok_or_else(|| InstantiateError::UnknownPolicy(policy.to_string()))
    }

    /// Apply every antagonistic rule in file order: when actions of both groups are present,
    /// the group holding the higher-ranked pattern (under `policy`) keeps its actions and the
    /// other group's actions are dropped. Returns the kept actions (input order) and one
    /// [`Conflict`] per rule that fired.
    pub fn resolve<S: AsRef<str>>(
        &self,
        actions: &[S],
        policy: &str,
    ) -> Result<(Vec<String>, Vec<Conflict>), InstantiateError> {
        let actions: Vec<&str> = actions.iter().map(AsRef::as_ref).collect();
        let mut kept = Vec::new();
        let mut conflicts = Vec::new();
        self.resolve_into(&actions, policy, &mut kept, &mut conflicts)?;
        Ok((kept.into_iter().map(str::to_string).collect(), conflicts))
    }

    /// As [`BehaviourConflicts::resolve`] over names: `kept` is overwritten, `conflicts`
    /// rewritten entry by entry (a test's or a tool's form; the cycle runs
    /// [`BehaviourConflicts::resolve_by`] on the catalogue's ids).
    pub fn resolve_into<'a>(
        &self,
        actions: &[&'a str],
        policy: &str,
        kept: &mut Vec<&'a str>,
        conflicts: &mut Vec<Conflict>,
    ) -> Result<(), InstantiateError> {
        let at = self.policy_position(policy)?;
        let list = ActionIds::from_names(actions);
        let mut ids = Vec::new();
        self.resolve_by(list.ids(), list.vocabulary(), at, &mut ids, conflicts)?;
        kept.clear();
        for a in ids {
            kept.extend(actions.iter().find(|&&x| x == list.name(a)));
        }
        Ok(())
    }

    /// As [`BehaviourConflicts::resolve_into`] over catalogue ids, `names` their names by id
    /// (what patterns match; the conflicts record the ids over them), under the policy at
    /// position `policy` of [`BehaviourConflicts::policies`] (resolved at load).
    pub fn resolve_by(
        &self,
        actions: &[ActionId],
        names: &ActionNames,
        policy: usize,
        kept: &mut Vec<ActionId>,
        conflicts: &mut Vec<Conflict>,
    ) -> Result<(), InstantiateError> {
        let (_, order) = self
            .priority
            .get(policy)
            .ok_or_else(|| InstantiateError::UnknownPolicy(format!("#{policy}")))?;
        kept.clear();
        kept.extend_from_slice(actions);
        let rank = |group: &[String]| {
            group
                .iter()
                .filter_map(|p| order.iter().position(|q| q == p))
                .min()
        };
        let name = |a: ActionId| names[a.index()].as_str();
        let mut fired = 0;
        for rule in &self.rules {
            let in_group = |g: usize, a: &ActionId| {
                rule.groups[g].iter().any(|p| pattern_matches(p, name(*a)))
            };
            let present = |g: usize| kept.iter().any(|a| in_group(g, a));
            if !present(0) || !present(1) {
                continue;
            }
            let a_wins = rank(&rule.groups[0]) <= rank(&rule.groups[1]);
            let (win, lose) = if a_wins { (0, 1) } else { (1, 0) };
            if fired == conflicts.len() {
                conflicts.push(Conflict::default());
            }
            let c = &mut conflicts[fired];
            fired += 1;
            let of_group = |g: usize| kept.iter().copied().filter(move |a| in_group(g, a));
            c.kept.set(names, of_group(win));
            c.dropped.set(names, of_group(lose));
            c.rule.clone_from(&rule.name);
            kept.retain(|a| !in_group(lose, a));
        }
        conflicts.truncate(fired);
        Ok(())
    }

    /// The original list-building form, kept as the reference `resolve_into` is tested against.
    #[cfg(test)]
    pub(crate) fn resolve_reference<S: AsRef<str>>(
        &self,
        actions: &[S],
        policy: &str,
    ) -> Result<(Vec<String>, Vec<Conflict>), InstantiateError> {
        let (_, order) = &self.priority[self.policy_position(policy)?];
        let mut kept: Vec<String> = actions.iter().map(|a| a.as_ref().to_string()).collect();
        let mut conflicts = Vec::new();
        let rank = |group: &[String]| {
            group
                .iter()
                .filter_map(|p| order.iter().position(|q| q == p))
                .min()
        };
        for rule in &self.rules {
            let present = |g: &[String]| -> Vec<String> {
                kept.iter()
                    .filter(|a| g.iter().any(|p| pattern_matches(p, a)))
                    .cloned()
                    .collect()
            };
            let (in_a, in_b) = (present(&rule.groups[0]), present(&rule.groups[1]));
            if in_a.is_empty() || in_b.is_empty() {
                continue;
            }
            let a_wins = rank(&rule.groups[0]) <= rank(&rule.groups[1]);
            let (win, lose) = if a_wins { (in_a, in_b) } else { (in_b, in_a) };
            kept.retain(|a| !lose.contains(a));
            conflicts.push(Conflict {
                kept: win.iter().collect(),
                dropped: lose.iter().collect(),
                rule: rule.name.clone(),
            });
        }
        Ok((kept, conflicts))
    }
}
