//! Bytes in, frames out: the one place network bytes become messages, and messages become bytes.
//!
//! Framing, CRC and signatures are the mavlink crate's (`MavlinkReader`, `write_v2_msg_signed`,
//! `SigningData`); this module only feeds it arbitrary chunks and counts what it drops, so that a
//! noisy serial line or a hostile UDP sender shows up in the counters instead of in a panic.

use super::{Msg, OUR_COMPONENT_ID};
use mavlink::{
    MAVLinkMessageRaw, MavHeader, MavlinkReader, MavlinkVersion, Message, SigningConfig,
    SigningData,
};
use std::io::Read;

/// What the ingest path accepted and dropped, for the decision log and docs/mavlink.md.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct IngestStats {
    /// Bytes received.
    pub bytes_in: u64,
    /// Bytes inside CRC-valid frames.
    pub frame_bytes: u64,
    /// Frames accepted (CRC, dialect and signing checks passed).
    pub frames_ok: u64,
    /// CRC-valid frames whose payload the dialect could not decode (bad enum value, ...).
    pub frames_malformed: u64,
    /// Signed frames whose signature did not verify (signing enabled only).
    pub bad_signatures: u64,
    /// Unsigned COMMAND_LONG/COMMAND_INT addressed to us, refused because signing is enabled.
    pub unsigned_commands_refused: u64,
    /// Other unsigned frames (telemetry, MAVLink 1) refused because signing is enabled.
    pub unsigned_refused: u64,
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
    /// Sender's system and component ids and sequence number.
    pub header: MavHeader,
    /// The decoded message.
    pub msg: Msg,
    /// Whether the frame carried a verified MAVLink 2 signature.
    pub signed: bool,
    /// MAVLink 1 or 2 framing.
    pub version: MavlinkVersion,
    /// The frame exactly as it arrived (start byte through checksum and signature), for the
    /// `.tlog`: re-encoding would lose the signature and could differ from the wire.
    pub raw: Vec<u8>,
}

/// One accepted message, borrowed: the decoded message and the wire bytes stay where the
/// reader put them (see [`Ingest::push_each`]); nothing is copied unless kept.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameRef<'a> {
    /// Sender's system and component ids and sequence number.
    pub header: MavHeader,
    /// The decoded message.
    pub msg: &'a Msg,
    /// Whether the frame carried a verified MAVLink 2 signature.
    pub signed: bool,
    /// MAVLink 1 or 2 framing.
    pub version: MavlinkVersion,
    /// The frame exactly as it arrived (start byte through checksum and signature).
    pub raw: &'a [u8],
}

impl FrameRef<'_> {
    /// The owned [`Frame`] (copies the wire bytes).
    pub fn into_owned(self) -> Frame {
        Frame {
            header: self.header,
            msg: self.msg.clone(),
            signed: self.signed,
            version: self.version,
            raw: self.raw.to_vec(),
        }
    }
}

/// The chunk queue the crate's reader pulls from; empty means "wait for more bytes". A flat
/// buffer and a read position: the reader drains everything it is given before asking again,
/// so the buffer is empty (and reset) at the start of almost every `push`.
#[derive(Default)]
struct Chunks {
    buf: Vec<u8>,
    at: usize,
}

impl Chunks {
    fn extend(&mut self, bytes: &[u8]) {
        // Drop what the reader has taken before appending (usually all of it, so nothing
        // moves): the buffer stays bounded by the unread bytes even if a push ever ends with
        // bytes left over, instead of growing by every chunk of a flight.
        self.buf.drain(..self.at);
        self.at = 0;
        self.buf.extend_from_slice(bytes);
    }
}

impl Read for Chunks {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let rest = &self.buf[self.at..];
        let n = buf.len().min(rest.len());
        buf[..n].copy_from_slice(&rest[..n]);
        self.at += n;
        Ok(n)
    }
}

/// Incremental decoder for one byte stream (one connection; reset it on reconnect).
pub struct Ingest {
    reader: MavlinkReader<Chunks>,
    signing: Option<SigningData>,
    our_system: u8,
    /// Counts of what was accepted and dropped on this stream.
    pub stats: IngestStats,
}

impl Ingest {
    /// `signing`: when set, signed frames must verify and unsigned commands to us are refused.
    pub fn new(signing: Option<SigningData>) -> Self {
        Self {
            reader: MavlinkReader::new(Chunks::default()),
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
        self.reader = MavlinkReader::new(Chunks::default());
    }

    /// Feed one chunk of bytes; returns every complete, valid, accepted message in it.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<Frame> {
        let mut out = Vec::new();
        self.push_each(bytes, |f| out.push(f.into_owned()));
        out
    }

    /// Feed one chunk of bytes and hand every complete, valid, accepted message to `each`, in
    /// order, with its wire bytes borrowed: the same frames as [`Ingest::push`] without a
    /// per-frame allocation (the tlog copies the bytes only when it is on).
    pub fn push_each(&mut self, bytes: &[u8], mut each: impl FnMut(FrameRef<'_>)) {
        self.stats.bytes_in += bytes.len() as u64;
        self.reader.get_mut().extend(bytes);
        // An error is the reader running out of bytes: the rest waits for the next chunk.
        // The raw frame (~280 bytes) and the decoded message are borrowed where they were
        // returned, not moved out: moving them cost a copy each per frame.
        loop {
            let next = self.reader.read_any_raw_message::<Msg>();
            let Ok(raw) = &next else { break };
            let (bytes, signed) = match raw {
                MAVLinkMessageRaw::V1(r) => (r.raw_bytes(), false),
                MAVLinkMessageRaw::V2(r) => (r.raw_bytes(), r.incompatibility_flags() & 0x01 != 0),
            };
            self.stats.frame_bytes += bytes.len() as u64;
            if let (Some(sd), MAVLinkMessageRaw::V2(r)) = (&self.signing, raw)
                && signed
                && !sd.verify_signature(r)
            {
                self.stats.bad_signatures += 1;
                continue;
            }
            let parsed = Msg::parse(raw.version(), raw.message_id(), raw.payload());
            let Ok(msg) = &parsed else {
                self.stats.frames_malformed += 1;
                continue;
            };
            // With a key, unsigned frames are refused like ArduPilot does (GCS_Signing.cpp,
            // `accept_unsigned_callback`: only RADIO_STATUS, "as the radio doesn't know the key"):
            // an injected battery level or target report must not reach the decisions any more
            // than an injected command.
            if self.signing.is_some() && !signed && !matches!(msg, Msg::RADIO_STATUS(_)) {
                if self.is_command_to_us(msg) {
                    self.stats.unsigned_commands_refused += 1;
                } else {
                    self.stats.unsigned_refused += 1;
                }
                continue;
            }
            self.stats.frames_ok += 1;
            let header = MavHeader {
                system_id: raw.system_id(),
                component_id: raw.component_id(),
                sequence: raw.sequence(),
            };
            each(FrameRef {
                header,
                msg,
                signed,
                version: raw.version(),
                raw: bytes,
            });
        }
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
    /// System id written in every header (the autopilot's, as a companion on the same vehicle).
    pub system_id: u8,
    /// Ours by default; benches and the soak run encode an autopilot's telemetry (component 1).
    pub component_id: u8,
    /// Frames encoded so far.
    pub frames_out: u64,
}

impl Encoder {
    /// An encoder with our ids, signing with `signing` when given.
    pub fn new(signing: Option<SigningData>) -> Self {
        Self {
            signing,
            sequence: 0,
            system_id: super::DEFAULT_SYSTEM_ID,
            component_id: OUR_COMPONENT_ID,
            frames_out: 0,
        }
    }

    /// One MAVLink 2 frame of `msg`, with the next sequence number (signed when a key is set).
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
    /// The key file could not be read (file, error).
    #[error("signing key {0}: cannot read: {1}")]
    Read(String, std::io::Error),
    /// The key file holds neither form (file, its length in bytes).
    #[error("signing key {0}: expected 32 raw bytes or 64 hex digits, got {1} bytes")]
    Format(String, usize),
}

/// A MAVLink 2 signing key from the bytes of the key file named `name` (the shell reads it):
/// 32 raw bytes, or 64 hex digits (whitespace ignored). Outgoing frames are signed; incoming
/// unsigned frames are accepted except commands to us.
pub fn parse_signing_key(name: &str, bytes: &[u8]) -> Result<[u8; 32], KeyError> {
    if bytes.len() == 32 {
        let mut k = [0u8; 32];
        k.copy_from_slice(bytes);
        return Ok(k);
    }
    let text: String = String::from_utf8_lossy(bytes).split_whitespace().collect();
    if text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit()) {
        let mut k = [0u8; 32];
        for (i, chunk) in text.as_bytes().chunks(2).enumerate() {
            let s = std::str::from_utf8(chunk).unwrap_or("00");
            k[i] = u8::from_str_radix(s, 16).unwrap_or(0);
        }
        return Ok(k);
    }
    Err(KeyError::Format(name.to_string(), bytes.len()))
}

/// Signing state for one connection (each needs its own: timestamps are per stream).
pub fn signing_data(key: [u8; 32]) -> SigningData {
    SigningData::from_config(SigningConfig::new(key, 0, true, true))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dialect::*;
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
    fn signing_refuses_every_unsigned_frame_but_radio_status() {
        let key = [7u8; 32];
        let sender = signing_data(key);
        let mut ing = Ingest::new(Some(signing_data(key)));
        ing.set_our_system(1);
        let radio = Msg::RADIO_STATUS(RADIO_STATUS_DATA {
            rssi: 200,
            ..RADIO_STATUS_DATA::DEFAULT
        });
        let unsigned_cmd = frame_from(255, 190, &arm_command(), None);
        let signed_cmd = frame_from(255, 190, &arm_command(), Some(&sender));
        let unsigned_hb = frame_from(1, 1, &heartbeat(), None);
        let signed_hb = frame_from(1, 1, &heartbeat(), Some(&sender));
        let unsigned_radio = frame_from(51, 68, &radio, None);
        let wrong_key = frame_from(255, 190, &arm_command(), Some(&signing_data([9u8; 32])));
        let mut v1_hb = Vec::new();
        let h = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 1,
        };
        mavlink::write_v1_msg(&mut v1_hb, h, &heartbeat()).unwrap();
        let got = ing.push(
            &[
                unsigned_cmd,
                signed_cmd,
                unsigned_hb,
                signed_hb,
                unsigned_radio,
                wrong_key,
                v1_hb,
            ]
            .concat(),
        );
        let kinds: Vec<(bool, &str)> = got
            .iter()
            .map(|f| (f.signed, mavlink::Message::message_name(&f.msg)))
            .collect();
        assert_eq!(
            kinds,
            vec![
                (true, "COMMAND_LONG"),
                (true, "HEARTBEAT"),
                (false, "RADIO_STATUS")
            ]
        );
        assert_eq!(ing.stats.unsigned_commands_refused, 1);
        assert_eq!(ing.stats.unsigned_refused, 2); // the v2 and the v1 heartbeat
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
        assert_eq!(parse_signing_key("raw.key", &[5u8; 32]).unwrap(), [5u8; 32]);
        let hex = format!("{}\n", "0a".repeat(32));
        assert_eq!(
            parse_signing_key("hex.key", hex.as_bytes()).unwrap(),
            [10u8; 32]
        );
        assert!(matches!(
            parse_signing_key("short.key", b"abc"),
            Err(KeyError::Format(_, 3))
        ));
    }

    /// The mavlink crate's own reader over the whole stream at once: the independent answer
    /// the chunked ingest must match (same frames, same order, same headers and messages).
    fn crate_reader_frames(stream: &[u8]) -> Vec<(MavHeader, Msg, MavlinkVersion, Vec<u8>)> {
        let mut r = MavlinkReader::new(stream);
        let mut out = Vec::new();
        while let Ok(raw) = r.read_any_raw_message::<Msg>() {
            if let Ok(m) = Msg::parse(raw.version(), raw.message_id(), raw.payload()) {
                let h = MavHeader {
                    system_id: raw.system_id(),
                    component_id: raw.component_id(),
                    sequence: raw.sequence(),
                };
                let bytes = match &raw {
                    MAVLinkMessageRaw::V1(r) => r.raw_bytes().to_vec(),
                    MAVLinkMessageRaw::V2(r) => r.raw_bytes().to_vec(),
                };
                out.push((h, m, raw.version(), bytes));
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
        /// Same frames (and the same wire bytes, for the tlog) as the mavlink crate's reader on
        /// any mix of v1, v2, signed, corrupted frames and garbage with frame markers, whatever
        /// the chunking, whether chunks go through `push` or `push_each`.
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
                let chunk = &stream[at..at + n];
                if k % 2 == 0 {
                    got.extend(ing.push(chunk).into_iter().map(|f| (f.header, f.msg, f.version, f.raw)));
                } else {
                    ing.push_each(chunk, |f| got.push((f.header, f.msg.clone(), f.version, f.raw.to_vec())));
                }
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
