//! What the fly shell keeps between cycles besides the protocol state: the mission estimate, the
//! operator gate, the words to the ground station and what they last told.

use super::{FlySetup, NOTICE, WARNING, words};
use companion_core::action_id::{ActionNames, id_in};
use companion_core::launch::LaunchRefusal;
use companion_core::mission::RouteRole;
use companion_core::record::{DecisionRecord, Event, GuaranteeRecord, LinkEvent};
use companion_core::vocabulary::{ActionId, ActionIds};
use companion_link::ingest;
use companion_link::mission_state::MissionState;
use companion_link::operator::{GcsText, OperatorGate};
use std::time::Duration;

/// What the shell keeps between cycles besides the protocol state (one per flight).
pub struct Shell {
    pub(super) mission: MissionState,
    /// The derived plan against the route flown: names `route_activity` each cycle.
    pub(super) route_progress: Option<super::route_progress::RouteProgress>,
    /// The derived activity the last cycle found flown (`route_activity`), when any.
    pub(super) route_activity: Option<usize>,
    /// The mission state a new flight starts from.
    pub(super) fresh_mission: MissionState,
    pub(super) precedence: Vec<String>,
    /// `precedence` as ids of the decider's catalogue, resolved on the first cycle.
    pub(super) precedence_ids: Option<Vec<ActionId>>,
    /// Per action of the decider's catalogue (by its id), the same action's id in the shell's
    /// (params/actions.toml, which the commands table and the mission estimate index), resolved
    /// on the first cycle: a scripted decider has a catalogue of its own.
    pub(super) shell_ids: Option<DeciderIds>,
    /// Events of the shell itself (the mission's end, the operator) for the next record.
    pub(super) pending_events: Vec<Event>,
    /// Who commands: the companion only once the operator started the mission. `Shell::new`
    /// starts it at once (the soak and fuzz runs); `fly` waits unless `--auto-start`.
    pub operator: OperatorGate,
    /// STATUSTEXT to the ground station, rate-limited.
    pub texts: GcsText,
    /// The values a ground station plots, and when the next are due.
    pub(super) ground_values: companion_link::ground_values::GroundValues,
    /// The last cycle's action set, to tell a change of behaviour.
    pub(super) last_actions: ActionIds,
    /// The last behaviour told to the ground station (motion and tracking version), and the
    /// evidence of that cycle (to say what changed).
    pub(super) last_told: words::Behaviour,
    pub(super) told_evidence:
        companion_core::named_slots::NamedSlots<companion_core::named_slots::Label>,
    /// What the guarantee's last verdict told was about (None: it could meet the goals).
    pub(super) guarantee_told: Option<Vec<String>>,
    /// Ingest counters now, and as last reported in a record's link_events.
    pub(super) ingest: ingest::IngestStats,
    pub(super) ingest_reported: ingest::IngestStats,
    /// The launch verdict of the latest record while the gate waits (before any record: not
    /// on the ground yet, no decision to read).
    pub(super) launch: Result<(), LaunchRefusal>,
    /// When the running start was granted (a job failing after it, before airborne, voids it).
    pub(super) granted_at: Option<Duration>,
    /// The last `--auto-start` refusal said (said once per reason).
    pub(super) refusal_told: Option<String>,
    /// A command addressed to us older than this is refused.
    pub(super) command_max_age: Duration,
    /// `fly --mission autopilot`: why the mission is not planned (no start is granted then).
    pub(super) mission_unplanned: Option<String>,
    /// While a flight found in progress goes on: the last cycle's guarantee and battery
    /// percentage, and when (the resume's proof reads them).
    pub(super) guarantee_in_flight: Option<(Duration, Option<GuaranteeRecord>, Option<f64>)>,
}

impl Shell {
    pub fn new(setup: &FlySetup) -> Self {
        let mut mission = MissionState::new(
            &setup.route,
            setup.takeoff_alt_m,
            setup.states.clone(),
            &setup.catalogue,
        );
        let f = &setup.link.flight;
        mission.landed_confirm_s = f.landed_confirm_s;
        mission.ground_altitude_m = f.ground_altitude_m;
        Self {
            route_progress: setup.route_progress.clone(),
            route_activity: None,
            fresh_mission: mission.clone(),
            mission,
            precedence: setup.link.vehicle_action_precedence.clone(),
            precedence_ids: None,
            shell_ids: None,
            pending_events: Vec::new(),
            operator: OperatorGate::started(),
            texts: GcsText::new(
                Duration::from_secs_f64(f.statustext_repeat_s),
                f.statustext_max_per_s,
            ),
            ground_values: companion_link::ground_values::GroundValues::new(
                &setup.link.ground_values,
                (setup.catalogue.actions.iter()).map(|a| (a.id.as_str(), a.paper.as_str())),
            ),
            last_actions: ActionIds::default(),
            last_told: Default::default(),
            told_evidence: Default::default(),
            guarantee_told: None,
            ingest: Default::default(),
            ingest_reported: Default::default(),
            launch: Err(LaunchRefusal::NotOnGround {
                state: String::new(),
                on_ground: setup.states.route_state(RouteRole::OnGround).to_string(),
            }),
            granted_at: None,
            refusal_told: None,
            command_max_age: Duration::from_secs_f64(f.command_max_age_s),
            mission_unplanned: None,
            guarantee_in_flight: None,
        }
    }

    /// The ingest counters now (reported in a record's link_events when bad input grew).
    pub fn set_ingest(&mut self, stats: ingest::IngestStats) {
        self.ingest = stats;
    }

    /// Flew, landed and disarmed: the mission is over.
    pub fn finished(&self) -> bool {
        self.mission.finished()
    }

    /// After a flight ended landed and disarmed: a fresh mission, and the operator must start
    /// the next one.
    pub fn new_flight(&mut self) {
        self.mission = self.fresh_mission.clone();
        self.operator.new_flight();
        self.granted_at = None;
        self.last_actions.clear();
        self.last_told = Default::default();
        self.told_evidence.clear();
        self.pending_events.push(Event::NewFlight);
    }

    /// A change of the cycle's action set, described for the journal and the ground station
    /// ("take_off -> follow_trajectory (waypoint 2)"), or None when it is the same as the
    /// last cycle's.
    pub(super) fn action_change(&mut self, rec: &DecisionRecord) -> Option<String> {
        if rec.actions == self.last_actions {
            return None;
        }
        let was = std::mem::replace(&mut self.last_actions, rec.actions.clone());
        let why = rec
            .events
            .iter()
            .find(|e| !matches!(e, Event::Command { .. }))
            .map_or_else(|| format!("state {}", rec.state), Event::to_string);
        let show = |a: &ActionIds| {
            if a.is_empty() {
                "-".to_string()
            } else {
                a.join("+")
            }
        };
        Some(format!("{} -> {} ({why})", show(&was), show(&rec.actions)))
    }

    /// What a pilot needs of a behaviour change: what the vehicle will do and why
    /// (`Battery 7%: returning home`, docs/mavlink.md "Words to the ground station"). `flown` is
    /// the vehicle action flown this cycle (the shell's landing included), so a landing the
    /// shell keeps is told as a landing. None when neither the motion nor the tracking version
    /// changed: one text per change, never one per cycle.
    pub(super) fn behaviour_text(
        &mut self,
        rec: &DecisionRecord,
        flown: Option<&str>,
    ) -> Option<String> {
        let now = words::Behaviour {
            motion: flown.map(str::to_string),
            motion_role: flown.and_then(|a| self.mission.states().actions().role_of(a)),
            tracking: {
                let ours = self.mission.actions().names();
                let ids = our_ids(ours, self.shell_ids.as_ref(), &rec.actions);
                self.mission.tracking_target(ids).map(str::to_string)
            },
        };
        if now == self.last_told {
            return None;
        }
        // Nothing flown, nothing tracked, the vehicle disarmed (down after a landing, or not yet
        // up): there is no behaviour to tell ("holding position" would be false on the ground).
        let disarmed = rec.observations.get("armed").is_some_and(|a| *a < 0.5);
        if now.motion.is_none() && now.tracking.is_none() && disarmed {
            self.last_told = now;
            return None;
        }
        let text = words::behaviour_text(
            &now,
            &self.last_told,
            rec,
            &self.told_evidence,
            self.mission.end(),
        );
        self.last_told = now;
        self.told_evidence.clone_from(&rec.evidence);
        Some(text)
    }

    /// The guarantee's verdict when it changed (what it is short of, not by how much): the
    /// journal line and the STATUSTEXT with its severity. None while it is the same, so a
    /// vehicle on the ground after landing hears it once, not once a cycle.
    pub(super) fn guarantee_change(
        &mut self,
        rec: &DecisionRecord,
    ) -> Option<(String, companion_link::dialect::MavSeverity, String)> {
        let g = rec.guarantee.as_ref()?;
        let key = words::guarantee_key(g);
        if key == self.guarantee_told {
            return None;
        }
        let was = std::mem::replace(&mut self.guarantee_told, key);
        match &self.guarantee_told {
            Some(_) => {
                let why = g
                    .infeasible_reason
                    .as_deref()
                    .unwrap_or("no allocation meets the goals");
                Some((
                    format!("guarantee: cannot meet the goals: {why}"),
                    WARNING,
                    words::guarantee_text(g),
                ))
            }
            None => was.map(|_| {
                (
                    "guarantee: the goals can be met again".to_string(),
                    NOTICE,
                    "Goals can be met again".to_string(),
                )
            }),
        }
    }

    /// A link event when bad input arrived since the last report: malformed frames or bad
    /// signatures, or more unframed bytes than one frame still arriving could explain.
    pub(super) fn ingest_note(&mut self) -> Option<LinkEvent> {
        let (now, was) = (&self.ingest, &self.ingest_reported);
        let grew = now.frames_malformed > was.frames_malformed
            || now.bad_signatures > was.bad_signatures
            || now.unsigned_commands_refused > was.unsigned_commands_refused
            || now.unsigned_refused > was.unsigned_refused
            || now.bytes_unframed() > was.bytes_unframed() + MAX_FRAME_BYTES;
        if !grew {
            return None;
        }
        self.ingest_reported = *now;
        Some(LinkEvent::Other(format!(
            "ingest: {} bytes outside valid frames (garbage or corrupt), {} malformed frames, {} bad signatures, {} unsigned commands refused, {} other unsigned frames refused (since start)",
            now.bytes_unframed(),
            now.frames_malformed,
            now.bad_signatures,
            now.unsigned_commands_refused,
            now.unsigned_refused
        )))
    }
}

/// Longest MAVLink 2 frame (signed): a frame still arriving is at most this many bytes.
const MAX_FRAME_BYTES: u64 = 280;

/// The decider's catalogue as the shell's: per action of the decider's (by its id), the same
/// action's id in the shell's (params/actions.toml, which the commands table and the mission
/// estimate index). A scripted decider has a catalogue of its own.
pub(super) struct DeciderIds {
    /// The decider's action names, the vocabulary of the records it writes.
    pub(super) names: ActionNames,
    /// By the decider's id, the shell's.
    pub(super) to_ours: Vec<Option<ActionId>>,
}

impl DeciderIds {
    /// The map from `decider`'s catalogue to `ours`.
    pub(super) fn new(
        decider: &companion_core::mission::ActionCatalogue,
        ours: &companion_core::mission::ActionCatalogue,
    ) -> Self {
        DeciderIds {
            names: decider.names().clone(),
            to_ours: decider.actions.iter().map(|a| ours.id(&a.id)).collect(),
        }
    }
}

/// The ids in the shell's catalogue (its action names `ours`) of the record's action list `list`: as they are when it is
/// over that catalogue (the shell's `shell_actions`), through `decider` when over the decider's
/// (the core's `actions`), by name otherwise. An action the shell's catalogue lacks is skipped.
pub(super) fn our_ids<'a>(
    ours: &'a ActionNames,
    decider: Option<&'a DeciderIds>,
    list: &'a ActionIds,
) -> impl Iterator<Item = ActionId> + Clone + 'a {
    let direct = std::sync::Arc::ptr_eq(list.vocabulary(), ours);
    let mapped = decider.filter(|d| std::sync::Arc::ptr_eq(list.vocabulary(), &d.names));
    list.ids()
        .iter()
        .filter_map(move |&a| match (direct, mapped) {
            (true, _) => Some(a),
            (false, Some(d)) => d.to_ours.get(a.index()).copied().flatten(),
            (false, None) => id_in(ours, list.name(a)),
        })
}

/// Say `unsaid` to the ground station now; when the STATUSTEXT rate cap holds it back it stays
/// unsaid, for a later turn (a plan's word is never lost to the cap).
pub(super) fn say_until_said(
    shell: &mut Shell,
    now: Duration,
    unsaid: &mut Option<(companion_link::dialect::MavSeverity, String)>,
) -> Vec<companion_link::Msg> {
    let Some((severity, text)) = unsaid.as_ref() else {
        return Vec::new();
    };
    let dropped = shell.texts.dropped;
    let out = shell.texts.say(now, *severity, text);
    if shell.texts.dropped == dropped {
        *unsaid = None;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fly::FlyArgs;

    fn test_shell() -> Shell {
        let args =
            FlyArgs::from_cli(["--connect", "udpin:127.0.0.1:14550", "--auto-start"]).unwrap();
        Shell::new(&FlySetup::load(&args).unwrap())
    }

    #[test]
    fn behaviour_text_names_the_tracking_state_the_plan_keeps() {
        let mut shell = test_shell();
        let rec = |actions: &[&str]| DecisionRecord {
            actions: actions.iter().map(|a| a.to_string()).collect(),
            ..Default::default()
        };
        let text = shell
            .behaviour_text(
                &rec(&["follow_trajectory", "track_v3"]),
                Some("follow_trajectory"),
            )
            .unwrap();
        assert_eq!(text, "Flying the route, tracking with V3");
        // detect_target runs the tracking application but keeps no tracking state.
        let text = shell
            .behaviour_text(
                &rec(&["follow_trajectory", "detect_target"]),
                Some("follow_trajectory"),
            )
            .unwrap();
        assert_eq!(text, "Flying the route");
    }

    /// The landing the shell keeps flying (the MDPs plan nothing in `landing`) is told as a
    /// landing, once, not as "hold (mode LAND)" and not once a cycle.
    #[test]
    fn nothing_flown_on_the_ground_is_not_told_as_holding_position() {
        let mut shell = test_shell();
        let mut rec = DecisionRecord::default();
        rec.observations.insert("armed".into(), 1.0);
        assert_eq!(
            shell.behaviour_text(&rec, Some("land")).as_deref(),
            Some("Landing here")
        );
        rec.observations.insert("armed".into(), 0.0);
        assert_eq!(shell.behaviour_text(&rec, None), None);
        // In the air, nothing flown after a motion is holding position.
        let mut shell = test_shell();
        rec.observations.insert("armed".into(), 1.0);
        assert!(shell.behaviour_text(&rec, Some("land")).is_some());
        assert_eq!(
            shell.behaviour_text(&rec, None).as_deref(),
            Some("Holding position")
        );
    }

    #[test]
    fn a_kept_landing_is_told_once_as_a_landing() {
        let mut shell = test_shell();
        let flying = DecisionRecord {
            actions: ["follow_trajectory"].into_iter().collect(),
            ..Default::default()
        };
        assert!(
            shell
                .behaviour_text(&flying, Some("follow_trajectory"))
                .is_some()
        );
        let landing = DecisionRecord {
            state: "landing".into(),
            shell_actions: ["land"].into_iter().collect(),
            events: vec![Event::Mode("LAND".into())],
            observations: [("zone_found".to_string(), 0.0)].into_iter().collect(),
            ..Default::default()
        };
        assert_eq!(
            shell.behaviour_text(&landing, Some("land")).as_deref(),
            Some("Landing here")
        );
        for _ in 0..5 {
            assert_eq!(shell.behaviour_text(&landing, Some("land")), None);
        }
    }

    /// The guarantee's verdict is said when it changes: its amounts changing every cycle (the
    /// margins of a vehicle on the ground) say nothing more.
    #[test]
    fn the_guarantee_verdict_is_said_once_per_change() {
        use companion_core::record::GuaranteeRecord;
        let mut shell = test_shell();
        let rec = |infeasible: bool, energy: f64| DecisionRecord {
            guarantee: Some(GuaranteeRecord {
                margins: [("energy_j".to_string(), energy)].into_iter().collect(),
                infeasible,
                infeasible_reason: infeasible
                    .then(|| format!("negative energy_j margin {energy:.1}: no allocation")),
                ..Default::default()
            }),
            ..Default::default()
        };
        assert!(shell.guarantee_change(&rec(false, 100.0)).is_none());
        let (line, severity, text) = shell.guarantee_change(&rec(true, -4210.0)).unwrap();
        assert_eq!(severity, WARNING);
        assert!(line.contains("negative energy_j margin -4210.0"), "{line}");
        assert_eq!(text, "Cannot meet goals: not enough energy");
        for cycle in 0..30 {
            assert!(
                shell
                    .guarantee_change(&rec(true, -4210.0 - cycle as f64))
                    .is_none(),
                "cycle {cycle}"
            );
        }
        let (_, severity, text) = shell.guarantee_change(&rec(false, 50.0)).unwrap();
        assert_eq!(
            (severity, text.as_str()),
            (NOTICE, "Goals can be met again")
        );
        assert!(shell.guarantee_change(&rec(true, -10.0)).is_some());
    }
}
