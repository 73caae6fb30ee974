//! The guarantee's verdict in the operator's terms (issue 36 item 4): the planned and the
//! available energy and time, and what would fit. Computed by `guarantee::verdict`; this is its
//! typed form in the decision record and `check --json`, and the one function that words it
//! ([`Verdict::words`]) for `check`, the start gate's STATUSTEXT and the journal.

use serde::{Deserialize, Serialize};

/// Longest line of [`Verdict::words`]: one MAVLink STATUSTEXT holds 50 characters, and the start
/// gate puts `Start refused: ` (15) before the first line.
pub const PLAN_LINE_MAX: usize = 35;
/// Longest second line of [`Verdict::words`] (one STATUSTEXT).
pub const FIT_LINE_MAX: usize = 50;

/// Planned against available, and what would fit. Energies in J, times in s.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Verdict {
    /// Some allocation meets every goal (the paper's algorithm, else the exact search).
    pub fits: bool,
    /// The energy the plan needs: the fitting allocation's total, or, when none fits, the
    /// lowest total any allocation reaches (the cheapest). `None` without an energy goal.
    pub planned_energy_j: Option<f64>,
    /// The energy the mission may spend: the goal's bound (the pack's usable energy above the
    /// reserve) less what the pack no longer holds. `None` without an energy goal.
    pub available_energy_j: Option<f64>,
    /// The pack's remaining percentage the available energy was reckoned at (100: `check`'s full
    /// pack).
    pub battery_pct: Option<f64>,
    /// The duration the plan needs, as `planned_energy_j` (the shortest when none fits).
    pub planned_duration_s: Option<f64>,
    /// The duration goal less the time already spent. `None` without a duration goal.
    pub available_duration_s: Option<f64>,
    /// The search hold as planned (s), when the mission has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planned_search_s: Option<f64>,
    /// When the mission does not fit: the longest search hold (whole seconds, rounded down)
    /// with which it fits, the other activities as planned; `None` when even no search does not
    /// fit, or the mission has no search hold.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub longest_search_s: Option<f64>,
    /// The tracking hold as planned (s), when the mission has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planned_tracking_s: Option<f64>,
    /// As `longest_search_s`, for the tracking hold.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub longest_tracking_s: Option<f64>,
    /// When it fits only without the most capable IAs: per activity lowered, the IA planned and
    /// the most capable one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub lowered: Vec<Lowered>,
    /// When it fits only without the most capable IAs: the energy the most capable ones need.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub most_capable_energy_j: Option<f64>,
    /// When no shorter search or tracking alone fits: the lowest energy the route needs with no
    /// search and no tracking hold at all.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub route_energy_j: Option<f64>,
    /// As `route_energy_j`, the shortest duration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub route_duration_s: Option<f64>,
}

/// An activity the fitting allocation flies with a less capable IA than its most capable.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Lowered {
    /// Activity name.
    pub activity: String,
    /// The IA the fitting allocation plans.
    pub planned: String,
    /// The activity's most capable IA.
    pub most_capable: String,
}

impl Verdict {
    /// The verdict in two lines: planned against available (at most [`PLAN_LINE_MAX`]
    /// characters: `plan 143 kJ, have 98.9 kJ at 100%`, or the time when only the time does not
    /// fit: `plan 2012 s, have 1800 s`) and the other goal and what fits (at most
    /// [`FIT_LINE_MAX`]: `Time 1012 s of 1800 s; fits: search 180 s`, the other goal left out
    /// when both do not fit in one line). The same words in `check`, the STATUSTEXT and the
    /// journal.
    pub fn words(&self) -> [String; 2] {
        let energy = self.planned_energy_j.zip(self.available_energy_j);
        let time = self.planned_duration_s.zip(self.available_duration_s);
        // The first line is the goal that does not fit: the energy, unless only the time fails.
        let time_only = time.is_some_and(|(p, a)| p > a) && energy.is_none_or(|(p, a)| p <= a);
        let (plan, other) = match (energy, time) {
            (Some((pe, ae)), Some((pd, ad))) if time_only => (
                format!("plan {}, have {}", secs(pd), secs(ad)),
                Some(format!("energy {} of {}", kj(pe), kj(ae))),
            ),
            (Some((p, a)), time) => {
                let at = self
                    .battery_pct
                    .map_or(String::new(), |b| format!(" at {b:.0}%"));
                let full = format!("plan {}, have {}{at}", kj(p), kj(a));
                let plan = if full.len() <= PLAN_LINE_MAX {
                    full
                } else {
                    format!("plan {}, have {}", kj(p), kj(a))
                };
                (
                    plan,
                    time.map(|(p, a)| format!("time {} of {}", secs(p), secs(a))),
                )
            }
            (None, Some((p, a))) => (format!("plan {}, have {}", secs(p), secs(a)), None),
            (None, None) => ("no energy or time goal".to_string(), None),
        };
        let what = self.what_fits();
        let fit = match other {
            Some(o) if o.len() + 2 + what.len() <= FIT_LINE_MAX => format!("{o}; {what}"),
            _ => what,
        };
        [
            clip(plan, PLAN_LINE_MAX),
            clip(capitalised(&fit), FIT_LINE_MAX),
        ]
    }

    /// What would fit, in words: `fits`, `fits with less capable IAs`, `fits: search 180 s or
    /// tracking 40 s`, `fits: no search, no tracking`, `nothing fits: route alone 120 kJ of 98.9 kJ`.
    fn what_fits(&self) -> String {
        if self.fits {
            return if self.lowered.is_empty() {
                "fits".into()
            } else {
                "fits with less capable IAs".into()
            };
        }
        let holds: Vec<String> = [
            ("search", self.longest_search_s),
            ("tracking", self.longest_tracking_s),
        ]
        .into_iter()
        .filter_map(|(what, s)| s.map(|s| format!("{what} {}", secs(s))))
        .collect();
        if !holds.is_empty() {
            return format!("fits: {}", holds.join(" or "));
        }
        let over = |need: Option<f64>, have: Option<f64>| need.zip(have).filter(|(n, h)| n > h);
        if let Some((n, h)) = over(self.route_energy_j, self.available_energy_j) {
            return format!("nothing fits: route alone {} of {}", kj(n), kj(h));
        }
        if let Some((n, h)) = over(self.route_duration_s, self.available_duration_s) {
            return format!("nothing fits: route alone {} of {}", secs(n), secs(h));
        }
        match (self.planned_search_s, self.planned_tracking_s) {
            (Some(_), Some(_)) => "fits: no search, no tracking".into(),
            (Some(_), None) => "fits: no search".into(),
            (None, Some(_)) => "fits: no tracking".into(),
            (None, None) => "nothing fits".into(),
        }
    }
}

/// Joules as kJ: one decimal below 100 kJ (`98.9 kJ`), whole above (`143 kJ`); below zero (a
/// pack under its reserve) as none: an operator reads "have 0.0 kJ", the record keeps the sign.
fn kj(j: f64) -> String {
    let k = j.max(0.0) / 1000.0;
    if k.abs() < 100.0 {
        format!("{k:.1} kJ")
    } else {
        format!("{k:.0} kJ")
    }
}

/// Seconds, whole (`1012 s`).
fn secs(s: f64) -> String {
    format!("{s:.0} s")
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

/// At most `max` characters, cut at a character boundary.
fn clip(mut s: String, max: usize) -> String {
    if let Some((i, _)) = s.char_indices().nth(max) {
        s.truncate(i);
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused() -> Verdict {
        Verdict {
            fits: false,
            planned_energy_j: Some(143_012.0),
            available_energy_j: Some(98_900.0),
            battery_pct: Some(100.0),
            planned_duration_s: Some(1012.4),
            available_duration_s: Some(1800.0),
            planned_search_s: Some(300.0),
            longest_search_s: Some(180.0),
            planned_tracking_s: Some(20.0),
            longest_tracking_s: None,
            ..Default::default()
        }
    }

    #[test]
    fn a_refusal_names_planned_available_and_what_fits() {
        assert_eq!(
            refused().words(),
            [
                "plan 143 kJ, have 98.9 kJ at 100%".to_string(),
                "Time 1012 s of 1800 s; fits: search 180 s".to_string()
            ]
        );
        let both = Verdict {
            longest_tracking_s: Some(0.0),
            ..refused()
        };
        assert_eq!(both.words()[1], "Fits: search 180 s or tracking 0 s");
        let nothing = Verdict {
            longest_search_s: None,
            route_energy_j: Some(120_300.0),
            route_duration_s: Some(400.0),
            ..refused()
        };
        assert_eq!(
            nothing.words()[1],
            "Nothing fits: route alone 120 kJ of 98.9 kJ"
        );
        let route_fits = Verdict {
            longest_search_s: None,
            route_energy_j: Some(60_000.0),
            route_duration_s: Some(400.0),
            ..refused()
        };
        assert_eq!(route_fits.words()[1], "Fits: no search, no tracking");
    }

    /// Only the time is short: the first line says the time, the second the energy.
    #[test]
    fn a_refusal_for_time_alone_leads_with_the_time() {
        let v = Verdict {
            planned_energy_j: Some(60_000.0),
            planned_duration_s: Some(2012.0),
            longest_tracking_s: None,
            ..refused()
        };
        assert_eq!(
            v.words(),
            [
                "plan 2012 s, have 1800 s".to_string(),
                "Energy 60.0 kJ of 98.9 kJ; fits: search 180 s".to_string()
            ]
        );
    }

    #[test]
    fn the_lines_stay_within_a_statustext_for_extreme_numbers() {
        for x in [0.0, 1.0, 99_949.0, 1e9, 1e300, f64::MAX, -1e12, f64::NAN] {
            let v = Verdict {
                planned_energy_j: Some(x),
                available_energy_j: Some(x),
                planned_duration_s: Some(x),
                available_duration_s: Some(x),
                longest_search_s: Some(x),
                longest_tracking_s: Some(x),
                ..refused()
            };
            let [plan, fit] = v.words();
            assert!(plan.len() <= PLAN_LINE_MAX, "{plan}");
            assert!(fit.len() <= FIT_LINE_MAX, "{fit}");
        }
    }
}
