//! Values a ground station plots (issue 37): each decision record's margins, pack, probabilities,
//! running version and chosen actions as NAMED_VALUE_FLOAT / NAMED_VALUE_INT from the companion's
//! component, at `params/link.toml` `[ground_values] rate_hz` (docs/mavlink.md, "Values a ground
//! station plots"). QGroundControl's MAVLink Inspector and Mission Planner's tuning graph plot
//! them by name; `time_boot_ms` is the record's `time_s` in ms, so a value names its cycle.

use crate::Msg;
use crate::dialect::{NAMED_VALUE_FLOAT_DATA, NAMED_VALUE_INT_DATA};
use companion_core::action_id::ActionNames;
use companion_core::record::DecisionRecord;
use companion_core::spec::SpecError;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

/// `params/link.toml` `[ground_values]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GroundValuesParams {
    /// Values sent per second (0: off).
    pub rate_hz: f64,
    /// The application whose running version (`trk_ver`) and its probability (`p_trk_ver`) are
    /// plotted; none: those two are not sent.
    pub app: Option<String>,
    /// The probability of a running version: `{version}` replaced by the version (`P_{version}`
    /// gives `P_V3`, the tracking MDP's P_Vi).
    pub version_probability: String,
    /// The probability plotted as `p_battery`.
    pub battery_probability: String,
}

impl Default for GroundValuesParams {
    fn default() -> Self {
        Self {
            rate_hz: 0.0,
            app: None,
            version_probability: "P_{version}".into(),
            battery_probability: "P_battery".into(),
        }
    }
}

/// Above this a 57,600-baud radio would spend more than a tenth of its bytes on plotted values
/// (9 values x 30 bytes x 2 Hz = 540 B/s of 5,760 B/s).
pub const MAX_RATE_HZ: f64 = 2.0;

impl GroundValuesParams {
    /// Checked when params/link.toml loads.
    pub fn check(&self, path: &Path) -> Result<(), SpecError> {
        if !(self.rate_hz.is_finite() && (0.0..=MAX_RATE_HZ).contains(&self.rate_hz)) {
            return Err(SpecError::new(
                path,
                "ground_values.rate_hz",
                format!(
                    "{} is out of range: must be in [0, {MAX_RATE_HZ}] Hz (0 is off)",
                    self.rate_hz
                ),
            ));
        }
        if !self.version_probability.contains("{version}") {
            return Err(SpecError::new(
                path,
                "ground_values.version_probability",
                "must contain {version}",
            ));
        }
        Ok(())
    }
}

/// One plotted value: a float or an integer, under a name of at most 10 characters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GroundValue {
    /// NAMED_VALUE_FLOAT.
    Float(&'static str, f32),
    /// NAMED_VALUE_INT.
    Int(&'static str, i32),
}

/// When the next values are due, and how to read them from a record.
#[derive(Debug, Clone)]
pub struct GroundValues {
    params: GroundValuesParams,
    period: Option<Duration>,
    next_due: Option<Duration>,
    /// Action name -> its paper number (`A12` -> 12), the bit it sets in `actions`.
    action_bits: BTreeMap<String, u32>,
    /// The same bits by id over the action names of the records seen (the catalogue's, shared
    /// by `Arc`): resolved once per vocabulary, then read by id.
    bits_by_id: Option<(ActionNames, Vec<Option<u32>>)>,
}

impl GroundValues {
    /// `paper_names`: each action's name and its paper name (`A0`..`A17`), whose number is its
    /// bit in the `actions` value.
    pub fn new<'a>(
        params: &GroundValuesParams,
        paper_names: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Self {
        let action_bits = paper_names
            .into_iter()
            .filter_map(|(name, paper)| {
                let n: u32 = paper.strip_prefix('A')?.parse().ok()?;
                (n < 31).then(|| (name.to_string(), n))
            })
            .collect();
        Self {
            params: params.clone(),
            period: (params.rate_hz > 0.0).then(|| Duration::from_secs_f64(1.0 / params.rate_hz)),
            next_due: None,
            action_bits,
            bits_by_id: None,
        }
    }

    /// The values of `rec` when they are due at `now`, else none. Cycles come at the decision
    /// period and on events: a value set is due a period after the last one, with a quarter of
    /// a period's slack so a cycle a few ms early at the same rate is not skipped.
    pub fn due(&mut self, rec: &DecisionRecord, now: Duration) -> Vec<Msg> {
        let Some(period) = self.period else {
            return Vec::new();
        };
        if let Some(due) = self.next_due
            && now + period / 4 < due
        {
            return Vec::new();
        }
        let next = self.next_due.map_or(now + period, |d| d + period);
        // Far behind (a stalled loop, a reconnect): start again from now rather than burst.
        self.next_due = Some(if next <= now { now + period } else { next });
        let time_boot_ms = (rec.time_s.max(0.0) * 1000.0).round() as u32;
        let vocabulary = rec.actions.vocabulary();
        if !(self.bits_by_id.as_ref()).is_some_and(|(v, _)| Arc::ptr_eq(v, vocabulary)) {
            let bits = vocabulary.iter().map(|a| self.action_bits.get(a).copied());
            self.bits_by_id = Some((Arc::clone(vocabulary), bits.collect()));
        }
        self.values(rec)
            .into_iter()
            .map(|v| message(v, time_boot_ms))
            .collect()
    }

    /// The plotted values of one record (those it has).
    pub fn values(&self, rec: &DecisionRecord) -> Vec<GroundValue> {
        use GroundValue::{Float, Int};
        let mut out = vec![Int("cycle", rec.cycle as i32)];
        if let Some(g) = &rec.guarantee {
            if let Some(m) = g.margins.get("energy_j") {
                out.push(Float("e_margin", *m as f32));
            }
            if let Some(m) = g.margins.get("duration_s") {
                out.push(Float("t_margin", *m as f32));
            }
            if let Some(s) = g.pack.as_ref().and_then(|p| p.spendable_j) {
                out.push(Float("e_spend", s as f32));
            }
        }
        if let Some(p) = rec.probabilities.get(&self.params.battery_probability) {
            out.push(Float("p_battery", *p as f32));
        }
        let running = self.params.app.as_deref().and_then(|app| {
            let res = rec.resources.as_ref()?;
            res.placements.iter().find(|p| p.app == app)
        });
        if let Some(p) = running {
            let number = p
                .version
                .trim_start_matches(|c: char| !c.is_ascii_digit())
                .parse::<i32>();
            if let Ok(n) = number {
                out.push(Int("trk_ver", n));
            }
            let name = self
                .params
                .version_probability
                .replace("{version}", &p.version);
            if let Some(pv) = rec.probabilities.get(&name) {
                out.push(Float("p_trk_ver", *pv as f32));
            }
        }
        let by_id = (self.bits_by_id.as_ref())
            .filter(|(v, _)| Arc::ptr_eq(v, rec.actions.vocabulary()))
            .map(|(_, bits)| bits);
        let mask = match by_id {
            Some(bits) => (rec.actions.ids().iter())
                .filter_map(|a| bits[a.index()])
                .fold(0i32, |m, bit| m | (1 << bit)),
            // A record over other names (a test's): by name.
            None => (rec.actions.iter())
                .filter_map(|a| self.action_bits.get(a))
                .fold(0i32, |m, bit| m | (1 << bit)),
        };
        out.push(Int("actions", mask));
        if let Some(ms) = rec.decide_ms {
            out.push(Float("cycle_ms", ms as f32));
        }
        out
    }
}

fn message(v: GroundValue, time_boot_ms: u32) -> Msg {
    match v {
        GroundValue::Float(name, value) => Msg::NAMED_VALUE_FLOAT(NAMED_VALUE_FLOAT_DATA {
            time_boot_ms,
            value,
            name: name.into(),
        }),
        GroundValue::Int(name, value) => Msg::NAMED_VALUE_INT(NAMED_VALUE_INT_DATA {
            time_boot_ms,
            value,
            name: name.into(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use companion_core::record::{GuaranteeRecord, PlacementRecord, ResourcesRecord};

    fn params() -> GroundValuesParams {
        GroundValuesParams {
            rate_hz: 1.0,
            app: Some("tracking".into()),
            ..Default::default()
        }
    }

    fn record(cycle: u64, time_s: f64) -> DecisionRecord {
        let mut rec = DecisionRecord {
            cycle,
            time_s,
            actions: ["track_v3", "detect_obstacles_lidar"].into_iter().collect(),
            decide_ms: Some(0.8),
            ..Default::default()
        };
        rec.probabilities.insert("P_battery".into(), 0.75);
        rec.probabilities.insert("P_V3".into(), 0.96);
        rec.probabilities.insert("P_V4".into(), 0.31);
        let mut g = GuaranteeRecord::default();
        g.margins.insert("energy_j".into(), 40_670.5);
        g.margins.insert("duration_s".into(), -12.0);
        rec.guarantee = Some(g);
        rec.resources = Some(ResourcesRecord {
            placements: vec![PlacementRecord {
                app: "tracking".into(),
                version: "V3".into(),
                implementation: "M".into(),
                ..Default::default()
            }],
            ..Default::default()
        });
        rec
    }

    fn names() -> Vec<(&'static str, &'static str)> {
        vec![
            ("track_v3", "A15"),
            ("detect_obstacles_lidar", "A11"),
            ("take_off", "A1"),
        ]
    }

    /// Once a record was due, its actions are read by id over its vocabulary: the same bits.
    #[test]
    fn actions_by_id_set_the_bits_their_names_set() {
        let mut gv = GroundValues::new(&params(), names());
        let mut rec = record(7, 12.5);
        let names: ActionNames = ["take_off", "track_v3", "detect_obstacles_lidar"]
            .map(String::from)
            .into();
        rec.actions = companion_core::action_id::ActionIds::over(&names);
        for name in ["track_v3", "detect_obstacles_lidar"] {
            rec.actions
                .push(companion_core::action_id::id_in(&names, name).unwrap());
        }
        assert_eq!(gv.due(&rec, Duration::from_secs(1)).len(), 8);
        assert!(
            gv.bits_by_id
                .as_ref()
                .is_some_and(|(v, _)| Arc::ptr_eq(v, &names))
        );
        let mask = gv.values(&rec).into_iter().find_map(|v| match v {
            GroundValue::Int("actions", m) => Some(m),
            _ => None,
        });
        assert_eq!(mask, Some((1 << 15) | (1 << 11)));
    }

    #[test]
    fn a_record_gives_its_margins_probabilities_version_and_actions() {
        let gv = GroundValues::new(&params(), names());
        let v = gv.values(&record(7, 12.5));
        use GroundValue::{Float, Int};
        assert_eq!(
            v,
            vec![
                Int("cycle", 7),
                Float("e_margin", 40_670.5),
                Float("t_margin", -12.0),
                Float("p_battery", 0.75),
                Int("trk_ver", 3),
                Float("p_trk_ver", 0.96),
                Int("actions", (1 << 15) | (1 << 11)),
                Float("cycle_ms", 0.8),
            ]
        );
        for x in &v {
            let (Float(n, _) | Int(n, _)) = x;
            assert!(n.len() <= 10, "{n}: MAVLink names hold 10 characters");
        }
    }

    #[test]
    fn values_come_at_the_rate_with_slack_and_off_sends_none() {
        let mut gv = GroundValues::new(&params(), names());
        let rec = record(0, 0.0);
        let s = Duration::from_secs_f64;
        assert!(
            !gv.due(&rec, s(10.0)).is_empty(),
            "the first is due at once"
        );
        assert!(gv.due(&rec, s(10.2)).is_empty(), "an event cycle between");
        assert!(
            !gv.due(&rec, s(10.99)).is_empty(),
            "a cycle 10 ms early is not skipped"
        );
        assert!(gv.due(&rec, s(11.5)).is_empty());
        assert!(!gv.due(&rec, s(12.0)).is_empty());
        // A stall: one set, then the rate again from there (no burst).
        assert!(!gv.due(&rec, s(30.0)).is_empty());
        assert!(gv.due(&rec, s(30.1)).is_empty());
        let msgs = gv.due(&rec, s(31.0));
        assert!(matches!(&msgs[0], Msg::NAMED_VALUE_INT(d) if d.time_boot_ms == 0));
        let mut off = GroundValues::new(&GroundValuesParams::default(), names());
        assert!(off.due(&rec, s(1.0)).is_empty());
    }

    #[test]
    fn a_rate_beyond_the_radio_budget_is_refused() {
        let p = GroundValuesParams {
            rate_hz: 5.0,
            ..params()
        };
        let e = p.check(Path::new("params/link.toml")).unwrap_err();
        assert!(e.to_string().contains("ground_values.rate_hz"), "{e}");
        assert!(params().check(Path::new("x")).is_ok());
    }
}
