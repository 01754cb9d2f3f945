//! MAVLink 2 message signing (<https://mavlink.io/en/guide/message_signing.html>): a signed
//! frame carries a link id, a 48-bit timestamp (10 µs since 2015-01-01) and the first 6 bytes
//! of `SHA-256(secret_key ‖ frame up to and with the timestamp)`. With a key, only frames
//! signed with it pass: unsigned ones, bad signatures and a timestamp not newer than the last
//! one of the same stream (link id, system, component: a replayed frame) are dropped and
//! counted. No wall clock is consulted, so a signed log replays as it was recorded.

use sha2::{Digest, Sha256};
use std::collections::HashMap;

/// `incompat_flags` bit of a signed frame.
const IFLAG_SIGNED: u8 = 0x01;
const SIGNATURE_LEN: usize = 13;
/// Streams remembered (link id × system × component); a sender past it restarts the oldest
/// map, so a flood of made-up ids cannot grow the state.
const MAX_STREAMS: usize = 4096;

/// What the check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Signed,
    Unsigned,
    BadSignature,
    /// A good signature whose timestamp is not newer than its stream's last.
    Replayed,
}

/// Why a key file is not a key.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct KeyError(String);

/// A secret key and the streams' last timestamps.
#[derive(Clone)]
pub struct Signing {
    key: [u8; 32],
    last: HashMap<(u8, u8, u8), u64>,
}

impl std::fmt::Debug for Signing {
    // Never the key.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Signing {{ streams: {} }}", self.last.len())
    }
}

impl Signing {
    pub fn new(key: [u8; 32]) -> Self {
        Self {
            key,
            last: HashMap::new(),
        }
    }

    /// A key file's contents: 32 raw bytes, 64 hexadecimal digits, or a passphrase (one line),
    /// whose SHA-256 is the key as MAVProxy's `signing setup` and Mission Planner make it.
    pub fn key_from_file_contents(bytes: &[u8]) -> Result<[u8; 32], KeyError> {
        if bytes.len() == 32 && std::str::from_utf8(bytes).is_err() {
            let mut key = [0u8; 32];
            key.copy_from_slice(bytes);
            return Ok(key);
        }
        let text = std::str::from_utf8(bytes)
            .map_err(|_| KeyError("neither 32 raw bytes nor text".into()))?
            .trim();
        if text.is_empty() {
            return Err(KeyError("empty".into()));
        }
        if text.len() == 64 && text.chars().all(|c| c.is_ascii_hexdigit()) {
            let mut key = [0u8; 32];
            for (i, k) in key.iter_mut().enumerate() {
                *k = u8::from_str_radix(&text[2 * i..2 * i + 2], 16)
                    .map_err(|e| KeyError(e.to_string()))?;
            }
            return Ok(key);
        }
        if text.contains('\n') {
            return Err(KeyError(
                "more than one line: give 64 hexadecimal digits or one passphrase".into(),
            ));
        }
        Ok(Sha256::digest(text.as_bytes()).into())
    }

    /// Check one whole frame (`frame` starts at its magic byte and is `frame_len` long).
    /// MAVLink 1 frames cannot be signed.
    pub fn check(&mut self, frame: &[u8]) -> Verdict {
        let signed = frame.len() > 10 + SIGNATURE_LEN
            && frame[0] == super::frame::MAGIC_V2
            && frame[2] & IFLAG_SIGNED != 0;
        if !signed {
            return Verdict::Unsigned;
        }
        let body = frame.len() - 6;
        let digest = Sha256::new()
            .chain_update(self.key)
            .chain_update(&frame[..body])
            .finalize();
        if digest[..6] != frame[body..] {
            return Verdict::BadSignature;
        }
        let link_id = frame[frame.len() - SIGNATURE_LEN];
        let mut ts = [0u8; 8];
        ts[..6].copy_from_slice(&frame[body - 6..body]);
        let timestamp = u64::from_le_bytes(ts);
        let stream = (link_id, frame[5], frame[6]);
        if self
            .last
            .get(&stream)
            .is_some_and(|&last| timestamp <= last)
        {
            return Verdict::Replayed;
        }
        if self.last.len() >= MAX_STREAMS && !self.last.contains_key(&stream) {
            self.last.clear();
        }
        self.last.insert(stream, timestamp);
        Verdict::Signed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame signed as the spec says, built here independently of `check`.
    fn signed(key: &[u8; 32], timestamp: u64, payload: &[u8]) -> Vec<u8> {
        let mut f = vec![
            super::super::frame::MAGIC_V2,
            payload.len() as u8,
            IFLAG_SIGNED,
            0,
        ];
        f.extend_from_slice(&[9, 1, 1, 0, 0, 0]); // seq, sysid, compid, msgid 0
        f.extend_from_slice(payload);
        f.extend_from_slice(&[0xAA, 0xBB]); // the CRC is not the signature's business
        f.push(3); // link id
        f.extend_from_slice(&timestamp.to_le_bytes()[..6]);
        let mut h = Sha256::new();
        h.update(key);
        h.update(&f);
        let d = h.finalize();
        f.extend_from_slice(&d[..6]);
        f
    }

    #[test]
    fn only_frames_signed_with_the_key_and_newer_pass() {
        let key = [7u8; 32];
        let mut s = Signing::new(key);
        assert_eq!(s.check(&signed(&key, 100, &[1, 2, 3])), Verdict::Signed);
        assert_eq!(s.check(&signed(&key, 101, &[1, 2, 3])), Verdict::Signed);
        assert_eq!(s.check(&signed(&key, 101, &[1, 2, 3])), Verdict::Replayed);
        assert_eq!(
            s.check(&signed(&[8u8; 32], 200, &[1, 2, 3])),
            Verdict::BadSignature
        );
        let mut tampered = signed(&key, 300, &[1, 2, 3]);
        tampered[10] ^= 1;
        assert_eq!(s.check(&tampered), Verdict::BadSignature);
        let mut unsigned = signed(&key, 400, &[1, 2, 3]);
        unsigned[2] = 0;
        unsigned.truncate(unsigned.len() - SIGNATURE_LEN);
        assert_eq!(s.check(&unsigned), Verdict::Unsigned);
    }

    #[test]
    fn key_files_hold_raw_bytes_hex_or_a_passphrase() {
        let raw: Vec<u8> = (0..32u8).map(|b| b | 0x80).collect();
        assert_eq!(Signing::key_from_file_contents(&raw).unwrap().to_vec(), raw);
        let hex: String = raw.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(
            Signing::key_from_file_contents(format!("{hex}\n").as_bytes())
                .unwrap()
                .to_vec(),
            raw
        );
        let from_phrase = Signing::key_from_file_contents(b"correct horse\n").unwrap();
        assert_eq!(
            from_phrase,
            <[u8; 32]>::from(Sha256::digest(b"correct horse"))
        );
        assert!(Signing::key_from_file_contents(b"  \n").is_err());
        assert!(Signing::key_from_file_contents(b"a\nb").is_err());
    }
}
