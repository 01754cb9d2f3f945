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

impl Udp {
    pub(super) async fn listen(addr: SocketAddr) -> std::io::Result<Self> {
        Ok(Self {
            sock: UdpSocket::bind(addr).await?,
            peer: None,
            learn_peer: true,
        })
    }

    /// A socket on an ephemeral port of `local` that sends to `peer`.
    pub(super) async fn send_to(local: SocketAddr, peer: SocketAddr) -> std::io::Result<Self> {
        Ok(Self {
            sock: UdpSocket::bind(local).await?,
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
