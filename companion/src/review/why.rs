//! The why of one decision cycle: what each MDP proposed and the probabilities it read, which
//! conflicts arose and what gave way, what the resources dropped or degraded, and the PANORAMA
//! margins. Bounded per cycle so a hostile record cannot make the report grow without end.

use companion_core::record::{DecisionRecord, Degraded, Dropped};

const MAX_PROPOSALS: usize = 32;
const MAX_INPUTS: usize = 48;
const MAX_LIST: usize = 32;

#[derive(Debug, Clone, PartialEq)]
pub struct ProposalWhy {
    pub mdp: String,
    pub state: String,
    pub action: String,
    pub actions: Vec<String>,
    pub value: f64,
    /// (name, value as text) of the probabilities this proposal read, when recorded.
    pub inputs: Vec<(String, String)>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ConflictWhy {
    pub kept: String,
    pub dropped: Vec<String>,
    pub rule: String,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MarginWhy {
    pub goal: String,
    pub margin: f64,
    pub target: Option<f64>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct GuaranteeWhy {
    pub activity: String,
    pub margins: Vec<MarginWhy>,
    pub infeasible: bool,
    pub infeasible_reason: Option<String>,
    pub reallocation: Option<String>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Why {
    pub cycle: u64,
    pub time_s: f64,
    pub state: String,
    pub actions: Vec<String>,
    /// What the fly shell flew on its own safety rules (the flight's end, a landing kept up).
    pub shell_actions: Vec<String>,
    pub proposals: Vec<ProposalWhy>,
    /// The cycle's named probabilities (what every proposal could read).
    pub probabilities: Vec<(String, f64)>,
    pub conflicts: Vec<ConflictWhy>,
    pub degraded: Vec<Degraded>,
    pub dropped: Vec<Dropped>,
    pub guarantee: Option<GuaranteeWhy>,
    /// Entries left out by the bounds above.
    pub omitted: usize,
}

fn value_text(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::Number(n) => match n.as_f64() {
            Some(x) => format!("{x:.3}"),
            None => n.to_string(),
        },
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// `proposals[].inputs` as (name, value) pairs, whatever shape the writer chose: an object of
/// name -> value, or a list of `{name, value|p|probability}` objects or `[name, value]` pairs.
pub fn inputs_of(v: &serde_json::Value) -> Vec<(String, String)> {
    match v {
        serde_json::Value::Object(m) => m.iter().map(|(k, x)| (k.clone(), value_text(x))).collect(),
        serde_json::Value::Array(a) => a
            .iter()
            .filter_map(|e| match e {
                serde_json::Value::Object(o) => {
                    let name = o.get("name").or_else(|| o.get("probability_name"))?;
                    let val = ["value", "p", "probability"]
                        .iter()
                        .find_map(|k| o.get(*k))
                        .map(value_text)
                        .unwrap_or_default();
                    Some((value_text(name), val))
                }
                serde_json::Value::Array(p) if p.len() == 2 => {
                    Some((value_text(&p[0]), value_text(&p[1])))
                }
                _ => None,
            })
            .collect(),
        _ => Vec::new(),
    }
}

fn capped<T: Clone>(v: &[T], max: usize, omitted: &mut usize) -> Vec<T> {
    *omitted += v.len().saturating_sub(max);
    v.iter().take(max).cloned().collect()
}

impl Why {
    pub fn of(r: &DecisionRecord, inputs: &[Option<serde_json::Value>]) -> Why {
        let mut omitted = 0;
        let proposals = r
            .proposals
            .iter()
            .take(MAX_PROPOSALS)
            .enumerate()
            .map(|(i, p)| {
                let all = inputs
                    .get(i)
                    .and_then(|x| x.as_ref())
                    .map(inputs_of)
                    .unwrap_or_default();
                ProposalWhy {
                    mdp: p.mdp.clone(),
                    state: p.state.clone(),
                    action: p.action.clone(),
                    actions: capped(&p.actions.to_names(), MAX_LIST, &mut omitted),
                    value: p.value,
                    inputs: capped(&all, MAX_INPUTS, &mut omitted),
                }
            })
            .collect();
        omitted += r.proposals.len().saturating_sub(MAX_PROPOSALS);
        omitted += r.probabilities.len().saturating_sub(MAX_INPUTS);
        let conflicts = r
            .conflicts
            .iter()
            .take(MAX_LIST)
            .map(|c| ConflictWhy {
                kept: c.kept.join("+"),
                dropped: c
                    .dropped
                    .iter()
                    .take(MAX_LIST)
                    .map(str::to_string)
                    .collect(),
                rule: c.rule.clone(),
            })
            .collect();
        omitted += r.conflicts.len().saturating_sub(MAX_LIST);
        let (degraded, dropped) = match &r.resources {
            Some(x) => (
                capped(&x.degraded, MAX_LIST, &mut omitted),
                capped(&x.dropped, MAX_LIST, &mut omitted),
            ),
            None => (Vec::new(), Vec::new()),
        };
        let guarantee = r.guarantee.as_ref().map(|g| {
            omitted += g.margins.len().saturating_sub(MAX_LIST);
            GuaranteeWhy {
                activity: g.activity_name.clone(),
                margins: g
                    .margins
                    .iter()
                    .take(MAX_LIST)
                    .map(|(k, m)| MarginWhy {
                        goal: k.clone(),
                        margin: *m,
                        target: g.goals.get(k).copied(),
                    })
                    .collect(),
                infeasible: g.infeasible,
                infeasible_reason: g.infeasible_reason.clone(),
                reallocation: g.reallocation.as_ref().map(|re| re.reason.clone()),
            }
        });
        Why {
            cycle: r.cycle,
            time_s: r.time_s,
            state: r.state.clone(),
            actions: capped(&r.actions.to_names(), MAX_LIST, &mut omitted),
            shell_actions: capped(&r.shell_actions.to_names(), MAX_LIST, &mut omitted),
            proposals,
            probabilities: r
                .probabilities
                .iter()
                .take(MAX_INPUTS)
                .map(|(k, v)| (k.clone(), *v))
                .collect(),
            conflicts,
            degraded,
            dropped,
            guarantee,
            omitted,
        }
    }

    /// Plain lines (no colour, caller cleans them for the terminal).
    pub fn lines(&self) -> Vec<String> {
        let mut o = vec![format!(
            "cycle {} at {:.2} s, state {}: actions {}",
            self.cycle,
            self.time_s,
            self.state,
            list(&self.actions)
        )];
        if !self.shell_actions.is_empty() {
            o.push(format!(
                "  shell (safety rule, not a model): {}",
                list(&self.shell_actions)
            ));
        }
        if self.proposals.is_empty() {
            o.push("  proposals: none recorded".into());
        }
        for p in &self.proposals {
            o.push(format!(
                "  proposal {} (state {}): {} -> {} (value {:.3})",
                p.mdp,
                p.state,
                p.action,
                list(&p.actions),
                p.value
            ));
            if !p.inputs.is_empty() {
                let read: Vec<String> =
                    p.inputs.iter().map(|(k, v)| format!("{k} = {v}")).collect();
                o.push(format!("    read: {}", read.join(", ")));
            }
        }
        if !self.probabilities.is_empty() && self.proposals.iter().all(|p| p.inputs.is_empty()) {
            let ps: Vec<String> = self
                .probabilities
                .iter()
                .map(|(k, v)| format!("{k} = {v:.3}"))
                .collect();
            o.push(format!("  probabilities this cycle: {}", ps.join(", ")));
        }
        if self.conflicts.is_empty() {
            o.push("  conflicts: none".into());
        }
        for c in &self.conflicts {
            o.push(format!(
                "  conflict: kept {}, gave way: {} (rule {})",
                c.kept,
                list(&c.dropped),
                c.rule
            ));
        }
        for d in &self.degraded {
            o.push(format!("  degraded: {d}"));
        }
        for d in &self.dropped {
            o.push(format!("  dropped for resources: {d}"));
        }
        match &self.guarantee {
            Some(g) => {
                let ms: Vec<String> = g
                    .margins
                    .iter()
                    .map(|m| match m.target {
                        Some(t) => format!("{} {:.2} of goal {:.2}", m.goal, m.margin, t),
                        None => format!("{} {:.2}", m.goal, m.margin),
                    })
                    .collect();
                o.push(format!(
                    "  guarantee ({}): margins {}",
                    g.activity,
                    if ms.is_empty() {
                        "none".into()
                    } else {
                        ms.join("; ")
                    }
                ));
                if g.infeasible {
                    o.push(format!(
                        "  guarantee says cannot: {}",
                        g.infeasible_reason
                            .as_deref()
                            .unwrap_or("no allocation meets every goal")
                    ));
                }
                if let Some(re) = &g.reallocation {
                    o.push(format!("  re-allocated: {re}"));
                }
            }
            None => o.push("  guarantee: none this cycle".into()),
        }
        if self.omitted > 0 {
            o.push(format!("  ({} more entries not shown)", self.omitted));
        }
        o
    }
}

fn list(v: &[String]) -> String {
    if v.is_empty() {
        "(none)".into()
    } else {
        v.join(", ")
    }
}
