//! What `fly` says about how far the autopilot link can be trusted (issue 26): a network link
//! without signing, an autopilot chosen only because it spoke first, and `--require-signing`.
//! Each is said once on stderr and once to the ground station (STATUSTEXT).

use super::FlyArgs;
use companion_link::Msg;
use companion_link::dialect::MavSeverity;
use companion_link::ingest::{self, IngestStats};
use companion_link::operator::GcsText;
use companion_link::url::ConnectUrl;
use companion_link::vehicle::Vehicle;
use std::time::Duration;

/// Whether anyone who can reach the link's address can put frames on it (UDP, TCP).
pub fn is_network_link(url: &ConnectUrl) -> bool {
    !matches!(url, ConnectUrl::Serial { .. })
}

/// Whether an `--onboard` link is a dedicated onboard wire: a serial port, or a socket on the
/// loopback (a tracker on the companion computer itself). Nothing on a network can send on it.
pub fn is_dedicated_onboard(url: &ConnectUrl) -> bool {
    let addr = match url {
        ConnectUrl::Serial { .. } => return true,
        ConnectUrl::UdpIn { bind } | ConnectUrl::TcpIn { bind } => bind,
        ConnectUrl::UdpOut { peer } | ConnectUrl::TcpOut { peer } => peer,
    };
    let host = addr.rsplit_once(':').map_or(addr.as_str(), |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Where `--learn-cpt` may learn from, decided before anything opens.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LearningSource {
    /// No learning, or every frame signed (`--signing-key`: unsigned frames are refused).
    Any,
    /// The tracker's reports only from the dedicated `--onboard` link (the autopilot link is
    /// unsigned: anyone reaching it could send the tracker's `tgt_det`).
    OnboardOnly,
}

/// `--require-signing` without `--signing-key`, and `--learn-cpt` with neither a key nor a
/// dedicated onboard link, are refused before anything opens.
pub fn check_args(args: &FlyArgs) -> anyhow::Result<LearningSource> {
    if args.require_signing && args.signing_key.is_none() {
        anyhow::bail!(
            "--require-signing: no --signing-key given; make and provision one with `companion signing-setup --connect URL --key FILE`, then pass --signing-key FILE"
        );
    }
    if !args.learn_cpt || args.signing_key.is_some() {
        return Ok(LearningSource::Any);
    }
    match &args.onboard {
        Some(u) if is_dedicated_onboard(u) || args.onboard_private => {
            Ok(LearningSource::OnboardOnly)
        }
        Some(u) => anyhow::bail!(
            "--learn-cpt: the links are unsigned and --onboard {} is reachable from a network: anyone there could send the tracker's reports and choose where the learned rows go; learn with a signed link (--signing-key, made with `companion signing-setup`) or a dedicated onboard link (--onboard on a serial port or a loopback address, or --onboard-private when that network is a private wire to the tracker alone)",
            crate::review::text::escape_controls(&u.to_string(), false)
        ),
        None => anyhow::bail!(
            "--learn-cpt: the autopilot link is unsigned and there is no dedicated onboard link: anyone who can put frames on the link could send the tracker's reports and choose where the learned rows go; learn with a signed link (--signing-key, made with `companion signing-setup`) or a dedicated onboard link carrying the tracker (--onboard on a serial port or a loopback address)"
        ),
    }
}

/// The ground-station texts (50 characters at most: STATUSTEXT's field).
const UNSIGNED_TEXT: &str = "companion: link UNSIGNED, can be spoofed";
const UNPINNED_TEXT: &str = "companion: first autopilot heard, not pinned";
const REFUSED_TEXT: &str = "companion: autopilot unsigned, will not fly";

/// The link's trust, said once each.
#[derive(Debug, Default)]
pub struct LinkSecurity {
    network: bool,
    keyed: bool,
    require: bool,
    unsigned_said: bool,
    unpinned_said: bool,
    unpinned_printed: bool,
    refused_said: bool,
    refused_printed: bool,
    /// When this run first had something to say to the ground station, and when it last said
    /// something: its texts wait out the burst at link-up and go one at a time, so they do not
    /// use up the STATUSTEXT rate limit that the mission's own texts need.
    first_due: Option<Duration>,
    last_said: Option<Duration>,
}

/// The ground-station texts wait this long after the first one is due ...
const TEXT_DELAY: Duration = Duration::from_secs(3);
/// ... and go out at least this far apart.
const TEXT_GAP: Duration = Duration::from_millis(1500);

impl LinkSecurity {
    /// At the start of `fly`: the unsigned-network-link warning on stderr.
    pub fn start(args: &FlyArgs, keyed: bool) -> Self {
        let s = Self {
            network: is_network_link(&args.connect),
            keyed,
            require: args.require_signing,
            ..Self::default()
        };
        if s.network && !keyed {
            eprintln!("companion fly: WARNING {}", s.unsigned_line(&args.connect));
            tracing::warn!("{}", s.unsigned_line(&args.connect));
        }
        s
    }

    fn unsigned_line(&self, url: &ConnectUrl) -> String {
        format!(
            "the autopilot link {url} is a network link without MAVLink signing: anyone who can reach it can pose as the autopilot or a ground station; provision a key with `companion signing-setup` and fly with --signing-key (--require-signing refuses to fly without)"
        )
    }

    /// Once per loop: the STATUSTEXTs still owed (retried while the rate limit holds them back),
    /// the unpinned choice once the autopilot is chosen, and with a key, an autopilot heard only
    /// unsigned (its frames are refused, so it is never chosen and nothing is commanded).
    pub fn check(
        &mut self,
        now: Duration,
        vehicle: &Vehicle,
        stats: &IngestStats,
        texts: &mut GcsText,
    ) -> Vec<Msg> {
        let mut out = Vec::new();
        let chosen = vehicle.target().is_some() && vehicle.liveness().alive();
        let first_due = self.first_due;
        let mut last_said = self.last_said;
        let mut due = false;
        let mut say = |done: &mut bool, severity, text: &str| {
            if *done {
                return;
            }
            due = true;
            let ready = first_due.is_some_and(|t| now.saturating_sub(t) >= TEXT_DELAY)
                && last_said.is_none_or(|t| now.saturating_sub(t) >= TEXT_GAP);
            if ready {
                let msgs = texts.say(now, severity, text);
                if !msgs.is_empty() {
                    *done = true;
                    last_said = Some(now);
                    out.extend(msgs);
                }
            }
        };
        if self.network && !self.keyed && chosen {
            say(
                &mut self.unsigned_said,
                MavSeverity::MAV_SEVERITY_WARNING,
                UNSIGNED_TEXT,
            );
        }
        if self.network
            && let Some(note) = vehicle.identity_note()
        {
            if !self.unpinned_printed {
                self.unpinned_printed = true;
                eprintln!("companion fly: WARNING {note}");
                tracing::warn!("{note}");
            }
            say(
                &mut self.unpinned_said,
                MavSeverity::MAV_SEVERITY_WARNING,
                UNPINNED_TEXT,
            );
        }
        if self.keyed && vehicle.target().is_none() && stats.unsigned_refused > 0 {
            if !self.refused_printed {
                self.refused_printed = true;
                let line = format!(
                    "frames without a signature are arriving and refused ({} so far) and no autopilot signed with --signing-key is heard: nothing is commanded{}; provision the autopilot with `companion signing-setup --connect URL --key FILE`",
                    stats.unsigned_refused,
                    if self.require {
                        " (--require-signing)"
                    } else {
                        ""
                    }
                );
                eprintln!("companion fly: {line}");
                tracing::error!("{line}");
            }
            say(
                &mut self.refused_said,
                MavSeverity::MAV_SEVERITY_ERROR,
                REFUSED_TEXT,
            );
        }
        self.last_said = last_said;
        if due && self.first_due.is_none() {
            self.first_due = Some(now);
        }
        out
    }
}

/// Read the MAVLink 2 signing key file at `path` (`fly --signing-key`, `signing-setup`):
/// the link parses it, the shell reads it (companion-link reads no files).
pub fn load_signing_key(path: &std::path::Path) -> Result<[u8; 32], ingest::KeyError> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| ingest::KeyError::Read(name.clone(), e))?;
    ingest::parse_signing_key(&name, &bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signing_key_file_is_read_by_the_shell_and_a_missing_one_named() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("raw.key");
        std::fs::write(&raw, [5u8; 32]).unwrap();
        assert_eq!(load_signing_key(&raw).unwrap(), [5u8; 32]);
        let missing = dir.path().join("missing");
        let e = load_signing_key(&missing).unwrap_err();
        assert!(matches!(e, ingest::KeyError::Read(..)), "{e:?}");
        assert!(e.to_string().contains("missing: cannot read"), "{e}");
    }

    fn texts_said(args: &[&str], keyed: bool, frames: &[Vec<u8>]) -> Vec<(f64, String)> {
        let args = FlyArgs::from_cli(args.iter().copied()).unwrap();
        let mut sec = LinkSecurity::start(&args, keyed);
        let mut v = Vehicle::new(Default::default(), Default::default(), None)
            .obeying(args.autopilot_sysid, args.autopilot_compid);
        let mut texts = GcsText::new(Duration::from_secs(15), 2);
        let mut ingest = companion_link::ingest::Ingest::new(None);
        let mut said = Vec::new();
        for k in 0..100 {
            let now = Duration::from_millis(100 * k);
            for b in frames {
                for f in ingest.push(b) {
                    v.on_frame(now, &f);
                }
            }
            for m in sec.check(now, &v, &ingest.stats, &mut texts) {
                if let Msg::STATUSTEXT(t) = m {
                    said.push((now.as_secs_f64(), t.text.to_str().unwrap().to_string()));
                }
            }
        }
        said
    }

    fn autopilot_heartbeat() -> Vec<u8> {
        use companion_link::dialect::*;
        let mut enc = companion_link::ingest::Encoder::new(None);
        enc.component_id = 1;
        enc.encode(&Msg::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            ..HEARTBEAT_DATA::DEFAULT
        }))
    }

    /// An unsigned, unpinned network link: each text once, after the link-up burst, apart.
    #[test]
    fn an_unsigned_unpinned_network_link_is_said_once_each() {
        let said = texts_said(
            &["--connect", "tcp:127.0.0.1:5760"],
            false,
            &[autopilot_heartbeat()],
        );
        let texts: Vec<&str> = said.iter().map(|(_, t)| t.as_str()).collect();
        assert_eq!(texts, vec![UNSIGNED_TEXT, UNPINNED_TEXT], "{said:?}");
        assert!(said[0].0 >= TEXT_DELAY.as_secs_f64(), "{said:?}");
        assert!(said[1].0 - said[0].0 >= TEXT_GAP.as_secs_f64(), "{said:?}");
    }

    /// Serial, or pinned and signed: nothing to say.
    #[test]
    fn a_serial_link_or_a_pinned_signed_one_says_nothing() {
        let hb = [autopilot_heartbeat()];
        assert!(texts_said(&["--connect", "serial:/dev/null:57600"], false, &hb).is_empty());
        let keyed = texts_said(
            &["--connect", "udpin:0.0.0.0:14550", "--autopilot-sysid", "1"],
            true,
            &hb,
        );
        // (with a key the ingest here is unkeyed: the heartbeat counts as heard, signed)
        assert!(keyed.is_empty(), "{keyed:?}");
    }

    #[test]
    fn ground_station_texts_fit_statustext() {
        for t in [UNSIGNED_TEXT, UNPINNED_TEXT, REFUSED_TEXT] {
            assert!(t.len() <= 50, "{t} is {} characters", t.len());
        }
    }

    #[test]
    fn require_signing_without_a_key_is_refused_naming_the_flags() {
        let args =
            FlyArgs::from_cli(["--connect", "tcp:127.0.0.1:5760", "--require-signing"]).unwrap();
        let e = check_args(&args).unwrap_err().to_string();
        assert!(e.contains("--require-signing"), "{e}");
        assert!(e.contains("--signing-key"), "{e}");
        let ok = FlyArgs::from_cli([
            "--connect",
            "tcp:127.0.0.1:5760",
            "--require-signing",
            "--signing-key",
            "k",
        ])
        .unwrap();
        assert!(check_args(&ok).is_ok());
    }

    #[test]
    fn learn_cpt_needs_a_signed_link_or_a_dedicated_onboard_link() {
        let check = |extra: &[&str]| {
            let args = FlyArgs::from_cli(
                ["--connect", "udpin:0.0.0.0:14550", "--learn-cpt"]
                    .iter()
                    .chain(extra),
            )
            .unwrap();
            check_args(&args).map_err(|e| e.to_string())
        };
        let e = check(&[]).unwrap_err();
        assert!(
            e.starts_with("--learn-cpt: the autopilot link is unsigned")
                && e.contains("--signing-key")
                && e.contains("--onboard"),
            "{e}"
        );
        let e = check(&["--onboard", "udpin:0.0.0.0:14560"]).unwrap_err();
        assert!(
            e.contains("--onboard udpin:0.0.0.0:14560 is reachable"),
            "{e}"
        );
        assert_eq!(check(&["--signing-key", "k"]), Ok(LearningSource::Any));
        // The operator declares the network link a private wire.
        assert_eq!(
            check(&["--onboard", "udpin:0.0.0.0:14560", "--onboard-private"]),
            Ok(LearningSource::OnboardOnly)
        );
        assert!(
            FlyArgs::from_cli(["--connect", "udpin:0.0.0.0:14550", "--onboard-private"]).is_err(),
            "--onboard-private needs --onboard"
        );
        for onboard in [
            "serial:/dev/ttyUSB1:921600",
            "udpin:127.0.0.1:14560",
            "tcp:localhost:5763",
            "udpin:[::1]:14560",
        ] {
            assert_eq!(
                check(&["--onboard", onboard]),
                Ok(LearningSource::OnboardOnly),
                "{onboard}"
            );
        }
        // Without --learn-cpt nothing changes.
        let plain = FlyArgs::from_cli(["--connect", "udpin:0.0.0.0:14550"]).unwrap();
        assert_eq!(check_args(&plain).unwrap(), LearningSource::Any);
    }

    #[test]
    fn autopilot_compid_needs_the_sysid() {
        assert!(
            FlyArgs::from_cli(["--connect", "tcp:127.0.0.1:5760", "--autopilot-compid", "2"])
                .is_err()
        );
        let a = FlyArgs::from_cli([
            "--connect",
            "tcp:127.0.0.1:5760",
            "--autopilot-sysid",
            "1",
            "--autopilot-compid",
            "2",
        ])
        .unwrap();
        assert_eq!((a.autopilot_sysid, a.autopilot_compid), (Some(1), 2));
    }

    #[test]
    fn only_serial_is_not_a_network_link() {
        for (u, net) in [
            ("serial:/dev/ttyAMA0:921600", false),
            ("udpin:0.0.0.0:14550", true),
            ("udpout:127.0.0.1:14550", true),
            ("tcp:127.0.0.1:5760", true),
            ("tcpin:0.0.0.0:5760", true),
        ] {
            let url = companion_link::url::parse(u).unwrap();
            assert_eq!(is_network_link(&url), net, "{u}");
        }
    }
}
