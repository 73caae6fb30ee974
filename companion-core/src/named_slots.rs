//! Values by id over names compiled once: the cycle writes a value at its slot, the names are read
//! only at the edges (the record's serialization, a tool or test looking one up). The names are a
//! sorted list shared by every record of a run (`Arc`), so writing a cycle's values copies no
//! string and builds no map; the serialized form is the map `name -> value` in name order, the
//! `BTreeMap<String, _>` the record held before, byte for byte.

use serde::de::{Deserialize, Deserializer};
use serde::ser::{Serialize, SerializeMap, Serializer};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Names in sorted order, unique: the vocabulary one kind of value is written over.
pub type SortedNames = Arc<[String]>;

/// Sorted, unique names from any list (the load's one sort).
pub fn sorted_names<I: IntoIterator<Item = String>>(names: I) -> SortedNames {
    let mut v: Vec<String> = names.into_iter().collect();
    v.sort();
    v.dedup();
    v.into()
}

/// No names (a vocabulary not set yet: every name written goes to an overflow).
pub fn no_names() -> SortedNames {
    Arc::from(Vec::new())
}

/// Values by slot over [`SortedNames`] (`None`: no value this cycle, absent when serialized).
pub struct NamedSlots<V> {
    names: SortedNames,
    values: Vec<Option<V>>,
}

impl<V> Default for NamedSlots<V> {
    fn default() -> Self {
        NamedSlots {
            names: no_names(),
            values: Vec::new(),
        }
    }
}

impl<V> NamedSlots<V> {
    /// No value yet over `names`.
    pub fn over(names: &SortedNames) -> Self {
        let mut s = NamedSlots::default();
        s.reset_over(names);
        s
    }

    /// Every slot emptied, over `names` (the buffer kept: no allocation when the names are the
    /// ones already held, the steady cycle).
    pub fn reset_over(&mut self, names: &SortedNames) {
        if !Arc::ptr_eq(&self.names, names) {
            self.names = Arc::clone(names);
        }
        self.values.clear();
        self.values.resize_with(names.len(), || None);
    }

    /// The names this is written over (sorted).
    pub fn names(&self) -> &SortedNames {
        &self.names
    }

    /// The values by slot.
    pub fn slots(&self) -> &[Option<V>] {
        &self.values
    }

    /// Set the value at `slot` (an index into [`NamedSlots::names`]).
    pub fn set(&mut self, slot: usize, value: V) {
        self.values[slot] = Some(value);
    }

    /// Empty the slot `slot`.
    pub fn reset_slot(&mut self, slot: usize) {
        self.values[slot] = None;
    }

    /// The value at `slot`, mutable.
    pub fn slot_mut(&mut self, slot: usize) -> Option<&mut V> {
        self.values.get_mut(slot).and_then(Option::as_mut)
    }

    /// Empty every slot (the names kept).
    pub fn clear(&mut self) {
        self.values.iter_mut().for_each(|v| *v = None);
    }

    /// The slot of `name`, if it is one of the names.
    pub fn slot_of(&self, name: &str) -> Option<usize> {
        self.names.binary_search_by(|n| n.as_str().cmp(name)).ok()
    }

    /// The value named `name` (an edge's lookup).
    pub fn get(&self, name: &str) -> Option<&V> {
        self.values[self.slot_of(name)?].as_ref()
    }

    /// The value named `name`, mutable.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut V> {
        let k = self.slot_of(name)?;
        self.values[k].as_mut()
    }

    /// Whether a value is named `name`.
    pub fn contains_key(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// Set the value named `name`, adding the name when it is new (an edge's write: tests,
    /// synthetic records; the names are copied then).
    pub fn insert(&mut self, name: String, value: V)
    where
        V: Clone,
    {
        match self.names.binary_search(&name) {
            Ok(k) => self.values[k] = Some(value),
            Err(k) => {
                let mut names = self.names.to_vec();
                names.insert(k, name);
                self.names = names.into();
                self.values.insert(k, Some(value));
            }
        }
    }

    /// The present values with their names, in name order.
    pub fn iter(&self) -> Iter<'_, V> {
        Iter {
            inner: self.names.iter().zip(self.values.iter()),
        }
    }

    /// The names of the present values, in order.
    pub fn keys(&self) -> impl Iterator<Item = &String> {
        self.iter().map(|(n, _)| n)
    }

    /// The present values, in name order.
    pub fn values(&self) -> impl Iterator<Item = &V> {
        self.iter().map(|(_, v)| v)
    }

    /// How many values are present.
    pub fn len(&self) -> usize {
        self.values.iter().filter(|v| v.is_some()).count()
    }

    /// No value present.
    pub fn is_empty(&self) -> bool {
        self.values.iter().all(Option::is_none)
    }
}

/// `clone_from` keeps this buffer and shares the names: copying a record of the same shape
/// allocates nothing.
impl<V: Clone> Clone for NamedSlots<V> {
    fn clone(&self) -> Self {
        NamedSlots {
            names: Arc::clone(&self.names),
            values: self.values.clone(),
        }
    }
    fn clone_from(&mut self, src: &Self) {
        if !Arc::ptr_eq(&self.names, &src.names) {
            self.names = Arc::clone(&src.names);
        }
        self.values.clone_from(&src.values);
    }
}

/// The present values of a [`NamedSlots`] with their names, in name order.
pub struct Iter<'a, V> {
    inner: std::iter::Zip<std::slice::Iter<'a, String>, std::slice::Iter<'a, Option<V>>>,
}

impl<'a, V> Iterator for Iter<'a, V> {
    type Item = (&'a String, &'a V);
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let (name, value) = self.inner.next()?;
            if let Some(v) = value {
                return Some((name, v));
            }
        }
    }
}

impl<'a, V> IntoIterator for &'a NamedSlots<V> {
    type Item = (&'a String, &'a V);
    type IntoIter = Iter<'a, V>;
    fn into_iter(self) -> Iter<'a, V> {
        self.iter()
    }
}

impl<V: Clone> FromIterator<(String, V)> for NamedSlots<V> {
    fn from_iter<I: IntoIterator<Item = (String, V)>>(iter: I) -> Self {
        let map: BTreeMap<String, V> = iter.into_iter().collect();
        let names: SortedNames = map.keys().cloned().collect::<Vec<_>>().into();
        NamedSlots {
            names,
            values: map.into_values().map(Some).collect(),
        }
    }
}

/// Each pair set as by [`NamedSlots::insert`] (an edge's write).
impl<V: Clone> Extend<(String, V)> for NamedSlots<V> {
    fn extend<I: IntoIterator<Item = (String, V)>>(&mut self, iter: I) {
        for (name, value) in iter {
            self.insert(name, value);
        }
    }
}

impl<V> std::ops::Index<&str> for NamedSlots<V> {
    type Output = V;
    fn index(&self, name: &str) -> &V {
        self.get(name)
            .unwrap_or_else(|| panic!("no value named `{name}`"))
    }
}

impl<V> std::ops::Index<&String> for NamedSlots<V> {
    type Output = V;
    fn index(&self, name: &String) -> &V {
        &self[name.as_str()]
    }
}

/// Equal when the same names hold the same values (how the slots were laid out aside).
impl<V: PartialEq> PartialEq for NamedSlots<V> {
    fn eq(&self, other: &Self) -> bool {
        self.iter().eq(other.iter())
    }
}

impl<V: std::fmt::Debug> std::fmt::Debug for NamedSlots<V> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_map().entries(self.iter()).finish()
    }
}

impl<V: Serialize> Serialize for NamedSlots<V> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.len()))?;
        for (name, value) in self.iter() {
            map.serialize_entry(name, value)?;
        }
        map.end()
    }
}

impl<'de, V: Deserialize<'de> + Clone> Deserialize<'de> for NamedSlots<V> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let map = BTreeMap::<String, V>::deserialize(d)?;
        Ok(map.into_iter().collect())
    }
}

/// A name written by id: one of a list compiled at load, shared (cloning it copies no string).
/// The evidence's states are these: the cycle picks the state, the record writes its name.
#[derive(Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Label(Arc<str>);

impl Label {
    /// The label's text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl From<&str> for Label {
    fn from(s: &str) -> Self {
        Label(Arc::from(s))
    }
}

impl From<String> for Label {
    fn from(s: String) -> Self {
        Label(Arc::from(s))
    }
}

impl std::ops::Deref for Label {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl PartialEq<str> for Label {
    fn eq(&self, other: &str) -> bool {
        &*self.0 == other
    }
}

impl PartialEq<&str> for Label {
    fn eq(&self, other: &&str) -> bool {
        &*self.0 == *other
    }
}

impl std::fmt::Debug for Label {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(&*self.0, f)
    }
}

impl std::fmt::Display for Label {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl Serialize for Label {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&self.0)
    }
}

impl<'de> Deserialize<'de> for Label {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(Label::from(String::deserialize(d)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serializes_as_the_map_it_replaces_and_reads_it_back() {
        let names = sorted_names(["P_b".to_string(), "P_a".into(), "P_c".into()]);
        let mut s = NamedSlots::over(&names);
        s.set(2, 0.5);
        s.set(0, 0.25);
        let map = BTreeMap::from([("P_a".to_string(), 0.25), ("P_c".to_string(), 0.5)]);
        let json = serde_json::to_string(&s).unwrap();
        assert_eq!(json, serde_json::to_string(&map).unwrap());
        let back: NamedSlots<f64> = serde_json::from_str(&json).unwrap();
        assert_eq!(back, s);
        assert_eq!(back.get("P_c"), Some(&0.5));
        assert_eq!(s.get("P_b"), None);
        assert_eq!(s.len(), 2);
        s.clear();
        assert!(s.is_empty());
        assert_eq!(serde_json::to_string(&s).unwrap(), "{}");
    }

    #[test]
    fn an_edge_insert_keeps_the_names_sorted() {
        let mut s: NamedSlots<f64> = NamedSlots::default();
        s.insert("b".into(), 1.0);
        s.insert("a".into(), 2.0);
        s.insert("b".into(), 3.0);
        let got: Vec<(&String, &f64)> = s.iter().collect();
        assert_eq!(got, [(&"a".to_string(), &2.0), (&"b".to_string(), &3.0)]);
        assert_eq!(s["a"], 2.0);
    }
}
