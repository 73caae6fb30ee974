//! Tracking time, the paper's Table 8 "tracking time (nbr steps)", defined once for `simulate`
//! (counted while the world advances) and `review` (counted from the decision records).
//!
//! A tracking step is a decision cycle that starts at the target or in a tracking state (the
//! `tracking` phase of params/mission.toml), chooses the action that keeps one tracking state
//! (`track_v3` keeps `v3`) and ends in that state: the target was kept for that step. A cycle
//! that chose to track but lost the target (back to `target`) or broke off to land is not one.

use crate::mission::MissionStates;
use crate::record::DecisionRecord;

/// One cycle: in state `before`, the action set `actions`, then in state `after`.
pub fn is_tracking_step<I>(states: &MissionStates, before: &str, actions: I, after: &str) -> bool
where
    I: IntoIterator,
    I::Item: AsRef<str>,
{
    if !states.is_target_in_sight(before) {
        return false;
    }
    states
        .tracking_target(actions)
        .is_some_and(|(kept, _)| kept == after)
}

/// Key under `DecisionRecord::vehicle` where `simulate` writes the world's phase after the step
/// (the state the next record starts in; the last record has no next one).
pub const STATE_AFTER_KEY: &str = "state_after";

/// The state a record's cycle ended in: its own `vehicle.state_after` when written, else the
/// next record's state.
pub fn state_after<'a>(r: &'a DecisionRecord, next: Option<&'a DecisionRecord>) -> Option<&'a str> {
    r.vehicle
        .get(STATE_AFTER_KEY)
        .and_then(|v| v.as_str())
        .or_else(|| next.map(|n| n.state.as_str()))
}

/// Counts tracking steps over records fed one at a time (each record is judged when the next one
/// arrives, or at [`TrackingCounter::finish`]), so a log can be streamed.
#[derive(Debug, Default, Clone)]
pub struct TrackingCounter {
    states: MissionStates,
    pending: Option<Pending>,
    steps: usize,
    seconds: f64,
}

#[derive(Debug, Clone)]
struct Pending {
    state: String,
    /// The tracking state the cycle's actions aimed at.
    kept: Option<String>,
    state_after: Option<String>,
    time_s: f64,
}

impl TrackingCounter {
    /// A counter judging by the mission's declared states ([`TrackingCounter::default`] uses
    /// [`MissionStates::undeclared`]).
    pub fn new(states: MissionStates) -> Self {
        Self {
            states,
            ..Self::default()
        }
    }

    /// The mission's states (and the roles of its actions) the counter judges by.
    pub fn states(&self) -> &MissionStates {
        &self.states
    }

    /// Feed the next record; `step_s` is the nominal cycle length, used for the last record.
    pub fn push(&mut self, r: &DecisionRecord) {
        if let Some(p) = self.pending.take() {
            let after = p.state_after.clone().unwrap_or_else(|| r.state.clone());
            let dt = (r.time_s - p.time_s).max(0.0);
            self.judge(&p, &after, dt);
        }
        self.pending = Some(Pending {
            state: r.state.clone(),
            kept: self
                .states
                .tracking_target(&r.actions)
                .map(|(kept, _)| kept.to_string()),
            state_after: r
                .vehicle
                .get(STATE_AFTER_KEY)
                .and_then(|v| v.as_str())
                .map(str::to_string),
            time_s: r.time_s,
        });
    }

    fn judge(&mut self, p: &Pending, after: &str, dt: f64) {
        let from_tracking = self.states.is_target_in_sight(&p.state);
        if from_tracking && p.kept.as_deref() == Some(after) {
            self.steps += 1;
            self.seconds += dt;
        }
    }

    /// Judge the last record (only when it says where it ended) and return (steps, seconds).
    pub fn finish(&mut self, last_step_s: f64) -> (usize, f64) {
        if let Some(p) = self.pending.take()
            && let Some(after) = p.state_after.clone()
        {
            self.judge(&p, &after, last_step_s);
        }
        (self.steps, self.seconds)
    }
}

/// Tracking steps of a whole run's records.
pub fn tracking_steps(states: &MissionStates, records: &[DecisionRecord]) -> usize {
    let mut c = TrackingCounter::new(states.clone());
    for r in records {
        c.push(r);
    }
    c.finish(0.0).0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(state: &str, actions: &[&str]) -> DecisionRecord {
        DecisionRecord {
            state: state.into(),
            actions: actions.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        }
    }

    fn shipped() -> MissionStates {
        MissionStates::load(&crate::shipped::params()).unwrap()
    }

    #[test]
    fn a_tracking_step_keeps_the_target_in_the_chosen_variant() {
        for s in [shipped(), MissionStates::undeclared()] {
            assert!(is_tracking_step(&s, "target", &["track_v3"], "v3"));
            assert!(is_tracking_step(&s, "v3", &["track_v1", "land"], "v1"));
            // Target lost, or broke off to land, or not at the target yet.
            assert!(!is_tracking_step(&s, "v3", &["track_v3"], "target"));
            assert!(!is_tracking_step(&s, "v3", &["track_v3"], "landing"));
            assert!(!is_tracking_step(&s, "wpf", &["track_v0"], "v0"));
            assert!(!is_tracking_step(&s, "v2", &["follow_trajectory"], "v2"));
            // detect_target runs the tracking application too but keeps no tracking state.
            assert!(!is_tracking_step(&s, "target", &["detect_target"], "v0"));
        }
    }

    #[test]
    fn the_undeclared_rule_of_old_logs_agrees_with_the_shipped_states() {
        let (declared, old) = (shipped(), MissionStates::undeclared());
        for st in [
            "base", "wp1", "wpi", "wpf", "target", "v0", "v3", "v5", "landing",
        ] {
            assert_eq!(declared.phase(st), old.phase(st), "{st}");
        }
        for a in ["track_v0", "track_v5", "detect_target", "land"] {
            assert_eq!(
                declared.tracking_target(&[a]),
                old.tracking_target(&[a]),
                "{a}"
            );
        }
    }

    #[test]
    fn records_judged_by_the_next_state_or_their_own_state_after() {
        let mut last = rec("v0", &["track_v0"]);
        last.vehicle
            .insert(STATE_AFTER_KEY.into(), serde_json::json!("v0"));
        let recs = vec![
            rec("wpf", &["detect_target"]),
            rec("target", &["track_v0"]), // -> v0: counted
            rec("v0", &["track_v0"]),     // -> target: lost
            rec("target", &["track_v0"]), // -> v0: counted
            last,                         // says it ended in v0: counted
        ];
        assert_eq!(tracking_steps(&shipped(), &recs), 3);
    }
}
