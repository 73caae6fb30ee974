//! `companion fly`'s command-line arguments.

use companion_link::liveness::parse_duration;
use companion_link::url::{self, ConnectUrl};
use std::path::PathBuf;
use std::time::Duration;

/// `companion fly` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct FlyArgs {
    /// Autopilot connection: serial:/dev/ttyAMA0:921600, udpin:0.0.0.0:14550, udpout:HOST:PORT,
    /// tcp:HOST:PORT, tcpin:ADDR:PORT.
    #[arg(long, value_parser = url::parse)]
    pub connect: ConnectUrl,
    /// Route for follow_trajectory (default params/missions/tracking_route.toml), or
    /// `autopilot`: fly the mission on the vehicle as a ground station uploaded it (nothing
    /// uploaded; planned once downloaded, re-planned when it changes; docs/mavlink.md).
    #[arg(long)]
    pub mission: Option<PathBuf>,
    /// Arbitration policy: a policy of params/policies.toml, safety (safety-first) or mission
    /// (mission-first); checked when the params load.
    #[arg(long, default_value = "safety")]
    pub policy: String,
    /// MAVLink 2 signing key (32 raw bytes or 64 hex digits): sign outgoing frames, refuse
    /// unsigned commands addressed to us.
    #[arg(long)]
    pub signing_key: Option<PathBuf>,
    /// Second MAVLink connection carrying onboard monitors (NAMED_VALUE_FLOAT, ...); on a serial
    /// port or a loopback address it is a dedicated onboard link (--learn-cpt may learn from it).
    #[arg(long, value_parser = url::parse)]
    pub onboard: Option<ConnectUrl>,
    /// The operator declares the --onboard link a private onboard wire (e.g. a direct Ethernet
    /// cable to the tracker, nothing else on it): a dedicated onboard link for --learn-cpt even
    /// on a network address.
    #[arg(long, requires = "onboard")]
    pub onboard_private: bool,
    /// Silence after which the autopilot counts as lost (e.g. 3s, 500ms).
    #[arg(long, default_value = "3s", value_parser = parse_duration)]
    pub link_timeout: Duration,
    /// Params directory (default: $COMPANION_PARAMS or the workspace params/) or a params overlay file
    /// (`companion calibrate --out`, docs/calibrate.md).
    #[arg(long)]
    pub params: Option<PathBuf>,
    /// A vehicle profile: params/vehicles/NAME.toml, a params overlay made by `companion
    /// calibrate` from that vehicle's flights (docs/calibrate.md); the default is the paper's
    /// mission with its stated assumptions.
    #[arg(long, value_name = "NAME")]
    pub vehicle: Option<String>,
    /// Stop after this long (e.g. 60s); default: run until Ctrl-C or SIGTERM, flight after
    /// flight (see --once).
    #[arg(long, value_parser = parse_duration)]
    pub duration: Option<Duration>,
    /// Where run folders go (a new `<UTC time>/` inside with decisions.jsonl and flight.tlog,
    /// printed at the start).
    #[arg(long, default_value = crate::decision_log::DEFAULT_RUNS_DIR)]
    pub log_dir: PathBuf,
    /// For SITL and tests only: start the first mission (mode, ARM, take-off) as soon as the
    /// autopilot is ready, without waiting for the operator. This ARMS THE VEHICLE by itself.
    /// Without it, the companion commands no motion until the pilot arms the vehicle or a
    /// ground station sends MAV_CMD_MISSION_START to component 191.
    #[arg(long)]
    pub auto_start: bool,
    /// Learn the health BN's CPT rows whose outcome the telemetry gives (the tracking versions'
    /// `C_Vk` and `U_detection_fail`, from the onboard tracker's `target_detected`) as the
    /// flight goes, bounded by params/learning.toml and logged in `cpt_learned`
    /// (docs/calibrate.md). Off by default. Needs a signed link (--signing-key) or a dedicated
    /// onboard link carrying the tracker (--onboard on a serial port or a loopback address,
    /// whose reports are then the only ones read); refused at start otherwise.
    #[arg(long)]
    pub learn_cpt: bool,
    /// Command only the autopilot with this MAVLink system id (when several speak on the link);
    /// default: the first autopilot heard. Others are reported, never obeyed.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_sysid: Option<u8>,
    /// With --autopilot-sysid: the autopilot's component id (default 1, MAV_COMP_ID_AUTOPILOT1).
    /// The pin is system and component: another component of that system is not obeyed.
    #[arg(long, default_value_t = 1, requires = "autopilot_sysid", value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_compid: u8,
    /// Refuse to start without --signing-key, and to fly an autopilot whose frames are not
    /// signed with it (nothing is commanded; said on stderr and to the ground station).
    #[arg(long)]
    pub require_signing: bool,
    /// Exit with an error when no autopilot HEARTBEAT arrives within this time (e.g. 30s);
    /// default: wait (and retry the connection) for ever.
    #[arg(long, value_parser = parse_duration)]
    pub connect_timeout: Option<Duration>,
    /// Exit after one flight (flown, then landed and disarmed) instead of waiting for the
    /// operator's next start.
    #[arg(long)]
    pub once: bool,
    /// The pilot arming the vehicle is a start request (held armed over every heartbeat for
    /// `[flight] operator_confirm_s`). Off by default: arming for a manual flight is not a start.
    #[arg(long)]
    pub start_on_arm: bool,
    /// The operator's ground station: its MAVLink system id (repeat for several). When given,
    /// only these may start a mission (even before their GCS HEARTBEAT); a GCS HEARTBEAT from
    /// another system is reported, never obeyed. Without it, systems heard sending a GCS
    /// HEARTBEAT count; an autopilot component never does.
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub gcs_sysid: Vec<u8>,
    /// Zones: a GeoJSON FeatureCollection whose features' `properties.constraints` name
    /// constraint classes; the route's legs are split where they enter or leave one (default
    /// for the default route: params/missions/tracking_zones.geojson; docs/guarantee.md).
    #[arg(long, value_name = "FILE.geojson")]
    pub zones: Option<PathBuf>,
    /// Judge the PANORAMA mission's typed `[[activities]]` (params/missions/tracking.toml's
    /// 1.35 km profile: the legacy plan, which the shipped vehicle profiles were fitted on)
    /// instead of the activities derived from the route flown and the zones.
    #[arg(long, conflicts_with = "zones")]
    pub legacy_plan: bool,
    /// Home as LAT,LON (degrees), to place a route relative to home among absolute zones.
    #[arg(long, value_name = "LAT,LON")]
    pub home: Option<String>,
    #[command(flatten)]
    pub live: crate::live::LiveArgs,
    /// The plan the guarantee judges, as `companion fly` derived it before any socket (the
    /// shell names the activity flown from it); `None`: the typed mission.
    #[arg(skip)]
    pub plan: Option<crate::route_input::PlanSummary>,
    /// The route is relative to home and the zones absolute, with no `--home`: the plan is made
    /// once the autopilot's home is known (`fly::home_plan`); `plan` stands in until then.
    #[arg(skip)]
    pub plan_waits_for_home: bool,
}

impl FlyArgs {
    /// `--mission autopilot`: the autopilot's own mission is flown.
    pub fn flies_autopilot_mission(&self) -> bool {
        self.mission
            .as_deref()
            .is_some_and(|m| m == std::path::Path::new(crate::autopilot_mission::AUTOPILOT))
    }

    /// The route file `--mission` names (none for `autopilot`: the default route stays loaded
    /// for the take-off altitude only).
    pub fn route_file(&self) -> Option<&std::path::Path> {
        self.mission
            .as_deref()
            .filter(|_| !self.flies_autopilot_mission())
    }

    /// The arguments `companion fly ARGS...` gives, the command line's defaults for the rest
    /// (for tests and tools that build a fly setup without a process).
    pub fn from_cli<I: IntoIterator<Item = S>, S: Into<std::ffi::OsString> + Clone>(
        args: I,
    ) -> Result<Self, clap::Error> {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Fly {
            #[command(flatten)]
            args: FlyArgs,
        }
        let argv = std::iter::once(std::ffi::OsString::from("fly"))
            .chain(args.into_iter().map(Into::into));
        Ok(Fly::try_parse_from(argv)?.args)
    }
}
