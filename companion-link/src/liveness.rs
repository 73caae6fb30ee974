//! Is the autopilot there? Alive while any message arrives from it; lost after `timeout` of
//! silence. A reboot shows as its boot clock (SYSTEM_TIME.time_boot_ms) going backwards.
//!
//! On loss the companion stops commanding and leaves the vehicle to its own failsafes
//! (ArduPilot's GCS/radio failsafes do not depend on us); on regain or reboot it re-requests its
//! streams and decides afresh from new telemetry: nothing queued before the loss is replayed.

use std::time::Duration;

/// A change in whether the autopilot is heard.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LivenessEvent {
    /// First message from the autopilot.
    Connected,
    /// Nothing heard for the timeout.
    Lost,
    /// Heard again after a loss.
    Regained,
    /// The autopilot restarted (boot clock went backwards).
    Rebooted,
}

/// Whether the autopilot is heard, from message arrival times on the caller's clock.
#[derive(Debug, Clone)]
pub struct Liveness {
    /// Silence after which the link counts as lost.
    pub timeout: Duration,
    last_heard: Option<Duration>,
    alive: bool,
    last_boot_ms: Option<u32>,
    /// Losses since start.
    pub losses: u32,
}

impl Liveness {
    /// Not yet heard; lost after `timeout` of silence once heard.
    pub fn new(timeout: Duration) -> Self {
        Self {
            timeout,
            last_heard: None,
            alive: false,
            last_boot_ms: None,
            losses: 0,
        }
    }

    /// Whether the autopilot was heard within the timeout.
    pub fn alive(&self) -> bool {
        self.alive
    }

    /// Any message from the autopilot.
    pub fn on_message(&mut self, now: Duration) -> Option<LivenessEvent> {
        let first = self.last_heard.is_none();
        self.last_heard = Some(now);
        if self.alive {
            return None;
        }
        self.alive = true;
        Some(if first {
            LivenessEvent::Connected
        } else {
            LivenessEvent::Regained
        })
    }

    /// The autopilot's milliseconds since boot (SYSTEM_TIME). A jump back of more than a second
    /// is a reboot; small steps back are reordering.
    pub fn on_boot_time(&mut self, time_boot_ms: u32) -> Option<LivenessEvent> {
        let prev = self.last_boot_ms.replace(time_boot_ms);
        match prev {
            Some(p) if time_boot_ms + 1000 < p => Some(LivenessEvent::Rebooted),
            _ => None,
        }
    }

    /// Check the clock: `Lost` once, when the silence reaches the timeout.
    pub fn tick(&mut self, now: Duration) -> Option<LivenessEvent> {
        match self.last_heard {
            Some(t) if self.alive && now.saturating_sub(t) >= self.timeout => {
                self.alive = false;
                self.losses += 1;
                Some(LivenessEvent::Lost)
            }
            _ => None,
        }
    }
}

/// Longest duration [`parse_duration`] accepts: 24 h. Longer timeouts and run lengths are typos,
/// and unbounded ones overflow the clock arithmetic they feed.
pub const MAX_DURATION: Duration = Duration::from_secs(24 * 3600);

/// Parse `3s`, `500ms`, `2.5s` or a bare number of seconds: finite, positive and at most
/// [`MAX_DURATION`].
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let (num, scale) = if let Some(v) = t.strip_suffix("ms") {
        (v, 1e-3)
    } else if let Some(v) = t.strip_suffix('s') {
        (v, 1.0)
    } else {
        (t, 1.0)
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a duration like 3s or 500ms"))?;
    if !v.is_finite() || v <= 0.0 {
        return Err(format!("{s:?}: duration must be positive"));
    }
    let secs = v * scale;
    if secs > MAX_DURATION.as_secs_f64() {
        return Err(format!(
            "{s:?}: duration must be at most {} s (24 h)",
            MAX_DURATION.as_secs()
        ));
    }
    Duration::try_from_secs_f64(secs).map_err(|e| format!("{s:?}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(v: f64) -> Duration {
        Duration::from_secs_f64(v)
    }

    #[test]
    fn lost_after_silence_and_regained_on_next_message() {
        let mut l = Liveness::new(s(3.0));
        assert_eq!(l.tick(s(10.0)), None, "never heard: nothing to lose");
        assert_eq!(l.on_message(s(0.0)), Some(LivenessEvent::Connected));
        assert_eq!(l.on_message(s(1.0)), None);
        assert_eq!(l.tick(s(3.9)), None);
        assert_eq!(l.tick(s(4.0)), Some(LivenessEvent::Lost));
        assert_eq!(l.tick(s(5.0)), None, "lost once");
        assert!(!l.alive());
        assert_eq!(l.on_message(s(6.0)), Some(LivenessEvent::Regained));
        assert_eq!(l.losses, 1);
    }

    #[test]
    fn reboot_is_the_boot_clock_going_back() {
        let mut l = Liveness::new(s(3.0));
        assert_eq!(l.on_boot_time(50_000), None);
        assert_eq!(l.on_boot_time(50_900), None);
        assert_eq!(l.on_boot_time(50_400), None, "reordering is not a reboot");
        assert_eq!(l.on_boot_time(1_200), Some(LivenessEvent::Rebooted));
        assert_eq!(l.on_boot_time(2_200), None);
    }

    #[test]
    fn durations() {
        assert_eq!(parse_duration("3s").unwrap(), s(3.0));
        assert_eq!(parse_duration("500ms").unwrap(), s(0.5));
        assert_eq!(parse_duration("2.5").unwrap(), s(2.5));
        assert!(parse_duration("soon").is_err());
        assert!(parse_duration("0s").is_err());
        assert!(parse_duration("-1s").is_err());
    }

    #[test]
    fn durations_beyond_a_day_or_not_finite_are_refused() {
        assert_eq!(parse_duration("86400s").unwrap(), MAX_DURATION);
        for bad in [
            "86401s",
            "1e30s",
            "1e30",
            "18446744073709551616",
            "inf",
            "nan",
            "1e400ms",
        ] {
            let e = parse_duration(bad).unwrap_err();
            assert!(e.contains(bad), "{bad}: {e}");
        }
    }
}
