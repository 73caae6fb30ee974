//! `companion signing-setup`: make a MAVLink 2 signing key, give it to the autopilot with
//! SETUP_SIGNING, and prove it took by talking signed (issue 26).
//!
//! SETUP_SIGNING has no acknowledgement. The proof is the autopilot's own behaviour: its frames
//! come back signed with our key (ArduPilot signs everything once it holds a key,
//! `GCS_Signing.cpp` `load_signing_key`), and it answers a signed COMMAND_LONG
//! (MAV_CMD_REQUEST_MESSAGE) with a COMMAND_ACK that verifies with the key. Anything short of
//! both is a failure, said with what was seen, and a non-zero exit.
//!
//! The secret goes only where the operator names (issue 40 item 5): the autopilot's system AND
//! component are both required, the pinned autopilot is listened to for [`LISTEN`] first, and any
//! other autopilot heard on the link before the proof ends the set-up, the key unsent if it was
//! heard first.

use crate::fly::transport::{self, Inbound, UdpPeer};
use crate::review::text::escape_controls;
use anyhow::Context;
use companion_link::Msg;
use companion_link::actions::ActionTable;
use companion_link::dialect::*;
use companion_link::ingest::{self, Encoder, Frame, Ingest};
use companion_link::url::{self, ConnectUrl};
use companion_link::vehicle::{Vehicle, VehicleConfig, is_autopilot_heartbeat};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// `companion signing-setup` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct SigningSetupArgs {
    /// Autopilot connection (the URLs `fly --connect` takes). Use a link only you can reach:
    /// the key crosses it in clear once.
    #[arg(long, value_parser = url::parse)]
    pub connect: ConnectUrl,
    /// Where to write the new key (64 hex digits, mode 0600); refused if the file exists.
    #[arg(long)]
    pub key: PathBuf,
    /// Write a new key over an existing key file (the old key stops working with the autopilot).
    #[arg(long)]
    pub force: bool,
    /// The autopilot to provision: its MAVLink system id (required, with --autopilot-compid:
    /// the key goes only to the autopilot named, never to the first one heard).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_sysid: Option<u8>,
    /// The autopilot's component id (required; 1 is MAV_COMP_ID_AUTOPILOT1, ArduPilot's and PX4's).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..))]
    pub autopilot_compid: Option<u8>,
    /// Give up when no autopilot HEARTBEAT arrives within this long.
    #[arg(long, default_value = "30s", value_parser = companion_link::liveness::parse_duration)]
    pub timeout: Duration,
}

/// SETUP_SIGNING is sent again while the autopilot's frames stay unsigned, this often ...
const SETUP_RETRY: Duration = Duration::from_millis(1500);
/// ... this many times in all.
const SETUP_ATTEMPTS: u32 = 5;
/// The signed REQUEST_MESSAGE is sent again while unanswered, this often and this many times.
const VERIFY_RETRY: Duration = Duration::from_secs(1);
const VERIFY_ATTEMPTS: u32 = 5;
/// The pinned autopilot is listened to this long (two 1 Hz heartbeats) before the key is sent:
/// another autopilot answering on the link in that time stops the set-up with the key unsent.
pub const LISTEN: Duration = Duration::from_secs(2);
/// The message the signed verification command asks for.
const AUTOPILOT_VERSION_ID: f32 = 148.0;

/// MAVLink signing timestamps: 10 µs units since 2015-01-01 00:00 UTC.
pub fn signing_timestamp(now: std::time::SystemTime) -> u64 {
    const EPOCH_2015_S: u64 = 1_420_070_400;
    let us = now
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64);
    us.saturating_sub(EPOCH_2015_S * 1_000_000) / 10
}

/// Write a fresh random key to `path` as 64 hex digits, mode 0600, through a temporary file
/// and a rename (never a half-written key). An existing file is kept unless `force`.
pub fn write_new_key(path: &Path, force: bool) -> anyhow::Result<[u8; 32]> {
    use rand::TryRngCore;
    use std::io::Write;
    // The shared output rules (output_file): no FIFO or device, no control characters in the
    // name; then the key's own: an existing key is kept unless --force.
    crate::output_file::check(path, &[], "signing-setup")
        .map_err(|e| anyhow::anyhow!("--key {e}"))?;
    let shown = crate::output_file::shown(path);
    match std::fs::symlink_metadata(path) {
        Ok(m) if !force => anyhow::bail!(
            "--key {shown}: a {} is already there; refusing to overwrite a key (--force writes a new one, and the old one stops working with the autopilot)",
            if m.is_file() { "file" } else { "non-file" }
        ),
        Ok(m) if !m.is_file() => {
            anyhow::bail!("--key {shown}: not a regular file; refusing to replace it")
        }
        _ => {}
    }
    let mut key = [0u8; 32];
    rand::rngs::OsRng
        .try_fill_bytes(&mut key)
        .context("reading the system's random source for the key")?;
    let hex: String = key.iter().map(|b| format!("{b:02x}")).collect();
    // A temporary file beside the key (created 0600), renamed over it only when whole.
    let written = (|| -> std::io::Result<()> {
        let mut tmp = crate::output_file::temp_beside(path)?;
        tmp.write_all(format!("{hex}\n").as_bytes())?;
        crate::output_file::persist(tmp, path, 0o600)
    })();
    written.with_context(|| format!("writing the key to {shown}"))?;
    Ok(key)
}

#[derive(Debug, Clone, PartialEq)]
enum Phase {
    WaitAutopilot,
    /// The pinned autopilot heard (first at): listening for others before the key goes out.
    Listen(Duration),
    /// SETUP_SIGNING sent (attempts, last at): waiting for the autopilot's frames to be signed.
    Setup(u32, Duration),
    /// The signed REQUEST_MESSAGE sent (attempts, last at): waiting for its signed ACK.
    Verify(u32, Duration),
    Done(Result<String, String>),
}

/// The provisioning protocol, sans IO: frames and ticks in, wire bytes out.
pub struct Provisioner {
    key: [u8; 32],
    initial_timestamp: u64,
    /// The pinned autopilot (system, component): the only one the key goes to.
    pin: (u8, u8),
    /// Tracks the pinned autopilot's state (armed) as `fly` does.
    vehicle: Vehicle,
    keyed: Ingest,
    plain: Encoder,
    signed: Encoder,
    phase: Phase,
    wait_until: Duration,
    verified: u64,
    bad_signatures: u64,
    unsigned_after_setup: u64,
}

impl Provisioner {
    /// `initial_timestamp`: SETUP_SIGNING's, in [`signing_timestamp`] units; `autopilot`: the
    /// pinned system and component; `heartbeat_timeout`: how long to wait for it.
    pub fn new(
        key: [u8; 32],
        initial_timestamp: u64,
        autopilot: (u8, u8),
        heartbeat_timeout: Duration,
    ) -> Self {
        let cfg = VehicleConfig {
            autopilot_sysid: Some(autopilot.0),
            autopilot_compid: autopilot.1,
            ..VehicleConfig::default()
        };
        Self {
            key,
            pin: autopilot,
            initial_timestamp,
            vehicle: Vehicle::new(cfg, ActionTable::default(), None),
            keyed: Ingest::new(Some(ingest::signing_data(key))),
            plain: Encoder::new(None),
            signed: Encoder::new(Some(ingest::signing_data(key))),
            phase: Phase::WaitAutopilot,
            wait_until: heartbeat_timeout,
            verified: 0,
            bad_signatures: 0,
            unsigned_after_setup: 0,
        }
    }

    /// The chosen autopilot (system, component), once heard.
    pub fn target(&self) -> Option<(u8, u8)> {
        self.vehicle.target()
    }

    /// Ok(what was proven) or Err(why not), once finished.
    pub fn outcome(&self) -> Option<&Result<String, String>> {
        match &self.phase {
            Phase::Done(r) => Some(r),
            _ => None,
        }
    }

    fn setup_signing(&mut self, now: Duration, attempt: u32) -> Vec<Vec<u8>> {
        let (sys, comp) = self.pin;
        self.phase = Phase::Setup(attempt, now);
        let msg = Msg::SETUP_SIGNING(SETUP_SIGNING_DATA {
            initial_timestamp: self.initial_timestamp,
            target_system: sys,
            target_component: comp,
            secret_key: self.key,
        });
        // Unsigned: the autopilot has no key to check a signature with yet.
        vec![self.plain.encode(&msg)]
    }

    fn request(&mut self, now: Duration, attempt: u32) -> Vec<Vec<u8>> {
        let (sys, comp) = self.pin;
        self.phase = Phase::Verify(attempt, now);
        let msg = Msg::COMMAND_LONG(COMMAND_LONG_DATA {
            target_system: sys,
            target_component: comp,
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            confirmation: (attempt - 1).min(255) as u8,
            param1: AUTOPILOT_VERSION_ID,
            ..COMMAND_LONG_DATA::DEFAULT
        });
        vec![self.signed.encode(&msg)]
    }

    /// A frame from the link (parsed without a key: signed or not, not yet verified).
    pub fn on_frame(&mut self, now: Duration, f: &Frame) -> Vec<Vec<u8>> {
        if self.outcome().is_some() {
            return Vec::new();
        }
        let _ = self.vehicle.on_frame(now, f);
        let src = (f.header.system_id.min(255) as u8, f.header.component_id);
        if let Msg::HEARTBEAT(h) = &f.msg
            && is_autopilot_heartbeat(h)
            && src != self.pin
        {
            self.another_autopilot(src);
            return Vec::new();
        }
        let Some(target) = self.vehicle.target() else {
            return Vec::new();
        };
        self.plain.system_id = target.0;
        self.signed.system_id = target.0;
        let from_target = src == target;
        if matches!(self.phase, Phase::WaitAutopilot | Phase::Listen(_))
            && self.vehicle.readiness().armed
        {
            self.phase = Phase::Done(Err(format!(
                "autopilot {}/{} is armed: a key is set up on the ground, disarmed, not in flight",
                target.0, target.1
            )));
            return Vec::new();
        }
        match self.phase.clone() {
            Phase::WaitAutopilot => {
                self.phase = Phase::Listen(now);
                Vec::new()
            }
            Phase::Listen(since) if now.saturating_sub(since) >= LISTEN => {
                self.setup_signing(now, 1)
            }
            Phase::Setup(..) | Phase::Verify(..) if from_target => {
                if !f.signed {
                    self.unsigned_after_setup += 1;
                    return Vec::new();
                }
                // Verified with our key (the keyed ingest drops a bad signature or a replay).
                let Some(v) = self.keyed.push(&f.raw).pop() else {
                    self.bad_signatures += 1;
                    return Vec::new();
                };
                self.verified += 1;
                match (&self.phase, &v.msg) {
                    (Phase::Setup(..), _) => self.request(now, 1),
                    (Phase::Verify(..), Msg::COMMAND_ACK(a))
                        if a.command == MavCmd::MAV_CMD_REQUEST_MESSAGE =>
                    {
                        self.phase = Phase::Done(Ok(format!(
                            "autopilot {}/{} holds the key: {} of its frames verified with it, and it answered a signed REQUEST_MESSAGE with a signed COMMAND_ACK ({:?})",
                            target.0, target.1, self.verified, a.result
                        )));
                        Vec::new()
                    }
                    _ => Vec::new(),
                }
            }
            _ => Vec::new(),
        }
    }

    /// Another autopilot answers on the link: the set-up ends; the key was never sent when it is
    /// heard before the listening time is over.
    fn another_autopilot(&mut self, (sys, comp): (u8, u8)) {
        let (ps, pc) = self.pin;
        let sent = match self.phase {
            Phase::WaitAutopilot | Phase::Listen(_) => "the key was not sent".to_string(),
            _ => format!(
                "the key went to {ps}/{pc} alone (addressed to it, in clear on this link), not verified"
            ),
        };
        self.phase = Phase::Done(Err(format!(
            "another autopilot, {sys}/{comp}, answers on this link besides the pinned {ps}/{pc}: {sent}; set the key up on a link where only that autopilot speaks (its USB or a direct serial wire)"
        )));
    }

    /// Resends and give-ups; the key goes out once the pinned autopilot was listened to
    /// for [`LISTEN`] alone.
    pub fn tick(&mut self, now: Duration) -> Vec<Vec<u8>> {
        match self.phase.clone() {
            Phase::Listen(since) if now.saturating_sub(since) >= LISTEN => {
                self.setup_signing(now, 1)
            }
            Phase::WaitAutopilot if now >= self.wait_until => {
                self.phase = Phase::Done(Err(format!(
                    "no HEARTBEAT from the pinned autopilot {}/{} within {:?}",
                    self.pin.0, self.pin.1, self.wait_until,
                )));
                Vec::new()
            }
            Phase::Setup(n, at) if now.saturating_sub(at) >= SETUP_RETRY => {
                if n < SETUP_ATTEMPTS {
                    return self.setup_signing(now, n + 1);
                }
                let why = if self.bad_signatures > 0 {
                    format!(
                        "its frames are signed with another key ({} with signatures that do not verify): it was provisioned before and refuses an unsigned SETUP_SIGNING on this link; set it up again over its USB/first port or with the old key",
                        self.bad_signatures
                    )
                } else if self.unsigned_after_setup > 0 {
                    format!(
                        "its frames stay unsigned ({} since the first SETUP_SIGNING): it did not take the key (an autopilot without MAVLink signing, e.g. a PX4 older than v1.18, or a link that does not pass SETUP_SIGNING)",
                        self.unsigned_after_setup
                    )
                } else {
                    "it fell silent after SETUP_SIGNING".to_string()
                };
                self.phase = Phase::Done(Err(format!(
                    "{SETUP_ATTEMPTS} SETUP_SIGNING sent and the autopilot never spoke signed with the key: {why}"
                )));
                Vec::new()
            }
            Phase::Verify(n, at) if now.saturating_sub(at) >= VERIFY_RETRY => {
                if n < VERIFY_ATTEMPTS {
                    return self.request(now, n + 1);
                }
                self.phase = Phase::Done(Err(format!(
                    "the autopilot signs with the key ({} frames verified) but never answered {VERIFY_ATTEMPTS} signed REQUEST_MESSAGE commands: it does not accept our signed frames (its signing timestamp ahead of this computer's clock by more than a minute?)",
                    self.verified
                )));
                Vec::new()
            }
            _ => Vec::new(),
        }
    }
}

/// The pinned autopilot of the command line, or why there is none: both ids are required.
pub fn pin(args: &SigningSetupArgs) -> anyhow::Result<(u8, u8)> {
    match (args.autopilot_sysid, args.autopilot_compid) {
        (Some(sys), Some(comp)) => Ok((sys, comp)),
        (sys, comp) => anyhow::bail!(
            "signing-setup needs the autopilot named: {} missing; the secret key goes only to the system and component you give (e.g. --autopilot-sysid 1 --autopilot-compid 1), never to whichever autopilot speaks first; nothing was written or sent",
            match (sys, comp) {
                (None, None) => "--autopilot-sysid and --autopilot-compid",
                (None, _) => "--autopilot-sysid",
                _ => "--autopilot-compid",
            }
        ),
    }
}

/// The subcommand: write the key, provision it, prove it; Ok only when proven.
pub fn run(args: &SigningSetupArgs) -> anyhow::Result<()> {
    let pin = pin(args)?;
    // The file name is the operator's: shown escaped, never sent to the terminal raw.
    let shown = escape_controls(&args.key.display().to_string(), false);
    let key = write_new_key(&args.key, args.force)
        .map_err(|e| anyhow::anyhow!(escape_controls(&format!("{e:#}"), false)))?;
    println!("signing-setup: new key written to {shown} (mode 0600)");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the tokio runtime")?;
    let outcome = rt.block_on(provision(args, pin, key));
    match outcome {
        Ok(done) => {
            println!("signing-setup: verified: {done}");
            println!(
                "signing-setup: fly with --signing-key {shown} --autopilot-sysid {} --autopilot-compid {} (and --require-signing to refuse an unsigned link)",
                pin.0, pin.1
            );
            Ok(())
        }
        Err(why) => anyhow::bail!(
            "signing-setup on {}: NOT verified: {why} (the key stays in {shown})",
            escape_controls(&args.connect.to_string(), false)
        ),
    }
}

async fn provision(
    args: &SigningSetupArgs,
    pin: (u8, u8),
    key: [u8; 32],
) -> Result<String, String> {
    let ts = signing_timestamp(std::time::SystemTime::now());
    let mut p = Provisioner::new(key, ts, pin, args.timeout);
    let mut link = transport::spawn(args.connect.clone(), Duration::from_secs(1));
    let mut plain = Ingest::new(None);
    let mut peer = UdpPeer::default();
    eprintln!(
        "signing-setup: waiting for autopilot {}/{} (pinned); any other autopilot heard stops the set-up",
        pin.0, pin.1
    );
    let start = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    loop {
        let mut out = Vec::new();
        tokio::select! {
            m = link.inbound.recv() => match m {
                Some(Inbound::Bytes(b)) => {
                    for f in plain.push(&b) {
                        out.extend(p.on_frame(start.elapsed(), &f));
                    }
                }
                Some(Inbound::Datagram(b, from)) => {
                    plain.reset();
                    for f in plain.push(&b) {
                        out.extend(p.on_frame(start.elapsed(), &f));
                        let src = (f.header.system_id.min(255) as u8, f.header.component_id);
                        if p.target() == Some(src) && peer.on_frame(from, Some(src)).is_some() {
                            let _ = link.peer.send(peer.addr);
                        }
                    }
                }
                Some(Inbound::Connected(name)) => {
                    plain.reset();
                    tracing::info!("connected {name}");
                }
                Some(Inbound::Disconnected(why)) => tracing::warn!("{}: {why}", args.connect),
                None => return Err("the transport task stopped".into()),
            },
            _ = tick.tick() => out.extend(p.tick(start.elapsed())),
        }
        for bytes in out {
            let _ = link.outbound.send(bytes).await;
        }
        if let Some(r) = p.outcome() {
            // Let the last frames leave before the transport is dropped.
            tokio::time::sleep(Duration::from_millis(200)).await;
            return r.clone();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use companion_link::ingest::signing_data;

    const KEY: [u8; 32] = [7; 32];

    /// An autopilot's frame as the link delivers it (parsed without a key), signed with `key`.
    fn autopilot(sys: u8, comp: u8, msg: &Msg, key: Option<[u8; 32]>) -> Frame {
        let mut enc = Encoder::new(key.map(signing_data));
        enc.system_id = sys;
        enc.component_id = comp;
        let bytes = enc.encode(msg);
        Ingest::new(None).push(&bytes).pop().unwrap()
    }

    fn hb(armed: bool) -> Msg {
        Msg::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            base_mode: if armed {
                MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
            } else {
                MavModeFlag::empty()
            },
            ..HEARTBEAT_DATA::DEFAULT
        })
    }

    fn ack() -> Msg {
        Msg::COMMAND_ACK(COMMAND_ACK_DATA {
            command: MavCmd::MAV_CMD_REQUEST_MESSAGE,
            result: MavResult::MAV_RESULT_ACCEPTED,
            ..COMMAND_ACK_DATA::DEFAULT
        })
    }

    /// Decode what the provisioner sent (signed or not, not verified).
    fn sent(bytes: &[Vec<u8>]) -> Vec<Frame> {
        bytes
            .iter()
            .flat_map(|b| Ingest::new(None).push(b))
            .collect()
    }

    fn s(t: f64) -> Duration {
        Duration::from_secs_f64(t)
    }

    /// The pinned 1/1 heard alone for LISTEN: the first SETUP_SIGNING sent.
    fn heard(mut p: Provisioner) -> Provisioner {
        assert!(
            p.on_frame(s(0.0), &autopilot(1, 1, &hb(false), None))
                .is_empty()
        );
        let out = sent(&p.tick(LISTEN));
        assert!(matches!(&out[..], [f] if matches!(f.msg, Msg::SETUP_SIGNING(_))));
        p
    }

    /// Every SETUP_SIGNING in `out`, with its target.
    fn setups(out: &[Vec<u8>]) -> Vec<(u8, u8)> {
        sent(out)
            .iter()
            .filter_map(|f| match &f.msg {
                Msg::SETUP_SIGNING(m) => Some((m.target_system, m.target_component)),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn provisions_then_proves_the_key_by_a_signed_exchange() {
        let mut p = Provisioner::new(KEY, 123_456, (1, 1), s(30.0));
        // The pinned autopilot is listened to first: nothing goes out before LISTEN.
        assert!(
            p.on_frame(s(0.0), &autopilot(1, 1, &hb(false), None))
                .is_empty()
        );
        assert!(
            p.on_frame(s(1.0), &autopilot(1, 1, &hb(false), None))
                .is_empty()
        );
        assert!(p.tick(s(1.9)).is_empty());
        let out = sent(&p.tick(s(2.0)));
        assert_eq!(out.len(), 1);
        assert!(
            !out[0].signed,
            "SETUP_SIGNING goes unsigned: the autopilot has no key yet"
        );
        match &out[0].msg {
            Msg::SETUP_SIGNING(m) => {
                assert_eq!((m.target_system, m.target_component), (1, 1));
                assert_eq!(m.secret_key, KEY);
                assert_eq!(m.initial_timestamp, 123_456);
            }
            m => panic!("{m:?}"),
        }
        // Still unsigned: sent again after the retry interval, not before.
        assert!(
            p.on_frame(s(2.5), &autopilot(1, 1, &hb(false), None))
                .is_empty()
        );
        assert!(p.tick(s(3.0)).is_empty());
        assert_eq!(sent(&p.tick(s(3.6))).len(), 1);
        // Signed with our key: the verification command goes out, signed.
        let out = sent(&p.on_frame(s(4.0), &autopilot(1, 1, &hb(false), Some(KEY))));
        assert_eq!(out.len(), 1);
        assert!(out[0].signed);
        assert!(
            !Ingest::new(Some(signing_data(KEY)))
                .push(&out[0].raw)
                .is_empty(),
            "the command verifies with the key"
        );
        assert!(matches!(&out[0].msg, Msg::COMMAND_LONG(c)
            if c.command == MavCmd::MAV_CMD_REQUEST_MESSAGE && c.target_system == 1 && c.target_component == 1));
        assert_eq!(
            p.outcome(),
            None,
            "a signed heartbeat alone does not prove it obeys us"
        );
        p.on_frame(s(4.5), &autopilot(1, 1, &ack(), Some(KEY)));
        let done = p.outcome().unwrap().as_ref().unwrap();
        assert!(done.contains("autopilot 1/1 holds the key"), "{done}");
    }

    #[test]
    fn another_key_on_the_autopilot_is_a_clear_failure() {
        let mut p = heard(Provisioner::new(KEY, 1, (1, 1), s(30.0)));
        let mut t = LISTEN.as_secs_f64();
        while p.outcome().is_none() && t < 20.0 {
            t += 0.5;
            p.on_frame(s(t), &autopilot(1, 1, &hb(false), Some([9; 32])));
            p.tick(s(t));
        }
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(why.contains("signed with another key"), "{why}");
    }

    #[test]
    fn an_autopilot_that_ignores_setup_signing_is_a_clear_failure() {
        let mut p = Provisioner::new(KEY, 1, (1, 1), s(30.0));
        let mut t = 0.0;
        let mut setups = 0;
        while p.outcome().is_none() && t < 20.0 {
            setups += sent(&p.on_frame(s(t), &autopilot(1, 1, &hb(false), None)))
                .iter()
                .chain(sent(&p.tick(s(t))).iter())
                .filter(|f| matches!(f.msg, Msg::SETUP_SIGNING(_)))
                .count();
            t += 0.5;
        }
        assert_eq!(setups, SETUP_ATTEMPTS as usize);
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(why.contains("stay unsigned"), "{why}");
    }

    #[test]
    fn a_signed_heartbeat_without_an_answer_is_not_verified() {
        let mut p = heard(Provisioner::new(KEY, 1, (1, 1), s(30.0)));
        let mut t = LISTEN.as_secs_f64();
        while p.outcome().is_none() && t < 20.0 {
            t += 0.5;
            p.on_frame(s(t), &autopilot(1, 1, &hb(false), Some(KEY)));
            p.tick(s(t));
        }
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(why.contains("never answered"), "{why}");
    }

    #[test]
    fn an_armed_autopilot_is_not_provisioned() {
        let mut p = Provisioner::new(KEY, 1, (1, 1), s(30.0));
        assert!(
            p.on_frame(s(0.0), &autopilot(1, 1, &hb(true), None))
                .is_empty()
        );
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(why.contains("armed"), "{why}");
    }

    #[test]
    fn an_impostor_heard_first_gets_nothing_and_the_set_up_is_refused() {
        // 7/1 (another system) and 1/2 (another component of the pinned system) alike.
        for impostor in [(7, 1), (1, 2)] {
            let mut p = Provisioner::new(KEY, 1, (1, 1), s(30.0));
            let mut out = p.on_frame(s(0.0), &autopilot(impostor.0, impostor.1, &hb(false), None));
            for i in 1..20 {
                let t = f64::from(i) * 0.5;
                out.extend(p.on_frame(s(t), &autopilot(1, 1, &hb(false), None)));
                out.extend(p.tick(s(t)));
            }
            assert_eq!(setups(&out), vec![], "{impostor:?}");
            let why = p.outcome().unwrap().as_ref().unwrap_err();
            assert!(
                why.contains(&format!("another autopilot, {}/{}", impostor.0, impostor.1))
                    && why.contains("the key was not sent"),
                "{why}"
            );
        }
    }

    #[test]
    fn an_impostor_heard_while_listening_stops_the_set_up_before_the_key_goes_out() {
        let mut p = Provisioner::new(KEY, 1, (1, 1), s(30.0));
        let mut out = p.on_frame(s(0.0), &autopilot(1, 1, &hb(false), None));
        out.extend(p.on_frame(s(1.5), &autopilot(7, 1, &hb(false), None)));
        for i in 4..40 {
            let t = f64::from(i) * 0.5;
            out.extend(p.on_frame(s(t), &autopilot(1, 1, &hb(false), Some(KEY))));
            out.extend(p.tick(s(t)));
        }
        assert_eq!(setups(&out), vec![]);
        assert!(sent(&out).is_empty(), "nothing at all is sent");
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(
            why.contains("7/1") && why.contains("the key was not sent"),
            "{why}"
        );
    }

    #[test]
    fn an_impostor_heard_after_the_key_went_out_leaves_it_unverified() {
        let mut p = heard(Provisioner::new(KEY, 1, (1, 1), s(30.0)));
        let _ = p.on_frame(s(2.5), &autopilot(1, 1, &hb(false), Some(KEY)));
        let out = p.on_frame(s(2.6), &autopilot(7, 1, &hb(false), None));
        assert!(out.is_empty());
        // The pinned autopilot's answer after that proves nothing: the set-up is over.
        p.on_frame(s(2.7), &autopilot(1, 1, &ack(), Some(KEY)));
        let why = p.outcome().unwrap().as_ref().unwrap_err();
        assert!(
            why.contains("7/1") && why.contains("went to 1/1 alone"),
            "{why}"
        );
    }

    #[test]
    fn the_signed_answer_must_come_from_the_pinned_component() {
        let mut p = heard(Provisioner::new(KEY, 1, (1, 1), s(30.0)));
        let out = sent(&p.on_frame(s(2.5), &autopilot(1, 1, &hb(false), Some(KEY))));
        assert!(
            matches!(&out[..], [f] if matches!(&f.msg, Msg::COMMAND_LONG(c)
            if (c.target_system, c.target_component) == (1, 1)))
        );
        // A signed ACK from another component (not an autopilot heartbeat) verifies nothing.
        p.on_frame(s(2.6), &autopilot(1, 100, &ack(), Some(KEY)));
        assert_eq!(p.outcome(), None);
        p.on_frame(s(2.7), &autopilot(1, 1, &ack(), Some(KEY)));
        assert!(p.outcome().unwrap().is_ok());
    }

    #[test]
    fn the_pin_is_required_both_ids() {
        let parse = |extra: &[&str]| {
            #[derive(clap::Parser)]
            struct Cli {
                #[command(flatten)]
                args: SigningSetupArgs,
            }
            use clap::Parser;
            let argv = ["x", "--connect", "udpin:127.0.0.1:1", "--key", "k"]
                .iter()
                .chain(extra);
            Cli::try_parse_from(argv).unwrap().args
        };
        for (extra, missing) in [
            (&[][..], "--autopilot-sysid and --autopilot-compid"),
            (
                &["--autopilot-sysid", "1"][..],
                "--autopilot-compid missing",
            ),
            (
                &["--autopilot-compid", "1"][..],
                "--autopilot-sysid missing",
            ),
        ] {
            let e = pin(&parse(extra)).unwrap_err().to_string();
            assert!(
                e.contains(missing) && e.contains("nothing was written"),
                "{e}"
            );
        }
        let both = parse(&["--autopilot-sysid", "3", "--autopilot-compid", "1"]);
        assert_eq!(pin(&both).unwrap(), (3, 1));
    }

    #[test]
    fn no_autopilot_within_the_timeout_fails() {
        let mut p = Provisioner::new(KEY, 1, (1, 1), s(3.0));
        p.tick(s(2.9));
        assert_eq!(p.outcome(), None);
        p.tick(s(3.0));
        assert!(
            p.outcome()
                .unwrap()
                .as_ref()
                .unwrap_err()
                .contains("no HEARTBEAT from the pinned autopilot 1/1")
        );
    }

    #[test]
    fn signing_timestamps_count_10us_since_2015() {
        let t = std::time::UNIX_EPOCH + Duration::from_secs(1_420_070_400 + 2);
        assert_eq!(signing_timestamp(t), 200_000);
    }

    #[test]
    fn the_key_file_is_0600_hex_and_never_overwritten_without_force() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("signing.key");
        let key = write_new_key(&path, false).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        assert_eq!(
            crate::fly::link_security::load_signing_key(&path).unwrap(),
            key
        );
        let e = write_new_key(&path, false).unwrap_err().to_string();
        assert!(e.contains("refusing to overwrite"), "{e}");
        assert_eq!(
            crate::fly::link_security::load_signing_key(&path).unwrap(),
            key
        );
        let new = write_new_key(&path, true).unwrap();
        assert_ne!(new, key);
        assert_eq!(
            crate::fly::link_security::load_signing_key(&path).unwrap(),
            new
        );
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
    }
}
