//! `.tlog` files: each record is an 8-byte big-endian count of µs since the Unix epoch, then
//! one raw MAVLink v1 or v2 frame (signed frames too).
//!
//! The reader streams (memory stays flat in the file's length), never panics on bad bytes,
//! and counts everything it drops: on a bad magic or CRC it slides byte by byte (`resync`,
//! `bad_crc`); a well-formed frame with an id our dialect does not know is skipped whole
//! (`unknown_id`) — sliding into it would lose the frames after it (its length is known);
//! a record cut off by the end of the file is `truncated`.

use crate::output::file::OutputFile;
use crate::protocol::MavMessage;
use crate::protocol::frame::{
    Frame, FrameCounters, MAGIC_V1, MAGIC_V2, Parsed, encode_v2, frame_len, parse,
};
use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::path::Path;

const CHUNK: usize = 64 * 1024;
/// Two records more than a day apart cannot be neighbours in one log: such a "timestamp" is
/// garbage met while resynchronising.
const MAX_TS_JUMP_US: u64 = 86_400_000_000;
/// Good frames in a row that move the reader's clock to theirs.
const REANCHOR_FRAMES: u32 = 3;
/// An input that is no regular file (a device, a pipe) with no good frame in this many bytes
/// is no telemetry log: an endless one (`/dev/zero`) would be read until stopped. A regular
/// file is read to its end, so a log with a long damaged head (a recovered card) is still read.
pub const MAX_BYTES_BEFORE_FIRST_FRAME: u64 = 1 << 20;

pub struct TlogReader<R: Read> {
    src: R,
    buf: Vec<u8>,
    pos: usize,
    eof: bool,
    syncing: bool,
    tail_cut: bool,
    last_ts: Option<u64>,
    /// A clock that good frames keep agreeing on while it disagrees with `last_ts`: its last
    /// stamp and how many frames in a row.
    ts_candidate: Option<(u64, u32)>,
    /// Bytes dropped from the front of `buf` so far (for progress).
    base: u64,
    pub counters: FrameCounters,
    /// With a key, only frames signed with it pass (`protocol::signing`).
    pub signing: Option<crate::protocol::signing::Signing>,
    /// Stop after this many bytes with no good frame (`None`: read to the end).
    pub give_up_after: Option<u64>,
    /// The reader stopped: `give_up_after` bytes read and no good frame in them.
    pub gave_up: bool,
}

impl TlogReader<File> {
    pub fn open(path: &Path) -> io::Result<Self> {
        let file = File::open(path)?;
        let regular = file.metadata()?.is_file();
        let mut reader = Self::new(file);
        if regular {
            reader.give_up_after = None;
        }
        Ok(reader)
    }
}

impl<R: Read> TlogReader<R> {
    pub fn new(src: R) -> Self {
        Self {
            src,
            buf: Vec::with_capacity(2 * CHUNK),
            pos: 0,
            eof: false,
            syncing: false,
            tail_cut: false,
            last_ts: None,
            ts_candidate: None,
            base: 0,
            counters: FrameCounters::default(),
            signing: None,
            give_up_after: Some(MAX_BYTES_BEFORE_FIRST_FRAME),
            gave_up: false,
        }
    }

    /// Bytes of the input consumed so far.
    pub fn position(&self) -> u64 {
        self.base + self.pos as u64
    }

    fn fill(&mut self) -> io::Result<()> {
        if self.pos > 0 {
            self.base += self.pos as u64;
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        let start = self.buf.len();
        self.buf.resize(start + CHUNK, 0);
        let n = loop {
            match self.src.read(&mut self.buf[start..]) {
                Ok(n) => break n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.buf.truncate(start);
                    return Err(e);
                }
            }
        };
        self.buf.truncate(start + n);
        if n == 0 {
            self.eof = true;
        }
        Ok(())
    }

    fn slide(&mut self) {
        if !self.syncing {
            self.counters.resync += 1;
            self.syncing = true;
        }
        self.counters.skipped_bytes += 1;
        self.pos += 1;
    }

    /// A good frame's timestamp: kept when plausible against the clock; otherwise the clock's
    /// (counted as repaired), until `REANCHOR_FRAMES` good frames in a row agree on the new
    /// one (the first record's stamp was the garbage, or the logger's clock was set): then
    /// the log goes on with it.
    fn checked_ts(&mut self, ts: u64) -> u64 {
        if self.plausible_ts(ts) {
            self.ts_candidate = None;
            self.last_ts = Some(ts);
            return ts;
        }
        let agreeing = match self.ts_candidate {
            Some((c, n)) if ts.abs_diff(c) <= MAX_TS_JUMP_US => n + 1,
            _ => 1,
        };
        if agreeing >= REANCHOR_FRAMES {
            self.ts_candidate = None;
            self.last_ts = Some(ts);
            return ts;
        }
        self.ts_candidate = Some((ts, agreeing));
        self.counters.repaired_ts += 1;
        self.last_ts.unwrap_or(ts)
    }

    fn plausible_ts(&self, ts: u64) -> bool {
        self.last_ts
            .is_none_or(|last| ts.abs_diff(last) <= MAX_TS_JUMP_US)
    }

    /// Does a plausible record start at `at` (or does the input end exactly there)?
    fn record_starts_at(&self, at: usize) -> bool {
        let b = &self.buf[at.min(self.buf.len())..];
        if b.is_empty() {
            return true;
        }
        if b.len() < 9 {
            return self.eof;
        }
        let ts = u64::from_be_bytes(b[..8].try_into().unwrap_or([0; 8]));
        (b[8] == MAGIC_V1 || b[8] == MAGIC_V2) && self.plausible_ts(ts)
    }

    /// The next record: (timestamp µs, frame). `Ok(None)` at the end of the input.
    pub fn next_frame(&mut self) -> io::Result<Option<(u64, Frame)>> {
        loop {
            let refused = self.counters.unsigned + self.counters.bad_signature;
            if self.counters.frames + refused == 0
                && self.give_up_after.is_some_and(|n| self.position() > n)
            {
                self.gave_up = true;
                return Ok(None);
            }
            let avail = self.buf.len() - self.pos;
            // Enough for the timestamp, the longest frame and the next record's head.
            if avail < 8 + crate::protocol::frame::MAX_FRAME + 9 && !self.eof {
                self.fill()?;
                continue;
            }
            if avail < 9 {
                if avail > 0 {
                    self.counters.skipped_bytes += avail as u64;
                    self.tail_cut = true;
                    self.pos = self.buf.len();
                }
                if self.tail_cut {
                    self.counters.truncated += 1;
                    self.tail_cut = false;
                }
                return Ok(None);
            }
            let rec = &self.buf[self.pos..];
            let ts = u64::from_be_bytes(rec[..8].try_into().unwrap_or([0; 8]));
            match parse(&rec[8..]) {
                Parsed::Frame(f, n) => {
                    let verdict = self.signing.as_mut().map(|s| s.check(&rec[8..8 + n]));
                    self.pos += 8 + n;
                    self.syncing = false;
                    self.tail_cut = false;
                    if crate::protocol::frame::count_unsigned(&mut self.counters, verdict) {
                        continue;
                    }
                    let ts = self.checked_ts(ts);
                    self.counters.frames += 1;
                    return Ok(Some((ts, *f)));
                }
                Parsed::UnknownId(n) => {
                    // No CRC_EXTRA to check it with: accept the skip only if it lands on
                    // another record (or the end), else it is corruption.
                    if self.plausible_ts(ts) && self.record_starts_at(self.pos + 8 + n) {
                        self.pos += 8 + n;
                        self.syncing = false;
                        self.counters.unknown_id += 1;
                        self.last_ts = Some(ts);
                    } else {
                        self.slide();
                    }
                }
                Parsed::ParseError(n) => {
                    self.pos += 8 + n;
                    self.counters.parse_error += 1;
                }
                Parsed::Incomplete(_) => {
                    // Only at the end of the input (we filled before): a cut-off record, or a
                    // corrupt length byte; look for anything after it.
                    self.tail_cut = true;
                    self.slide();
                }
                Parsed::BadCrc => {
                    self.counters.bad_crc += 1;
                    self.slide();
                }
                Parsed::BadMagic => self.slide(),
            }
        }
    }
}

/// Writes records that pymavlink's `mavutil.mavlink_connection(path)` loads.
pub struct TlogWriter<W: Write> {
    out: W,
    frame: Vec<u8>,
    seq: [u8; 256],
    pub records: u64,
}

impl TlogWriter<BufWriter<OutputFile>> {
    /// The tlog at `path` (`-`: standard output), replaced when its first record is written.
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(Self::new(BufWriter::new(OutputFile::open(path)?)))
    }
}

impl<W: Write> TlogWriter<W> {
    pub fn new(out: W) -> Self {
        Self {
            out,
            frame: Vec::with_capacity(crate::protocol::frame::MAX_FRAME),
            seq: [0; 256],
            records: 0,
        }
    }

    /// One record: `ts_us` (µs since the Unix epoch), the message as a v2 frame with a
    /// per-system sequence number.
    pub fn write(&mut self, ts_us: u64, sysid: u8, compid: u8, msg: &MavMessage) -> io::Result<()> {
        let seq = &mut self.seq[sysid as usize];
        encode_v2(sysid, compid, *seq, msg, &mut self.frame);
        *seq = seq.wrapping_add(1);
        let frame = std::mem::take(&mut self.frame);
        let res = self.write_raw(ts_us, &frame);
        self.frame = frame;
        res
    }

    /// One record from an already encoded frame.
    pub fn write_raw(&mut self, ts_us: u64, frame: &[u8]) -> io::Result<()> {
        debug_assert!(matches!(frame_len(frame), Some(Ok(n)) if n == frame.len()));
        self.out.write_all(&ts_us.to_be_bytes())?;
        self.out.write_all(frame)?;
        self.records += 1;
        Ok(())
    }

    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }
}
