//! Which kind of log a file is, told by its first bytes (never by its name), and what a
//! reader of a vehicle's own log reports.

use crate::protocol::FrameCounters;
use std::io::Read;

/// A log's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// A ground station's telemetry log: 8-byte timestamps and MAVLink frames.
    Tlog,
    /// ArduPilot's on-board log (`.bin`): starts with a FMT message, `A3 95 80`.
    DataFlash,
    /// PX4's on-board log (`.ulg`): starts with `ULog` and its magic.
    ULog,
}

impl LogFormat {
    pub fn name(self) -> &'static str {
        match self {
            LogFormat::Tlog => "MAVLink telemetry log",
            LogFormat::DataFlash => "ArduPilot DataFlash log",
            LogFormat::ULog => "PX4 ULog",
        }
    }
}

const ULOG_MAGIC: [u8; 7] = [b'U', b'L', b'o', b'g', 0x01, 0x12, 0x35];

/// The format of a log from its first bytes: DataFlash and ULog have magic numbers; anything
/// else is read as a tlog, whose reader says plainly when it holds no MAVLink frame.
pub fn sniff(mut input: impl Read) -> std::io::Result<LogFormat> {
    let mut head = [0u8; 8];
    let mut n = 0;
    while n < head.len() {
        match input.read(&mut head[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(if n >= 7 && head[..7] == ULOG_MAGIC {
        LogFormat::ULog
    } else if n >= 3 && head[..3] == [0xA3, 0x95, 0x80] {
        LogFormat::DataFlash
    } else {
        LogFormat::Tlog
    })
}

/// What reading a vehicle's own log gave: the counters in the tlog reader's terms (`frames`
/// are the log's messages), the bytes read, and notes to tell the user.
#[derive(Debug, Clone, Default)]
pub struct LogReport {
    pub counters: FrameCounters,
    pub bytes: u64,
    pub notes: Vec<String>,
    /// The on-board logger's own dropouts (it could not write fast enough), and their length.
    pub dropouts: u64,
    pub dropout_ms: u64,
}

impl LogReport {
    pub(super) fn note_dropout(&mut self, ms: u16) {
        self.dropouts += 1;
        self.dropout_ms += u64::from(ms);
    }
}

#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("no message could be read: not a complete log of this kind")]
    Empty,
    #[error("{0}")]
    Malformed(String),
}

/// One item of a log, in the log's order: a telemetry log's MAVLink frame, or a record of a
/// vehicle's own log (its one vehicle's, on its own clock).
pub enum LogItem<'a> {
    Frame(&'a crate::protocol::Frame),
    Record(&'a crate::telemetry::Record),
}

/// Any log, its format told by content, item by item; `at` is told the bytes read so far
/// (for progress). A telemetry log's report carries its reader's counters and size.
pub fn read_log(
    path: &std::path::Path,
    each: &mut dyn FnMut(LogItem<'_>),
    at: &mut dyn FnMut(u64),
) -> Result<(LogFormat, LogReport), LogError> {
    let format = sniff(std::fs::File::open(path)?)?;
    let report = match format {
        LogFormat::Tlog => {
            let mut reader = super::TlogReader::open(path)?;
            while let Some((_, frame)) = reader.next_frame()? {
                each(LogItem::Frame(&frame));
                at(reader.position());
            }
            LogReport {
                counters: reader.counters,
                bytes: reader.position(),
                ..LogReport::default()
            }
        }
        LogFormat::DataFlash => super::dataflash::read(
            std::io::BufReader::new(std::fs::File::open(path)?),
            &mut |r| each(LogItem::Record(r)),
            at,
        )?,
        LogFormat::ULog => super::ulog::read(path, &mut |r| each(LogItem::Record(r)))?,
    };
    Ok((format, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_format_is_told_by_content() {
        assert_eq!(
            sniff(&b"ULog\x01\x12\x35\x01rest"[..]).ok(),
            Some(LogFormat::ULog)
        );
        assert_eq!(
            sniff(&[0xA3, 0x95, 0x80, 0x80, 89][..]).ok(),
            Some(LogFormat::DataFlash)
        );
        assert_eq!(sniff(&[0u8, 5, 1][..]).ok(), Some(LogFormat::Tlog));
        assert_eq!(sniff(&[][..]).ok(), Some(LogFormat::Tlog));
    }
}
