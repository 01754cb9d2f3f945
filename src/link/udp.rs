//! UDP: `udpin` listens and answers the last peer it heard from; `udpout` and `udpbcast`
//! send to a fixed address. Datagrams keep their boundaries, which the framer is told.

use super::conn::Read;
use std::net::SocketAddr;
use tokio::net::UdpSocket;

pub(super) struct Udp {
    sock: UdpSocket,
    /// Where sends go: fixed for udpout/udpbcast, the last sender for udpin.
    peer: Option<SocketAddr>,
    learn_peer: bool,
}

/// Receive buffer asked of the kernel (it caps it at `net.core.rmem_max`). The default,
/// about 200 KiB on Linux, overflows when the monitor is busy for a few ms while several
/// vehicles stream at 400 Hz (about 100 datagrams lost per vehicle a minute, measured by
/// `benches/live400.sh` against the kernel's RcvbufErrors); 4 MiB holds about a second of it.
const RECEIVE_BUFFER_BYTES: usize = 4 << 20;

/// A UDP socket bound to `addr` with the larger receive buffer (best effort: a kernel that
/// refuses keeps its default).
fn bind(addr: SocketAddr) -> std::io::Result<UdpSocket> {
    use socket2::{Domain, Protocol, Socket, Type};
    let sock = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))?;
    if let Err(e) = sock.set_recv_buffer_size(RECEIVE_BUFFER_BYTES) {
        tracing::debug!("UDP receive buffer left at the kernel's default: {e}");
    }
    sock.bind(&addr.into())?;
    sock.set_nonblocking(true)?;
    UdpSocket::from_std(sock.into())
}

impl Udp {
    pub(super) async fn listen(addr: SocketAddr) -> std::io::Result<Self> {
        Ok(Self {
            sock: bind(addr)?,
            peer: None,
            learn_peer: true,
        })
    }

    /// A socket on an ephemeral port of `local` that sends to `peer`.
    pub(super) async fn send_to(local: SocketAddr, peer: SocketAddr) -> std::io::Result<Self> {
        Ok(Self {
            sock: bind(local)?,
            peer: Some(peer),
            learn_peer: false,
        })
    }

    pub(super) async fn broadcast(peer: SocketAddr) -> std::io::Result<Self> {
        let sock = UdpSocket::bind("0.0.0.0:0").await?;
        sock.set_broadcast(true)?;
        Ok(Self {
            sock,
            peer: Some(peer),
            learn_peer: false,
        })
    }

    pub(super) fn local_addr(&self) -> Option<SocketAddr> {
        self.sock.local_addr().ok()
    }

    pub(super) async fn read(&mut self, buf: &mut [u8]) -> std::io::Result<Read> {
        match self.sock.recv_from(buf).await {
            Ok((n, from)) => {
                if self.learn_peer {
                    self.peer = Some(from);
                }
                Ok(Read::Datagram(n, from))
            }
            // e.g. ICMP port unreachable after a send: not fatal for a datagram link.
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => Ok(Read::Nothing),
            Err(e) => Err(e),
        }
    }

    /// `Ok(false)`: nowhere to send yet (udpin before any peer), or the peer refused.
    pub(super) async fn send(&mut self, frame: &[u8]) -> std::io::Result<bool> {
        let Some(p) = self.peer else {
            return Ok(false);
        };
        match self.sock.send_to(frame, p).await {
            Ok(_) => Ok(true),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => Ok(false),
            Err(e) => Err(e),
        }
    }
}
