//! Everything `companion` loads from a params directory, in one call: `check`, `simulate` and
//! `fly` all start with [`Params::load`], so what one accepts the others accept, and a file that
//! stops `fly` also fails `check` with the same file, entry and reason (docs/params.md).

// The file helpers, under the paths callers have always used (`params::read_params_dir`, ...).
pub use crate::params_files::{
    add_file, default_params_dir, read_params_dir, regular_file, vehicle_profile,
};
use crate::world_spec::WorldSpec;
use companion_core::decision::Model;
use companion_core::mission::ActionKind;
use companion_core::named_slots::SortedNames;
use companion_core::spec::{ParamsFiles, SpecError};
use companion_link::actions::{ActionTable, Flown, LinkParams, Route};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The route `fly` follows when `--mission` names none, relative to the params directory.
pub const DEFAULT_ROUTE: &str = "missions/tracking_route.toml";

/// Every params file, loaded and cross-checked.
pub struct Params {
    pub dir: PathBuf,
    /// The files as read (what the model was compiled from).
    pub files: ParamsFiles,
    /// The decision core's model (mission, actions, health, MDPs, policies, resources, guarantee).
    pub model: Model,
    /// The simulated world (`world.toml`).
    pub world: WorldSpec,
    /// The MAVLink link settings (`link.toml`).
    pub link: LinkParams,
    /// Vehicle actions as MAVLink steps (`commands.toml`).
    pub commands: ActionTable,
    /// The route (`--mission FILE`, else [`DEFAULT_ROUTE`]).
    pub route: Route,
    pub route_file: PathBuf,
    /// In-flight CPT learning's bound (`learning.toml`, optional; `--learn-cpt`).
    pub learning: crate::learning_params::LearningParams,
    /// The observation vocabulary compiled at load (`vocabulary::Vocabulary`), shared by the
    /// link's telemetry, the simulated world and, through their snapshots, the core.
    pub vocabulary: SortedNames,
}

impl Params {
    /// Load and cross-check every file of `dir`; `route` overrides the default route file.
    pub fn load(dir: &Path, route: Option<&Path>) -> Result<Self, SpecError> {
        let mut files = read_params_dir(dir)?;
        if let Some(r) = route {
            add_file(&mut files, r);
        }
        Self::from_files(files, route)
    }

    /// Load and cross-check params already read (`route`, when given, must be in `files`).
    pub fn from_files(files: ParamsFiles, route: Option<&Path>) -> Result<Self, SpecError> {
        let dir = files.dir().to_path_buf();
        let model = Model::load(&files)?;
        let world = WorldSpec::load(&files)?;
        let (link, commands, route, route_file) = load_fly_files(&files, route, &model.actions)?;
        let learning = crate::learning_params::LearningParams::load(&files)?;
        let mut p = Params {
            vocabulary: companion_core::named_slots::no_names(),
            learning,
            dir,
            files,
            model,
            world,
            link,
            commands,
            route,
            route_file,
        };
        p.vocabulary = p.cross_check()?.names;
        // One vocabulary for the run: the link's telemetry and the world write by its slots.
        p.link.telemetry.vocabulary = Arc::clone(&p.vocabulary);
        p.world.vocabulary = Arc::clone(&p.vocabulary);
        Ok(p)
    }

    /// Checks between the link files and the model: every vehicle action the MDPs can choose
    /// has MAVLink steps, and the precedence list names only vehicle actions.
    fn cross_check(&self) -> Result<crate::vocabulary::Vocabulary, SpecError> {
        let commands = self.dir.join("commands.toml");
        let link = self.dir.join("link.toml");
        let vehicle: Vec<&str> = self
            .model
            .actions
            .actions
            .iter()
            .filter(|a| a.kind == ActionKind::Vehicle)
            .map(|a| a.id.as_str())
            .collect();
        for a in &vehicle {
            let steps = self.model.actions.id(a);
            if steps
                .and_then(|id| self.commands.steps(Flown::Action(id)))
                .is_none()
            {
                return Err(SpecError::new(
                    &commands,
                    *a,
                    format!("vehicle action `{a}` (params/actions.toml) has no MAVLink steps"),
                ));
            }
        }
        for (i, a) in self.link.vehicle_action_precedence.iter().enumerate() {
            if !vehicle.contains(&a.as_str()) {
                return Err(SpecError::new(
                    &link,
                    format!("vehicle_action_precedence[{i}]"),
                    format!(
                        "`{a}` is not a vehicle action in params/actions.toml ({})",
                        vehicle.join(", ")
                    ),
                ));
            }
        }
        self.check_mission_projections()?;
        self.check_performance_models()?;
        let code = crate::vocabulary::CodeLists::SHIPPED;
        crate::vocabulary::Vocabulary::compile(&self.sources(), &code)
    }

    /// The loaded files as the vocabulary checks see them.
    pub fn sources(&self) -> crate::vocabulary::Sources<'_> {
        crate::vocabulary::Sources {
            dir: &self.dir,
            files: &self.files,
            model: &self.model,
            world: &self.world,
            link: &self.link,
            commands: &self.commands,
        }
    }

    /// `mission.toml`'s projections against the MDPs: each names a loaded MDP and one of its
    /// states, and every shared mission state (`guarantee.activity_of_state`) reaches a state of
    /// every MDP, as itself or through an unconditional rule. A file cut short fails here.
    fn check_mission_projections(&self) -> Result<(), SpecError> {
        let file = self.dir.join("mission.toml");
        let mission = &self.model.mission;
        for (name, rules) in &mission.projection {
            let Some(mdp) = self.model.mdps.get(name) else {
                return Err(SpecError::new(
                    &file,
                    format!("projection.{name}"),
                    "no MDP of this name in params/mdp/index.toml",
                ));
            };
            for (i, r) in rules.iter().enumerate() {
                if !mdp.states().contains(&r.state) {
                    return Err(SpecError::new(
                        &file,
                        format!("projection.{name}[{i}].state"),
                        format!("`{}` is not a state of MDP `{name}`", r.state),
                    ));
                }
            }
        }
        for mdp in self.model.mdps.all() {
            let rules = mission.projection.get(mdp.name());
            for shared in mission.guarantee.activity_of_state.keys() {
                let covered = mdp.states().contains(shared)
                    || rules.is_some_and(|rs| {
                        rs.iter().any(|r| {
                            r.observation.is_none()
                                && (r.states.is_empty() || r.states.contains(shared))
                        })
                    });
                if !covered {
                    return Err(SpecError::new(
                        &file,
                        format!("projection.{}", mdp.name()),
                        format!(
                            "mission state `{shared}` (guarantee.activity_of_state) is not a \
                             state of MDP `{}` and no unconditional rule projects it",
                            mdp.name()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Every application in `variants.toml` and in `mission.toml`'s `rates` has a frame-rate
    /// model in `platform.toml` (without one its required rate would silently be unknown).
    fn check_performance_models(&self) -> Result<(), SpecError> {
        let platform = &self.model.resources.platform;
        let file = self.dir.join(companion_core::resources::PLATFORM_FILE);
        for app in self.model.resources.catalogue.apps() {
            if !platform.performance.contains_key(app) {
                return Err(SpecError::new(
                    &file,
                    format!("performance.{app}"),
                    format!("application `{app}` (params/variants.toml) has no frame-rate model"),
                ));
            }
        }
        for app in self.model.mission.rates.keys() {
            if !platform.performance.contains_key(app) {
                return Err(SpecError::new(
                    &file,
                    format!("performance.{app}"),
                    format!(
                        "application `{app}` (params/mission.toml rates) has no frame-rate model"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The files `fly` reads besides the model: `link.toml`, `commands.toml` (resolved against the
/// action catalogue `actions`) and the route (`route`, else [`DEFAULT_ROUTE`]).
pub fn load_fly_files(
    files: &ParamsFiles,
    route: Option<&Path>,
    actions: &companion_core::mission::ActionCatalogue,
) -> Result<(LinkParams, ActionTable, Route, PathBuf), SpecError> {
    let dir = files.dir();
    let link = LinkParams::load(files, &dir.join("link.toml"))?;
    let commands = ActionTable::load(files, &dir.join("commands.toml"), actions)?;
    let route_file = route.map_or_else(|| dir.join(DEFAULT_ROUTE), Path::to_path_buf);
    let end = companion_link::actions::RouteEnd::for_handoff(link.flight.handoff);
    let route = match crate::operator_mission::parse(files, &route_file)? {
        Some(planned) => crate::operator_mission::operator_route(&planned, end).0,
        None => Route {
            end,
            ..Route::load(files, &route_file)?
        },
    };
    Ok((link, commands, route, route_file))
}

/// The model alone from a params directory (tests, tools).
pub fn load_model(dir: &Path) -> Result<Model, SpecError> {
    Model::load(&read_params_dir(dir)?)
}
