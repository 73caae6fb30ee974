//! Presentation of the compiled params: the `companion check` sections of the stages that need
//! their private items (JSON for `--json`, text for people) and PANORAMA's allocation table.

pub mod guarantee;
pub mod resources;
