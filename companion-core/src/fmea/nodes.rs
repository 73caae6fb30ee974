//! What a health manager's file says about every node (its role, states and the solutions of
//! each error), as the compiler and the table rules read it.

use super::err;
use super::roles::Role;
use super::schema::{HmFile, NodeSpec};
use crate::spec::SpecError;
use std::collections::BTreeMap;
use std::path::Path;

/// What the whole file says about every node: its role, its states, and the solutions of each
/// error.
pub(super) struct Hm<'a> {
    pub(super) file: &'a Path,
    pub(super) spec: &'a HmFile,
    pub(super) role: BTreeMap<String, Role>,
    /// Nodes in the order they were first named (FMEA rows, then `node` tables).
    pub(super) order: Vec<String>,
    pub(super) states: BTreeMap<String, Vec<String>>,
    pub(super) solutions_of: BTreeMap<&'a str, Vec<String>>,
    /// The settings of the nodes named only in FMEA rows: their role's defaults.
    pub(super) defaults: BTreeMap<String, NodeSpec>,
}

impl Hm<'_> {
    pub(super) fn node(&self, n: &str) -> &NodeSpec {
        self.spec.node.get(n).unwrap_or_else(|| &self.defaults[n])
    }

    pub(super) fn known(&self, node: &str, entry: String) -> Result<(), SpecError> {
        if self.states.contains_key(node) {
            Ok(())
        } else {
            Err(err(self.file, entry, format!("unknown node `{node}`")))
        }
    }

    pub(super) fn state_idx(
        &self,
        node: &str,
        st: &str,
        entry: String,
    ) -> Result<usize, SpecError> {
        let file = self.file;
        let s = self
            .states
            .get(node)
            .ok_or_else(|| err(file, entry.clone(), format!("unknown node `{node}`")))?;
        s.iter().position(|x| x == st).ok_or_else(|| {
            err(
                file,
                entry,
                format!(
                    "node `{node}` has no state `{st}` (states: {})",
                    s.join(", ")
                ),
            )
        })
    }

    pub(super) fn has_role(&self, node: &str, r: Role) -> bool {
        self.role.get(node) == Some(&r)
    }
}
