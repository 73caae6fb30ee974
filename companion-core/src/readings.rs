//! The snapshot's values the cycle reads, by slot. Every name the core reads (the declared
//! observations, the rates, the projection rules', the guarantee's pack and failure readings,
//! the platform's faults) is given a slot when the core starts; each cycle reads the snapshot
//! once, by the vocabulary's slots it is written over, and every stage then reads by index
//! (a name lookup per reading per stage took a sixth of the steady cycle).

use crate::named_slots::SortedNames;
use crate::observations::Observations;
use std::sync::Arc;

/// Where one reading sits among [`Readings`]' values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Slot(u32);

/// The names read, and the values of the last snapshot read.
#[derive(Debug, Clone, Default)]
pub struct Readings {
    /// Names by slot, in the order they were first asked for.
    names: Vec<String>,
    /// The last snapshot's value per slot (`None`: absent from it).
    values: Vec<Option<f64>>,
    /// The vocabulary the last snapshot was written over (`None`: none read yet, or a slot was
    /// added since), and where each slot sits in it: a snapshot over the same vocabulary (the
    /// steady case, one `Arc` from load) is read by index, no name compared.
    vocabulary: Option<SortedNames>,
    in_vocabulary: Vec<Option<usize>>,
}
impl Readings {
    /// Readings whose first slots are `first`, in order (slot `k` is `first[k]`; a repeated name
    /// keeps its first slot).
    pub fn starting_with<'a>(first: impl IntoIterator<Item = &'a str>) -> Self {
        let mut r = Readings::default();
        for name in first {
            r.slot(name);
        }
        r
    }

    /// The slot of `name`, given one if it has none yet.
    pub fn slot(&mut self, name: &str) -> Slot {
        if let Some(k) = self.names.iter().position(|n| n == name) {
            return Slot(k as u32);
        }
        let k = self.names.len() as u32;
        self.names.push(name.to_string());
        self.values.push(None);
        self.vocabulary = None;
        Slot(k)
    }

    /// Read `obs`: every slot's value from the snapshot (`None` when absent): by the slot of
    /// the vocabulary it is written over, else (a name outside it) from its overflow.
    pub fn read(&mut self, obs: &Observations) {
        let values = &obs.values;
        let same = (self.vocabulary.as_ref()).is_some_and(|v| Arc::ptr_eq(v, values.names()));
        if !same {
            self.in_vocabulary.clear();
            (self.in_vocabulary).extend(self.names.iter().map(|n| values.slot_of(n)));
            self.vocabulary = Some(Arc::clone(values.names()));
        }
        let slots = values.slots();
        for (k, at) in self.in_vocabulary.iter().enumerate() {
            self.values[k] = match at {
                Some(j) => slots[*j],
                None if values.overflow().is_empty() => None,
                None => values.get(&self.names[k]).copied(),
            };
        }
    }

    /// The value read at `slot`.
    pub fn get(&self, slot: Slot) -> Option<f64> {
        self.values[slot.0 as usize]
    }

    /// The values read, by slot (the first ones are [`Readings::starting_with`]'s names).
    pub fn values(&self) -> &[Option<f64>] {
        &self.values
    }

    /// The name of `slot`.
    pub fn name(&self, slot: Slot) -> &str {
        &self.names[slot.0 as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::named_slots::sorted_names;
    use crate::observation_values::ObservationValues;
    use proptest::prelude::*;

    proptest! {
        /// Every slot reads what the snapshot's own lookup gives, whatever the names and the
        /// snapshot hold (names asked for in any order, repeated, present or absent).
        #[test]
        fn every_slot_reads_what_the_snapshot_holds(
            asked in proptest::collection::vec("[a-e]{0,3}", 0..30),
            held in proptest::collection::btree_map("[a-e]{0,3}", -5.0f64..5.0, 0..30),
        ) {
            let mut r = Readings::starting_with(asked.iter().take(3).map(String::as_str));
            let slots: Vec<Slot> = asked.iter().map(|n| r.slot(n)).collect();
            let obs = Observations { values: held.into_iter().collect(), ..Default::default() };
            r.read(&obs);
            for (name, &slot) in asked.iter().zip(&slots) {
                prop_assert_eq!(r.name(slot), name.as_str());
                prop_assert_eq!(r.get(slot), obs.get(name));
            }
            // The first names keep the first slots, in order (a repeat keeps its first slot).
            let mut first: Vec<&str> = Vec::new();
            for n in asked.iter().take(3) {
                if !first.contains(&n.as_str()) {
                    first.push(n);
                }
            }
            for (k, name) in first.iter().enumerate() {
                prop_assert_eq!(r.values()[k], obs.get(name));
                prop_assert_eq!(r.slot(name), Slot(k as u32));
            }
            // A second snapshot overwrites the first: absent now is None, not last cycle's.
            r.read(&Observations::default());
            prop_assert!(r.values().iter().all(Option::is_none));
        }

        /// A stream of snapshots, some with the last one's names (read down the remembered
        /// layout), some with others, slots added between reads: every read gives what each
        /// snapshot holds, as a fresh reading reads it.
        #[test]
        fn a_stream_of_snapshots_reads_as_each_alone(
            asked in proptest::collection::vec("[a-d]{1,2}", 0..12),
            added in proptest::collection::vec("[a-d]{1,2}", 0..4),
            shapes in proptest::collection::vec(
                proptest::collection::btree_map("[a-d]{1,2}", -5.0f64..5.0, 0..12), 1..4),
            stream in proptest::collection::vec((0usize..4, -5.0f64..5.0, 0usize..6), 1..20),
            vocabulary in proptest::collection::vec("[a-d]{1,2}", 0..8),
        ) {
            let vocabulary = sorted_names(vocabulary);
            let mut r = Readings::default();
            asked.iter().for_each(|n| { r.slot(n); });
            for (k, &(shape, shift, add)) in stream.iter().enumerate() {
                if let Some(n) = added.get(add).filter(|_| k % 5 == 4) {
                    r.slot(n);
                }
                // The shape's names with values moved by `shift`: same names, new values.
                // Over the stream's one vocabulary (the shape's names in part), read by index.
                let pairs = shapes[shape % shapes.len()]
                    .iter()
                    .map(|(n, v)| (n.clone(), v + shift));
                let values = ObservationValues::over_with(&vocabulary, pairs);
                let obs = Observations { values, ..Default::default() };
                r.read(&obs);
                let mut fresh = r.clone();
                fresh.vocabulary = None;
                fresh.read(&obs);
                prop_assert_eq!(r.values(), fresh.values());
                for k in 0..r.values().len() {
                    let slot = Slot(k as u32);
                    prop_assert_eq!(r.get(slot), obs.get(r.name(slot)));
                }
            }
        }
    }
}
