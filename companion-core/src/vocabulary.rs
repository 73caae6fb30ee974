//! The primitive actions as a checked vocabulary: each action of params/actions.toml is interned
//! at load into an [`ActionId`], every action an MDP proposes (`does` in params/mdp/*.toml) must
//! be in the catalogue, and every catalogue action must be proposed by some MDP (an action no
//! MDP proposes could never run). `companion check --json` lists the result under `actions`;
//! the shell adds how the fly shell maps each vehicle action (params/commands.toml).

use crate::mission::{ActionCatalogue, ActionKind};
use crate::mission_mdp::MissionMdps;
use crate::spec::SpecError;
use serde::Serialize;
use std::path::Path;

pub use crate::action_id::{ActionId, ActionIds};

/// Most actions params/actions.toml may declare (ids are `u16`).
pub const MAX_ACTIONS: usize = u16::MAX as usize;

/// The id of the action named `name` in `catalogue`.
pub fn action_id(catalogue: &ActionCatalogue, name: &str) -> Option<ActionId> {
    catalogue
        .actions
        .iter()
        .take(MAX_ACTIONS)
        .position(|a| a.id == name)
        .map(|i| ActionId::from_index(i as u16))
}

impl ActionCatalogue {
    /// The id of the action named `name` ([`action_id`]).
    pub fn id(&self, name: &str) -> Option<ActionId> {
        action_id(self, name)
    }

    /// The action an id of this catalogue names.
    pub fn by_id(&self, id: ActionId) -> &crate::mission::Action {
        &self.actions[id.index()]
    }

    /// The actions of `list`: by id when it is over this catalogue's names (every list the core
    /// writes), by name otherwise (a list read from a file; a name not in the catalogue skipped).
    pub fn actions_of<'a>(
        &'a self,
        list: &'a ActionIds,
    ) -> impl Iterator<Item = &'a crate::mission::Action> + 'a {
        let ours = std::sync::Arc::ptr_eq(list.vocabulary(), self.names());
        list.ids().iter().filter_map(move |&a| match ours {
            true => Some(self.by_id(a)),
            false => self.get(list.name(a)),
        })
    }

    /// The name of the action an id of this catalogue names (what the record writes).
    pub fn name(&self, id: ActionId) -> &str {
        &self.by_id(id).id
    }
}

/// The application variant an action starts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ActionApplication {
    /// Application (`tracking`).
    pub app: String,
    /// Its version (`V3`).
    pub version: String,
}

/// One primitive action and the MDPs that propose it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct NamedAction {
    /// Action name (`track_v3`).
    pub name: String,
    /// The paper's name (`A15`).
    pub paper: String,
    /// `vehicle` (an autopilot command) or `application` (a variant on the platform).
    pub kind: &'static str,
    /// The application variant it starts, if any (params/actions.toml `app`, `version`).
    pub application: Option<ActionApplication>,
    /// The MDPs with an action whose `does` lists it, in params/mdp/index.toml order.
    pub proposed_by: Vec<String>,
}

/// Every catalogue action, in file order, with the MDPs that propose it.
pub fn named_actions(actions: &ActionCatalogue, mdps: &MissionMdps) -> Vec<NamedAction> {
    actions
        .actions
        .iter()
        .map(|a| NamedAction {
            name: a.id.clone(),
            paper: a.paper.clone(),
            kind: match a.kind {
                ActionKind::Vehicle => "vehicle",
                ActionKind::Application => "application",
            },
            application: match (&a.app, &a.version) {
                (Some(app), Some(version)) => Some(ActionApplication {
                    app: app.clone(),
                    version: version.clone(),
                }),
                _ => None,
            },
            proposed_by: mdps
                .all()
                .iter()
                .filter(|m| (0..m.n_actions()).any(|k| m.primitives(k).contains(&a.id)))
                .map(|m| m.name().to_string())
                .collect(),
        })
        .collect()
}

/// Refuse an MDP action that does a primitive action the catalogue lacks (named in the MDP's
/// file), and a catalogue action no MDP proposes (named in params/actions.toml). `dir` is the
/// params directory.
pub fn check_actions(
    dir: &Path,
    actions: &ActionCatalogue,
    mdps: &MissionMdps,
) -> Result<(), SpecError> {
    let file = dir.join("actions.toml");
    if actions.actions.len() > MAX_ACTIONS {
        return Err(SpecError::new(
            &file,
            "action",
            format!("{} actions: at most {MAX_ACTIONS}", actions.actions.len()),
        ));
    }
    for m in mdps.all() {
        for k in 0..m.n_actions() {
            for (j, p) in m.primitives(k).iter().enumerate() {
                if action_id(actions, p).is_none() {
                    return Err(SpecError::new(
                        m.file(),
                        format!("action[{k}]({}).does[{j}]", m.action_name(k)),
                        format!("`{p}` is not an action of params/actions.toml"),
                    ));
                }
            }
        }
    }
    for (i, a) in named_actions(actions, mdps).iter().enumerate() {
        if a.proposed_by.is_empty() {
            return Err(SpecError::new(
                &file,
                format!("action[{i}]({})", a.name),
                "no MDP proposes it: no action of params/mdp/*.toml lists it in `does`",
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::ParamsFiles;

    /// The shipped params with `file`'s text edited by `edit`.
    fn edited(file: &str, edit: impl Fn(&str) -> String) -> ParamsFiles {
        let mut files = crate::shipped::params();
        let path = files.dir().join(file);
        let text = edit(files.text(&path).unwrap());
        files.insert(&path, text);
        files
    }

    #[test]
    fn every_shipped_action_is_interned_and_proposed_by_an_mdp() {
        let m = crate::decision::Model::load(&crate::shipped::params()).unwrap();
        let all = named_actions(&m.actions, &m.mdps);
        assert_eq!(all.len(), m.actions.actions.len());
        for (i, a) in all.iter().enumerate() {
            assert!(!a.proposed_by.is_empty(), "{}", a.name);
            assert_eq!(action_id(&m.actions, &a.name).unwrap().index(), i);
        }
        let v3 = all.iter().find(|a| a.name == "track_v3").unwrap();
        assert!(v3.proposed_by.iter().any(|p| p == "tracking"), "{v3:?}");
        assert_eq!(v3.application.as_ref().unwrap().version, "V3");
        assert_eq!(action_id(&m.actions, "fly_to_the_moon"), None);
    }

    #[test]
    fn an_mdp_action_missing_from_the_catalogue_is_refused_in_the_mdp_file() {
        let files = edited("mdp/tracking.toml", |t| {
            t.replacen("does = [\"track_v3\"]", "does = [\"track_v9\"]", 1)
        });
        let e = crate::decision::Model::load(&files).err().unwrap();
        assert!(e.file.ends_with("mdp/tracking.toml"), "{e}");
        assert_eq!(e.entry, "action[7](A15).does[0]", "{e}");
        assert!(e.reason.contains("`track_v9`"), "{e}");
        assert!(e.reason.contains("params/actions.toml"), "{e}");
    }

    #[test]
    fn a_catalogue_action_no_mdp_proposes_is_refused() {
        let files = edited("actions.toml", |t| {
            format!(
                "{t}\n[[action]]\nid = \"hover\"\npaper = \"-\"\nkind = \"vehicle\"\nlabel = \"hover\"\nrole = \"detect_obstacles\"\n"
            )
        });
        let e = crate::decision::Model::load(&files).err().unwrap();
        assert!(e.file.ends_with("actions.toml"), "{e}");
        assert_eq!(e.entry, "action[18](hover)", "{e}");
        assert!(e.reason.contains("no MDP proposes it"), "{e}");
    }
}
