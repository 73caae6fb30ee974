//! Is the autopilot ready to arm? Only the autopilot knows; we track what it says and never arm
//! (or command) a vehicle it reports as not ready.
//!
//! Evidence (ArduPilot): SYS_STATUS `MAV_SYS_STATUS_PREARM_CHECK` — always present, enabled when
//! arming checks are on (ARMING_CHECK != 0), healthy while armed or while they pass
//! (`GCS::update_sensor_status_flags`, libraries/GCS_MAVLink/GCS.cpp). The bit is the only signal
//! of the fail -> pass edge: `PreArm:` texts repeat every 30 s while failing and stop silently.
//! Also: EKF_STATUS_REPORT flags (attitude, horizontal velocity, absolute horizontal and vertical
//! position, not initialising, not in constant-position mode); `PreArm: ...` STATUSTEXT; a failed
//! arm COMMAND_ACK. After a failed arm, readiness needs a
//! fresh healthy report received after the failure: that is what makes an arm retry not blind.
//!
//! Evidence (PX4, `Flavor::Px4`): PX4 sends no EKF_STATUS_REPORT (ArduPilot's message; a stream
//! request for it is answered FAILED). What it does send:
//! - SYS_STATUS with `MAV_SYS_STATUS_PREARM_CHECK` in `onboard_control_sensors_health` only: its
//!   health-and-arming checks set the health bit while arming is possible and never set it in
//!   present/enabled (seen on PX4 SITL main 2026-03: present 0x0300402f, enabled 0x0301402f,
//!   health 0x0320c83f before and 0x1320c83f after "Ready for takeoff!"). So for PX4 the health
//!   bit alone is the verdict.
//! - HEARTBEAT `system_status`: MAV_STATE_UNINIT while booting, MAV_STATE_STANDBY once on the
//!   ground and ready (commander's `vehicle_status.nav_state` / arming state), ACTIVE when flying.
//! - ESTIMATOR_STATUS (EKF2's solution flags, 1023 once ready on SIH, with bit 7 "constant
//!   position mode" set even when GPS is fused, so that bit is not read): attitude, horizontal
//!   velocity, absolute horizontal and vertical position must be good, no GPS glitch or
//!   accelerometer error.
//! - `Preflight Fail: ...` STATUSTEXT (health_and_arming_checks) while a check fails, e.g.
//!   "heading estimate not stable" in the first seconds.

use super::dialect::{
    EKF_STATUS_REPORT_DATA, ESTIMATOR_STATUS_DATA, EkfStatusFlags, EstimatorStatusFlags, MavState,
    MavSysStatusSensor, SYS_STATUS_DATA,
};
use super::modes::Flavor;
use std::time::Duration;

/// Whether the autopilot reports itself ready to arm, from its own pre-arm and estimator reports.
#[derive(Debug, Clone)]
pub struct Readiness {
    /// Whose evidence counts (set when the autopilot's HEARTBEAT is first seen).
    pub flavor: Flavor,
    /// PX4: last HEARTBEAT system_status is STANDBY (or later: ACTIVE while flying).
    standby: Option<bool>,
    /// Last SYS_STATUS prearm verdict, when the autopilot reports the prearm bit.
    prearm: Option<(bool, Duration)>,
    /// Last EKF verdict.
    ekf: Option<(bool, Duration)>,
    /// Last `PreArm:` text and when it came.
    prearm_text: Option<(String, Duration)>,
    /// Reports older than this do not count (set by a failed arm).
    fresh_after: Duration,
    /// Any SYS_STATUS seen (PX4 sets at most the prearm health bit, never present/enabled, so
    /// its EKF flags decide).
    sys_status_at: Option<Duration>,
    /// Whether the last HEARTBEAT said armed.
    pub armed: bool,
}

impl Default for Readiness {
    fn default() -> Self {
        Self::new(Flavor::Other)
    }
}

impl Readiness {
    /// No report yet; `flavor` says whose evidence counts.
    pub fn new(flavor: Flavor) -> Self {
        Self {
            flavor,
            standby: None,
            prearm: None,
            ekf: None,
            prearm_text: None,
            fresh_after: Duration::ZERO,
            sys_status_at: None,
            armed: false,
        }
    }

    /// HEARTBEAT system_status (read for PX4 only: ArduPilot reports STANDBY before its checks pass).
    pub fn on_heartbeat_status(&mut self, status: MavState) {
        self.standby = Some(matches!(
            status,
            MavState::MAV_STATE_STANDBY | MavState::MAV_STATE_ACTIVE
        ));
    }

    /// ESTIMATOR_STATUS (PX4's estimator report; the EKF verdict for PX4).
    pub fn on_estimator(&mut self, now: Duration, e: &ESTIMATOR_STATUS_DATA) {
        let need = EstimatorStatusFlags::ESTIMATOR_ATTITUDE
            | EstimatorStatusFlags::ESTIMATOR_VELOCITY_HORIZ
            | EstimatorStatusFlags::ESTIMATOR_POS_HORIZ_ABS
            | EstimatorStatusFlags::ESTIMATOR_POS_VERT_ABS;
        let bad = EstimatorStatusFlags::ESTIMATOR_GPS_GLITCH
            | EstimatorStatusFlags::ESTIMATOR_ACCEL_ERROR;
        self.ekf = Some((e.flags.contains(need) && !e.flags.intersects(bad), now));
    }

    /// SYS_STATUS: the prearm-check health bit (ArduPilot only when present and enabled).
    pub fn on_sys_status(&mut self, now: Duration, s: &SYS_STATUS_DATA) {
        self.sys_status_at = Some(now);
        let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        // PX4 sets only the health bit; ArduPilot's counts when the check is present and enabled.
        if self.flavor == Flavor::Px4
            || (s.onboard_control_sensors_present.contains(bit)
                && s.onboard_control_sensors_enabled.contains(bit))
        {
            self.prearm = Some((s.onboard_control_sensors_health.contains(bit), now));
        }
    }

    /// EKF_STATUS_REPORT (ArduPilot's estimator report; the EKF verdict for ArduPilot).
    pub fn on_ekf(&mut self, now: Duration, e: &EKF_STATUS_REPORT_DATA) {
        let need = EkfStatusFlags::EKF_ATTITUDE
            | EkfStatusFlags::EKF_VELOCITY_HORIZ
            | EkfStatusFlags::EKF_POS_HORIZ_ABS
            | EkfStatusFlags::EKF_POS_VERT_ABS;
        let bad = EkfStatusFlags::EKF_UNINITIALIZED | EkfStatusFlags::EKF_CONST_POS_MODE;
        self.ekf = Some((e.flags.contains(need) && !e.flags.intersects(bad), now));
    }

    /// STATUSTEXT: remembers `PreArm:` failures (ArduPilot repeats them while checks fail) and
    /// PX4's `Preflight Fail:` / `Arming denied` texts.
    pub fn on_text(&mut self, now: Duration, text: &str) {
        if text.starts_with("PreArm:")
            || text.starts_with("Arm:")
            || text.starts_with("Preflight Fail")
            || text.starts_with("Arming denied")
        {
            self.prearm_text = Some((text.to_string(), now));
        }
    }

    /// A failed arm: forget earlier good reports, wait for a fresh one.
    pub fn invalidate(&mut self, now: Duration) {
        self.fresh_after = now;
    }

    /// Forget everything (autopilot rebooted or link re-established); the flavour stays.
    pub fn reset(&mut self) {
        *self = Self::new(self.flavor);
    }

    /// Ok when the autopilot says it is ready; else the reasons it is not.
    pub fn check(&self) -> Result<(), Vec<String>> {
        if self.flavor == Flavor::Px4 {
            return self.check_px4();
        }
        let mut why = Vec::new();
        let fresh = |t: Duration| t >= self.fresh_after;
        match self.prearm {
            Some((true, t)) if fresh(t) => {}
            Some((true, _)) => {
                why.push("waiting for a prearm report newer than the last failed arm".into())
            }
            Some((false, _)) => why.push("autopilot prearm checks failing (SYS_STATUS)".into()),
            None if self.sys_status_at.is_none() => {
                why.push("no SYS_STATUS from the autopilot yet".into())
            }
            None => {}
        }
        match self.ekf {
            Some((true, t)) if fresh(t) || self.prearm.is_some() => {}
            Some((true, _)) => {
                why.push("waiting for an EKF report newer than the last failed arm".into())
            }
            Some((false, _)) => {
                why.push("EKF not ready (attitude/velocity/absolute position)".into())
            }
            None if self.prearm.is_none() => why.push("no EKF_STATUS_REPORT yet".into()),
            None => {}
        }
        if let Some((text, at)) = &self.prearm_text {
            // A PreArm text stands until a healthy prearm report arrives after it.
            let cleared = matches!(self.prearm, Some((true, t)) if t > *at);
            if !cleared && self.prearm.is_some() {
                why.push(format!("autopilot says {}", crate::quoted(text)));
            }
        }
        if why.is_empty() { Ok(()) } else { Err(why) }
    }

    /// PX4: STANDBY heartbeat, the prearm health bit, a good ESTIMATOR_STATUS, no standing
    /// `Preflight Fail` text; after a failed arm, a prearm report newer than the failure.
    fn check_px4(&self) -> Result<(), Vec<String>> {
        let mut why = Vec::new();
        match self.standby {
            Some(true) => {}
            Some(false) => why.push("autopilot not in STANDBY (HEARTBEAT system_status)".into()),
            None => why.push("no HEARTBEAT system_status yet".into()),
        }
        match self.prearm {
            Some((true, t)) if t >= self.fresh_after => {}
            Some((true, _)) => {
                why.push("waiting for a prearm report newer than the last failed arm".into())
            }
            Some((false, _)) => why.push("autopilot prearm checks failing (SYS_STATUS)".into()),
            None => why.push("no SYS_STATUS from the autopilot yet".into()),
        }
        match self.ekf {
            Some((true, _)) => {}
            Some((false, _)) => why.push(
                "estimator not ready (ESTIMATOR_STATUS attitude/velocity/absolute position)".into(),
            ),
            None => why.push("no ESTIMATOR_STATUS yet".into()),
        }
        if let Some((text, at)) = &self.prearm_text {
            let cleared = matches!(self.prearm, Some((true, t)) if t > *at);
            if !cleared {
                why.push(format!("autopilot says {}", crate::quoted(text)));
            }
        }
        if why.is_empty() { Ok(()) } else { Err(why) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    fn sys(healthy: bool) -> SYS_STATUS_DATA {
        let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        SYS_STATUS_DATA {
            onboard_control_sensors_present: bit,
            onboard_control_sensors_enabled: bit,
            onboard_control_sensors_health: if healthy {
                bit
            } else {
                MavSysStatusSensor::empty()
            },
            ..SYS_STATUS_DATA::DEFAULT
        }
    }

    fn ekf(good: bool) -> EKF_STATUS_REPORT_DATA {
        let mut flags = EkfStatusFlags::EKF_ATTITUDE
            | EkfStatusFlags::EKF_VELOCITY_HORIZ
            | EkfStatusFlags::EKF_POS_HORIZ_ABS
            | EkfStatusFlags::EKF_POS_VERT_ABS;
        if !good {
            flags |= EkfStatusFlags::EKF_CONST_POS_MODE;
        }
        EKF_STATUS_REPORT_DATA {
            flags,
            ..EKF_STATUS_REPORT_DATA::DEFAULT
        }
    }

    #[test]
    fn nothing_heard_is_not_ready() {
        assert!(Readiness::default().check().is_err());
    }

    #[test]
    fn ready_needs_prearm_bit_and_ekf() {
        let mut r = Readiness::default();
        r.on_sys_status(s(1.0), &sys(true));
        r.on_ekf(s(1.0), &ekf(false));
        assert!(r.check().unwrap_err()[0].contains("EKF"));
        r.on_ekf(s(2.0), &ekf(true));
        assert_eq!(r.check(), Ok(()));
        r.on_sys_status(s(3.0), &sys(false));
        assert!(r.check().is_err());
    }

    #[test]
    fn prearm_text_blocks_until_a_later_healthy_report() {
        let mut r = Readiness::default();
        r.on_sys_status(s(1.0), &sys(true));
        r.on_ekf(s(1.0), &ekf(true));
        r.on_text(s(1.5), "PreArm: Need 3D Fix");
        let why = r.check().unwrap_err();
        assert!(why[0].contains("Need 3D Fix"), "{why:?}");
        r.on_sys_status(s(2.0), &sys(true));
        assert_eq!(r.check(), Ok(()));
    }

    #[test]
    fn failed_arm_requires_a_fresh_report() {
        let mut r = Readiness::default();
        r.on_sys_status(s(1.0), &sys(true));
        r.on_ekf(s(1.0), &ekf(true));
        r.invalidate(s(1.2));
        assert!(
            r.check().is_err(),
            "old report must not count after a failed arm"
        );
        r.on_sys_status(s(2.0), &sys(true));
        assert_eq!(r.check(), Ok(()));
    }

    #[test]
    fn without_prearm_bit_the_ekf_decides() {
        let mut r = Readiness::default();
        r.on_sys_status(s(1.0), &SYS_STATUS_DATA::DEFAULT);
        assert!(r.check().is_err());
        r.on_ekf(s(1.0), &ekf(true));
        assert_eq!(r.check(), Ok(()));
    }

    /// PX4's SYS_STATUS as seen from PX4 SITL (main, 2026-03): the prearm bit only in health.
    fn px4_sys(ready: bool) -> SYS_STATUS_DATA {
        let health = if ready { 0x1320_c83f } else { 0x0320_c83f };
        SYS_STATUS_DATA {
            onboard_control_sensors_present: MavSysStatusSensor::from_bits_truncate(0x0300_402f),
            onboard_control_sensors_enabled: MavSysStatusSensor::from_bits_truncate(0x0301_402f),
            onboard_control_sensors_health: MavSysStatusSensor::from_bits_truncate(health),
            ..SYS_STATUS_DATA::DEFAULT
        }
    }

    /// ESTIMATOR_STATUS flags as PX4 SITL sends them: 164 while aligning, 1023 once ready.
    fn px4_estimator(flags: u16) -> ESTIMATOR_STATUS_DATA {
        ESTIMATOR_STATUS_DATA {
            flags: EstimatorStatusFlags::from_bits_truncate(flags),
            ..ESTIMATOR_STATUS_DATA::DEFAULT
        }
    }

    fn px4_ready_at(r: &mut Readiness, t: f64) {
        r.on_heartbeat_status(MavState::MAV_STATE_STANDBY);
        r.on_sys_status(s(t), &px4_sys(true));
        r.on_estimator(s(t), &px4_estimator(1023));
    }

    #[test]
    fn px4_ready_from_health_bit_standby_and_estimator_without_ekf_status_report() {
        let mut r = Readiness::new(Flavor::Px4);
        r.on_heartbeat_status(MavState::MAV_STATE_UNINIT);
        r.on_sys_status(s(1.0), &px4_sys(false));
        r.on_estimator(s(1.0), &px4_estimator(164));
        let why = r.check().unwrap_err();
        assert_eq!(why.len(), 3, "{why:?}");
        assert!(
            why.iter().all(|w| !w.contains("EKF_STATUS_REPORT")),
            "{why:?}"
        );
        px4_ready_at(&mut r, 2.0);
        assert_eq!(r.check(), Ok(()), "PX4 never sends EKF_STATUS_REPORT");
        // The same SYS_STATUS means "not ready" to an ArduPilot reading (bit not present).
        let mut ap = Readiness::new(Flavor::ArduPilot);
        ap.on_sys_status(s(1.0), &px4_sys(true));
        assert!(ap.check().is_err());
    }

    #[test]
    fn px4_each_missing_piece_blocks_arming() {
        let mut r = Readiness::new(Flavor::Px4);
        px4_ready_at(&mut r, 1.0);
        r.on_heartbeat_status(MavState::MAV_STATE_CRITICAL);
        assert!(r.check().unwrap_err()[0].contains("STANDBY"));
        px4_ready_at(&mut r, 2.0);
        r.on_sys_status(s(3.0), &px4_sys(false));
        assert!(r.check().unwrap_err()[0].contains("prearm"));
        px4_ready_at(&mut r, 4.0);
        // A GPS glitch (1024) spoils an otherwise complete estimate.
        r.on_estimator(s(5.0), &px4_estimator(1023 | 1024));
        assert!(r.check().unwrap_err()[0].contains("estimator"));
        px4_ready_at(&mut r, 6.0);
        assert_eq!(r.check(), Ok(()));
    }

    #[test]
    fn px4_preflight_fail_text_blocks_until_a_later_healthy_report() {
        let mut r = Readiness::new(Flavor::Px4);
        px4_ready_at(&mut r, 1.0);
        r.on_text(s(1.5), "Preflight Fail: heading estimate not stable");
        let why = r.check().unwrap_err();
        assert!(why[0].contains("heading estimate"), "{why:?}");
        px4_ready_at(&mut r, 2.0);
        assert_eq!(r.check(), Ok(()));
    }

    #[test]
    fn px4_failed_arm_requires_a_fresh_prearm_report_and_reset_keeps_flavor() {
        let mut r = Readiness::new(Flavor::Px4);
        px4_ready_at(&mut r, 1.0);
        r.invalidate(s(1.2));
        assert!(r.check().is_err());
        px4_ready_at(&mut r, 2.0);
        assert_eq!(r.check(), Ok(()));
        r.reset();
        assert_eq!(r.flavor, Flavor::Px4);
        assert!(r.check().is_err());
    }
}
