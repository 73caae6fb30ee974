//! A job of the command executor: the steps of the entries asked for, what runs now, and what
//! the job was started for (the key a repeated request is matched against).

use super::*;
use crate::actions::Flown;

#[derive(Debug, Clone, PartialEq)]
pub(in crate::vehicle) enum Running {
    /// Nothing issued for the current step yet.
    Idle,
    Command(u64),
    Mission,
    WaitReady {
        since: Duration,
    },
    /// The zone reposition was accepted: flying there (lat, lon in degrees * 1e7).
    Arrive {
        target: (i32, i32),
        since: Duration,
    },
    /// PX4 accepted SET_MODE at `since`: waiting for a HEARTBEAT that shows the mode.
    ConfirmMode {
        since: Duration,
    },
}

#[derive(Debug, Clone)]
pub(in crate::vehicle) struct Job {
    /// What was asked for; the same request again leaves the job alone.
    pub(in crate::vehicle) key: JobKey,
    pub(in crate::vehicle) steps: VecDeque<(String, Step)>,
    pub(in crate::vehicle) running: Running,
    pub(in crate::vehicle) arm_attempts: u32,
    /// SET_MODE sent for the current mode step (PX4 confirmation resends).
    pub(in crate::vehicle) mode_attempts: u32,
    /// The custom mode reported when the current step's SET_MODE was first issued.
    pub(in crate::vehicle) mode_from: Option<u32>,
}

/// What a job was started for.
#[derive(Debug, Clone, PartialEq)]
pub(in crate::vehicle) enum JobKey {
    /// The decision's request (one entry, or several flown one after the other).
    Request(Vec<Flown>),
    /// The hand-off when the companion stops: this mode.
    Handoff(FlightMode),
}

impl JobKey {
    /// Whether the job was started for exactly `request`.
    pub(in crate::vehicle) fn is(&self, request: &[Flown]) -> bool {
        matches!(self, JobKey::Request(k) if k == request)
    }
}

#[derive(Debug, Clone, PartialEq)]
pub(in crate::vehicle) enum JobStatus {
    Running,
    Done,
    Failed(Duration),
}
