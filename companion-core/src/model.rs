//! The decision model: everything compiled from params/ once at start-up (the mission, the
//! action catalogue, the health managers, the MDPs, the behaviour conflicts, the resources and
//! the PANORAMA mission), and which MDPs drive a run ([`ModelKind`]).

use crate::conflicts::BehaviourConflicts;
use crate::guarantee::MissionSpec;
use crate::health::HealthModel;
use crate::mission::{ActionCatalogue, MissionFile, MissionStates, Policy};
use crate::mission_mdp::MissionMdps;
use crate::resources::ResourceSpec;
use crate::spec::SpecError;

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
    /// The model's name as on the command line (`bfm`, `reference`, `monolithic`).
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

/// Everything loaded from params/ once at start-up. Immutable; each [`Core`] clones the parts it
/// updates in place (the battery DBN's slice, the MDPs' transition storage).
pub struct Model {
    /// params/mission.toml: horizon, rates, guarantee coupling, state projections.
    pub mission: MissionFile,
    /// The mission's states and phases (params/mission.toml), checked against the catalogue.
    pub states: MissionStates,
    /// The primitive actions (params/actions.toml).
    pub actions: ActionCatalogue,
    /// The health managers and observation mapping (params/health/, params/observations.toml).
    pub health: HealthModel,
    /// The MDPs of params/mdp/.
    pub mdps: MissionMdps,
    /// Behaviour conflict rules and policy priorities (params/policies.toml).
    pub conflicts: BehaviourConflicts,
    /// Platform, variant catalogue and resource policies.
    pub resources: ResourceSpec,
    /// The PANORAMA mission whose goals the guarantee stage watches.
    pub guarantee: MissionSpec,
    /// The decision policies params/policies.toml declares (`priority` tables), in file-key
    /// order; a [`Policy`] is an index into it.
    pub policies: Vec<String>,
    /// Each policy's resource policy (params/resource_policies.toml), resolved at load, in
    /// [`Model::policies`] order.
    resource_policies: Vec<fpga_model::ResourcePolicy>,
}

impl Model {
    /// The policy named `name`, or why there is none (the names params/policies.toml declares).
    pub fn policy(&self, name: &str) -> Result<Policy, String> {
        self.policies
            .iter()
            .position(|p| p == name)
            .map(Policy::from_index)
            .ok_or_else(|| {
                format!(
                    "unknown policy `{name}` (params/policies.toml: {})",
                    self.policies.join(", ")
                )
            })
    }

    /// The name of a policy of this model.
    pub fn policy_name(&self, policy: Policy) -> &str {
        self.policies.get(policy.index()).map_or("", String::as_str)
    }

    /// The resource policy a policy of this model arbitrates resources under.
    pub fn resource_policy(&self, policy: Policy) -> &fpga_model::ResourcePolicy {
        &self.resource_policies[policy.index()]
    }

    /// Compile the whole model from the params files (the shell reads them).
    pub fn load(files: &crate::spec::ParamsFiles) -> Result<Self, SpecError> {
        let params = files.dir();
        let mission = MissionFile::load(files)?;
        let actions = ActionCatalogue::load(files)?;
        let states = MissionStates::compile(&params.join("mission.toml"), &mission, &actions)?;
        let health = HealthModel::load(files)?;
        let names = health.publishes();
        let name_refs: Vec<&str> = names.iter().map(String::as_str).collect();
        let mdps = MissionMdps::load(files, &name_refs)?;
        crate::probabilities::check_vocabulary(params, &health, &mdps, &mission)?;
        crate::vocabulary::check_actions(params, &actions, &mdps)?;
        let ids: Vec<&str> = actions.actions.iter().map(|a| a.id.as_str()).collect();
        let conflicts = BehaviourConflicts::load(files, &params.join("policies.toml"), &ids)?;
        let resources = ResourceSpec::load(files)?;
        let guarantee = crate::guarantee::load_mission(files, &mission.guarantee.mission)?;
        let policies: Vec<String> = conflicts.policies().map(str::to_owned).collect();
        if policies.is_empty() || policies.len() > usize::from(u8::MAX) {
            return Err(SpecError::new(
                params.join("policies.toml"),
                "priority",
                format!("declares {} policies: 1 to 255 expected", policies.len()),
            ));
        }
        // Every policy arbitrates resources too: its resource policy must exist.
        let resource_policies = policies
            .iter()
            .map(|p| resources.policy(p).cloned())
            .collect::<Result<Vec<_>, _>>()?;
        let file = params.join("actions.toml");
        for (i, a) in actions.actions.iter().enumerate() {
            if let (Some(app), Some(v)) = (&a.app, &a.version)
                && !resources.catalogue.has_version(app, v)
            {
                return Err(SpecError::new(
                    &file,
                    format!("action[{i}]"),
                    format!("variant {app}/{v} is not in params/variants.toml"),
                ));
            }
        }
        Ok(Model {
            mission,
            states,
            actions,
            health,
            mdps,
            conflicts,
            resources,
            guarantee,
            policies,
            resource_policies,
        })
    }

    /// The MDP names a model kind runs concurrently.
    pub fn mdp_names(&self, kind: ModelKind) -> Vec<String> {
        match kind {
            ModelKind::Bfm => self.mdps.concurrent().to_vec(),
            ModelKind::Monolithic => self
                .mdps
                .monolithic()
                .map(str::to_owned)
                .into_iter()
                .collect(),
            ModelKind::Reference => self
                .mdps
                .reference()
                .map(str::to_owned)
                .into_iter()
                .collect(),
        }
    }
}
