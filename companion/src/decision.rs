//! One decision cycle: observations -> evidence -> health -> concurrent MDPs -> behaviour
//! arbitration -> resource arbitration (fpga_model) -> guarantee (PANORAMA) -> plan + record.
//!
//! `step` is pure: everything it needs comes in as the loaded [`Model`], the [`MissionState`]
//! carried between cycles and one [`Observations`] snapshot. No clock, file or randomness.

use crate::health::HealthModel;
use crate::mission::{ActionCatalogue, ActionKind, MissionFile};
pub use crate::mission::Policy;
use crate::mission_mdp::{BehaviourConflicts, MissionMdps};
use crate::observations::Observations;
use crate::record::{DecisionRecord, MdpProposal, Plan};
use crate::resources::Resources;
use crate::spec::SpecError;
use std::collections::BTreeMap;
use std::path::Path;

/// Which decision model drives a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelKind {
    /// The three concurrent MDPs of section 6 (navigation, landing, tracking).
    Bfm,
    /// Figure 1's reference MDP: nominal tracking only.
    Reference,
    /// Section 5's monolithic MDP.
    Monolithic,
}

impl ModelKind {
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Bfm => "bfm",
            ModelKind::Reference => "reference",
            ModelKind::Monolithic => "monolithic",
        }
    }
}

impl std::str::FromStr for ModelKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "bfm" => Ok(ModelKind::Bfm),
            "reference" => Ok(ModelKind::Reference),
            "monolithic" => Ok(ModelKind::Monolithic),
            o => Err(format!("unknown model `{o}` (bfm, reference, monolithic)")),
        }
    }
}

/// Everything loaded from params/ once at start-up.
pub struct Model {
    pub mission: MissionFile,
    pub actions: ActionCatalogue,
    pub health: HealthModel,
    pub mdps: MissionMdps,
    pub conflicts: BehaviourConflicts,
    pub resources: Resources,
}

impl Model {
    pub fn load(params: &Path) -> Result<Self, SpecError> {
        let mission = MissionFile::load(params)?;
        let actions = ActionCatalogue::load(params)?;
        let health = HealthModel::load(params)?;
        let names: Vec<String> = health.publishes().iter().map(|s| s.to_string()).collect();
        let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let mdps = MissionMdps::load(params, &name_refs)?;
        let conflicts = BehaviourConflicts::load(params)?;
        let resources = Resources::load(params)?;
        let file = params.join("mission.toml");
        for (kind, list) in &mission.models {
            for (i, m) in list.iter().enumerate() {
                if mdps.get(m).is_none() {
                    return Err(SpecError::new(&file, format!("models.{kind}[{i}]"), format!("no MDP named `{m}` in params/mdp/")));
                }
            }
        }
        Ok(Model { mission, actions, health, mdps, conflicts, resources })
    }

    fn mdp_names(&self, kind: ModelKind) -> &[String] {
        self.mission.models.get(kind.name()).map_or(&[], Vec::as_slice)
    }
}

/// What the core carries from one cycle to the next.
pub struct MissionState {
    pub cycle: u64,
    pub health: crate::health::HealthState,
    pub platform: fpga_model::PlatformState,
    /// Set by the guarantee stage when no allocation meets the goals.
    pub guarantee_infeasible: bool,
}

/// A decision core bound to a model, a model kind and a policy: `step` once per cycle.
pub struct Core<'m> {
    pub model: &'m Model,
    pub kind: ModelKind,
    pub policy: Policy,
    pub state: MissionState,
}

impl<'m> Core<'m> {
    pub fn new(model: &'m Model, kind: ModelKind, policy: Policy) -> Self {
        let state = MissionState {
            cycle: 0,
            health: model.health.initial_state(),
            platform: model.resources.initial_state(),
            guarantee_infeasible: false,
        };
        Core { model, kind, policy, state }
    }

    pub fn step(&mut self, obs: &Observations) -> (Plan, DecisionRecord) {
        step(self.model, self.kind, self.policy, &mut self.state, obs)
    }
}

/// One decision cycle.
pub fn step(
    model: &Model,
    kind: ModelKind,
    policy: Policy,
    st: &mut MissionState,
    obs: &Observations,
) -> (Plan, DecisionRecord) {
    let mut rec = DecisionRecord {
        cycle: st.cycle,
        time_s: obs.time_s,
        state: obs.state.clone(),
        events: obs.events.clone(),
        observations: obs.values.clone(),
        ..Default::default()
    };
    st.cycle += 1;

    // evidence -> health
    rec.evidence = model.health.evidence(obs);
    rec.probabilities = model.health.evaluate(&mut st.health, &rec.evidence);
    if st.guarantee_infeasible {
        let cap = model.mission.guarantee.infeasible_p_battery;
        if let Some(p) = rec.probabilities.get_mut("P_battery") {
            *p = p.min(cap);
        }
    }

    // decision: every MDP of the model, solved at its projected state
    let mut merged: Vec<String> = Vec::new();
    for name in model.mdp_names(kind) {
        let local = model.mission.project(name, obs);
        let Some(p) = model.mdps.decide(name, &rec.probabilities, policy, local, model.mission.horizon) else {
            rec.events.push(format!("{name}: state `{local}` unknown to this MDP"));
            continue;
        };
        for a in &p.actions {
            if !merged.contains(a) {
                merged.push(a.clone());
            }
        }
        rec.proposals.push(p);
    }

    // behaviour arbitration
    let (kept, conflicts) = model.conflicts.resolve(&merged, policy);
    rec.conflicts = conflicts;

    // resource arbitration: application actions become variant requests on the platform
    let (actions, resources) = model.resources.arbitrate(&kept, policy, obs, &model.actions, &mut st.platform);
    for d in resources.degraded.iter().chain(&resources.dropped) {
        rec.events.push(d.clone());
    }
    rec.actions = actions;
    rec.resources = Some(resources);

    // plan
    let mut plan = Plan::default();
    for a in &rec.actions {
        if model.actions.get(a).is_some_and(|x| x.kind == ActionKind::Vehicle) {
            plan.vehicle_actions.push(a.clone());
        }
    }
    if let Some(r) = &rec.resources {
        plan.applications = r.placements.clone();
    }
    (plan, rec)
}

/// The decision table in the shape of the BFM paper's Tables 4 to 7: consecutive cycles with the
/// same state and action set are grouped; a row starts on any change or event.
pub fn table(records: &[DecisionRecord], model: &Model) -> String {
    let mut rows: Vec<[String; 5]> = Vec::new();
    let mut last: Option<(String, Vec<String>)> = None;
    for r in records {
        let key = (r.state.clone(), r.actions.clone());
        let events = r.events.join("; ");
        if last.as_ref() == Some(&key) && events.is_empty() {
            if let Some(row) = rows.last_mut() {
                let start = row[0].split('-').next().unwrap_or("").to_string();
                row[0] = format!("{start}-{}", r.cycle);
            }
            continue;
        }
        last = Some(key);
        let labels: Vec<&str> = r.actions.iter().map(|a| model.actions.label(a)).collect();
        rows.push([
            r.cycle.to_string(),
            r.state.clone(),
            labels.join(" / "),
            if events.is_empty() { "no event".into() } else { events },
            r.resources.as_ref().map_or("-".into(), |x| if x.summary.is_empty() { "-".into() } else { x.summary.clone() }),
        ]);
    }
    let header = ["step", "state", "set of actions", "events", "resources"];
    let mut width = header.map(str::len);
    for row in &rows {
        for (w, c) in width.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    width[2] = width[2].min(70);
    let mut out = String::new();
    let line = |cells: [&str; 5], out: &mut String| {
        for (i, c) in cells.iter().enumerate() {
            let pad = width[i].saturating_sub(c.chars().count());
            out.push_str(c);
            out.push_str(&" ".repeat(pad));
            out.push_str(if i < 4 { " | " } else { "\n" });
        }
    };
    line(header, &mut out);
    out.push_str(&width.iter().map(|w| "-".repeat(*w)).collect::<Vec<_>>().join("-+-"));
    out.push('\n');
    for row in &rows {
        line([&row[0], &row[1], &row[2], &row[3], &row[4]], &mut out);
    }
    out
}

/// Probabilities keyed by name, as the decision layer consumes them.
pub type Probabilities = BTreeMap<String, f64>;
