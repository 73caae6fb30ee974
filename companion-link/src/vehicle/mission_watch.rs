//! The autopilot's own mission (`fly --mission autopilot`): downloaded when the autopilot is
//! chosen, downloaded again whenever it may have changed, and handed to the shell when it did.
//!
//! What each autopilot says when a ground station uploads a mission (checked on the real
//! firmwares of ../shared/sitl):
//! - ArduCopter 4.7: nothing addressed to a companion on another port (the upload's MISSION_ACK
//!   goes to the ground station's channel only). Its MISSION_CURRENT carries no `mission_id`
//!   (5 payload bytes: seq, total, mission_state), only `total`, which a new mission of the same
//!   length leaves as it was. So a changed `total` asks for a download at once, and otherwise the
//!   mission is downloaded again every `poll` and compared item by item.
//! - PX4 (mavlink_mission.cpp): MISSION_CURRENT's `mission_id` (MAVLink 2 extension) is a
//!   checksum of the stored mission, changed by any upload (PX4 SIH: `total` 65535 and
//!   `mission_id` 0 with no mission; after a ground station's upload of 2 items, `total` 2 and a
//!   non-zero `mission_id`). Once an autopilot reports a non-zero id, a changed id asks for a
//!   download and no periodic download is needed.
//!
//! Whatever asked, a change is what the download shows: items that differ from the last
//! download (ArduPilot's home at seq 0, which moves when the vehicle arms, excluded) or from the
//! companion's own verified upload, which is therefore never reported as a change.

use super::executor::Advance;
use super::*;
use crate::mission::{MissionItem, compare_from};

/// The autopilot's mission, as the shell gets it.
#[derive(Debug, Clone, PartialEq)]
pub enum AutopilotMission {
    /// The first download since the autopilot was chosen.
    Loaded(Vec<MissionItem>),
    /// A download differs from the mission known before: someone uploaded a new one.
    Changed(Vec<MissionItem>),
}

/// How often the mission is downloaded again from an autopilot that reports no `mission_id`.
pub const MISSION_POLL: Duration = Duration::from_secs(2);

/// The watch's state (inside [`Vehicle`]).
#[derive(Debug, Clone, Default)]
pub(super) struct MissionWatch {
    /// Watching at all (`fly --mission autopilot`).
    enabled: bool,
    /// The mission as last downloaded or verified after our own upload.
    known: Option<Vec<MissionItem>>,
    /// MISSION_CURRENT's `total` and non-zero `mission_id` as last seen.
    total_seen: Option<u16>,
    id_seen: Option<u32>,
    /// The autopilot has reported a `mission_id`: trust it, no periodic download.
    has_id: bool,
    /// A download is wanted now.
    due: bool,
    /// The next periodic download (ArduPilot).
    next_poll: Duration,
    /// Our download is running.
    downloading: bool,
    /// What the shell has not taken yet.
    pending: Option<AutopilotMission>,
}

impl Vehicle {
    /// Watch the autopilot's own mission (`fly --mission autopilot`): download it once the
    /// autopilot is chosen and whenever it may have changed; [`Vehicle::take_autopilot_mission`]
    /// hands it over. The route's upload step then uploads nothing: the autopilot's mission is
    /// the one flown.
    pub fn watch_autopilot_mission(&mut self) {
        self.watch.enabled = true;
        self.watch.due = true;
    }

    /// Stop watching (a restarted companion downloaded the mission once to compare it with its
    /// own route, and flies that route): no more downloads, the route's upload step uploads.
    pub fn unwatch_autopilot_mission(&mut self) {
        self.watch = MissionWatch::default();
    }

    /// Whether the autopilot's own mission is the one flown (and watched).
    pub fn flies_autopilot_mission(&self) -> bool {
        self.watch.enabled
    }

    /// The autopilot's mission as last downloaded, if any.
    pub fn autopilot_mission(&self) -> Option<&[MissionItem]> {
        self.watch.known.as_deref()
    }

    /// The mission loaded or changed since the last call.
    pub fn take_autopilot_mission(&mut self) -> Option<AutopilotMission> {
        self.watch.pending.take()
    }

    /// A new autopilot (or the same one rebooted): its mission is downloaded afresh.
    pub(super) fn reset_mission_watch(&mut self) {
        let enabled = self.watch.enabled;
        self.watch = MissionWatch {
            enabled,
            due: enabled,
            ..MissionWatch::default()
        };
    }

    /// MISSION_CURRENT from the autopilot: a changed `total` or `mission_id` asks for a download.
    pub(super) fn watch_mission_current(&mut self, m: &MISSION_CURRENT_DATA) {
        let w = &mut self.watch;
        if !w.enabled {
            return;
        }
        if m.mission_id != 0 {
            w.has_id = true;
            if w.id_seen.is_some_and(|id| id != m.mission_id) {
                w.due = true;
            }
            w.id_seen = Some(m.mission_id);
        }
        if w.total_seen.is_some_and(|t| t != m.total) {
            w.due = true;
        }
        w.total_seen = Some(m.total);
    }

    /// Start a download when one is due and the mission protocol is free.
    pub(super) fn pump_mission_watch(&mut self, now: Duration, out: &mut Vec<Msg>) {
        let w = &mut self.watch;
        if !w.enabled || w.downloading || self.target.is_none() {
            return;
        }
        if !w.has_id && now >= w.next_poll {
            w.due = true;
        }
        if !w.due || self.mission.busy() {
            return;
        }
        if let Ok(msgs) = self.mission.download(now) {
            let w = &mut self.watch;
            w.due = false;
            w.downloading = true;
            w.next_poll = now + MISSION_POLL;
            out.extend(msgs);
        }
    }

    /// Our download ended: `Some(items)` when it completed.
    pub(super) fn watch_downloaded(&mut self, items: Option<Vec<MissionItem>>, why: &str) {
        self.watch.downloading = false;
        let Some(items) = items else {
            // Tried again at the next poll (or the next MISSION_CURRENT change).
            self.watch.due = self.watch.has_id;
            self.link_event(
                LinkEvent::Other(format!("autopilot mission download failed: {why}")),
                false,
            );
            return;
        };
        let first = usize::from(self.mission.home_at_seq0);
        let update = match &self.watch.known {
            None => Some(AutopilotMission::Loaded(items.clone())),
            Some(known) if compare_from(known, &items, first).is_err() => {
                Some(AutopilotMission::Changed(items.clone()))
            }
            Some(_) => None,
        };
        self.watch.known = Some(items);
        if let Some(u) = update {
            let significant = matches!(u, AutopilotMission::Changed(_));
            let what = match &u {
                AutopilotMission::Loaded(i) => format!("autopilot mission: {} items", i.len()),
                AutopilotMission::Changed(i) => {
                    format!("autopilot mission changed: {} items", i.len())
                }
            };
            // Loaded before the watch's first answer is pending: the later one is what flies.
            self.watch.pending = Some(match (self.watch.pending.take(), u) {
                (Some(AutopilotMission::Loaded(_)), AutopilotMission::Changed(i)) => {
                    AutopilotMission::Loaded(i)
                }
                (_, u) => u,
            });
            self.link_event(LinkEvent::Other(what), significant);
        }
    }

    /// Our own upload was verified: that mission is known, so it is no change.
    pub(super) fn watch_uploaded(&mut self, items: &[MissionItem]) {
        if self.watch.enabled {
            self.watch.known = Some(items.to_vec());
        }
    }

    /// The route's upload step when the autopilot's mission is flown: nothing to upload once it
    /// is known; refused before (no start on a mission not yet read).
    pub(super) fn keep_autopilot_mission_step(&mut self, now: Duration, action: String) -> Advance {
        let result = if self.watch.known.is_some() {
            self.step_done();
            CommandOutcome::Skipped("the autopilot's own mission is flown".into())
        } else {
            self.job_failed(now);
            CommandOutcome::Failed(Some("the autopilot's mission is not downloaded yet".into()))
        };
        self.record_step(action, "MISSION_UPLOAD".into(), result);
        Advance::Again
    }
}
