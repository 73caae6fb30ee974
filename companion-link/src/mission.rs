//! The MAVLink mission protocol (upload, download, clear, set current), sans IO.
//!
//! ArduPilot specifics (libraries/GCS_MAVLink/MissionItemProtocol*.cpp):
//! - seq 0 is home. An upload must still send an item 0 (we send a placeholder at home); on
//!   download ArduPilot returns its current home there, so verification skips seq 0.
//! - ArduPilot requests items with the legacy MISSION_REQUEST as well as MISSION_REQUEST_INT and
//!   re-requests after about 1 s; we answer both with MISSION_ITEM_INT.
//! - MISSION_ACK with INVALID_SEQUENCE means "that item was ignored": the upload goes on; any
//!   other non-ACCEPTED result ends it.
//! - On download, items come back in non-INT frames (GLOBAL_RELATIVE_ALT rather than
//!   GLOBAL_RELATIVE_ALT_INT) and altitudes rounded to centimetres, so the comparison normalises
//!   frames and allows 2 cm.
//!
//! PX4 (src/modules/mavlink/mavlink_mission.cpp): no home item; seq 0 is the first item flown,
//! and every item comes back on download as it was sent, so verification compares seq 0 too
//! (`MissionClient::home_at_seq0`). It asks with MISSION_REQUEST_INT and acknowledges the last
//! item with MISSION_ACK ACCEPTED like ArduPilot.
//!
//! Every upload here is verified by downloading it back and comparing item by item.

// MISSION_REQUEST, MISSION_ITEM, MISSION_SET_CURRENT and the `_INT` frames are deprecated in
// MAVLink but still sent by ArduPilot: handling them is the point.
#![allow(deprecated)]

use super::Msg;
use super::dialect::*;
use companion_core::record::CommandOutcome;
use std::time::Duration;

/// One mission item as we store and compare it.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionItem {
    /// MAV_CMD of the item (`MAV_CMD_NAV_WAYPOINT`, ...).
    pub command: MavCmd,
    /// Coordinate frame of `x`, `y`, `z`.
    pub frame: MavFrame,
    /// param1..param4 as the command defines them.
    pub params: [f32; 4],
    /// Latitude / longitude in degrees * 1e7.
    pub x: i32,
    /// Longitude in degrees * 1e7 (`x` is the latitude).
    pub y: i32,
    /// Altitude in metres (meaning depends on the frame).
    pub z: f32,
}

impl MissionItem {
    /// A NAV_WAYPOINT at `lat_e7`/`lon_e7` (degrees * 1e7), `alt_rel_m` metres above home.
    pub fn waypoint(lat_e7: i32, lon_e7: i32, alt_rel_m: f32) -> Self {
        Self {
            command: MavCmd::MAV_CMD_NAV_WAYPOINT,
            frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
            params: [0.0; 4],
            x: lat_e7,
            y: lon_e7,
            z: alt_rel_m,
        }
    }

    /// The item at `seq` as the route planner reads an autopilot's mission: MAV_CMD and
    /// MAV_FRAME numbers, params, latitude and longitude in degrees.
    pub fn planned(&self, seq: usize) -> companion_core::route_plan::AutopilotItem {
        let p = |v: f32| f64::from(v);
        companion_core::route_plan::AutopilotItem {
            seq,
            command: self.command as u64,
            frame: self.frame as u64,
            params: [
                p(self.params[0]),
                p(self.params[1]),
                p(self.params[2]),
                p(self.params[3]),
                f64::from(self.x) / 1e7,
                f64::from(self.y) / 1e7,
                p(self.z),
            ],
        }
    }

    fn to_msg(&self, seq: u16, target: (u8, u8)) -> Msg {
        Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
            param1: self.params[0],
            param2: self.params[1],
            param3: self.params[2],
            param4: self.params[3],
            x: self.x,
            y: self.y,
            z: self.z,
            seq,
            command: self.command,
            target_system: target.0,
            target_component: target.1,
            frame: self.frame,
            current: 0,
            autocontinue: 1,
            ..MISSION_ITEM_INT_DATA::DEFAULT
        })
    }

    fn from_int(m: &MISSION_ITEM_INT_DATA) -> Self {
        Self {
            command: m.command,
            frame: m.frame,
            params: [m.param1, m.param2, m.param3, m.param4],
            x: m.x,
            y: m.y,
            z: m.z,
        }
    }

    fn from_float(m: &MISSION_ITEM_DATA) -> Self {
        Self {
            command: m.command,
            frame: m.frame,
            params: [m.param1, m.param2, m.param3, m.param4],
            x: (m.x as f64 * 1e7).round() as i32,
            y: (m.y as f64 * 1e7).round() as i32,
            z: m.z,
        }
    }
}

/// The frame without its `_INT` spelling: autopilots answer in either.
fn normalise_frame(f: MavFrame) -> MavFrame {
    match f {
        MavFrame::MAV_FRAME_GLOBAL_INT => MavFrame::MAV_FRAME_GLOBAL,
        MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT_INT => MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
        MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT_INT => MavFrame::MAV_FRAME_GLOBAL_TERRAIN_ALT,
        other => other,
    }
}

/// An item whose command flies to no position of its own: ArduPilot stores none for it and
/// answers it in MAV_FRAME_GLOBAL at 0/0/0 whatever was sent (seen on ArduCopter 4.7 SITL: an
/// RTL, and a DO_CHANGE_SPEED sent in MAV_FRAME_MISSION), so only the command (and a speed
/// change's speed, param2) is compared.
fn positionless(command: MavCmd) -> bool {
    matches!(
        command,
        MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH | MavCmd::MAV_CMD_DO_CHANGE_SPEED
    )
}

/// First difference between what we uploaded and what came back, seq 0 (home) excluded.
pub fn compare(sent: &[MissionItem], got: &[MissionItem]) -> Result<(), String> {
    compare_from(sent, got, 1)
}

/// First difference from seq `first` on (0 for PX4, which keeps no home item at seq 0).
pub fn compare_from(sent: &[MissionItem], got: &[MissionItem], first: usize) -> Result<(), String> {
    if sent.len() != got.len() {
        return Err(format!(
            "count: sent {} items, autopilot has {}",
            sent.len(),
            got.len()
        ));
    }
    for (seq, (a, b)) in sent.iter().zip(got).enumerate().skip(first) {
        if a.command != b.command {
            return Err(format!(
                "item {seq}: command {} came back as {}",
                crate::mavlink_name(&a.command),
                crate::mavlink_name(&b.command)
            ));
        }
        if positionless(a.command) {
            let speed = |i: &MissionItem| i.params[1];
            if a.command == MavCmd::MAV_CMD_DO_CHANGE_SPEED && (speed(a) - speed(b)).abs() > 0.01 {
                return Err(format!(
                    "item {seq}: speed {} came back as {}",
                    speed(a),
                    speed(b)
                ));
            }
            continue;
        }
        if normalise_frame(a.frame) != normalise_frame(b.frame) {
            return Err(format!(
                "item {seq}: frame {} came back as {}",
                crate::mavlink_name(&a.frame),
                crate::mavlink_name(&b.frame)
            ));
        }
        if (a.x - b.x).abs() > 1 || (a.y - b.y).abs() > 1 {
            return Err(format!(
                "item {seq}: position ({}, {}) came back as ({}, {})",
                a.x, a.y, b.x, b.y
            ));
        }
        if (a.z - b.z).abs() > 0.02 || a.z.is_nan() != b.z.is_nan() {
            return Err(format!("item {seq}: altitude {} came back as {}", a.z, b.z));
        }
    }
    Ok(())
}

/// Mission protocol timing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MissionConfig {
    /// Silence from the autopilot during a transfer before we re-send our last message.
    pub item_timeout: Duration,
    /// Sends of one message (COUNT, one REQUEST, CLEAR_ALL, SET_CURRENT) before giving up.
    pub max_attempts: u32,
}

impl Default for MissionConfig {
    fn default() -> Self {
        // MAVLink mission protocol suggests 1.5 s for items; ArduPilot re-requests after 1 s.
        Self {
            item_timeout: Duration::from_millis(1500),
            max_attempts: 5,
        }
    }
}

/// A mission operation, as its outcome names it.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionOp {
    /// Upload, then download and compare.
    UploadVerified,
    /// Download the autopilot's mission.
    Download,
    /// Clear the autopilot's mission.
    Clear,
    /// Make this sequence number the current item.
    SetCurrent(u16),
}

impl MissionOp {
    /// The `CommandRecord.command` of the operation: the MAVLink step it starts with, as the
    /// record of a verified upload names it.
    pub fn command_name(&self) -> String {
        match self {
            MissionOp::UploadVerified => "MISSION_UPLOAD".into(),
            MissionOp::Download => "MISSION_REQUEST_LIST".into(),
            MissionOp::Clear => "MISSION_CLEAR_ALL".into(),
            MissionOp::SetCurrent(seq) => format!("MISSION_SET_CURRENT {seq}"),
        }
    }
}

/// Why a mission operation failed or was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionError {
    /// The autopilot answered MISSION_ACK with this result.
    Ack(MavMissionResult),
    /// No answer after every allowed attempt; names the step.
    Timeout(String),
    /// The download after an upload differs: the first difference.
    VerifyMismatch(String),
    /// Another operation is running.
    Busy,
    /// Dropped (link lost).
    Cancelled(String),
}

impl MissionError {
    /// The `CommandRecord.result` of an operation that failed this way: a cancel is
    /// `CANCELLED (why)` (a stop, not a failure), no answer `TIMEOUT (step)`, the rest
    /// `FAILED (why)`.
    pub fn outcome(&self) -> CommandOutcome {
        match self {
            MissionError::Ack(result) => {
                CommandOutcome::Failed(Some(format!("MISSION_ACK {}", crate::mavlink_name(result))))
            }
            MissionError::Timeout(step) => {
                CommandOutcome::Timeout(Some(format!("no answer to {step}")))
            }
            MissionError::VerifyMismatch(first) => {
                CommandOutcome::Failed(Some(format!("read back differs: {first}")))
            }
            MissionError::Busy => {
                CommandOutcome::Failed(Some("another mission operation is running".into()))
            }
            MissionError::Cancelled(why) => CommandOutcome::Cancelled(Some(why.clone())),
        }
    }
}

/// Progress and outcome of a mission operation.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionEvent {
    /// Upload acknowledged by the autopilot; verification download starts.
    Uploaded {
        /// Items sent.
        count: u16,
    },
    /// The operation succeeded.
    Done {
        /// Which operation.
        op: MissionOp,
        /// Items downloaded (the verified read-back for an upload; empty for clear and
        /// set-current).
        items: Vec<MissionItem>,
    },
    /// The operation failed; the client is idle again.
    Failed {
        /// Which operation.
        op: MissionOp,
        /// Why.
        error: MissionError,
    },
}

#[derive(Debug, Clone, PartialEq)]
enum State {
    Idle,
    Uploading {
        items: Vec<MissionItem>,
        last_sent: Option<u16>,
    },
    Downloading {
        verify: Option<Vec<MissionItem>>,
        count: Option<u16>,
        got: Vec<MissionItem>,
    },
    Clearing,
    SettingCurrent(u16),
}

/// Mission client for one autopilot: one operation at a time.
#[derive(Debug, Clone)]
pub struct MissionClient {
    /// Protocol timing.
    pub cfg: MissionConfig,
    target: (u8, u8),
    state: State,
    deadline: Duration,
    attempts: u32,
    /// Last message sent, re-sent on timeout.
    last: Option<Msg>,
    /// Count of MISSION_ACK INVALID_SEQUENCE and stray messages, for the log.
    pub ignored: u32,
    /// ArduPilot answers its own home at seq 0, so verification skips it; PX4 stores seq 0
    /// like any other item, so it is compared too.
    pub home_at_seq0: bool,
}

impl MissionClient {
    /// An idle client targeting system 1 component 1, expecting ArduPilot's home at seq 0.
    pub fn new(cfg: MissionConfig) -> Self {
        Self {
            cfg,
            target: (1, 1),
            state: State::Idle,
            deadline: Duration::ZERO,
            attempts: 0,
            last: None,
            ignored: 0,
            home_at_seq0: true,
        }
    }

    /// Address the autopilot `system`/`component` from now on.
    pub fn set_target(&mut self, system: u8, component: u8) {
        self.target = (system, component);
    }

    /// Whether an operation is running.
    pub fn busy(&self) -> bool {
        self.state != State::Idle
    }

    fn send(&mut self, now: Duration, msg: Msg) -> Vec<Msg> {
        self.deadline = now + self.cfg.item_timeout;
        self.attempts = 1;
        self.last = Some(msg.clone());
        vec![msg]
    }

    fn op(&self) -> MissionOp {
        match &self.state {
            State::Uploading { .. } => MissionOp::UploadVerified,
            State::Downloading {
                verify: Some(_), ..
            } => MissionOp::UploadVerified,
            State::Downloading { .. } => MissionOp::Download,
            State::Clearing => MissionOp::Clear,
            State::SettingCurrent(s) => MissionOp::SetCurrent(*s),
            State::Idle => MissionOp::Download,
        }
    }

    fn fail(&mut self, error: MissionError) -> MissionEvent {
        let op = self.op();
        self.state = State::Idle;
        self.last = None;
        MissionEvent::Failed { op, error }
    }

    /// Upload `items` (item 0 is home / placeholder), then download and compare.
    pub fn upload(
        &mut self,
        now: Duration,
        items: Vec<MissionItem>,
    ) -> Result<Vec<Msg>, MissionError> {
        if self.busy() {
            return Err(MissionError::Busy);
        }
        let count = items.len() as u16;
        self.state = State::Uploading {
            items,
            last_sent: None,
        };
        let msg = Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count,
            target_system: self.target.0,
            target_component: self.target.1,
            ..MISSION_COUNT_DATA::DEFAULT
        });
        Ok(self.send(now, msg))
    }

    /// Start downloading the autopilot's mission; refused while another operation runs.
    pub fn download(&mut self, now: Duration) -> Result<Vec<Msg>, MissionError> {
        if self.busy() {
            return Err(MissionError::Busy);
        }
        Ok(self.start_download(now, None))
    }

    fn start_download(&mut self, now: Duration, verify: Option<Vec<MissionItem>>) -> Vec<Msg> {
        self.state = State::Downloading {
            verify,
            count: None,
            got: Vec::new(),
        };
        let msg = Msg::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
            target_system: self.target.0,
            target_component: self.target.1,
            ..MISSION_REQUEST_LIST_DATA::DEFAULT
        });
        self.send(now, msg)
    }

    /// Start clearing the autopilot's mission; refused while another operation runs.
    pub fn clear(&mut self, now: Duration) -> Result<Vec<Msg>, MissionError> {
        if self.busy() {
            return Err(MissionError::Busy);
        }
        self.state = State::Clearing;
        let msg = Msg::MISSION_CLEAR_ALL(MISSION_CLEAR_ALL_DATA {
            target_system: self.target.0,
            target_component: self.target.1,
            ..MISSION_CLEAR_ALL_DATA::DEFAULT
        });
        Ok(self.send(now, msg))
    }

    /// MISSION_SET_CURRENT, confirmed by a MISSION_CURRENT naming `seq`.
    pub fn set_current(&mut self, now: Duration, seq: u16) -> Result<Vec<Msg>, MissionError> {
        if self.busy() {
            return Err(MissionError::Busy);
        }
        self.state = State::SettingCurrent(seq);
        let msg = Msg::MISSION_SET_CURRENT(MISSION_SET_CURRENT_DATA {
            seq,
            target_system: self.target.0,
            target_component: self.target.1,
        });
        Ok(self.send(now, msg))
    }

    /// Handle a message from the autopilot. Returns messages to send and events.
    pub fn on_message(&mut self, now: Duration, msg: &Msg) -> (Vec<Msg>, Vec<MissionEvent>) {
        let target = self.target;
        match (&mut self.state, msg) {
            (
                State::Uploading { items, last_sent },
                Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA { seq, .. }),
            )
            | (
                State::Uploading { items, last_sent },
                Msg::MISSION_REQUEST(MISSION_REQUEST_DATA { seq, .. }),
            ) => {
                let Some(item) = items.get(*seq as usize) else {
                    self.ignored += 1;
                    return (vec![], vec![]);
                };
                // A re-request of the same item is the autopilot's retry, not progress.
                let m = item.to_msg(*seq, target);
                let progressed = *last_sent != Some(*seq);
                *last_sent = Some(*seq);
                self.deadline = now + self.cfg.item_timeout;
                if progressed {
                    self.attempts = 1;
                }
                self.last = Some(m.clone());
                (vec![m], vec![])
            }
            (State::Uploading { items, .. }, Msg::MISSION_ACK(a)) => match a.mavtype {
                MavMissionResult::MAV_MISSION_ACCEPTED => {
                    let items = std::mem::take(items);
                    let count = items.len() as u16;
                    let out = self.start_download(now, Some(items));
                    (out, vec![MissionEvent::Uploaded { count }])
                }
                MavMissionResult::MAV_MISSION_INVALID_SEQUENCE => {
                    self.ignored += 1;
                    (vec![], vec![])
                }
                other => (vec![], vec![self.fail(MissionError::Ack(other))]),
            },
            (State::Downloading { count, got, .. }, Msg::MISSION_COUNT(c)) if count.is_none() => {
                *count = Some(c.count);
                got.clear();
                if c.count == 0 {
                    return self.download_complete(now);
                }
                let m = self.request(0);
                (self.send(now, m), vec![])
            }
            (
                State::Downloading {
                    count: Some(n),
                    got,
                    ..
                },
                Msg::MISSION_ITEM_INT(_) | Msg::MISSION_ITEM(_),
            ) => {
                let (seq, item) = match msg {
                    Msg::MISSION_ITEM_INT(m) => (m.seq, MissionItem::from_int(m)),
                    Msg::MISSION_ITEM(m) => (m.seq, MissionItem::from_float(m)),
                    _ => unreachable!("matched above"),
                };
                if seq as usize != got.len() {
                    self.ignored += 1;
                    return (vec![], vec![]);
                }
                got.push(item);
                if got.len() == *n as usize {
                    return self.download_complete(now);
                }
                let next = got.len() as u16;
                let m = self.request(next);
                (self.send(now, m), vec![])
            }
            (State::Downloading { .. }, Msg::MISSION_ACK(a))
                if a.mavtype != MavMissionResult::MAV_MISSION_ACCEPTED =>
            {
                (vec![], vec![self.fail(MissionError::Ack(a.mavtype))])
            }
            (State::Clearing, Msg::MISSION_ACK(a)) => {
                if a.mavtype == MavMissionResult::MAV_MISSION_ACCEPTED {
                    self.state = State::Idle;
                    (
                        vec![],
                        vec![MissionEvent::Done {
                            op: MissionOp::Clear,
                            items: vec![],
                        }],
                    )
                } else {
                    (vec![], vec![self.fail(MissionError::Ack(a.mavtype))])
                }
            }
            (State::SettingCurrent(want), Msg::MISSION_CURRENT(c)) if c.seq == *want => {
                let op = MissionOp::SetCurrent(*want);
                self.state = State::Idle;
                (vec![], vec![MissionEvent::Done { op, items: vec![] }])
            }
            _ => (vec![], vec![]),
        }
    }

    fn request(&self, seq: u16) -> Msg {
        Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
            seq,
            target_system: self.target.0,
            target_component: self.target.1,
            ..MISSION_REQUEST_INT_DATA::DEFAULT
        })
    }

    fn download_complete(&mut self, _now: Duration) -> (Vec<Msg>, Vec<MissionEvent>) {
        let State::Downloading { verify, got, .. } =
            std::mem::replace(&mut self.state, State::Idle)
        else {
            unreachable!("download_complete outside a download")
        };
        self.last = None;
        let ack = Msg::MISSION_ACK(MISSION_ACK_DATA {
            target_system: self.target.0,
            target_component: self.target.1,
            mavtype: MavMissionResult::MAV_MISSION_ACCEPTED,
            ..MISSION_ACK_DATA::DEFAULT
        });
        let event = match verify {
            None => MissionEvent::Done {
                op: MissionOp::Download,
                items: got,
            },
            Some(sent) => match compare_from(&sent, &got, usize::from(self.home_at_seq0)) {
                Ok(()) => MissionEvent::Done {
                    op: MissionOp::UploadVerified,
                    items: got,
                },
                Err(diff) => MissionEvent::Failed {
                    op: MissionOp::UploadVerified,
                    error: MissionError::VerifyMismatch(diff),
                },
            },
        };
        (vec![ack], vec![event])
    }

    /// Advance time: re-send the last message after `item_timeout`, give up after `max_attempts`.
    pub fn tick(&mut self, now: Duration) -> (Vec<Msg>, Vec<MissionEvent>) {
        if self.state == State::Idle || now < self.deadline {
            return (vec![], vec![]);
        }
        if self.attempts >= self.cfg.max_attempts {
            let step = self
                .last
                .as_ref()
                .map(|m| mavlink::Message::message_name(m).to_string())
                .unwrap_or_default();
            return (vec![], vec![self.fail(MissionError::Timeout(step))]);
        }
        self.attempts += 1;
        self.deadline = now + self.cfg.item_timeout;
        (self.last.clone().into_iter().collect(), vec![])
    }

    /// End the running operation as cancelled (`why`); `None` when idle.
    pub fn cancel(&mut self, why: &str) -> Option<MissionEvent> {
        if self.busy() {
            Some(self.fail(MissionError::Cancelled(why.to_string())))
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mission_error_is_recorded_as_its_outcome_not_its_debug_text() {
        let said = |e: MissionError| e.outcome().to_string();
        assert_eq!(
            said(MissionError::Cancelled("link lost".into())),
            "CANCELLED (link lost)"
        );
        assert_eq!(
            said(MissionError::Ack(MavMissionResult::MAV_MISSION_DENIED)),
            "FAILED (MISSION_ACK MAV_MISSION_DENIED)"
        );
        assert_eq!(
            said(MissionError::Timeout("MISSION_ITEM_INT".into())),
            "TIMEOUT (no answer to MISSION_ITEM_INT)"
        );
        assert_eq!(MissionOp::UploadVerified.command_name(), "MISSION_UPLOAD");
    }

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn items() -> Vec<MissionItem> {
        vec![
            MissionItem::waypoint(473_977_420, 85_455_940, 0.0), // home placeholder
            MissionItem::waypoint(473_978_320, 85_455_940, 20.0),
            MissionItem::waypoint(473_978_320, 85_457_270, 20.0),
        ]
    }

    fn req(seq: u16) -> Msg {
        Msg::MISSION_REQUEST(MISSION_REQUEST_DATA {
            seq,
            target_system: 1,
            target_component: 191,
            ..MISSION_REQUEST_DATA::DEFAULT
        })
    }
    fn req_int(seq: u16) -> Msg {
        Msg::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
            seq,
            target_system: 1,
            target_component: 191,
            ..MISSION_REQUEST_INT_DATA::DEFAULT
        })
    }
    fn ack(r: MavMissionResult) -> Msg {
        Msg::MISSION_ACK(MISSION_ACK_DATA {
            target_system: 1,
            target_component: 191,
            mavtype: r,
            ..MISSION_ACK_DATA::DEFAULT
        })
    }
    fn count(n: u16) -> Msg {
        Msg::MISSION_COUNT(MISSION_COUNT_DATA {
            count: n,
            target_system: 1,
            target_component: 191,
            ..MISSION_COUNT_DATA::DEFAULT
        })
    }
    /// What ArduPilot sends back: non-INT frame, its own home at seq 0.
    fn stored(seq: u16, it: &MissionItem) -> Msg {
        let home = seq == 0;
        Msg::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
            seq,
            command: it.command,
            frame: if home {
                MavFrame::MAV_FRAME_GLOBAL
            } else {
                MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT
            },
            x: if home { 473_970_000 } else { it.x },
            y: it.y,
            z: if home { 584.0 } else { it.z },
            ..MISSION_ITEM_INT_DATA::DEFAULT
        })
    }

    fn seq_of(m: &Msg) -> u16 {
        match m {
            Msg::MISSION_ITEM_INT(i) => i.seq,
            Msg::MISSION_REQUEST_INT(r) => r.seq,
            other => panic!("{other:?}"),
        }
    }

    /// Drive a full upload + verify against a scripted autopilot that stores `stored_items`.
    fn upload_and_verify(c: &mut MissionClient, stored_items: &[MissionItem]) -> Vec<MissionEvent> {
        let mut events = Vec::new();
        let out = c.upload(ms(0), items()).unwrap();
        assert!(matches!(
            out[0],
            Msg::MISSION_COUNT(MISSION_COUNT_DATA { count: 3, .. })
        ));
        for s in 0..3 {
            // ArduPilot's legacy request for odd items, the INT one for even.
            let r = if s % 2 == 1 { req(s) } else { req_int(s) };
            let (out, _) = c.on_message(ms(10 + s as u64), &r);
            assert_eq!(seq_of(&out[0]), s);
        }
        let (out, ev) = c.on_message(ms(20), &ack(MavMissionResult::MAV_MISSION_ACCEPTED));
        events.extend(ev);
        assert!(matches!(out[0], Msg::MISSION_REQUEST_LIST(_)));
        let (out, _) = c.on_message(ms(30), &count(stored_items.len() as u16));
        let mut next = out;
        let mut i = 0u16;
        loop {
            if next.is_empty() {
                break;
            }
            if let Msg::MISSION_ACK(_) = next[0] {
                break;
            }
            assert_eq!(seq_of(&next[0]), i);
            let (out, ev) = c.on_message(ms(40 + i as u64), &stored(i, &stored_items[i as usize]));
            events.extend(ev);
            next = out;
            i += 1;
        }
        events
    }

    #[test]
    fn upload_answers_legacy_and_int_requests_and_verifies() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.set_target(1, 1);
        let ev = upload_and_verify(&mut c, &items());
        assert_eq!(ev[0], MissionEvent::Uploaded { count: 3 });
        assert!(
            matches!(&ev[1], MissionEvent::Done { op: MissionOp::UploadVerified, items } if items.len() == 3),
            "{ev:?}"
        );
        assert!(!c.busy());
    }

    #[test]
    fn verify_detects_a_changed_waypoint() {
        let mut c = MissionClient::new(MissionConfig::default());
        let mut bad = items();
        bad[2].z = 25.0;
        let ev = upload_and_verify(&mut c, &bad);
        match &ev[1] {
            MissionEvent::Failed {
                op: MissionOp::UploadVerified,
                error: MissionError::VerifyMismatch(d),
            } => {
                assert!(d.contains("item 2") && d.contains("altitude"), "{d}")
            }
            other => panic!("{other:?}"),
        }
    }

    /// ArduPilot answers a NAV_RETURN_TO_LAUNCH item in MAV_FRAME_GLOBAL at 0/0/0, whatever was
    /// sent: only its command counts; a changed command still fails.
    #[test]
    fn an_rtl_item_is_compared_by_its_command_only() {
        let rtl = |frame, z| MissionItem {
            command: MavCmd::MAV_CMD_NAV_RETURN_TO_LAUNCH,
            frame,
            ..MissionItem::waypoint(0, 0, z)
        };
        let mut sent = items();
        sent.push(rtl(MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT, 0.0));
        let mut got = sent.clone();
        got[3] = rtl(MavFrame::MAV_FRAME_GLOBAL, 0.0);
        assert_eq!(compare(&sent, &got), Ok(()));
        got[3].command = MavCmd::MAV_CMD_NAV_LAND;
        assert!(compare(&sent, &got).is_err_and(|d| d.contains("item 3")));
    }

    /// ArduPilot answers a DO_CHANGE_SPEED sent in MAV_FRAME_MISSION in MAV_FRAME_GLOBAL (ArduCopter
    /// 4.7 SITL, a QGroundControl `.plan`'s speed change): its command and speed count, a changed
    /// speed fails.
    #[test]
    fn a_speed_change_is_compared_by_its_command_and_speed() {
        let speed = |frame, mps| MissionItem {
            command: MavCmd::MAV_CMD_DO_CHANGE_SPEED,
            frame,
            params: [1.0, mps, -1.0, 0.0],
            ..MissionItem::waypoint(0, 0, 0.0)
        };
        let mut sent = items();
        sent.insert(2, speed(MavFrame::MAV_FRAME_MISSION, 6.0));
        let mut got = sent.clone();
        got[2] = speed(MavFrame::MAV_FRAME_GLOBAL, 6.0);
        assert_eq!(compare(&sent, &got), Ok(()));
        got[2].params[1] = 10.0;
        assert!(compare(&sent, &got).is_err_and(|d| d.contains("item 2") && d.contains("speed")));
    }

    #[test]
    fn verify_detects_a_missing_item() {
        let mut c = MissionClient::new(MissionConfig::default());
        let ev = upload_and_verify(&mut c, &items()[..2]);
        assert!(
            matches!(&ev[1], MissionEvent::Failed { error: MissionError::VerifyMismatch(d), .. } if d.contains("count"))
        );
    }

    #[test]
    fn item_is_resent_on_silence_then_upload_times_out() {
        let mut c = MissionClient::new(MissionConfig {
            item_timeout: ms(1000),
            max_attempts: 3,
        });
        c.upload(ms(0), items()).unwrap();
        c.on_message(ms(100), &req_int(1));
        assert!(c.tick(ms(1099)).0.is_empty());
        let (out, _) = c.tick(ms(1100));
        assert_eq!(seq_of(&out[0]), 1, "the last requested item is resent");
        let (out, _) = c.tick(ms(2100));
        assert_eq!(seq_of(&out[0]), 1);
        let (out, ev) = c.tick(ms(3100));
        assert!(out.is_empty());
        assert_eq!(
            ev,
            vec![MissionEvent::Failed {
                op: MissionOp::UploadVerified,
                error: MissionError::Timeout("MISSION_ITEM_INT".into())
            }]
        );
        assert!(!c.busy());
    }

    #[test]
    fn count_is_resent_when_no_request_comes() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.upload(ms(0), items()).unwrap();
        let (out, _) = c.tick(ms(1500));
        assert!(matches!(out[0], Msg::MISSION_COUNT(_)));
        // Progress resets the per-item budget.
        c.on_message(ms(1600), &req(0));
        c.on_message(ms(1700), &req(1));
        let (out, ev) = c.tick(ms(3200));
        assert_eq!(seq_of(&out[0]), 1);
        assert!(ev.is_empty());
    }

    #[test]
    fn ack_error_ends_the_upload_but_invalid_sequence_does_not() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.upload(ms(0), items()).unwrap();
        c.on_message(ms(10), &req_int(0));
        let (_, ev) = c.on_message(ms(20), &ack(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE));
        assert!(ev.is_empty() && c.busy());
        let (_, ev) = c.on_message(ms(30), &ack(MavMissionResult::MAV_MISSION_NO_SPACE));
        assert_eq!(
            ev,
            vec![MissionEvent::Failed {
                op: MissionOp::UploadVerified,
                error: MissionError::Ack(MavMissionResult::MAV_MISSION_NO_SPACE)
            }]
        );
        assert!(!c.busy());
    }

    #[test]
    fn requests_beyond_the_mission_are_ignored() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.upload(ms(0), items()).unwrap();
        assert!(c.on_message(ms(10), &req_int(9)).0.is_empty());
        assert_eq!(c.ignored, 1);
    }

    #[test]
    fn one_operation_at_a_time() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.upload(ms(0), items()).unwrap();
        assert_eq!(c.download(ms(1)), Err(MissionError::Busy));
        assert_eq!(c.clear(ms(1)), Err(MissionError::Busy));
    }

    #[test]
    fn download_of_empty_mission_and_legacy_items() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.download(ms(0)).unwrap();
        let (out, ev) = c.on_message(ms(1), &count(0));
        assert!(matches!(out[0], Msg::MISSION_ACK(_)));
        assert_eq!(
            ev,
            vec![MissionEvent::Done {
                op: MissionOp::Download,
                items: vec![]
            }]
        );
        c.download(ms(2)).unwrap();
        c.on_message(ms(3), &count(1));
        let legacy = Msg::MISSION_ITEM(MISSION_ITEM_DATA {
            seq: 0,
            x: 47.397742,
            y: 8.545594,
            z: 10.0,
            command: MavCmd::MAV_CMD_NAV_WAYPOINT,
            frame: MavFrame::MAV_FRAME_GLOBAL_RELATIVE_ALT,
            ..MISSION_ITEM_DATA::DEFAULT
        });
        let (_, ev) = c.on_message(ms(4), &legacy);
        match &ev[0] {
            MissionEvent::Done { items, .. } => assert!(
                (items[0].x - 473_977_420).abs() <= 40,
                "f32 degrees: {}",
                items[0].x
            ),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn clear_and_set_current() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.clear(ms(0)).unwrap();
        let (_, ev) = c.on_message(ms(1), &ack(MavMissionResult::MAV_MISSION_ACCEPTED));
        assert_eq!(
            ev,
            vec![MissionEvent::Done {
                op: MissionOp::Clear,
                items: vec![]
            }]
        );
        c.set_current(ms(2), 2).unwrap();
        let cur = |s| {
            Msg::MISSION_CURRENT(MISSION_CURRENT_DATA {
                seq: s,
                ..MISSION_CURRENT_DATA::DEFAULT
            })
        };
        assert!(
            c.on_message(ms(3), &cur(1)).1.is_empty(),
            "the old current item is not a confirmation"
        );
        let (_, ev) = c.on_message(ms(4), &cur(2));
        assert_eq!(
            ev,
            vec![MissionEvent::Done {
                op: MissionOp::SetCurrent(2),
                items: vec![]
            }]
        );
    }

    #[test]
    fn cancel_ends_the_operation() {
        let mut c = MissionClient::new(MissionConfig::default());
        c.upload(ms(0), items()).unwrap();
        assert!(matches!(
            c.cancel("link lost"),
            Some(MissionEvent::Failed {
                error: MissionError::Cancelled(_),
                ..
            })
        ));
        assert!(c.tick(ms(100_000)).0.is_empty());
    }
}
