//! Tracking time, the paper's Table 8 "tracking time (nbr steps)", defined once for `simulate`
//! (counted while the world advances) and `review` (counted from the decision records).
//!
//! A tracking step is a decision cycle that starts at the target or in a tracking phase
//! (`target`, `v0`..`v5`), chooses a tracking variant (`track_vN`) and ends in that variant's
//! tracking phase (`vN`): the target was kept for that step. A cycle that chose to track but lost
//! the target (back to `target`) or broke off to land is not one.

use crate::record::DecisionRecord;

/// `v0`..`v9`: a tracking phase of the mission.
pub fn is_tracking_phase(state: &str) -> bool {
    state.len() == 2 && state.starts_with('v') && state.as_bytes()[1].is_ascii_digit()
}

/// The tracking variant chosen in an action set (`track_v3` -> `3`), the first if several.
pub fn tracked_variant<S: AsRef<str>>(actions: &[S]) -> Option<&str> {
    actions
        .iter()
        .find_map(|a| a.as_ref().strip_prefix("track_v"))
}

/// One cycle: in state `before`, the action set `actions`, then in state `after`.
pub fn is_tracking_step<S: AsRef<str>>(before: &str, actions: &[S], after: &str) -> bool {
    if before != "target" && !is_tracking_phase(before) {
        return false;
    }
    match tracked_variant(actions) {
        Some(v) => after.strip_prefix('v') == Some(v) && is_tracking_phase(after),
        None => false,
    }
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
    pending: Option<Pending>,
    steps: usize,
    seconds: f64,
}

#[derive(Debug, Clone)]
struct Pending {
    state: String,
    variant: Option<String>,
    state_after: Option<String>,
    time_s: f64,
}

impl TrackingCounter {
    /// Feed the next record; `step_s` is the nominal cycle length, used for the last record.
    pub fn push(&mut self, r: &DecisionRecord) {
        if let Some(p) = self.pending.take() {
            let after = p.state_after.clone().unwrap_or_else(|| r.state.clone());
            let dt = (r.time_s - p.time_s).max(0.0);
            self.judge(&p, &after, dt);
        }
        self.pending = Some(Pending {
            state: r.state.clone(),
            variant: tracked_variant(&r.actions).map(str::to_string),
            state_after: r
                .vehicle
                .get(STATE_AFTER_KEY)
                .and_then(|v| v.as_str())
                .map(str::to_string),
            time_s: r.time_s,
        });
    }

    fn judge(&mut self, p: &Pending, after: &str, dt: f64) {
        let actions: Vec<String> = p.variant.iter().map(|v| format!("track_v{v}")).collect();
        if is_tracking_step(&p.state, &actions, after) {
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
pub fn tracking_steps(records: &[DecisionRecord]) -> usize {
    let mut c = TrackingCounter::default();
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

    #[test]
    fn a_tracking_step_keeps_the_target_in_the_chosen_variant() {
        assert!(is_tracking_step("target", &["track_v3"], "v3"));
        assert!(is_tracking_step("v3", &["track_v1", "land"], "v1"));
        // Target lost, or broke off to land, or not at the target yet.
        assert!(!is_tracking_step("v3", &["track_v3"], "target"));
        assert!(!is_tracking_step("v3", &["track_v3"], "landing"));
        assert!(!is_tracking_step("wpf", &["track_v0"], "v0"));
        assert!(!is_tracking_step("v2", &["follow_trajectory"], "v2"));
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
        assert_eq!(tracking_steps(&recs), 3);
    }
}
