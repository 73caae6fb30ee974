//! Everything `fly` loads from params before any socket opens.

use super::{FlyArgs, link_security};
use companion_core::mission::ActionCatalogue;
use companion_link::actions::{ActionTable, Flown, LinkParams, Route};
use companion_link::vehicle::{Vehicle, VehicleConfig};
use std::time::Duration;

/// Everything loaded from params before any socket opens.
pub struct FlySetup {
    pub link: LinkParams,
    pub actions: ActionTable,
    pub route: Route,
    pub key: Option<[u8; 32]>,
    /// Altitude the take_off action climbs to (m): MAV_CMD_NAV_TAKEOFF param 7, else the route's.
    pub takeoff_alt_m: f64,
    /// The mission's states and phases (params/mission.toml) the mission estimator moves through.
    pub states: companion_core::mission::MissionStates,
    /// The action catalogue (params/actions.toml) whose ids the shell's actions are.
    pub catalogue: ActionCatalogue,
    /// Where `--learn-cpt` may take the tracker's reports from.
    pub learning: link_security::LearningSource,
    /// The params as read (`fly --mission autopilot` plans the autopilot's mission on them).
    pub files: companion_core::spec::ParamsFiles,
    /// `fly --mission autopilot`: the speeds' params fallback (`[derive]`), checked at start.
    pub autopilot_speeds: Option<crate::autopilot_mission::ParamsSpeeds>,
    /// `fly --mission autopilot --zones FILE`: the zones it is planned among, checked at start.
    pub autopilot_zones: Option<crate::autopilot_mission::MissionZones>,
    /// The derived plan against the route flown (`route_activity`); `None` for the typed plan.
    pub route_progress: Option<super::route_progress::RouteProgress>,
    /// `[flight] restart_in_air = "resume_with_consent"`: the previous run's log in `--log-dir`
    /// (or why there is none), read before this run's folder was made.
    pub previous_run: Option<Result<super::resume::PreviousRun, String>>,
}

impl FlySetup {
    pub fn load(args: &FlyArgs) -> anyhow::Result<Self> {
        let dir = args
            .params
            .clone()
            .unwrap_or_else(crate::params::default_params_dir);
        // The same loader `check` and `simulate` use (crate::params), so they cannot drift.
        let mut files = crate::params::read_params_dir(&dir)?;
        if let Some(r) = args.route_file() {
            crate::params::add_file(&mut files, r);
        }
        Self::from_files(&files, args)
    }

    /// [`FlySetup::load`] on params already read (`--mission`'s file, when given, among them).
    pub fn from_files(
        files: &companion_core::spec::ParamsFiles,
        args: &FlyArgs,
    ) -> anyhow::Result<Self> {
        let learning = link_security::check_args(args)?;
        let catalogue = ActionCatalogue::load(files)?;
        let (link, actions, route, _) =
            crate::params::load_fly_files(files, args.route_file(), &catalogue)?;
        let key = match &args.signing_key {
            Some(p) => {
                crate::params::regular_file(p)
                    .map_err(|reason| anyhow::anyhow!("--signing-key {}: {reason}", p.display()))?;
                Some(link_security::load_signing_key(p)?)
            }
            None => None,
        };
        let states = companion_core::mission::MissionStates::load(files)?;
        let take_off = catalogue.id(states
            .actions()
            .action(companion_core::action_role::ActionRole::TakeOff));
        let takeoff_alt_m = take_off
            .and_then(|id| actions.steps(Flown::Action(id)))
            .and_then(|steps| {
                steps.iter().find_map(|st| match st {
                    companion_link::actions::Step::Command { command, params }
                        if *command == companion_link::dialect::MavCmd::MAV_CMD_NAV_TAKEOFF
                            && params[6] > 0.0 =>
                    {
                        Some(params[6] as f64)
                    }
                    _ => None,
                })
            })
            .unwrap_or(route.altitude_m);
        // The route progress follows the mission flown: the route TOML's waypoints, an
        // operator's `.plan` / WPL items by their upload seq; an autopilot mission's once it is
        // downloaded and planned (`autopilot_plan`).
        let route_progress = match (args.plan.as_ref(), args.route_file()) {
            (_, None) if args.flies_autopilot_mission() => None,
            (Some(plan), Some(file)) => match crate::operator_mission::parse(files, file)? {
                Some(planned) => {
                    let (_, seqs) = crate::operator_mission::operator_route(&planned, route.end);
                    let seq_of = |i: usize| seqs.iter().find(|s| s.0 == i).map(|s| s.1);
                    super::route_progress::RouteProgress::for_items(
                        &plan.derived,
                        0,
                        &planned.items,
                        seq_of,
                        None,
                        states.clone(),
                    )
                }
                None => super::route_progress::RouteProgress::new(plan, &route, states.clone()),
            },
            (Some(plan), None) => {
                super::route_progress::RouteProgress::new(plan, &route, states.clone())
            }
            (None, _) => None,
        };
        Ok(Self {
            previous_run: None,
            route_progress,
            link,
            actions,
            route,
            key,
            takeoff_alt_m,
            states,
            catalogue,
            learning,
            files: files.clone(),
            autopilot_speeds: args
                .flies_autopilot_mission()
                .then(|| crate::autopilot_mission::params_speeds(files, args.params.as_deref()))
                .transpose()?,
            autopilot_zones: (args.zones.as_deref())
                .filter(|_| args.flies_autopilot_mission())
                .map(|z| crate::autopilot_mission::MissionZones::load(files, z))
                .transpose()?,
        })
    }

    /// The protocol state `fly` drives, configured from these params (clones the action table
    /// and route, so a soak run can build a fresh one per mission).
    pub fn vehicle(&self, link_timeout: Duration) -> Vehicle {
        let cfg = VehicleConfig {
            link_timeout,
            streams: self.link.stream_ids(),
            streams_not_sent: self.link.streams_not_sent(),
            telemetry: self.link.telemetry.clone(),
            arm_wait: Duration::from_secs_f64(self.link.arm_wait_s),
            max_arm_attempts: self.link.max_arm_attempts,
            zone_radius_m: self.link.flight.zone_radius_m,
            zone_arrive_timeout: Duration::from_secs_f64(self.link.flight.zone_arrive_timeout_s),
            mode_confirm: Duration::from_secs_f64(self.link.flight.mode_confirm_s),
            max_mode_attempts: self.link.flight.max_mode_attempts,
            ground_altitude_m: self.link.flight.ground_altitude_m,
            tracker_onboard_only: self.learning == link_security::LearningSource::OnboardOnly,
            ..VehicleConfig::default()
        };
        Vehicle::new(cfg, self.actions.clone(), Some(self.route.clone()))
    }
}
