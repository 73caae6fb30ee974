//! The mission as the decision core reads it: the primitive action catalogue (params/actions.toml)
//! and params/mission.toml (model sets, horizon, projections of the shared mission state).

pub use crate::action_role::{ActionRole, ActionRoles};
use crate::observations::Observations;
use crate::spec::{SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;

/// A decision policy (the BFM paper's safety-first and mission-first): one of the names
/// params/policies.toml declares, interned when the model loads. Get one by name with
/// `Model::policy` and its name back with `Model::policy_name`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Policy(u8);

impl Policy {
    /// Position of the policy in `Model::policies`.
    pub fn index(self) -> usize {
        self.0 as usize
    }

    pub(crate) fn from_index(i: usize) -> Self {
        Policy(i as u8)
    }
}

/// Whether a primitive action moves the vehicle or runs an application on the platform.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionKind {
    /// Becomes an autopilot command (params/commands.toml).
    Vehicle,
    /// Starts an application variant on the modeled platform.
    Application,
}

/// One primitive action (the paper's A1..A17).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Action {
    /// Action name used throughout params and the decision record (`take_off`).
    pub id: String,
    /// The paper's name for it (`A1`..`A17`).
    pub paper: String,
    /// Vehicle command or application.
    pub kind: ActionKind,
    /// The paper's wording (Tables 4-7), used in decision tables.
    pub label: String,
    /// Application variant it runs on the platform (fpga_model), if any.
    pub app: Option<String>,
    /// Version of `app` it runs (`V3`).
    pub version: Option<String>,
    /// What the action does for the code that acts on it (an [`ActionRole`] key); read through
    /// [`ActionCatalogue::roles`].
    pub role: Option<String>,
}

/// The primitive actions of params/actions.toml.
#[derive(Debug, Clone)]
pub struct ActionCatalogue {
    /// Every action, in file order.
    pub actions: Vec<Action>,
    /// The role each action plays, checked.
    pub roles: ActionRoles,
    /// Per action, the first action starting the same application variant (itself when it is
    /// the first or starts none): `variant_id`, asked every cycle, computed once.
    variant_of: Vec<crate::action_id::ActionId>,
    /// The actions' names by id, shared by every record's action lists ([`ActionCatalogue::names`]).
    names: crate::action_id::ActionNames,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ActionsFile {
    action: Vec<Action>,
}

impl ActionCatalogue {
    /// Read params/actions.toml from `files`.
    pub fn load(files: &crate::spec::ParamsFiles) -> Result<Self, SpecError> {
        let params = files.dir();
        let file = params.join("actions.toml");
        let f: ActionsFile = read_toml(files, &file)?;
        let mut seen = std::collections::BTreeSet::new();
        for (i, a) in f.action.iter().enumerate() {
            if !seen.insert(a.id.clone()) {
                return Err(SpecError::new(
                    &file,
                    format!("action[{i}].id"),
                    format!("duplicate action `{}`", a.id),
                ));
            }
            if a.app.is_some() != a.version.is_some() {
                return Err(SpecError::new(
                    &file,
                    format!("action[{i}]"),
                    "`app` and `version` go together",
                ));
            }
            if a.kind == ActionKind::Application && a.app.is_none() {
                return Err(SpecError::new(
                    &file,
                    format!("action[{i}]"),
                    "an application action needs `app` and `version`",
                ));
            }
        }
        let declared: Vec<(&str, Option<&str>)> = f
            .action
            .iter()
            .map(|a| (a.id.as_str(), a.role.as_deref()))
            .collect();
        let roles = ActionRoles::compile(&file, &declared)?;
        Ok(Self::new(f.action, roles))
    }

    /// A catalogue of `actions` with their roles (ids are `u16`: at most 65,535 actions get one).
    pub fn new(actions: Vec<Action>, roles: ActionRoles) -> Self {
        let variant_of = (0..actions.len().min(usize::from(u16::MAX)))
            .map(|i| {
                let a = &actions[i];
                let first = actions[..i]
                    .iter()
                    .position(|b| b.app == a.app && b.version == a.version)
                    .unwrap_or(i);
                crate::action_id::ActionId::from_index(first as u16)
            })
            .collect();
        let names = actions.iter().map(|a| a.id.clone()).collect();
        Self {
            actions,
            roles,
            variant_of,
            names,
        }
    }

    /// The actions' names by id, compiled once: the vocabulary a record's
    /// [`crate::action_id::ActionIds`] are written over.
    pub fn names(&self) -> &crate::action_id::ActionNames {
        &self.names
    }

    /// The first action of the catalogue starting the same application variant as `id` (or
    /// `id` itself): one id per variant, so equal ids mean an equal app and version.
    pub fn variant_id(&self, id: crate::action_id::ActionId) -> crate::action_id::ActionId {
        self.variant_of[id.index()]
    }

    /// The action with this id.
    pub fn get(&self, id: &str) -> Option<&Action> {
        self.actions.iter().find(|a| a.id == id)
    }

    /// The action's label, or the id itself when no action has it.
    pub fn label<'a>(&'a self, id: &'a str) -> &'a str {
        self.get(id).map_or(id, |a| a.label.as_str())
    }

    /// The primitive action that runs `app`/`version`, preferring one that keeps a tracking
    /// state of `states` (`track_v1` over `detect_target`, both on tracking V1's variant).
    pub fn for_variant(&self, app: &str, version: &str, states: &MissionStates) -> Option<&Action> {
        let mut it = self
            .actions
            .iter()
            .filter(|a| a.app.as_deref() == Some(app) && a.version.as_deref() == Some(version));
        let first = it.next()?;
        Some(
            it.find(|a| states.is_keeping_action(&a.id))
                .unwrap_or(first),
        )
    }
}

/// One projection rule (params/mission.toml).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProjectionRule {
    /// Shared mission states the rule applies in (empty: any).
    #[serde(default)]
    pub states: Vec<String>,
    /// Observation the rule tests, if any.
    pub observation: Option<String>,
    /// Matches when the observation is below this value.
    pub below: Option<f64>,
    /// Matches when the observation is above this value.
    pub above: Option<f64>,
    /// The MDP's state when the rule matches.
    pub state: String,
}

impl ProjectionRule {
    fn matches(&self, obs: &Observations) -> bool {
        let value = self.observation.as_deref().and_then(|name| obs.get(name));
        self.matches_reading(&obs.state, value)
    }

    /// Does the rule match in shared state `state`, its observation reading `value`?
    pub fn matches_reading(&self, state: &str, value: Option<f64>) -> bool {
        if !self.states.is_empty() && !self.states.iter().any(|s| s == state) {
            return false;
        }
        match &self.observation {
            None => true,
            Some(_) => value.is_some_and(|v| {
                self.below.is_none_or(|b| v < b) && self.above.is_none_or(|a| v > a)
            }),
        }
    }
}

/// How the decision core feeds and reads the PANORAMA guarantee stage.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuaranteeCoupling {
    /// The PANORAMA mission (params/missions/NAME.toml) whose margins are watched.
    pub mission: String,
    /// The named probability capped when no allocation meets the goals, and the cap.
    pub capped_probability: String,
    /// The cap put on `capped_probability` when no allocation meets the goals.
    pub infeasible_p_battery: f64,
    /// The end-oriented goal measuring time (its per-activity estimate tells how far into an
    /// activity the drone is).
    pub progress_goal: String,
    /// Shared mission state -> index of the activity being flown.
    pub activity_of_state: BTreeMap<String, usize>,
    /// Resource name (as in the mission file) -> observation that reports it failed (> 0.5).
    #[serde(default)]
    pub failures: BTreeMap<String, String>,
    /// The plan and what runs are one configuration (docs/guarantee.md "One configuration"):
    /// the implementations the plan names are requested, the plan follows the versions the
    /// models run, and a version without a feasible alternative is capped. `false` watches the
    /// margins only (the plan switched off, for comparison).
    #[serde(default = "binds_default")]
    pub binds: bool,
}

fn binds_default() -> bool {
    true
}

/// One shared mission state as params/mission.toml declares it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StateDecl {
    /// State name (`base`, `wp1`, `v3`, ...).
    pub name: String,
    /// Phase it belongs to, one of the file's `phases`.
    pub phase: String,
    /// In a tracking state: the action (params/actions.toml) that keeps the target in it.
    pub action: Option<String>,
}

/// The phase whose states keep the target: tracking time (the paper's Table 8) counts cycles
/// spent there, and each of its states names the tracking action flown in it.
pub const TRACKING_PHASE: &str = "tracking";

/// A point of the route the mission flies, which one declared state stands for (params/
/// mission.toml `route_states`): on the ground, to the first waypoint, through the intermediate
/// ones, at the last one (the tracking area), the target found, landing. The simulated world and
/// the flight shell's estimator move through the route by these roles, never by state names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RouteRole {
    /// On the ground before take-off.
    OnGround,
    /// Airborne, flying to the route's first waypoint.
    FirstLeg,
    /// Flying through the intermediate waypoints.
    BetweenWaypoints,
    /// The last waypoint reached: the tracking area, where the target is searched.
    LastWaypoint,
    /// The target seen but not yet tracked (or lost): tracking starts from it as from a
    /// tracking state.
    TargetFound,
    /// Landing (or returning to base): the end of the flight.
    Landing,
}

impl RouteRole {
    /// Every role, in flight order.
    pub const ALL: [RouteRole; 6] = [
        RouteRole::OnGround,
        RouteRole::FirstLeg,
        RouteRole::BetweenWaypoints,
        RouteRole::LastWaypoint,
        RouteRole::TargetFound,
        RouteRole::Landing,
    ];

    /// The role's key in params/mission.toml `route_states`.
    pub fn key(self) -> &'static str {
        match self {
            RouteRole::OnGround => "on_ground",
            RouteRole::FirstLeg => "first_leg",
            RouteRole::BetweenWaypoints => "between_waypoints",
            RouteRole::LastWaypoint => "last_waypoint",
            RouteRole::TargetFound => "target_found",
            RouteRole::Landing => "landing",
        }
    }

    /// The role whose key is `key`.
    pub fn from_key(key: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.key() == key)
    }
}

/// Which declared state plays each [`RouteRole`] (params/mission.toml `route_states`, checked):
/// every role has one, and no state plays two.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RouteStates {
    /// Indexed by `RouteRole as usize`.
    names: [String; RouteRole::ALL.len()],
}

impl RouteStates {
    /// The state standing for `role`.
    pub fn state(&self, role: RouteRole) -> &str {
        &self.names[role as usize]
    }

    /// Whether `state` is the one standing for `role`.
    pub fn is(&self, role: RouteRole, state: &str) -> bool {
        self.state(role) == state
    }

    /// The role `state` plays, if any.
    pub fn role_of(&self, state: &str) -> Option<RouteRole> {
        RouteRole::ALL.into_iter().find(|&r| self.is(r, state))
    }

    /// Check `table` (role key -> state name) against the declared states `declared`; `file`
    /// names the file in errors.
    fn compile(
        file: &std::path::Path,
        table: &BTreeMap<String, String>,
        declared: &[StateInfo],
    ) -> Result<Self, SpecError> {
        let roles = || {
            RouteRole::ALL
                .iter()
                .map(|r| r.key())
                .collect::<Vec<_>>()
                .join(", ")
        };
        if let Some(k) = table.keys().find(|k| RouteRole::from_key(k).is_none()) {
            return Err(SpecError::new(
                file,
                format!("route_states.{k}"),
                format!("`{k}` is not a route role (roles: {})", roles()),
            ));
        }
        let mut names: Vec<String> = Vec::with_capacity(RouteRole::ALL.len());
        for role in RouteRole::ALL {
            let entry = format!("route_states.{}", role.key());
            let Some(name) = table.get(role.key()) else {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "missing: every route role names the declared state standing for it (roles: {})",
                        roles()
                    ),
                ));
            };
            let Some(info) = declared.iter().find(|s| &s.name == name) else {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!("`{name}` is not a declared state"),
                ));
            };
            if info.phase == TRACKING_PHASE {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "`{name}` is a `{TRACKING_PHASE}` state: the route's states are the ones around tracking"
                    ),
                ));
            }
            if let Some(i) = names.iter().position(|n| n == name) {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "`{name}` already plays the route role `{}`",
                        RouteRole::ALL[i].key()
                    ),
                ));
            }
            names.push(name.clone());
        }
        let names = names
            .try_into()
            .expect("one name per route role, pushed in the loop above");
        Ok(Self { names })
    }

    /// The route of the decision logs written before params/mission.toml declared its states.
    fn undeclared() -> Self {
        Self {
            names: ["base", "wp1", "wpi", "wpf", "target", "landing"].map(String::from),
        }
    }
}

/// One mission state, compiled: its phase and, in a tracking state, the action that keeps the
/// target there and that action's variant version.
#[derive(Debug, Clone, PartialEq, Eq)]
struct StateInfo {
    name: String,
    phase: String,
    keeping: Option<(String, String)>,
}

/// The mission's states and phases (params/mission.toml `phases`, `states`), checked against the
/// action catalogue: the one answer to "which phase is this state in" and "which tracking state
/// does this action set aim at" for the simulated world, the flight shell and the review.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MissionStates {
    phases: Vec<String>,
    states: Vec<StateInfo>,
    route: RouteStates,
    actions: ActionRoles,
}

impl Default for MissionStates {
    /// The rule of params sets that declare no states (decision logs written before
    /// `mission.toml` declared them): see [`MissionStates::undeclared`].
    fn default() -> Self {
        Self::undeclared()
    }
}

impl MissionStates {
    /// Read params/mission.toml and params/actions.toml.
    pub fn load(files: &crate::spec::ParamsFiles) -> Result<Self, SpecError> {
        let mission = MissionFile::load(files)?;
        let actions = ActionCatalogue::load(files)?;
        Self::compile(&files.dir().join("mission.toml"), &mission, &actions)
    }

    /// Check `mission`'s declared states against the catalogue. A params set that declares no
    /// states is refused: only old decision logs go without (see [`MissionStates::undeclared`]).
    pub fn compile(
        file: &std::path::Path,
        mission: &MissionFile,
        actions: &ActionCatalogue,
    ) -> Result<Self, SpecError> {
        if mission.states.is_empty() {
            return Err(SpecError::new(file, "states", "declares no mission state"));
        }
        let mut phases: Vec<String> = Vec::new();
        for (i, p) in mission.phases.iter().enumerate() {
            if phases.contains(p) {
                return Err(SpecError::new(
                    file,
                    format!("phases[{i}]"),
                    format!("duplicate phase `{p}`"),
                ));
            }
            phases.push(p.clone());
        }
        let mut states: Vec<StateInfo> = Vec::new();
        for (i, d) in mission.states.iter().enumerate() {
            let entry = format!("states[{i}]");
            if states.iter().any(|s| s.name == d.name) {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!("duplicate state `{}`", d.name),
                ));
            }
            if !phases.contains(&d.phase) {
                return Err(SpecError::new(
                    file,
                    entry,
                    format!(
                        "state `{}` is in the unknown phase `{}` (phases: {})",
                        d.name,
                        d.phase,
                        phases.join(", ")
                    ),
                ));
            }
            let keeping = match (&d.action, d.phase == TRACKING_PHASE) {
                (None, false) => None,
                (None, true) => {
                    return Err(SpecError::new(
                        file,
                        entry,
                        format!("tracking state `{}` names no `action`", d.name),
                    ));
                }
                (Some(_), false) => {
                    return Err(SpecError::new(
                        file,
                        entry,
                        format!("only a `{TRACKING_PHASE}` state names an `action`"),
                    ));
                }
                (Some(a), true) => {
                    if actions
                        .roles
                        .role_of(a)
                        .is_some_and(|r| r != ActionRole::Track)
                    {
                        return Err(SpecError::new(
                            file,
                            format!("states[{i}].action"),
                            format!(
                                "`{a}` keeps a tracking state but plays the role `{}`, not `{}`",
                                actions.roles.role_of(a).map_or("", ActionRole::key),
                                ActionRole::Track.key()
                            ),
                        ));
                    }
                    let version =
                        actions
                            .get(a)
                            .and_then(|x| x.version.clone())
                            .ok_or_else(|| {
                                SpecError::new(
                                    file,
                                    format!("states[{i}].action"),
                                    format!(
                                        "`{a}` is not an application action of params/actions.toml"
                                    ),
                                )
                            })?;
                    if states
                        .iter()
                        .any(|s| s.keeping.as_ref().is_some_and(|(k, _)| k == a))
                    {
                        return Err(SpecError::new(
                            file,
                            format!("states[{i}].action"),
                            format!("`{a}` already keeps another state"),
                        ));
                    }
                    Some((a.clone(), version))
                }
            };
            states.push(StateInfo {
                name: d.name.clone(),
                phase: d.phase.clone(),
                keeping,
            });
        }
        // The rest of mission.toml names shared states too: they must be declared ones.
        let declared = |s: &str| states.iter().any(|x| x.name == s);
        for s in mission.guarantee.activity_of_state.keys() {
            if !declared(s) {
                return Err(SpecError::new(
                    file,
                    "guarantee.activity_of_state",
                    format!("`{s}` is not a declared state"),
                ));
            }
        }
        for (name, rules) in &mission.projection {
            for (i, r) in rules.iter().enumerate() {
                if let Some(s) = r.states.iter().find(|s| !declared(s)) {
                    return Err(SpecError::new(
                        file,
                        format!("projection.{name}[{i}].states"),
                        format!("`{s}` is not a declared state"),
                    ));
                }
            }
        }
        let route = RouteStates::compile(file, &mission.route_states, &states)?;
        Ok(Self {
            phases,
            states,
            route,
            actions: actions.roles.clone(),
        })
    }

    /// The rule used before mission.toml declared its states, kept only to read the decision
    /// logs written then: `v0`..`v9` are the tracking states, kept by `track_v0`..`track_v9`
    /// (versions `V0`..`V9`); every other state is its own phase; the route is `base`, `wp1`,
    /// `wpi`, `wpf`, `target`, `landing`.
    pub fn undeclared() -> Self {
        let states = (0..10)
            .map(|n| StateInfo {
                name: format!("v{n}"),
                phase: TRACKING_PHASE.into(),
                keeping: Some((format!("track_v{n}"), format!("V{n}"))),
            })
            .collect();
        Self {
            phases: Vec::new(),
            states,
            route: RouteStates::undeclared(),
            actions: ActionRoles::undeclared(),
        }
    }

    /// The declared phases, in flight order (empty for [`MissionStates::undeclared`]).
    pub fn phases(&self) -> &[String] {
        &self.phases
    }

    /// Whether `phase` is one of the mission's phases.
    pub fn has_phase(&self, phase: &str) -> bool {
        self.phases.iter().any(|p| p == phase)
    }

    /// Whether `state` is a declared state.
    pub fn has_state(&self, state: &str) -> bool {
        self.states.iter().any(|s| s.name == state)
    }

    /// The phase `state` is in; a state not declared is taken as its own phase.
    pub fn phase<'a>(&'a self, state: &'a str) -> &'a str {
        self.states
            .iter()
            .find(|s| s.name == state)
            .map_or(state, |s| s.phase.as_str())
    }

    /// Whether `state` keeps the target (is in the tracking phase).
    pub fn is_tracking(&self, state: &str) -> bool {
        self.phase(state) == TRACKING_PHASE
    }

    /// Which state stands for each point of the route.
    pub fn route(&self) -> &RouteStates {
        &self.route
    }

    /// The role each primitive action plays (params/actions.toml `role`).
    pub fn actions(&self) -> &ActionRoles {
        &self.actions
    }

    /// The state standing for the route's `role`.
    pub fn route_state(&self, role: RouteRole) -> &str {
        self.route.state(role)
    }

    /// Whether `state` is `role`'s state.
    pub fn is_route(&self, role: RouteRole, state: &str) -> bool {
        self.route.is(role, state)
    }

    /// Whether the target is in sight in `state`: found, or kept in a tracking state. Tracking
    /// starts from such a state.
    pub fn is_target_in_sight(&self, state: &str) -> bool {
        self.route.is(RouteRole::TargetFound, state) || self.is_tracking(state)
    }

    /// The tracking state the action set aims at, and the tracking variant version flown there:
    /// the first action that keeps a tracking state.
    pub fn tracking_target<I>(&self, actions: I) -> Option<(&str, &str)>
    where
        I: IntoIterator,
        I::Item: AsRef<str>,
    {
        actions.into_iter().find_map(|a| {
            self.states.iter().find_map(|s| match &s.keeping {
                Some((k, v)) if k == a.as_ref() => Some((s.name.as_str(), v.as_str())),
                _ => None,
            })
        })
    }

    /// Whether action `id` keeps some tracking state.
    pub fn is_keeping_action(&self, id: &str) -> bool {
        self.tracking_target(&[id]).is_some()
    }
}

/// Longest MDP horizon (steps) `mission.toml` may ask for (the BFM paper uses 100).
pub const MAX_HORIZON: usize = 10_000;

/// params/mission.toml.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MissionFile {
    /// Finite horizon of every MDP solve (steps; at most [`MAX_HORIZON`]).
    pub horizon: usize,
    /// The mission's phases, in flight order; read through [`MissionStates`].
    #[serde(default)]
    pub phases: Vec<String>,
    /// The shared mission states and their phases; read through [`MissionStates`].
    #[serde(default)]
    pub states: Vec<StateDecl>,
    /// Route role key (`on_ground`, ...) -> the declared state standing for it; read through
    /// [`MissionStates`] (see [`RouteRole`]).
    #[serde(default)]
    pub route_states: BTreeMap<String, String>,
    /// Named probabilities published for the decision record and the review only (no MDP reads
    /// them); every other published name must have a reader (see `crate::probabilities`).
    #[serde(default)]
    pub recorded_probabilities: Vec<String>,
    /// Application -> the observation (m/s) giving the relative speed its frame rate must follow
    /// (the BFM paper's section 4.3.2 performance constraint; formula in params/platform.toml).
    pub rates: BTreeMap<String, String>,
    /// How the decision core feeds and reads the PANORAMA guarantee.
    pub guarantee: GuaranteeCoupling,
    /// MDP name -> rules projecting the shared mission state onto that MDP's states, tried in order.
    #[serde(default)]
    pub projection: BTreeMap<String, Vec<ProjectionRule>>,
}

impl MissionFile {
    /// Read params/mission.toml from `files`.
    pub fn load(files: &crate::spec::ParamsFiles) -> Result<Self, SpecError> {
        let params = files.dir();
        let file = params.join("mission.toml");
        let m: MissionFile = read_toml(files, &file)?;
        // Each decision cycle solves this many stages: bounded so a typo cannot stall it.
        if !(1..=MAX_HORIZON).contains(&m.horizon) {
            return Err(SpecError::new(
                &file,
                "horizon",
                format!(
                    "{} is out of range: must be in 1..={MAX_HORIZON}",
                    m.horizon
                ),
            ));
        }
        for (name, rules) in &m.projection {
            for (i, r) in rules.iter().enumerate() {
                if r.observation.is_some() && r.below.is_none() && r.above.is_none() {
                    return Err(SpecError::new(
                        &file,
                        format!("projection.{name}[{i}]"),
                        "an observation rule needs `below` or `above`",
                    ));
                }
            }
        }
        if !(0.0..=1.0).contains(&m.guarantee.infeasible_p_battery) {
            return Err(SpecError::new(
                &file,
                "guarantee.infeasible_p_battery",
                "is not a probability",
            ));
        }
        Ok(m)
    }

    /// MDP `mdp`'s projection rules, first match first (none: the shared state is its state).
    pub fn projection_rules(&self, mdp: &str) -> &[ProjectionRule] {
        self.projection.get(mdp).map_or(&[], Vec::as_slice)
    }

    /// The state MDP `mdp` is in, given the shared state and observations.
    pub fn project<'a>(&'a self, mdp: &str, obs: &'a Observations) -> &'a str {
        self.projection
            .get(mdp)
            .and_then(|rules| rules.iter().find(|r| r.matches(obs)))
            .map_or(obs.state.as_str(), |r| r.state.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn obs(state: &str, vals: &[(&str, f64)]) -> Observations {
        let mut o = Observations {
            state: state.into(),
            ..Default::default()
        };
        for (k, v) in vals {
            o.set(k, *v);
        }
        o
    }

    #[test]
    fn projection_rules_first_match_wins_and_fall_back_to_shared_state() {
        let params = crate::shipped::params();
        let m = MissionFile::load(&params).unwrap();
        // An obstacle closer than 10 m puts navigation in obstacle_detected whatever the phase.
        assert_eq!(
            m.project("navigation", &obs("v3", &[("obstacle_m", 4.0)])),
            "obstacle_detected"
        );
        // Tracking phases hover at the final waypoint for navigation.
        assert_eq!(
            m.project("navigation", &obs("v3", &[("obstacle_m", 50.0)])),
            "wpf"
        );
        // Landing: a found T zone wins over the plain hover projection.
        assert_eq!(
            m.project("landing", &obs("v1", &[("zone_t_found", 1.0)])),
            "zone_t_ok"
        );
        assert_eq!(
            m.project("landing", &obs("v1", &[("zone_t_found", 0.0)])),
            "wpf"
        );
        // No rule: the shared state itself.
        assert_eq!(m.project("tracking", &obs("v2", &[])), "v2");
        assert_eq!(m.project("navigation", &obs("wpi", &[])), "wpi");
    }

    /// The shipped params with mission.toml's `[route_states]` table replaced by `table` (TOML
    /// lines; empty: no table).
    fn with_route_states(table: &str) -> crate::spec::ParamsFiles {
        let mut files = crate::shipped::params();
        let path = files.dir().join("mission.toml");
        let text = files.text(&path).unwrap().to_string();
        let start = text.find("[route_states]\n").unwrap();
        let end = start + text[start..].find("\n\n").unwrap();
        let replaced = format!("{}{table}{}", &text[..start], &text[end..]);
        files.insert(path, replaced);
        files
    }

    const SHIPPED_ROUTE: &str = "[route_states]\non_ground = \"base\"\nfirst_leg = \"wp1\"\n\
        between_waypoints = \"wpi\"\nlast_waypoint = \"wpf\"\ntarget_found = \"target\"\n\
        landing = \"landing\"";

    #[test]
    fn shipped_route_states_name_each_point_of_the_route() {
        let states = MissionStates::load(&crate::shipped::params()).unwrap();
        let route = states.route();
        let names: Vec<&str> = RouteRole::ALL.iter().map(|&r| route.state(r)).collect();
        assert_eq!(
            names,
            ["base", "wp1", "wpi", "wpf", "target", "landing"],
            "the route of the paper's Figure 1, in flight order"
        );
        assert_eq!(route.role_of("wpf"), Some(RouteRole::LastWaypoint));
        assert_eq!(route.role_of("v3"), None);
        assert!(states.is_target_in_sight("target") && states.is_target_in_sight("v3"));
        assert!(!states.is_target_in_sight("wpf"));
        // The table rebuilt from SHIPPED_ROUTE is the shipped one (the helper replaces it whole).
        let same = MissionStates::load(&with_route_states(SHIPPED_ROUTE)).unwrap();
        assert_eq!(same, states);
        // The rule of old logs flies the same route.
        assert_eq!(MissionStates::undeclared().route(), route);
    }

    #[test]
    fn route_states_follow_the_names_the_params_give() {
        // `wp1` and `wpi` swap roles: the route is read from the table, not from the names.
        let files = with_route_states(
            &SHIPPED_ROUTE
                .replace("\"wp1\"", "\"x\"")
                .replace("\"wpi\"", "\"wp1\"")
                .replace("\"x\"", "\"wpi\""),
        );
        let states = MissionStates::load(&files).unwrap();
        assert_eq!(states.route_state(RouteRole::FirstLeg), "wpi");
        assert_eq!(states.route_state(RouteRole::BetweenWaypoints), "wp1");
        assert!(states.is_route(RouteRole::FirstLeg, "wpi"));
    }

    fn route_error(table: &str) -> SpecError {
        MissionStates::load(&with_route_states(table)).unwrap_err()
    }

    #[test]
    fn a_missing_route_role_is_refused_with_its_entry() {
        let e = route_error(&SHIPPED_ROUTE.replace("last_waypoint = \"wpf\"\n", ""));
        assert!(e.file.ends_with("mission.toml"), "{e}");
        assert_eq!(e.entry, "route_states.last_waypoint");
        assert!(e.reason.contains("missing"), "{e}");
        // No table at all: the first role is the one reported.
        let e = route_error("");
        assert_eq!(e.entry, "route_states.on_ground");
    }

    #[test]
    fn a_route_role_naming_an_undeclared_state_is_refused() {
        let e = route_error(&SHIPPED_ROUTE.replace("\"target\"", "\"tgt\""));
        assert_eq!(e.entry, "route_states.target_found");
        assert!(e.reason.contains("`tgt` is not a declared state"), "{e}");
    }

    #[test]
    fn a_state_playing_two_route_roles_is_refused() {
        let e = route_error(&SHIPPED_ROUTE.replace("\"wp1\"", "\"wpi\""));
        // `wpi` plays first_leg first, then between_waypoints again.
        assert_eq!(e.entry, "route_states.between_waypoints");
        assert!(
            e.reason
                .contains("`wpi` already plays the route role `first_leg`"),
            "{e}"
        );
    }

    #[test]
    fn an_unknown_route_role_is_refused() {
        let e = route_error(&format!("{SHIPPED_ROUTE}\nhovering = \"wpf\""));
        assert_eq!(e.entry, "route_states.hovering");
        assert!(e.reason.contains("not a route role"), "{e}");
    }

    #[test]
    fn a_tracking_state_cannot_play_a_route_role() {
        let e = route_error(&SHIPPED_ROUTE.replace("\"target\"", "\"v0\""));
        assert_eq!(e.entry, "route_states.target_found");
        assert!(e.reason.contains("`v0` is a `tracking` state"), "{e}");
    }

    #[test]
    fn action_catalogue_rejects_duplicates_and_half_variants() {
        let mut files = crate::spec::ParamsFiles::new("p");
        files.insert(
            "p/actions.toml",
            "[[action]]\nid='a'\npaper='A1'\nkind='vehicle'\nlabel='a'\n[[action]]\nid='a'\npaper='A2'\nkind='vehicle'\nlabel='b'\n",
        );
        let e = ActionCatalogue::load(&files).unwrap_err();
        assert_eq!(e.entry, "action[1].id");
        files.insert(
            "p/actions.toml",
            "[[action]]\nid='a'\npaper='A1'\nkind='application'\nlabel='a'\napp='tracking'\n",
        );
        let e = ActionCatalogue::load(&files).unwrap_err();
        assert_eq!(e.entry, "action[0]");
        assert!(e.reason.contains("together"), "{}", e.reason);
    }
}
