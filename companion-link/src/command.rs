//! The MAVLink command protocol (COMMAND_LONG / COMMAND_INT → COMMAND_ACK), sans IO.
//!
//! Rules (MAVLink command protocol, ArduPilot GCS_MAVLink behaviour):
//! - one command in flight per command id (an ACK names only the command id, so two in flight
//!   with the same id could not be told apart);
//! - no ACK within `ack_timeout`: resend with `confirmation` + 1, up to `max_attempts` sends;
//! - `TEMPORARILY_REJECTED`: try again after `retry_later`, within the same attempt budget;
//! - `IN_PROGRESS`: the autopilot is working on it; the deadline moves to `in_progress_timeout`
//!   from now and nothing is resent (a resend could restart the operation);
//! - `DENIED`, `FAILED`, `UNSUPPORTED`, `CANCELLED`, ...: final, never retried;
//! - commands marked `no_blind_retry` (arming) are sent once: a lost ACK or a temporary
//!   rejection ends them as failed, and the caller decides whether the autopilot is ready again.
//!
//! Every submitted command ends in exactly one [`CommandEvent::Finished`].

use super::dialect::{COMMAND_INT_DATA, COMMAND_LONG_DATA, MavCmd, MavFrame, MavResult};
use super::{Msg, OUR_COMPONENT_ID};
use companion_core::record::CommandOutcome;
use std::collections::BTreeMap;
use std::time::Duration;

/// What to send: COMMAND_LONG, or COMMAND_INT when it carries a position.
#[derive(Debug, Clone, PartialEq)]
pub enum CommandBody {
    /// COMMAND_LONG: seven float parameters.
    Long {
        /// param1..param7 as the command defines them.
        params: [f32; 7],
    },
    /// COMMAND_INT: a position in integer coordinates.
    Int {
        /// param1..param4 as the command defines them.
        params: [f32; 4],
        /// Coordinate frame of `x`, `y`, `z`.
        frame: MavFrame,
        /// Latitude (degE7) or local x, depending on `frame`.
        x: i32,
        /// Longitude (degE7) or local y, depending on `frame`.
        y: i32,
        /// Altitude (m) in `frame`.
        z: f32,
    },
}

/// A command to run.
#[derive(Debug, Clone, PartialEq)]
pub struct CommandSpec {
    /// MAV_CMD id.
    pub command: MavCmd,
    /// Message kind and parameters.
    pub body: CommandBody,
    /// Never resend on timeout or temporary rejection (arming).
    pub no_blind_retry: bool,
}

impl CommandSpec {
    /// A COMMAND_LONG that may be resent.
    pub fn long(command: MavCmd, params: [f32; 7]) -> Self {
        Self {
            command,
            body: CommandBody::Long { params },
            no_blind_retry: false,
        }
    }
    /// A COMMAND_INT that may be resent.
    pub fn int(command: MavCmd, frame: MavFrame, params: [f32; 4], x: i32, y: i32, z: f32) -> Self {
        Self {
            command,
            body: CommandBody::Int {
                params,
                frame,
                x,
                y,
                z,
            },
            no_blind_retry: false,
        }
    }
    /// The same command, sent once only (no resend on timeout or temporary rejection).
    pub fn once(mut self) -> Self {
        self.no_blind_retry = true;
        self
    }
    /// `MAV_CMD_NAV_TAKEOFF`, ... (the name the decision log shows).
    pub fn name(&self) -> String {
        crate::mavlink_name(&self.command)
    }
}

/// Protocol timing; defaults follow MAVSDK/QGC practice (ArduPilot ACKs within one loop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandConfig {
    /// Time to wait for an ACK before resending (default 1.5 s).
    pub ack_timeout: Duration,
    /// Sends allowed per command, the first included (default 3).
    pub max_attempts: u32,
    /// Wait after TEMPORARILY_REJECTED before trying again (default 1 s).
    pub retry_later: Duration,
    /// Deadline after an IN_PROGRESS answer, from that answer (default 10 s).
    pub in_progress_timeout: Duration,
}

impl Default for CommandConfig {
    fn default() -> Self {
        Self {
            ack_timeout: Duration::from_millis(1500),
            max_attempts: 3,
            retry_later: Duration::from_secs(1),
            in_progress_timeout: Duration::from_secs(10),
        }
    }
}

/// How a command ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// ACCEPTED.
    Acked,
    /// Anything else, and why.
    Failed(FailReason),
}

/// Why a command did not end ACCEPTED.
#[derive(Debug, Clone, PartialEq)]
pub enum FailReason {
    /// A final MAV_RESULT other than ACCEPTED (DENIED, FAILED, UNSUPPORTED, ...).
    Result(MavResult),
    /// No ACK after every allowed attempt.
    Timeout,
    /// Still TEMPORARILY_REJECTED when the attempts ran out (or on the only attempt).
    TemporarilyRejected,
    /// Dropped without an answer (link lost, superseded).
    Cancelled(String),
}

impl Outcome {
    /// The `CommandRecord.result` spelling.
    pub fn label(&self) -> CommandOutcome {
        match self {
            Outcome::Acked => CommandOutcome::Accepted,
            Outcome::Failed(FailReason::Result(r)) => match r {
                MavResult::MAV_RESULT_ACCEPTED => CommandOutcome::Accepted,
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED => CommandOutcome::TemporarilyRejected,
                MavResult::MAV_RESULT_DENIED => CommandOutcome::Denied,
                MavResult::MAV_RESULT_UNSUPPORTED => CommandOutcome::Unsupported,
                MavResult::MAV_RESULT_FAILED => CommandOutcome::Failed(None),
                MavResult::MAV_RESULT_IN_PROGRESS => CommandOutcome::InProgress,
                MavResult::MAV_RESULT_CANCELLED => CommandOutcome::Cancelled(None),
                // The rarer answers keep the MAV_RESULT name.
                other => CommandOutcome::Other(
                    crate::mavlink_name(other)
                        .trim_start_matches("MAV_RESULT_")
                        .to_string(),
                ),
            },
            Outcome::Failed(FailReason::Timeout) => CommandOutcome::Timeout(None),
            Outcome::Failed(FailReason::TemporarilyRejected) => CommandOutcome::TemporarilyRejected,
            Outcome::Failed(FailReason::Cancelled(why)) => {
                CommandOutcome::Cancelled(Some(why.clone()))
            }
        }
    }
}

/// Something the caller should know.
#[derive(Debug, Clone, PartialEq)]
pub enum CommandEvent {
    /// IN_PROGRESS with a progress report.
    Progress {
        /// Ticket [`CommandClient::submit`] returned.
        ticket: u64,
        /// The command's MAV_CMD id.
        command: MavCmd,
        /// Progress the autopilot reported (%).
        percent: u8,
    },
    /// The command ended; the last event of its ticket.
    Finished {
        /// Ticket [`CommandClient::submit`] returned.
        ticket: u64,
        /// The command's MAV_CMD id.
        command: MavCmd,
        /// How it ended.
        outcome: Outcome,
        /// Sends made.
        attempts: u32,
        /// Caller's clock at the first send.
        first_sent: Duration,
        /// Caller's clock when it ended.
        finished: Duration,
    },
}

#[derive(Debug, Clone, PartialEq)]
enum Wait {
    Ack { deadline: Duration },
    InProgress { deadline: Duration },
    RetryAt(Duration),
}

#[derive(Debug, Clone)]
struct Pending {
    ticket: u64,
    spec: CommandSpec,
    attempts: u32,
    first_sent: Duration,
    wait: Wait,
}

/// Submit refused: a command with the same id is already in flight.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{} already in flight", crate::mavlink_name(.0))]
pub struct Busy(pub MavCmd);

/// The command client for one autopilot.
#[derive(Debug, Clone)]
pub struct CommandClient {
    /// Protocol timing.
    pub cfg: CommandConfig,
    /// MAVLink system id commands go to.
    pub target_system: u8,
    /// MAVLink component id commands go to.
    pub target_component: u8,
    our_system: u8,
    pending: BTreeMap<u32, Pending>,
    next_ticket: u64,
}

impl CommandClient {
    /// A client with no command in flight, targeting system 1 component 1 until
    /// [`Self::set_target`].
    pub fn new(cfg: CommandConfig) -> Self {
        Self {
            cfg,
            target_system: 1,
            target_component: 1,
            our_system: super::DEFAULT_SYSTEM_ID,
            pending: BTreeMap::new(),
            next_ticket: 1,
        }
    }

    /// Address the autopilot `system`/`component` from now on.
    pub fn set_target(&mut self, system: u8, component: u8) {
        self.target_system = system;
        self.target_component = component;
        self.our_system = system;
    }

    /// Whether a command with this id waits for its answer.
    pub fn in_flight(&self, command: MavCmd) -> bool {
        self.pending.contains_key(&(command as u32))
    }

    /// Commands waiting for their answer.
    pub fn pending_count(&self) -> usize {
        self.pending.len()
    }

    /// Send `spec` now. Returns the ticket that its events carry and the message to send.
    pub fn submit(&mut self, now: Duration, spec: CommandSpec) -> Result<(u64, Vec<Msg>), Busy> {
        let key = spec.command as u32;
        if self.pending.contains_key(&key) {
            return Err(Busy(spec.command));
        }
        let ticket = self.next_ticket;
        self.next_ticket += 1;
        let msg = self.encode(&spec, 0);
        self.pending.insert(
            key,
            Pending {
                ticket,
                spec,
                attempts: 1,
                first_sent: now,
                wait: Wait::Ack {
                    deadline: now + self.cfg.ack_timeout,
                },
            },
        );
        Ok((ticket, vec![msg]))
    }

    fn encode(&self, spec: &CommandSpec, confirmation: u8) -> Msg {
        match &spec.body {
            CommandBody::Long { params: p } => Msg::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                param5: p[4],
                param6: p[5],
                param7: p[6],
                command: spec.command,
                target_system: self.target_system,
                target_component: self.target_component,
                confirmation,
            }),
            CommandBody::Int {
                params: p,
                frame,
                x,
                y,
                z,
            } => Msg::COMMAND_INT(COMMAND_INT_DATA {
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                x: *x,
                y: *y,
                z: *z,
                command: spec.command,
                target_system: self.target_system,
                target_component: self.target_component,
                frame: *frame,
                current: 0,
                autocontinue: 0,
            }),
        }
    }

    /// Handle a COMMAND_ACK from the autopilot.
    pub fn on_ack(
        &mut self,
        now: Duration,
        ack: &super::dialect::COMMAND_ACK_DATA,
    ) -> (Vec<Msg>, Vec<CommandEvent>) {
        // ACKs addressed to another component (a GCS on the same link) are not ours. Old
        // autopilots leave the target fields zero.
        if (ack.target_system != 0 && ack.target_system != self.our_system)
            || (ack.target_component != 0 && ack.target_component != OUR_COMPONENT_ID)
        {
            return (vec![], vec![]);
        }
        let key = ack.command as u32;
        let Some(p) = self.pending.get_mut(&key) else {
            return (vec![], vec![]);
        };
        match ack.result {
            MavResult::MAV_RESULT_ACCEPTED => (vec![], vec![self.finish(key, now, Outcome::Acked)]),
            MavResult::MAV_RESULT_IN_PROGRESS => {
                p.wait = Wait::InProgress {
                    deadline: now + self.cfg.in_progress_timeout,
                };
                (
                    vec![],
                    vec![CommandEvent::Progress {
                        ticket: p.ticket,
                        command: ack.command,
                        percent: ack.progress,
                    }],
                )
            }
            MavResult::MAV_RESULT_TEMPORARILY_REJECTED => {
                if p.spec.no_blind_retry || p.attempts >= self.cfg.max_attempts {
                    (
                        vec![],
                        vec![self.finish(
                            key,
                            now,
                            Outcome::Failed(FailReason::TemporarilyRejected),
                        )],
                    )
                } else {
                    p.wait = Wait::RetryAt(now + self.cfg.retry_later);
                    (vec![], vec![])
                }
            }
            other => (
                vec![],
                vec![self.finish(key, now, Outcome::Failed(FailReason::Result(other)))],
            ),
        }
    }

    fn finish(&mut self, key: u32, now: Duration, outcome: Outcome) -> CommandEvent {
        let p = self
            .pending
            .remove(&key)
            .expect("finish called on a pending command");
        CommandEvent::Finished {
            ticket: p.ticket,
            command: p.spec.command,
            outcome,
            attempts: p.attempts,
            first_sent: p.first_sent,
            finished: now,
        }
    }

    /// Advance time: resend on timeout, retry after a temporary rejection, give up.
    pub fn tick(&mut self, now: Duration) -> (Vec<Msg>, Vec<CommandEvent>) {
        let mut out = Vec::new();
        let mut events = Vec::new();
        let keys: Vec<u32> = self.pending.keys().copied().collect();
        for key in keys {
            let p = &self.pending[&key];
            let (due, timed_out) = match p.wait {
                Wait::Ack { deadline } => (now >= deadline, true),
                Wait::InProgress { deadline } => (now >= deadline, false),
                Wait::RetryAt(t) => (now >= t, false),
            };
            if !due {
                continue;
            }
            let in_progress = matches!(p.wait, Wait::InProgress { .. });
            if in_progress || p.spec.no_blind_retry || p.attempts >= self.cfg.max_attempts {
                let reason = if timed_out || in_progress {
                    FailReason::Timeout
                } else {
                    FailReason::TemporarilyRejected
                };
                events.push(self.finish(key, now, Outcome::Failed(reason)));
                continue;
            }
            let p = self.pending.get_mut(&key).expect("key from pending");
            p.attempts += 1;
            p.wait = Wait::Ack {
                deadline: now + self.cfg.ack_timeout,
            };
            let confirmation = (p.attempts - 1).min(255) as u8;
            let spec = p.spec.clone();
            out.push(self.encode(&spec, confirmation));
        }
        (out, events)
    }

    /// `command`, if in flight, is sent no more: its current attempt is its last (a timeout or
    /// a temporary rejection ends it).
    pub fn no_resend(&mut self, command: MavCmd) {
        if let Some(p) = self.pending.get_mut(&(command as u32)) {
            p.spec.no_blind_retry = true;
        }
    }

    /// Drop the commands whose ticket `pred` selects: each ends Failed(Cancelled); nothing of
    /// them is resent later.
    pub fn cancel_tickets(
        &mut self,
        now: Duration,
        why: &str,
        pred: impl Fn(u64) -> bool,
    ) -> Vec<CommandEvent> {
        let keys: Vec<u32> = self
            .pending
            .iter()
            .filter(|(_, p)| pred(p.ticket))
            .map(|(k, _)| *k)
            .collect();
        keys.into_iter()
            .map(|k| {
                self.finish(
                    k,
                    now,
                    Outcome::Failed(FailReason::Cancelled(why.to_string())),
                )
            })
            .collect()
    }

    /// Drop everything in flight (link lost): each ends Failed(Cancelled); nothing is resent later.
    pub fn cancel_all(&mut self, now: Duration, why: &str) -> Vec<CommandEvent> {
        let keys: Vec<u32> = self.pending.keys().copied().collect();
        keys.into_iter()
            .map(|k| {
                self.finish(
                    k,
                    now,
                    Outcome::Failed(FailReason::Cancelled(why.to_string())),
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::COMMAND_ACK_DATA;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn ack(command: MavCmd, result: MavResult) -> COMMAND_ACK_DATA {
        COMMAND_ACK_DATA {
            command,
            result,
            ..COMMAND_ACK_DATA::DEFAULT
        }
    }

    fn confirmation(m: &Msg) -> u8 {
        match m {
            Msg::COMMAND_LONG(c) => c.confirmation,
            other => panic!("expected COMMAND_LONG, got {other:?}"),
        }
    }

    fn takeoff() -> CommandSpec {
        CommandSpec::long(MavCmd::MAV_CMD_NAV_TAKEOFF, [0., 0., 0., 0., 0., 0., 10.])
    }

    fn client() -> CommandClient {
        let mut c = CommandClient::new(CommandConfig::default());
        c.set_target(1, 1);
        c
    }

    #[test]
    fn timeout_resends_with_confirmation_incremented_then_fails() {
        let mut c = client();
        let (t, out) = c.submit(ms(0), takeoff()).unwrap();
        assert_eq!(confirmation(&out[0]), 0);
        assert!(
            c.tick(ms(1499)).0.is_empty(),
            "no resend before the timeout"
        );
        let (out, ev) = c.tick(ms(1500));
        assert_eq!((out.len(), confirmation(&out[0]), ev.len()), (1, 1, 0));
        let (out, _) = c.tick(ms(3000));
        assert_eq!(confirmation(&out[0]), 2);
        let (out, ev) = c.tick(ms(4500));
        assert!(out.is_empty());
        assert_eq!(
            ev,
            vec![CommandEvent::Finished {
                ticket: t,
                command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                outcome: Outcome::Failed(FailReason::Timeout),
                attempts: 3,
                first_sent: ms(0),
                finished: ms(4500)
            }]
        );
        assert_eq!(c.pending_count(), 0);
    }

    #[test]
    fn accepted_after_a_resend_counts_two_attempts() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        c.tick(ms(1500));
        let (_, ev) = c.on_ack(
            ms(1600),
            &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Acked,
                attempts: 2,
                ..
            }
        ));
        assert!(c.tick(ms(10_000)).0.is_empty());
    }

    #[test]
    fn one_in_flight_per_command_id() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        assert_eq!(
            c.submit(ms(1), takeoff()),
            Err(Busy(MavCmd::MAV_CMD_NAV_TAKEOFF))
        );
        // A different command id may run concurrently.
        assert!(
            c.submit(
                ms(1),
                CommandSpec::long(MavCmd::MAV_CMD_DO_SET_MODE, [1., 4., 0., 0., 0., 0., 0.])
            )
            .is_ok()
        );
    }

    #[test]
    fn denied_and_failed_are_final_and_never_resent() {
        for result in [
            MavResult::MAV_RESULT_DENIED,
            MavResult::MAV_RESULT_FAILED,
            MavResult::MAV_RESULT_UNSUPPORTED,
        ] {
            let mut c = client();
            c.submit(ms(0), takeoff()).unwrap();
            let (out, ev) = c.on_ack(ms(100), &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, result));
            assert!(out.is_empty());
            assert!(
                matches!(&ev[0], CommandEvent::Finished { outcome: Outcome::Failed(FailReason::Result(r)), attempts: 1, .. } if *r == result)
            );
            assert!(c.tick(ms(60_000)).0.is_empty(), "{result:?} resent");
        }
    }

    #[test]
    fn temporarily_rejected_is_retried_later_with_next_confirmation() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        let (out, ev) = c.on_ack(
            ms(100),
            &ack(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            ),
        );
        assert!(out.is_empty() && ev.is_empty());
        assert!(c.tick(ms(1099)).0.is_empty());
        let (out, _) = c.tick(ms(1100));
        assert_eq!(confirmation(&out[0]), 1);
        c.on_ack(
            ms(1200),
            &ack(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            ),
        );
        c.tick(ms(2200));
        let (_, ev) = c.on_ack(
            ms(2300),
            &ack(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            ),
        );
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Failed(FailReason::TemporarilyRejected),
                attempts: 3,
                ..
            }
        ));
    }

    #[test]
    fn in_progress_extends_the_deadline_without_resending() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        let mut a = ack(
            MavCmd::MAV_CMD_NAV_TAKEOFF,
            MavResult::MAV_RESULT_IN_PROGRESS,
        );
        a.progress = 40;
        let (_, ev) = c.on_ack(ms(1000), &a);
        assert_eq!(
            ev,
            vec![CommandEvent::Progress {
                ticket: 1,
                command: MavCmd::MAV_CMD_NAV_TAKEOFF,
                percent: 40
            }]
        );
        // Past the ACK timeout but within the in-progress window: nothing resent, nothing failed.
        let (out, ev) = c.tick(ms(5000));
        assert!(out.is_empty() && ev.is_empty());
        let (_, ev) = c.on_ack(
            ms(8000),
            &ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_ACCEPTED),
        );
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Acked,
                attempts: 1,
                ..
            }
        ));
    }

    #[test]
    fn in_progress_that_goes_silent_times_out_without_resend() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        c.on_ack(
            ms(1000),
            &ack(
                MavCmd::MAV_CMD_NAV_TAKEOFF,
                MavResult::MAV_RESULT_IN_PROGRESS,
            ),
        );
        let (out, ev) = c.tick(ms(11_000));
        assert!(out.is_empty());
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Failed(FailReason::Timeout),
                attempts: 1,
                ..
            }
        ));
    }

    #[test]
    fn arming_is_never_resent_blindly() {
        let arm = CommandSpec::long(
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.],
        )
        .once();
        let mut c = client();
        c.submit(ms(0), arm.clone()).unwrap();
        let (out, ev) = c.tick(ms(1500));
        assert!(out.is_empty(), "arm resent after a lost ACK");
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Failed(FailReason::Timeout),
                attempts: 1,
                ..
            }
        ));
        c.submit(ms(2000), arm).unwrap();
        let (out, ev) = c.on_ack(
            ms(2100),
            &ack(
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                MavResult::MAV_RESULT_TEMPORARILY_REJECTED,
            ),
        );
        assert!(out.is_empty());
        assert!(matches!(
            &ev[0],
            CommandEvent::Finished {
                outcome: Outcome::Failed(FailReason::TemporarilyRejected),
                ..
            }
        ));
        assert!(c.tick(ms(60_000)).0.is_empty());
    }

    #[test]
    fn acks_for_other_components_or_commands_are_ignored() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        let mut other = ack(MavCmd::MAV_CMD_NAV_TAKEOFF, MavResult::MAV_RESULT_DENIED);
        other.target_system = 1;
        other.target_component = 190; // a GCS's command
        assert!(c.on_ack(ms(10), &other).1.is_empty());
        assert!(
            c.on_ack(
                ms(10),
                &ack(MavCmd::MAV_CMD_NAV_LAND, MavResult::MAV_RESULT_ACCEPTED)
            )
            .1
            .is_empty()
        );
        assert!(c.in_flight(MavCmd::MAV_CMD_NAV_TAKEOFF));
    }

    #[test]
    fn cancel_all_ends_everything_and_nothing_is_replayed() {
        let mut c = client();
        c.submit(ms(0), takeoff()).unwrap();
        c.submit(
            ms(0),
            CommandSpec::long(MavCmd::MAV_CMD_DO_SET_MODE, [1., 4., 0., 0., 0., 0., 0.]),
        )
        .unwrap();
        let ev = c.cancel_all(ms(500), "link lost");
        assert_eq!(ev.len(), 2);
        assert!(ev.iter().all(|e| matches!(
            e,
            CommandEvent::Finished {
                outcome: Outcome::Failed(FailReason::Cancelled(_)),
                ..
            }
        )));
        assert!(c.tick(ms(100_000)).0.is_empty());
    }

    #[test]
    fn command_int_carries_position_and_target() {
        let mut c = client();
        c.set_target(7, 1);
        let spec = CommandSpec::int(
            MavCmd::MAV_CMD_DO_REPOSITION,
            MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
            [-1., 1., 0., f32::NAN],
            473_977_420,
            85_455_940,
            12.0,
        );
        let (_, out) = c.submit(ms(0), spec).unwrap();
        match &out[0] {
            Msg::COMMAND_INT(ci) => {
                assert_eq!(
                    (ci.target_system, ci.target_component, ci.x, ci.y, ci.z),
                    (7, 1, 473_977_420, 85_455_940, 12.0)
                );
                assert_eq!(ci.frame, MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn outcome_labels() {
        assert_eq!(Outcome::Acked.label(), "ACCEPTED");
        assert_eq!(
            Outcome::Failed(FailReason::Result(MavResult::MAV_RESULT_DENIED)).label(),
            "DENIED"
        );
        assert_eq!(Outcome::Failed(FailReason::Timeout).label(), "TIMEOUT");
    }
}
