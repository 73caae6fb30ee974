//! The route TOML `fly` flies, planned at the autopilot's own cruise speed: the plan made before
//! any socket takes `[derive].cruise_speed_mps` (params: ArduCopter's default WPNAV_SPEED); when
//! the autopilot reports its cruise parameter (`cruise_speed_mps`: WPNAV_SPEED, MPC_XY_CRUISE)
//! and it differs, the route's activities are derived again at that speed (through the vehicle
//! profile's leg model, as before) and the guarantee re-planned, on the ground only: a plan
//! changed in the air would restart the allocation from the take-off. The ground station and the
//! record are told (docs/guarantee.md). Climb and descent stay the profile's fitted rates (what
//! the vehicle does) or params': the autopilot's WPNAV_SPEED_UP / _DN are commanded maxima.

use super::{Decider, NOTICE, Shell};
use companion_core::record::Event;
use companion_core::spec::ParamsFiles;
use companion_link::Msg;
use companion_link::vehicle::Vehicle;
use std::path::PathBuf;
use std::time::Duration;

/// The observation the cruise speed comes in (companion-link's telemetry).
const CRUISE: &str = "cruise_speed_mps";

/// What the route's plan was made from, to make it again at another cruise speed.
pub(super) struct RouteReplan {
    files: ParamsFiles,
    zones: Option<PathBuf>,
    route: Option<PathBuf>,
    home: Option<String>,
    /// The cruise speed the plan in force was derived at (m/s) and whether it was params'.
    planned_cruise: f64,
    /// What the ground station must still be told (the STATUSTEXT rate cap may hold it back).
    unsaid: Option<(companion_link::dialect::MavSeverity, String)>,
}

impl RouteReplan {
    /// For a derived plan of the companion's own route (`None` for the typed plan or an
    /// autopilot mission, which plans at the autopilot's speeds itself).
    pub(super) fn new(args: &super::FlyArgs, files: &ParamsFiles) -> Option<Self> {
        let plan = args.plan.as_ref().filter(|p| !p.derived.is_empty())?;
        if args.flies_autopilot_mission() || plan.route_file.is_none() {
            return None;
        }
        // A route TOML only: its legs all fly at the cruise speed (a `.plan`'s DO_CHANGE_SPEED
        // items keep theirs, which `replay`'s re-plan does not tell apart).
        if let Some(r) = args.route_file() {
            let text = files.text(r).ok()?;
            let kind = companion_core::route_plan::detect_kind(r, text).ok()?;
            if kind != companion_core::route_plan::MissionSourceKind::RouteToml {
                return None;
            }
        }
        let mut files = files.clone();
        crate::route_input::add_plan_files(
            &mut files,
            None,
            args.zones.as_deref(),
            args.route_file(),
        );
        let planned_cruise =
            companion_core::guarantee::derive_settings(&files, crate::route_input::DERIVE_MISSION)
                .ok()?
                .cruise_speed_mps;
        Some(Self {
            files,
            zones: args.zones.clone(),
            route: args.route_file().map(PathBuf::from),
            home: args.home.clone(),
            planned_cruise,
            unsaid: None,
        })
    }

    /// Every turn: on the ground, the route re-planned when the autopilot reports a cruise
    /// speed other than the one planned with.
    pub(super) fn recheck<D: Decider>(
        &mut self,
        vehicle: &Vehicle,
        decider: &mut D,
        shell: &mut Shell,
    ) {
        let Some(cruise) = vehicle.telemetry().get(CRUISE) else {
            return;
        };
        if vehicle.telemetry().armed
            || !(cruise.is_finite() && cruise > 0.0)
            || (cruise - self.planned_cruise).abs() < 1e-6
        {
            return;
        }
        let was = self.planned_cruise;
        self.planned_cruise = cruise;
        let derived = crate::route_input::derive_at_cruise(
            &self.files,
            None,
            self.zones.as_deref(),
            self.route.as_deref(),
            self.home.as_deref(),
            Some(cruise),
        );
        let event = match derived {
            Ok(Some(d)) => {
                let summary = crate::route_input::summary(Some(&d), &d.spec);
                let feasible = decider.replace_mission(d.spec);
                let plan = match (summary.planned_energy_j, summary.planned_duration_s) {
                    (Some(e), Some(t)) if feasible => format!("{:.1} kJ {t:.0} s", e / 1000.0),
                    _ => "no allocation meets the goals".to_string(),
                };
                // The speed as read (replay plans again at `cruise_mps`).
                Event::RouteReplanned {
                    cruise_mps: cruise,
                    was_mps: was,
                    plan,
                }
            }
            Ok(None) => return,
            Err(e) => Event::RouteNotReplanned {
                cruise_mps: cruise,
                why: format!("{e:#}"),
            },
        };
        let text = event.to_string();
        tracing::info!("{text}");
        shell.pending_events.push(event);
        self.unsaid = Some((NOTICE, text));
    }

    /// Tell the ground station what is still unsaid, unless the rate cap holds it back again.
    pub(super) fn say(&mut self, shell: &mut Shell, now: Duration) -> Vec<Msg> {
        super::shell::say_until_said(shell, now, &mut self.unsaid)
    }
}
