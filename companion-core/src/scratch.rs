//! The decision cycle's working lists, kept between cycles for their capacity, shared by the
//! cycle (decision.rs) and its arbitration stage (arbitration.rs).

use crate::vocabulary::ActionId;
use fpga_model::Implementation;

/// One resource request as the schedule memo keys it: the application variant (the catalogue's
/// first action starting it, [`crate::mission::ActionCatalogue::variant_id`], so equal keys mean
/// an equal app and version), the implementation the allocation in force plans for it (if
/// any), required fps bits.
pub(crate) type RequestKey = (ActionId, Option<Implementation>, u64);

/// Per-cycle working lists, kept between cycles for their capacity. Actions are catalogue ids
/// (names are resolved when the record is written), so filling them allocates nothing.
#[derive(Default)]
pub(crate) struct Scratch {
    pub(crate) merged: Vec<ActionId>,
    pub(crate) kept: Vec<ActionId>,
    pub(crate) owners: Vec<ActionId>,
    pub(crate) actions: Vec<ActionId>,
    /// Proposals replaced by a re-solve of the same MDP within the cycle.
    pub(crate) superseded: Vec<usize>,
    /// Per proposal of the record (same index): the MDP (its index in the core's MDP list) and
    /// the MDP action chosen, whose primitives' ids the core resolved at start
    /// (`HealthMdpStage::mdp_primitives`), so arbitration merges ids without looking names up.
    pub(crate) proposed: Vec<(usize, usize)>,
    /// The resource requests, one key each.
    pub(crate) key: Vec<RequestKey>,
    pub(crate) failed: Vec<String>,
}
