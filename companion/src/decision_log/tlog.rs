//! `.tlog`: the telemetry log format of MAVProxy / pymavlink / Mission Planner / UAVLogViewer.
//! Each entry is an 8-byte big-endian timestamp (microseconds since the Unix epoch) followed by
//! one raw MAVLink frame (v1 or v2, as received or sent). There is no file header.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Writes a `.tlog`. Each entry goes out in one write, so a killed process leaves whole frames
/// behind; a failed write (disk full) is cut back to the last whole entry and counted.
pub struct TlogWriter {
    out: File,
    /// Bytes of whole entries in the file.
    bytes: u64,
    frames: u64,
    failed: u64,
    /// Shared with the decision log, which says the cap ([`super::DecisionLog::watch_tlog`]).
    capped: Arc<AtomicU64>,
    max_bytes: u64,
    buf: Vec<u8>,
    path: PathBuf,
}

impl TlogWriter {
    /// Create (or truncate) the file at `path`, capped at [`super::DEFAULT_MAX_BYTES`] (`fly`
    /// gives it the decision log's cap, `$COMPANION_LOG_MAX_BYTES`, with [`Self::with_max_bytes`]).
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(TlogWriter {
            out: File::create(path)?,
            bytes: 0,
            frames: 0,
            failed: 0,
            capped: Arc::new(AtomicU64::new(0)),
            max_bytes: super::DEFAULT_MAX_BYTES,
            buf: Vec::with_capacity(8 + 280),
            path: path.to_path_buf(),
        })
    }

    /// The count of frames not written for the cap, for the decision log to say
    /// ([`super::DecisionLog::watch_tlog`]).
    pub fn capped_counter(&self) -> Arc<AtomicU64> {
        self.capped.clone()
    }

    /// Stop writing (count instead) once the file would pass `max_bytes`.
    pub fn with_max_bytes(mut self, max_bytes: u64) -> Self {
        self.max_bytes = max_bytes;
        self
    }

    /// Append one frame received or sent at `t_us` (microseconds since the Unix epoch).
    /// `frame` must be one complete MAVLink frame, from its start byte (0xFD / 0xFE) through its
    /// checksum (and signature, if signed).
    pub fn write(&mut self, t_us: u64, frame: &[u8]) -> io::Result<()> {
        self.buf.clear();
        self.buf.extend_from_slice(&t_us.to_be_bytes());
        self.buf.extend_from_slice(frame);
        if self.bytes + self.buf.len() as u64 > self.max_bytes {
            if self.capped.fetch_add(1, Ordering::AcqRel) == 0 {
                eprintln!(
                    "warning: {} reached its cap of {} bytes: further frames are counted, not \
                     written",
                    crate::text::escape_controls(&self.path.display().to_string(), false),
                    self.max_bytes
                );
            }
            return Err(io::Error::other(format!(
                "tlog cap of {} bytes reached: frame counted, not written",
                self.max_bytes
            )));
        }
        match self.out.write_all(&self.buf).and_then(|_| self.out.flush()) {
            Ok(()) => {
                self.bytes += self.buf.len() as u64;
                self.frames += 1;
                Ok(())
            }
            Err(e) => {
                self.failed += 1;
                let _ = self.out.set_len(self.bytes);
                let _ = self.out.seek(SeekFrom::Start(self.bytes));
                Err(e)
            }
        }
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Frames that could not be written (disk full, I/O error).
    pub fn failed(&self) -> u64 {
        self.failed
    }

    /// Frames not written because the file reached its cap.
    pub fn capped(&self) -> u64 {
        self.capped.load(Ordering::Acquire)
    }
}

/// One entry read back from a `.tlog`.
#[derive(Debug, Clone, PartialEq)]
pub struct TlogFrame {
    pub t_us: u64,
    pub frame: Vec<u8>,
}

/// Length of the MAVLink frame starting at `b[0]`, from its header, or None if `b` does not
/// start with a frame header.
pub(crate) fn frame_len(b: &[u8]) -> Option<usize> {
    match *b.first()? {
        // v2: STX, len, incompat, compat, seq, sysid, compid, msgid(3), payload, crc(2) [, sig(13)]
        0xFD => {
            let len = *b.get(1)? as usize;
            let signed = b.get(2)? & 0x01 != 0;
            Some(10 + len + 2 + if signed { 13 } else { 0 })
        }
        // v1: STX, len, seq, sysid, compid, msgid, payload, crc(2)
        0xFE => Some(6 + *b.get(1)? as usize + 2),
        _ => None,
    }
}

/// Read every whole entry of a `.tlog`; stops at the first entry that is cut off or does not
/// start with a MAVLink start byte (returns the entries before it and the byte offset).
pub fn read_tlog(path: &Path) -> io::Result<(Vec<TlogFrame>, Option<usize>)> {
    let bytes = std::fs::read(path)?;
    let mut frames = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let rest = &bytes[i..];
        let Some(n) = rest.get(8..).and_then(frame_len) else {
            return Ok((frames, Some(i)));
        };
        if rest.len() < 8 + n {
            return Ok((frames, Some(i)));
        }
        let t_us = u64::from_be_bytes(rest[..8].try_into().expect("8 bytes"));
        frames.push(TlogFrame {
            t_us,
            frame: rest[8..8 + n].to_vec(),
        });
        i += 8 + n;
    }
    Ok((frames, None))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::MavHeader;
    use mavlink::dialects::ardupilotmega::{self as apm, MavMessage};

    fn heartbeat(custom_mode: u32) -> MavMessage {
        MavMessage::HEARTBEAT(apm::HEARTBEAT_DATA {
            custom_mode,
            mavtype: apm::MavType::MAV_TYPE_QUADROTOR,
            autopilot: apm::MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: apm::MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: apm::MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    #[test]
    fn tlog_reads_back_frames_and_times() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("flight.tlog");
        let mut w = TlogWriter::create(&path).unwrap();
        let mut sent = Vec::new();
        for i in 0..5u8 {
            let mut frame = Vec::new();
            let hdr = MavHeader {
                system_id: 1,
                component_id: 1,
                sequence: i,
            };
            let msg = heartbeat(u32::from(i) * 3);
            if i % 2 == 0 {
                mavlink::write_v2_msg(&mut frame, hdr, &msg).unwrap();
            } else {
                mavlink::write_v1_msg(&mut frame, hdr, &msg).unwrap();
            }
            let t = 1_700_000_000_000_000 + u64::from(i) * 250_000;
            w.write(t, &frame).unwrap();
            sent.push((t, frame, msg));
        }
        assert_eq!(w.frames(), 5);
        drop(w);
        // Independent of read_tlog: file length is the sum of 8 + frame length per entry.
        let total: usize = sent.iter().map(|(_, f, _)| 8 + f.len()).sum();
        assert_eq!(std::fs::metadata(&path).unwrap().len() as usize, total);

        let (frames, stop) = read_tlog(&path).unwrap();
        assert_eq!(stop, None);
        assert_eq!(frames.len(), 5);
        for (got, (t, frame, msg)) in frames.iter().zip(&sent) {
            assert_eq!(got.t_us, *t);
            assert_eq!(&got.frame, frame);
            // The mavlink crate decodes the stored frame back into the message we sent.
            let mut r = mavlink::MavlinkReader::new(&got.frame[..]);
            let (_, decoded) = r.read_any_message::<MavMessage>().unwrap();
            assert_eq!(&decoded, msg);
        }
    }

    #[test]
    fn truncated_tlog_keeps_whole_frames() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("cut.tlog");
        let mut w = TlogWriter::create(&path).unwrap();
        let mut frame = Vec::new();
        mavlink::write_v2_msg(&mut frame, MavHeader::default(), &heartbeat(4)).unwrap();
        w.write(1, &frame).unwrap();
        w.write(2, &frame).unwrap();
        drop(w);
        let full = std::fs::read(&path).unwrap();
        std::fs::write(&path, &full[..full.len() - 3]).unwrap();
        let (frames, stop) = read_tlog(&path).unwrap();
        assert_eq!(frames.len(), 1);
        assert_eq!(stop, Some(8 + frame.len()));
    }
}
