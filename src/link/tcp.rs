//! TCP: `tcpin` reads one client at a time (a new one takes over from one silent for
//! [`TCPIN_IDLE`]), `tcpout` connects and reconnects every second.
//! A sender never waits for its peer: the monitor's loop (estimators, decisions, ctrl-c) must
//! go on while no planner is there; frames until then are not sent.

use super::conn::Read;
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

/// How long a sender waits for an outgoing TCP connection before dropping the frame (it tries
/// again a second later).
const SEND_CONNECT_TIMEOUT: Duration = Duration::from_millis(100);
/// How long a send may wait for room in a TCP peer's buffer.
const SEND_WRITE_TIMEOUT: Duration = Duration::from_millis(100);

/// A `tcpin` client that has sent nothing for this long gives way to a new one: an idle
/// client that connected first used to keep the vehicle out for good.
pub const TCPIN_IDLE: Duration = Duration::from_secs(2);

pub(super) struct TcpIn {
    listener: TcpListener,
    stream: Option<TcpStream>,
    /// When the connected client last sent bytes (or connected).
    last_bytes: tokio::time::Instant,
}

pub(super) struct TcpOut {
    addr: SocketAddr,
    stream: Option<TcpStream>,
    /// Why the first connection attempt failed (the link retries every second).
    refused: Option<String>,
    /// A sender tries to reconnect at most this often (see `send`).
    next_attempt: tokio::time::Instant,
    /// Times the connection was re-established.
    pub(super) reconnects: u64,
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

/// One read of a connected stream: `None` when there is none. A closed or failed one is
/// dropped, with `lost` as the note (`Read::Lost`).
async fn read_stream(
    stream: &mut Option<TcpStream>,
    buf: &mut [u8],
    notes: &mut VecDeque<String>,
    lost: impl FnOnce() -> String,
) -> Option<Read> {
    let s = stream.as_mut()?;
    Some(match s.read(buf).await {
        Ok(0) | Err(_) => {
            *stream = None;
            notes.push_back(lost());
            Read::Lost
        }
        Ok(n) => Read::Bytes(n),
    })
}

impl TcpIn {
    pub(super) async fn listen(addr: SocketAddr) -> std::io::Result<Self> {
        Ok(Self {
            listener: TcpListener::bind(addr).await?,
            stream: None,
            last_bytes: tokio::time::Instant::now(),
        })
    }

    pub(super) fn local_addr(&self) -> Option<SocketAddr> {
        self.listener.local_addr().ok()
    }

    pub(super) async fn read(
        &mut self,
        buf: &mut [u8],
        notes: &mut VecDeque<String>,
    ) -> std::io::Result<Read> {
        let lost = || "the client disconnected; waiting for another".to_string();
        let Self {
            listener,
            stream,
            last_bytes,
        } = self;
        if stream.is_some() {
            // Both futures are cancel-safe: a read or an accept that loses the race is lost
            // to neither.
            tokio::select! {
                read = read_stream(stream, buf, notes, lost) => {
                    if let Some(Read::Bytes(_)) = read {
                        *last_bytes = tokio::time::Instant::now();
                    }
                    return Ok(read.unwrap_or(Read::Nothing));
                }
                accepted = listener.accept() => {
                    let (s, from) = accepted?;
                    let silent = last_bytes.elapsed();
                    if silent >= TCPIN_IDLE {
                        *stream = Some(s);
                        *last_bytes = tokio::time::Instant::now();
                        notes.push_back(format!(
                            "a client connected from {from}; the previous one, silent for {:.1} s, was dropped",
                            silent.as_secs_f64()
                        ));
                    } else {
                        notes.push_back(format!(
                            "a second client from {from} was refused: one client at a time, and the connected one is sending"
                        ));
                    }
                    return Ok(Read::Nothing);
                }
            }
        }
        let (s, from) = listener.accept().await?;
        *stream = Some(s);
        *last_bytes = tokio::time::Instant::now();
        notes.push_back(format!("a client connected from {from}"));
        Ok(Read::Nothing)
    }

    pub(super) async fn send(
        &mut self,
        frame: &[u8],
        notes: &mut VecDeque<String>,
    ) -> std::io::Result<bool> {
        if self.stream.is_none() {
            // One look at the backlog, no waiting (not even a timer tick).
            let listener = &self.listener;
            let polled =
                std::future::poll_fn(|cx| std::task::Poll::Ready(listener.poll_accept(cx))).await;
            match polled {
                std::task::Poll::Ready(Ok((s, from))) => {
                    self.stream = Some(s);
                    self.last_bytes = tokio::time::Instant::now();
                    notes.push_back(format!("a client connected from {from}"));
                }
                std::task::Poll::Ready(Err(e)) => return Err(e),
                std::task::Poll::Pending => return Ok(false),
            }
        }
        Ok(write_or_drop(&mut self.stream, frame).await)
    }
}

impl TcpOut {
    /// Tries once now; a refused connection is kept as the reason and retried every second.
    pub(super) async fn connect(addr: SocketAddr) -> Self {
        let (stream, refused) = match TcpStream::connect(addr).await {
            Ok(s) => (Some(s), None),
            Err(e) => (None, Some(e.to_string())),
        };
        Self {
            addr,
            stream,
            refused,
            next_attempt: tokio::time::Instant::now(),
            reconnects: 0,
        }
    }

    /// Why it is not connected (None once connected).
    pub(super) fn not_connected(&self) -> Option<&str> {
        match self.stream {
            None => Some(self.refused.as_deref().unwrap_or("connection lost")),
            Some(_) => None,
        }
    }

    pub(super) async fn read(
        &mut self,
        buf: &mut [u8],
        notes: &mut VecDeque<String>,
    ) -> std::io::Result<Read> {
        let addr = self.addr;
        let lost = || format!("connection to {addr} lost; reconnecting every second");
        if let Some(read) = read_stream(&mut self.stream, buf, notes, lost).await {
            return Ok(read);
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
        if let Ok(s) = TcpStream::connect(addr).await {
            self.stream = Some(s);
            self.reconnects += 1;
            notes.push_back(format!("connected to {addr}"));
        }
        Ok(Read::Nothing)
    }

    pub(super) async fn send(
        &mut self,
        frame: &[u8],
        notes: &mut VecDeque<String>,
    ) -> std::io::Result<bool> {
        if self.stream.is_none() {
            let now = tokio::time::Instant::now();
            if now < self.next_attempt {
                return Ok(false);
            }
            self.next_attempt = now + Duration::from_secs(1);
            let connect = TcpStream::connect(self.addr);
            match tokio::time::timeout(SEND_CONNECT_TIMEOUT, connect).await {
                Ok(Ok(s)) => {
                    self.stream = Some(s);
                    self.reconnects += 1;
                    notes.push_back(format!("connected to {}", self.addr));
                }
                _ => return Ok(false),
            }
        }
        Ok(write_or_drop(&mut self.stream, frame).await)
    }
}
