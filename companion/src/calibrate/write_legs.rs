//! How the vehicle flies (`legs`) in calibrate's report, its refusals and the overlay: the
//! mission's `[derive]` entries the derivation of activities from a route plans with
//! (`waypoint_overhead_s`, `speed_fraction`, `climb_speed_mps`, `descent_speed_mps`), each with
//! its source (runs, samples, fit error) in `[calibration.sources]`.

use super::Calibration;
use super::legs::{LegFitError, LegModel, SpeedSource, Vertical, fit_legs, rate};
use super::toml_table::{round4, table_at};
use std::fmt::Write;
use toml::{Table, Value};

/// A leg model whose overhead is below zero by more than this, or its fit's RMS if larger (s),
/// describes no vehicle: refused.
const OVERHEAD_SLACK_S: f64 = 0.5;
/// Legs flown this much faster than commanded: the commanded speed is not the autopilot's.
const FASTEST_FRACTION: f64 = 1.25;
/// Vertical rates outside this (m/s) are no take-off or landing of a multicopter.
const RATE_RANGE: (f64, f64) = (0.05, 30.0);
/// Legs listed one by one in the report.
const SHOWN_LEGS: usize = 12;

/// The fallback commanded speed calibrate was given, and its words.
fn fallback_of(cal: &Calibration) -> Option<(f64, &str)> {
    cal.legs.fallback().map(|(v, from)| (*v, from.as_str()))
}

fn speed_words(fallback: Option<(f64, &str)>, m: &LegModel) -> String {
    let words: Vec<String> = m
        .sources
        .iter()
        .map(|s| match s {
            SpeedSource::MissionItem => "the mission's DO_CHANGE_SPEED".to_string(),
            SpeedSource::AutopilotParam => {
                "the autopilot's WPNAV_SPEED / MPC_XY_CRUISE (PARAM_VALUE)".to_string()
            }
            SpeedSource::Fallback => match fallback {
                Some((v, from)) => format!("{from} {v} m/s (the tlog does not say it)"),
                None => "the fallback".to_string(),
            },
        })
        .collect();
    words.join(", ")
}

fn leg_source(made_by: &str, runs: usize, fallback: Option<(f64, &str)>, m: &LegModel) -> String {
    format!(
        "{made_by}: {} legs in {runs} run(s), {:.0}..{:.0} m, commanded {:.1}..{:.1} m/s ({}); \
         model t = L / {} + c, fit RMS {:.2} s; without it (c = 0, the commanded speed) RMS {:.2} s",
        m.legs,
        m.lengths.0,
        m.lengths.1,
        m.commanded.0,
        m.commanded.1,
        speed_words(fallback, m),
        if m.speed_fraction.is_some() {
            "(f v_cmd)"
        } else {
            "v_cmd"
        },
        m.rms_s,
        m.rms_before_s
    )
}

fn vertical_source(made_by: &str, what: &str, r: &FittedRate, runs: usize) -> String {
    format!(
        "{made_by}: {} {what}(s) in {runs} run(s), {:.1} m on average; rate = height / time \
         over them all; RMS of each one's time against it {:.2} s",
        r.flights, r.mean_height_m, r.rms_s
    )
}

/// A climb or descent rate fitted: over how many flights, their mean height, the rate (height
/// over time, all of them) and the RMS of each one's time against it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedRate {
    pub flights: usize,
    pub mean_height_m: f64,
    pub rate_mps: f64,
    pub rms_s: f64,
}

impl FittedRate {
    /// The rate of `v` (`legs::rate`), none without a flight.
    fn of(v: &[Vertical]) -> Option<Self> {
        let (rate_mps, rms_s) = rate(v)?;
        Some(FittedRate {
            flights: v.len(),
            mean_height_m: v.iter().map(|x| x.height_m).sum::<f64>() / v.len() as f64,
            rate_mps,
            rms_s,
        })
    }
}

/// How the vehicle flies as the overlay writes it: the fits, not the legs (`companion-fleet
/// calibrate` has the same fits from SQL sums over its `legs` table).
#[derive(Debug, Clone, PartialEq)]
pub struct FittedLegs<'a> {
    /// The fallback commanded speed and its words; without one the mission has no `[derive]`
    /// to plan with and nothing is written.
    pub fallback: Option<(f64, &'a str)>,
    pub model: Option<LegModel>,
    pub climb: Option<FittedRate>,
    pub descent: Option<FittedRate>,
}

impl<'a> FittedLegs<'a> {
    /// The fits of calibrate's legs.
    pub(super) fn of(cal: &'a Calibration) -> Self {
        FittedLegs {
            fallback: fallback_of(cal),
            model: fit_legs(&cal.legs.legs).ok(),
            climb: FittedRate::of(&cal.legs.climbs),
            descent: FittedRate::of(&cal.legs.descents),
        }
    }
}

/// What the leg, climb and descent fits say no vehicle can be: each a reason.
pub(super) fn refusals(cal: &Calibration) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(m) = fit_legs(&cal.legs.legs) {
        if m.overhead_s < -m.rms_s.max(OVERHEAD_SLACK_S) {
            out.push(format!(
                "legs: a time per waypoint of {:.2} s (below zero by more than the fit's RMS {:.2} s): \
                 the legs are no vehicle's",
                m.overhead_s, m.rms_s
            ));
        }
        if let Some(f) = m.fitted_fraction.filter(|f| *f > FASTEST_FRACTION) {
            out.push(format!(
                "legs: flown at {:.2} x the commanded speed ({}): that is not the speed the autopilot \
                 commanded; give it with --cruise-speed-mps",
                f,
                speed_words(fallback_of(cal), &m)
            ));
        }
    }
    for (what, v) in [("climb", &cal.legs.climbs), ("descent", &cal.legs.descents)] {
        if let Some((r, _)) = rate(v)
            && !(RATE_RANGE.0..=RATE_RANGE.1).contains(&r)
        {
            out.push(format!(
                "{what} rate {r:.3} m/s is outside {}..{} m/s: no take-off or landing of a multicopter",
                RATE_RANGE.0, RATE_RANGE.1
            ));
        }
    }
    out
}

/// The report's section on how the vehicle flies.
pub(super) fn report(s: &mut String, cal: &Calibration) {
    let _ = writeln!(
        s,
        "\nhow the vehicle flies (flight.tlog: legs between MISSION_ITEM_REACHED, the autopilot's clock):"
    );
    match fit_legs(&cal.legs.legs) {
        Ok(m) => {
            let _ = writeln!(
                s,
                "  legs: {} ({:.0}..{:.0} m), commanded {:.1}..{:.1} m/s ({})\n  \
                 fit error before (c = 0, the commanded speed): RMS {:.2} s\n  \
                 fit error after:                               RMS {:.2} s\n  \
                 time per waypoint (derive.waypoint_overhead_s): {:.2} s",
                m.legs,
                m.lengths.0,
                m.lengths.1,
                m.commanded.0,
                m.commanded.1,
                speed_words(fallback_of(cal), &m),
                m.rms_before_s,
                m.rms_s,
                m.overhead_s
            );
            let reached = match (m.speed_fraction, m.fitted_fraction) {
                (Some(f), _) => format!("not reached: derive.speed_fraction {f:.3}"),
                (None, Some(f)) => format!("reached (fitted fraction {f:.3})"),
                (None, None) => "not judged: the legs' L / v_cmd do not spread 2:1".to_string(),
            };
            let _ = writeln!(s, "  commanded speed: {reached}");
            // Each leg's residual shows what the model leaves out (the first few: a long route
            // has hundreds).
            let f = m.speed_fraction.unwrap_or(1.0);
            for (i, l) in cal.legs.legs.iter().enumerate().take(SHOWN_LEGS) {
                let model = l.length_m / (f * l.commanded_mps) + m.overhead_s;
                let _ = writeln!(
                    s,
                    "    leg {}: {:.1} m in {:.2} s at {:.1} m/s commanded; modelled {model:.2} s",
                    i + 1,
                    l.length_m,
                    l.duration_s,
                    l.commanded_mps
                );
            }
            if cal.legs.legs.len() > SHOWN_LEGS {
                let _ = writeln!(s, "    ... {} more", cal.legs.legs.len() - SHOWN_LEGS);
            }
        }
        Err(LegFitError::TooFew(n)) => {
            let _ = writeln!(
                s,
                "  legs: not fitted, nothing about legs written: {}",
                LegFitError::TooFew(n)
            );
        }
    }
    for (what, key, v) in [
        ("climb", "climb_speed_mps", &cal.legs.climbs),
        ("descent", "descent_speed_mps", &cal.legs.descents),
    ] {
        match rate(v) {
            Some((r, e)) => {
                let _ = writeln!(
                    s,
                    "  {what}: {} flight(s), derive.{key} {r:.3} m/s (RMS {e:.2} s)",
                    v.len()
                );
            }
            None => {
                let _ = writeln!(s, "  {what}: none measured, not written");
            }
        }
    }
}

/// The overlay's `[derive]` entries (only when the mission has a `[derive]` to plan with), the
/// fits `legs` of `runs` runs, made by `made_by`.
pub(super) fn overlay(
    t: &mut Table,
    sources: &mut Table,
    mf: &str,
    (legs, runs, made_by): (&FittedLegs<'_>, usize, &str),
) {
    if legs.fallback.is_none() {
        return;
    }
    let mut entries: Vec<(&str, f64, String)> = Vec::new();
    if let Some(m) = &legs.model {
        let src = leg_source(made_by, runs, legs.fallback, m);
        // A small negative overhead (within the refusal's slack) is none.
        entries.push(("waypoint_overhead_s", m.overhead_s.max(0.0), src.clone()));
        if let Some(f) = m.speed_fraction {
            entries.push(("speed_fraction", f, src));
        }
    }
    for (what, key, r) in [
        ("climb", "climb_speed_mps", &legs.climb),
        ("descent", "descent_speed_mps", &legs.descent),
    ] {
        if let Some(r) = r {
            entries.push((key, r.rate_mps, vertical_source(made_by, what, r, runs)));
        }
    }
    if entries.is_empty() {
        return;
    }
    let d = table_at(t, &[mf, "derive"]);
    for (key, v, src) in entries {
        d.insert(key.into(), round4(v));
        sources.insert(format!("{mf}:derive.{key}"), Value::String(src));
    }
}
