//! Implementation alternatives from task implementation options (paper section 6.2.2, Fig. 6):
//! an IA picks one TIO per robotic task; core-oriented and experimental constraints remove TIOs.

use serde::{Deserialize, Serialize};

/// A task implementation option: the hardware and software resources that implement one task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tio {
    /// Name, unique within its task.
    pub name: String,
    /// Hardware and software resources the option uses.
    #[serde(default)]
    pub resources: Vec<String>,
}

/// A robotic task and its options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// Name of the robotic task.
    pub name: String,
    /// The implementation options of the task.
    pub tios: Vec<Tio>,
}

/// A core-oriented (or experimental) constraint on one task of an activity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CoreConstraint {
    /// The task's TIO must use `resource` (glazed area: moving methods must use sonar).
    Require {
        /// The constrained task.
        task: String,
        /// The resource every allowed TIO uses.
        resource: String,
    },
    /// The task's TIO must not use `resource`.
    Forbid {
        /// The constrained task.
        task: String,
        /// The resource no allowed TIO uses.
        resource: String,
    },
    /// Only these TIOs of the task are allowed.
    Only {
        /// The constrained task.
        task: String,
        /// Names of the allowed TIOs.
        tios: Vec<String>,
    },
}

impl CoreConstraint {
    /// The task this constraint applies to.
    pub fn task(&self) -> &str {
        match self {
            CoreConstraint::Require { task, .. }
            | CoreConstraint::Forbid { task, .. }
            | CoreConstraint::Only { task, .. } => task,
        }
    }

    fn allows(&self, tio: &Tio) -> bool {
        match self {
            CoreConstraint::Require { resource, .. } => tio.resources.iter().any(|r| r == resource),
            CoreConstraint::Forbid { resource, .. } => !tio.resources.iter().any(|r| r == resource),
            CoreConstraint::Only { tios, .. } => tios.iter().any(|t| t == &tio.name),
        }
    }
}

/// All IAs of an activity: the cartesian product of the TIOs of each task that pass every
/// constraint naming that task. Each IA is the list of TIO indices, one per task, in task order;
/// the product is enumerated with the last task varying fastest.
pub fn combine(tasks: &[Task], constraints: &[CoreConstraint]) -> Vec<Vec<usize>> {
    let allowed: Vec<Vec<usize>> = tasks
        .iter()
        .map(|t| {
            (0..t.tios.len())
                .filter(|&i| {
                    constraints
                        .iter()
                        .filter(|c| c.task() == t.name)
                        .all(|c| c.allows(&t.tios[i]))
                })
                .collect()
        })
        .collect();
    let mut out = vec![Vec::new()];
    for a in &allowed {
        out = out
            .into_iter()
            .flat_map(|prefix: Vec<usize>| {
                a.iter().map(move |&i| {
                    let mut p = prefix.clone();
                    p.push(i);
                    p
                })
            })
            .collect();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tio(n: &str, r: &[&str]) -> Tio {
        Tio {
            name: n.into(),
            resources: r.iter().map(|s| s.to_string()).collect(),
        }
    }

    #[test]
    fn product_and_filters() {
        // Fig. 6: three tasks with 4, 2 and 3 TIOs give 24 IAs.
        let tasks = vec![
            Task {
                name: "a".into(),
                tios: vec![
                    tio("a1", &["x"]),
                    tio("a2", &[]),
                    tio("a3", &["x", "y"]),
                    tio("a4", &["y"]),
                ],
            },
            Task {
                name: "b".into(),
                tios: vec![tio("b1", &[]), tio("b2", &["y"])],
            },
            Task {
                name: "c".into(),
                tios: vec![tio("c1", &[]), tio("c2", &[]), tio("c3", &[])],
            },
        ];
        assert_eq!(combine(&tasks, &[]).len(), 24);
        let req = CoreConstraint::Require {
            task: "a".into(),
            resource: "x".into(),
        };
        assert_eq!(combine(&tasks, std::slice::from_ref(&req)).len(), 12);
        let forbid = CoreConstraint::Forbid {
            task: "a".into(),
            resource: "y".into(),
        };
        let ias = combine(&tasks, &[req.clone(), forbid]);
        assert_eq!(ias.len(), 6);
        assert!(ias.iter().all(|ia| ia[0] == 0));
        let only = CoreConstraint::Only {
            task: "c".into(),
            tios: vec!["c2".into()],
        };
        let ias = combine(&tasks, &[req, only]);
        assert_eq!(
            ias,
            vec![vec![0, 0, 1], vec![0, 1, 1], vec![2, 0, 1], vec![2, 1, 1]]
        );
    }
}
