//! Home before plan: a route relative to home among absolute zones (`--zones` of longitude /
//! latitude polygons, no `--home`) cannot be planned until the vehicle's home is known. `fly`
//! then waits for the autopilot's HOME_POSITION (or, before it, the first GPS fix, said), derives
//! the plan from there and hands it to the decider's guarantee; until the plan exists a start is
//! refused (`LaunchRefusal::MissionNotPlanned`), never granted on an unplanned mission.

use super::{Decider, NOTICE, Shell, WARNING};
use companion_core::record::Event;
use companion_core::spec::ParamsFiles;
use companion_link::Msg;
use companion_link::dialect::MavSeverity;
use companion_link::vehicle::Vehicle;
use std::path::PathBuf;
use std::time::Duration;

/// Why no start is granted before home is known.
pub(super) const WAITING_FOR_HOME: &str =
    "waiting for the autopilot's home position to place the route among the zones";

/// The plan to make once home is known, and what the ground station must still be told.
pub(super) struct HomePlan {
    files: ParamsFiles,
    zones: PathBuf,
    route: Option<PathBuf>,
    states: companion_core::mission::MissionStates,
    route_def: companion_link::actions::Route,
    planned: bool,
    unsaid: Option<(MavSeverity, String)>,
}

impl HomePlan {
    /// Waiting for home: the start stays refused until the plan stands.
    pub(super) fn new(
        setup: &super::FlySetup,
        args: &super::FlyArgs,
        shell: &mut Shell,
    ) -> Option<Self> {
        if !args.plan_waits_for_home {
            return None;
        }
        let zones = args.zones.clone()?;
        let mut files = setup.files.clone();
        crate::route_input::add_plan_files(&mut files, None, Some(&zones), args.route_file());
        shell.mission_unplanned = Some(WAITING_FOR_HOME.to_string());
        Some(Self {
            files,
            zones,
            route: args.route_file().map(PathBuf::from),
            states: setup.states.clone(),
            route_def: setup.route.clone(),
            planned: false,
            unsaid: None,
        })
    }

    /// Every turn until planned: home known (HOME_POSITION, else the first GPS fix), plan.
    pub(super) fn recheck<D: Decider>(
        &mut self,
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) {
        if self.planned {
            return;
        }
        let t = vehicle.telemetry();
        let (home, from) = match (t.home, t.position) {
            (Some((lat, lon, _)), _) => ((lat, lon), "HOME_POSITION"),
            (None, Some(p)) if p.lat_e7 != 0 || p.lon_e7 != 0 => (
                (p.lat_e7, p.lon_e7),
                "the first GPS fix, no HOME_POSITION yet",
            ),
            _ => return,
        };
        self.planned = true;
        let home = format!("{},{}", f64::from(home.0) / 1e7, f64::from(home.1) / 1e7);
        let derived = crate::route_input::derive(
            &self.files,
            None,
            Some(&self.zones),
            self.route.as_deref(),
            Some(&home),
        );
        let (event, severity) = match derived {
            Ok(Some(d)) => {
                let spec = d.spec.clone();
                let summary = crate::route_input::summary(Some(&d), &spec);
                shell.route_progress = super::route_progress::RouteProgress::new(
                    &summary,
                    &self.route_def,
                    self.states.clone(),
                );
                let feasible = decider.replace_mission(spec);
                shell.mission_unplanned =
                    (!feasible).then(|| "the guarantee finds no allocation for it".to_string());
                tracing::info!("{}", crate::route_input::summary_line(&summary));
                let planned = Event::MissionPlannedFromHome {
                    home: from.to_string(),
                    activities: summary.activities,
                    energy_j: summary.planned_energy_j,
                    duration_s: summary.planned_duration_s,
                };
                (planned, NOTICE)
            }
            Ok(None) => return,
            Err(e) => {
                let why = format!("{e:#}");
                shell.mission_unplanned = Some(why.clone());
                (Event::MissionRefused(why), WARNING)
            }
        };
        let text = event.to_string();
        tracing::info!("{text}");
        shell.pending_events.push(event);
        self.unsaid = Some((severity, text));
    }

    /// Tell the ground station what is still unsaid, unless the rate cap holds it back again.
    pub(super) fn say(&mut self, shell: &mut Shell, now: Duration) -> Vec<Msg> {
        super::shell::say_until_said(shell, now, &mut self.unsaid)
    }
}
