//! What the guarantee stage reads of the snapshot and says of a drift (decision.rs's
//! `watch_guarantee`).

use crate::observations::Observations;
use crate::record::Event;

/// What the snapshot says of the pack (docs/guarantee.md, "Energy from the autopilot").
pub(super) fn pack_reading(obs: &Observations) -> crate::guarantee::PackReading {
    crate::guarantee::PackReading {
        capacity_mah: obs.get("battery_capacity_mah"),
        cells: obs.get("battery_cells"),
        voltage_v: obs.get("battery_v"),
        current_a: obs.get("battery_current_a"),
        consumed_mah: obs.get("consumed_mah"),
        vehicle_time_s: obs.get("vehicle_time_s"),
        armed: obs.get("armed").map(|a| a > 0.5),
    }
}

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
