//! Flight modes by name, per autopilot (chosen from HEARTBEAT.autopilot).
//!
//! ArduPilot Copter: `custom_mode` is the mode number (ArduCopter/mode.h `Mode::Number`, also the
//! ardupilotmega `COPTER_MODE` enum): AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9, BRAKE 17. Set with
//! MAV_CMD_DO_SET_MODE(param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, param2 = number).
//!
//! PX4: `custom_mode` packs main mode in bits 16..24 and sub mode in bits 24..32
//! (px4_custom_mode.h); set with DO_SET_MODE(param1 = 1, param2 = main, param3 = sub). PX4 has no
//! GUIDED or BRAKE: both map to AUTO.LOITER (Hold), which accepts MAV_CMD_DO_REPOSITION.

use super::command::CommandSpec;
use super::dialect::{MavAutopilot, MavCmd};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavor {
    ArduPilot,
    Px4,
    Other,
}

impl Flavor {
    pub fn from_autopilot(a: MavAutopilot) -> Self {
        match a {
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA => Flavor::ArduPilot,
            MavAutopilot::MAV_AUTOPILOT_PX4 => Flavor::Px4,
            _ => Flavor::Other,
        }
    }
}

/// (name, ArduPilot Copter number, PX4 main, PX4 sub)
const MODES: &[(&str, u32, u8, u8)] = &[
    ("STABILIZE", 0, 7, 0),
    ("ALT_HOLD", 2, 2, 0),
    ("AUTO", 3, 4, 4),
    ("GUIDED", 4, 4, 3),
    ("LOITER", 5, 4, 3),
    ("RTL", 6, 4, 5),
    ("LAND", 9, 4, 6),
    ("POSHOLD", 16, 3, 0),
    ("BRAKE", 17, 4, 3),
    ("SMART_RTL", 21, 4, 5),
];

/// PX4 names for decoding its heartbeat (main, sub) -> name.
const PX4_NAMES: &[(u8, u8, &str)] = &[
    (1, 0, "MANUAL"),
    (2, 0, "ALT_HOLD"),
    (3, 0, "POSHOLD"),
    (4, 1, "AUTO_READY"),
    (4, 2, "TAKEOFF"),
    (4, 3, "LOITER"),
    (4, 4, "AUTO"),
    (4, 5, "RTL"),
    (4, 6, "LAND"),
    (4, 8, "FOLLOW"),
    (4, 9, "PRECLAND"),
    (5, 0, "ACRO"),
    (6, 0, "OFFBOARD"),
    (7, 0, "STABILIZE"),
];

/// The DO_SET_MODE command for a mode name, or None when this autopilot has no such mode.
pub fn set_mode_command(flavor: Flavor, name: &str) -> Option<CommandSpec> {
    let &(_, ap, main, sub) = MODES.iter().find(|m| m.0 == name)?;
    let params = match flavor {
        Flavor::ArduPilot => [1.0, ap as f32, 0.0, 0.0, 0.0, 0.0, 0.0],
        Flavor::Px4 => [1.0, main as f32, sub as f32, 0.0, 0.0, 0.0, 0.0],
        Flavor::Other => return None,
    };
    Some(CommandSpec::long(MavCmd::MAV_CMD_DO_SET_MODE, params))
}

/// The mode name a heartbeat's `custom_mode` stands for (`MODE_<n>` when unknown).
pub fn mode_name(flavor: Flavor, custom_mode: u32) -> String {
    match flavor {
        Flavor::ArduPilot => MODES
            .iter()
            .find(|m| m.1 == custom_mode)
            .map(|m| m.0.to_string())
            .unwrap_or_else(|| format!("MODE_{custom_mode}")),
        Flavor::Px4 => {
            let main = ((custom_mode >> 16) & 0xff) as u8;
            let sub = ((custom_mode >> 24) & 0xff) as u8;
            let sub = if main == 4 { sub } else { 0 };
            PX4_NAMES
                .iter()
                .find(|n| n.0 == main && n.1 == sub)
                .map(|n| n.2.to_string())
                .unwrap_or_else(|| format!("PX4_{main}_{sub}"))
        }
        Flavor::Other => format!("MODE_{custom_mode}"),
    }
}

/// Whether the vehicle's reported mode already is `name` (so a mode step can be skipped).
pub fn is_in_mode(flavor: Flavor, custom_mode: u32, name: &str) -> bool {
    let Some(&(_, ap, main, sub)) = MODES.iter().find(|m| m.0 == name) else {
        return false;
    };
    match flavor {
        Flavor::ArduPilot => custom_mode == ap,
        Flavor::Px4 => {
            ((custom_mode >> 16) & 0xff) as u8 == main
                && (main != 4 || ((custom_mode >> 24) & 0xff) as u8 == sub)
        }
        Flavor::Other => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(c: &CommandSpec) -> [f32; 7] {
        match c.body {
            crate::link::command::CommandBody::Long { params } => params,
            _ => panic!(),
        }
    }

    #[test]
    fn ardupilot_copter_numbers() {
        // ArduCopter/mode.h: AUTO 3, GUIDED 4, LOITER 5, RTL 6, LAND 9, BRAKE 17.
        for (name, n) in [
            ("AUTO", 3.0),
            ("GUIDED", 4.0),
            ("LOITER", 5.0),
            ("RTL", 6.0),
            ("LAND", 9.0),
            ("BRAKE", 17.0),
        ] {
            let c = set_mode_command(Flavor::ArduPilot, name).unwrap();
            assert_eq!(c.command, MavCmd::MAV_CMD_DO_SET_MODE);
            assert_eq!(params(&c)[..2], [1.0, n], "{name}");
            assert_eq!(mode_name(Flavor::ArduPilot, n as u32), name);
        }
        assert_eq!(mode_name(Flavor::ArduPilot, 8), "MODE_8");
        assert!(set_mode_command(Flavor::ArduPilot, "WARP").is_none());
    }

    #[test]
    fn px4_main_and_sub_modes() {
        let c = set_mode_command(Flavor::Px4, "AUTO").unwrap();
        assert_eq!(params(&c)[..3], [1.0, 4.0, 4.0]);
        let rtl = set_mode_command(Flavor::Px4, "RTL").unwrap();
        assert_eq!(params(&rtl)[..3], [1.0, 4.0, 5.0]);
        // AUTO.MISSION: main 4 at bits 16..24, sub 4 at bits 24..32.
        let cm = (4u32 << 16) | (4u32 << 24);
        assert_eq!(cm, 67_371_008);
        assert_eq!(mode_name(Flavor::Px4, cm), "AUTO");
        assert_eq!(mode_name(Flavor::Px4, 6 << 16), "OFFBOARD");
        assert!(is_in_mode(Flavor::Px4, (4 << 16) | (6 << 24), "LAND"));
        assert!(!is_in_mode(Flavor::Px4, (4 << 16) | (6 << 24), "RTL"));
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
        assert!(set_mode_command(Flavor::Other, "AUTO").is_none());
    }
}
