//! The guarantee record's maps keyed by the goals' names (`energy_j`, `duration_s`): neither
//! observations, probabilities nor evidence, copied in place when the goals are the same.

use super::{GuaranteeRecord, map_clone_from};

/// `dst`'s margins, goals and drift as `src`'s (buffers reused when the goal names are the same).
pub(super) fn clone_goal_maps_from(dst: &mut GuaranteeRecord, src: &GuaranteeRecord) {
    map_clone_from(&mut dst.margins, &src.margins);
    map_clone_from(&mut dst.goals, &src.goals);
    map_clone_from(&mut dst.drift, &src.drift);
}
