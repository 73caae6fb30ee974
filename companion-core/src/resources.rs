//! Resources stage: loads the platform (`params/platform.toml`), the Table 2 variant catalogue
//! (`params/variants.toml`) and the resource policies (`params/resource_policies.toml`) into
//! `fpga_model` types, turns a schedule into the decision record, and gives the resource health
//! BN its observations (`free_tiles`, `cpu_load`). Format: docs/params/platform.md.

use crate::observations::Observations;
use crate::record::{Degraded, Dropped, PlacementRecord, ResourcesRecord};
use crate::spec::{ParamsFiles, SpecError, read_toml};
use fpga_model::{
    Catalogue, Platform, PlatformState, PoliciesFile, Request, ResourcePolicy, Schedule,
    ScheduleWorkspace, VariantsFile,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Platform model file in the params dir.
pub const PLATFORM_FILE: &str = "platform.toml";
/// Variant catalogue file in the params dir.
pub const VARIANTS_FILE: &str = "variants.toml";
/// Resource policies file in the params dir.
pub const POLICIES_FILE: &str = "resource_policies.toml";

/// Everything the scheduler needs, validated.
#[derive(Debug, Clone)]
pub struct ResourceSpec {
    /// The platform model (params/platform.toml).
    pub platform: Platform,
    /// The variant catalogue (params/variants.toml), checked against the platform.
    pub catalogue: Catalogue,
    /// By name (`safety`, `mission`).
    pub policies: BTreeMap<String, ResourcePolicy>,
    /// Where the policies came from, for error messages.
    pub policies_file: PathBuf,
}

impl ResourceSpec {
    /// Load the three files from a params directory.
    pub fn load(params: &ParamsFiles) -> Result<Self, SpecError> {
        let params_dir = params.dir();
        let platform = load_platform(params, &params_dir.join(PLATFORM_FILE))?;
        let catalogue = load_variants(params, &params_dir.join(VARIANTS_FILE), &platform)?;
        let policies_file = params_dir.join(POLICIES_FILE);
        let policies = load_policies(params, &policies_file, &catalogue)?;
        Ok(Self {
            platform,
            catalogue,
            policies,
            policies_file,
        })
    }

    /// A policy by name; unknown names are a spec error naming the policies file.
    pub fn policy(&self, name: &str) -> Result<&ResourcePolicy, SpecError> {
        self.policies.get(name).ok_or_else(|| {
            let known: Vec<&str> = self.policies.keys().map(String::as_str).collect();
            SpecError::new(
                &self.policies_file,
                name,
                format!("unknown resource policy (known: {})", known.join(", ")),
            )
        })
    }

    /// One scheduling decision under the named policy.
    pub fn schedule(
        &self,
        policy: &str,
        state: &PlatformState,
        requests: &[Request],
    ) -> Result<(Schedule, PlatformState), SpecError> {
        let policy = self.policy(policy)?;
        Ok(fpga_model::schedule(
            &self.platform,
            &self.catalogue,
            policy,
            state,
            requests,
        ))
    }

    /// [`ResourceSpec::schedule`] into reused outputs and working memory
    /// ([`fpga_model::schedule_into`]): same result, no allocation once warm.
    pub fn schedule_into(
        &self,
        policy: &str,
        state: &PlatformState,
        requests: &[Request],
        ws: &mut ScheduleWorkspace,
        out: &mut Schedule,
        next: &mut PlatformState,
    ) -> Result<(), SpecError> {
        let policy = self.policy(policy)?;
        self.schedule_with(policy, state, requests, ws, out, next);
        Ok(())
    }

    /// [`ResourceSpec::schedule_into`] under a policy resolved beforehand.
    pub fn schedule_with(
        &self,
        policy: &ResourcePolicy,
        state: &PlatformState,
        requests: &[Request],
        ws: &mut ScheduleWorkspace,
        out: &mut Schedule,
        next: &mut PlatformState,
    ) {
        fpga_model::schedule_into(
            &self.platform,
            &self.catalogue,
            policy,
            state,
            requests,
            ws,
            out,
            next,
        );
    }

    /// Required frame rate of `app` from the drone's and the watched thing's velocities (m/s),
    /// by the section 4.3.2 model in platform.toml; `None` when params give the app no model.
    pub fn required_fps(
        &self,
        app: &str,
        drone_velocity: [f64; 2],
        target_velocity: [f64; 2],
    ) -> Option<f64> {
        self.platform
            .required_fps(app, drone_velocity, target_velocity)
    }
}

/// Read and validate the platform model at `path`.
pub fn load_platform(params: &ParamsFiles, path: &Path) -> Result<Platform, SpecError> {
    let platform: Platform = read_toml(params, path)?;
    platform
        .validate()
        .map_err(|e| SpecError::new(path, e.entry, e.reason))?;
    Ok(platform)
}

/// Read the variant catalogue at `path` and check it against `platform`.
pub fn load_variants(
    params: &ParamsFiles,
    path: &Path,
    platform: &Platform,
) -> Result<Catalogue, SpecError> {
    let file: VariantsFile = read_toml(params, path)?;
    Catalogue::new(file.variant, platform).map_err(|e| SpecError::new(path, e.entry, e.reason))
}

/// Read the resource policies at `path` and check them against `catalogue`.
pub fn load_policies(
    params: &ParamsFiles,
    path: &Path,
    catalogue: &Catalogue,
) -> Result<BTreeMap<String, ResourcePolicy>, SpecError> {
    let mut file: PoliciesFile = read_toml(params, path)?;
    if file.is_empty() {
        return Err(SpecError::new(path, "-", "no resource policy defined"));
    }
    for (name, policy) in file.iter_mut() {
        policy.name = name.clone();
        policy
            .validate(name, catalogue)
            .map_err(|e| SpecError::new(path, e.entry, e.reason))?;
    }
    Ok(file)
}

/// The placements as the plan's application list.
pub fn placement_records(schedule: &Schedule) -> Vec<PlacementRecord> {
    schedule
        .placements
        .iter()
        .map(|p| PlacementRecord {
            app: p.app.clone(),
            version: p.version.clone(),
            implementation: p.implementation.to_string(),
            support: p.support.to_string(),
            tiles: p.tiles.clone(),
            cpu_share: p.cpu_share,
            ms_per_frame: p.ms_per_frame,
        })
        .collect()
}

/// The decision record's resources section.
pub fn to_record(schedule: &Schedule) -> ResourcesRecord {
    ResourcesRecord {
        placements: placement_records(schedule),
        cpu_load: schedule.cpu_load,
        tiles_used: schedule.tiles_used,
        reconfigurations: schedule.reconfigurations,
        degraded: schedule
            .degraded
            .iter()
            .map(|d| Degraded {
                app: d.app.clone(),
                from: d.from.clone(),
                to: d.to.clone(),
                reason: d.reason.clone(),
            })
            .collect(),
        dropped: schedule
            .dropped
            .iter()
            .map(|d| Dropped {
                app: d.app.clone(),
                version: d.version.clone(),
                reason: d.reason.clone(),
            })
            .collect(),
        summary: schedule.summary.clone(),
        policy: schedule.policy.clone(),
        free_tiles: schedule.free_tiles,
        failed_tiles: schedule.failed_tiles.clone(),
        reconfiguration_ms: schedule.reconfiguration_ms,
        power_w: schedule.power_w,
    }
}

/// [`to_record`] into an existing record, reusing its strings and lists (no allocation once
/// `rec` has held a record as large).
pub fn to_record_into(schedule: &Schedule, rec: &mut ResourcesRecord) {
    use std::fmt::Write;
    fn set(dst: &mut String, src: &str) {
        dst.clear();
        dst.push_str(src);
    }
    let n = schedule.placements.len();
    rec.placements.truncate(n);
    for (i, p) in schedule.placements.iter().enumerate() {
        if i == rec.placements.len() {
            rec.placements.push(PlacementRecord {
                app: String::new(),
                version: String::new(),
                implementation: String::new(),
                support: String::new(),
                tiles: Vec::new(),
                cpu_share: 0.0,
                ms_per_frame: 0.0,
            });
        }
        let r = &mut rec.placements[i];
        set(&mut r.app, &p.app);
        set(&mut r.version, &p.version);
        r.implementation.clear();
        let _ = write!(r.implementation, "{}", p.implementation);
        r.support.clear();
        let _ = write!(r.support, "{}", p.support);
        r.tiles.clone_from(&p.tiles);
        r.cpu_share = p.cpu_share;
        r.ms_per_frame = p.ms_per_frame;
    }
    rec.cpu_load = schedule.cpu_load;
    rec.tiles_used = schedule.tiles_used;
    rec.reconfigurations = schedule.reconfigurations;
    fill(&mut rec.degraded, &schedule.degraded, |r, d| {
        set(&mut r.app, &d.app);
        set(&mut r.from, &d.from);
        set(&mut r.to, &d.to);
        set(&mut r.reason, &d.reason);
    });
    fill(&mut rec.dropped, &schedule.dropped, |r, d| {
        set(&mut r.app, &d.app);
        set(&mut r.version, &d.version);
        set(&mut r.reason, &d.reason);
    });
    set(&mut rec.summary, &schedule.summary);
    set(&mut rec.policy, &schedule.policy);
    rec.free_tiles = schedule.free_tiles;
    rec.failed_tiles.clone_from(&schedule.failed_tiles);
    rec.reconfiguration_ms = schedule.reconfiguration_ms;
    rec.power_w = schedule.power_w;
}

/// `out = items.map(copy)`, reusing the entries (and their strings) already in `out`.
fn fill<R: Default, T>(out: &mut Vec<R>, items: &[T], copy: impl Fn(&mut R, &T)) {
    out.truncate(items.len());
    for (i, x) in items.iter().enumerate() {
        if i == out.len() {
            out.push(R::default());
        }
        copy(&mut out[i], x);
    }
}

/// What the resource health BN observes after scheduling (section 4.3.1, Figure 5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResourceObservations {
    /// Healthy tiles not in use.
    pub free_tiles: f64,
    /// Utilisation of the online cores (0..1, may exceed 1 when external load alone is over).
    pub cpu_load: f64,
}

impl ResourceObservations {
    /// Write them into an observation snapshot under the names `free_tiles` and `cpu_load`.
    pub fn apply(&self, obs: &mut Observations) {
        obs.set("free_tiles", self.free_tiles);
        obs.set("cpu_load", self.cpu_load);
    }
}

/// What the resource BN observes after `schedule`.
pub fn observations(schedule: &Schedule) -> ResourceObservations {
    ResourceObservations {
        free_tiles: f64::from(schedule.free_tiles),
        cpu_load: schedule.cpu_load,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    fn real() -> ResourceSpec {
        ResourceSpec::load(&crate::shipped::params()).expect("shipped params load")
    }

    /// The shipped files with one of them replaced by `text`.
    fn with_file(name: &str, text: &str) -> ((), ParamsFiles) {
        let mut p = crate::shipped::params();
        p.insert(p.dir().join(name), text);
        ((), p)
    }

    fn shipped(name: &str) -> String {
        let p = crate::shipped::params();
        p.text(&p.dir().join(name)).unwrap().to_string()
    }

    /// Replace exactly one occurrence of `from` in the shipped file `name`, load, return the error.
    fn error_after(name: &str, from: &str, to: &str) -> SpecError {
        let text = shipped(name);
        assert_eq!(
            text.matches(from).count(),
            1,
            "pattern {from:?} must occur once in {name}"
        );
        let (_dir, path) = with_file(name, &text.replacen(from, to, 1));
        let err = ResourceSpec::load(&path).expect_err("must be rejected");
        assert_eq!(err.file, path.dir().join(name));
        err
    }

    #[test]
    fn shipped_params_load() {
        let spec = real();
        assert_eq!(spec.platform.tiles, 4);
        assert_eq!(spec.catalogue.variants().len(), 27);
        assert!(spec.policy("safety").is_ok() && spec.policy("mission").is_ok());
    }

    #[test]
    fn missing_file_is_named() {
        let empty = ParamsFiles::new("empty");
        let err = ResourceSpec::load(&empty).unwrap_err();
        assert_eq!(err.file, empty.dir().join(PLATFORM_FILE));
        assert!(err.reason.starts_with("cannot read"), "{err}");
    }

    #[test]
    fn toml_syntax_error_names_the_line() {
        let err = error_after(
            VARIANTS_FILE,
            "app = \"path_planning\"",
            "app = path_planning\"",
        );
        assert!(err.entry.starts_with("line "), "{err}");
    }

    #[test]
    fn platform_zero_tiles() {
        let err = error_after(PLATFORM_FILE, "tiles = 4 ", "tiles = 0 ");
        assert_eq!(err.entry, "tiles");
    }

    #[test]
    fn platform_budget_over_one() {
        let err = error_after(PLATFORM_FILE, "cpu_budget = 0.8", "cpu_budget = 1.5");
        assert_eq!(err.entry, "cpu_budget");
    }

    #[test]
    fn platform_thresholds_must_increase() {
        let err = error_after(
            PLATFORM_FILE,
            "cpu_thresholds = [0.3, 0.8]",
            "cpu_thresholds = [0.8, 0.3]",
        );
        assert_eq!(err.entry, "cpu_thresholds[1]");
    }

    #[test]
    fn platform_negative_reconfiguration_time() {
        let err = error_after(
            PLATFORM_FILE,
            "reconfiguration_ms_per_tile = 20.0",
            "reconfiguration_ms_per_tile = -1.0",
        );
        assert_eq!(err.entry, "reconfiguration_ms_per_tile");
    }

    #[test]
    fn platform_bad_performance_parameter() {
        let err = error_after(PLATFORM_FILE, "window_m = 1.155", "window_m = 0.0");
        assert_eq!(err.entry, "performance.tracking.window_m");
    }

    #[test]
    fn variant_more_tiles_than_the_platform() {
        // V2 F (the 9th variant) uses 4 tiles.
        let err = error_after(
            VARIANTS_FILE,
            "ms = [7.0]\ntiles = 4",
            "ms = [7.0]\ntiles = 5",
        );
        assert_eq!(err.entry, "variant[8].tiles");
        assert!(err.reason.contains("platform has 4"), "{err}");
    }

    #[test]
    fn variant_negative_ms() {
        let err = error_after(
            VARIANTS_FILE,
            "ms = [285.0]\ntiles = 0",
            "ms = [-285.0]\ntiles = 0",
        );
        assert_eq!(err.entry, "variant[0].ms[0]");
    }

    #[test]
    fn variant_software_with_tiles() {
        let err = error_after(
            VARIANTS_FILE,
            "ms = [730.0]\ntiles = 0",
            "ms = [730.0]\ntiles = 1",
        );
        assert_eq!(err.entry, "variant[6].tiles");
    }

    #[test]
    fn variant_sw_hw_without_a_hw_part() {
        let err = error_after(
            VARIANTS_FILE,
            "parts = [\"HW\", \"SW\"]",
            "parts = [\"SW\", \"SW\"]",
        );
        assert_eq!(err.entry, "variant[4].parts");
    }

    #[test]
    fn variant_duplicate_implementation() {
        let err = error_after(
            VARIANTS_FILE,
            "version = \"fusion\"\ndescription = \"IR + ultrasonic sensor fusion\"",
            "version = \"lidar\"\ndescription = \"IR + ultrasonic sensor fusion\"",
        );
        assert_eq!(err.entry, "variant[23].implementation");
    }

    #[test]
    fn variant_unknown_support_label() {
        let err = error_after(
            VARIANTS_FILE,
            "support = \"SW-HW\"\nms = [30.0, 10.0]",
            "support = \"GPU\"\nms = [30.0, 10.0]",
        );
        assert!(err.entry.starts_with("line "), "{err}");
        assert!(err.reason.contains("GPU"), "{err}");
    }

    #[test]
    fn policy_unknown_app() {
        let err = error_after(
            POLICIES_FILE,
            "priority = [\"obstacle_detection\", \"obstacle_avoidance\", \"landing_search\"",
            "priority = [\"obstacle_detection\", \"obstacle_avoidance\", \"landing_serch\"",
        );
        assert_eq!(err.entry, "safety.priority[2]");
        assert!(err.reason.contains("landing_serch"), "{err}");
    }

    #[test]
    fn policy_app_not_ranked() {
        let err = error_after(
            POLICIES_FILE,
            ", \"path_planning\", \"tracking\"]",
            ", \"tracking\"]",
        );
        assert_eq!(err.entry, "safety.priority");
        assert!(err.reason.contains("path_planning"), "{err}");
    }

    #[test]
    fn policy_app_ranked_twice() {
        let err = error_after(
            POLICIES_FILE,
            "\"path_planning\", \"tracking\"]",
            "\"tracking\", \"tracking\"]",
        );
        assert_eq!(err.entry, "safety.priority[4]");
    }

    #[test]
    fn policy_unknown_degrade_version() {
        // The shipped policies have no degradation paths; an optional one is still validated.
        let err = error_after(
            POLICIES_FILE,
            "\n[mission]\n",
            "\n[safety.degrade.tracking]\nV3 = [\"V7\"]\n\n[mission]\n",
        );
        assert_eq!(err.entry, "safety.degrade.tracking.V3[0]");
    }

    #[test]
    fn policy_unknown_degrade_app() {
        let err = error_after(
            POLICIES_FILE,
            "\n[mission]\n",
            "\n[safety.degrade.trackin]\nV3 = [\"V1\"]\n\n[mission]\n",
        );
        assert_eq!(err.entry, "safety.degrade.trackin");
    }

    #[test]
    fn no_policy_at_all() {
        let (_dir, path) = with_file(POLICIES_FILE, "# nothing\n");
        let err = ResourceSpec::load(&path).unwrap_err();
        assert_eq!(err.reason, "no resource policy defined");
    }

    #[test]
    fn unknown_policy_name() {
        let err = real().policy("reckless").unwrap_err();
        assert_eq!(err.entry, "reckless");
        assert!(err.reason.contains("mission, safety"), "{err}");
    }

    #[test]
    fn record_and_observations_from_the_vibration_event() {
        let spec = real();
        let mut state = PlatformState::new(&spec.platform);
        state.fail_tile(3);
        let reqs = [
            Request::new("tracking", "V3", 25.0),
            Request::new("obstacle_detection", "lidar", 10.0),
            Request::new("landing_search", "emergency", 5.0),
        ];
        let (s, _) = spec.schedule("safety", &state, &reqs).unwrap();
        let rec = to_record(&s);
        // No degradation path in the shipped policies: tracking, ranked last under safety, gives
        // way (the decision core then re-solves the tracking MDP); obstacle detection and the
        // emergency search (F, 2 tiles, for 5 fps) run.
        assert_eq!(rec.summary, "5 + 7 ms");
        assert!(rec.degraded.is_empty(), "{:?}", rec.degraded);
        assert_eq!(rec.dropped.len(), 1);
        let d = &rec.dropped[0];
        assert_eq!(
            (d.app.as_str(), d.version.as_str()),
            ("tracking", "V3"),
            "{d}"
        );
        assert!(
            d.reason.starts_with("insufficient resources")
                && d.reason.contains("policy safety ranks tracking 5 of 5"),
            "{d}"
        );
        assert_eq!(
            (rec.tiles_used, rec.free_tiles, rec.failed_tiles.clone()),
            (2, 1, vec![3])
        );
        // Two tiles newly configured from a blank board: 2 x 20 ms.
        assert_eq!(rec.reconfigurations, 2);
        assert_eq!(rec.reconfiguration_ms, 40.0);
        // CPU: lidar 5 ms x 10 fps = 50 ms/s over 2 cores.
        let mut obs = Observations::default();
        observations(&s).apply(&mut obs);
        assert_eq!(obs.get("free_tiles"), Some(1.0));
        assert!((obs.get("cpu_load").unwrap() - 0.025).abs() < 1e-12);
        // Power: 2.5 W + 2 tiles x 0.4 W + 1.2 W x 0.025.
        assert!((rec.power_w - (2.5 + 0.8 + 1.2 * 0.025)).abs() < 1e-12);
        // The record round-trips through JSON.
        let back: ResourcesRecord =
            serde_json::from_value(serde_json::to_value(&rec).unwrap()).unwrap();
        assert_eq!(back, rec);
    }

    /// The reusing paths (`schedule_into` with one workspace, `to_record_into` over the previous
    /// record) give what the allocating ones give, whatever was in the buffers before: a
    /// sequence with more, fewer and different placements, degradations and drops.
    #[test]
    fn reused_schedule_and_record_equal_fresh_ones() {
        let spec = real();
        let full = vec![
            Request::new("tracking", "V3", 25.0),
            Request::new("landing_search", "emergency", 5.0),
            Request::new("obstacle_detection", "lidar", 10.0),
            Request::new("obstacle_avoidance", "right_turn", 1.0),
            Request::new("path_planning", "ga", 0.5),
        ];
        let mut ws = fpga_model::ScheduleWorkspace::new();
        let mut out = Schedule::default();
        let mut next = PlatformState::default();
        let mut rec = ResourcesRecord::default();
        let mut state = PlatformState::new(&spec.platform);
        let cases: [(usize, u8, &str); 6] = [
            (5, 0, "safety"),
            (5, 3, "mission"),
            (1, 0, "safety"),
            (5, 2, "safety"),
            (0, 1, "mission"),
            (3, 4, "safety"),
        ];
        for (n, failed, policy) in cases {
            let mut st = state.clone();
            for t in 0..failed {
                st.fail_tile(t);
            }
            let (want, want_next) = spec.schedule(policy, &st, &full[..n]).unwrap();
            spec.schedule_into(policy, &st, &full[..n], &mut ws, &mut out, &mut next)
                .unwrap();
            assert_eq!(out, want, "{n} requests, {failed} failed, {policy}");
            assert_eq!(next, want_next);
            to_record_into(&out, &mut rec);
            assert_eq!(rec, to_record(&want));
            state = next.clone();
        }
        assert!(
            spec.schedule_into("reckless", &state, &full, &mut ws, &mut out, &mut next)
                .is_err()
        );
    }
}
