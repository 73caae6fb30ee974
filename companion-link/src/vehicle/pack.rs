//! The autopilot parameters the plan needs, read with PARAM_REQUEST_READ: the pack's (capacity,
//! cells) and how fast the autopilot flies a mission (cruise, climb, descent speed).

use super::*;
use crate::telemetry::SpeedParam;

/// What a parameter read from the autopilot is for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamUse {
    /// A pack parameter.
    Pack(PackParam),
    /// A mission speed; the parameter times `to_mps` is m/s.
    Speed {
        /// Which speed.
        what: SpeedParam,
        /// Unit factor to m/s (ArduCopter's are cm/s).
        to_mps: f64,
    },
}

/// The mission speeds each autopilot family flies at: ArduCopter `WPNAV_SPEED`,
/// `WPNAV_SPEED_UP`, `WPNAV_SPEED_DN` (cm/s); PX4 `MPC_XY_CRUISE` and the auto modes' vertical
/// speeds `MPC_Z_V_AUTO_UP`/`_DN` (m/s; `MPC_Z_VEL_MAX_*` only caps them). A mission's
/// DO_CHANGE_SPEED overrides the cruise speed on both.
pub fn speed_params(flavor: Flavor) -> &'static [(&'static str, ParamUse)] {
    const fn speed(what: SpeedParam, to_mps: f64) -> ParamUse {
        ParamUse::Speed { what, to_mps }
    }
    const ARDUPILOT: [(&str, ParamUse); 3] = [
        ("WPNAV_SPEED", speed(SpeedParam::Cruise, 0.01)),
        ("WPNAV_SPEED_UP", speed(SpeedParam::Climb, 0.01)),
        ("WPNAV_SPEED_DN", speed(SpeedParam::Descent, 0.01)),
    ];
    const PX4: [(&str, ParamUse); 3] = [
        ("MPC_XY_CRUISE", speed(SpeedParam::Cruise, 1.0)),
        ("MPC_Z_V_AUTO_UP", speed(SpeedParam::Climb, 1.0)),
        ("MPC_Z_V_AUTO_DN", speed(SpeedParam::Descent, 1.0)),
    ];
    match flavor {
        Flavor::ArduPilot => &ARDUPILOT,
        Flavor::Px4 => &PX4,
        Flavor::Other => &[],
    }
}

/// The pack parameters each autopilot family names, read with PARAM_REQUEST_READ: the capacity
/// (mAh) and, where there is one, the cell count. ArduPilot has no cell-count parameter.
pub fn pack_params(flavor: Flavor) -> &'static [(&'static str, PackParam)] {
    match flavor {
        Flavor::ArduPilot => &[("BATT_CAPACITY", PackParam::CapacityMah)],
        Flavor::Px4 => &[
            ("BAT1_CAPACITY", PackParam::CapacityMah),
            ("BAT1_N_CELLS", PackParam::Cells),
        ],
        Flavor::Other => &[],
    }
}

/// PARAM_REQUEST_READ of one pack parameter is sent at most this many times ...
pub const PACK_PARAM_ATTEMPTS: u32 = 5;
/// ... this far apart, until the autopilot answers (PARAM_VALUE is not acknowledged otherwise).
pub const PACK_PARAM_RETRY: Duration = Duration::from_secs(2);

/// The pack and speed parameters asked for (the chosen autopilot's family's [`pack_params`]
/// and [`speed_params`]), inside [`Vehicle`].
#[derive(Debug, Clone, Default)]
pub(super) struct PackRequests(Vec<PackRequest>);

/// One pack parameter asked for until the autopilot answers.
#[derive(Debug, Clone)]
struct PackRequest {
    name: &'static str,
    what: ParamUse,
    sent: u32,
    next_at: Duration,
    answered: bool,
}

impl PackRequests {
    /// Ask (again) for the pack and speed parameters of the chosen autopilot's family.
    pub(super) fn reset(&mut self, flavor: Flavor) {
        let pack = pack_params(flavor)
            .iter()
            .map(|&(name, what)| (name, ParamUse::Pack(what)));
        self.0 = pack
            .chain(speed_params(flavor).iter().copied())
            .map(|(name, what)| PackRequest {
                name,
                what,
                sent: 0,
                next_at: Duration::ZERO,
                answered: false,
            })
            .collect();
    }

    /// PARAM_REQUEST_READ of the pack parameters not answered yet, each retried a few times.
    pub(super) fn request(&mut self, now: Duration, target: Option<(u8, u8)>, out: &mut Vec<Msg>) {
        let Some((sys, comp)) = target else {
            return;
        };
        for r in &mut self.0 {
            if r.answered || r.sent >= PACK_PARAM_ATTEMPTS || now < r.next_at {
                continue;
            }
            r.sent += 1;
            r.next_at = now + PACK_PARAM_RETRY;
            out.push(Msg::PARAM_REQUEST_READ(PARAM_REQUEST_READ_DATA {
                param_index: -1,
                target_system: sys,
                target_component: comp,
                param_id: r.name.into(),
            }));
        }
    }

    /// A PARAM_VALUE from the autopilot: a parameter asked for goes to the telemetry (also the
    /// PARAM_VALUE the autopilot broadcasts after anyone's PARAM_SET: the value in force).
    /// A link event when the value says something the operator should hear.
    pub(super) fn on_param_value(
        &mut self,
        p: &PARAM_VALUE_DATA,
        flavor: Flavor,
        telemetry: &mut Telemetry,
    ) -> Option<LinkEvent> {
        let id = p.param_id.to_str().unwrap_or("").trim_end_matches('\0');
        let r = self.0.iter_mut().find(|r| r.name == id)?;
        // PX4 sends integer parameters bytewise in the float (MAV_PROTOCOL_CAPABILITY_PARAM_
        // ENCODE_BYTEWISE); ArduPilot casts them to float.
        let int = matches!(
            p.param_type,
            MavParamType::MAV_PARAM_TYPE_INT32
                | MavParamType::MAV_PARAM_TYPE_UINT32
                | MavParamType::MAV_PARAM_TYPE_INT16
                | MavParamType::MAV_PARAM_TYPE_UINT16
                | MavParamType::MAV_PARAM_TYPE_INT8
                | MavParamType::MAV_PARAM_TYPE_UINT8
        );
        let value = if int && flavor == Flavor::Px4 {
            p.param_value.to_bits() as i32 as f64
        } else {
            p.param_value as f64
        };
        r.answered = true;
        let (name, what) = match r.what {
            ParamUse::Pack(what) => (r.name, what),
            ParamUse::Speed { what, to_mps } => {
                telemetry.on_speed_param(what, value * to_mps);
                return None;
            }
        };
        telemetry.on_pack_param(what, value);
        (what == PackParam::CapacityMah && value <= 0.0).then(|| {
            LinkEvent::Other(format!(
                "autopilot {name} = {value}: the pack's capacity is not set, the guarantee uses params [battery]"
            ))
        })
    }
}
