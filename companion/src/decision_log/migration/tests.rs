use super::*;
use crate::decision_log::Header;

mod sentences;

fn header_with(mission: Option<String>) -> Header {
    let dir = crate::params::default_params_dir();
    let mut h = Header::new("companion simulate", std::time::SystemTime::UNIX_EPOCH);
    if let Some(m) = mission {
        h.params.insert("mission.toml".into(), m);
        h.params.insert(
            "actions.toml".into(),
            std::fs::read_to_string(dir.join("actions.toml")).unwrap(),
        );
    }
    h
}

#[test]
fn review_reads_the_mission_states_from_the_log_header() {
    let shipped =
        std::fs::read_to_string(crate::params::default_params_dir().join("mission.toml")).unwrap();
    let declared = mission_states_of(&header_with(Some(shipped.clone())));
    assert_eq!(declared.phase("v4"), "tracking");
    assert!(declared.has_phase("wpi"));
    // The run's own params decide: a run whose v5 was a landing state is read as such.
    let changed = shipped.replacen(
        r#"{ name = "v5", phase = "tracking", action = "track_v5" }"#,
        r#"{ name = "v5", phase = "landing" }"#,
        1,
    );
    assert_ne!(changed, shipped);
    assert!(!mission_states_of(&header_with(Some(changed))).is_tracking("v5"));
}

#[test]
fn review_of_a_log_declaring_states_but_no_route_states_keeps_its_phases() {
    let shipped =
        std::fs::read_to_string(crate::params::default_params_dir().join("mission.toml")).unwrap();
    let table = "[route_states]\non_ground = \"base\"\nfirst_leg = \"wp1\"\n\
        between_waypoints = \"wpi\"\nlast_waypoint = \"wpf\"\ntarget_found = \"target\"\n\
        landing = \"landing\"\n";
    assert!(shipped.contains(table), "the shipped table as written here");
    let before = shipped.replacen(table, "", 1);
    let read = mission_states_of(&header_with(Some(before)));
    assert_ne!(read, MissionStates::undeclared(), "not the earlier rule");
    assert!(read.has_phase("wpi") && read.phase("v4") == "tracking");
    assert_eq!(read, mission_states_of(&header_with(Some(shipped))));
}

#[test]
fn review_of_a_log_without_declared_states_uses_the_earlier_rule() {
    // No params in the header, or a mission.toml from before `states` existed.
    let old = MissionStates::undeclared();
    assert_eq!(mission_states_of(&header_with(None)), old);
    let pre_states = "horizon = 100\n[rates]\n[guarantee]\nmission = \"tracking\"\n\
        capped_probability = \"P_battery\"\ninfeasible_p_battery = 0.05\n\
        progress_goal = \"duration_s\"\nactivity_of_state = {}\n";
    assert_eq!(
        mission_states_of(&header_with(Some(pre_states.into()))),
        old
    );
    assert!(old.is_tracking("v7") && !old.is_tracking("wpf"));
}
