//! [`MdpBuilder`]: collects choices in any order and lays them out as an [`Mdp`].

use crate::model::{ActionId, Mdp, MdpError, NONE, StateId, uniform_successors};

/// (state, action, reward, transitions) as given to [`MdpBuilder::choice`].
type PendingChoice = (usize, usize, f64, Vec<(usize, f64)>);

/// Collects choices in any order, then builds an [`Mdp`].
#[derive(Debug, Clone)]
pub struct MdpBuilder {
    n_states: usize,
    n_actions: usize,
    choices: Vec<PendingChoice>,
}

impl MdpBuilder {
    /// An empty builder for `n_states` states and actions `0..n_actions`.
    pub fn new(n_states: usize, n_actions: usize) -> Self {
        Self {
            n_states,
            n_actions,
            choices: Vec::new(),
        }
    }

    /// Make `action` admissible in `state` with reward `reward` and transitions `(next, p)`.
    /// Transitions keep the given order (callers may rely on it to overwrite probabilities).
    pub fn choice(
        &mut self,
        state: StateId,
        action: ActionId,
        reward: f64,
        transitions: &[(StateId, f64)],
    ) -> &mut Self {
        self.choices
            .push((state, action, reward, transitions.to_vec()));
        self
    }

    /// Check indices and duplicates, lay out the storage and [`Mdp::validate`] it.
    pub fn build(self) -> Result<Mdp, MdpError> {
        let mdp = self.build_unchecked()?;
        mdp.validate()?;
        Ok(mdp)
    }

    /// Like [`MdpBuilder::build`] but without checking probabilities and rewards, for callers that
    /// fill them in afterwards (then call [`Mdp::validate`]).
    pub fn build_unchecked(mut self) -> Result<Mdp, MdpError> {
        let n_states = self.n_states;
        let n_actions = self.n_actions;
        let total: usize = self.choices.iter().map(|c| c.3.len()).sum();
        if n_states >= NONE as usize
            || n_actions >= NONE as usize
            || self.choices.len() >= NONE as usize
            || total >= NONE as usize
        {
            return Err(MdpError::TooLarge);
        }
        for (s, a, _, tr) in &self.choices {
            if *s >= n_states {
                return Err(MdpError::StateOutOfRange {
                    state: *s,
                    n_states,
                });
            }
            if *a >= n_actions {
                return Err(MdpError::ActionOutOfRange {
                    action: *a,
                    n_actions,
                });
            }
            if tr.is_empty() {
                return Err(MdpError::NoTransition {
                    state: *s,
                    action: *a,
                });
            }
            for (i, (n, _)) in tr.iter().enumerate() {
                if *n >= n_states {
                    return Err(MdpError::StateOutOfRange {
                        state: *n,
                        n_states,
                    });
                }
                if tr[..i].iter().any(|(m, _)| m == n) {
                    return Err(MdpError::DuplicateNext {
                        state: *s,
                        action: *a,
                        next: *n,
                    });
                }
            }
        }
        self.choices.sort_by_key(|c| (c.0, c.1));
        for w in self.choices.windows(2) {
            if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
                return Err(MdpError::DuplicateChoice {
                    state: w[0].0,
                    action: w[0].1,
                });
            }
        }
        let mut mdp = Mdp {
            n_actions,
            state_start: Vec::with_capacity(n_states + 1),
            choice_action: Vec::with_capacity(self.choices.len()),
            choice_reward: Vec::with_capacity(self.choices.len()),
            choice_start: Vec::with_capacity(self.choices.len() + 1),
            next: Vec::with_capacity(total),
            prob: Vec::with_capacity(total),
            uniform_successors: 0,
        };
        let mut c = 0;
        for s in 0..n_states {
            mdp.state_start.push(mdp.choice_action.len() as u32);
            while c < self.choices.len() && self.choices[c].0 == s {
                let (_, a, r, tr) = &self.choices[c];
                mdp.choice_action.push(*a as u32);
                mdp.choice_reward.push(*r);
                mdp.choice_start.push(mdp.next.len() as u32);
                for (n, p) in tr {
                    mdp.next.push(*n as u32);
                    mdp.prob.push(*p);
                }
                c += 1;
            }
        }
        mdp.state_start.push(mdp.choice_action.len() as u32);
        mdp.choice_start.push(mdp.next.len() as u32);
        mdp.uniform_successors = uniform_successors(&mdp.choice_start);
        Ok(mdp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builder_rejects_bad_input() {
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(1, 0.5)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::RowSum {
                state: 0,
                action: 0,
                ..
            })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(2, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::StateOutOfRange { state: 2, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 1, 0.0, &[(1, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::ActionOutOfRange { action: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[(1, 1.0)])
            .choice(0, 0, 0.0, &[(1, 1.0)]);
        assert!(matches!(b.build(), Err(MdpError::DuplicateChoice { .. })));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(0, 0, 0.0, &[]);
        assert!(matches!(b.build(), Err(MdpError::NoTransition { .. })));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, 0.0, &[(0, 1.5), (1, -0.5)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::BadProbability { state: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, f64::NAN, &[(0, 1.0)]);
        assert!(matches!(
            b.build(),
            Err(MdpError::BadReward { state: 1, .. })
        ));
        let mut b = MdpBuilder::new(2, 1);
        b.choice(1, 0, 0.0, &[(0, 0.5), (0, 0.5)]);
        assert!(matches!(b.build(), Err(MdpError::DuplicateNext { .. })));
    }
}
