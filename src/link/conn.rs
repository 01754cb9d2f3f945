//! Live MAVLink connections, spelled as MAVProxy and rust-mavlink spell them:
//! `udpin:HOST:PORT`, `udpout:HOST:PORT`, `udpbcast:HOST:PORT`, `tcpin:HOST:PORT`,
//! `tcpout:HOST:PORT`, `serial:DEVICE:BAUD`.
//!
//! UDP and TCP are framed by our own [`StreamFramer`], so every dropped byte is counted (the
//! `mavlink` crate's `recv` skips silently, shared/mavlink.md §1.2). Outgoing kinds (`udpout`,
//! `tcpout`) reconnect; `udpin` answers the last peer it heard from.

use super::frame::{Frame, FrameCounters, StreamFramer};
use std::net::SocketAddr;
use std::str::FromStr;
use std::time::Duration;
use thiserror::Error;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream, UdpSocket};

/// How long a sender waits for an outgoing TCP connection before dropping the frame (it tries
/// again a second later).
const SEND_CONNECT_TIMEOUT: Duration = Duration::from_millis(100);
/// How long a send may wait for room in a TCP peer's buffer.
const SEND_WRITE_TIMEOUT: Duration = Duration::from_millis(100);

#[derive(Debug, Error)]
pub enum ConnError {
    #[error(
        "connection `{0}`: {1}; expected udpin:HOST:PORT, udpout:HOST:PORT, udpbcast:HOST:PORT, tcpin:HOST:PORT, tcpout:HOST:PORT or serial:DEVICE:BAUD (udp: is udpin:, tcp: is tcpout:)"
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

/// Connection kinds (`udp` is `udpin`, `tcp` is `tcpout`, as in MAVProxy and pymavlink).
const KINDS: [&str; 8] = [
    "udpin", "udp", "udpout", "udpbcast", "tcpin", "tcpout", "tcp", "serial",
];

/// An I/O error of opening `spec`, with what was being done (the OS's text alone, "No such
/// file or directory", named no device).
fn opening(spec: &ConnSpec, what: String) -> impl Fn(std::io::Error) -> ConnError {
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

impl FromStr for ConnSpec {
    type Err = ConnError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |why: String| ConnError::Syntax(s.to_string(), why);
        let (kind, rest) = s.split_once(':').ok_or_else(|| {
            if KINDS.contains(&s) {
                bad(format!("`{s}` needs an address after a `:`"))
            } else {
                bad("no kind before a `:`".into())
            }
        })?;
        if kind == "serial" {
            let (dev, baud) = rest
                .rsplit_once(':')
                .ok_or_else(|| bad("no baud rate".into()))?;
            let baud = baud
                .parse()
                .map_err(|_| bad(format!("baud rate `{baud}` is not a whole number")))?;
            if dev.is_empty() {
                return Err(bad("no device".into()));
            }
            if baud == 0 {
                return Err(bad("baud rate 0".into()));
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

enum Transport {
    Udp {
        sock: UdpSocket,
        /// Where sends go: fixed for udpout/udpbcast, the last sender for udpin.
        peer: Option<SocketAddr>,
        learn_peer: bool,
    },
    TcpIn {
        listener: TcpListener,
        stream: Option<TcpStream>,
    },
    TcpOut {
        addr: SocketAddr,
        stream: Option<TcpStream>,
        /// Why the first connection attempt failed (the link retries every second).
        refused: Option<String>,
        /// A sender tries to reconnect at most this often (see `send`).
        next_attempt: tokio::time::Instant,
    },
    /// Read as a byte stream through our own framer, like TCP, so that bad CRCs, resyncs
    /// and unknown ids on a radio link are counted too.
    Serial(Box<tokio_serial::SerialStream>),
}

/// Write a frame to a TCP stream; a failed write drops the stream (it is re-made on the next
/// send or receive). True when written.
async fn write_or_drop(stream: &mut Option<TcpStream>, frame: &[u8]) -> bool {
    let Some(s) = stream.as_mut() else {
        return false;
    };
    // A peer that stops reading fills the socket's buffer; waiting on it would stall the
    // monitor, so a write that does not finish soon drops the connection (a partial frame
    // has spoilt the stream anyway).
    match tokio::time::timeout(SEND_WRITE_TIMEOUT, s.write_all(frame)).await {
        Ok(Ok(())) => true,
        _ => {
            *stream = None;
            false
        }
    }
}

/// What [`Link::recv_or_note`] brings.
// Nearly every one is a frame, moved on at once: boxing it would allocate per frame.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum Received {
    Frame(Frame),
    Note(String),
}

/// One live connection: receive frames, send encoded frames.
pub struct Link {
    pub spec: ConnSpec,
    transport: Transport,
    framer: StreamFramer,
    buf: Vec<u8>,
    /// Times an outgoing TCP connection was re-established.
    pub reconnects: u64,
    /// What happened to a TCP connection since last asked (connected, lost), for the user.
    notes: std::collections::VecDeque<String>,
    /// UDP: the sender of the datagram being parsed, and per autopilot (system id) the address
    /// it was last heard from and when; systems already said to come from two at once.
    datagram_from: Option<SocketAddr>,
    autopilot_from: std::collections::BTreeMap<u8, (SocketAddr, tokio::time::Instant)>,
    told_two_sources: std::collections::BTreeSet<u8>,
}

/// Two senders of one autopilot's system id within this of each other are two streams at once
/// (not a sender that restarted on a new port).
const TWO_SOURCES_WITHIN: Duration = Duration::from_secs(1);

impl Link {
    pub async fn open(spec: ConnSpec) -> Result<Self, ConnError> {
        let transport = match &spec {
            ConnSpec::UdpIn(a) => Transport::Udp {
                sock: UdpSocket::bind(a)
                    .await
                    .map_err(opening(&spec, format!("cannot listen on UDP {a}")))?,
                peer: None,
                learn_peer: true,
            },
            ConnSpec::UdpOut(a) => {
                let local: SocketAddr = if a.is_ipv4() {
                    "0.0.0.0:0".parse().expect("literal")
                } else {
                    "[::]:0".parse().expect("literal")
                };
                Transport::Udp {
                    sock: UdpSocket::bind(local).await.map_err(opening(
                        &spec,
                        format!("cannot open a UDP socket on {local}"),
                    ))?,
                    peer: Some(*a),
                    learn_peer: false,
                }
            }
            ConnSpec::UdpBcast(a) => {
                let io = opening(&spec, "cannot open a UDP broadcast socket".into());
                let sock = UdpSocket::bind("0.0.0.0:0").await.map_err(&io)?;
                sock.set_broadcast(true).map_err(&io)?;
                Transport::Udp {
                    sock,
                    peer: Some(*a),
                    learn_peer: false,
                }
            }
            ConnSpec::TcpIn(a) => Transport::TcpIn {
                listener: TcpListener::bind(a)
                    .await
                    .map_err(opening(&spec, format!("cannot listen on TCP {a}")))?,
                stream: None,
            },
            ConnSpec::TcpOut(a) => {
                let (stream, refused) = match TcpStream::connect(a).await {
                    Ok(s) => (Some(s), None),
                    Err(e) => (None, Some(e.to_string())),
                };
                Transport::TcpOut {
                    addr: *a,
                    stream,
                    refused,
                    next_attempt: tokio::time::Instant::now(),
                }
            }
            ConnSpec::Serial(dev, baud) => {
                use tokio_serial::SerialPortBuilderExt;
                let port = tokio_serial::new(dev.as_str(), *baud)
                    .open_native_async()
                    .map_err(|e| {
                        opening(&spec, format!("cannot open serial device {dev}"))(
                            std::io::Error::other(e.to_string()),
                        )
                    })?;
                Transport::Serial(Box::new(port))
            }
        };
        Ok(Self {
            spec,
            transport,
            framer: StreamFramer::default(),
            buf: vec![0; 65536],
            reconnects: 0,
            notes: Default::default(),
            datagram_from: None,
            autopilot_from: Default::default(),
            told_two_sources: Default::default(),
        })
    }

    /// A frame from an autopilot (component 1) whose system id another address is sending
    /// too, at the same time: said once per system id (two links to one vehicle, or two
    /// vehicles with the same id, whose streams the monitor can only count as reordered and
    /// duplicated).
    fn note_source(&mut self, f: &Frame) {
        let Some(from) = self.datagram_from else {
            return;
        };
        if f.compid != 1 {
            return;
        }
        let now = tokio::time::Instant::now();
        if let Some((before, at)) = self.autopilot_from.insert(f.sysid, (from, now))
            && before != from
            && now.duration_since(at) < TWO_SOURCES_WITHIN
            && self.told_two_sources.insert(f.sysid)
        {
            self.notes.push_back(format!(
                "system {} is heard from {before} and from {from} at once: two links to one vehicle, or two vehicles with the same system id (its samples will count as reordered and duplicated)",
                f.sysid
            ));
        }
    }

    /// The local address (UDP/TCP), e.g. to learn the port of `udpin:127.0.0.1:0`.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.transport {
            Transport::Udp { sock, .. } => sock.local_addr().ok(),
            Transport::TcpIn { listener, .. } => listener.local_addr().ok(),
            _ => None,
        }
    }

    /// Why an outgoing TCP link is not connected yet (it keeps retrying every second); None
    /// for every other link, and once connected.
    pub fn not_connected(&self) -> Option<&str> {
        match &self.transport {
            Transport::TcpOut {
                stream: None,
                refused,
                ..
            } => Some(refused.as_deref().unwrap_or("connection lost")),
            _ => None,
        }
    }

    pub fn counters(&self) -> FrameCounters {
        self.framer.counters
    }

    /// Next frame; waits as long as it takes (wrap in a timeout for link-loss detection).
    /// I/O errors of outgoing TCP are absorbed by reconnecting (every second).
    pub async fn recv(&mut self) -> Result<Frame, ConnError> {
        loop {
            if let Received::Frame(f) = self.recv_or_note().await? {
                return Ok(f);
            }
        }
    }

    /// Next frame, or a change of a TCP connection's state as it happens ("connected to
    /// 127.0.0.1:5760", "connection to ... lost; reconnecting every second").
    pub async fn recv_or_note(&mut self) -> Result<Received, ConnError> {
        loop {
            if let Some(note) = self.notes.pop_front() {
                return Ok(Received::Note(note));
            }
            if let Some(f) = self.framer.next_frame() {
                self.note_source(&f);
                return Ok(Received::Frame(f));
            }
            let io = |spec: &ConnSpec, source| ConnError::Io {
                spec: spec.to_string(),
                source,
            };
            match &mut self.transport {
                Transport::Udp {
                    sock,
                    peer,
                    learn_peer,
                } => match sock.recv_from(&mut self.buf).await {
                    Ok((n, from)) => {
                        if *learn_peer {
                            *peer = Some(from);
                        }
                        self.datagram_from = Some(from);
                        // What the last datagram left is a partial frame that cannot complete
                        // (UDP keeps boundaries): counted, not joined to this one.
                        self.framer.end_datagram();
                        self.framer.push(&self.buf[..n]);
                        // Parse this datagram completely before the next one.
                        if let Some(f) = self.framer.next_frame() {
                            self.note_source(&f);
                            return Ok(Received::Frame(f));
                        }
                        self.framer.end_datagram();
                    }
                    // e.g. ICMP port unreachable after a send: not fatal for a datagram link.
                    Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {}
                    Err(e) => return Err(io(&self.spec, e)),
                },
                Transport::TcpIn { listener, stream } => match stream {
                    None => {
                        let (s, from) = listener.accept().await.map_err(|e| io(&self.spec, e))?;
                        *stream = Some(s);
                        self.notes
                            .push_back(format!("a client connected from {from}"));
                    }
                    Some(s) => match s.read(&mut self.buf).await {
                        // A partial frame of the lost connection cannot complete either.
                        Ok(0) | Err(_) => {
                            *stream = None;
                            self.framer.end_datagram();
                            self.notes
                                .push_back("the client disconnected; waiting for another".into());
                        }
                        Ok(n) => self.framer.push(&self.buf[..n]),
                    },
                },
                Transport::TcpOut { addr, stream, .. } => match stream {
                    None => {
                        tokio::time::sleep(Duration::from_secs(1)).await;
                        if let Ok(s) = TcpStream::connect(*addr).await {
                            *stream = Some(s);
                            self.reconnects += 1;
                            self.notes.push_back(format!("connected to {addr}"));
                        }
                    }
                    Some(s) => match s.read(&mut self.buf).await {
                        // A partial frame of the lost connection cannot complete either.
                        Ok(0) | Err(_) => {
                            *stream = None;
                            self.framer.end_datagram();
                            self.notes.push_back(format!(
                                "connection to {addr} lost; reconnecting every second"
                            ));
                        }
                        Ok(n) => self.framer.push(&self.buf[..n]),
                    },
                },
                Transport::Serial(port) => match port.read(&mut self.buf).await {
                    Ok(0) => {
                        // A closed device (USB radio unplugged): wait and let the caller's
                        // link-loss timer report it, rather than spinning.
                        tokio::time::sleep(Duration::from_millis(100)).await;
                    }
                    Ok(n) => self.framer.push(&self.buf[..n]),
                    Err(e) => return Err(io(&self.spec, e)),
                },
            }
        }
    }

    /// Send one encoded frame. `Ok(false)`: nowhere to send yet (udpin before any peer,
    /// tcp without a connection).
    pub async fn send(&mut self, frame: &[u8]) -> Result<bool, ConnError> {
        let spec = self.spec.to_string();
        let io = |source| ConnError::Io {
            spec: spec.clone(),
            source,
        };
        match &mut self.transport {
            Transport::Udp { sock, peer, .. } => match peer {
                Some(p) => match sock.send_to(frame, *p).await {
                    Ok(_) => Ok(true),
                    Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => Ok(false),
                    Err(e) => Err(io(e)),
                },
                None => Ok(false),
            },
            // A sender never waits for its peer: the monitor's loop (estimators, decisions,
            // ctrl-c) must go on while no planner is there. Frames until then are not sent.
            Transport::TcpIn { listener, stream } => {
                if stream.is_none() {
                    // One look at the backlog, no waiting (not even a timer tick).
                    let polled =
                        std::future::poll_fn(|cx| std::task::Poll::Ready(listener.poll_accept(cx)))
                            .await;
                    match polled {
                        std::task::Poll::Ready(Ok((s, from))) => {
                            *stream = Some(s);
                            self.notes
                                .push_back(format!("a client connected from {from}"));
                        }
                        std::task::Poll::Ready(Err(e)) => return Err(io(e)),
                        std::task::Poll::Pending => return Ok(false),
                    }
                }
                Ok(write_or_drop(stream, frame).await)
            }
            Transport::TcpOut {
                addr,
                stream,
                next_attempt,
                ..
            } => {
                if stream.is_none() {
                    let now = tokio::time::Instant::now();
                    if now < *next_attempt {
                        return Ok(false);
                    }
                    *next_attempt = now + Duration::from_secs(1);
                    let connect = TcpStream::connect(*addr);
                    match tokio::time::timeout(SEND_CONNECT_TIMEOUT, connect).await {
                        Ok(Ok(s)) => {
                            *stream = Some(s);
                            self.reconnects += 1;
                            self.notes.push_back(format!("connected to {addr}"));
                        }
                        _ => return Ok(false),
                    }
                }
                Ok(write_or_drop(stream, frame).await)
            }
            Transport::Serial(port) => {
                port.write_all(frame).await.map_err(io)?;
                Ok(true)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runtime() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime")
    }

    #[test]
    fn a_bad_connection_string_says_what_is_wrong_with_it() {
        let cases = [
            ("udpin:0.0.0.0:99999", "port `99999`"),
            ("udpin:1234", "no port"),
            ("udpin:[::1]", "no port"),
            ("nocolon", "no kind"),
            ("udpin", "`udpin` needs an address after a `:`"),
            ("serial:/dev/ttyS0:0", "baud rate 0"),
            ("foo:127.0.0.1:5", "unknown kind `foo`"),
            ("serial:/dev/ttyUSB0:fast", "baud rate `fast`"),
            ("serial::57600", "no device"),
        ];
        for (spec, says) in cases {
            let e = spec.parse::<ConnSpec>().unwrap_err().to_string();
            assert!(e.contains(says) && e.contains(spec), "{spec}: {e}");
        }
        assert_eq!(
            "udpin:127.0.0.1:14550".parse::<ConnSpec>().unwrap(),
            ConnSpec::UdpIn("127.0.0.1:14550".parse().unwrap())
        );
        assert_eq!(
            "serial:/dev/ttyUSB0:57600".parse::<ConnSpec>().unwrap(),
            ConnSpec::Serial("/dev/ttyUSB0".into(), 57600)
        );
    }

    #[test]
    fn a_tcp_connection_lost_and_made_again_is_told_as_it_happens() {
        runtime().block_on(async {
            let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
            let addr = listener.local_addr().expect("addr");
            let spec: ConnSpec = format!("tcpout:{addr}").parse().expect("spec");
            let mut link = Link::open(spec).await.expect("connects");
            let (peer, _) = listener.accept().await.expect("accept");
            drop(peer);
            async fn next(link: &mut Link) -> String {
                match tokio::time::timeout(Duration::from_secs(5), link.recv_or_note()).await {
                    Ok(Ok(Received::Note(n))) => n,
                    other => panic!("{other:?}"),
                }
            }
            // Told before any frame comes (it reconnects within a second, the next note).
            let lost = next(&mut link).await;
            assert!(lost.contains("lost; reconnecting"), "{lost}");
            let again = next(&mut link).await;
            assert_eq!(again, format!("connected to {addr}"));
            assert_eq!(link.reconnects, 1);
        });
    }

    #[test]
    fn outgoing_tcp_says_why_it_is_not_connected() {
        runtime().block_on(async {
            // A port nobody listens on any more: the link opens and says why it waits.
            let closed = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
            let port = closed.local_addr().expect("addr").port();
            drop(closed);
            let spec: ConnSpec = format!("tcpout:127.0.0.1:{port}").parse().expect("spec");
            let link = Link::open(spec).await.expect("opens while refused");
            assert!(link.not_connected().is_some_and(|why| !why.is_empty()));
            // With a listener it is connected at once.
            let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
            let addr = listener.local_addr().expect("addr");
            let spec: ConnSpec = format!("tcpout:{addr}").parse().expect("spec");
            let link = Link::open(spec).await.expect("connects");
            assert_eq!(link.not_connected(), None);
            // Other links never wait for a connection.
            let udp: ConnSpec = "udpin:127.0.0.1:0".parse().expect("spec");
            assert_eq!(Link::open(udp).await.expect("binds").not_connected(), None);
        });
    }

    /// A UDP port already taken (a ground station on 14550) says what to do about it.
    #[test]
    fn a_taken_port_says_how_to_share_the_stream() {
        let taken = std::net::UdpSocket::bind("127.0.0.1:0").expect("bind");
        let addr = taken.local_addr().expect("addr");
        runtime().block_on(async {
            let spec: ConnSpec = format!("udpin:{addr}").parse().expect("spec");
            let Err(e) = Link::open(spec).await else {
                panic!("a second socket bound {addr}");
            };
            let msg = format!("{e:#}");
            assert!(msg.contains("in use"), "{msg}");
            assert!(
                msg.contains("listen on a free port and have it forward"),
                "{msg}"
            );
        });
    }

    #[test]
    fn tcp_senders_never_wait_for_their_peer() {
        runtime().block_on(async {
            let limit = Duration::from_secs(1);
            // tcpin with no client yet: the frame is not sent, at once.
            let spec: ConnSpec = "tcpin:127.0.0.1:0".parse().expect("spec");
            let mut server = Link::open(spec).await.expect("listens");
            let addr = server.local_addr().expect("addr");
            let sent = tokio::time::timeout(limit, server.send(b"x")).await;
            assert!(matches!(sent, Ok(Ok(false))), "{sent:?}");
            // Once a planner connects, frames go to it.
            let mut client = TcpStream::connect(addr).await.expect("connect");
            let sent = tokio::time::timeout(limit, server.send(b"hello")).await;
            assert!(matches!(sent, Ok(Ok(true))), "{sent:?}");
            let mut got = [0u8; 5];
            client.read_exact(&mut got).await.expect("read");
            assert_eq!(&got, b"hello");
            // A planner that stops reading: once its buffers are full the connection is
            // dropped, and no send waits long.
            let big = vec![0u8; 65536];
            let mut dropped = false;
            for _ in 0..400 {
                let sent = tokio::time::timeout(limit, server.send(&big)).await;
                match sent {
                    Ok(Ok(true)) => {}
                    Ok(Ok(false)) => {
                        dropped = true;
                        break;
                    }
                    other => panic!("a send waited or failed: {other:?}"),
                }
            }
            assert!(dropped, "26 MB went into a peer that reads nothing");
            drop(client);
            // tcpout to nobody: not sent, and not retried within the second.
            let closed = std::net::TcpListener::bind("127.0.0.1:0").expect("bind");
            let port = closed.local_addr().expect("addr").port();
            drop(closed);
            let spec: ConnSpec = format!("tcpout:127.0.0.1:{port}").parse().expect("spec");
            let mut out = Link::open(spec).await.expect("opens");
            for _ in 0..3 {
                let sent = tokio::time::timeout(limit, out.send(b"x")).await;
                assert!(matches!(sent, Ok(Ok(false))), "{sent:?}");
            }
        });
    }

    #[test]
    fn a_partial_frame_at_a_datagram_end_is_counted_not_joined_to_the_next() {
        use crate::link::dialects::ahcmon::{HEARTBEAT_DATA, MavMessage};
        runtime().block_on(async {
            let spec: ConnSpec = "udpin:127.0.0.1:0".parse().expect("spec");
            let mut link = Link::open(spec).await.expect("binds");
            let to = link.local_addr().expect("addr");
            let mut frame = Vec::new();
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
            super::super::frame::encode_v2(1, 1, 0, &hb, &mut frame);
            // Datagram 1: a whole frame, then the first half of another; datagram 2: the
            // second half (alone it is no frame), then a whole frame.
            let half = frame.len() / 2;
            let first = [frame.as_slice(), &frame[..half]].concat();
            let second = [&frame[half..], frame.as_slice()].concat();
            let sock = UdpSocket::bind("127.0.0.1:0").await.expect("bind");
            sock.send_to(&first, to).await.expect("send");
            sock.send_to(&second, to).await.expect("send");
            for _ in 0..2 {
                tokio::time::timeout(Duration::from_secs(5), link.recv())
                    .await
                    .expect("a frame in time")
                    .expect("a frame");
            }
            let c = link.counters();
            assert_eq!(c.frames, 2, "{c:?}");
            assert_eq!(c.truncated, 1, "{c:?}");
            // The two halves were never parsed as one frame.
            assert_eq!(c.bad_crc, 0, "{c:?}");
        });
    }

    #[test]
    fn one_system_id_from_two_addresses_at_once_is_told_once() {
        use crate::link::dialects::ahcmon::{HEARTBEAT_DATA, MavMessage};
        runtime().block_on(async {
            let spec: ConnSpec = "udpin:127.0.0.1:0".parse().expect("spec");
            let mut link = Link::open(spec).await.expect("binds");
            let to = link.local_addr().expect("addr");
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
            let frame = |sysid, compid| {
                let mut f = Vec::new();
                super::super::frame::encode_v2(sysid, compid, 0, &hb, &mut f);
                f
            };
            let (a, b) = (
                UdpSocket::bind("127.0.0.1:0").await.expect("bind"),
                UdpSocket::bind("127.0.0.1:0").await.expect("bind"),
            );
            // System 1's autopilot from both; system 2's from one; a camera (component 100) of
            // system 2 from the other: only system 1 is two streams.
            for _ in 0..3 {
                a.send_to(&frame(1, 1), to).await.expect("send");
                b.send_to(&frame(1, 1), to).await.expect("send");
                a.send_to(&frame(2, 1), to).await.expect("send");
                b.send_to(&frame(2, 100), to).await.expect("send");
            }
            let mut notes = vec![];
            let mut frames = 0;
            while frames < 12 {
                match tokio::time::timeout(Duration::from_secs(5), link.recv_or_note()).await {
                    Ok(Ok(Received::Frame(_))) => frames += 1,
                    Ok(Ok(Received::Note(n))) => notes.push(n),
                    other => panic!("{other:?}"),
                }
            }
            if let Ok(Ok(Received::Note(n))) =
                tokio::time::timeout(Duration::from_millis(100), link.recv_or_note()).await
            {
                notes.push(n);
            }
            assert_eq!(notes.len(), 1, "{notes:?}");
            assert!(notes[0].starts_with("system 1 is heard from"), "{notes:?}");
        });
    }
}
