//! Raw observations to BN evidence: each observation names a node and ordered thresholds
//! (params/observations.toml). A value `v` maps to `states[i]` where `i` counts the thresholds
//! `t <= v` (a value on a threshold goes to the upper state). A missing or non-finite value puts
//! no evidence on its node.
//!
//! Observation names are interned at load: each observation of the file gets an
//! [`ObservationId`] (its position in the file), and the per-cycle evidence path works on ids
//! (the caller's computed values come as ids, resolved once; the snapshot is read in one ordered
//! pass instead of one lookup per name).

use crate::named_slots::{Label, NamedSlots, SortedNames};
use crate::observations::Observations;
use crate::spec::{SpecError, read_toml};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObservationsFile {
    #[serde(default)]
    observation: Vec<ObservationSpec>,
}

/// An observation of params/observations.toml, interned at load: its position in
/// [`ObservationMap::observations`]. Only a map's own [`ObservationMap::id`] makes one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ObservationId(u16);

impl ObservationId {
    /// Position of the observation in its map's `observations`.
    pub fn index(self) -> usize {
        usize::from(self.0)
    }
}

/// Most observations params/observations.toml may declare (ids are `u16`).
pub const MAX_OBSERVATIONS: usize = u16::MAX as usize;

/// Observations the decision core reads itself, besides the evidence mapping: the platform
/// model's inputs (failed tiles, CPU load from other processes) and the activity of the route
/// being flown, reported by the shell.
pub const CORE_READS: [&str; 3] = [FAILED_TILES, EXTERNAL_CPU_LOAD, ROUTE_ACTIVITY];
/// Index (flight order, 0-based) of the guarantee's activity being flown, from the route's
/// progress (fly: the mission item and the position; simulate: the world's phase). Present, it
/// is the activity the guarantee watches; absent or not an activity's index, the core falls back
/// to params/mission.toml's `guarantee.activity_of_state`.
pub const ROUTE_ACTIVITY: &str = "route_activity";
/// Tiles out of service (count), an input of the core's platform model.
pub const FAILED_TILES: &str = "failed_tiles";
/// CPU share taken by processes outside the companion, an input of the core's platform model.
pub const EXTERNAL_CPU_LOAD: &str = "external_cpu_load";

/// Observations the decision core computes itself from its platform model (the room left beside
/// the other applications, the rate the assessed application needs) and puts in the evidence in
/// place of the snapshot's values.
pub const CORE_COMPUTES: [&str; 3] = [FREE_TILES, CPU_HEADROOM, TRACKING_FPS];
/// Healthy tiles left beside the other applications (count), computed by the core.
pub const FREE_TILES: &str = "free_tiles";
/// CPU share left beside the other applications and external load, computed by the core.
pub const CPU_HEADROOM: &str = "cpu_headroom";
/// Frame rate the assessed application needs now, computed by the core.
pub const TRACKING_FPS: &str = "tracking_fps";

/// One observation and how it discretises.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    /// Observation name, the key in `Observations.values` (`wind_mps`).
    pub name: String,
    /// Unit of the value (`m/s`, `%`, `lx`, ...), for display.
    #[serde(default)]
    pub unit: String,
    /// The BN node (in any health manager) that receives the evidence.
    pub node: String,
    /// Strictly increasing; `states.len() == thresholds.len() + 1`.
    pub thresholds: Vec<f64>,
    /// The node's state for each interval between thresholds, in value order.
    pub states: Vec<String>,
    /// Free text from the file.
    #[serde(default)]
    pub description: String,
}

impl ObservationSpec {
    /// The state a value falls in.
    pub fn state(&self, value: f64) -> Option<&str> {
        self.state_index(value).map(|i| self.states[i].as_str())
    }

    /// The index in `states` of the state a value falls in.
    pub fn state_index(&self, value: f64) -> Option<usize> {
        if !value.is_finite() {
            return None;
        }
        Some(self.thresholds.iter().filter(|&&t| t <= value).count())
    }
}

/// A cycle's evidence by observation: the state index each observation's value fell in (None:
/// no value, or not finite), indexed by [`ObservationId`]. The core keeps one between cycles.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EvidenceStates {
    /// Per observation id.
    pub state: Vec<Option<u16>>,
}

/// The validated observation mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservationMap {
    /// File the mapping was read from (params/observations.toml).
    pub file: PathBuf,
    /// Every observation mapped to evidence, in file order; an [`ObservationId`] indexes it.
    pub observations: Vec<ObservationSpec>,
    /// The ids sorted by name: name lookups at load, and the ordered pass over a snapshot.
    by_name: Vec<ObservationId>,
    /// The ids sorted by node name: the order of the evidence map's keys.
    by_node: Vec<ObservationId>,
    /// The nodes' names, sorted: the names the record's evidence is written over.
    node_names: SortedNames,
    /// Per observation id: its node's slot in `node_names`.
    node_slot: Vec<usize>,
    /// Per observation id: its states' names, compiled once (the record's evidence holds them).
    labels: Vec<Vec<Label>>,
}

impl ObservationMap {
    /// Read and validate the mapping at `path`.
    pub fn load(params: &crate::spec::ParamsFiles, path: &Path) -> Result<Self, SpecError> {
        let f: ObservationsFile = read_toml(params, path)?;
        if f.observation.is_empty() {
            return Err(SpecError::new(
                path,
                "observation",
                "no observations: the health managers would never receive evidence",
            ));
        }
        Self::new(path, f.observation)
    }

    /// Validate: unique names, one observation per node, thresholds strictly increasing and
    /// finite, one more state than thresholds.
    pub fn new(file: &Path, observations: Vec<ObservationSpec>) -> Result<Self, SpecError> {
        if observations.len() > MAX_OBSERVATIONS {
            return Err(SpecError::new(
                file,
                "observation",
                format!(
                    "{} observations: at most {MAX_OBSERVATIONS}",
                    observations.len()
                ),
            ));
        }
        let mut names = BTreeMap::new();
        let mut nodes = BTreeMap::new();
        for (i, o) in observations.iter().enumerate() {
            let entry = |k: &str| format!("observation[{i}]({}).{k}", o.name);
            if names.insert(o.name.clone(), i).is_some() {
                return Err(SpecError::new(
                    file,
                    entry("name"),
                    "duplicate observation name",
                ));
            }
            if let Some(j) = nodes.insert(o.node.clone(), i) {
                return Err(SpecError::new(
                    file,
                    entry("node"),
                    format!("node `{}` already receives observation[{j}]", o.node),
                ));
            }
            if let Some(t) = o.thresholds.iter().find(|t| !t.is_finite()) {
                return Err(SpecError::new(
                    file,
                    entry("thresholds"),
                    format!("{t} is not finite"),
                ));
            }
            if let Some(w) = o.thresholds.windows(2).find(|w| w[0] >= w[1]) {
                return Err(SpecError::new(
                    file,
                    entry("thresholds"),
                    format!(
                        "thresholds out of order: {} then {} (must strictly increase)",
                        w[0], w[1]
                    ),
                ));
            }
            if o.states.len() != o.thresholds.len() + 1 {
                return Err(SpecError::new(
                    file,
                    entry("states"),
                    format!(
                        "{} states for {} thresholds (need one more state)",
                        o.states.len(),
                        o.thresholds.len()
                    ),
                ));
            }
        }
        // `names` is sorted by name and holds each index once (duplicates were refused above).
        let by_name = names
            .into_values()
            .map(|i| ObservationId(i as u16))
            .collect();
        let node_names: SortedNames = nodes.keys().cloned().collect::<Vec<_>>().into();
        let by_node: Vec<ObservationId> = nodes
            .into_values()
            .map(|i| ObservationId(i as u16))
            .collect();
        let mut node_slot = vec![0; observations.len()];
        for (k, id) in by_node.iter().enumerate() {
            node_slot[id.index()] = k;
        }
        let labels = (observations.iter())
            .map(|o| o.states.iter().map(|s| Label::from(s.as_str())).collect())
            .collect();
        Ok(Self {
            file: file.to_path_buf(),
            observations,
            by_name,
            by_node,
            node_names,
            node_slot,
            labels,
        })
    }

    /// The id of the observation named `name`, if the file declares it.
    pub fn id(&self, name: &str) -> Option<ObservationId> {
        self.by_name
            .binary_search_by(|id| self.observations[id.index()].name.as_str().cmp(name))
            .ok()
            .map(|k| self.by_name[k])
    }

    /// Every observation's id, in the order of their nodes' names (the evidence map's order).
    pub fn by_node(&self) -> impl Iterator<Item = ObservationId> + '_ {
        self.by_node.iter().copied()
    }

    /// The observation an id of this map names.
    pub fn spec(&self, id: ObservationId) -> &ObservationSpec {
        &self.observations[id.index()]
    }

    /// The mapping of the observation named `name`.
    pub fn get(&self, name: &str) -> Option<&ObservationSpec> {
        self.id(name).map(|id| self.spec(id))
    }

    /// Evidence (node -> state) for every observation present in the snapshot.
    pub fn evidence(&self, obs: &Observations) -> BTreeMap<String, String> {
        let mut out = BTreeMap::new();
        self.evidence_into(obs, &mut out);
        out
    }

    /// As [`ObservationMap::evidence`], into the caller's map. When the same nodes get evidence
    /// as last time (the steady state) the entries are rewritten in place and nothing is
    /// allocated once every state name has fitted in its entry.
    pub fn evidence_into(&self, obs: &Observations, out: &mut BTreeMap<String, String>) {
        self.evidence_with_into(obs, &[], out)
    }

    /// As [`ObservationMap::evidence_into`], with `extra` (name, value) pairs taking the place
    /// of the snapshot's values of those names (values the caller computes itself). Names the
    /// file does not declare are ignored.
    pub fn evidence_with_into(
        &self,
        obs: &Observations,
        extra: &[(&str, f64)],
        out: &mut BTreeMap<String, String>,
    ) {
        // Resolved once per call; a caller passes a handful (the core's three).
        let mut ids = [(ObservationId(0), 0.0); 8];
        let mut n = 0;
        for &(name, v) in extra {
            if let Some(id) = self.id(name) {
                if n == ids.len() {
                    // More than fit on the stack: the slow path, same result.
                    let all: Vec<(ObservationId, f64)> = extra
                        .iter()
                        .filter_map(|&(name, v)| Some((self.id(name)?, v)))
                        .collect();
                    return self.evidence_with_ids_into(obs, &all, out);
                }
                ids[n] = (id, v);
                n += 1;
            }
        }
        self.evidence_with_ids_into(obs, &ids[..n], out)
    }

    /// The values of every declared observation this cycle, by id in name order: `extra` first
    /// (the first entry of an id wins), else the snapshot's.
    fn values_by_id(
        &self,
        obs: &Observations,
        extra: &[(ObservationId, f64)],
        mut f: impl FnMut(ObservationId, f64),
    ) {
        for &id in &self.by_name {
            let value = extra
                .iter()
                .find(|(x, _)| *x == id)
                .map(|&(_, v)| v)
                .or_else(|| obs.get(&self.observations[id.index()].name));
            if let Some(v) = value {
                f(id, v);
            }
        }
    }

    /// As [`ObservationMap::evidence_with_into`], with the caller's values given by id.
    pub fn evidence_with_ids_into(
        &self,
        obs: &Observations,
        extra: &[(ObservationId, f64)],
        out: &mut BTreeMap<String, String>,
    ) {
        let mut states = EvidenceStates::default();
        self.evidence_states_into(obs, extra, &mut states, out);
    }

    /// As [`ObservationMap::evidence_with_ids_into`], also giving each observation's state
    /// index in `states` (kept by the caller: nothing is allocated once warm). When the same
    /// nodes get evidence as last time, `out`'s entries are rewritten in place, walked in key
    /// order beside the observations sorted by node (no lookups).
    pub fn evidence_states_into(
        &self,
        obs: &Observations,
        extra: &[(ObservationId, f64)],
        states: &mut EvidenceStates,
        out: &mut BTreeMap<String, String>,
    ) {
        let st = &mut states.state;
        st.clear();
        st.resize(self.observations.len(), None);
        let mut n = 0;
        self.values_by_id(obs, extra, |id, v| {
            st[id.index()] = self.spec(id).state_index(v).map(|i| i as u16);
            n += usize::from(st[id.index()].is_some());
        });
        self.write_states(st, n, out);
    }

    /// As [`ObservationMap::evidence_states_into`], with the snapshot's values already read by
    /// observation id (`values[id.index()]`, e.g. the first slots of a
    /// [`crate::readings::Readings`] started with [`ObservationMap::names`]).
    pub fn evidence_states_from_into(
        &self,
        values: &[Option<f64>],
        extra: &[(ObservationId, f64)],
        states: &mut EvidenceStates,
        out: &mut NamedSlots<Label>,
    ) {
        let st = &mut states.state;
        st.clear();
        for (k, o) in self.observations.iter().enumerate() {
            let id = ObservationId(k as u16);
            let value = extra
                .iter()
                .find(|(x, _)| *x == id)
                .map(|&(_, v)| v)
                .or(values.get(k).copied().flatten());
            let s = value.and_then(|v| o.state_index(v)).map(|i| i as u16);
            st.push(s);
        }
        self.write_evidence(st, out);
    }

    /// The evidence by node slot from the states by observation (the record's form: the
    /// state's label shared, no string copied).
    pub fn write_evidence(&self, st: &[Option<u16>], out: &mut NamedSlots<Label>) {
        out.reset_over(&self.node_names);
        for (i, s) in st.iter().enumerate() {
            if let Some(s) = s {
                out.set(self.node_slot[i], self.labels[i][usize::from(*s)].clone());
            }
        }
    }

    /// The evidence map from the states by observation (`n` of them given): rewritten in place
    /// when it holds the same nodes, else rebuilt.
    fn write_states(&self, st: &[Option<u16>], n: usize, out: &mut BTreeMap<String, String>) {
        if n == out.len() {
            let mut present = self
                .by_node
                .iter()
                .filter_map(|&id| Some((id, st[id.index()]?)));
            let same = out.iter_mut().all(|(node, state)| match present.next() {
                Some((id, s)) => {
                    let o = self.spec(id);
                    let s = o.states[usize::from(s)].as_str();
                    if *node != o.node {
                        return false;
                    }
                    if state != s {
                        state.clear();
                        state.push_str(s);
                    }
                    true
                }
                None => false,
            });
            if same {
                return;
            }
        }
        out.clear();
        for (i, s) in st.iter().enumerate() {
            if let Some(s) = s {
                let o = &self.observations[i];
                out.insert(o.node.clone(), o.states[usize::from(*s)].clone());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> ObservationMap {
        let files = crate::shipped::params();
        ObservationMap::load(&files, &files.dir().join("observations.toml")).unwrap()
    }

    #[test]
    fn observation_names_are_interned_in_file_order_and_found_by_name() {
        let m = map();
        for (i, o) in m.observations.iter().enumerate() {
            let id = m.id(&o.name).unwrap();
            assert_eq!(id.index(), i, "{}", o.name);
            assert_eq!(m.spec(id).name, o.name);
        }
        assert_eq!(m.id("no_such_observation"), None);
        assert_eq!(m.get("wind_mps").unwrap().node, "A_wind");
    }

    #[test]
    fn evidence_reads_the_snapshot_and_the_callers_values_by_id() {
        let m = map();
        let mut obs = Observations::default();
        obs.set("wind_mps", 12.0);
        obs.set("aaa_unknown", 1.0);
        obs.set("zzz_unknown", 1.0);
        obs.set("vibration_mps2", 3.0);
        obs.set("free_tiles", 4.0);
        let mut out = BTreeMap::new();
        // The caller's value replaces the snapshot's; an undeclared name is ignored.
        m.evidence_with_into(&obs, &[("free_tiles", 0.0), ("nothing", 1.0)], &mut out);
        let want: BTreeMap<String, String> = [
            ("A_wind", "strong"),
            ("A_vibration", "low"),
            ("A_free_tiles", "0"),
        ]
        .into_iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
        assert_eq!(out, want);
        // Again into the same map, with a node gone: exactly the new evidence.
        obs.values.remove("wind_mps");
        m.evidence_with_into(&obs, &[("free_tiles", 0.0)], &mut out);
        assert_eq!(out.len(), 2);
        assert!(!out.contains_key("A_wind"));
        // More caller values than the stack holds: same result.
        let many: Vec<(&str, f64)> = std::iter::repeat_n(("free_tiles", 0.0), 12).collect();
        let mut again = BTreeMap::new();
        m.evidence_with_into(&obs, &many, &mut again);
        assert_eq!(again, out);
    }

    /// The core's path (the snapshot read into slots first, `Readings`) gives the evidence the
    /// snapshot path gives, states and map alike, over random snapshots: values on, just off
    /// and beyond thresholds, absent, NaN, undeclared names, and caller values replacing some.
    #[test]
    fn evidence_from_read_values_equals_evidence_from_the_snapshot() {
        let m = map();
        let mut readings = crate::readings::Readings::starting_with(
            m.observations.iter().map(|o| o.name.as_str()),
        );
        let mut seed: u64 = 0x8f1b_bcdc_bf6d_4e2a;
        let mut next = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            seed >> 33
        };
        let (mut want_states, mut got_states) =
            (EvidenceStates::default(), EvidenceStates::default());
        let (mut want, mut got) = (BTreeMap::new(), NamedSlots::default());
        for cycle in 0..300 {
            let mut obs = Observations::default();
            for o in &m.observations {
                let v = match next() % 6 {
                    0 => continue,
                    1 => f64::NAN,
                    k => o
                        .thresholds
                        .get(k as usize % (o.thresholds.len() + 1))
                        .map_or(1e9, |t| t + [0.0, -1e-9, 1e-9][(next() % 3) as usize]),
                };
                obs.set(&o.name, v);
            }
            obs.set("zz_undeclared", 1.0);
            let extra: Vec<(ObservationId, f64)> = (0..next() % 3)
                .map(|_| {
                    let id = ObservationId((next() as usize % m.observations.len()) as u16);
                    (id, (next() % 5) as f64)
                })
                .collect();
            m.evidence_states_into(&obs, &extra, &mut want_states, &mut want);
            readings.read(&obs);
            m.evidence_states_from_into(readings.values(), &extra, &mut got_states, &mut got);
            assert_eq!(want_states, got_states, "cycle {cycle}");
            let got: BTreeMap<String, String> = got
                .iter()
                .map(|(k, v)| (k.clone(), v.to_string()))
                .collect();
            assert_eq!(want, got, "cycle {cycle}");
        }
    }
}
