//! Connection URLs: `serial:/dev/ttyAMA0:921600`, `udpin:0.0.0.0:14550`, `udpout:HOST:PORT`,
//! `tcp:HOST:PORT` (alias `tcpout:`), `tcpin:ADDR:PORT`. Same spellings as MAVProxy and the
//! mavlink crate, and MAVSDK's (`udpin://HOST:PORT`, `udpout://`, `tcpin://`, `tcpout://`,
//! `serial:///dev/ttyUSB0:57600`), parsed here so that a typo is rejected with a reason before
//! anything opens.

use std::fmt;

/// Where the autopilot (or an onboard monitor) is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConnectUrl {
    /// A serial device at a baud rate.
    Serial {
        /// Device path (`/dev/ttyAMA0`).
        path: String,
        /// Baud rate (bit/s).
        baud: u32,
    },
    /// Listen for UDP datagrams; replies go to the last sender.
    UdpIn {
        /// Local address to listen on (`0.0.0.0:14550`).
        bind: String,
    },
    /// Send UDP datagrams to a fixed peer.
    UdpOut {
        /// Address to send to.
        peer: String,
    },
    /// Connect to a TCP server (SITL's default `tcp:127.0.0.1:5760`); reconnects on loss.
    TcpOut {
        /// Server address to connect to.
        peer: String,
    },
    /// Accept one TCP client at a time; accepts again after it leaves.
    TcpIn {
        /// Local address to listen on.
        bind: String,
    },
}

/// Why a URL was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("connection URL {url:?}: {reason}")]
pub struct UrlError {
    /// The URL as given.
    pub url: String,
    /// What is wrong with it.
    pub reason: String,
}

impl fmt::Display for ConnectUrl {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConnectUrl::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
            ConnectUrl::UdpIn { bind } => write!(f, "udpin:{bind}"),
            ConnectUrl::UdpOut { peer } => write!(f, "udpout:{peer}"),
            ConnectUrl::TcpOut { peer } => write!(f, "tcp:{peer}"),
            ConnectUrl::TcpIn { bind } => write!(f, "tcpin:{bind}"),
        }
    }
}

impl std::str::FromStr for ConnectUrl {
    type Err = UrlError;
    fn from_str(s: &str) -> Result<Self, UrlError> {
        parse(s)
    }
}

/// Parse a connection URL.
pub fn parse(url: &str) -> Result<ConnectUrl, UrlError> {
    let err = |reason: &str| UrlError {
        url: url.to_string(),
        reason: reason.to_string(),
    };
    let (scheme, rest) = url.split_once(':').ok_or_else(|| {
        err("expected SCHEME:..., one of serial, udpin, udpout, tcp, tcpout, tcpin")
    })?;
    // MAVSDK writes `scheme://rest` (`serial:///dev/ttyUSB0:57600` keeps the device's own slash).
    let rest = rest.strip_prefix("//").unwrap_or(rest);
    match scheme {
        "serial" => {
            let (path, baud) = rest.rsplit_once(':').ok_or_else(|| {
                err("expected serial:DEVICE:BAUD, e.g. serial:/dev/ttyAMA0:921600")
            })?;
            if path.is_empty() {
                return Err(err("empty serial device path"));
            }
            let baud: u32 = baud
                .parse()
                .map_err(|_| err(&format!("baud rate {baud:?} is not a positive integer")))?;
            if baud == 0 {
                return Err(err("baud rate must be positive"));
            }
            Ok(ConnectUrl::Serial {
                path: path.to_string(),
                baud,
            })
        }
        "udpin" | "udpout" | "tcp" | "tcpout" | "tcpin" => {
            let addr = host_port(rest).map_err(|r| err(&r))?;
            Ok(match scheme {
                "udpin" => ConnectUrl::UdpIn { bind: addr },
                "udpout" => ConnectUrl::UdpOut { peer: addr },
                "tcpin" => ConnectUrl::TcpIn { bind: addr },
                _ => ConnectUrl::TcpOut { peer: addr },
            })
        }
        other => Err(err(&format!(
            "unknown scheme {other:?}; expected serial, udpin, udpout, tcp, tcpout or tcpin"
        ))),
    }
}

/// `HOST:PORT` with a non-empty host and a port in 1..=65535 (`[::1]:14550` for IPv6).
fn host_port(s: &str) -> Result<String, String> {
    let (host, port) = s
        .rsplit_once(':')
        .ok_or_else(|| format!("expected HOST:PORT, got {s:?}"))?;
    if host.is_empty() || host == "[]" {
        return Err("empty host".into());
    }
    if host.contains('/') {
        return Err(format!("host {host:?} contains '/'"));
    }
    if host.contains(':') && !(host.starts_with('[') && host.ends_with(']')) {
        return Err(format!(
            "IPv6 host {host:?} must be written in brackets, e.g. [::1]:14550"
        ));
    }
    let port: u16 = port
        .parse()
        .map_err(|_| format!("port {port:?} is not a number in 1..65535"))?;
    if port == 0 {
        return Err("port 0 is not a usable port".into());
    }
    Ok(format!("{host}:{port}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_every_scheme() {
        assert_eq!(
            parse("serial:/dev/ttyAMA0:921600").unwrap(),
            ConnectUrl::Serial {
                path: "/dev/ttyAMA0".into(),
                baud: 921600
            }
        );
        assert_eq!(
            parse("udpin:0.0.0.0:14550").unwrap(),
            ConnectUrl::UdpIn {
                bind: "0.0.0.0:14550".into()
            }
        );
        assert_eq!(
            parse("udpout:127.0.0.1:14550").unwrap(),
            ConnectUrl::UdpOut {
                peer: "127.0.0.1:14550".into()
            }
        );
        assert_eq!(
            parse("tcp:127.0.0.1:5760").unwrap(),
            ConnectUrl::TcpOut {
                peer: "127.0.0.1:5760".into()
            }
        );
        assert_eq!(
            parse("tcpout:localhost:5760").unwrap(),
            ConnectUrl::TcpOut {
                peer: "localhost:5760".into()
            }
        );
        assert_eq!(
            parse("tcpin:0.0.0.0:5760").unwrap(),
            ConnectUrl::TcpIn {
                bind: "0.0.0.0:5760".into()
            }
        );
        assert_eq!(
            parse("udpout:[::1]:14550").unwrap(),
            ConnectUrl::UdpOut {
                peer: "[::1]:14550".into()
            }
        );
        // Windows-style serial names have no slash.
        assert_eq!(
            parse("serial:COM3:57600").unwrap(),
            ConnectUrl::Serial {
                path: "COM3".into(),
                baud: 57600
            }
        );
    }

    #[test]
    fn parses_mavsdk_url_forms() {
        let cases = [
            ("udpin://0.0.0.0:14550", "udpin:0.0.0.0:14550"),
            ("udpin://127.0.0.1:14599", "udpin:127.0.0.1:14599"),
            ("udpout://10.0.0.2:14550", "udpout:10.0.0.2:14550"),
            ("tcpin://0.0.0.0:5760", "tcpin:0.0.0.0:5760"),
            ("tcpout://127.0.0.1:5760", "tcp:127.0.0.1:5760"),
            ("tcp://127.0.0.1:5760", "tcp:127.0.0.1:5760"),
            ("udpout://[::1]:14550", "udpout:[::1]:14550"),
            ("serial:///dev/ttyUSB0:57600", "serial:/dev/ttyUSB0:57600"),
            ("serial://COM3:57600", "serial:COM3:57600"),
        ];
        for (mavsdk, canonical) in cases {
            let u = parse(mavsdk).unwrap_or_else(|e| panic!("{mavsdk}: {e}"));
            assert_eq!(u.to_string(), canonical, "{mavsdk}");
        }
    }

    #[test]
    fn display_round_trips() {
        for u in [
            "serial:/dev/ttyUSB0:115200",
            "udpin:0.0.0.0:14550",
            "udpout:10.0.0.2:14550",
            "tcp:127.0.0.1:5760",
            "tcpin:0.0.0.0:5760",
        ] {
            assert_eq!(parse(u).unwrap().to_string(), u);
        }
    }

    #[test]
    fn rejects_malformed_urls_with_a_reason() {
        let cases = [
            ("", "expected SCHEME"),
            ("127.0.0.1", "expected SCHEME"),
            ("http:127.0.0.1:80", "unknown scheme"),
            ("udp:127.0.0.1:14550", "unknown scheme"),
            ("udpin:14550", "expected HOST:PORT"),
            ("udpin::14550", "empty host"),
            ("tcp:127.0.0.1:", "not a number"),
            ("tcp:127.0.0.1:99999", "not a number"),
            ("tcp:127.0.0.1:0", "port 0"),
            ("tcpin:::1:5760", "brackets"),
            ("serial:/dev/ttyAMA0", "expected serial:DEVICE:BAUD"),
            ("serial:/dev/ttyAMA0:fast", "not a positive integer"),
            ("serial:/dev/ttyAMA0:0", "must be positive"),
            ("serial::921600", "empty serial device"),
            ("serial:921600", "expected serial:DEVICE:BAUD"),
            ("serial:///dev/ttyUSB0", "expected serial:DEVICE:BAUD"),
            ("udp://0.0.0.0:14550", "unknown scheme"),
            ("http://127.0.0.1:80", "unknown scheme"),
            ("udpin:///0.0.0.0:14550", "contains '/'"),
            ("udpin://:14550", "empty host"),
        ];
        for (url, why) in cases {
            let e = parse(url).expect_err(url);
            assert!(e.reason.contains(why), "{url}: {e}");
            assert_eq!(e.url, url);
        }
    }
}
