//! One manager evaluated again within a cycle (the resource manager, once the placements
//! changed the room it observes): by observation for the cycle, by name for the tests and tools.

use super::{HealthError, HealthModel, NamedSlots, state_of};
use bayes_net::Evidence;
use std::collections::BTreeMap;

impl HealthModel {
    /// As [`HealthModel::reevaluate_manager_into`], the manager at `index` under the evidence by
    /// observation (the cycle's path: no name looked up), its published probabilities updated
    /// in `out` by slot.
    pub fn reevaluate_manager_states_into(
        &mut self,
        index: usize,
        states: &crate::evidence::EvidenceStates,
        out: &mut NamedSlots<f64>,
    ) -> Result<(), HealthError> {
        if index >= self.managers.len() {
            return Ok(());
        }
        let mut ev = Evidence::new();
        for id in self.observations.by_node() {
            let Some(Some(s)) = states.state.get(id.index()) else {
                continue;
            };
            for &(mi, node, st) in &self.observation_hits[id.index()][usize::from(*s)] {
                if mi == index {
                    ev.set_state(node, st);
                }
            }
        }
        self.requery_manager(index, &ev)?;
        let m = &self.managers[index];
        for (j, &(_, id, s, complement)) in m.published.iter().enumerate() {
            let p = m.engine.marginal(id)[s];
            out.set(
                self.publish_slots[index][j],
                if complement { 1.0 - p } else { p },
            );
        }
        Ok(())
    }

    /// The manager at `index` queried under `ev` (its imported priors as the last evaluation
    /// left them); its marginals then no longer match the evidence the next cycle compares.
    fn requery_manager(&mut self, index: usize, ev: &Evidence) -> Result<(), HealthError> {
        let m = &mut self.managers[index];
        m.engine.query(ev).map_err(|error| HealthError::Inference {
            manager: m.name.clone(),
            error,
        })?;
        if let Some(f) = self.scratch.fresh.get_mut(index) {
            *f = false;
        }
        Ok(())
    }

    /// Evaluate one manager again under `evidence` (its imported priors as the last evaluation
    /// left them) and update its published probabilities in `out`. The dynamic managers do not
    /// advance: the decision core uses it within a cycle, when a placement changed what the
    /// resource manager observes. Unknown manager: nothing changes.
    pub fn reevaluate_manager_into(
        &mut self,
        name: &str,
        evidence: &BTreeMap<String, String>,
        out: &mut BTreeMap<String, f64>,
    ) -> Result<(), HealthError> {
        let Some(i) = self.managers.iter().position(|m| m.name == name) else {
            return Ok(());
        };
        let m = &mut self.managers[i];
        let mut ev = Evidence::new();
        for (node, state) in evidence {
            let net = m.engine.network();
            if let Some(id) = net.id(node) {
                ev.set_state(id, state_of(net, id, node, state)?);
            }
        }
        self.requery_manager(i, &ev)?;
        let m = &self.managers[i];
        for &(k, id, s, complement) in &m.published {
            let p = m.engine.marginal(id)[s];
            let p = if complement { 1.0 - p } else { p };
            match out.get_mut(m.publish[k].name.as_str()) {
                Some(x) => *x = p,
                None => {
                    out.insert(m.publish[k].name.clone(), p);
                }
            }
        }
        Ok(())
    }
}
