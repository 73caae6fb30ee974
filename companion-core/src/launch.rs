//! The launch verdict: do the models agree to a start? PANORAMA's pre-launch check (the goals can
//! be met: the guarantee is not `infeasible` and no margin is negative) and the MDPs' own choice
//! at the on-ground state (the arbitrated actions hold `take_off`, not `stay_on_ground`), read
//! from the latest decision record. Pure: the shell asks it before it arms and, on a refusal,
//! says [`LaunchRefusal::pilot_text`] to the ground station and records
//! [`LaunchRefusal::description`] (docs/guarantee.md, "The launch verdict").

use crate::decision::Model;
use crate::guarantee::{DURATION, ENERGY};
use crate::mission::{ActionRole, RouteRole};
use crate::record::{DecisionRecord, EnergySource, Verdict};
use serde::Serialize;

/// The named probability the verdict quotes when a model stays (the battery belief).
const P_BATTERY: &str = "P_battery";
/// MAVLink STATUSTEXT holds at most this many characters.
pub const PILOT_TEXT_MAX: usize = 50;

/// Why the models refuse a start. Numbers are what the record held.
#[derive(Debug, Clone, PartialEq, Serialize, thiserror::Error)]
#[serde(tag = "refusal", rename_all = "snake_case")]
pub enum LaunchRefusal {
    /// The latest record is not at the on-ground state (or there is none yet).
    #[error(
        "the latest decision record is in state `{state}`, not the on-ground state `{on_ground}`: no launch decision to read"
    )]
    NotOnGround {
        /// The record's mission state (empty: no record yet).
        state: String,
        /// The mission's on-ground state (params/mission.toml `route_states.on_ground`).
        on_ground: String,
    },
    /// The mission to fly is not planned yet, or could not be (`fly --mission autopilot` before
    /// the autopilot's mission is downloaded, or when an item of it cannot be planned).
    #[error("the mission is not planned: {reason}")]
    MissionNotPlanned {
        /// Why: not downloaded yet, or the refusal naming the item.
        reason: String,
    },
    /// No performance guarantee runs: the mission's goals cannot be met even by the pre-flight
    /// allocation with a full pack.
    #[error(
        "no performance guarantee: the pre-flight allocation found no way to meet the mission's goals (see `companion check`)"
    )]
    NoGuarantee,
    /// The energy the battery holds, by the autopilot's remaining percentage, is short of what
    /// the mission needs.
    #[error(
        "the battery reports {pct:.0} %: the energy it holds is {short_j:.0} J short of the mission's estimate plus the reserve (guarantee energy margin -{short_j:.0} J){reason}{}",
        verdict_words(verdict.as_deref())
    )]
    BatteryLow {
        /// Remaining battery percentage the autopilot reported.
        pct: f64,
        /// How much energy is missing (J): minus the energy margin.
        short_j: f64,
        /// The guarantee's reason, when it gave one (`: ...`), else empty.
        #[serde(skip_serializing_if = "String::is_empty")]
        reason: String,
        /// Planned against available and what would fit, when the guarantee judged it.
        #[serde(skip_serializing_if = "Option::is_none")]
        verdict: Option<Box<Verdict>>,
    },
    /// The energy goal cannot be met (the energy used came from the autopilot's consumed energy,
    /// or no percentage was reported).
    #[error(
        "energy short by {short_j:.0} J: the guarantee's energy margin is -{short_j:.0} J (energy used from: {energy_from}){reason}{}",
        verdict_words(verdict.as_deref())
    )]
    EnergyShort {
        /// How much energy is missing (J): minus the energy margin.
        short_j: f64,
        /// Where the energy used came from (`energy_consumed`, `estimate`).
        energy_from: String,
        /// The guarantee's reason, when it gave one (`: ...`), else empty.
        #[serde(skip_serializing_if = "String::is_empty")]
        reason: String,
        /// Planned against available and what would fit, when the guarantee judged it.
        #[serde(skip_serializing_if = "Option::is_none")]
        verdict: Option<Box<Verdict>>,
    },
    /// The mission does not fit its time limit.
    #[error(
        "mission time short by {short_s:.0} s: the guarantee's duration margin is -{short_s:.0} s{reason}{}",
        verdict_words(verdict.as_deref())
    )]
    DurationShort {
        /// How much time is missing (s): minus the duration margin.
        short_s: f64,
        /// The guarantee's reason, when it gave one (`: ...`), else empty.
        #[serde(skip_serializing_if = "String::is_empty")]
        reason: String,
        /// Planned against available and what would fit, when the guarantee judged it.
        #[serde(skip_serializing_if = "Option::is_none")]
        verdict: Option<Box<Verdict>>,
    },
    /// The guarantee found no allocation meeting the goals for another reason (a failed
    /// resource every alternative needs).
    #[error("the guarantee finds no allocation meeting the mission's goals: {reason}")]
    GoalsUnmet {
        /// The guarantee's `infeasible_reason`.
        reason: String,
    },
    /// An MDP proposes to stay on the ground.
    #[error(
        "the {mdp} MDP proposes to stay on the ground (P_battery {p_battery:.3}, P_sys {p_sys:.3})"
    )]
    ModelsStay {
        /// The MDP that chose to stay (`navigation`).
        mdp: String,
        /// The battery belief it read (NaN when it read none).
        p_battery: f64,
        /// The system health it read (NaN when it read none).
        p_sys: f64,
    },
    /// The arbitrated actions hold no take-off (and no MDP stays): nothing proposes to fly.
    #[error("the arbitrated actions ({actions}) hold no take-off")]
    NoTakeOff {
        /// The record's arbitrated actions, `+`-joined.
        actions: String,
    },
}

impl LaunchRefusal {
    /// The refusal in plain words for the ground station: at most [`PILOT_TEXT_MAX`] characters
    /// (one MAVLink STATUSTEXT), e.g. `Start refused: battery 12%, not enough energy`. By how
    /// much is not said: the margins are plotted (`e_margin`, `t_margin`, docs/mavlink.md), and
    /// a text never repeats a number the ground station plots.
    pub fn pilot_text(&self) -> String {
        let text = match self {
            LaunchRefusal::NotOnGround { .. } => "Start refused: not on the ground".to_string(),
            LaunchRefusal::NoGuarantee => "Start refused: mission cannot be met".to_string(),
            LaunchRefusal::MissionNotPlanned { .. } => "Start refused: mission not planned".into(),
            LaunchRefusal::BatteryLow { pct, .. } => {
                format!("Start refused: battery {pct:.0}%, not enough energy")
            }
            LaunchRefusal::EnergyShort { .. } => "Start refused: not enough energy".to_string(),
            LaunchRefusal::DurationShort { .. } => "Start refused: not enough time".to_string(),
            LaunchRefusal::GoalsUnmet { .. } => "Start refused: goals cannot be met".to_string(),
            LaunchRefusal::ModelsStay { mdp, .. } => format!("Start refused: {mdp} says stay"),
            LaunchRefusal::NoTakeOff { .. } => "Start refused: no model proposes take-off".into(),
        };
        clip(text, PILOT_TEXT_MAX)
    }

    /// The longer description for the record and the journal (the [`std::fmt::Display`] text).
    pub fn description(&self) -> String {
        self.to_string()
    }

    /// The guarantee's verdict behind the refusal, when it judged one.
    pub fn guarantee_verdict(&self) -> Option<&Verdict> {
        match self {
            LaunchRefusal::BatteryLow { verdict, .. }
            | LaunchRefusal::EnergyShort { verdict, .. }
            | LaunchRefusal::DurationShort { verdict, .. } => verdict.as_deref(),
            _ => None,
        }
    }

    /// The lines that tell the refusal, each at most [`PILOT_TEXT_MAX`] characters: with the
    /// guarantee's verdict, `Start refused: plan 143 kJ, have 98.9 kJ at 100%` then what fits
    /// (`Time 1012 s of 1800 s; fits: search 180 s`, [`Verdict::words`]); else
    /// [`LaunchRefusal::pilot_text`] alone.
    pub fn pilot_lines(&self) -> Vec<String> {
        match self.guarantee_verdict() {
            Some(v) => {
                let [plan, fit] = v.words();
                vec![
                    clip(format!("Start refused: {plan}"), PILOT_TEXT_MAX),
                    clip(fit, PILOT_TEXT_MAX),
                ]
            }
            None => vec![self.pilot_text()],
        }
    }

    /// The one STATUSTEXT that tells the refusal (a change of decision is one text, issue 37):
    /// [`LaunchRefusal::pilot_lines`] joined, `Start refused: plan 143 kJ, have 98.9 kJ at
    /// 100%. Time 1012 s of 1800 s; fits: search 180 s`. At most 2 x [`PILOT_TEXT_MAX`] + 2
    /// characters: MAVLink 2 chunks of one text (3 at most), which ground stations join.
    pub fn pilot_words(&self) -> String {
        self.pilot_lines().join(". ")
    }
}

/// `; plan ...; ...` (the verdict's words) or empty.
fn verdict_words(v: Option<&Verdict>) -> String {
    v.map_or(String::new(), |v| {
        let [plan, fit] = v.words();
        format!("; {plan}; {fit}")
    })
}

/// At most `max` characters, cut at a character boundary.
fn clip(mut s: String, max: usize) -> String {
    if let Some((i, _)) = s.char_indices().nth(max) {
        s.truncate(i);
    }
    s
}

/// `: reason` or empty.
fn with_reason(reason: Option<&String>) -> String {
    reason.map_or(String::new(), |r| format!(": {r}"))
}

/// Do the models agree to a start? `record` is the latest decision record, taken at the
/// on-ground state; `model` gives that state's name. `Ok(())` when the guarantee can meet every
/// goal and the arbitrated actions hold the take-off; else the first reason found, the
/// guarantee's before the MDPs' (the guarantee caps the battery belief only from the next cycle).
pub fn verdict(record: &DecisionRecord, model: &Model) -> Result<(), LaunchRefusal> {
    let on_ground = model.states.route_state(RouteRole::OnGround);
    if record.state != on_ground {
        return Err(LaunchRefusal::NotOnGround {
            state: record.state.clone(),
            on_ground: on_ground.to_string(),
        });
    }
    let g = record
        .guarantee
        .as_ref()
        .ok_or(LaunchRefusal::NoGuarantee)?;
    let reason = with_reason(g.infeasible_reason.as_ref());
    let verdict = g.verdict.clone().map(Box::new);
    let margin = |goal: &str| g.margins.get(goal).copied().filter(|m| *m < 0.0);
    if let Some(m) = margin(ENERGY) {
        let pct = record
            .observations
            .get("battery_pct")
            .copied()
            .filter(|_| g.energy_source == EnergySource::BatteryRemaining);
        return Err(match pct {
            Some(pct) => LaunchRefusal::BatteryLow {
                pct,
                short_j: -m,
                reason,
                verdict,
            },
            None => LaunchRefusal::EnergyShort {
                short_j: -m,
                energy_from: serde_json::to_value(g.energy_source)
                    .ok()
                    .and_then(|v| v.as_str().map(str::to_owned))
                    .unwrap_or_default(),
                reason,
                verdict,
            },
        });
    }
    if let Some(m) = margin(DURATION) {
        return Err(LaunchRefusal::DurationShort {
            short_s: -m,
            reason,
            verdict,
        });
    }
    if g.infeasible {
        return Err(LaunchRefusal::GoalsUnmet {
            reason: g.infeasible_reason.clone().unwrap_or_default(),
        });
    }
    // The actions that leave or keep the ground, by their roles (params/actions.toml).
    let roles = model.states.actions();
    if let Some(p) = record
        .proposals
        .iter()
        .find(|p| roles.any(&p.actions, ActionRole::StayOnGround))
    {
        let read = |name: &str| {
            p.inputs
                .get(name)
                .or_else(|| record.probabilities.get(name))
                .copied()
                .unwrap_or(f64::NAN)
        };
        return Err(LaunchRefusal::ModelsStay {
            mdp: p.mdp.clone(),
            p_battery: read(P_BATTERY),
            p_sys: read("P_sys"),
        });
    }
    let acts = &record.actions;
    if !roles.any(acts, ActionRole::TakeOff) || roles.any(acts, ActionRole::StayOnGround) {
        return Err(LaunchRefusal::NoTakeOff {
            actions: acts.join("+"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decision::{Core, ModelKind};
    use crate::observations::Observations;
    use crate::record::{GuaranteeRecord, MdpProposal};
    use std::sync::Arc;

    fn model() -> Arc<Model> {
        Arc::new(Model::load(&crate::shipped::params()).expect("shipped params load"))
    }

    /// The on-ground snapshot of a healthy vehicle with `battery_pct` left.
    fn on_ground(battery_pct: f64) -> Observations {
        let mut o = Observations {
            state: "base".into(),
            ..Default::default()
        };
        for (k, v) in [
            ("battery_pct", battery_pct),
            ("gps_fix", 3.0),
            ("gps_sats", 12.0),
            ("wind_mps", 2.0),
            ("vibration_mps2", 1.0),
            ("drone_speed_mps", 0.0),
        ] {
            o.set(k, v);
        }
        o
    }

    /// The verdict after `cycles` decision cycles on the ground.
    fn verdict_after(
        model: &Arc<Model>,
        kind: ModelKind,
        policy: &str,
        pct: f64,
        cycles: usize,
    ) -> (Result<(), LaunchRefusal>, DecisionRecord) {
        let mut core = Core::new(Arc::clone(model), kind, model.policy(policy).unwrap());
        let mut rec = DecisionRecord::default();
        for k in 0..cycles {
            let mut o = on_ground(pct);
            o.time_s = k as f64;
            rec = core.step(&o).1;
        }
        (verdict(&rec, model), rec)
    }

    /// The shipped actions playing the take-off and stay-on-ground roles.
    const TAKE_OFF: &str = "take_off";
    const STAY_ON_GROUND: &str = "stay_on_ground";

    #[test]
    fn the_actions_it_reads_are_the_roles_of_the_catalogue() {
        let m = model();
        let roles = m.states.actions();
        assert_eq!(roles.action(ActionRole::TakeOff), TAKE_OFF);
        assert_eq!(roles.action(ActionRole::StayOnGround), STAY_ON_GROUND);
    }

    /// A full pack: the models agree to the default mission, under both policies and every model.
    #[test]
    fn full_battery_is_accepted() {
        let m = model();
        for kind in [ModelKind::Bfm, ModelKind::Monolithic] {
            for pol in ["safety", "mission"] {
                let (v, rec) = verdict_after(&m, kind, pol, 100.0, 3);
                assert_eq!(v, Ok(()), "{kind:?} {pol}: {rec:?}");
                assert!(rec.actions.iter().any(|a| a == TAKE_OFF));
            }
        }
    }

    /// A first reading of 12 %: the guarantee's bound is the energy 12 % holds, so the default
    /// mission's energy margin is negative and the start is refused on the first cycle already;
    /// from the next cycles on the MDPs stay on the ground too (the battery belief is capped).
    #[test]
    fn battery_at_12_percent_is_refused() {
        let m = model();
        for pol in ["safety", "mission"] {
            let (v, rec) = verdict_after(&m, ModelKind::Bfm, pol, 12.0, 1);
            let Err(LaunchRefusal::BatteryLow { pct, short_j, .. }) = &v else {
                panic!("{pol}: {v:?}");
            };
            assert_eq!(*pct, 12.0);
            let margin = rec.guarantee.as_ref().unwrap().margins["energy_j"];
            assert_eq!(*short_j, -margin);
            // The pack holds 12 % of 74 Wh; the mission's estimate is far above what is left.
            assert!(*short_j > 100_000.0, "{short_j}");
            let text = v.as_ref().unwrap_err().pilot_text();
            assert_eq!(text, "Start refused: battery 12%, not enough energy");
            // The guarantee's verdict rides with the refusal: 12 % is under the reserve, so
            // nothing is available and not even the route without tracking fits.
            let g = rec.guarantee.as_ref().unwrap();
            let verdict = g
                .verdict
                .as_ref()
                .expect("the refused cycle's record holds a verdict");
            assert_eq!(v.as_ref().unwrap_err().guarantee_verdict(), Some(verdict));
            assert!(!verdict.fits);
            assert_eq!(verdict.battery_pct, Some(12.0));
            let pack = 74.0 * 3600.0;
            let available = verdict.available_energy_j.unwrap();
            assert!(
                (available - (0.12 * pack - 0.25 * pack)).abs() < 1e-6,
                "{available}"
            );
            assert_eq!(verdict.longest_tracking_s, None);
            assert!(verdict.route_energy_j.unwrap() > 0.0);
            let texts = v.as_ref().unwrap_err().pilot_lines();
            assert_eq!(texts.len(), 2, "{texts:?}");
            // One STATUSTEXT (chunked): both lines, in order.
            let words = v.as_ref().unwrap_err().pilot_words();
            assert_eq!(words, format!("{}. {}", texts[0], texts[1]));
            assert!(texts[0].starts_with("Start refused: plan "), "{texts:?}");
            assert!(texts[0].ends_with(" kJ, have 0.0 kJ at 12%"), "{texts:?}");
            assert!(texts[1].contains("othing fits: route alone "), "{texts:?}");
            assert!(texts.iter().all(|t| t.len() <= PILOT_TEXT_MAX), "{texts:?}");
            // Later cycles: still refused, and the MDPs now choose to stay.
            let (v, rec) = verdict_after(&m, ModelKind::Bfm, pol, 12.0, 4);
            assert!(matches!(v, Err(LaunchRefusal::BatteryLow { .. })), "{v:?}");
            assert!(
                rec.actions.iter().any(|a| a == STAY_ON_GROUND),
                "{pol}: {:?}",
                rec.actions
            );
            assert!(
                !rec.actions.iter().any(|a| a == TAKE_OFF),
                "{pol}: {:?}",
                rec.actions
            );
        }
    }

    fn base_record() -> DecisionRecord {
        let mut g = GuaranteeRecord::default();
        g.margins.insert(ENERGY.into(), 1000.0);
        g.margins.insert(DURATION.into(), 10.0);
        let mut r = DecisionRecord {
            state: "base".into(),
            guarantee: Some(g),
            actions: crate::action_id::ActionIds::from_names([TAKE_OFF]),
            ..Default::default()
        };
        r.observations.insert("battery_pct".into(), 80.0);
        r
    }

    /// Each reason, from a record written by hand (not by the code under test).
    #[test]
    fn each_refusal_from_its_record() {
        let m = model();
        assert_eq!(verdict(&base_record(), &m), Ok(()));

        let mut r = base_record();
        r.state = "wp1".into();
        assert!(matches!(
            verdict(&r, &m),
            Err(LaunchRefusal::NotOnGround { .. })
        ));

        let mut r = base_record();
        r.guarantee = None;
        assert_eq!(verdict(&r, &m), Err(LaunchRefusal::NoGuarantee));

        let mut r = base_record();
        r.guarantee
            .as_mut()
            .unwrap()
            .margins
            .insert(ENERGY.into(), -4213.0);
        let e = verdict(&r, &m).unwrap_err();
        assert_eq!(
            e.pilot_text(),
            "Start refused: battery 80%, not enough energy"
        );
        r.guarantee.as_mut().unwrap().energy_source = EnergySource::EnergyConsumed;
        let e = verdict(&r, &m).unwrap_err();
        assert_eq!(e.pilot_text(), "Start refused: not enough energy");
        assert!(e.description().contains("energy_consumed"), "{e}");

        let mut r = base_record();
        let g = r.guarantee.as_mut().unwrap();
        g.margins.insert(DURATION.into(), -120.4);
        g.infeasible = true;
        g.infeasible_reason = Some("negative duration_s margin -120.4".into());
        let e = verdict(&r, &m).unwrap_err();
        assert_eq!(e.pilot_text(), "Start refused: not enough time");
        assert!(
            e.description().contains("negative duration_s margin"),
            "{e}"
        );

        let mut r = base_record();
        let g = r.guarantee.as_mut().unwrap();
        g.infeasible = true;
        g.infeasible_reason = Some("failed resource in plan: lidar".into());
        assert_eq!(
            verdict(&r, &m),
            Err(LaunchRefusal::GoalsUnmet {
                reason: "failed resource in plan: lidar".into()
            })
        );

        let mut r = base_record();
        r.actions = crate::action_id::ActionIds::from_names([STAY_ON_GROUND]);
        r.proposals.push(MdpProposal {
            mdp: "navigation".into(),
            actions: crate::action_id::ActionIds::from_names([STAY_ON_GROUND]),
            inputs: [("P_battery".to_string(), 0.05), ("P_sys".to_string(), 0.9)]
                .into_iter()
                .collect(),
            ..Default::default()
        });
        let e = verdict(&r, &m).unwrap_err();
        assert_eq!(
            e,
            LaunchRefusal::ModelsStay {
                mdp: "navigation".into(),
                p_battery: 0.05,
                p_sys: 0.9
            }
        );
        assert_eq!(e.pilot_text(), "Start refused: navigation says stay");
        assert!(e.description().contains("P_battery 0.050"), "{e}");

        let mut r = base_record();
        r.actions = crate::action_id::ActionIds::from_names(["detect_obstacles_lidar"]);
        assert!(matches!(
            verdict(&r, &m),
            Err(LaunchRefusal::NoTakeOff { .. })
        ));
    }

    /// Every pilot text fits one STATUSTEXT, whatever the numbers and names.
    #[test]
    fn pilot_texts_fit_a_statustext() {
        let long = "ä".repeat(80);
        let all = [
            LaunchRefusal::NotOnGround {
                state: long.clone(),
                on_ground: long.clone(),
            },
            LaunchRefusal::NoGuarantee,
            LaunchRefusal::MissionNotPlanned {
                reason: long.clone(),
            },
            LaunchRefusal::BatteryLow {
                pct: 1e300,
                short_j: 1e300,
                reason: long.clone(),
                verdict: None,
            },
            LaunchRefusal::EnergyShort {
                short_j: f64::MAX,
                energy_from: long.clone(),
                reason: long.clone(),
                verdict: None,
            },
            LaunchRefusal::DurationShort {
                short_s: 1e300,
                reason: long.clone(),
                verdict: None,
            },
            LaunchRefusal::GoalsUnmet {
                reason: long.clone(),
            },
            LaunchRefusal::ModelsStay {
                mdp: long.clone(),
                p_battery: f64::NAN,
                p_sys: 0.0,
            },
            LaunchRefusal::NoTakeOff {
                actions: long.clone(),
            },
        ];
        for r in &all {
            let t = r.pilot_text();
            assert!(t.chars().count() <= PILOT_TEXT_MAX, "{t}");
            assert!(t.starts_with("Start refused: "), "{t}");
            assert!(
                r.description().len() > t.len() || matches!(r, LaunchRefusal::NoGuarantee),
                "{r:?}"
            );
        }
    }
}
