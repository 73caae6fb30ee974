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

use super::executor::Ports;
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

impl MissionWatch {
    /// Watch the autopilot's own mission (`fly --mission autopilot`).
    pub(super) fn enable(&mut self) {
        self.enabled = true;
        self.due = true;
    }

    /// Whether the autopilot's own mission is the one flown (and watched).
    pub(super) fn flies(&self) -> bool {
        self.enabled
    }

    /// The autopilot's mission as last downloaded, if any.
    pub(super) fn known(&self) -> Option<&[MissionItem]> {
        self.known.as_deref()
    }

    /// The mission loaded or changed since the last call.
    pub(super) fn take_pending(&mut self) -> Option<AutopilotMission> {
        self.pending.take()
    }

    /// A new autopilot (or the same one rebooted): its mission is downloaded afresh.
    pub(super) fn reset(&mut self) {
        let enabled = self.enabled;
        *self = MissionWatch {
            enabled,
            due: enabled,
            ..MissionWatch::default()
        };
    }

    /// MISSION_CURRENT from the autopilot: a changed `total` or `mission_id` asks for a download.
    pub(super) fn on_mission_current(&mut self, m: &MISSION_CURRENT_DATA) {
        let w = self;
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

    /// Start a download when one is due and the mission protocol is free (`target`: the
    /// autopilot is chosen).
    pub(super) fn pump(
        &mut self,
        now: Duration,
        target: Option<(u8, u8)>,
        mission: &mut MissionClient,
        out: &mut Vec<Msg>,
    ) {
        let w = self;
        if !w.enabled || w.downloading || target.is_none() {
            return;
        }
        if !w.has_id && now >= w.next_poll {
            w.due = true;
        }
        if !w.due || mission.busy() {
            return;
        }
        if let Ok(msgs) = mission.download(now) {
            w.due = false;
            w.downloading = true;
            w.next_poll = now + MISSION_POLL;
            out.extend(msgs);
        }
    }

    /// Our own upload was verified: that mission is known, so it is no change.
    pub(super) fn uploaded(&mut self, items: &[MissionItem]) {
        if self.enabled {
            self.known = Some(items.to_vec());
        }
    }
}

impl Ports<'_> {
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
}
