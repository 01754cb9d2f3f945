//! tlog reading on real logs (frame counts against pymavlink's, SOURCES.md) and on corrupted
//! copies: everything dropped is counted, nothing panics, the good frames still come through.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::link::{TlogReader, TlogWriter};
use ahcmon::protocol::MavMessage;
use std::collections::BTreeMap;

mod common;
use common::data;

fn read_all(bytes: &[u8]) -> (Vec<(u64, u32)>, ahcmon::protocol::FrameCounters) {
    let mut r = TlogReader::new(bytes);
    let mut out = Vec::new();
    while let Some((ts, f)) = r.next_frame().expect("reading from memory cannot fail") {
        out.push((ts, f.msg_id));
    }
    (out, r.counters)
}

#[test]
fn ardusub_logs_frame_counts_match_pymavlink() {
    // Expected counts from SOURCES.md (pymavlink 2.4.50, 0 bad data).
    for (file, expected) in [
        ("mavlink/rust-mavlink-log.tlog", 1426),
        (
            "mavlink/mavlink-server-00025-2024-04-22_18-49-07.tlog",
            30439,
        ),
    ] {
        let bytes = std::fs::read(data(file)).unwrap();
        let (frames, c) = read_all(&bytes);
        assert_eq!(frames.len(), expected, "{file}: {c}");
        assert_eq!(c.frames, expected as u64);
        assert_eq!(c.resync, 0, "{file}: {c}");
        assert_eq!(c.skipped_bytes, 0, "{file}: {c}");
        assert_eq!(c.dropped(), 0, "{file}: {c}");
    }
}

#[test]
fn sitl_log_message_counts_match_source_md() {
    let bytes = std::fs::read(data(
        "sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog",
    ))
    .unwrap();
    let (frames, c) = read_all(&bytes);
    let mut by_id = BTreeMap::new();
    for (_, id) in &frames {
        *by_id.entry(*id).or_insert(0u32) += 1;
    }
    // SOURCE.md: ATTITUDE 8781, SERVO_OUTPUT_RAW 8781, RAW_IMU 8781, PARAM_VALUE 1032, HEARTBEAT 182.
    assert_eq!(by_id[&30], 8781);
    assert_eq!(by_id[&36], 8781);
    assert_eq!(by_id[&27], 8781);
    assert_eq!(by_id[&22], 1032);
    assert_eq!(by_id[&0], 182);
    assert_eq!(c.dropped(), 0);
}

/// Start offset of every record of a clean log.
fn record_offsets(bytes: &[u8]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < bytes.len() {
        out.push(pos);
        let len = match bytes[pos + 8] {
            0xFE => 8 + bytes[pos + 9] as usize,
            _ => 12 + bytes[pos + 9] as usize + if bytes[pos + 10] & 1 != 0 { 13 } else { 0 },
        };
        pos += 8 + len;
    }
    out
}

fn clean_log() -> Vec<u8> {
    std::fs::read(data("mavlink/rust-mavlink-log.tlog")).unwrap()
}

#[test]
fn flipped_bytes_are_counted_and_the_rest_survives() {
    let mut bytes = clean_log();
    let (good, _) = read_all(&bytes);
    // Flip one byte in every 50th record's payload region (deterministic positions).
    let mut flipped = 0;
    let mut i = 2000;
    while i < bytes.len() {
        bytes[i] ^= 0x5A;
        flipped += 1;
        i += 2003;
    }
    let (frames, c) = read_all(&bytes);
    assert!(c.bad_crc + c.resync > 0, "{c}");
    // Each flip can spoil at most the record it hits (and is found by CRC or resync).
    assert!(
        frames.len() + flipped >= good.len(),
        "{} of {} frames left after {flipped} flips: {c}",
        frames.len(),
        good.len()
    );
    assert!(frames.len() < good.len());
    // What comes through is a subsequence of the clean log's frames, in order (by id: a flip
    // inside a timestamp leaves a good frame with a plausible but wrong time, undetectable).
    let mut it = good.iter();
    let mut ts_changed = 0;
    for f in &frames {
        let g = it.find(|g| g.1 == f.1).expect("frame not in the clean log");
        ts_changed += usize::from(g.0 != f.0);
    }
    assert!(ts_changed <= flipped);
}

#[test]
fn a_garbage_first_timestamp_does_not_become_the_logs_clock() {
    let mut bytes = clean_log();
    let (good, _) = read_all(&bytes);
    // The first record's timestamp: years off.
    bytes[..8].copy_from_slice(&u64::MAX.to_be_bytes());
    let (frames, c) = read_all(&bytes);
    assert_eq!(frames.len(), good.len(), "{c}");
    // The reader held its (garbage) clock for the frames before three agreed on the real
    // one, counted each, then went on with the log's own stamps.
    assert!(c.repaired_ts >= 1 && c.repaired_ts <= 2, "{c}");
    let n = c.repaired_ts as usize + 1;
    assert_eq!(&frames[n..], &good[n..], "{c}");
}

#[test]
fn truncated_tail_is_counted_not_fatal() {
    let bytes = clean_log();
    let (good, _) = read_all(&bytes);
    for cut in [1, 5, 9, 20] {
        let (frames, c) = read_all(&bytes[..bytes.len() - cut]);
        assert_eq!(frames.len(), good.len() - 1, "cut {cut}: {c}");
        assert_eq!(c.truncated, 1, "cut {cut}: {c}");
        assert_eq!(c.bad_crc, 0);
    }
}

#[test]
fn random_garbage_appended_and_inserted_is_skipped() {
    let bytes = clean_log();
    let (good, _) = read_all(&bytes);
    // xorshift noise, with magic bytes sprinkled in to provoke false starts
    let mut state = 0x9E3779B97F4A7C15u64;
    let mut noise = Vec::new();
    for k in 0..5000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        noise.push(if k % 97 == 0 { 0xFD } else { state as u8 });
    }
    // a record boundary: the offset after the first 100 records
    let mid = record_offsets(&bytes)[100];
    let mut corrupt = bytes[..mid].to_vec();
    corrupt.extend_from_slice(&noise);
    corrupt.extend_from_slice(&bytes[mid..]);
    corrupt.extend_from_slice(&noise);
    let (frames, c) = read_all(&corrupt);
    assert_eq!(frames, good, "{c}");
    assert!(c.resync >= 2, "{c}");
    assert!(c.skipped_bytes >= 2 * noise.len() as u64 - 600, "{c}");
}

#[test]
fn unknown_ids_are_skipped_whole() {
    // Re-write the clean log, turning every HEARTBEAT's id into 60000 (not in any dialect):
    // each such record must be skipped whole and counted, the rest must come through.
    let bytes = clean_log();
    let (good, _) = read_all(&bytes);
    let mut out = Vec::new();
    let mut changed = 0;
    let offsets = record_offsets(&bytes);
    for (k, &pos) in offsets.iter().enumerate() {
        let end = offsets.get(k + 1).copied().unwrap_or(bytes.len());
        let mut rec = bytes[pos..end].to_vec();
        let id = u32::from(rec[15]) | u32::from(rec[16]) << 8 | u32::from(rec[17]) << 16;
        if id == 0 {
            rec[15] = (60000u32 & 0xFF) as u8;
            rec[16] = (60000u32 >> 8) as u8;
            changed += 1;
        }
        out.extend_from_slice(&rec);
    }
    let (frames, c) = read_all(&out);
    assert!(changed > 5);
    assert_eq!(c.unknown_id, changed, "{c}");
    assert_eq!(c.resync, 0, "{c}");
    assert_eq!(frames.len() as u64, good.len() as u64 - changed);
}

#[test]
fn writer_round_trips_through_the_reader() {
    use ahcmon::protocol::dialects::ahcmon::{ATTITUDE_DATA, SERVO_OUTPUT_RAW_DATA};
    let mut buf = Vec::new();
    {
        let mut w = TlogWriter::new(&mut buf);
        for k in 0..100u32 {
            let ts = 1_700_000_000_000_000 + u64::from(k) * 20_000;
            let att = ATTITUDE_DATA {
                time_boot_ms: k * 20,
                rollspeed: k as f32 * 0.01,
                ..Default::default()
            };
            w.write(ts, 1, 1, &MavMessage::ATTITUDE(att)).unwrap();
            let servo = SERVO_OUTPUT_RAW_DATA {
                time_usec: k * 20_000,
                servo1_raw: 1500,
                servo9_raw: 1234,
                ..Default::default()
            };
            w.write(ts, 1, 1, &MavMessage::SERVO_OUTPUT_RAW(servo))
                .unwrap();
        }
        w.flush().unwrap();
    }
    let mut r = TlogReader::new(&buf[..]);
    let mut n = 0;
    while let Some((ts, f)) = r.next_frame().unwrap() {
        assert_eq!(ts, 1_700_000_000_000_000 + (n / 2) * 20_000);
        if let MavMessage::SERVO_OUTPUT_RAW(s) = f.msg {
            assert_eq!(s.servo9_raw, 1234);
        }
        n += 1;
    }
    assert_eq!(n, 200);
    assert_eq!(r.counters.dropped(), 0);
}
