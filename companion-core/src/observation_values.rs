//! A snapshot's observation values by slot over the vocabulary compiled at load, with a small
//! overflow for names outside it; the snapshot ([`crate::observations::Observations`]) and the
//! record ([`crate::record::DecisionRecord::observations`]) both hold one.

use crate::named_slots::{NamedSlots, SortedNames};
use serde::de::{Deserialize, Deserializer};
use serde::ser::{Serialize, SerializeMap, Serializer};
use std::collections::BTreeMap;

/// A snapshot's values: by slot over the observation vocabulary compiled once at load (every
/// name a producer of the params writes or a consumer reads, `companion::vocabulary`), shared by
/// `Arc` between the shell that writes it, the core that reads it and the record that keeps it,
/// so copying a snapshot into the record copies no name. A name outside the vocabulary (an
/// onboard monitor's NAMED_VALUE_FLOAT that params do not declare, a test's own name) goes to a
/// small overflow list, sorted, kept in the record as before. Serialized as the one
/// `name -> value` map in name order the record held before, byte for byte.
#[derive(Default)]
pub struct ObservationValues {
    slots: NamedSlots<f64>,
    /// Names outside `slots`' names, sorted, unique.
    overflow: Vec<(String, f64)>,
}

impl ObservationValues {
    /// No value yet over the vocabulary `names`.
    pub fn over(names: &SortedNames) -> Self {
        ObservationValues {
            slots: NamedSlots::over(names),
            overflow: Vec::new(),
        }
    }

    /// `pairs` written over the vocabulary `names` (outside it: the overflow).
    pub fn over_with<I: IntoIterator<Item = (String, f64)>>(names: &SortedNames, pairs: I) -> Self {
        let mut v = ObservationValues::over(names);
        for (name, value) in pairs {
            v.set(&name, value);
        }
        v
    }

    /// The vocabulary this is written over.
    pub fn names(&self) -> &SortedNames {
        self.slots.names()
    }

    /// The values by slot of the vocabulary.
    pub fn slots(&self) -> &[Option<f64>] {
        self.slots.slots()
    }

    /// The values outside the vocabulary, sorted by name.
    pub fn overflow(&self) -> &[(String, f64)] {
        &self.overflow
    }

    /// Set the value at `slot` of the vocabulary.
    pub fn set_slot(&mut self, slot: usize, value: f64) {
        self.slots.set(slot, value);
    }

    /// The slot of `name` in the vocabulary.
    pub fn slot_of(&self, name: &str) -> Option<usize> {
        self.slots.slot_of(name)
    }

    fn overflow_at(&self, name: &str) -> Result<usize, usize> {
        self.overflow
            .binary_search_by(|(n, _)| n.as_str().cmp(name))
    }

    /// Set (or replace) the value named `name`: at its slot, else in the overflow.
    pub fn set(&mut self, name: &str, value: f64) {
        if let Some(k) = self.slots.slot_of(name) {
            self.slots.set(k, value);
            return;
        }
        match self.overflow_at(name) {
            Ok(k) => self.overflow[k].1 = value,
            Err(k) => self.overflow.insert(k, (name.to_string(), value)),
        }
    }

    /// As [`ObservationValues::set`], with the old value (the map's `insert`).
    pub fn insert(&mut self, name: String, value: f64) -> Option<f64> {
        let old = self.get(&name).copied();
        self.set(&name, value);
        old
    }

    /// The value named `name`.
    pub fn get(&self, name: &str) -> Option<&f64> {
        match self.slots.slot_of(name) {
            Some(k) => self.slots.slots()[k].as_ref(),
            None => self.overflow_at(name).ok().map(|k| &self.overflow[k].1),
        }
    }

    /// The value named `name`, mutable.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut f64> {
        match self.slots.slot_of(name) {
            Some(k) => self.slots.slot_mut(k),
            None => match self.overflow_at(name) {
                Ok(k) => Some(&mut self.overflow[k].1),
                Err(_) => None,
            },
        }
    }

    /// Take the value named `name` out.
    pub fn remove(&mut self, name: &str) -> Option<f64> {
        match self.slots.slot_of(name) {
            Some(k) => {
                let v = self.slots.slots()[k];
                self.slots.reset_slot(k);
                v
            }
            None => self
                .overflow_at(name)
                .ok()
                .map(|k| self.overflow.remove(k).1),
        }
    }

    /// Whether a value is named `name`.
    pub fn contains_key(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// Empty every slot and the overflow (the vocabulary kept).
    pub fn clear(&mut self) {
        self.slots.clear();
        self.overflow.clear();
    }

    /// Keep only the values `keep` accepts.
    pub fn retain(&mut self, mut keep: impl FnMut(&str, f64) -> bool) {
        let gone: Vec<usize> = (self.slots.iter())
            .filter(|(n, v)| !keep(n, **v))
            .filter_map(|(n, _)| self.slots.slot_of(n))
            .collect();
        gone.into_iter().for_each(|k| self.slots.reset_slot(k));
        self.overflow.retain(|(n, v)| keep(n, *v));
    }

    /// The present values with their names, in name order (the vocabulary's and the overflow's
    /// merged).
    pub fn iter(&self) -> impl Iterator<Item = (&String, &f64)> + '_ {
        let mut a = self.slots.iter().peekable();
        let mut b = self.overflow.iter().map(|(n, v)| (n, v)).peekable();
        std::iter::from_fn(move || match (a.peek(), b.peek()) {
            (Some(x), Some(y)) if y.0 < x.0 => b.next(),
            (Some(_), _) => a.next(),
            (None, _) => b.next(),
        })
    }

    /// The names of the present values, in order.
    pub fn keys(&self) -> impl Iterator<Item = &String> + '_ {
        self.iter().map(|(n, _)| n)
    }

    /// The present values, in name order.
    pub fn values(&self) -> impl Iterator<Item = &f64> + '_ {
        self.iter().map(|(_, v)| v)
    }

    /// How many values are present.
    pub fn len(&self) -> usize {
        self.slots.len() + self.overflow.len()
    }

    /// No value present.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty() && self.overflow.is_empty()
    }
}

/// `clone_from` keeps the buffers and shares the vocabulary: copying the snapshot into the
/// record allocates nothing once warm.
impl Clone for ObservationValues {
    fn clone(&self) -> Self {
        ObservationValues {
            slots: self.slots.clone(),
            overflow: self.overflow.clone(),
        }
    }
    fn clone_from(&mut self, src: &Self) {
        self.slots.clone_from(&src.slots);
        // By element: a tuple's `clone_from` would clone the name anew.
        self.overflow.truncate(src.overflow.len());
        for (d, s) in self.overflow.iter_mut().zip(&src.overflow) {
            d.0.clone_from(&s.0);
            d.1 = s.1;
        }
        let n = self.overflow.len();
        self.overflow.extend_from_slice(&src.overflow[n..]);
    }
}

/// Names from the pairs themselves (no vocabulary: a test's or a tool's snapshot).
impl FromIterator<(String, f64)> for ObservationValues {
    fn from_iter<I: IntoIterator<Item = (String, f64)>>(iter: I) -> Self {
        ObservationValues {
            slots: iter.into_iter().collect(),
            overflow: Vec::new(),
        }
    }
}

impl Extend<(String, f64)> for ObservationValues {
    fn extend<I: IntoIterator<Item = (String, f64)>>(&mut self, iter: I) {
        for (name, value) in iter {
            self.set(&name, value);
        }
    }
}

impl<const N: usize> From<[(String, f64); N]> for ObservationValues {
    fn from(pairs: [(String, f64); N]) -> Self {
        pairs.into_iter().collect()
    }
}

impl std::ops::Index<&str> for ObservationValues {
    type Output = f64;
    fn index(&self, name: &str) -> &f64 {
        self.get(name)
            .unwrap_or_else(|| panic!("no observation named `{name}`"))
    }
}

/// Equal when the same names hold the same values (vocabulary and overflow aside).
impl PartialEq for ObservationValues {
    fn eq(&self, other: &Self) -> bool {
        self.iter().eq(other.iter())
    }
}

impl std::fmt::Debug for ObservationValues {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.iter()).finish()
    }
}

impl Serialize for ObservationValues {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.len()))?;
        for (name, value) in self.iter() {
            map.serialize_entry(name, value)?;
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for ObservationValues {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(BTreeMap::<String, f64>::deserialize(d)?
            .into_iter()
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::named_slots::sorted_names;
    use proptest::prelude::*;

    proptest! {
        /// Whatever part of the names the vocabulary holds, the values read, iterate and
        /// serialize as the map written the same way.
        #[test]
        fn reads_and_serializes_as_the_map(
            vocabulary in proptest::collection::vec("[a-e]{1,2}", 0..8),
            writes in proptest::collection::vec(("[a-e]{1,2}", -5.0f64..5.0, 0u8..4), 0..30),
        ) {
            let names = sorted_names(vocabulary);
            let mut v = ObservationValues::over(&names);
            let mut map = BTreeMap::new();
            for (name, value, op) in &writes {
                match op {
                    0 => prop_assert_eq!(v.remove(name), map.remove(name)),
                    _ => {
                        v.set(name, *value);
                        map.insert(name.clone(), *value);
                    }
                }
                prop_assert_eq!(v.get(name), map.get(name));
            }
            prop_assert_eq!(v.len(), map.len());
            let got: Vec<(&String, &f64)> = v.iter().collect();
            let want: Vec<(&String, &f64)> = map.iter().collect();
            prop_assert_eq!(got, want);
            let json = serde_json::to_string(&v).unwrap();
            prop_assert_eq!(&json, &serde_json::to_string(&map).unwrap());
            let back: ObservationValues = serde_json::from_str(&json).unwrap();
            prop_assert_eq!(&back, &v);
            let mut copy = ObservationValues::over(&names);
            copy.set("zz", 1.0);
            copy.clone_from(&v);
            prop_assert_eq!(&copy, &v);
            prop_assert!(v.overflow().iter().all(|(n, _)| v.slot_of(n).is_none()));
        }
    }
}
