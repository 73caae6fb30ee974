//! How long each activity actually ran (docs/calibrate.md): from the records' activity in force
//! (`guarantee.activity_name`) and their time, one duration per activity completed (left for the
//! next one) in each run. An activity a run ends in is not counted: it was cut. The time is the
//! autopilot's clock (observation `vehicle_time_s`, SYSTEM_TIME) when the records have it (a SITL
//! at `--speedup 3` flies three seconds a companion second), else the record's `time_s`. An
//! activity's clock starts at arming: records that say the vehicle is disarmed (`armed` 0, the
//! wait for the autopilot to be ready before take-off) move its start on, as nothing is flown
//! or drawn then.

use companion_core::record::DecisionRecord;
use std::collections::BTreeMap;

/// Running mean and spread of one activity's durations.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DurationStats {
    pub n: u64,
    sum: f64,
    sum_sq: f64,
}

impl DurationStats {
    fn add(&mut self, x: f64) {
        self.n += 1;
        self.sum += x;
        self.sum_sq += x * x;
    }

    /// From the sums another engine computed (companion-fleet's SQL): n, Σd and Σd².
    pub fn from_sums(n: u64, sum: f64, sum_sq: f64) -> Self {
        DurationStats { n, sum, sum_sq }
    }

    /// n, Σd and Σd² (what companion-fleet's SQL sums; scripts/fleet_spark.sh compares them).
    pub fn sums(&self) -> (u64, f64, f64) {
        (self.n, self.sum, self.sum_sq)
    }

    pub fn mean(&self) -> f64 {
        self.sum / self.n as f64
    }

    /// Sample standard deviation (0 for one run).
    pub fn sd(&self) -> f64 {
        if self.n < 2 {
            return 0.0;
        }
        let m = self.mean();
        ((self.sum_sq - self.n as f64 * m * m) / (self.n - 1) as f64)
            .max(0.0)
            .sqrt()
    }
}

/// One run's stretches of one activity, fed its records in order: the rule of the module's
/// header, which companion-fleet's `stretches` table follows too (it writes each stretch as a
/// row at ingest; [`Durations`] sums them here).
#[derive(Debug, Default)]
pub struct Stretches {
    /// The activity in force and when its stretch started.
    current: Option<(String, f64)>,
}

impl Stretches {
    /// A new run begins: the activity in force of the last one was not completed.
    pub fn start_run(&mut self) {
        self.current = None;
    }

    /// Feed record `r`: the stretch it completes, when it starts another activity (that
    /// stretch's activity and how long it lasted, which may be zero or less).
    pub fn next(&mut self, r: &DecisionRecord) -> Option<(String, f64)> {
        let g = r.guarantee.as_ref()?;
        let t = r
            .observations
            .get("vehicle_time_s")
            .copied()
            .unwrap_or(r.time_s);
        if g.activity_name.is_empty() || !t.is_finite() {
            return None;
        }
        let disarmed = r.observations.get("armed").is_some_and(|a| *a < 0.5);
        match &mut self.current {
            Some((name, t0)) if *name == g.activity_name => {
                if disarmed {
                    *t0 = t;
                }
                None
            }
            Some((name, t0)) => {
                let done = (std::mem::replace(name, g.activity_name.clone()), t - *t0);
                *t0 = t;
                Some(done)
            }
            None => {
                self.current = Some((g.activity_name.clone(), t));
                None
            }
        }
    }
}

/// Activity durations over many runs, fed one record at a time.
#[derive(Default)]
pub struct Durations {
    stats: BTreeMap<String, DurationStats>,
    /// Completed activities that lasted zero or less (the clock stood or went back): per name,
    /// how many and the shortest. No duration is fitted from records like these.
    non_positive: BTreeMap<String, (u64, f64)>,
    stretches: Stretches,
}

impl Durations {
    /// A new run begins: the activity in force of the last one was not completed.
    pub fn start_run(&mut self) {
        self.stretches.start_run();
    }

    pub fn add(&mut self, r: &DecisionRecord) {
        let Some((name, d)) = self.stretches.next(r) else {
            return;
        };
        if d > 0.0 {
            self.stats.entry(name).or_default().add(d);
        } else {
            let e = self.non_positive.entry(name).or_insert((0, d));
            e.0 += 1;
            e.1 = e.1.min(d);
        }
    }

    /// Per activity name, the durations of its completed runs.
    pub fn stats(&self) -> &BTreeMap<String, DurationStats> {
        &self.stats
    }

    /// Per activity name, its completed runs of zero or negative length (count, shortest).
    pub fn non_positive(&self) -> &BTreeMap<String, (u64, f64)> {
        &self.non_positive
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_and_negative_durations_are_kept_apart() {
        let mut d = Durations::default();
        for (t, a) in [(5.0, "a"), (5.0, "b"), (3.0, "c"), (4.0, "d")] {
            d.add(&rec(t, a));
        }
        assert_eq!(d.stats().keys().collect::<Vec<_>>(), ["c"]);
        assert_eq!(d.non_positive()["a"], (1, 0.0));
        assert_eq!(d.non_positive()["b"], (1, -2.0));
    }
    use companion_core::record::GuaranteeRecord;

    fn rec(t: f64, activity: &str) -> DecisionRecord {
        DecisionRecord {
            time_s: t,
            guarantee: Some(GuaranteeRecord {
                activity_name: activity.into(),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    #[test]
    fn completed_activities_are_timed_and_the_cut_one_is_not() {
        let mut d = Durations::default();
        for (t, a) in [
            (0.0, "a"),
            (5.0, "a"),
            (10.0, "b"),
            (40.0, "c"),
            (45.0, "c"),
        ] {
            d.add(&rec(t, a));
        }
        d.start_run();
        for (t, a) in [(0.0, "a"), (14.0, "b"), (20.0, "b")] {
            d.add(&rec(t, a));
        }
        let s = d.stats();
        assert_eq!(s["a"].n, 2);
        assert!((s["a"].mean() - 12.0).abs() < 1e-12);
        assert!((s["a"].sd() - 8f64.sqrt()).abs() < 1e-12);
        assert_eq!(s["b"].n, 1);
        assert!((s["b"].mean() - 30.0).abs() < 1e-12);
        assert!(!s.contains_key("c"), "the run ended in c: not completed");
    }

    #[test]
    fn the_wait_on_the_ground_before_arming_is_not_flown() {
        let mut d = Durations::default();
        for (t, a, armed) in [
            (0.0, "a", 0.0),
            (30.0, "a", 0.0),
            (31.0, "a", 1.0),
            (41.0, "b", 1.0),
        ] {
            let mut r = rec(t, a);
            r.observations.insert("armed".into(), armed);
            d.add(&r);
        }
        assert!(
            (d.stats()["a"].mean() - 11.0).abs() < 1e-12,
            "{}",
            d.stats()["a"].mean()
        );
    }

    #[test]
    fn the_autopilots_clock_is_used_when_recorded() {
        let mut d = Durations::default();
        for (t, a) in [(0.0, "a"), (10.0, "b"), (11.0, "c")] {
            let mut r = rec(t, a);
            // A SITL at --speedup 3.
            r.observations
                .insert("vehicle_time_s".into(), 1000.0 + 3.0 * t);
            d.add(&r);
        }
        assert!((d.stats()["a"].mean() - 30.0).abs() < 1e-12);
    }
}
