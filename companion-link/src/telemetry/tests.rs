use super::*;

fn s(v: f64) -> Duration {
    Duration::from_secs_f64(v)
}
/// Heartbeats decode as ArduPilot's (custom mode 3 is AUTO, 4 GUIDED).
const AP: Flavor = Flavor::ArduPilot;

fn dist(id: u8, cm: u16, orientation: MavSensorOrientation) -> Msg {
    Msg::DISTANCE_SENSOR(DISTANCE_SENSOR_DATA {
        min_distance: 20,
        max_distance: 4000,
        current_distance: cm,
        id,
        orientation,
        ..DISTANCE_SENSOR_DATA::DEFAULT
    })
}

fn nvf(n: &str, v: f32) -> Msg {
    Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
        time_boot_ms: 0,
        value: v,
        name: n.into(),
    })
}

#[test]
fn telemetry_observations_lists_every_name_the_autopilot_messages_produce() {
    let mut t = Telemetry::new(TelemetryConfig {
        onboard: BTreeMap::new(),
        ..TelemetryConfig::default()
    });
    let msgs = [
        Msg::HOME_POSITION(HOME_POSITION_DATA {
            latitude: 473_977_420,
            longitude: 85_455_940,
            ..HOME_POSITION_DATA::DEFAULT
        }),
        Msg::SYS_STATUS(SYS_STATUS_DATA {
            battery_remaining: 80,
            voltage_battery: 16_000,
            ..SYS_STATUS_DATA::DEFAULT
        }),
        Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
            battery_remaining: 80,
            energy_consumed: 10,
            current_consumed: 10,
            ..BATTERY_STATUS_DATA::DEFAULT
        }),
        Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: 473_977_420,
            lon: 85_455_940,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        }),
        Msg::GPS_RAW_INT(GPS_RAW_INT_DATA {
            satellites_visible: 10,
            ..GPS_RAW_INT_DATA::DEFAULT
        }),
        Msg::VIBRATION(VIBRATION_DATA::DEFAULT),
        // A wind estimate (an all-zero WIND is no estimate and produces nothing).
        Msg::WIND(WIND_DATA {
            speed: 1.0,
            ..WIND_DATA::DEFAULT
        }),
        Msg::MISSION_CURRENT(MISSION_CURRENT_DATA::DEFAULT),
        Msg::CAMERA_TRACKING_IMAGE_STATUS(CAMERA_TRACKING_IMAGE_STATUS_DATA {
            tracking_status: CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE,
            ..CAMERA_TRACKING_IMAGE_STATUS_DATA::DEFAULT
        }),
        Msg::SYSTEM_TIME(SYSTEM_TIME_DATA::DEFAULT),
        dist(0, 1200, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
    ];
    for m in &msgs {
        t.on_message(s(0.0), m, AP);
    }
    t.on_pack_param(PackParam::CapacityMah, 5000.0);
    t.on_pack_param(PackParam::Cells, 4.0);
    for what in [SpeedParam::Cruise, SpeedParam::Climb, SpeedParam::Descent] {
        t.on_speed_param(what, 5.0);
    }
    let mut produced: Vec<String> = t
        .observations(s(0.0), vec![])
        .values
        .keys()
        .cloned()
        .collect();
    // BATTERY_STATUS's copy of the percentage is internal (removed from the snapshot).
    produced.sort();
    let mut listed: Vec<String> = TELEMETRY_OBSERVATIONS
        .iter()
        .map(|n| n.to_string())
        .collect();
    listed.sort();
    assert_eq!(produced, listed);
}

#[test]
fn obstacle_events_from_forward_sensor_only() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    assert!(
        t.on_message(
            s(0.0),
            &dist(1, 500, MavSensorOrientation::MAV_SENSOR_ROTATION_PITCH_270),
            AP
        )
        .is_empty(),
        "downward rangefinder is altitude"
    );
    assert_eq!(
        t.on_message(
            s(0.1),
            &dist(0, 3000, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
            AP
        ),
        Vec::<Event>::new()
    );
    assert_eq!(
        t.on_message(
            s(0.2),
            &dist(0, 1200, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
            AP
        ),
        vec![Event::ObstacleDetected]
    );
    assert_eq!(t.observations(s(0.3), vec![]).get("obstacle_m"), Some(12.0));
    assert!(
        t.on_message(
            s(0.3),
            &dist(0, 1100, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
            AP
        )
        .is_empty(),
        "still near: no new event"
    );
    assert_eq!(
        t.on_message(
            s(0.4),
            &dist(0, 2500, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
            AP
        ),
        vec!["obstacle cleared"]
    );
    // Stale readings vanish.
    t.on_message(
        s(0.5),
        &dist(0, 800, MavSensorOrientation::MAV_SENSOR_ROTATION_NONE),
        AP,
    );
    assert_eq!(t.observations(s(3.0), vec![]).get("obstacle_m"), None);
}

#[test]
fn obstacle_distance_scan_ignores_unknown_and_empty_sectors() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    let mut distances = [u16::MAX; 72];
    distances[3] = 4001; // max_distance + 1: nothing there
    distances[10] = 900;
    distances[11] = 10; // below min_distance: invalid
    let m = Msg::OBSTACLE_DISTANCE(OBSTACLE_DISTANCE_DATA {
        distances,
        min_distance: 20,
        max_distance: 4000,
        increment: 5,
        ..OBSTACLE_DISTANCE_DATA::DEFAULT
    });
    assert_eq!(t.on_message(s(0.0), &m, AP), vec![Event::ObstacleDetected]);
    assert_eq!(t.obstacle_m(s(0.0)), Some(9.0));
}

#[test]
fn onboard_monitors_map_names_and_target_events() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    assert_eq!(
        t.on_message(s(0.0), &nvf("tgt_det", 1.0), AP),
        vec![Event::TargetDetected]
    );
    t.on_message(s(0.0), &nvf("lum", 350.0), AP);
    t.on_message(s(0.0), &nvf("mystery", 2.0), AP);
    let o = t.observations(s(0.0), vec![]);
    assert_eq!(o.get("luminosity_lux"), Some(350.0));
    assert_eq!(o.get("onboard.mystery"), Some(2.0));
    assert_eq!(
        t.on_message(s(1.0), &nvf("tgt_det", 0.0), AP),
        vec!["target lost"]
    );
    let track = |flags| {
        Msg::CAMERA_TRACKING_IMAGE_STATUS(CAMERA_TRACKING_IMAGE_STATUS_DATA {
            tracking_status: flags,
            point_x: 0.4,
            point_y: 0.6,
            ..CAMERA_TRACKING_IMAGE_STATUS_DATA::DEFAULT
        })
    };
    assert_eq!(
        t.on_message(
            s(2.0),
            &track(CameraTrackingStatusFlags::CAMERA_TRACKING_STATUS_FLAGS_ACTIVE),
            AP
        ),
        vec![Event::TargetDetected]
    );
    assert_eq!(t.get("target_x"), Some(0.4f32 as f64));
}

#[test]
fn battery_status_gives_pack_voltage_and_current_over_sys_status() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    let sys = Msg::SYS_STATUS(SYS_STATUS_DATA {
        voltage_battery: 12_000,
        current_battery: 500,
        battery_remaining: 50,
        ..SYS_STATUS_DATA::DEFAULT
    });
    t.on_message(s(0.0), &sys, AP);
    assert_eq!(t.get("battery_v"), Some(12.0));
    assert_eq!(t.get("battery_current_a"), Some(5.0));
    // PX4 style: four cells of 3.9 V, 12.34 A.
    let mut voltages = [u16::MAX; 10];
    voltages[..4].copy_from_slice(&[3900; 4]);
    let bat = Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
        voltages,
        current_battery: 1234,
        battery_remaining: 50,
        ..BATTERY_STATUS_DATA::DEFAULT
    });
    t.on_message(s(1.0), &bat, AP);
    assert_eq!(t.get("battery_v"), Some(15.6));
    assert_eq!(t.get("battery_current_a"), Some(12.34));
    // SYS_STATUS no longer overrides BATTERY_STATUS's reading.
    t.on_message(s(2.0), &sys, AP);
    assert_eq!(t.get("battery_v"), Some(15.6));
    assert_eq!(t.get("battery_current_a"), Some(12.34));
    assert_eq!(t.observations(s(2.0), vec![]).get("battery_status_v"), None);
    // A pack parameter out of reason is refused and counted; -1 ("not set") is kept.
    t.on_pack_param(PackParam::CapacityMah, f64::NAN);
    t.on_pack_param(PackParam::Cells, 300.0);
    assert_eq!(t.rejected.out_of_range, 2);
    assert_eq!(t.get("battery_capacity_mah"), None);
    t.on_pack_param(PackParam::CapacityMah, -1.0);
    assert_eq!(t.get("battery_capacity_mah"), Some(-1.0));
}

#[test]
fn battery_thresholds_fire_once_on_the_way_down() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    let bat = |p: i8| {
        Msg::BATTERY_STATUS(BATTERY_STATUS_DATA {
            battery_remaining: p,
            energy_consumed: 360,
            current_consumed: 1200,
            ..BATTERY_STATUS_DATA::DEFAULT
        })
    };
    assert!(t.on_message(s(0.0), &bat(55), AP).is_empty());
    assert_eq!(
        t.on_message(s(1.0), &bat(49), AP),
        vec![Event::BatteryBelow(50.0)]
    );
    assert!(t.on_message(s(2.0), &bat(49), AP).is_empty());
    assert_eq!(
        t.on_message(s(3.0), &bat(15), AP),
        vec![Event::BatteryBelow(30.0), Event::BatteryBelow(20.0)]
    );
    assert_eq!(t.get("energy_consumed_j"), Some(36_000.0));
    // SYS_STATUS does not override BATTERY_STATUS once that is heard.
    t.on_message(
        s(4.0),
        &Msg::SYS_STATUS(SYS_STATUS_DATA {
            battery_remaining: 90,
            ..SYS_STATUS_DATA::DEFAULT
        }),
        AP,
    );
    assert_eq!(t.get("battery_pct"), Some(15.0));
}

#[test]
fn mode_and_arming_changes_are_events() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    let hb = |mode: u32, armed: bool| {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: mode,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            } else {
                MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            },
            ..HEARTBEAT_DATA::DEFAULT
        })
    };
    assert_eq!(
        t.on_message(s(0.0), &hb(4, false), AP),
        vec![Event::Mode("GUIDED".into())]
    );
    assert!(t.on_message(s(1.0), &hb(4, false), AP).is_empty());
    assert_eq!(
        t.on_message(s(2.0), &hb(3, true), AP),
        vec![Event::Armed, Event::Mode("AUTO".into())]
    );
}

fn wind(speed: f32, direction: f32) -> Msg {
    Msg::WIND(WIND_DATA {
        direction,
        speed,
        speed_z: 0.0,
    })
}

/// ArduCopter without wind states sends WIND all zero: no wind observation (absent, not
/// calm) until a non-zero reading shows the estimator runs; after that, zero is calm.
#[test]
fn all_zero_wind_is_no_estimate_until_the_autopilot_estimates() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    for k in 0..50 {
        t.on_message(s(k as f64 * 0.2), &wind(0.0, 0.0), AP);
    }
    let o = t.observations(s(10.0), vec![]);
    assert_eq!(o.get("wind_mps"), None);
    assert_eq!(o.get("wind_dir_deg"), None);
    assert!(!t.wind_estimating());
    t.on_message(s(10.2), &wind(0.4, 185.0), AP);
    assert!(t.wind_estimating());
    assert_eq!(
        t.observations(s(10.2), vec![]).get("wind_mps"),
        Some(0.4f32 as f64)
    );
    t.on_message(s(10.4), &wind(0.0, 0.0), AP);
    assert_eq!(t.observations(s(10.4), vec![]).get("wind_mps"), Some(0.0));
    // ArduCopter SITL without wind states: speed 0, direction -180 (atan2 of zeros) in
    // every message. The direction of a zero vector is no sign of estimation.
    let mut t = Telemetry::new(TelemetryConfig::default());
    for k in 0..10 {
        t.on_message(s(k as f64), &wind(0.0, -180.0), AP);
    }
    assert_eq!(t.observations(s(10.0), vec![]).get("wind_mps"), None);
    assert!(!t.wind_estimating());
}

/// PX4's WIND_COV: speed from the north/east components, direction the wind blows from;
/// NaN (no estimate) and all-zero before any estimate give no observation.
#[test]
fn wind_cov_gives_speed_and_direction() {
    let cov = |x: f32, y: f32| {
        Msg::WIND_COV(WIND_COV_DATA {
            wind_x: x,
            wind_y: y,
            ..WIND_COV_DATA::DEFAULT
        })
    };
    let mut t = Telemetry::new(TelemetryConfig::default());
    t.on_message(s(0.0), &cov(f32::NAN, f32::NAN), AP);
    t.on_message(s(0.1), &cov(0.0, 0.0), AP);
    assert_eq!(t.observations(s(0.1), vec![]).get("wind_mps"), None);
    // Air moving 3 m/s north and 4 m/s east: 5 m/s from the south-west (233.13 deg).
    t.on_message(s(0.2), &cov(3.0, 4.0), AP);
    let o = t.observations(s(0.2), vec![]);
    assert!((o.get("wind_mps").unwrap() - 5.0).abs() < 1e-9);
    assert!((o.get("wind_dir_deg").unwrap() - 233.130_102).abs() < 1e-4);
    // Wind from the north (air moving south): 0 deg.
    t.on_message(s(0.3), &cov(-2.0, 0.0), AP);
    assert!(
        t.observations(s(0.3), vec![])
            .get("wind_dir_deg")
            .unwrap()
            .abs()
            < 1e-9
    );
}

#[test]
fn position_vibration_wind_gps() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    t.on_message(
        s(0.0),
        &Msg::HOME_POSITION(HOME_POSITION_DATA {
            latitude: 473_977_420,
            longitude: 85_455_940,
            altitude: 488_000,
            ..HOME_POSITION_DATA::DEFAULT
        }),
        AP,
    );
    // 0.0009 deg north = 100.19 m.
    t.on_message(
        s(0.0),
        &Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat: 473_986_420,
            lon: 85_455_940,
            relative_alt: 20_000,
            vx: 300,
            vy: 400,
            hdg: 9000,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        }),
        AP,
    );
    t.on_message(
        s(0.0),
        &Msg::VIBRATION(VIBRATION_DATA {
            vibration_x: 3.0,
            vibration_y: 12.5,
            vibration_z: 7.0,
            ..VIBRATION_DATA::DEFAULT
        }),
        AP,
    );
    t.on_message(
        s(0.0),
        &Msg::WIND(WIND_DATA {
            direction: 270.0,
            speed: 6.5,
            speed_z: 0.0,
        }),
        AP,
    );
    t.on_message(
        s(0.0),
        &Msg::GPS_RAW_INT(GPS_RAW_INT_DATA {
            fix_type: GpsFixType::GPS_FIX_TYPE_3D_FIX,
            satellites_visible: 11,
            ..GPS_RAW_INT_DATA::DEFAULT
        }),
        AP,
    );
    let o = t.observations(s(0.0), vec![]);
    assert_eq!(o.get("altitude_m"), Some(20.0));
    assert_eq!(o.get("groundspeed_mps"), Some(5.0));
    assert!((o.get("distance_home_m").unwrap() - 100.19).abs() < 0.05);
    assert_eq!(o.get("vibration_mps2"), Some(12.5));
    assert_eq!(o.get("wind_mps"), Some(6.5));
    assert_eq!(
        (o.get("gps_fix"), o.get("gps_sats")),
        (Some(3.0), Some(11.0))
    );
    assert_eq!(t.position.unwrap().heading_deg, Some(90.0));
}

#[test]
fn monitor_values_outside_their_range_are_refused_and_counted() {
    let mut cfg = TelemetryConfig::default();
    cfg.onboard.insert("zone_n".into(), "zone_north_m".into());
    cfg.ranges.insert("zone_north_m".into(), [-1000.0, 1000.0]);
    let mut t = Telemetry::new(cfg);
    t.on_message(s(0.0), &nvf("zone_n", 40.0), AP);
    t.on_message(s(0.1), &nvf("zone_n", -2.0e7), AP);
    t.on_message(s(0.2), &nvf("zone_n", f32::NAN), AP);
    t.on_message(s(0.3), &nvf("other", f32::INFINITY), AP);
    assert_eq!(
        t.get("zone_north_m"),
        Some(40.0),
        "the last good value stays"
    );
    assert_eq!(t.get("onboard.other"), None);
    assert_eq!(t.rejected.out_of_range, 3);
    assert_eq!(t.rejected.last.as_deref(), Some("onboard.other = inf"));
}

#[test]
fn unmapped_names_are_capped_and_the_rest_counted() {
    let cfg = TelemetryConfig {
        max_onboard_names: 4,
        ..TelemetryConfig::default()
    };
    let mut t = Telemetry::new(cfg);
    for i in 0..1000 {
        t.on_message(s(0.0), &nvf(&format!("n{i}"), 1.0), AP);
    }
    // Control characters never become an observation name.
    t.on_message(s(0.5), &nvf("a\x1b[2J", 1.0), AP);
    // Names already kept still update; mapped names always pass.
    t.on_message(s(1.0), &nvf("n0", 7.0), AP);
    t.on_message(s(1.0), &nvf("lum", 300.0), AP);
    let o = t.observations(s(1.0), vec![]);
    let onboard = o
        .values
        .keys()
        .filter(|k| k.starts_with("onboard."))
        .count();
    assert_eq!(onboard, 4);
    assert_eq!(o.get("onboard.n0"), Some(7.0));
    assert_eq!(o.get("luminosity_lux"), Some(300.0));
    assert_eq!(t.rejected.names_dropped, 997);
}

#[test]
fn positions_off_the_globe_are_refused() {
    let mut t = Telemetry::new(TelemetryConfig::default());
    let pos = |lat, lon| {
        Msg::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            lat,
            lon,
            ..GLOBAL_POSITION_INT_DATA::DEFAULT
        })
    };
    t.on_message(s(0.0), &pos(473_977_420, 85_455_940), AP);
    t.on_message(s(0.1), &pos(950_000_000, 85_455_940), AP);
    t.on_message(s(0.2), &pos(473_977_420, -1_813_000_000), AP);
    assert_eq!(t.position.unwrap().lat_e7, 473_977_420);
    assert_eq!(t.get("lon_deg"), Some(85_455_940.0 * 1e-7));
    assert_eq!(t.rejected.out_of_range, 2);
}

#[test]
fn displace_stays_on_the_globe() {
    let (lat, lon) = displace((0, 1_799_999_000), 0.0, 500.0);
    assert!(
        on_globe(lat, lon) && lon < -1_799_000_000,
        "wrapped east: {lon}"
    );
    let (lat, _) = displace((899_999_000, 0), 5_000.0, 0.0);
    assert_eq!(lat, 900_000_000);
}

#[test]
fn trust_settings_are_checked() {
    assert_eq!(TelemetryConfig::default().check_trust(), Ok(()));
    let bad = |f: &dyn Fn(&mut TelemetryConfig)| {
        let mut c = TelemetryConfig::default();
        f(&mut c);
        c.check_trust().unwrap_err().0
    };
    assert_eq!(
        bad(&|c| {
            c.ranges.insert("zone_north_m".into(), [5.0, -5.0]);
        }),
        "telemetry.ranges.zone_north_m"
    );
    assert_eq!(
        bad(&|c| {
            c.ranges.insert("lum".into(), [0.0, f64::NAN]);
        }),
        "telemetry.ranges.lum"
    );
    assert_eq!(
        bad(&|c| c.max_onboard_names = 1_000_000),
        "telemetry.max_onboard_names"
    );
    assert_eq!(
        bad(&|c| c.monitors.sources.push([0, 100])),
        "telemetry.monitors.sources"
    );
    assert_eq!(
        bad(&|c| c.monitors.autopilot_system_components.push(0)),
        "telemetry.monitors.autopilot_system_components"
    );
}

/// The shipped link.toml names the camera component and the landing-zone ranges; a broken
/// range stops loading with file, entry and reason.
#[test]
fn link_params_carry_and_check_the_trust_settings() {
    use crate::actions::LinkParams;
    let shipped = crate::test_support::default_params_dir().join("link.toml");
    let lp = crate::test_support::disk(LinkParams::load)(&shipped).unwrap();
    let t = &lp.telemetry;
    assert_eq!(t.monitors.autopilot_system_components, vec![100]);
    assert_eq!(t.ranges.get("zone_east_m"), Some(&[-2000.0, 2000.0]));
    assert!(t.max_onboard_names > 0);
    let text = std::fs::read_to_string(&shipped).unwrap().replace(
        "zone_north_m = [-2000.0, 2000.0]",
        "zone_north_m = [2000.0, -2000.0]",
    );
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("link.toml");
    std::fs::write(&bad, text).unwrap();
    let e = crate::test_support::disk(LinkParams::load)(&bad).unwrap_err();
    assert_eq!(e.entry, "telemetry.ranges.zone_north_m", "{e}");
    assert!(
        e.file.ends_with("link.toml") && e.reason.contains("min <= max"),
        "{e}"
    );
}

/// A range whose key one side renamed (the observation in `[telemetry.onboard]`, or the range's
/// own key) guards nothing: the load refuses it, naming the range (issue 39 item 1).
#[test]
fn a_range_naming_no_onboard_observation_is_refused() {
    use crate::actions::LinkParams;
    let shipped = crate::test_support::default_params_dir().join("link.toml");
    let text = std::fs::read_to_string(&shipped).unwrap();
    for (from, to) in [
        // the mapping renamed, the range not
        ("zone_n = \"zone_north_m\"", "zone_n = \"zone_n_m\""),
        // the range renamed, the mapping not
        ("zone_north_m = [-2000.0", "zone_n_m = [-2000.0"),
    ] {
        assert!(text.contains(from), "{from}");
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("link.toml");
        std::fs::write(&bad, text.replacen(from, to, 1)).unwrap();
        let e = crate::test_support::disk(LinkParams::load)(&bad).unwrap_err();
        assert!(e.entry.starts_with("telemetry.ranges.zone_"), "{e}");
        assert!(e.reason.contains("would guard nothing"), "{e}");
    }
    // An unmapped NAMED_VALUE_FLOAT is written as `onboard.NAME`, and a range may guard it.
    let mut c = TelemetryConfig::default();
    c.ranges.insert("onboard.rpm".into(), [0.0, 1.0e5]);
    assert_eq!(c.check_trust(), Ok(()));
}

#[test]
fn monitor_sources_follow_the_allow_list() {
    let m = MonitorSources {
        autopilot_system_components: vec![100],
        sources: vec![[42, 7]],
    };
    let ap = Some((1, 1));
    assert!(m.allows(1, 1, ap), "the autopilot itself");
    assert!(m.allows(1, 100, ap), "camera of the autopilot's system");
    assert!(!m.allows(1, 101, ap));
    assert!(!m.allows(99, 100, ap), "same component id, another system");
    assert!(m.allows(42, 7, ap), "named pair");
    assert!(
        !m.allows(1, 100, None),
        "no autopilot chosen yet: its system is unknown"
    );
    assert!(m.allows(42, 7, None));
}

#[test]
fn displace_and_offset_are_inverse() {
    let home = (473_977_420, 85_455_940);
    let p = displace(home, 120.0, -45.0);
    let (n, e) = offset_m(home, p);
    assert!(
        (n - 120.0).abs() < 0.02 && (e + 45.0).abs() < 0.02,
        "{n} {e}"
    );
}
