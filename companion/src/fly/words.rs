//! What the fly shell tells the ground station, in a pilot's words: what the vehicle will do and
//! why (`Battery 7%: returning home`, `Search time over: landing here`, `Vibration high:
//! tracking with V3`), and when the guarantee cannot meet the goals (`Cannot meet goals: not
//! enough energy`). No text repeats a number the ground station already plots (the margins, the
//! spendable energy, P_battery: docs/mavlink.md, "Values a ground station plots"): the text says
//! what changed and why, the plot says how much. Sans IO: every text is built from the decision record's typed fields (the
//! action flown, the proposal that chose it and the probabilities it read, observations,
//! evidence, the guarantee's margins and failed resources, the mission's end), never by reading
//! its sentences back. docs/mavlink.md, "Words to the ground station".

use companion_core::action_role::ActionRole;
use companion_core::named_slots::{Label, NamedSlots};
use companion_core::record::{DecisionRecord, Event, GuaranteeRecord};
use companion_link::mission_state::MissionEnd;

/// What the vehicle does, as told to the ground station: the motion flown (a primitive vehicle
/// action, None for none) and the tracking version kept (`v3`), if any.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Behaviour {
    /// The vehicle action flown (its id, as the record names it).
    pub motion: Option<String>,
    /// What that action does (params/actions.toml `role`): the words follow the role, so a
    /// renamed action is told the same.
    pub motion_role: Option<ActionRole>,
    pub tracking: Option<String>,
}

/// Below this, the `P_battery` a proposal read counts as the battery being its reason
/// (P_battery is the health model's belief that the battery lasts the mission).
const P_BATTERY_LOW: f64 = 0.5;

/// The STATUSTEXT for `now`: "Reason: doing", or "Doing" when the record holds no reason.
/// `was` is what was told before (to tell what changed), `evidence_was` the evidence of that
/// cycle, `end` why the mission script ended the mission (when it did).
pub fn behaviour_text(
    now: &Behaviour,
    was: &Behaviour,
    rec: &DecisionRecord,
    evidence_was: &NamedSlots<Label>,
    end: Option<&MissionEnd>,
) -> String {
    let doing = doing(now, rec);
    match reason(now, was, rec, evidence_was, end) {
        Some(why) => format!("{}: {doing}", capitalised(&why)),
        None => capitalised(&doing),
    }
}

/// What the vehicle will do, in words.
fn doing(b: &Behaviour, rec: &DecisionRecord) -> String {
    let zone = rec.observations.get("zone_found").is_some_and(|v| *v > 0.5);
    let motion = b.motion.as_deref().map(|m| match b.motion_role {
        Some(ActionRole::TakeOff) => "taking off".to_string(),
        Some(ActionRole::FollowRoute) => "flying the route".to_string(),
        Some(ActionRole::AvoidObstacle) => "avoiding the obstacle".to_string(),
        Some(ActionRole::Land) if zone => "landing at the found zone".to_string(),
        Some(ActionRole::Land) => "landing here".to_string(),
        Some(ActionRole::ReplanAndLand) if zone => "landing at the emergency zone".to_string(),
        Some(ActionRole::ReplanAndLand) => "emergency landing here".to_string(),
        Some(ActionRole::ReturnToBase) => "returning home".to_string(),
        _ => m.replace('_', " "),
    });
    let tracking = b
        .tracking
        .as_deref()
        .map(|v| format!("tracking with {}", v.to_uppercase()));
    match (motion, tracking) {
        (Some(m), Some(t)) => format!("{m}, {t}"),
        (Some(m), None) => m,
        (None, Some(t)) => t,
        (None, None) => "holding position".to_string(),
    }
}

/// Why, from the record's typed data, most telling first; None when it holds no reason.
fn reason(
    now: &Behaviour,
    was: &Behaviour,
    rec: &DecisionRecord,
    evidence_was: &NamedSlots<Label>,
    end: Option<&MissionEnd>,
) -> Option<String> {
    let motion = now.motion.as_deref();
    let motion_changed = now.motion != was.motion;
    if motion_changed && let Some(m) = motion {
        // The mission script's own end: the shell flies the landing (shell_actions).
        if rec.shell_actions.iter().any(|a| a == m)
            && let Some(end) = end
        {
            return Some(
                match end {
                    MissionEnd::SearchTimeLimit(_) => "search time over",
                    MissionEnd::TrackingTimeLimit(_) => "tracking time over",
                }
                .to_string(),
            );
        }
        if ends_flight(now)
            && let Some(why) = ending_reason(m, rec)
        {
            return Some(why);
        }
        if now.motion_role == Some(ActionRole::AvoidObstacle)
            && let Some(d) = rec.observations.get("obstacle_m")
        {
            return Some(format!("obstacle {d:.0} m"));
        }
    }
    // What happened this cycle, as typed events.
    for e in &rec.events {
        let why = match e {
            Event::TargetDetected => "target found",
            Event::TargetLost => "target lost",
            Event::ObstacleCleared if motion_changed => "obstacle cleared",
            _ => continue,
        };
        return Some(why.to_string());
    }
    if now.tracking != was.tracking && now.tracking.is_some() {
        if let Some(r) = &rec.resources
            && !r.failed_tiles.is_empty()
        {
            return Some("FPGA tile failed".to_string());
        }
        // The first piece of evidence that changed since the last text.
        if let Some((node, state)) = rec
            .evidence
            .iter()
            .find(|(n, s)| evidence_was.get(n).is_some_and(|w| w != *s))
        {
            return Some(format!("{} {state}", evidence_words(node)));
        }
    }
    if motion_changed
        && let Some(m) = motion
        && ends_flight(now)
        && let Some(p) = proposer(rec, m)
    {
        // No evidence stood out: name the model that chose it.
        return Some(format!("{} model", p.mdp));
    }
    None
}

/// The motion ends the flight (land, replan and land, return to base): its reason is what a
/// pilot must hear.
fn ends_flight(b: &Behaviour) -> bool {
    b.motion_role.is_some_and(ActionRole::ends_flight)
}

/// Why a flight-ending motion: a low battery the proposing model read, then the guarantee's
/// energy or time shortfall, then a failed resource.
fn ending_reason(motion: &str, rec: &DecisionRecord) -> Option<String> {
    if let Some(p) = proposer(rec, motion)
        && p.inputs
            .get("P_battery")
            .is_some_and(|v| *v < P_BATTERY_LOW)
    {
        return Some(match rec.observations.get("battery_pct") {
            Some(pct) => format!("battery {pct:.0}%"),
            None => "battery low".to_string(),
        });
    }
    let g = rec.guarantee.as_ref()?;
    shortfalls(g).into_iter().next()
}

/// The proposal whose actions hold `motion` (the first, as the record lists them).
fn proposer<'a>(
    rec: &'a DecisionRecord,
    motion: &str,
) -> Option<&'a companion_core::record::MdpProposal> {
    rec.proposals
        .iter()
        .find(|p| p.actions.iter().any(|a| a == motion))
}

/// `A_vibration` -> `vibration`, `S_battery` -> `battery`, `A_target_speed` -> `target speed`.
fn evidence_words(node: &str) -> String {
    node.strip_prefix("A_")
        .or_else(|| node.strip_prefix("S_"))
        .unwrap_or(node)
        .replace('_', " ")
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// What the guarantee is short of, in words, most pressing first: each goal with a negative
/// margin (`not enough energy`, `not enough time`: the amounts are plotted, `e_margin` and
/// `t_margin`), then each failed resource.
fn shortfalls(g: &GuaranteeRecord) -> Vec<String> {
    let mut out = Vec::new();
    for (goal, margin) in &g.margins {
        if *margin >= 0.0 || !margin.is_finite() {
            continue;
        }
        out.push(match goal.as_str() {
            "energy_j" => "not enough energy".to_string(),
            "duration_s" => "not enough time".to_string(),
            other => format!("not enough {}", other.replace('_', " ")),
        });
    }
    let mut failed: Vec<String> = g
        .failed_resources
        .iter()
        .map(|r| {
            if r.starts_with("tile_slot:") {
                "FPGA tile failed".to_string()
            } else {
                format!("{r} failed")
            }
        })
        .collect();
    let mut seen = std::collections::BTreeSet::new();
    failed.retain(|f| seen.insert(f.clone()));
    out.extend(failed);
    out
}

/// What the guarantee's verdict is about, to say it once per change: the goals short and the
/// failed resources (their names, not their changing amounts); None when it can meet the goals.
pub fn guarantee_key(g: &GuaranteeRecord) -> Option<Vec<String>> {
    if !g.infeasible {
        return None;
    }
    let mut key: Vec<String> = g
        .margins
        .iter()
        .filter(|(_, m)| **m < 0.0)
        .map(|(goal, _)| goal.clone())
        .collect();
    key.extend(g.failed_resources.iter().cloned());
    Some(key)
}

/// The STATUSTEXT when the guarantee cannot meet the goals.
pub fn guarantee_text(g: &GuaranteeRecord) -> String {
    let short = shortfalls(g);
    if short.is_empty() {
        "Cannot meet the mission goals".to_string()
    } else {
        format!("Cannot meet goals: {}", short.join(", "))
    }
}

/// The STATUSTEXT for this cycle's re-allocation for a margin or a failure: why (what the
/// guarantee is short of, not by how much), then the plan in force, `Not enough energy: plan
/// changed, search S1, tracking V2`. None without one, and for the plan following the versions
/// the models run (told as the version switch it follows: one text per change).
pub fn reallocation_text(g: &GuaranteeRecord) -> Option<String> {
    let re = g.reallocation.as_ref().filter(|r| !r.trigger.is_follow())?;
    let head = shortfalls(g)
        .first()
        .map_or("Plan changed".to_string(), |why| {
            format!("{}: plan changed", capitalised(why))
        });
    let plan: Vec<String> = re
        .allocation
        .iter()
        .map(|(activity, ia)| format!("{} {}", activity.replace('_', " "), ia.replace('_', " ")))
        .collect();
    Some(if plan.is_empty() {
        head
    } else {
        format!("{head}, {}", plan.join(", "))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use companion_core::record::{MdpProposal, ResourcesRecord};
    use std::collections::BTreeMap;

    fn b(motion: Option<&str>, tracking: Option<&str>) -> Behaviour {
        let roles = companion_core::action_role::ActionRoles::undeclared();
        Behaviour {
            motion: motion.map(str::to_string),
            motion_role: motion.and_then(|m| roles.role_of(m)),
            tracking: tracking.map(str::to_string),
        }
    }

    fn proposal(mdp: &str, actions: &[&str], inputs: &[(&str, f64)]) -> MdpProposal {
        MdpProposal {
            mdp: mdp.into(),
            actions: actions.iter().map(|a| a.to_string()).collect(),
            inputs: inputs.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Default::default()
        }
    }

    fn guarantee(margins: &[(&str, f64)], failed: &[&str]) -> GuaranteeRecord {
        GuaranteeRecord {
            margins: margins.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            failed_resources: failed.iter().map(|r| r.to_string()).collect(),
            infeasible: true,
            infeasible_reason: Some("negative energy_j margin -4200.0: no allocation".into()),
            ..Default::default()
        }
    }

    fn obs(vals: &[(&str, f64)]) -> companion_core::observations::ObservationValues {
        vals.iter().map(|(k, v)| (k.to_string(), *v)).collect()
    }

    const NONE: Option<&MissionEnd> = None;

    #[test]
    fn a_low_battery_return_says_the_battery_and_what_the_vehicle_does() {
        let rec = DecisionRecord {
            actions: ["return_to_base"].into_iter().collect(),
            proposals: vec![
                proposal("navigation", &["follow_trajectory"], &[("P_battery", 0.02)]),
                proposal("landing", &["return_to_base"], &[("P_battery", 0.02)]),
            ],
            observations: obs(&[("battery_pct", 7.2)]),
            guarantee: Some(guarantee(&[("energy_j", -4200.0)], &[])),
            ..Default::default()
        };
        let was = b(Some("follow_trajectory"), None);
        let now = b(Some("return_to_base"), None);
        let text = behaviour_text(&now, &was, &rec, &NamedSlots::default(), NONE);
        assert_eq!(text, "Battery 7%: returning home");
    }

    #[test]
    fn an_energy_shortfall_return_says_energy_is_missing_not_the_plotted_amount() {
        let rec = DecisionRecord {
            actions: ["return_to_base"].into_iter().collect(),
            proposals: vec![proposal(
                "landing",
                &["return_to_base"],
                &[("P_battery", 0.9)],
            )],
            observations: obs(&[("battery_pct", 64.0)]),
            guarantee: Some(guarantee(
                &[("duration_s", 10.0), ("energy_j", -4210.0)],
                &[],
            )),
            ..Default::default()
        };
        let text = behaviour_text(
            &b(Some("return_to_base"), None),
            &b(Some("follow_trajectory"), None),
            &rec,
            &NamedSlots::default(),
            NONE,
        );
        assert_eq!(text, "Not enough energy: returning home");
    }

    #[test]
    fn the_mission_scripts_landing_says_why_and_where() {
        let rec = DecisionRecord {
            shell_actions: ["land"].into_iter().collect(),
            events: vec![Event::ShellLand(
                MissionEnd::SearchTimeLimit(120.0).to_string(),
            )],
            observations: obs(&[("zone_found", 0.0)]),
            ..Default::default()
        };
        let end = MissionEnd::SearchTimeLimit(120.0);
        let text = behaviour_text(
            &b(Some("land"), None),
            &b(Some("follow_trajectory"), None),
            &rec,
            &NamedSlots::default(),
            Some(&end),
        );
        assert_eq!(text, "Search time over: landing here");
    }

    #[test]
    fn a_tracking_version_change_names_the_evidence_that_changed() {
        let was_ev: NamedSlots<Label> = [("A_vibration", "low"), ("A_wind", "calm")]
            .iter()
            .map(|(k, v)| (k.to_string(), Label::from(*v)))
            .collect();
        let mut now_ev = was_ev.clone();
        now_ev.insert("A_vibration".into(), "high".into());
        let rec = DecisionRecord {
            actions: ["track_v3"].into_iter().collect(),
            evidence: now_ev,
            ..Default::default()
        };
        let text = behaviour_text(
            &b(None, Some("v3")),
            &b(None, Some("v0")),
            &rec,
            &was_ev,
            NONE,
        );
        assert_eq!(text, "Vibration high: tracking with V3");
        let tile = DecisionRecord {
            resources: Some(ResourcesRecord {
                failed_tiles: vec![2],
                ..Default::default()
            }),
            ..rec
        };
        assert_eq!(
            behaviour_text(
                &b(None, Some("v5")),
                &b(None, Some("v3")),
                &tile,
                &was_ev,
                NONE
            ),
            "FPGA tile failed: tracking with V5"
        );
    }

    #[test]
    fn an_obstacle_sidestep_says_how_near_and_a_found_target_says_so() {
        let rec = DecisionRecord {
            observations: obs(&[("obstacle_m", 4.4)]),
            events: vec![Event::ObstacleDetected],
            ..Default::default()
        };
        assert_eq!(
            behaviour_text(
                &b(Some("avoid_obstacle"), None),
                &b(Some("follow_trajectory"), None),
                &rec,
                &NamedSlots::default(),
                NONE
            ),
            "Obstacle 4 m: avoiding the obstacle"
        );
        let found = DecisionRecord {
            events: vec![Event::TargetDetected],
            ..Default::default()
        };
        assert_eq!(
            behaviour_text(
                &b(None, Some("v0")),
                &b(Some("follow_trajectory"), None),
                &found,
                &NamedSlots::default(),
                NONE
            ),
            "Target found: tracking with V0"
        );
    }

    #[test]
    fn without_a_reason_the_text_says_only_what_the_vehicle_does() {
        let rec = DecisionRecord::default();
        assert_eq!(
            behaviour_text(
                &b(Some("take_off"), None),
                &b(None, None),
                &rec,
                &NamedSlots::default(),
                NONE
            ),
            "Taking off"
        );
        let by_model = DecisionRecord {
            proposals: vec![proposal(
                "tracking",
                &["return_to_base"],
                &[("P_battery", 0.9)],
            )],
            ..Default::default()
        };
        assert_eq!(
            behaviour_text(
                &b(Some("return_to_base"), None),
                &b(Some("follow_trajectory"), None),
                &by_model,
                &NamedSlots::default(),
                NONE
            ),
            "Tracking model: returning home"
        );
    }

    #[test]
    fn the_guarantee_text_names_each_shortfall_and_its_key_ignores_the_amounts() {
        let g = guarantee(
            &[("duration_s", -35.2), ("energy_j", -4210.0)],
            &["lidar", "tile_slot:1", "tile_slot:2"],
        );
        assert_eq!(
            guarantee_text(&g),
            "Cannot meet goals: not enough time, not enough energy, lidar failed, FPGA tile failed"
        );
        let mut later = g.clone();
        later.margins.insert("energy_j".into(), -5000.0);
        assert_eq!(guarantee_key(&g), guarantee_key(&later));
        later.margins.insert("duration_s".into(), 3.0);
        assert_ne!(guarantee_key(&g), guarantee_key(&later));
        later.infeasible = false;
        assert_eq!(guarantee_key(&later), None);
    }

    /// The numbers in `text` (`4.2`, `35`, `12`).
    /// The numbers a text shows: its words that are numbers (`7%`, `4.2`); the digit of a name
    /// (`V3`, `S1`, an implementation alternative) is not a value.
    fn numbers(text: &str) -> Vec<f64> {
        text.split(|c: char| c.is_whitespace() || ",;:()".contains(c))
            .filter_map(|t| t.trim_matches(|c| c == '.' || c == '%').parse().ok())
            .collect()
    }

    #[test]
    fn no_decision_text_repeats_a_plotted_value() {
        use companion_link::ground_values::{GroundValue, GroundValues, GroundValuesParams};
        let params = GroundValuesParams::default();
        let plotted = GroundValues::new(&params, std::iter::empty());
        let mut g = guarantee(&[("duration_s", -35.2), ("energy_j", -4210.0)], &["lidar"]);
        g.reallocation = Some(companion_core::record::Reallocation {
            trigger: companion_core::record::ReallocationTrigger::Margin,
            reason: "negative energy_j margin -4210.0".into(),
            allocation: vec![
                ("search".into(), "S1".into()),
                ("tracking".into(), "V2".into()),
            ],
            margins_after: BTreeMap::from([("energy_j".to_string(), 98.9)]),
        });
        g.pack = Some(companion_core::record::PackRecord {
            spendable_j: Some(98_900.0),
            ..Default::default()
        });
        let rec = DecisionRecord {
            cycle: 417,
            actions: ["return_to_base"].into_iter().collect(),
            proposals: vec![proposal(
                "landing",
                &["return_to_base"],
                &[("P_battery", 0.9)],
            )],
            probabilities: [("P_battery".to_string(), 0.9)].into_iter().collect(),
            observations: obs(&[("battery_pct", 64.0)]),
            guarantee: Some(g.clone()),
            ..Default::default()
        };
        let texts = [
            behaviour_text(
                &b(Some("return_to_base"), None),
                &b(Some("follow_trajectory"), None),
                &rec,
                &NamedSlots::default(),
                NONE,
            ),
            guarantee_text(&g),
            reallocation_text(&g).expect("a re-allocation for a margin is told"),
            // The start refusal without the guarantee's verdict. With it, the refusal says the
            // planned and the available energy (issue 36 item 4), and the available energy is
            // the plotted `e_spend` at that moment: kept, as issue 36 asks.
            companion_core::launch::LaunchRefusal::BatteryLow {
                pct: 64.0,
                short_j: 4210.0,
                reason: String::new(),
                verdict: None,
            }
            .pilot_words(),
        ];
        let values: Vec<f64> = (plotted.values(&rec).into_iter())
            .filter(|v| !matches!(v, GroundValue::Int("cycle", _)))
            .map(|v| match v {
                GroundValue::Float(_, x) => f64::from(x),
                GroundValue::Int(_, x) => f64::from(x),
            })
            .collect();
        assert!(values.len() >= 3, "{values:?}");
        for text in &texts {
            for n in numbers(text) {
                for v in &values {
                    // As the value, in thousands (kJ) or as a percentage, rounded as a text would.
                    for shown in [v.abs(), v.abs() / 1000.0, v.abs() * 100.0] {
                        assert!((n - shown).abs() > 0.5, "`{text}` repeats the plotted {v}");
                    }
                }
            }
        }
    }

    /// A re-allocation for a margin or a failure is told once, in words: why, then the plan
    /// in force; the plan following the running versions is not (the version switch says it).
    #[test]
    fn a_reallocation_says_why_and_the_plan_in_force() {
        use companion_core::record::{Reallocation, ReallocationTrigger};
        let mut g = guarantee(&[("energy_j", -4210.0)], &[]);
        g.infeasible = false;
        let re = |trigger| Reallocation {
            trigger,
            allocation: vec![
                ("search_area".into(), "gps_vision S1".into()),
                ("tracking".into(), "V2".into()),
            ],
            ..Default::default()
        };
        assert_eq!(reallocation_text(&g), None, "no re-allocation this cycle");
        g.reallocation = Some(re(ReallocationTrigger::Margin));
        assert_eq!(
            reallocation_text(&g).as_deref(),
            Some("Not enough energy: plan changed, search area gps vision S1, tracking V2")
        );
        let mut failed = guarantee(&[], &["tile_slot:2"]);
        failed.reallocation = Some(re(ReallocationTrigger::Failure));
        assert_eq!(
            reallocation_text(&failed).as_deref(),
            Some("FPGA tile failed: plan changed, search area gps vision S1, tracking V2")
        );
        for follow in [
            ReallocationTrigger::FollowsVersions,
            ReallocationTrigger::FollowsPlacement,
        ] {
            g.reallocation = Some(re(follow));
            assert_eq!(reallocation_text(&g), None, "{follow:?}");
        }
    }
}
