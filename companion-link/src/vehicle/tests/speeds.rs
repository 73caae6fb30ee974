//! The mission speeds read from the autopilot's parameters.

use super::*;

#[test]
fn arducopter_speeds_are_read_in_cm_per_s_and_follow_a_later_param_set() {
    let mut v = vehicle();
    let mut asked = Vec::new();
    for t in 0..3 {
        asked.extend(param_requests(&v.on_frame(s(t as f64), &hb(0, false))));
    }
    for name in ["WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN"] {
        assert!(asked.iter().any(|a| a == name), "{name} asked: {asked:?}");
    }
    let real = MavParamType::MAV_PARAM_TYPE_REAL32;
    v.on_frame(s(3.0), &frame(param_value("WPNAV_SPEED", 1000.0, real)));
    v.on_frame(s(3.1), &frame(param_value("WPNAV_SPEED_UP", 250.0, real)));
    v.on_frame(s(3.2), &frame(param_value("WPNAV_SPEED_DN", 150.0, real)));
    assert_eq!(v.telemetry.get("cruise_speed_mps"), Some(10.0));
    assert_eq!(v.telemetry.get("climb_speed_mps"), Some(2.5));
    assert_eq!(v.telemetry.get("descent_speed_mps"), Some(1.5));
    let obs = v.observations(s(3.3), vec![]);
    assert_eq!(obs.values.get("cruise_speed_mps"), Some(&10.0));
    // A ground station's PARAM_SET: ArduPilot broadcasts the new value, which is the one in force.
    v.on_frame(s(10.0), &frame(param_value("WPNAV_SPEED", 750.0, real)));
    assert_eq!(v.telemetry.get("cruise_speed_mps"), Some(7.5));
    // A speed no multicopter flies is refused, the last good one kept.
    v.on_frame(s(11.0), &frame(param_value("WPNAV_SPEED", -5.0, real)));
    assert_eq!(v.telemetry.get("cruise_speed_mps"), Some(7.5));
}

#[test]
fn px4_speeds_are_read_in_m_per_s() {
    let mut v = vehicle();
    let out = px4_ready(&mut v, 0.0);
    let asked = param_requests(&out);
    for name in ["MPC_XY_CRUISE", "MPC_Z_V_AUTO_UP", "MPC_Z_V_AUTO_DN"] {
        assert!(asked.iter().any(|a| a == name), "{name} asked: {asked:?}");
    }
    let real = MavParamType::MAV_PARAM_TYPE_REAL32;
    v.on_frame(s(1.0), &px4_frame(param_value("MPC_XY_CRUISE", 5.0, real)));
    v.on_frame(
        s(1.1),
        &px4_frame(param_value("MPC_Z_V_AUTO_UP", 3.0, real)),
    );
    assert_eq!(v.telemetry.get("cruise_speed_mps"), Some(5.0));
    assert_eq!(v.telemetry.get("climb_speed_mps"), Some(3.0));
    assert_eq!(
        v.telemetry.get("descent_speed_mps"),
        None,
        "not answered yet"
    );
}
