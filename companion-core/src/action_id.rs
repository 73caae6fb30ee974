//! [`ActionId`], the interned name of a primitive action, on its own so the record types can
//! carry it without importing the catalogue (`vocabulary` makes ids; `record` only holds them),
//! and [`ActionIds`], a record's list of them.

use serde::de::{Deserialize, Deserializer};
use serde::ser::{Serialize, Serializer};
use std::sync::Arc;

/// A primitive action of params/actions.toml, interned at load: its position in
/// [`crate::mission::ActionCatalogue::actions`]. Only [`crate::vocabulary::action_id`] makes
/// one (and the catalogue's own lookups), so an id always names an action of a catalogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ActionId(u16);

impl ActionId {
    /// Position of the action in its catalogue's `actions`.
    pub fn index(self) -> usize {
        usize::from(self.0)
    }

    /// The id of the action at `index` of a catalogue (the catalogue checks the index).
    pub(crate) fn from_index(index: u16) -> Self {
        ActionId(index)
    }
}

/// The names of a catalogue's actions by id (position `id.index()`), compiled once at load and
/// shared by every record of a run: an [`ActionIds`] over them copies no string.
pub type ActionNames = Arc<[String]>;

/// The id of `name` among `names` (a catalogue's [`ActionNames`]): a list over other names
/// resolved against a catalogue.
pub fn id_in(names: &ActionNames, name: &str) -> Option<ActionId> {
    let k = names.iter().take(MAX_NAMES).position(|n| n == name)?;
    Some(ActionId(k as u16))
}

/// Primitive actions by id over the names of the catalogue they index, the record's action lists
/// (`actions`, `shell_actions`, a proposal's `actions`, a conflict's `dropped`): the cycle writes
/// ids, the names are read only at the edges (serialization, a message, a review). Serialized as
/// the list of names it replaces, byte for byte. A list read from a file carries the names it
/// read as its own vocabulary ([`ActionIds::from_names`]): a log is read without params, and an
/// old log may name actions today's catalogue renamed or dropped.
pub struct ActionIds {
    names: ActionNames,
    ids: Vec<ActionId>,
}

impl Default for ActionIds {
    fn default() -> Self {
        ActionIds {
            names: crate::named_slots::no_names(),
            ids: Vec::new(),
        }
    }
}

/// Most distinct names a list read from a file may hold (ids are `u16`).
const MAX_NAMES: usize = u16::MAX as usize;

impl ActionIds {
    /// No action yet, over `names`.
    pub fn over(names: &ActionNames) -> Self {
        ActionIds {
            names: Arc::clone(names),
            ids: Vec::new(),
        }
    }

    /// Every id removed, over `names` (the buffer kept: no allocation in the steady cycle).
    pub fn reset_over(&mut self, names: &ActionNames) {
        if !Arc::ptr_eq(&self.names, names) {
            self.names = Arc::clone(names);
        }
        self.ids.clear();
    }

    /// The list rewritten as `ids` over `names` (the buffer kept: no allocation in the steady
    /// cycle).
    pub fn set(&mut self, names: &ActionNames, ids: impl IntoIterator<Item = ActionId>) {
        self.reset_over(names);
        ids.into_iter().for_each(|id| self.push(id));
    }

    /// Add action `id` (an id over [`ActionIds::vocabulary`]).
    pub fn push(&mut self, id: ActionId) {
        assert!(
            id.index() < self.names.len(),
            "action id {} over {} names",
            id.index(),
            self.names.len()
        );
        self.ids.push(id);
    }

    /// The ids, in order.
    pub fn ids(&self) -> &[ActionId] {
        &self.ids
    }

    /// The names the ids index (the catalogue's, or those a file named).
    pub fn vocabulary(&self) -> &ActionNames {
        &self.names
    }

    /// The name of `id` in this list's vocabulary.
    pub fn name(&self, id: ActionId) -> &str {
        &self.names[id.index()]
    }

    /// The actions' names, in order (an edge's read).
    pub fn iter(&self) -> Names<'_> {
        Names {
            names: &self.names,
            ids: self.ids.iter(),
        }
    }

    /// How many actions.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// No action.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// Remove every action (the vocabulary kept).
    pub fn clear(&mut self) {
        self.ids.clear();
    }

    /// Whether action `id` is in the list.
    pub fn contains(&self, id: ActionId) -> bool {
        self.ids.contains(&id)
    }

    /// Whether an action named `name` is in the list (an edge's lookup).
    pub fn contains_name(&self, name: &str) -> bool {
        self.iter().any(|a| a == name)
    }

    /// The names joined by `sep` (a message's text).
    pub fn join(&self, sep: &str) -> String {
        self.iter().collect::<Vec<_>>().join(sep)
    }

    /// The names, copied (an edge's list).
    pub fn to_names(&self) -> Vec<String> {
        self.iter().map(str::to_string).collect()
    }

    /// A list of `names` over a vocabulary of its own (the distinct names, first seen first):
    /// a list read from a file or written by a test. `None` past 65,535 distinct names.
    pub fn try_from_names<S: AsRef<str>>(names: impl IntoIterator<Item = S>) -> Option<Self> {
        let mut vocabulary: Vec<String> = Vec::new();
        let mut ids = Vec::new();
        for n in names {
            let n = n.as_ref();
            let k = match vocabulary.iter().position(|v| v == n) {
                Some(k) => k,
                None if vocabulary.len() < MAX_NAMES => {
                    vocabulary.push(n.to_string());
                    vocabulary.len() - 1
                }
                None => return None,
            };
            ids.push(ActionId(k as u16));
        }
        Some(ActionIds {
            names: vocabulary.into(),
            ids,
        })
    }

    /// [`ActionIds::try_from_names`] for a list known to be short (a test's, a shell's few).
    pub fn from_names<S: AsRef<str>>(names: impl IntoIterator<Item = S>) -> Self {
        Self::try_from_names(names).expect("at most 65,535 distinct action names")
    }
}

/// `clone_from` keeps this buffer and shares the names: no allocation in the steady cycle.
impl Clone for ActionIds {
    fn clone(&self) -> Self {
        ActionIds {
            names: Arc::clone(&self.names),
            ids: self.ids.clone(),
        }
    }
    fn clone_from(&mut self, src: &Self) {
        if !Arc::ptr_eq(&self.names, &src.names) {
            self.names = Arc::clone(&src.names);
        }
        self.ids.clone_from(&src.ids);
    }
}

/// Equal when the same names come in the same order (the vocabularies aside).
impl PartialEq for ActionIds {
    fn eq(&self, other: &Self) -> bool {
        if Arc::ptr_eq(&self.names, &other.names) {
            return self.ids == other.ids;
        }
        self.iter().eq(other.iter())
    }
}

impl<const N: usize> PartialEq<[&str; N]> for ActionIds {
    fn eq(&self, other: &[&str; N]) -> bool {
        self.iter().eq(other.iter().copied())
    }
}

impl PartialEq<[String]> for ActionIds {
    fn eq(&self, other: &[String]) -> bool {
        self.iter().eq(other.iter().map(String::as_str))
    }
}

impl std::fmt::Debug for ActionIds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

/// The names of an [`ActionIds`], in order.
#[derive(Clone)]
pub struct Names<'a> {
    names: &'a [String],
    ids: std::slice::Iter<'a, ActionId>,
}

impl<'a> Iterator for Names<'a> {
    type Item = &'a str;
    fn next(&mut self) -> Option<&'a str> {
        let a = self.ids.next()?;
        Some(&self.names[a.index()])
    }
    fn size_hint(&self) -> (usize, Option<usize>) {
        self.ids.size_hint()
    }
}

impl ExactSizeIterator for Names<'_> {}

impl<'a> IntoIterator for &'a ActionIds {
    type Item = &'a str;
    type IntoIter = Names<'a>;
    fn into_iter(self) -> Names<'a> {
        self.iter()
    }
}

/// [`ActionIds::from_names`]: a list a test or a shell writes by name.
impl<S: AsRef<str>> FromIterator<S> for ActionIds {
    fn from_iter<I: IntoIterator<Item = S>>(iter: I) -> Self {
        ActionIds::from_names(iter)
    }
}

impl Serialize for ActionIds {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.iter())
    }
}

impl<'de> Deserialize<'de> for ActionIds {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let names = Vec::<String>::deserialize(d)?;
        ActionIds::try_from_names(&names).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "an action list naming more than {MAX_NAMES} distinct actions"
            ))
        })
    }
}

/// The names of an [`ActionIds`] joined by `+` (`avoid_obstacle+search_zone_t`), as a message
/// or a conflict's `kept` writes them.
pub struct Joined<'a>(pub &'a ActionIds);

impl std::fmt::Display for Joined<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, name) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("+")?;
            }
            f.write_str(name)?;
        }
        Ok(())
    }
}

/// Serde for an [`ActionIds`] written as one string, its names joined by `+` (a conflict's
/// `kept`, as the record wrote it when it was that string); read back split at `+` (the empty
/// string: no action), so a string read is written again byte for byte.
pub mod joined {
    use super::{ActionIds, Joined, MAX_NAMES};
    use serde::{Deserialize, Deserializer, Serializer};

    /// The names joined by `+`.
    pub fn serialize<S: Serializer>(a: &ActionIds, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&Joined(a))
    }

    /// A `+`-joined string of names, over a vocabulary of its own.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<ActionIds, D::Error> {
        let text = String::deserialize(d)?;
        if text.is_empty() {
            return Ok(ActionIds::default());
        }
        ActionIds::try_from_names(text.split('+')).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "a `+`-joined action list naming more than {MAX_NAMES} distinct actions"
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn serializes_as_the_list_of_names_and_reads_it_back() {
        let names: ActionNames = ["take_off", "land", "track_v3"].map(String::from).into();
        let mut a = ActionIds::over(&names);
        a.push(ActionId(2));
        a.push(ActionId(0));
        let json = serde_json::to_string(&a).unwrap();
        assert_eq!(json, r#"["track_v3","take_off"]"#);
        let back: ActionIds = serde_json::from_str(&json).unwrap();
        assert_eq!(back, a);
        assert_eq!(back, ["track_v3", "take_off"]);
        assert_eq!(
            back.vocabulary().len(),
            2,
            "read: the names it read, its own"
        );
        assert!(back.contains_name("take_off") && !back.contains_name("land"));
        assert_eq!(a.join("+"), "track_v3+take_off");
        let twice: ActionIds = serde_json::from_str(r#"["land","land"]"#).unwrap();
        assert_eq!(serde_json::to_string(&twice).unwrap(), r#"["land","land"]"#);
        assert_eq!(serde_json::to_string(&ActionIds::default()).unwrap(), "[]");
        assert!(serde_json::from_str::<ActionIds>(r#"["land",3]"#).is_err());
    }

    #[test]
    fn a_joined_list_is_written_and_read_as_its_string() {
        #[derive(serde::Serialize, serde::Deserialize)]
        struct Kept(#[serde(with = "joined")] ActionIds);
        for text in [
            r#""""#,
            r#""avoid_obstacle""#,
            r#""land+track_v3""#,
            r#""a++b""#,
        ] {
            let k: Kept = serde_json::from_str(text).unwrap();
            assert_eq!(serde_json::to_string(&k).unwrap(), text);
        }
        let k: Kept = serde_json::from_str(r#""land+track_v3""#).unwrap();
        assert_eq!(k.0, ["land", "track_v3"]);
        assert_eq!(Joined(&k.0).to_string(), "land+track_v3");
    }

    #[test]
    fn clone_from_shares_the_names() {
        let names: ActionNames = ["a", "b"].map(String::from).into();
        let mut src = ActionIds::over(&names);
        src.push(ActionId(1));
        let mut dst = ActionIds::default();
        dst.clone_from(&src);
        assert!(Arc::ptr_eq(dst.vocabulary(), &names));
        assert_eq!(dst.ids(), [ActionId(1)]);
        dst.reset_over(&names);
        assert!(dst.is_empty());
    }
}
