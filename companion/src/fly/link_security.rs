//! What `fly` says about how far the autopilot link can be trusted (issue 26): a network link
//! without signing, an autopilot chosen only because it spoke first, and `--require-signing`.
//! Each is said once on stderr and once to the ground station (STATUSTEXT).

use super::FlyArgs;
use companion_link::Msg;
use companion_link::dialect::MavSeverity;
use companion_link::ingest::IngestStats;
use companion_link::operator::GcsText;
use companion_link::url::ConnectUrl;
use companion_link::vehicle::Vehicle;
use std::time::Duration;

/// Whether anyone who can reach the link's address can put frames on it (UDP, TCP).
pub fn is_network_link(url: &ConnectUrl) -> bool {
    !matches!(url, ConnectUrl::Serial { .. })
}

/// `--require-signing` without `--signing-key` is refused before anything opens.
pub fn check_args(args: &FlyArgs) -> anyhow::Result<()> {
    if args.require_signing && args.signing_key.is_none() {
        anyhow::bail!(
            "--require-signing: no --signing-key given; make and provision one with `companion signing-setup --connect URL --key FILE`, then pass --signing-key FILE"
        );
    }
    Ok(())
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
}

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
        let chosen = vehicle.target.is_some() && vehicle.liveness.alive();
        let mut say = |done: &mut bool, severity, text: &str| {
            if !*done && let Some(m) = texts.say(now, severity, text) {
                *done = true;
                out.push(m);
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
        if self.keyed && vehicle.target.is_none() && stats.unsigned_refused > 0 {
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
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
