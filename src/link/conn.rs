//! One live MAVLink connection over any transport (`udp.rs`, `tcp.rs`, `serial.rs`).
//!
//! Every transport is framed by our own [`StreamFramer`], so every dropped byte is counted
//! (the `mavlink` crate's `recv` skips silently). Outgoing kinds (`udpout`, `tcpout`)
//! reconnect; `udpin` answers the last peer it heard from.

use super::serial::Serial;
use super::spec::{ConnError, ConnSpec, opening};
use super::tcp::{TcpIn, TcpOut};
use super::udp::Udp;
use crate::protocol::frame::{Frame, FrameCounters, StreamFramer};
use std::net::{Ipv6Addr, SocketAddr};
use std::time::Duration;

enum Transport {
    Udp(Udp),
    TcpIn(TcpIn),
    TcpOut(TcpOut),
    Serial(Serial),
}

/// What one read of a transport gave the framer.
pub(super) enum Read {
    /// One datagram of this many bytes, from that sender (UDP keeps boundaries).
    Datagram(usize, SocketAddr),
    /// This many bytes of a byte stream.
    Bytes(usize),
    /// The stream was lost: a partial frame of it cannot complete.
    Lost,
    /// Nothing to parse (a connection made, a refused datagram, a wait).
    Nothing,
}

/// What [`Link::recv_or_note`] brings.
// Nearly every one is a frame, moved on at once: boxing it would allocate per frame.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
pub enum Received {
    Frame(Frame),
    Note(String),
    /// An autopilot's system id heard from a second address at the same time: two links to
    /// one vehicle, or two vehicles with one id (said once per id).
    TwoSources {
        sysid: u8,
        detail: String,
    },
}

/// One live connection: receive frames, send encoded frames.
pub struct Link {
    pub spec: ConnSpec,
    transport: Transport,
    framer: StreamFramer,
    buf: Vec<u8>,
    /// What happened to a TCP connection since last asked (connected, lost), for the user.
    notes: std::collections::VecDeque<String>,
    /// UDP: the sender of the datagram being parsed, and per autopilot (system id) the address
    /// it was last heard from and when; systems already said to come from two at once.
    datagram_from: Option<SocketAddr>,
    autopilot_from: std::collections::BTreeMap<u8, (SocketAddr, tokio::time::Instant)>,
    told_two_sources: std::collections::BTreeSet<u8>,
    two_sources: std::collections::VecDeque<(u8, String)>,
}

/// Two senders of one autopilot's system id within this of each other are two streams at once
/// (not a sender that restarted on a new port).
const TWO_SOURCES_WITHIN: Duration = Duration::from_secs(1);

impl Link {
    pub async fn open(spec: ConnSpec) -> Result<Self, ConnError> {
        let transport = match &spec {
            ConnSpec::UdpIn(a) => Transport::Udp(
                Udp::listen(*a)
                    .await
                    .map_err(opening(&spec, format!("cannot listen on UDP {a}")))?,
            ),
            ConnSpec::UdpOut(a) => {
                let local = if a.is_ipv4() {
                    SocketAddr::from(([0, 0, 0, 0], 0))
                } else {
                    SocketAddr::from((Ipv6Addr::UNSPECIFIED, 0))
                };
                Transport::Udp(Udp::send_to(local, *a).await.map_err(opening(
                    &spec,
                    format!("cannot open a UDP socket on {local}"),
                ))?)
            }
            ConnSpec::UdpBcast(a) => Transport::Udp(
                Udp::broadcast(*a)
                    .await
                    .map_err(opening(&spec, "cannot open a UDP broadcast socket".into()))?,
            ),
            ConnSpec::TcpIn(a) => Transport::TcpIn(
                TcpIn::listen(*a)
                    .await
                    .map_err(opening(&spec, format!("cannot listen on TCP {a}")))?,
            ),
            ConnSpec::TcpOut(a) => Transport::TcpOut(TcpOut::connect(*a).await),
            ConnSpec::Serial(dev, baud) => Transport::Serial(
                Serial::open(dev, *baud)
                    .map_err(opening(&spec, format!("cannot open serial device {dev}")))?,
            ),
        };
        Ok(Self {
            spec,
            transport,
            framer: StreamFramer::default(),
            buf: vec![0; 65536],
            notes: Default::default(),
            datagram_from: None,
            autopilot_from: Default::default(),
            told_two_sources: Default::default(),
            two_sources: Default::default(),
        })
    }

    /// Only frames signed with this key pass (`protocol::signing`).
    pub fn set_signing(&mut self, signing: crate::protocol::signing::Signing) {
        self.framer.signing = Some(signing);
    }

    /// Times an outgoing TCP connection was re-established (0 for every other link).
    pub fn reconnects(&self) -> u64 {
        match &self.transport {
            Transport::TcpOut(t) => t.reconnects,
            _ => 0,
        }
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
            self.two_sources.push_back((
                f.sysid,
                format!(
                    "system {} is heard from {before} and from {from} at once: two links to one vehicle, or two vehicles with the same system id (its samples will count as reordered and duplicated, its estimates may be wrong)",
                    f.sysid
                ),
            ));
        }
    }

    /// The local address (UDP/TCP), e.g. to learn the port of `udpin:127.0.0.1:0`.
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.transport {
            Transport::Udp(u) => u.local_addr(),
            Transport::TcpIn(t) => t.local_addr(),
            _ => None,
        }
    }

    /// Why an outgoing TCP link is not connected yet (it keeps retrying every second); None
    /// for every other link, and once connected.
    pub fn not_connected(&self) -> Option<&str> {
        match &self.transport {
            Transport::TcpOut(t) => t.not_connected(),
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
            if let Some((sysid, detail)) = self.two_sources.pop_front() {
                return Ok(Received::TwoSources { sysid, detail });
            }
            if let Some(f) = self.framer.next_frame() {
                self.note_source(&f);
                return Ok(Received::Frame(f));
            }
            let read = match &mut self.transport {
                Transport::Udp(u) => u.read(&mut self.buf).await,
                Transport::TcpIn(t) => t.read(&mut self.buf, &mut self.notes).await,
                Transport::TcpOut(t) => t.read(&mut self.buf, &mut self.notes).await,
                Transport::Serial(s) => s.read(&mut self.buf).await,
            };
            let read = read.map_err(|source| ConnError::Io {
                spec: self.spec.to_string(),
                source,
            })?;
            match read {
                Read::Datagram(n, from) => {
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
                Read::Bytes(n) => self.framer.push(&self.buf[..n]),
                // A partial frame of the lost connection cannot complete.
                Read::Lost => self.framer.end_datagram(),
                Read::Nothing => {}
            }
        }
    }

    /// Send one encoded frame. `Ok(false)`: nowhere to send yet (udpin before any peer,
    /// tcp without a connection).
    pub async fn send(&mut self, frame: &[u8]) -> Result<bool, ConnError> {
        let sent = match &mut self.transport {
            Transport::Udp(u) => u.send(frame).await,
            Transport::TcpIn(t) => t.send(frame, &mut self.notes).await,
            Transport::TcpOut(t) => t.send(frame, &mut self.notes).await,
            Transport::Serial(s) => s.send(frame).await,
        };
        sent.map_err(|source| ConnError::Io {
            spec: self.spec.to_string(),
            source,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::ConnSpec;
    use tokio::io::AsyncReadExt;
    use tokio::net::{TcpListener, TcpStream, UdpSocket};

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

    /// MAVProxy's `--master` forms of a serial device: `DEVICE,BAUD`, or the device alone at
    /// its default 57600; `serial:DEVICE` too.
    #[test]
    fn a_serial_device_is_taken_as_mavproxy_spells_it() {
        use crate::link::spec::DEFAULT_BAUD;
        let serial = |d: &str, b| ConnSpec::Serial(d.into(), b);
        for (spec, want) in [
            ("/dev/ttyUSB0,57600", serial("/dev/ttyUSB0", 57600)),
            ("/dev/ttyACM0,115200", serial("/dev/ttyACM0", 115200)),
            ("/dev/ttyUSB0", serial("/dev/ttyUSB0", DEFAULT_BAUD)),
            ("serial:/dev/ttyUSB0", serial("/dev/ttyUSB0", DEFAULT_BAUD)),
            (
                "serial:/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0",
                serial(
                    "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0",
                    DEFAULT_BAUD,
                ),
            ),
            ("COM3,921600", serial("COM3", 921600)),
            ("com4", serial("com4", DEFAULT_BAUD)),
            // A by-path name holds colons; the whole of it is the device.
            (
                "/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0,57600",
                serial("/dev/serial/by-path/pci-0000:00:14.0-usb-0:1:1.0", 57600),
            ),
        ] {
            assert_eq!(spec.parse::<ConnSpec>().unwrap(), want, "{spec}");
        }
        assert_eq!(DEFAULT_BAUD, 57600);
        for (spec, says) in [
            ("/dev/ttyUSB0,fast", "baud rate `fast`"),
            ("/dev/ttyUSB0,0", "baud rate 0"),
            ("COMX", "no kind"),
        ] {
            let e = spec.parse::<ConnSpec>().unwrap_err().to_string();
            assert!(e.contains(says), "{spec}: {e}");
        }
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
            assert_eq!(link.reconnects(), 1);
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

    /// An idle client that connected to `tcpin` first no longer keeps the vehicle out: once
    /// it has been silent for `TCPIN_IDLE`, the next client takes over and its frames are
    /// read; a second client while the first is sending is refused.
    #[test]
    fn tcpin_gives_an_idle_client_s_place_to_the_next() {
        use crate::protocol::dialects::ahcmon::{
            HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
        };
        use tokio::io::AsyncWriteExt;
        runtime().block_on(async {
            let spec: ConnSpec = "tcpin:127.0.0.1:0".parse().expect("spec");
            let mut server = Link::open(spec).await.expect("listens");
            let addr = server.local_addr().expect("addr");
            let idle = TcpStream::connect(addr).await.expect("connect");
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            });
            let mut frame = Vec::new();
            crate::protocol::frame::encode_v2(7, 1, 0, &hb, &mut frame);
            let vehicle = tokio::spawn(async move {
                tokio::time::sleep(crate::link::tcp::TCPIN_IDLE + Duration::from_millis(300)).await;
                let mut v = TcpStream::connect(addr).await.expect("connect");
                for _ in 0..20 {
                    v.write_all(&frame).await.expect("write");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                v
            });
            let mut notes = vec![];
            let got = tokio::time::timeout(Duration::from_secs(10), async {
                loop {
                    match server.recv_or_note().await.expect("recv") {
                        Received::Frame(f) => return f,
                        Received::Note(n) => notes.push(n),
                        Received::TwoSources { .. } => {}
                    }
                }
            })
            .await
            .expect("the vehicle's frames never came past the idle client");
            assert_eq!(got.sysid, 7);
            assert!(notes.iter().any(|n| n.contains("silent for")), "{notes:?}");
            // A third client while the vehicle sends: refused, the vehicle read on.
            let _third = TcpStream::connect(addr).await.expect("connect");
            let mut refused = false;
            for _ in 0..10 {
                match tokio::time::timeout(Duration::from_secs(2), server.recv_or_note()).await {
                    Ok(Ok(Received::Note(n))) if n.contains("was refused") => refused = true,
                    Ok(Ok(Received::Frame(f))) => assert_eq!(f.sysid, 7),
                    _ => {}
                }
            }
            assert!(refused);
            drop(idle);
            let _ = vehicle.await;
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
        use crate::protocol::dialects::ahcmon::{HEARTBEAT_DATA, MavMessage};
        runtime().block_on(async {
            let spec: ConnSpec = "udpin:127.0.0.1:0".parse().expect("spec");
            let mut link = Link::open(spec).await.expect("binds");
            let to = link.local_addr().expect("addr");
            let mut frame = Vec::new();
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
            crate::protocol::frame::encode_v2(1, 1, 0, &hb, &mut frame);
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
        use crate::protocol::dialects::ahcmon::{HEARTBEAT_DATA, MavMessage};
        runtime().block_on(async {
            let spec: ConnSpec = "udpin:127.0.0.1:0".parse().expect("spec");
            let mut link = Link::open(spec).await.expect("binds");
            let to = link.local_addr().expect("addr");
            let hb = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
            let frame = |sysid, compid| {
                let mut f = Vec::new();
                crate::protocol::frame::encode_v2(sysid, compid, 0, &hb, &mut f);
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
                    Ok(Ok(Received::TwoSources { sysid, detail })) => notes.push((sysid, detail)),
                    other => panic!("{other:?}"),
                }
            }
            if let Ok(Ok(Received::TwoSources { sysid, detail })) =
                tokio::time::timeout(Duration::from_millis(100), link.recv_or_note()).await
            {
                notes.push((sysid, detail));
            }
            assert_eq!(notes.len(), 1, "{notes:?}");
            assert_eq!(notes[0].0, 1, "{notes:?}");
            assert!(
                notes[0].1.starts_with("system 1 is heard from"),
                "{notes:?}"
            );
        });
    }
}
