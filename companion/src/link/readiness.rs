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

use super::dialect::{EKF_STATUS_REPORT_DATA, EkfStatusFlags, MavSysStatusSensor, SYS_STATUS_DATA};
use std::time::Duration;

#[derive(Debug, Clone, Default)]
pub struct Readiness {
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
    pub armed: bool,
}

impl Readiness {
    pub fn on_sys_status(&mut self, now: Duration, s: &SYS_STATUS_DATA) {
        self.sys_status_at = Some(now);
        let bit = MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK;
        if s.onboard_control_sensors_present.contains(bit)
            && s.onboard_control_sensors_enabled.contains(bit)
        {
            self.prearm = Some((s.onboard_control_sensors_health.contains(bit), now));
        }
    }

    pub fn on_ekf(&mut self, now: Duration, e: &EKF_STATUS_REPORT_DATA) {
        let need = EkfStatusFlags::EKF_ATTITUDE
            | EkfStatusFlags::EKF_VELOCITY_HORIZ
            | EkfStatusFlags::EKF_POS_HORIZ_ABS
            | EkfStatusFlags::EKF_POS_VERT_ABS;
        let bad = EkfStatusFlags::EKF_UNINITIALIZED | EkfStatusFlags::EKF_CONST_POS_MODE;
        self.ekf = Some((e.flags.contains(need) && !e.flags.intersects(bad), now));
    }

    /// STATUSTEXT: remembers `PreArm:` failures (ArduPilot repeats them while checks fail).
    pub fn on_text(&mut self, now: Duration, text: &str) {
        if text.starts_with("PreArm:") || text.starts_with("Arm:") {
            self.prearm_text = Some((text.to_string(), now));
        }
    }

    /// A failed arm: forget earlier good reports, wait for a fresh one.
    pub fn invalidate(&mut self, now: Duration) {
        self.fresh_after = now;
    }

    /// Forget everything (autopilot rebooted or link re-established).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Ok when the autopilot says it is ready; else the reasons it is not.
    pub fn check(&self) -> Result<(), Vec<String>> {
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
                why.push(format!("autopilot says {text:?}"));
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
}
