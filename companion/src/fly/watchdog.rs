//! systemd's service notifications (deploy/companion.service: `Type=notify`, `WatchdogSec=`):
//! READY=1 once the fly loop turns, WATCHDOG=1 from the loop while it is alive, STOPPING=1 at the
//! stop. A hung loop (or one whose decision cycles stopped while the autopilot is known) stops
//! pinging, systemd kills it and starts it again, and the new run finds the vehicle as any start
//! does ([`super::restart`]: a flight in progress is said and handed off). Outside systemd
//! (`NOTIFY_SOCKET` unset) every call does nothing (`sd_notify::notify` returns at once).

use sd_notify::NotifyState;
use std::time::Duration;

/// The loop's side of the watchdog: when to ping.
#[derive(Debug, Clone)]
pub(super) struct Watchdog {
    /// Half of systemd's `WatchdogSec` (its `WATCHDOG_USEC`), as sd_watchdog_enabled(3)
    /// advises; None when systemd runs no watchdog for this process.
    every: Option<Duration>,
    /// The decision cycles count as hung after this long without one (once the autopilot is
    /// known: before, no cycle runs).
    cycle_stale: Duration,
    last_ping: Option<Duration>,
}

impl Watchdog {
    /// The watchdog systemd asked for (none outside systemd); `decision_period_s` sets how
    /// old the last decision cycle may be.
    pub(super) fn from_env(decision_period_s: f64) -> Self {
        Self::new(sd_notify::watchdog_enabled(), decision_period_s)
    }

    fn new(watchdog_usec: Option<Duration>, decision_period_s: f64) -> Self {
        Self {
            every: watchdog_usec.map(|d| d / 2),
            // Three missed periodic cycles, never under 3 s.
            cycle_stale: Duration::from_secs_f64((3.0 * decision_period_s).max(3.0)),
            last_ping: None,
        }
    }

    /// READY=1 (and a status line for `systemctl status`): the loop runs.
    pub(super) fn ready(&self) {
        let _ = sd_notify::notify(&[NotifyState::Ready, NotifyState::Status("fly loop running")]);
    }

    /// STOPPING=1: the stop has begun (a hand-off may still be awaited).
    pub(super) fn stopping(&self) {
        let _ = sd_notify::notify(&[NotifyState::Stopping]);
    }

    /// One turn of the loop at `now`: WATCHDOG=1 when a ping is due and the loop is alive (no
    /// autopilot known yet, or a decision cycle ran within `cycle_stale`).
    pub(super) fn turn(
        &mut self,
        now: Duration,
        autopilot_known: bool,
        last_cycle: Option<Duration>,
    ) {
        if self.due(now, autopilot_known, last_cycle) {
            self.last_ping = Some(now);
            let _ = sd_notify::notify(&[NotifyState::Watchdog]);
        }
    }

    fn due(&self, now: Duration, autopilot_known: bool, last_cycle: Option<Duration>) -> bool {
        let Some(every) = self.every else {
            return false;
        };
        let cycles_alive = !autopilot_known
            || last_cycle.is_some_and(|c| now.saturating_sub(c) <= self.cycle_stale);
        cycles_alive
            && self
                .last_ping
                .is_none_or(|l| now.saturating_sub(l) >= every)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(t: f64) -> Duration {
        Duration::from_secs_f64(t)
    }

    #[test]
    fn pings_at_half_the_watchdog_only_while_the_cycles_run() {
        let mut w = Watchdog::new(Some(s(10.0)), 1.0);
        // Before the autopilot is known, the loop's turns are the life sign.
        assert!(w.due(s(0.0), false, None));
        w.turn(s(0.0), false, None);
        assert!(!w.due(s(4.9), false, None), "every WatchdogSec / 2");
        assert!(w.due(s(5.0), false, None));
        w.turn(s(5.0), true, Some(s(4.5)));
        // The cycles stopped: no ping, however often the loop turns.
        assert!(!w.due(s(10.0), true, Some(s(6.0))), "last cycle 4 s ago");
        assert!(w.due(s(10.0), true, Some(s(7.5))));
        assert!(!w.due(s(10.0), true, None));
        // Outside systemd's watchdog: never.
        let w = Watchdog::new(None, 1.0);
        assert!(!w.due(s(100.0), false, None));
    }
}
