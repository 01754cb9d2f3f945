//! MAVLink v1/v2 framing with our own drop counters.
//!
//! The `mavlink` crate's readers skip bad candidates silently (`mavlink-core` 0.21), so we
//! frame ourselves: check the magic, the length, the CRC with the dialect's CRC_EXTRA, and
//! decode the payload with the generated dialect. Every byte or frame we drop is counted.

use super::dialects::ahcmon::MavMessage;
use mavlink_core::{MavlinkVersion, Message, calculate_crc};
use serde::Serialize;
use std::sync::LazyLock;

pub const MAGIC_V1: u8 = 0xFE;
pub const MAGIC_V2: u8 = 0xFD;
/// Longest frame: v2 header 10 + payload 255 + CRC 2 + signature 13.
pub const MAX_FRAME: usize = 280;

/// One decoded MAVLink message with its header.
#[derive(Debug, Clone)]
pub struct Frame {
    pub version: MavlinkVersion,
    pub sysid: u8,
    pub compid: u8,
    pub seq: u8,
    pub msg_id: u32,
    pub msg: MavMessage,
}

/// What was dropped and why. Reported at the end of every replay and in the monitor footer.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct FrameCounters {
    /// Frames decoded.
    pub frames: u64,
    /// Times the reader lost sync (bad magic or CRC) and had to slide to the next magic byte.
    pub resync: u64,
    /// Bytes skipped while sliding.
    pub skipped_bytes: u64,
    /// Candidate frames with a known id and a wrong CRC.
    pub bad_crc: u64,
    /// Well-formed frames whose id our dialect does not know (skipped whole).
    pub unknown_id: u64,
    /// Frames with a good CRC whose payload did not decode (e.g. an enum value out of range).
    pub parse_error: u64,
    /// A record cut off by the end of the input.
    pub truncated: u64,
    /// Tlogs: good frames whose timestamp was implausible (a day or more off the log's clock)
    /// and was replaced by the clock's.
    pub repaired_ts: u64,
    /// With a signing key: good frames not signed, and signed but not with the key (or
    /// replayed: a timestamp not newer than its stream's last). Dropped.
    #[serde(skip_serializing_if = "is_zero")]
    pub unsigned: u64,
    #[serde(skip_serializing_if = "is_zero")]
    pub bad_signature: u64,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

impl FrameCounters {
    pub fn dropped(&self) -> u64 {
        self.bad_crc
            + self.unknown_id
            + self.parse_error
            + self.truncated
            + self.unsigned
            + self.bad_signature
    }

    pub fn add(&mut self, o: &FrameCounters) {
        self.frames += o.frames;
        self.resync += o.resync;
        self.skipped_bytes += o.skipped_bytes;
        self.bad_crc += o.bad_crc;
        self.unknown_id += o.unknown_id;
        self.parse_error += o.parse_error;
        self.truncated += o.truncated;
        self.repaired_ts += o.repaired_ts;
        self.unsigned += o.unsigned;
        self.bad_signature += o.bad_signature;
    }
}

impl std::fmt::Display for FrameCounters {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            // The bytes skipped are the resyncs' and the truncated frames' together ("resync 0
            // (1 bytes skipped)" read as a contradiction on a cut log).
            "frames {} · resync {} · bad_crc {} · unknown_id {} · parse_error {} · truncated {} ({} bytes skipped in all)",
            self.frames,
            self.resync,
            self.bad_crc,
            self.unknown_id,
            self.parse_error,
            self.truncated,
            self.skipped_bytes
        )?;
        if self.repaired_ts > 0 {
            write!(f, " · repaired timestamps {}", self.repaired_ts)?;
        }
        if self.unsigned + self.bad_signature > 0 {
            write!(
                f,
                " · unsigned {} · bad_signature {} (dropped: not signed with the key, or replayed)",
                self.unsigned, self.bad_signature
            )?;
        }
        Ok(())
    }
}

/// The message ids of our dialect (all below 2^16), found once by asking the generated code.
static KNOWN_IDS: LazyLock<Box<[u64; 1024]>> = LazyLock::new(|| {
    let mut bits = Box::new([0u64; 1024]);
    for id in 0..65536u32 {
        if MavMessage::default_message_from_id(id).is_some() {
            bits[(id / 64) as usize] |= 1 << (id % 64);
        }
    }
    bits
});

pub fn is_known_id(id: u32) -> bool {
    id < 65536 && KNOWN_IDS[(id / 64) as usize] & (1 << (id % 64)) != 0
}

/// Result of looking at the bytes at the start of a buffer.
#[derive(Debug)]
pub enum Parsed {
    /// A frame, and its length in bytes.
    Frame(Box<Frame>, usize),
    /// The first byte is not a magic byte.
    BadMagic,
    /// The buffer ends before the frame would (this many bytes needed in all).
    Incomplete(usize),
    /// A known id whose CRC does not match.
    BadCrc,
    /// A complete frame (by length) with an id the dialect does not know; its length.
    UnknownId(usize),
    /// CRC good, payload did not decode; its length.
    ParseError(usize),
}

/// Frame length from the header bytes (`b[0]` is the magic); None on a bad magic.
pub fn frame_len(b: &[u8]) -> Option<Result<usize, usize>> {
    let magic = *b.first()?;
    if magic != MAGIC_V1 && magic != MAGIC_V2 {
        return None;
    }
    // Need the length byte (and v2's incompat flags) before the length is known.
    let head = if magic == MAGIC_V1 { 2 } else { 3 };
    if b.len() < head {
        return Some(Err(head));
    }
    let len = b[1] as usize;
    Some(Ok(if magic == MAGIC_V1 {
        6 + len + 2
    } else {
        let signed = b[2] & 0x01 != 0;
        10 + len + 2 + if signed { 13 } else { 0 }
    }))
}

/// Try to decode one frame at the start of `b`.
pub fn parse(b: &[u8]) -> Parsed {
    let total = match frame_len(b) {
        None => return Parsed::BadMagic,
        Some(Err(need)) => return Parsed::Incomplete(need),
        Some(Ok(n)) => n,
    };
    if b.len() < total {
        return Parsed::Incomplete(total);
    }
    let v1 = b[0] == MAGIC_V1;
    let len = b[1] as usize;
    let (header, seq, sysid, compid, msg_id) = if v1 {
        (6, b[2], b[3], b[4], b[5] as u32)
    } else {
        let id = u32::from(b[7]) | u32::from(b[8]) << 8 | u32::from(b[9]) << 16;
        (10, b[4], b[5], b[6], id)
    };
    if !is_known_id(msg_id) {
        return Parsed::UnknownId(total);
    }
    let crc_end = header + len;
    let crc = u16::from_le_bytes([b[crc_end], b[crc_end + 1]]);
    if calculate_crc(&b[1..crc_end], MavMessage::extra_crc(msg_id)) != crc {
        return Parsed::BadCrc;
    }
    let version = if v1 {
        MavlinkVersion::V1
    } else {
        MavlinkVersion::V2
    };
    match MavMessage::parse(version, msg_id, &b[header..crc_end]) {
        Ok(msg) => Parsed::Frame(
            Box::new(Frame {
                version,
                sysid,
                compid,
                seq,
                msg_id,
                msg,
            }),
            total,
        ),
        Err(_) => Parsed::ParseError(total),
    }
}

/// Serialise one message as a v2 frame into `out` (cleared first).
pub fn encode_v2(sysid: u8, compid: u8, seq: u8, msg: &MavMessage, out: &mut Vec<u8>) {
    out.clear();
    let header = mavlink_core::MavHeader {
        system_id: sysid.into(),
        component_id: compid,
        sequence: seq,
    };
    // Writing into a Vec cannot fail.
    let _ = mavlink_core::write_v2_msg(out, header, msg);
}

/// Count a frame the signing check refused; true when refused (`None`: no key, all pass).
pub fn count_unsigned(
    counters: &mut FrameCounters,
    verdict: Option<super::signing::Verdict>,
) -> bool {
    use super::signing::Verdict;
    match verdict {
        None | Some(Verdict::Signed) => false,
        Some(Verdict::Unsigned) => {
            counters.unsigned += 1;
            true
        }
        Some(Verdict::BadSignature | Verdict::Replayed) => {
            counters.bad_signature += 1;
            true
        }
    }
}

/// A byte-stream framer for live links (UDP datagrams, TCP, serial): no timestamps.
#[derive(Debug, Default)]
pub struct StreamFramer {
    buf: Vec<u8>,
    syncing: bool,
    pub counters: FrameCounters,
    /// With a key, only frames signed with it pass ([`super::signing`]).
    pub signing: Option<super::signing::Signing>,
}

impl StreamFramer {
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Next frame in the buffered bytes; None when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Frame> {
        let mut pos = 0;
        let mut out = None;
        while pos < self.buf.len() {
            match parse(&self.buf[pos..]) {
                Parsed::Frame(f, n) => {
                    let verdict = self
                        .signing
                        .as_mut()
                        .map(|s| s.check(&self.buf[pos..pos + n]));
                    pos += n;
                    self.syncing = false;
                    if count_unsigned(&mut self.counters, verdict) {
                        continue;
                    }
                    self.counters.frames += 1;
                    out = Some(*f);
                    break;
                }
                Parsed::Incomplete(_) => break,
                // An unknown id has no CRC we can check, so its length byte is trusted only
                // when the next frame (or the end of the bytes) follows it; otherwise this is
                // most likely a magic byte inside a damaged frame, and skipping by its length
                // would swallow the good frames behind it.
                Parsed::UnknownId(n) if self.frame_follows(pos + n) => {
                    pos += n;
                    self.syncing = false;
                    self.counters.unknown_id += 1;
                }
                Parsed::UnknownId(_) => self.slide(&mut pos),
                Parsed::ParseError(n) => {
                    pos += n;
                    self.counters.parse_error += 1;
                }
                Parsed::BadCrc => {
                    self.counters.bad_crc += 1;
                    self.slide(&mut pos);
                }
                Parsed::BadMagic => self.slide(&mut pos),
            }
        }
        self.buf.drain(..pos);
        out
    }

    fn frame_follows(&self, at: usize) -> bool {
        self.buf
            .get(at)
            .is_none_or(|&b| b == MAGIC_V1 || b == MAGIC_V2)
    }

    fn slide(&mut self, pos: &mut usize) {
        if !self.syncing {
            self.counters.resync += 1;
            self.syncing = true;
        }
        self.counters.skipped_bytes += 1;
        *pos += 1;
    }

    /// End of a datagram (UDP keeps boundaries) or of a connection: a partial frame left over
    /// cannot complete; it is counted as truncated and dropped.
    pub fn end_datagram(&mut self) {
        if !self.buf.is_empty() {
            self.counters.truncated += 1;
            self.counters.skipped_bytes += self.buf.len() as u64;
            self.buf.clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::dialects::ahcmon::ATTITUDE_DATA;

    fn attitude_frame(k: u32) -> Vec<u8> {
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: 1000 + 20 * k,
            roll: 0.1,
            pitch: 0.2,
            yaw: 0.3,
            rollspeed: 0.01,
            pitchspeed: 0.02,
            yawspeed: 0.03,
        });
        let mut out = Vec::new();
        encode_v2(1, 1, k as u8, &msg, &mut out);
        out
    }

    #[test]
    fn a_magic_byte_inside_a_damaged_frame_does_not_swallow_good_frames() {
        // A frame whose payload was damaged so that it holds what looks like the header of a
        // 252-byte v2 frame with an unknown id; its CRC no longer matches.
        let mut damaged = attitude_frame(0);
        damaged[10..20].copy_from_slice(&[0xFD, 0xF0, 0, 0, 7, 1, 1, 0xEE, 0xEE, 0x0E]);
        let mut bytes = damaged.clone();
        let good = 12;
        for k in 1..=good {
            bytes.extend(attitude_frame(k));
        }
        assert!(
            bytes.len() > 10 + 252,
            "the fake length must reach into the good frames"
        );
        let mut framer = StreamFramer::default();
        framer.push(&bytes);
        let mut frames = 0;
        while framer.next_frame().is_some() {
            frames += 1;
        }
        assert_eq!(frames, good, "{:?}", framer.counters);
        assert_eq!(framer.counters.bad_crc, 1);
        assert_eq!(framer.counters.unknown_id, 0);
        assert_eq!(framer.counters.skipped_bytes as usize, damaged.len());
    }
}
