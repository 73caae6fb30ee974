//! A node's role in a health manager (`role` key or where the FMEA rows name it) and the one
//! derivation of every node's role, shared by the loader (schema.rs, on the raw entries) and the
//! compiler (compile.rs, on the parsed ones).

use super::{ROLES, err};
use crate::spec::SpecError;
use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

/// A node's role: its `role` key, or where the FMEA rows name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Role {
    Qos,
    Error,
    Monitor,
    Context,
    MonitorHealth,
    Solution,
    Version,
    Resource,
    Performance,
    Activation,
    Fit,
    Import,
    State,
}

impl Role {
    pub(super) const ALL: [Role; 13] = [
        Role::Qos,
        Role::Error,
        Role::Monitor,
        Role::Context,
        Role::MonitorHealth,
        Role::Solution,
        Role::Version,
        Role::Resource,
        Role::Performance,
        Role::Activation,
        Role::Fit,
        Role::Import,
        Role::State,
    ];

    pub(super) fn parse(s: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.as_str() == s)
    }

    pub(super) fn as_str(self) -> &'static str {
        match self {
            Role::Qos => "qos",
            Role::Error => "error",
            Role::Monitor => "monitor",
            Role::Context => "context",
            Role::MonitorHealth => "monitor_health",
            Role::Solution => "solution",
            Role::Version => "version",
            Role::Resource => "resource",
            Role::Performance => "performance",
            Role::Activation => "activation",
            Role::Fit => "fit",
            Role::Import => "import",
            Role::State => "state",
        }
    }

    /// Roots take a prior and no parents.
    pub(super) fn is_root(self) -> bool {
        matches!(
            self,
            Role::Context | Role::Resource | Role::Solution | Role::Import
        )
    }

    pub(super) fn default_states(self) -> Option<&'static [&'static str]> {
        Some(match self {
            Role::Qos => &["high", "medium", "low"],
            Role::Error => &["absent", "present"],
            Role::Monitor => &["ok", "alarm"],
            Role::MonitorHealth => &["ok", "faulty"],
            Role::Solution | Role::Version => &["deactivate", "activate"],
            Role::Activation => &["ToDeactivate", "ToActivate"],
            Role::Fit => &["no", "yes"],
            _ => return None,
        })
    }

    /// Roles whose default rule is written for two states, nominal first.
    pub(super) fn binary_rule(self) -> bool {
        matches!(
            self,
            Role::Error | Role::Monitor | Role::MonitorHealth | Role::Version | Role::Activation
        )
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The nodes one FMEA row names, by the role the row gives them.
pub(super) struct RowNodes<'a> {
    pub(super) error: &'a str,
    pub(super) monitors: &'a [String],
    pub(super) contexts: &'a [String],
    pub(super) solutions: &'a [String],
}

/// Give `name` role `r`, or refuse a second, different role.
fn assign(
    file: &Path,
    role: &mut BTreeMap<String, Role>,
    order: &mut Vec<String>,
    name: &str,
    r: Role,
    entry: String,
) -> Result<(), SpecError> {
    match role.get(name) {
        Some(old) if *old != r => Err(err(
            file,
            entry,
            format!("node `{name}` is used as {r} but already as {old}"),
        )),
        Some(_) => Ok(()),
        None => {
            role.insert(name.to_string(), r);
            order.push(name.to_string());
            Ok(())
        }
    }
}

/// Roles: from the FMEA rows, then the `role` key of each node entry (which must agree), given
/// as (node, `role` key if any) in the file's order. The loader calls it on the raw entries,
/// the compiler on the parsed ones: the same roles, order and errors.
pub(super) fn assign_roles<'a>(
    file: &Path,
    fmea: impl IntoIterator<Item = RowNodes<'a>>,
    node_roles: impl IntoIterator<Item = (&'a str, Option<&'a str>)>,
) -> Result<(BTreeMap<String, Role>, Vec<String>), SpecError> {
    let mut role: BTreeMap<String, Role> = BTreeMap::new();
    let mut order: Vec<String> = Vec::new();
    for (i, row) in fmea.into_iter().enumerate() {
        let mut named = |name: &str, r: Role, key: &str| {
            assign(
                file,
                &mut role,
                &mut order,
                name,
                r,
                format!("fmea[{i}].{key}"),
            )
        };
        named(row.error, Role::Error, "error")?;
        for m in row.monitors {
            named(m, Role::Monitor, "monitors")?;
        }
        for c in row.contexts {
            named(c, Role::Context, "contexts")?;
        }
        for s in row.solutions {
            named(s, Role::Solution, "solutions")?;
        }
    }
    for (name, key) in node_roles {
        let entry = format!("node.{name}.role");
        match (key, role.get(name)) {
            (Some(r), _) => {
                let Some(r) = Role::parse(r) else {
                    return Err(err(
                        file,
                        entry,
                        format!("unknown role `{r}` (one of {})", ROLES.join(", ")),
                    ));
                };
                assign(file, &mut role, &mut order, name, r, entry)?
            }
            (None, Some(_)) => {}
            (None, None) => {
                return Err(err(file, entry, "node is in no FMEA row and has no `role`"));
            }
        }
    }
    Ok((role, order))
}
