//! Power samples (and, to `legs`, every message) of the autopilot from a run's `flight.tlog` (the autopilot's own telemetry, at its rate: ~10 Hz
//! BATTERY_STATUS on ArduPilot), read one entry at a time and decoded as `fly` decodes them
//! (`companion_link::telemetry::Telemetry`): pack voltage x current from BATTERY_STATUS (until
//! the first one, SYS_STATUS), speed and altitude from GLOBAL_POSITION_INT, armed from HEARTBEAT.
//! Only the autopilot's frames count: the system *and* component `fly` would choose from the
//! same HEARTBEATs (`companion_link::vehicle::is_autopilot_heartbeat`): the pin when given
//! (`calibrate --autopilot-sysid/--autopilot-compid`, as `fly`'s), else component 1 at once and
//! another component only once it has spoken alone for `OTHER_COMPONENT_WAIT` of the tlog's
//! time. Every other autopilot is an impostor: its frames are counted out and reported. A
//! companion shares the autopilot's system id, and the tlog holds its own disarmed-looking
//! heartbeats too.

use super::power_fit::Sample;
use crate::decision_log::frame_len;
use companion_link::Msg;
use companion_link::telemetry::{Telemetry, TelemetryConfig};
use std::io::{BufReader, Read};
use std::path::Path;
use std::time::Duration;

/// The largest tlog entry: 8-byte time stamp and a signed MAVLink 2 frame.
const MAX_ENTRY: usize = 8 + 10 + 255 + 2 + 13;

/// The autopilot `fly` obeys: a pin, or none (fly's choice rule).
pub type Pin = Option<(u8, u8)>;

/// What a tlog gave: its samples, the autopilot they are from, the impostors counted out.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct TlogRead {
    pub samples: u64,
    pub autopilot: Option<(u8, u8)>,
    /// The pin it was chosen by (calibrate's or the run's `fly`'s), if any.
    pub pin: Pin,
    /// Other autopilots (system, component) and how many of their frames were left out.
    pub impostors: std::collections::BTreeMap<(u8, u8), u64>,
}

/// `fly`'s choice of the autopilot over a tlog (companion_link's `Vehicle::choice`).
struct Chooser {
    pin: Pin,
    chosen: Option<(u8, u8)>,
    candidate: Option<((u8, u8), u64)>,
}

impl Chooser {
    /// The sender's HEARTBEAT at `t_us` (tlog time): whether it makes the sender the autopilot.
    fn heartbeat(&mut self, sender: (u8, u8), t_us: u64) {
        if self.chosen.is_some() {
            return;
        }
        if let Some(p) = self.pin {
            if sender == p {
                self.chosen = Some(sender);
            }
            return;
        }
        if sender.1 == companion_link::vehicle::AUTOPILOT_COMPONENT {
            self.chosen = Some(sender);
            return;
        }
        let wait = companion_link::vehicle::OTHER_COMPONENT_WAIT.as_micros() as u64;
        match self.candidate {
            None => self.candidate = Some((sender, t_us)),
            Some((id, since)) if id == sender && t_us.saturating_sub(since) >= wait => {
                self.chosen = Some(sender);
            }
            _ => {}
        }
    }
}

/// Call `each` with every power sample of the tlog at `path` from the autopilot `fly` would
/// obey (`pin`, else its choice rule); returns what was read. A cut
/// last entry (a run killed while writing) ends the read with a warning; an entry that does not
/// start a MAVLink frame stops it with the file, the byte offset and the reason.
pub fn for_each_sample(
    path: &Path,
    pin: Pin,
    mut each: impl FnMut(Sample),
    mut each_msg: impl FnMut(&Msg),
) -> anyhow::Result<TlogRead> {
    crate::params_files::regular_file(path)
        .map_err(|r| anyhow::anyhow!("{}: {r}", crate::output_file::shown(path)))?;
    let file = std::fs::File::open(path)
        .map_err(|e| anyhow::anyhow!("{}: {e}", crate::output_file::shown(path)))?;
    let mut rd = BufReader::new(file);
    let mut ingest = companion_link::ingest::Ingest::new(None);
    let mut tel = Telemetry::new(TelemetryConfig::default());
    let mut chooser = Chooser {
        pin,
        chosen: None,
        candidate: None,
    };
    let mut read = TlogRead::default();
    let mut battery_status_seen = false;
    let mut buf = [0u8; MAX_ENTRY];
    let (mut offset, mut n) = (0u64, 0u64);
    loop {
        let head = read_upto(&mut rd, &mut buf[..11])?;
        if head == 0 {
            break;
        }
        let len = (head == 11).then(|| frame_len(&buf[8..11])).flatten();
        let Some(len) = len else {
            if head < 11 {
                tracing::warn!(
                    "{}: last entry at byte {offset} cut off (skipped)",
                    crate::output_file::shown(path)
                );
                break;
            }
            anyhow::bail!(
                "{}, byte {offset}: not a tlog entry (8-byte time stamp, then a MAVLink frame starting 0xFD or 0xFE; found 0x{:02X})",
                crate::output_file::shown(path),
                buf[8]
            );
        };
        let got = read_upto(&mut rd, &mut buf[11..8 + len])?;
        if got < len - 3 {
            tracing::warn!(
                "{}: last entry at byte {offset} cut off (skipped)",
                crate::output_file::shown(path)
            );
            break;
        }
        offset += (8 + len) as u64;
        let t_us = u64::from_be_bytes(buf[..8].try_into().expect("8 bytes"));
        let mut msgs: Vec<((u8, u8), Msg)> = Vec::new();
        ingest.push_each(&buf[8..8 + len], |fr| {
            msgs.push((
                (fr.header.system_id as u8, fr.header.component_id),
                fr.msg.clone(),
            ))
        });
        for (sender, msg) in msgs {
            let autopilot_hb = matches!(&msg, Msg::HEARTBEAT(h)
                if companion_link::vehicle::is_autopilot_heartbeat(h));
            if autopilot_hb {
                chooser.heartbeat(sender, t_us);
            }
            if chooser.chosen != Some(sender) {
                // Another autopilot's frames (an impostor, or one heard before the choice).
                if autopilot_hb || read.impostors.contains_key(&sender) {
                    *read.impostors.entry(sender).or_default() += 1;
                }
                continue;
            }
            each_msg(&msg);
            tel.on_message(Duration::ZERO, &msg, companion_link::modes::Flavor::Other);
            let emit = match &msg {
                Msg::BATTERY_STATUS(b) if b.id == 0 => {
                    battery_status_seen = true;
                    true
                }
                Msg::SYS_STATUS(_) => !battery_status_seen,
                _ => false,
            };
            if emit && let Some(s) = sample_of(&tel) {
                each(s);
                n += 1;
            }
        }
    }
    read.autopilot = chooser.chosen;
    read.pin = pin;
    if let Some(a) = read.autopilot {
        read.impostors.remove(&a);
    }
    read.samples = n;
    Ok(read)
}

/// Read until `buf` is full or the file ends; the bytes read.
fn read_upto(rd: &mut impl Read, buf: &mut [u8]) -> anyhow::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match rd.read(&mut buf[got..])? {
            0 => break,
            k => got += k,
        }
    }
    Ok(got)
}

fn sample_of(tel: &Telemetry) -> Option<Sample> {
    let mut r = companion_core::record::DecisionRecord::default();
    for k in [
        "battery_v",
        "battery_current_a",
        "groundspeed_mps",
        "altitude_m",
    ] {
        if let Some(v) = tel.get(k) {
            r.observations.insert(k.into(), v);
        }
    }
    r.observations
        .insert("armed".into(), if tel.armed { 1.0 } else { 0.0 });
    super::runs::sample_of(&r)
}
