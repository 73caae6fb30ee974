//! The decision cycle's working lists, kept between cycles for their capacity, shared by the
//! cycle (decision.rs) and its arbitration stage (arbitration.rs).

use fpga_model::Implementation;

/// One resource request as the schedule memo keys it: app, version, the implementation the
/// allocation in force plans for it (if any), required fps bits.
pub(crate) type RequestKey<'m> = (&'m str, &'m str, Option<Implementation>, u64);

/// Per-cycle working lists, kept between cycles for their capacity. Action names borrow the
/// model (`'m`), so filling them allocates nothing.
#[derive(Default)]
pub(crate) struct Scratch<'m> {
    pub(crate) merged: Vec<&'m str>,
    pub(crate) kept: Vec<&'m str>,
    pub(crate) owners: Vec<&'m str>,
    pub(crate) actions: Vec<&'m str>,
    /// Proposals replaced by a re-solve of the same MDP within the cycle.
    pub(crate) superseded: Vec<usize>,
    /// The resource requests, one key each.
    pub(crate) key: Vec<RequestKey<'m>>,
    pub(crate) failed: Vec<String>,
}
