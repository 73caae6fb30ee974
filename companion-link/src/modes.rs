//! Flight modes by name, per autopilot (chosen from HEARTBEAT.autopilot).
//!
//! ArduPilot Copter: `custom_mode` is the mode number, `Mode::Number` in ArduPilot's
//! `ArduCopter/mode.h` (also the ardupilotmega `COPTER_MODE` enum). Set with
//! MAV_CMD_DO_SET_MODE(param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 = number)
//! (`GCS_MAVLINK::handle_command_do_set_mode` in `libraries/GCS_MAVLink/GCS_Common.cpp`).
//!
//! PX4: `src/modules/commander/px4_custom_mode.h` in PX4-Autopilot. `union px4_custom_mode` is
//! `{ uint16_t reserved; uint8_t main_mode; uint8_t sub_mode; }` over a little-endian `uint32_t`,
//! so HEARTBEAT.custom_mode carries the main mode in bits 16..24 and the sub mode in bits 24..32
//! (`get_px4_custom_mode(nav_state)` fills it for the heartbeat). Sub modes are meaningful for
//! main mode AUTO (`PX4_CUSTOM_SUB_MODE_AUTO`) and POSCTL (`PX4_CUSTOM_SUB_MODE_POSCTL`). Set with
//! DO_SET_MODE(param1 with MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 = main, param3 = sub):
//! `Commander::handle_command`, case `VEHICLE_CMD_DO_SET_MODE` (`src/modules/commander/
//! Commander.cpp`) ignores param2/3 unless param1 has the custom-mode flag, treats AUTO with
//! sub 0 as AUTO.MISSION, answers an unknown AUTO sub mode "Unsupported auto mode" and a refused
//! transition TEMPORARILY_REJECTED.
//!
//! PX4 has no GUIDED or BRAKE: both map to AUTO.LOITER (Hold), which accepts
//! MAV_CMD_DO_REPOSITION. ArduPilot Copter has no TAKEOFF mode (take-off is NAV_TAKEOFF in
//! GUIDED), so `TAKEOFF` exists only for PX4.

use super::command::CommandSpec;
use super::dialect::{MavAutopilot, MavCmd, MavFrame};

/// Autopilot firmware family, from HEARTBEAT.autopilot: it decides mode numbers and protocol
/// quirks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavor {
    /// ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA).
    ArduPilot,
    /// PX4 (MAV_AUTOPILOT_PX4).
    Px4,
    /// Any other autopilot: no mode names are known for it.
    Other,
}

impl Flavor {
    /// The family's name in the record (`LinkEvent::Autopilot.flavor`).
    pub fn name(self) -> &'static str {
        match self {
            Flavor::ArduPilot => "ArduPilot",
            Flavor::Px4 => "Px4",
            Flavor::Other => "Other",
        }
    }

    /// The family a HEARTBEAT's autopilot field names.
    pub fn from_autopilot(a: MavAutopilot) -> Self {
        match a {
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Flavor::ArduPilot,
            MavAutopilot::MAV_AUTOPILOT_PX4 => Flavor::Px4,
            _ => Flavor::Other,
        }
    }
}

/// `enum PX4_CUSTOM_MAIN_MODE` (px4_custom_mode.h): MANUAL = 1, then in order.
pub mod px4_main {
    /// Manual: direct stick control.
    pub const MANUAL: u8 = 1;
    /// Altitude control: sticks with altitude hold.
    pub const ALTCTL: u8 = 2;
    /// Position control: sticks with position hold (sub modes in `px4_posctl`).
    pub const POSCTL: u8 = 3;
    /// Auto: the autopilot flies on its own (sub modes in `px4_auto`).
    pub const AUTO: u8 = 4;
    /// Acro: body rates from the sticks.
    pub const ACRO: u8 = 5;
    /// Offboard: setpoints streamed by a companion computer.
    pub const OFFBOARD: u8 = 6;
    /// Stabilized: attitude from the sticks.
    pub const STABILIZED: u8 = 7;
    /// Rattitude (removed from current PX4; the number stays reserved).
    pub const RATTITUDE_LEGACY: u8 = 8;
    /// Simple: position control with stick input in the world frame.
    pub const SIMPLE: u8 = 9;
    /// Termination: flight terminated.
    pub const TERMINATION: u8 = 10;
}

/// `enum PX4_CUSTOM_SUB_MODE_AUTO` (px4_custom_mode.h): READY = 1, then in order; 7 was RTGS,
/// now RESERVED_DO_NOT_USE.
pub mod px4_auto {
    /// AUTO.READY: armed on the ground, waiting.
    pub const READY: u8 = 1;
    /// AUTO.TAKEOFF: take-off to the take-off altitude.
    pub const TAKEOFF: u8 = 2;
    /// AUTO.LOITER: hold position (PX4 "Hold").
    pub const LOITER: u8 = 3;
    /// AUTO.MISSION: fly the uploaded mission.
    pub const MISSION: u8 = 4;
    /// AUTO.RTL: return to launch.
    pub const RTL: u8 = 5;
    /// AUTO.LAND: land where it is.
    pub const LAND: u8 = 6;
    /// AUTO.FOLLOW_TARGET: follow a target's position.
    pub const FOLLOW_TARGET: u8 = 8;
    /// AUTO.PRECLAND: precision landing.
    pub const PRECLAND: u8 = 9;
    /// AUTO.VTOL_TAKEOFF: VTOL take-off.
    pub const VTOL_TAKEOFF: u8 = 10;
}

/// `enum PX4_CUSTOM_SUB_MODE_POSCTL` (px4_custom_mode.h): POSCTL = 0, ORBIT, SLOW.
pub mod px4_posctl {
    /// POSCTL.POSCTL: plain position control.
    pub const POSCTL: u8 = 0;
    /// POSCTL.ORBIT: orbit a point.
    pub const ORBIT: u8 = 1;
    /// POSCTL.SLOW: position control at reduced speed.
    pub const SLOW: u8 = 2;
}

/// PX4 `custom_mode` from main and sub mode (the `px4_custom_mode` union's `data`).
pub fn px4_custom_mode(main: u8, sub: u8) -> u32 {
    (u32::from(main) << 16) | (u32::from(sub) << 24)
}

/// (main, sub) from a PX4 `custom_mode`.
pub fn px4_main_sub(custom_mode: u32) -> (u8, u8) {
    ((custom_mode >> 16) as u8, (custom_mode >> 24) as u8)
}

/// A flight mode by purpose, named as ArduPilot names it (PX4-only modes by PX4's): what
/// params (`commands.toml` mode steps), the link and the shell speak of. Each autopilot flavour
/// serves it with its own number: [`FlightMode::ardupilot`] (ArduCopter's `Mode::Number`) and
/// [`FlightMode::px4`] (PX4's main and sub mode); `None` where that autopilot has no such mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FlightMode {
    /// `STABILIZE`.
    Stabilize,
    /// `ACRO`.
    Acro,
    /// `ALT_HOLD`.
    AltHold,
    /// `AUTO`.
    Auto,
    /// `GUIDED`.
    Guided,
    /// `LOITER`.
    Loiter,
    /// `RTL`.
    Rtl,
    /// `CIRCLE`.
    Circle,
    /// `LAND`.
    Land,
    /// `DRIFT`.
    Drift,
    /// `SPORT`.
    Sport,
    /// `FLIP`.
    Flip,
    /// `AUTOTUNE`.
    Autotune,
    /// `POSHOLD`.
    PosHold,
    /// `BRAKE`.
    Brake,
    /// `THROW`.
    Throw,
    /// `AVOID_ADSB`.
    AvoidAdsb,
    /// `GUIDED_NOGPS`.
    GuidedNoGps,
    /// `SMART_RTL`.
    SmartRtl,
    /// `FLOWHOLD`.
    FlowHold,
    /// `FOLLOW`.
    Follow,
    /// `ZIGZAG`.
    ZigZag,
    /// `SYSTEMID`.
    SystemId,
    /// `AUTOROTATE`.
    Autorotate,
    /// `AUTO_RTL`.
    AutoRtl,
    /// `TURTLE`.
    Turtle,
    /// `MANUAL`.
    Manual,
    /// `TAKEOFF`.
    Takeoff,
    /// `PRECLAND`.
    PrecLand,
    /// `OFFBOARD`.
    Offboard,
}

/// An ArduPilot Copter custom mode: the number in HEARTBEAT.custom_mode and DO_SET_MODE param2.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ArduCopterMode(pub u32);

/// A PX4 custom mode: main mode and sub mode (`union px4_custom_mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Px4Mode {
    /// `PX4_CUSTOM_MAIN_MODE` ([`px4_main`]).
    pub main: u8,
    /// The sub mode ([`px4_auto`], [`px4_posctl`]; 0 for the other main modes).
    pub sub: u8,
}

impl Px4Mode {
    /// The mode a heartbeat's `custom_mode` shows, the sub mode cleared where PX4 does not use it.
    pub fn from_custom_mode(custom_mode: u32) -> Self {
        let (main, sub) = px4_significant(custom_mode);
        Px4Mode { main, sub }
    }
}

/// `(mode, ArduPilot Copter mode number, PX4 (main, sub) mode)`.
type ModeRow = (FlightMode, &'static str, Option<u32>, Option<(u8, u8)>);

const MODES: &[ModeRow] = &[
    (
        FlightMode::Stabilize,
        "STABILIZE",
        Some(0),
        Some((px4_main::STABILIZED, 0)),
    ),
    (FlightMode::Acro, "ACRO", Some(1), Some((px4_main::ACRO, 0))),
    (
        FlightMode::AltHold,
        "ALT_HOLD",
        Some(2),
        Some((px4_main::ALTCTL, 0)),
    ),
    (
        FlightMode::Auto,
        "AUTO",
        Some(3),
        Some((px4_main::AUTO, px4_auto::MISSION)),
    ),
    (
        FlightMode::Guided,
        "GUIDED",
        Some(4),
        Some((px4_main::AUTO, px4_auto::LOITER)),
    ),
    (
        FlightMode::Loiter,
        "LOITER",
        Some(5),
        Some((px4_main::AUTO, px4_auto::LOITER)),
    ),
    (
        FlightMode::Rtl,
        "RTL",
        Some(6),
        Some((px4_main::AUTO, px4_auto::RTL)),
    ),
    (
        FlightMode::Circle,
        "CIRCLE",
        Some(7),
        Some((px4_main::POSCTL, px4_posctl::ORBIT)),
    ),
    (
        FlightMode::Land,
        "LAND",
        Some(9),
        Some((px4_main::AUTO, px4_auto::LAND)),
    ),
    (FlightMode::Drift, "DRIFT", Some(11), None),
    (FlightMode::Sport, "SPORT", Some(13), None),
    (FlightMode::Flip, "FLIP", Some(14), None),
    (FlightMode::Autotune, "AUTOTUNE", Some(15), None),
    (
        FlightMode::PosHold,
        "POSHOLD",
        Some(16),
        Some((px4_main::POSCTL, px4_posctl::POSCTL)),
    ),
    (
        FlightMode::Brake,
        "BRAKE",
        Some(17),
        Some((px4_main::AUTO, px4_auto::LOITER)),
    ),
    (FlightMode::Throw, "THROW", Some(18), None),
    (FlightMode::AvoidAdsb, "AVOID_ADSB", Some(19), None),
    (FlightMode::GuidedNoGps, "GUIDED_NOGPS", Some(20), None),
    (
        FlightMode::SmartRtl,
        "SMART_RTL",
        Some(21),
        Some((px4_main::AUTO, px4_auto::RTL)),
    ),
    (FlightMode::FlowHold, "FLOWHOLD", Some(22), None),
    (
        FlightMode::Follow,
        "FOLLOW",
        Some(23),
        Some((px4_main::AUTO, px4_auto::FOLLOW_TARGET)),
    ),
    (FlightMode::ZigZag, "ZIGZAG", Some(24), None),
    (FlightMode::SystemId, "SYSTEMID", Some(25), None),
    (FlightMode::Autorotate, "AUTOROTATE", Some(26), None),
    (FlightMode::AutoRtl, "AUTO_RTL", Some(27), None),
    (FlightMode::Turtle, "TURTLE", Some(28), None),
    (
        FlightMode::Manual,
        "MANUAL",
        None,
        Some((px4_main::MANUAL, 0)),
    ),
    (
        FlightMode::Takeoff,
        "TAKEOFF",
        None,
        Some((px4_main::AUTO, px4_auto::TAKEOFF)),
    ),
    (
        FlightMode::PrecLand,
        "PRECLAND",
        None,
        Some((px4_main::AUTO, px4_auto::PRECLAND)),
    ),
    (
        FlightMode::Offboard,
        "OFFBOARD",
        None,
        Some((px4_main::OFFBOARD, 0)),
    ),
];

impl FlightMode {
    fn row(self) -> &'static ModeRow {
        MODES
            .iter()
            .find(|m| m.0 == self)
            .expect("every mode has a row")
    }

    /// The mode's name (ArduPilot's, or PX4's for a PX4-only mode), as params and records write it.
    pub fn name(self) -> &'static str {
        self.row().1
    }

    /// The mode named `name`, if any autopilot we know has it.
    pub fn from_name(name: &str) -> Option<Self> {
        MODES.iter().find(|m| m.1 == name).map(|m| m.0)
    }

    /// ArduPilot Copter's number for this mode.
    pub fn ardupilot(self) -> Option<ArduCopterMode> {
        self.row().2.map(ArduCopterMode)
    }

    /// PX4's (main, sub) mode serving the same purpose.
    pub fn px4(self) -> Option<Px4Mode> {
        self.row().3.map(|(main, sub)| Px4Mode { main, sub })
    }
}

/// PX4 (main, sub) -> the name its heartbeat is reported as. For main modes other than AUTO and
/// POSCTL the sub mode is not looked at.
const PX4_NAMES: &[(u8, u8, &str)] = &[
    (px4_main::MANUAL, 0, "MANUAL"),
    (px4_main::ALTCTL, 0, "ALT_HOLD"),
    (px4_main::POSCTL, px4_posctl::POSCTL, "POSHOLD"),
    (px4_main::POSCTL, px4_posctl::ORBIT, "CIRCLE"),
    (px4_main::POSCTL, px4_posctl::SLOW, "POSHOLD_SLOW"),
    (px4_main::AUTO, px4_auto::READY, "AUTO_READY"),
    (px4_main::AUTO, px4_auto::TAKEOFF, "TAKEOFF"),
    (px4_main::AUTO, px4_auto::LOITER, "LOITER"),
    (px4_main::AUTO, px4_auto::MISSION, "AUTO"),
    (px4_main::AUTO, px4_auto::RTL, "RTL"),
    (px4_main::AUTO, px4_auto::LAND, "LAND"),
    (px4_main::AUTO, px4_auto::FOLLOW_TARGET, "FOLLOW"),
    (px4_main::AUTO, px4_auto::PRECLAND, "PRECLAND"),
    (px4_main::AUTO, px4_auto::VTOL_TAKEOFF, "VTOL_TAKEOFF"),
    (px4_main::ACRO, 0, "ACRO"),
    (px4_main::OFFBOARD, 0, "OFFBOARD"),
    (px4_main::STABILIZED, 0, "STABILIZE"),
    (px4_main::RATTITUDE_LEGACY, 0, "RATTITUDE"),
    (px4_main::TERMINATION, 0, "TERMINATION"),
];

impl std::fmt::Display for FlightMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The mode an autopilot's heartbeat reports, decoded once where the heartbeat is read: a
/// [`FlightMode`] the companion speaks of, or a number no such mode stands for (an autopilot's
/// mode this build does not know is a value, never an error). Its name is what records write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReportedMode {
    /// A mode params and the shell name.
    Known(FlightMode),
    /// A PX4 (main, sub) with no [`FlightMode`]: AUTO.READY, POSCTL.SLOW, VTOL take-off,
    /// Rattitude, Termination, or numbers PX4 has not defined.
    Px4(Px4Mode),
    /// ArduPilot's (or another autopilot's) `custom_mode` with no mode we know.
    Number(u32),
}

impl ReportedMode {
    /// The mode a heartbeat's `custom_mode` stands for on this autopilot.
    pub fn decode(flavor: Flavor, custom_mode: u32) -> Self {
        match flavor {
            Flavor::ArduPilot => MODES
                .iter()
                .find(|m| m.2 == Some(custom_mode))
                .map_or(ReportedMode::Number(custom_mode), |m| {
                    ReportedMode::Known(m.0)
                }),
            Flavor::Px4 => {
                let mode = Px4Mode::from_custom_mode(custom_mode);
                px4_name(mode)
                    .and_then(FlightMode::from_name)
                    .map_or(ReportedMode::Px4(mode), ReportedMode::Known)
            }
            Flavor::Other => ReportedMode::Number(custom_mode),
        }
    }

    /// The flight mode, when the report is one the companion speaks of.
    pub fn known(self) -> Option<FlightMode> {
        match self {
            ReportedMode::Known(m) => Some(m),
            _ => None,
        }
    }
}

impl std::fmt::Display for ReportedMode {
    /// The name (`MODE_<n>` / `PX4_<main>_<sub>` for numbers without one).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            ReportedMode::Known(m) => f.write_str(m.name()),
            ReportedMode::Px4(p) => match px4_name(p) {
                Some(n) => f.write_str(n),
                None => write!(f, "PX4_{}_{}", p.main, p.sub),
            },
            ReportedMode::Number(n) => write!(f, "MODE_{n}"),
        }
    }
}

/// The name PX4's heartbeat (main, sub) is reported as, when it has one.
fn px4_name(mode: Px4Mode) -> Option<&'static str> {
    PX4_NAMES
        .iter()
        .find(|n| n.0 == mode.main && n.1 == mode.sub)
        .map(|n| n.2)
}

/// Whether any autopilot we know has a mode of this name (for validating params).
pub fn is_known_mode(name: &str) -> bool {
    FlightMode::from_name(name).is_some()
}

/// The DO_SET_MODE command for a mode, or None when this autopilot has no such mode.
pub fn set_mode_command(flavor: Flavor, mode: FlightMode) -> Option<CommandSpec> {
    // param1: MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (1); both autopilots read param2 (and PX4 param3)
    // only with it set.
    let params = match flavor {
        Flavor::ArduPilot => [1.0, mode.ardupilot()?.0 as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        Flavor::Px4 => {
            let Px4Mode { main, sub } = mode.px4()?;
            [1.0, f32::from(main), f32::from(sub), 0.0, 0.0, 0.0, 0.0]
        }
        Flavor::Other => return None,
    };
    Some(CommandSpec::long(MavCmd::MAV_CMD_DO_SET_MODE, params))
}

/// The seven params a `command` step sends to this autopilot. commands.toml writes them as
/// ArduPilot reads them; PX4 reads MAV_CMD_NAV_TAKEOFF differently
/// (`Navigator::run`, src/modules/navigator/navigator_main.cpp, and `FlightTaskTakeoff`):
/// param7 is AMSL, not above home, and finite param5/param6 are the lat/lon to take off
/// towards (0, 0 would be the Gulf of Guinea), finite param4 a yaw. So for PX4 param7 becomes
/// home AMSL + param7 and params 4-6 NaN (current position and heading). None when PX4 needs
/// home and none is known yet.
pub fn command_params(
    flavor: Flavor,
    command: MavCmd,
    params: [f32; 7],
    home_amsl_m: Option<f64>,
) -> Option<[f32; 7]> {
    if flavor != Flavor::Px4 || command != MavCmd::MAV_CMD_NAV_TAKEOFF {
        return Some(params);
    }
    let home = home_amsl_m?;
    Some([
        params[0],
        0.0,
        0.0,
        f32::NAN,
        f32::NAN,
        f32::NAN,
        (home + f64::from(params[6])) as f32,
    ])
}

/// Frame and altitude of a COMMAND_INT DO_REPOSITION to `target_rel_m` above home, from the
/// vehicle's current AMSL and above-home altitudes. ArduPilot honours
/// MAV_FRAME_GLOBAL_RELATIVE_ALT. PX4 (main 02e73e3b, SITL) takes a DO_REPOSITION COMMAND_INT
/// only in MAV_FRAME_GLOBAL_INT and answers COMMAND_UNSUPPORTED_MAV_FRAME to GLOBAL, the relative
/// frames and terrain frames ("frame invalid for command 192" in its log); its navigator reads the
/// altitude as AMSL. So for PX4 the altitude goes as AMSL (home = current AMSL - current
/// above-home) in MAV_FRAME_GLOBAL_INT.
// MAV_FRAME_GLOBAL_INT is superseded in the MAVLink definitions, but it is the one PX4 accepts here.
#[allow(deprecated)]
pub fn reposition_frame_alt(
    flavor: Flavor,
    target_rel_m: f64,
    vehicle_amsl_m: f64,
    vehicle_rel_m: f64,
) -> (MavFrame, f32) {
    match flavor {
        Flavor::Px4 => (
            MavFrame::MAV_FRAME_GLOBAL_INT,
            (vehicle_amsl_m - vehicle_rel_m + target_rel_m) as f32,
        ),
        _ => (MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, target_rel_m as f32),
    }
}

/// PX4's (main, sub) with the sub mode cleared where PX4 does not use it.
fn px4_significant(custom_mode: u32) -> (u8, u8) {
    let (main, sub) = px4_main_sub(custom_mode);
    match main {
        px4_main::AUTO | px4_main::POSCTL => (main, sub),
        _ => (main, 0),
    }
}

/// The mode name a heartbeat's `custom_mode` stands for (`MODE_<n>` / `PX4_<main>_<sub>` when
/// unknown).
pub fn mode_name(flavor: Flavor, custom_mode: u32) -> String {
    ReportedMode::decode(flavor, custom_mode).to_string()
}

/// Whether the vehicle's reported mode already is `name` (so a mode step can be skipped).
pub fn is_in_mode(flavor: Flavor, custom_mode: u32, mode: FlightMode) -> bool {
    match flavor {
        Flavor::ArduPilot => mode.ardupilot() == Some(ArduCopterMode(custom_mode)),
        Flavor::Px4 => mode.px4() == Some(Px4Mode::from_custom_mode(custom_mode)),
        Flavor::Other => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(name: &str) -> FlightMode {
        FlightMode::from_name(name).expect(name)
    }

    /// Every mode's name finds it again, and no two modes share a name.
    #[test]
    fn flight_mode_names_round_trip() {
        for &(mode, name, _, _) in MODES {
            assert_eq!(mode.name(), name);
            assert_eq!(FlightMode::from_name(name), Some(mode), "{name}");
        }
        assert_eq!(FlightMode::Auto.ardupilot(), Some(ArduCopterMode(3)));
        assert_eq!(
            FlightMode::Land.px4(),
            Some(Px4Mode {
                main: px4_main::AUTO,
                sub: px4_auto::LAND
            })
        );
        assert_eq!(FlightMode::Takeoff.ardupilot(), None);
    }

    fn params(c: &CommandSpec) -> [f32; 7] {
        match c.body {
            crate::command::CommandBody::Long { params } => params,
            _ => panic!(),
        }
    }

    /// Every number of `enum class Number` in ArduPilot's ArduCopter/mode.h (copied by hand):
    /// the command carries it in param2 with the custom-mode flag in param1, and a heartbeat
    /// with it decodes back to the name.
    #[test]
    fn ardupilot_copter_numbers_round_trip() {
        let copied = [
            ("STABILIZE", 0),
            ("ACRO", 1),
            ("ALT_HOLD", 2),
            ("AUTO", 3),
            ("GUIDED", 4),
            ("LOITER", 5),
            ("RTL", 6),
            ("CIRCLE", 7),
            ("LAND", 9),
            ("DRIFT", 11),
            ("SPORT", 13),
            ("FLIP", 14),
            ("AUTOTUNE", 15),
            ("POSHOLD", 16),
            ("BRAKE", 17),
            ("THROW", 18),
            ("AVOID_ADSB", 19),
            ("GUIDED_NOGPS", 20),
            ("SMART_RTL", 21),
            ("FLOWHOLD", 22),
            ("FOLLOW", 23),
            ("ZIGZAG", 24),
            ("SYSTEMID", 25),
            ("AUTOROTATE", 26),
            ("AUTO_RTL", 27),
            ("TURTLE", 28),
        ];
        for (name, n) in copied {
            let c = set_mode_command(Flavor::ArduPilot, m(name)).unwrap();
            assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
            assert_eq!(
                params(&c),
                [1.0, n as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
                "{name}"
            );
            assert_eq!(mode_name(Flavor::ArduPilot, n), name);
            assert!(is_in_mode(Flavor::ArduPilot, n, m(name)));
        }
        // 8, 10 and 12 are unused in mode.h.
        assert_eq!(mode_name(Flavor::ArduPilot, 8), "MODE_8");
        assert!(FlightMode::from_name("WARP").is_none());
        // No TAKEOFF mode on Copter (NAV_TAKEOFF in GUIDED is how it takes off).
        assert!(set_mode_command(Flavor::ArduPilot, m("TAKEOFF")).is_none());
        assert!(is_known_mode("TAKEOFF") && !is_known_mode("WARP"));
    }

    /// PX4 `custom_mode` values as a ground station sees them in HEARTBEAT, computed by hand
    /// from px4_custom_mode.h (main = PX4_CUSTOM_MAIN_MODE, sub = PX4_CUSTOM_SUB_MODE_AUTO,
    /// value = main * 65536 + sub * 16777216): e.g. AUTO.LOITER = 4 * 65536 + 3 * 16777216.
    #[test]
    fn px4_main_and_sub_modes_round_trip() {
        let copied: [(&str, u8, u8, u32); 12] = [
            ("MANUAL", 1, 0, 65_536),
            ("ALT_HOLD", 2, 0, 131_072),
            ("POSHOLD", 3, 0, 196_608),
            ("CIRCLE", 3, 1, 16_973_824),
            ("TAKEOFF", 4, 2, 33_816_576),
            ("LOITER", 4, 3, 50_593_792),
            ("AUTO", 4, 4, 67_371_008),
            ("RTL", 4, 5, 84_148_224),
            ("LAND", 4, 6, 100_925_440),
            ("PRECLAND", 4, 9, 151_257_088),
            ("OFFBOARD", 6, 0, 393_216),
            ("STABILIZE", 7, 0, 458_752),
        ];
        for (name, main, sub, value) in copied {
            assert_eq!(px4_custom_mode(main, sub), value, "{name}");
            assert_eq!(px4_main_sub(value), (main, sub), "{name}");
            // The union's memory layout: reserved u16, then main, then sub (little-endian).
            assert_eq!(value.to_le_bytes(), [0, 0, main, sub], "{name}");
            assert_eq!(mode_name(Flavor::Px4, value), name);
            assert!(is_in_mode(Flavor::Px4, value, m(name)), "{name}");
            let c = set_mode_command(Flavor::Px4, m(name)).unwrap();
            assert_eq!(
                params(&c),
                [1.0, f32::from(main), f32::from(sub), 0.0, 0.0, 0.0, 0.0],
                "{name}"
            );
        }
        // GUIDED and BRAKE fly as AUTO.LOITER (Hold) on PX4; a Hold heartbeat satisfies both.
        for name in ["GUIDED", "BRAKE"] {
            let c = set_mode_command(Flavor::Px4, m(name)).unwrap();
            assert_eq!(params(&c)[..3], [1.0, 4.0, 3.0]);
            assert!(is_in_mode(Flavor::Px4, 50_593_792, m(name)));
        }
        // Sub mode ignored outside AUTO and POSCTL; significant inside.
        assert_eq!(mode_name(Flavor::Px4, px4_custom_mode(2, 7)), "ALT_HOLD");
        assert!(!is_in_mode(
            Flavor::Px4,
            px4_custom_mode(3, 1),
            m("POSHOLD")
        ));
        assert!(!is_in_mode(Flavor::Px4, px4_custom_mode(4, 6), m("RTL")));
        // Copter-only modes have no PX4 command; unknown PX4 numbers decode to a readable name.
        assert!(set_mode_command(Flavor::Px4, m("DRIFT")).is_none());
        assert_eq!(mode_name(Flavor::Px4, px4_custom_mode(4, 7)), "PX4_4_7");
    }

    /// A heartbeat's mode is decoded once into a value: modes the companion speaks of are
    /// `Known`, anything else (unused ArduCopter numbers, PX4 modes without a FlightMode, numbers
    /// PX4 never defined, any other autopilot) is a value with its record name, never a panic.
    #[test]
    fn reported_modes_decode_to_values_with_their_record_names() {
        use ReportedMode::*;
        let px4 = |main, sub| ReportedMode::decode(Flavor::Px4, px4_custom_mode(main, sub));
        assert_eq!(
            ReportedMode::decode(Flavor::ArduPilot, 9),
            Known(FlightMode::Land)
        );
        assert_eq!(ReportedMode::decode(Flavor::ArduPilot, 8), Number(8));
        assert_eq!(
            ReportedMode::decode(Flavor::ArduPilot, 8).to_string(),
            "MODE_8"
        );
        assert_eq!(ReportedMode::decode(Flavor::Other, 3).to_string(), "MODE_3");
        assert_eq!(px4(4, 3), Known(FlightMode::Loiter), "PX4 Hold");
        let slow = px4(px4_main::POSCTL, px4_posctl::SLOW);
        assert_eq!(slow.known(), None);
        assert_eq!(slow.to_string(), "POSHOLD_SLOW");
        assert_eq!(px4(4, 7).to_string(), "PX4_4_7");
        assert_eq!(
            px4(2, 7),
            Known(FlightMode::AltHold),
            "sub ignored outside AUTO/POSCTL"
        );
        for v in [0, 1, u32::MAX, 0xdead_beef, px4_custom_mode(255, 255)] {
            for f in [Flavor::ArduPilot, Flavor::Px4, Flavor::Other] {
                assert_eq!(ReportedMode::decode(f, v).to_string(), mode_name(f, v));
            }
        }
    }

    #[test]
    fn flavor_from_heartbeat() {
        assert_eq!(
            Flavor::from_autopilot(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA),
            Flavor::ArduPilot
        );
        assert_eq!(
            Flavor::from_autopilot(MavAutopilot::MAV_AUTOPILOT_PX4),
            Flavor::Px4
        );
        assert_eq!(
            Flavor::from_autopilot(MavAutopilot::MAV_AUTOPILOT_GENERIC),
            Flavor::Other
        );
        assert!(set_mode_command(Flavor::Other, m("AUTO")).is_none());
    }

    /// PX4 reads NAV_TAKEOFF param7 as AMSL and finite param5/6 as where to go: the take-off
    /// from commands.toml (10 m above home) becomes home AMSL + 10 with NaN position and yaw.
    #[test]
    fn px4_takeoff_altitude_is_amsl_and_position_is_left_to_px4() {
        let p = [0., 0., 0., 0., 0., 0., 10.];
        let got = command_params(Flavor::Px4, MavCmd::MAV_CMD_NAV_TAKEOFF, p, Some(488.0)).unwrap();
        assert_eq!(got[6], 498.0);
        assert!(
            got[3].is_nan() && got[4].is_nan() && got[5].is_nan(),
            "{got:?}"
        );
        assert!(command_params(Flavor::Px4, MavCmd::MAV_CMD_NAV_TAKEOFF, p, None).is_none());
        // ArduPilot reads param7 above home: unchanged; other commands unchanged on PX4.
        assert_eq!(
            command_params(
                Flavor::ArduPilot,
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                p,
                Some(488.0)
            ),
            Some(p)
        );
        assert_eq!(
            command_params(Flavor::Px4, MavCmd::MAV_CMD_DO_CHANGE_SPEED, p, Some(488.0)),
            Some(p)
        );
    }

    /// PX4 takes a DO_REPOSITION COMMAND_INT only in MAV_FRAME_GLOBAL_INT and reads its altitude
    /// as AMSL: 20 m above a home at 488 m goes as 508 m; ArduPilot keeps the relative frame.
    #[test]
    #[allow(deprecated)]
    fn px4_reposition_altitude_is_amsl() {
        assert_eq!(
            reposition_frame_alt(Flavor::Px4, 20.0, 500.0, 12.0),
            (MavFrame::MAV_FRAME_GLOBAL_INT, 508.0)
        );
        assert_eq!(
            reposition_frame_alt(Flavor::ArduPilot, 20.0, 500.0, 12.0),
            (MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 20.0)
        );
    }
}
