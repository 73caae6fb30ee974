//! Which autopilot is obeyed: the choice on HEARTBEATs (pin, component 1 preferred), the
//! others reported, and the trust notes.

use super::*;

/// Distinct other autopilots reported by name; more are only counted.
pub(super) const MAX_OTHER_AUTOPILOTS: usize = 16;

/// MAV_COMP_ID_AUTOPILOT1: the component an autopilot speaks from (ArduPilot and PX4 alike).
pub const AUTOPILOT_COMPONENT: u8 = 1;

/// Without a pin, an autopilot HEARTBEAT from a component other than 1 is chosen only after it
/// has been heard this long with no component-1 autopilot speaking: a real autopilot is
/// preferred over an impostor on another component of the same system that spoke first.
pub const OTHER_COMPONENT_WAIT: Duration = Duration::from_secs(2);

/// What an autopilot HEARTBEAT does to the choice of the autopilot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Choice {
    /// It is the autopilot: choose it now.
    Take,
    /// Not component 1 and no pin: chosen only if it is still the only one after
    /// [`OTHER_COMPONENT_WAIT`].
    Wait,
    /// Another autopilot: reported, never obeyed.
    Other,
}

/// Which autopilot is obeyed and who else was heard (inside [`Vehicle`]): the candidate on
/// another component, the other autopilots, and the trust counters.
#[derive(Debug, Clone, Default)]
pub(super) struct Identity {
    /// Without a pin: an autopilot on a component other than 1, and when it was first heard,
    /// waiting [`OTHER_COMPONENT_WAIT`] for a component-1 autopilot before it is chosen.
    pub(super) candidate: Option<((u8, u8), Duration)>,
    /// Other autopilots heard (reported once each, never obeyed).
    other_autopilots: std::collections::BTreeSet<(u8, u8)>,
    /// Refused for trust reasons since start: monitor frames from components not allowed ...
    pub(super) foreign_monitor_frames: u64,
    /// ... and HEARTBEATs from other autopilots, ignored.
    pub(super) other_autopilot_heartbeats: u64,
    /// The totals as last reported in a link event.
    trust_reported: (u64, u64, u64, u64),
}

impl Identity {
    /// One link event when frames or values were refused for trust since the last report.
    pub(super) fn trust_note(
        &mut self,
        telemetry: &Telemetry,
        cfg: &VehicleConfig,
    ) -> Option<String> {
        let r = &telemetry.rejected;
        let now = (
            self.foreign_monitor_frames,
            r.out_of_range,
            r.names_dropped,
            self.other_autopilot_heartbeats,
        );
        if now == self.trust_reported {
            return None;
        }
        self.trust_reported = now;
        let last = r
            .last
            .as_deref()
            .map(|l| format!(" (last: {l})"))
            .unwrap_or_default();
        Some(format!(
            "trust: {} monitor frames from components not allowed, {} values out of range{last}, {} onboard names dropped (over the cap of {} or not printable), {} heartbeats from other autopilots refused (since start)",
            now.0, now.1, now.2, cfg.telemetry.max_onboard_names, now.3
        ))
    }

    /// An autopilot other than the chosen one (or than the one `--autopilot-sysid` asks for)
    /// speaks: reported once per identity (the link event returned), never obeyed.
    pub(super) fn other_autopilot(
        &mut self,
        (sys, comp): (u8, u8),
        target: Option<(u8, u8)>,
        cfg: &VehicleConfig,
    ) -> Option<LinkEvent> {
        self.other_autopilot_heartbeats += 1;
        if self.other_autopilots.len() >= MAX_OTHER_AUTOPILOTS
            || !self.other_autopilots.insert((sys, comp))
        {
            return None;
        }
        let why = match (target, cfg.autopilot_sysid) {
            (Some((ts, tc)), _) => format!("autopilot {ts}/{tc} already chosen"),
            (None, Some(want)) => format!(
                "--autopilot-sysid {want} --autopilot-compid {}",
                cfg.autopilot_compid
            ),
            (None, None) => match self.candidate {
                Some(((cs, cc), _)) => format!("autopilot {cs}/{cc} heard first"),
                None => "not chosen".to_string(),
            },
        };
        tracing::warn!(
            sys,
            comp,
            "another autopilot {sys}/{comp} heard and ignored ({why})"
        );
        Some(LinkEvent::OtherAutopilot {
            system: sys,
            component: comp,
            why: why.to_string(),
        })
    }

    /// Whether the autopilot HEARTBEAT of `sys`/`comp` (not the chosen one) chooses it: with a
    /// pin only that system and component; without one, component 1 at once and another
    /// component only after [`OTHER_COMPONENT_WAIT`] with no component 1 heard.
    pub(super) fn choice(
        &mut self,
        now: Duration,
        (sys, comp): (u8, u8),
        target: Option<(u8, u8)>,
        cfg: &VehicleConfig,
    ) -> Choice {
        if target.is_some() {
            return Choice::Other;
        }
        if let Some(want) = cfg.autopilot_sysid {
            return if (sys, comp) == (want, cfg.autopilot_compid) {
                Choice::Take
            } else {
                Choice::Other
            };
        }
        if comp == AUTOPILOT_COMPONENT {
            return Choice::Take;
        }
        match self.candidate {
            None => {
                self.candidate = Some(((sys, comp), now));
                Choice::Wait
            }
            Some((id, since)) if id == (sys, comp) => {
                if now.saturating_sub(since) >= OTHER_COMPONENT_WAIT {
                    Choice::Take
                } else {
                    Choice::Wait
                }
            }
            Some(_) => Choice::Other,
        }
    }

    /// When the autopilot was chosen without a pin (`--autopilot-sysid`): which one, that it was
    /// the first heard, and how to pin it. `fly` says it on stderr and to the ground station on
    /// a network link, where anyone who can reach the port can speak first.
    pub(super) fn note(cfg: &VehicleConfig, target: Option<(u8, u8)>) -> Option<String> {
        if cfg.autopilot_sysid.is_some() {
            return None;
        }
        let (sys, comp) = target?;
        let compid = if comp == AUTOPILOT_COMPONENT {
            String::new()
        } else {
            format!(" --autopilot-compid {comp}")
        };
        Some(format!(
            "autopilot {sys}/{comp} chosen: the first autopilot heard (no pin); pin it with --autopilot-sysid {sys}{compid}"
        ))
    }
}

/// A HEARTBEAT that can choose the autopilot: from a flight controller (an autopilot type,
/// not INVALID) of a vehicle (not a GCS, companion, gimbal, camera or other peripheral).
/// `--autopilot-sysid` narrows the choice further in `Vehicle::on_frame`; `calibrate` reads a
/// tlog's autopilot by it too.
pub fn is_autopilot_heartbeat(h: &HEARTBEAT_DATA) -> bool {
    h.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID && is_vehicle_type(h.mavtype)
}

/// A vehicle's MAV_TYPE, not a ground station, companion computer or peripheral.
pub(super) fn is_vehicle_type(t: MavType) -> bool {
    !matches!(
        t,
        MavType::MAV_TYPE_GCS
            | MavType::MAV_TYPE_ONBOARD_CONTROLLER
            | MavType::MAV_TYPE_GIMBAL
            | MavType::MAV_TYPE_CAMERA
            | MavType::MAV_TYPE_ADSB
            | MavType::MAV_TYPE_ANTENNA_TRACKER
            | MavType::MAV_TYPE_CHARGING_STATION
            | MavType::MAV_TYPE_FLARM
            | MavType::MAV_TYPE_SERVO
            | MavType::MAV_TYPE_ODID
            | MavType::MAV_TYPE_BATTERY
            | MavType::MAV_TYPE_PARACHUTE
            | MavType::MAV_TYPE_LOG
            | MavType::MAV_TYPE_OSD
            | MavType::MAV_TYPE_IMU
            | MavType::MAV_TYPE_GPS
            | MavType::MAV_TYPE_WINCH
            | MavType::MAV_TYPE_GRIPPER
            | MavType::MAV_TYPE_ILLUMINATOR
            | MavType::MAV_TYPE_RADIO
    )
}
