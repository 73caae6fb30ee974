//! A synthetic but realistic decision-record sequence shaped like the BFM paper's Table 4
//! (scenario 1, vibrations, safety policy): base -> wp1 -> wpi -> wpf -> target -> v3 (V3 degraded
//! to V1 on insufficient resources) -> landing. For tests, the log stress helper and demos of the
//! review report while the real simulation is elsewhere; it is no model of anything.

use companion_core::record::*;
use std::collections::BTreeMap;

/// Phase of cycle `i` of an `n`-cycle mission, by fraction of the run.
fn phase(i: u64, n: u64) -> &'static str {
    let f = i as f64 / n.max(1) as f64;
    if i == 0 {
        "base"
    } else if f < 0.08 {
        "wp1"
    } else if f < 0.16 {
        "wpi"
    } else if f < 0.22 {
        "wpf"
    } else if f < 0.26 {
        "target"
    } else if f < 0.93 {
        "v3"
    } else {
        "landing"
    }
}

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

fn placement(
    app: &str,
    version: &str,
    imp: &str,
    support: &str,
    tiles: &[u8],
    cpu: f64,
    ms: f64,
) -> PlacementRecord {
    PlacementRecord {
        app: app.into(),
        version: version.into(),
        implementation: imp.into(),
        support: support.into(),
        tiles: tiles.to_vec(),
        cpu_share: cpu,
        ms_per_frame: ms,
    }
}

/// Record `i` of an `n`-cycle synthetic mission (`n` >= 20 for every phase to appear), one
/// cycle per second.
pub fn record(i: u64, n: u64) -> DecisionRecord {
    let n = n.max(20);
    let state = phase(i, n);
    let f = i as f64 / n as f64;
    // Tracking sub-phases as in Table 4: obstacle (avoid), then insufficient resources (V3 -> V1).
    let obstacle = (0.40..0.46).contains(&f);
    let degraded = f >= 0.60 && state == "v3";
    let first_degraded = degraded && ((i - 1) as f64 / n as f64) < 0.60;
    let mut events = Vec::new();
    let mut conflicts = Vec::new();
    let mut res_degraded = Vec::new();
    let (actions, summary, placements): (Vec<String>, &str, Vec<PlacementRecord>) = match state {
        "base" => (s(&["take_off"]), "-", vec![]),
        "wp1" => (
            s(&["follow_trajectory", "detect_obstacles_lidar"]),
            "5 ms",
            vec![placement(
                "obstacle_detection",
                "lidar",
                "S",
                "SW",
                &[],
                0.12,
                5.0,
            )],
        ),
        "wpi" => (
            s(&[
                "follow_trajectory",
                "detect_obstacles_lidar",
                "search_zone_t",
            ]),
            "5 + 394 ms",
            vec![
                placement("obstacle_detection", "lidar", "S", "SW", &[], 0.12, 5.0),
                placement("landing_search", "zone_t", "M", "SW-HW", &[0], 0.30, 394.0),
            ],
        ),
        "wpf" => (
            s(&[
                "follow_trajectory",
                "detect_obstacles_lidar",
                "search_zone_t",
                "detect_target",
            ]),
            "5 + 394 + 10 ms",
            vec![
                placement("obstacle_detection", "lidar", "S", "SW", &[], 0.12, 5.0),
                placement("landing_search", "zone_t", "M", "SW-HW", &[0], 0.30, 394.0),
                placement("tracking", "V0", "F", "HW", &[1], 0.10, 10.0),
            ],
        ),
        "landing" => (s(&["land"]), "-", vec![]),
        _ if obstacle => {
            conflicts.push(Conflict {
                kept: ["avoid_obstacle"].into_iter().collect(),
                dropped: ["follow_trajectory"].into_iter().collect(),
                rule: "safety: avoid_obstacle > follow_trajectory".into(),
            });
            (
                s(&["track_v3", "avoid_obstacle", "search_emergency_zone"]),
                "1 + 255 ms",
                vec![
                    placement(
                        "obstacle_avoidance",
                        "right_turn",
                        "S",
                        "SW",
                        &[],
                        0.05,
                        1.0,
                    ),
                    placement(
                        "landing_search",
                        "emergency",
                        "M",
                        "SW-HW",
                        &[0],
                        0.25,
                        255.0,
                    ),
                ],
            )
        }
        _ if degraded => {
            if first_degraded {
                res_degraded.push(Degraded {
                    app: "tracking".into(),
                    from: "V3".into(),
                    to: "V1".into(),
                    reason: "insufficient resources (cpu 1.12 > 1.00)".into(),
                });
            }
            (
                s(&[
                    "track_v1",
                    "detect_obstacles_lidar",
                    "search_emergency_zone",
                ]),
                "10 + 5 + 255 ms",
                vec![
                    placement("tracking", "V1", "S", "SW", &[], 0.35, 10.0),
                    placement("obstacle_detection", "lidar", "S", "SW", &[], 0.12, 5.0),
                    placement(
                        "landing_search",
                        "emergency",
                        "M",
                        "SW-HW",
                        &[0],
                        0.25,
                        255.0,
                    ),
                ],
            )
        }
        _ => (
            s(&[
                if state == "target" {
                    "track_v0"
                } else {
                    "track_v3"
                },
                "detect_obstacles_lidar",
                "search_zone_t",
            ]),
            "10 + 5 + 394 ms",
            vec![
                placement(
                    "tracking",
                    if state == "target" { "V0" } else { "V3" },
                    "F",
                    "HW",
                    &[1, 2],
                    0.20,
                    10.0,
                ),
                placement("obstacle_detection", "lidar", "S", "SW", &[], 0.12, 5.0),
                placement("landing_search", "zone_t", "M", "SW-HW", &[0], 0.30, 394.0),
            ],
        ),
    };
    let prev_state = if i == 0 { "" } else { phase(i - 1, n) };
    if state == "wpf" && prev_state == "wpi" {
        events.push(Event::TargetDetected);
    }
    if obstacle && ((i - 1) as f64 / n as f64) < 0.40 {
        events.push(Event::ObstacleDetected);
    }
    if first_degraded {
        events.push(Event::Other("insufficient resources to execute V3".into()));
    }
    let tiles_used = placements.iter().flat_map(|p| p.tiles.iter()).count() as u8;
    let cpu_load: f64 = placements.iter().map(|p| p.cpu_share).sum();

    // Named probabilities (section 7.1 values, vibration context), drifting a little.
    let wobble = ((i as f64) * 0.7).sin() * 0.02;
    let mut probabilities = BTreeMap::new();
    for (k, v) in [
        ("P_sys", 0.9),
        ("P_battery", 0.8 - 0.3 * f),
        ("P_obs", if obstacle { 0.5 } else { 0.95 }),
        ("P_SI", 0.6),
        ("P_SF", 0.4),
        ("P_appT", 0.5),
        ("P_detect", 0.8),
        ("P_V3", if degraded { 0.31 } else { 0.96 }),
        ("P_V1", 0.37),
    ] {
        probabilities.insert(k.to_string(), (v + wobble).clamp(0.0, 1.0));
    }

    // PANORAMA margins: predicted totals creep up; an obstacle detour costs energy and time and
    // triggers one re-allocation.
    let detour = if f >= 0.46 {
        4000.0
    } else if obstacle {
        4000.0 * (f - 0.40) / 0.06
    } else {
        0.0
    };
    let energy_pred = 42_000.0 + 60.0 * i as f64 + detour;
    let duration_pred = 700.0 + 0.5 * i as f64 + detour / 40.0;
    let goals = BTreeMap::from([
        ("energy_j".to_string(), 60_000.0),
        ("duration_s".to_string(), 900.0),
    ]);
    let margins = BTreeMap::from([
        ("energy_j".to_string(), 60_000.0 - energy_pred),
        ("duration_s".to_string(), 900.0 - duration_pred),
    ]);
    let reallocation =
        (obstacle && events.iter().any(|e| e == "obstacle detected")).then(|| Reallocation {
            trigger: companion_core::record::ReallocationTrigger::Margin,
            reason: "energy margin fell below 15 % of goal".into(),
            allocation: vec![
                ("track".into(), "tracking/V1".into()),
                ("return".into(), "direct".into()),
            ],
            margins_after: BTreeMap::from([
                ("energy_j".to_string(), 60_000.0 - energy_pred + 1500.0),
                ("duration_s".to_string(), 900.0 - duration_pred + 20.0),
            ]),
        });

    let mut commands = Vec::new();
    let mut link_events = Vec::new();
    let mode = match state {
        "base" => "GUIDED",
        "landing" => "LAND",
        _ => "GUIDED",
    };
    if i == 0 {
        commands.push(CommandRecord {
            action: "take_off".into(),
            command: "MAV_CMD_NAV_TAKEOFF".into(),
            result: CommandOutcome::Accepted,
            attempts: 1,
            latency_ms: Some(120.0),
        });
    }
    if state == "landing" && prev_state != "landing" {
        commands.push(CommandRecord {
            action: "land".into(),
            command: "SET_MODE LAND".into(),
            result: CommandOutcome::Timeout(None),
            attempts: 3,
            latency_ms: None,
        });
        commands.push(CommandRecord {
            action: "land".into(),
            command: "MAV_CMD_NAV_LAND".into(),
            result: CommandOutcome::Accepted,
            attempts: 1,
            latency_ms: Some(85.0),
        });
    }
    if i == n / 2 {
        link_events.push(LinkEvent::Other("heartbeat lost for 1.5 s".into()));
    }
    if i == n / 2 + 1 {
        link_events.push(LinkEvent::Other("heartbeat regained".into()));
    }
    let altitude = match state {
        "base" => 0.0,
        "landing" => {
            let k = i as f64 - (0.93 * n as f64).ceil();
            (20.0 - 4.0 * k).max(0.0)
        }
        _ => (5.0 * i as f64).min(20.0),
    };
    let vehicle = BTreeMap::from([
        ("altitude_m".to_string(), serde_json::json!(altitude)),
        (
            "battery_pct".to_string(),
            serde_json::json!(100.0 - 55.0 * f),
        ),
        ("mode".to_string(), serde_json::json!(mode)),
    ]);
    let observations = BTreeMap::from([
        ("vibration_mps2".to_string(), 3.5 + wobble * 10.0),
        ("battery_pct".to_string(), 100.0 - 55.0 * f),
        ("cpu_load".to_string(), cpu_load),
    ]);
    let tracking_action = actions.iter().find(|a| a.starts_with("track_")).cloned();
    let proposals = vec![
        MdpProposal {
            mdp: "navigation".into(),
            state: state.into(),
            action: actions.first().cloned().unwrap_or_default(),
            actions: actions.iter().collect(),
            value: 10.0 - f,
            iterations: 4,
            ..Default::default()
        },
        MdpProposal {
            mdp: "tracking".into(),
            state: state.into(),
            action: tracking_action.clone().unwrap_or_else(|| "none".into()),
            actions: tracking_action.into_iter().collect(),
            value: 8.0 + f,
            iterations: 5,
            ..Default::default()
        },
    ];
    DecisionRecord {
        cycle: i,
        time_s: i as f64,
        state: state.into(),
        events,
        observations: observations.into_iter().collect(),
        evidence: [("vibration".to_string(), "high".into())]
            .into_iter()
            .collect(),
        absent_evidence: Vec::new(),
        probabilities: probabilities.into_iter().collect(),
        proposals,
        conflicts,
        actions: actions.iter().collect(),
        shell_actions: Default::default(),
        cpt_learned: Vec::new(),
        live_dropped: None,
        resources: Some(ResourcesRecord {
            placements,
            cpu_load,
            tiles_used,
            reconfigurations: u32::from(first_degraded),
            degraded: res_degraded,
            dropped: vec![],
            summary: summary.into(),
            ..Default::default()
        }),
        guarantee: Some(GuaranteeRecord {
            activity: if f < 0.22 {
                0
            } else if f < 0.93 {
                1
            } else {
                2
            },
            activity_name: if f < 0.22 {
                "transit"
            } else if f < 0.93 {
                "track"
            } else {
                "return"
            }
            .into(),
            margins,
            goals,
            drift: BTreeMap::from([
                ("energy_j".to_string(), detour),
                ("duration_s".to_string(), detour / 40.0),
            ]),
            reallocation,
            infeasible: false,
            ..Default::default()
        }),
        commands,
        link_events,
        vehicle: vehicle.into_iter().collect(),
        utc_us: None,
        decide_ms: None,
    }
}

/// The whole `n`-cycle mission.
pub fn mission(n: u64) -> Vec<DecisionRecord> {
    (0..n).map(|i| record(i, n)).collect()
}
