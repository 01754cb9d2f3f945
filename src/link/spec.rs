//! Connection strings, spelled as MAVProxy and rust-mavlink spell them: `udpin:HOST:PORT`,
//! `udpout:HOST:PORT`, `udpbcast:HOST:PORT`, `tcpin:HOST:PORT`, `tcpout:HOST:PORT`,
//! `serial:DEVICE:BAUD` (`udp:` is `udpin:`, `tcp:` is `tcpout:`), and a serial device as
//! MAVProxy's `--master` takes it: `DEVICE,BAUD` or `DEVICE` alone (a path, or `COMn`), at
//! [`DEFAULT_BAUD`] when none is given.

use std::net::SocketAddr;
use std::str::FromStr;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ConnError {
    #[error(
        "connection `{0}`: {1}; expected udpin:HOST:PORT, udpout:HOST:PORT, udpbcast:HOST:PORT, tcpin:HOST:PORT, tcpout:HOST:PORT, serial:DEVICE:BAUD or DEVICE[,BAUD] (udp: is udpin:, tcp: is tcpout:)"
    )]
    Syntax(String, String),
    #[error("connection `{spec}`: {source}")]
    Io {
        spec: String,
        #[source]
        source: std::io::Error,
    },
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConnSpec {
    UdpIn(SocketAddr),
    UdpOut(SocketAddr),
    UdpBcast(SocketAddr),
    TcpIn(SocketAddr),
    TcpOut(SocketAddr),
    Serial(String, u32),
}

/// The baud rate of a serial device given without one: MAVProxy's `--baudrate` default, the
/// usual telemetry radio's rate.
pub const DEFAULT_BAUD: u32 = 57600;

/// Connection kinds (`udp` is `udpin`, `tcp` is `tcpout`, as in MAVProxy and pymavlink).
const KINDS: [&str; 8] = [
    "udpin", "udp", "udpout", "udpbcast", "tcpin", "tcpout", "tcp", "serial",
];

/// An I/O error of opening `spec`, with what was being done (the OS's text alone, "No such
/// file or directory", named no device).
pub(super) fn opening(spec: &ConnSpec, what: String) -> impl Fn(std::io::Error) -> ConnError {
    let spec = spec.to_string();
    move |source| {
        // A port taken is most often a ground station on its default port (14550).
        let hint = if source.kind() == std::io::ErrorKind::AddrInUse {
            "; another program (a ground station?) listens there: listen on a free port and have it forward to that one (MAVProxy --out=udp:127.0.0.1:PORT, or the ground station's MAVLink forwarding)"
        } else {
            ""
        };
        ConnError::Io {
            spec: spec.clone(),
            source: std::io::Error::new(source.kind(), format!("{what}: {source}{hint}")),
        }
    }
}

/// A baud rate as written, or why it is not one.
fn baud_rate(baud: &str) -> Result<u32, String> {
    match baud.parse() {
        Ok(0) => Err("baud rate 0".into()),
        Ok(b) => Ok(b),
        Err(_) => Err(format!("baud rate `{baud}` is not a whole number")),
    }
}

/// MAVProxy's serial form: a device path (or `COMn`) with an optional `,BAUD`. A path that
/// exists with its comma is the device itself, as pymavlink reads it.
fn device_form(s: &str) -> Option<Result<ConnSpec, String>> {
    let upper = s.to_ascii_uppercase();
    let looks_like_device = s.starts_with('/')
        || s.starts_with(r"\\.\")
        || (upper.starts_with("COM") && upper[3..].split(',').next()?.parse::<u16>().is_ok());
    if !looks_like_device {
        return None;
    }
    let split = s
        .rsplit_once(',')
        .filter(|_| !std::path::Path::new(s).exists());
    Some(match split {
        Some((dev, baud)) => baud_rate(baud).map(|b| ConnSpec::Serial(dev.to_string(), b)),
        None => Ok(ConnSpec::Serial(s.to_string(), DEFAULT_BAUD)),
    })
}

impl FromStr for ConnSpec {
    type Err = ConnError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |why: String| ConnError::Syntax(s.to_string(), why);
        if let Some(spec) = device_form(s) {
            return spec.map_err(bad);
        }
        let (kind, rest) = s.split_once(':').ok_or_else(|| {
            if KINDS.contains(&s) {
                bad(format!("`{s}` needs an address after a `:`"))
            } else {
                bad("no kind before a `:`".into())
            }
        })?;
        if kind == "serial" {
            // The last `:` part is a baud rate when it is one word (`57600`, or a mistake such
            // as `fast`); a device's name may hold colons (`pci-0000:00:14.0-usb-0:1:1.0`).
            let (dev, baud) = match rest.rsplit_once(':') {
                Some((dev, baud)) if baud.chars().all(|c| c.is_ascii_alphanumeric()) => {
                    (dev, baud_rate(baud).map_err(bad)?)
                }
                _ => (rest, DEFAULT_BAUD),
            };
            if dev.is_empty() {
                return Err(bad("no device".into()));
            }
            return Ok(Self::Serial(dev.to_string(), baud));
        }
        if !KINDS.contains(&kind) {
            return Err(bad(format!("unknown kind `{kind}`")));
        }
        let (host, port) = rest
            .rsplit_once(':')
            .filter(|(_, port)| !port.ends_with(']'))
            .ok_or_else(|| bad("no port".into()))?;
        if port.parse::<u16>().is_err() {
            return Err(bad(format!(
                "port `{port}` is not a number from 0 to 65535"
            )));
        }
        // HOST may be a name (localhost): resolve it now, once.
        let addr = std::net::ToSocketAddrs::to_socket_addrs(rest)
            .ok()
            .and_then(|mut a| a.next())
            .ok_or_else(|| bad(format!("cannot resolve host `{host}`")))?;
        Ok(match kind {
            "udpin" | "udp" => Self::UdpIn(addr),
            "udpout" => Self::UdpOut(addr),
            "udpbcast" => Self::UdpBcast(addr),
            "tcpin" => Self::TcpIn(addr),
            "tcpout" | "tcp" => Self::TcpOut(addr),
            _ => return Err(bad(format!("unknown kind `{kind}`"))),
        })
    }
}

impl std::fmt::Display for ConnSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::UdpIn(a) => write!(f, "udpin:{a}"),
            Self::UdpOut(a) => write!(f, "udpout:{a}"),
            Self::UdpBcast(a) => write!(f, "udpbcast:{a}"),
            Self::TcpIn(a) => write!(f, "tcpin:{a}"),
            Self::TcpOut(a) => write!(f, "tcpout:{a}"),
            Self::Serial(d, b) => write!(f, "serial:{d}:{b}"),
        }
    }
}
