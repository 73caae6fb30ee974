//! [`ActionId`], the interned name of a primitive action, on its own so the record types can
//! carry it without importing the catalogue (`vocabulary` makes ids; `record` only holds them).

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
