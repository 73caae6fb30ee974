//! Bytes in, frames out: the one place network bytes become messages, and messages become bytes.
//!
//! Framing follows the mavlink crate's reader exactly (a candidate starts at an 0xFD/0xFE
//! marker; unsupported incompatibility flags, a CRC mismatch or an unknown message id reject it
//! and the scan resumes at its second byte, so a marker inside garbage cannot hide a real frame),
//! but runs on one reusable buffer with an inline X.25 CRC: the crate's reader spent two thirds of
//! ingest time in its generic CRC and in copying each frame into a 280-byte raw struct
//! (docs/performance.md, MAVLink ingest). Payload decoding and signature checks are the crate's
//! (`Message::parse`, `SigningData::verify_signature`). This module feeds it arbitrary chunks and
//! counts what it drops, so that a noisy serial line or a hostile UDP sender shows up in the
//! counters instead of in a panic.

use super::{Msg, OUR_COMPONENT_ID};
use mavlink::{
    MAVLinkMessageRaw, MavHeader, MavlinkReader, MavlinkVersion, Message, SigningConfig,
    SigningData,
};
use std::path::Path;

/// What the ingest path accepted and dropped, for the decision log and docs/mavlink.md.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct IngestStats {
    pub bytes_in: u64,
    /// Bytes inside CRC-valid frames.
    pub frame_bytes: u64,
    pub frames_ok: u64,
    /// CRC-valid frames whose payload the dialect could not decode (bad enum value, ...).
    pub frames_malformed: u64,
    /// Signed frames whose signature did not verify (signing enabled only).
    pub bad_signatures: u64,
    /// Unsigned COMMAND_LONG/COMMAND_INT addressed to us, refused because signing is enabled.
    pub unsigned_commands_refused: u64,
}

impl IngestStats {
    /// Bytes that were not part of any valid frame so far (garbage, broken frames, unknown
    /// message ids, plus a frame still arriving).
    pub fn bytes_unframed(&self) -> u64 {
        self.bytes_in - self.frame_bytes
    }
}

/// One accepted message.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub header: MavHeader,
    pub msg: Msg,
    pub signed: bool,
    pub version: MavlinkVersion,
}

const STX_V1: u8 = 0xFE;
const STX_V2: u8 = 0xFD;
const IFLAG_SIGNED: u8 = 0x01;
const IFLAG_SYSID32: u8 = 0x02;
const SIGNATURE_LEN: usize = 13;

/// MAVLink's CRC-16/MCRF4XX (X.25) accumulate, one byte at a time (mavlink.io checksum).
#[inline]
fn crc_accumulate(crc: u16, b: u8) -> u16 {
    let mut tmp = b ^ (crc as u8);
    tmp ^= tmp << 4;
    let t = tmp as u16;
    (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4)
}

fn crc(data: &[u8], extra: u8) -> u16 {
    crc_accumulate(
        data.iter().fold(0xFFFF, |c, &b| crc_accumulate(c, b)),
        extra,
    )
}

/// One CRC-valid frame found at the start of the scanned slice.
struct Found {
    len: usize,
    version: MavlinkVersion,
}

/// Scan `buf` for the next CRC-valid frame. Returns (bytes before it that are not part of any
/// frame, the frame), or (bytes that can be dropped, None) when more input is needed.
fn scan(buf: &[u8]) -> (usize, Option<Found>) {
    let mut i = 0;
    loop {
        let Some(off) = buf[i..].iter().position(|&b| b == STX_V2 || b == STX_V1) else {
            return (buf.len(), None);
        };
        i += off;
        let c = &buf[i..];
        let v2 = c[0] == STX_V2;
        if c.len() < if v2 { 3 } else { 2 } {
            return (i, None);
        }
        let flags = if v2 { c[2] } else { 0 };
        if flags & !(IFLAG_SIGNED | IFLAG_SYSID32) != 0 {
            i += 1;
            continue;
        }
        let payload_len = c[1] as usize;
        let sysid32 = flags & IFLAG_SYSID32 != 0;
        let header_len = match (v2, sysid32) {
            (false, _) => 5,
            (true, false) => 9,
            (true, true) => 12,
        };
        let signature = if flags & IFLAG_SIGNED != 0 {
            SIGNATURE_LEN
        } else {
            0
        };
        let len = 1 + header_len + payload_len + 2 + signature;
        if c.len() < len {
            return (i, None);
        }
        let id = match (v2, sysid32) {
            (false, _) => c[5] as u32,
            (true, false) => u32::from_le_bytes([c[7], c[8], c[9], 0]),
            (true, true) => u32::from_le_bytes([c[10], c[11], c[12], 0]),
        };
        let at = 1 + header_len + payload_len;
        let expected = u16::from_le_bytes([c[at], c[at + 1]]);
        if crc(&c[1..at], <Msg as Message>::extra_crc(id)) == expected {
            let version = if v2 {
                MavlinkVersion::V2
            } else {
                MavlinkVersion::V1
            };
            return (i, Some(Found { len, version }));
        }
        i += 1;
    }
}

/// Header, message id and payload of a CRC-valid frame (layout as in the mavlink crate).
fn parts(f: &[u8], version: MavlinkVersion) -> (MavHeader, u32, &[u8]) {
    match version {
        MavlinkVersion::V1 => (
            MavHeader {
                system_id: f[3] as u32,
                component_id: f[4],
                sequence: f[2],
            },
            f[5] as u32,
            &f[6..6 + f[1] as usize],
        ),
        MavlinkVersion::V2 if f[2] & IFLAG_SYSID32 != 0 => (
            MavHeader {
                system_id: u32::from_le_bytes([f[5], f[6], f[7], f[8]]),
                component_id: f[9],
                sequence: f[4],
            },
            u32::from_le_bytes([f[10], f[11], f[12], 0]),
            &f[13..13 + f[1] as usize],
        ),
        MavlinkVersion::V2 => (
            MavHeader {
                system_id: f[5] as u32,
                component_id: f[6],
                sequence: f[4],
            },
            u32::from_le_bytes([f[7], f[8], f[9], 0]),
            &f[10..10 + f[1] as usize],
        ),
    }
}

/// The crate's raw form of one signed frame, for its signature check (signing only).
fn raw_v2(frame: &[u8]) -> Option<mavlink::MAVLinkV2MessageRaw> {
    match MavlinkReader::new(frame).read_any_raw_message::<Msg>() {
        Ok(MAVLinkMessageRaw::V2(r)) => Some(r),
        _ => None,
    }
}

/// Incremental decoder for one byte stream (one connection; reset it on reconnect).
pub struct Ingest {
    /// Bytes not yet consumed start at `start`; the buffer keeps its capacity.
    buf: Vec<u8>,
    start: usize,
    signing: Option<SigningData>,
    our_system: u8,
    pub stats: IngestStats,
}

impl Ingest {
    /// `signing`: when set, signed frames must verify and unsigned commands to us are refused.
    pub fn new(signing: Option<SigningData>) -> Self {
        Self {
            buf: Vec::with_capacity(4096),
            start: 0,
            signing,
            our_system: super::DEFAULT_SYSTEM_ID,
            stats: IngestStats::default(),
        }
    }

    /// Our system id, used to recognise commands addressed to us.
    pub fn set_our_system(&mut self, sys: u8) {
        self.our_system = sys;
    }

    /// Drop buffered partial frames (after a reconnect the old stream's tail is meaningless).
    pub fn reset(&mut self) {
        self.buf.clear();
        self.start = 0;
    }

    /// Feed one chunk of bytes; returns every complete, valid, accepted message in it.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Frame> {
        self.stats.bytes_in += bytes.len() as u64;
        // Keep only the unconsumed tail (at most one partial frame), then append.
        self.buf.drain(..self.start);
        self.start = 0;
        self.buf.extend_from_slice(bytes);
        let mut out = Vec::new();
        loop {
            let (skip, found) = scan(&self.buf[self.start..]);
            self.start += skip;
            let Some(Found { len, version }) = found else {
                break;
            };
            let at = self.start;
            self.start += len;
            self.stats.frame_bytes += len as u64;
            let frame = &self.buf[at..at + len];
            let signed = version == MavlinkVersion::V2 && frame[2] & IFLAG_SIGNED != 0;
            if let Some(sd) = &self.signing
                && signed
                && !raw_v2(frame).is_some_and(|r| sd.verify_signature(&r))
            {
                self.stats.bad_signatures += 1;
                continue;
            }
            let (header, id, payload) = parts(frame, version);
            let msg = match Msg::parse(version, id, payload) {
                Ok(m) => m,
                Err(_) => {
                    self.stats.frames_malformed += 1;
                    continue;
                }
            };
            if self.signing.is_some() && !signed && self.is_command_to_us(&msg) {
                self.stats.unsigned_commands_refused += 1;
                continue;
            }
            self.stats.frames_ok += 1;
            out.push(Frame {
                header,
                msg,
                signed,
                version,
            });
        }
        out
    }

    fn is_command_to_us(&self, msg: &Msg) -> bool {
        let (ts, tc) = match msg {
            Msg::COMMAND_LONG(c) => (c.target_system, c.target_component),
            Msg::COMMAND_INT(c) => (c.target_system, c.target_component),
            Msg::COMMAND_CANCEL(c) => (c.target_system, c.target_component),
            _ => return false,
        };
        (ts == self.our_system || ts == 0) && (tc == OUR_COMPONENT_ID || tc == 0)
    }
}

/// Serialises outgoing messages as MAVLink 2 (signed when a key is set), with our header and
/// a running sequence number.
pub struct Encoder {
    signing: Option<SigningData>,
    sequence: u8,
    pub system_id: u8,
    /// Ours by default; benches and the soak run encode an autopilot's telemetry (component 1).
    pub component_id: u8,
    pub frames_out: u64,
}

impl Encoder {
    pub fn new(signing: Option<SigningData>) -> Self {
        Self {
            signing,
            sequence: 0,
            system_id: super::DEFAULT_SYSTEM_ID,
            component_id: OUR_COMPONENT_ID,
            frames_out: 0,
        }
    }

    pub fn encode(&mut self, msg: &Msg) -> Vec<u8> {
        let header = MavHeader {
            system_id: self.system_id as u32,
            component_id: self.component_id,
            sequence: self.sequence,
        };
        self.sequence = self.sequence.wrapping_add(1);
        self.frames_out += 1;
        let mut buf = Vec::with_capacity(64);
        // Writing into a Vec cannot fail for a message of our own dialect.
        let _ = mavlink::write_v2_msg_signed(&mut buf, header, msg, self.signing.as_ref());
        buf
    }
}

/// Why a signing key file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    #[error("signing key {0}: cannot read: {1}")]
    Read(String, std::io::Error),
    #[error("signing key {0}: expected 32 raw bytes or 64 hex digits, got {1} bytes")]
    Format(String, usize),
}

/// Load a MAVLink 2 signing key: 32 raw bytes, or 64 hex digits (whitespace ignored).
/// Outgoing frames are signed; incoming unsigned frames are accepted except commands to us.
pub fn load_signing_key(path: &Path) -> Result<[u8; 32], KeyError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| KeyError::Read(name.clone(), e))?;
    if bytes.len() == 32 {
        let mut k = [0u8; 32];
        k.copy_from_slice(&bytes);
        return Ok(k);
    }
    let text: String = String::from_utf8_lossy(&bytes).split_whitespace().collect();
    if text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit()) {
        let mut k = [0u8; 32];
        for (i, chunk) in text.as_bytes().chunks(2).enumerate() {
            let s = std::str::from_utf8(chunk).unwrap_or("00");
            k[i] = u8::from_str_radix(s, 16).unwrap_or(0);
        }
        return Ok(k);
    }
    Err(KeyError::Format(name, bytes.len()))
}

/// Signing state for one connection (each needs its own: timestamps are per stream).
pub fn signing_data(key: [u8; 32]) -> SigningData {
    SigningData::from_config(SigningConfig::new(key, 0, true, true))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::dialect::*;
    use proptest::prelude::*;

    fn heartbeat() -> Msg {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 4,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn frame_from(sys: u8, comp: u8, msg: &Msg, signing: Option<&SigningData>) -> Vec<u8> {
        let mut buf = Vec::new();
        let h = MavHeader {
            system_id: sys as u32,
            component_id: comp,
            sequence: 7,
        };
        mavlink::write_v2_msg_signed(&mut buf, h, msg, signing).unwrap();
        buf
    }

    fn arm_command() -> Msg {
        Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            command: MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            target_system: 1,
            target_component: OUR_COMPONENT_ID,
            param1: 1.0,
            ..COMMAND_LONG_DATA::DEFAULT
        })
    }

    #[test]
    fn decodes_frames_split_at_every_byte_boundary() {
        let bytes = [
            frame_from(1, 1, &heartbeat(), None),
            frame_from(1, 1, &heartbeat(), None),
        ]
        .concat();
        for cut in 0..bytes.len() {
            let mut ing = Ingest::new(None);
            let mut got = ing.push(&bytes[..cut]);
            got.extend(ing.push(&bytes[cut..]));
            assert_eq!(got.len(), 2, "cut at {cut}");
            assert_eq!(got[0].header.system_id, 1);
            assert_eq!(got[0].msg, heartbeat());
            assert_eq!(ing.stats.bytes_unframed(), 0);
        }
    }

    #[test]
    fn corrupted_frame_is_counted_and_the_next_one_survives() {
        let good = frame_from(1, 1, &heartbeat(), None);
        let mut bad = good.clone();
        bad[12] ^= 0xff; // payload byte: CRC no longer matches
        let mut ing = Ingest::new(None);
        let got = ing.push(&[bad.clone(), good.clone()].concat());
        assert_eq!(got.len(), 1);
        assert_eq!(ing.stats.frames_ok, 1);
        assert_eq!(ing.stats.bytes_unframed(), bad.len() as u64);
    }

    #[test]
    fn signing_refuses_unsigned_commands_to_us_but_keeps_telemetry() {
        let key = [7u8; 32];
        let sender = signing_data(key);
        let mut ing = Ingest::new(Some(signing_data(key)));
        ing.set_our_system(1);
        let unsigned_cmd = frame_from(255, 190, &arm_command(), None);
        let signed_cmd = frame_from(255, 190, &arm_command(), Some(&sender));
        let unsigned_hb = frame_from(1, 1, &heartbeat(), None);
        let wrong_key = frame_from(255, 190, &arm_command(), Some(&signing_data([9u8; 32])));
        let got = ing.push(&[unsigned_cmd, signed_cmd, unsigned_hb, wrong_key].concat());
        assert_eq!(got.len(), 2);
        assert!(got[0].signed && matches!(got[0].msg, Msg::COMMAND_LONG(_)));
        assert!(!got[1].signed && matches!(got[1].msg, Msg::HEARTBEAT(_)));
        assert_eq!(ing.stats.unsigned_commands_refused, 1);
        assert_eq!(ing.stats.bad_signatures, 1);
    }

    #[test]
    fn mavlink1_frames_are_accepted() {
        // ArduPilot starts MAVLink 1 on some ports until it hears MAVLink 2.
        let mut buf = Vec::new();
        let h = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 3,
        };
        mavlink::write_v1_msg(&mut buf, h, &heartbeat()).unwrap();
        let got = Ingest::new(None).push(&buf);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].version, MavlinkVersion::V1);
        assert_eq!(got[0].msg, heartbeat());
    }

    #[test]
    fn without_signing_unsigned_commands_pass() {
        let mut ing = Ingest::new(None);
        assert_eq!(
            ing.push(&frame_from(255, 190, &arm_command(), None)).len(),
            1
        );
    }

    #[test]
    fn encoder_output_decodes_and_is_signed_when_keyed() {
        let key = [3u8; 32];
        let mut enc = Encoder::new(Some(signing_data(key)));
        enc.system_id = 42;
        let bytes = enc.encode(&heartbeat());
        let mut ing = Ingest::new(Some(signing_data(key)));
        let got = ing.push(&bytes);
        assert_eq!(got.len(), 1);
        assert!(got[0].signed);
        assert_eq!(
            (got[0].header.system_id, got[0].header.component_id),
            (42, OUR_COMPONENT_ID)
        );
        let mut plain = Encoder::new(None);
        let got = Ingest::new(None).push(&plain.encode(&heartbeat()));
        assert!(!got[0].signed);
    }

    #[test]
    fn key_file_formats() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("raw.key");
        std::fs::write(&raw, [5u8; 32]).unwrap();
        assert_eq!(load_signing_key(&raw).unwrap(), [5u8; 32]);
        let hex = dir.path().join("hex.key");
        std::fs::write(&hex, format!("{}\n", "0a".repeat(32))).unwrap();
        assert_eq!(load_signing_key(&hex).unwrap(), [10u8; 32]);
        let short = dir.path().join("short.key");
        std::fs::write(&short, "abc").unwrap();
        assert!(matches!(
            load_signing_key(&short),
            Err(KeyError::Format(_, 3))
        ));
        assert!(matches!(
            load_signing_key(&dir.path().join("missing")),
            Err(KeyError::Read(..))
        ));
    }

    /// The mavlink crate's own reader over the whole stream at once: the independent answer
    /// the chunked ingest must match (same frames, same order, same headers and messages).
    fn crate_reader_frames(stream: &[u8]) -> Vec<(MavHeader, Msg, MavlinkVersion)> {
        let mut r = MavlinkReader::new(stream);
        let mut out = Vec::new();
        while let Ok(raw) = r.read_any_raw_message::<Msg>() {
            if let Ok(m) = Msg::parse(raw.version(), raw.message_id(), raw.payload()) {
                let h = MavHeader {
                    system_id: raw.system_id(),
                    component_id: raw.component_id(),
                    sequence: raw.sequence(),
                };
                out.push((h, m, raw.version()));
            }
        }
        out
    }

    fn piece() -> impl Strategy<Value = Vec<u8>> {
        let sd = signing_data([4u8; 32]);
        prop_oneof![
            // v2 frame, unsigned or signed, any sender
            (any::<u8>(), any::<u8>(), any::<u8>(), any::<bool>()).prop_map(
                move |(s, c, q, sign)| {
                    let mut b = Vec::new();
                    let h = MavHeader {
                        system_id: s as u32,
                        component_id: c,
                        sequence: q,
                    };
                    let msg = if q % 2 == 0 {
                        heartbeat()
                    } else {
                        arm_command()
                    };
                    mavlink::write_v2_msg_signed(
                        &mut b,
                        h,
                        &msg,
                        if sign { Some(&sd) } else { None },
                    )
                    .unwrap();
                    b
                }
            ),
            // v1 frame
            (any::<u8>(), any::<u8>()).prop_map(|(s, q)| {
                let mut b = Vec::new();
                let h = MavHeader {
                    system_id: s as u32,
                    component_id: 1,
                    sequence: q,
                };
                mavlink::write_v1_msg(&mut b, h, &heartbeat()).unwrap();
                b
            }),
            // garbage, markers included (a bogus header's length may cover real frames)
            proptest::collection::vec(prop_oneof![any::<u8>(), Just(0xFDu8), Just(0xFEu8)], 1..40),
            // a corrupted v2 frame: one byte anywhere flipped
            (any::<u8>(), any::<prop::sample::Index>()).prop_map(|(x, i)| {
                let mut b = frame_from(1, 1, &heartbeat(), None);
                let k = i.index(b.len());
                b[k] ^= x | 1;
                b
            }),
        ]
    }

    proptest! {
        /// Same frames as the mavlink crate's reader on any mix of v1, v2, signed, corrupted
        /// frames and garbage with frame markers, whatever the chunking.
        #[test]
        fn chunked_ingest_matches_the_crate_reader(
            pieces in proptest::collection::vec(piece(), 0..30),
            cuts in proptest::collection::vec(1usize..200, 1..20),
        ) {
            let stream = pieces.concat();
            let want = crate_reader_frames(&stream);
            let mut ing = Ingest::new(None);
            let mut got = Vec::new();
            let mut at = 0;
            let mut k = 0;
            while at < stream.len() {
                let n = cuts[k % cuts.len()].min(stream.len() - at);
                k += 1;
                got.extend(ing.push(&stream[at..at + n]).into_iter().map(|f| (f.header, f.msg, f.version)));
                at += n;
            }
            prop_assert_eq!(got, want);
        }

        #[test]
        fn random_bytes_never_panic_and_are_accounted(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..300), 0..20)) {
            let mut ing = Ingest::new(Some(signing_data([1u8; 32])));
            let mut total = 0u64;
            let mut n = 0u64;
            for c in &chunks {
                total += c.len() as u64;
                n += ing.push(c).len() as u64;
            }
            prop_assert_eq!(ing.stats.bytes_in, total);
            prop_assert_eq!(ing.stats.frames_ok, n);
            prop_assert!(ing.stats.frame_bytes <= total);
        }

        /// Garbage without frame markers between valid frames: every frame comes out, and
        /// exactly the garbage bytes are counted as unframed.
        #[test]
        fn garbage_between_frames_is_counted_exactly(
            garbage in proptest::collection::vec(proptest::collection::vec(any::<u8>().prop_filter("no STX", |b| *b != 0xFD && *b != 0xFE), 0..64), 1..8),
            split in 1usize..50,
        ) {
            let frame = frame_from(1, 1, &heartbeat(), None);
            let mut stream = Vec::new();
            let mut garbage_len = 0;
            for g in &garbage {
                stream.extend_from_slice(g);
                stream.extend_from_slice(&frame);
                garbage_len += g.len();
            }
            let mut ing = Ingest::new(None);
            let mut got = 0;
            for c in stream.chunks(split) {
                got += ing.push(c).len();
            }
            prop_assert_eq!(got, garbage.len());
            prop_assert_eq!(ing.stats.bytes_unframed(), garbage_len as u64);
        }
    }
}
