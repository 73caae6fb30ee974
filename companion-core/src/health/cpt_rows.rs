//! Reading and setting one CPT row of a health manager's network: the in-flight learning of the
//! rows `companion calibrate` counts (`--learn-cpt`, docs/calibrate.md), set as an `override` row
//! would be at load.

use super::{HealthError, HealthModel};

impl HealthModel {
    /// The CPT rows of `node` whose parents are in the states `when` names (parents it does
    /// not name: every state), as (row index, probabilities); `None` when no manager has a
    /// node of that name with those parents and states. The first manager defining it answers.
    fn cpt_rows(&self, node: &str, when: &[(String, String)]) -> Option<(usize, Vec<usize>)> {
        self.managers.iter().enumerate().find_map(|(mi, m)| {
            let net = m.engine.network();
            let n = net.node(net.id(node)?);
            let parents: Vec<&bayes_net::Node> = n.parents.iter().map(|&p| net.node(p)).collect();
            let mut fixed = Vec::with_capacity(when.len());
            for (p, st) in when {
                let pos = parents.iter().position(|q| &q.name == p)?;
                fixed.push((pos, parents[pos].states.iter().position(|x| x == st)?));
            }
            let sizes: Vec<usize> = parents.iter().map(|q| q.states.len()).collect();
            let rows: usize = sizes.iter().product();
            // Row-major, first parent most significant.
            let matching = (0..rows)
                .filter(|&r| {
                    fixed.iter().all(|&(pos, s)| {
                        let below: usize = sizes[pos + 1..].iter().product();
                        (r / below) % sizes[pos] == s
                    })
                })
                .collect();
            Some((mi, matching))
        })
    }

    /// The first CPT row of `node` matching `when` (parent -> state), as loaded or as last set
    /// by [`HealthModel::set_cpt_row`]; `None` when no manager has such a node and row.
    pub fn cpt_row(&self, node: &str, when: &[(String, String)]) -> Option<Vec<f64>> {
        let (mi, rows) = self.cpt_rows(node, when)?;
        let net = self.managers[mi].engine.network();
        let n = net.node(net.id(node)?);
        let k = n.states.len();
        let r = *rows.first()?;
        Some(n.cpt[r * k..(r + 1) * k].to_vec())
    }

    /// Set every CPT row of `node` matching `when` to `p` (one probability per state): the
    /// in-flight learning of a row (docs/calibrate.md), as an `override` row would at load.
    pub fn set_cpt_row(
        &mut self,
        node: &str,
        when: &[(String, String)],
        p: &[f64],
    ) -> Result<(), HealthError> {
        let (mi, rows) = self
            .cpt_rows(node, when)
            .ok_or_else(|| HealthError::UnknownNode(node.to_string()))?;
        let m = &mut self.managers[mi];
        let net = m.engine.network();
        let id = net
            .id(node)
            .ok_or_else(|| HealthError::UnknownNode(node.to_string()))?;
        let k = net.node(id).states.len();
        let mut cpt = net.node(id).cpt.clone();
        for r in rows {
            if p.len() == k {
                cpt[r * k..(r + 1) * k].copy_from_slice(p);
            }
        }
        m.engine
            .set_cpt(id, &cpt)
            .map_err(|error| HealthError::Inference {
                manager: m.name.clone(),
                error,
            })?;
        // The managers' kept marginals were of the old CPT.
        self.scratch.fresh.clear();
        Ok(())
    }
}
