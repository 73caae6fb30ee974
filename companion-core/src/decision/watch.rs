//! What the guarantee stage says of a drift (decision.rs's `watch_guarantee`).

use crate::record::Event;

pub(super) fn drift_event(
    record: &crate::record::GuaranteeRecord,
    tolerance: f64,
) -> Option<Event> {
    let pw = record.power.as_ref().filter(|pw| pw.drift_began)?;
    Some(Event::Other(format!(
        "performance drift: {} measured {:.0} J against {:.0} J predicted in {:.0} s (x{:.2}, beyond {:.0} %); remaining energy estimates x{:.2}",
        record.activity_name,
        pw.measured_j.unwrap_or(0.0),
        pw.predicted_j,
        pw.activity_s,
        pw.ratio.unwrap_or(1.0),
        tolerance * 100.0,
        pw.energy_scale
    )))
}
