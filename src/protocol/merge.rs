//! Several links into one monitor (two radios to one vehicle, a serial link beside a UDP
//! forward): a frame another link has already delivered is dropped, so a vehicle heard on two
//! links is one stream, each link filling the other's losses.
//!
//! **Copy.** A frame is a copy when a frame with the same system id, component id, sequence
//! number, message id and payload came in on *another* link within [`COPY_WINDOW_S`]. The
//! sender numbers its frames per component, so the two links' copies of one frame agree on
//! all five; two different frames agree on all five only when a component sends the same
//! payload again 256·k frames later inside the window, a repeat that carries nothing new. A
//! repeat on the *same* link is not dropped here: it is that link's own duplicate, and the
//! monitor counts it (`contaminated`).
//!
//! **Two sources.** Redundant links share most frames; two vehicles with one system id on two
//! links share only the frames that happen to be equal (both at rest, a constant message;
//! 1.5 % between a simulated helicopter and quad). A component's frames are counted in blocks
//! of [`SOURCES_BLOCK`] while two links deliver it within [`TWO_SOURCES_WITHIN_S`] of each
//! other; a block with under [`MIN_COPY_SHARE`] copies is two sources, said once per system id
//! ([`Merger::take_two_sources`]). Two links losing p₁ and p₂ of the frames give a copy share
//! of (1-p₁)(1-p₂) / ((1-p₁)+(1-p₂)): 40 % at a fifth lost on each, 5 % only at 90 % lost on
//! both.
//!
//! Memory is bounded: the frames of the last [`COPY_WINDOW_S`] are kept as 8-byte keys, at most
//! [`MAX_RECENT`] of them (older ones evicted first, counted).

use super::Frame;
use mavlink_core::Message as _;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::hash::{Hash, Hasher};

/// How long a delivered frame is remembered for its copies (s): links to one vehicle differ
/// in delay by tens of ms (a radio against a network forward); half a second covers that with
/// room.
pub const COPY_WINDOW_S: f64 = 0.5;
/// Keys kept at most: 0.5 s of 100,000 frames a second.
pub const MAX_RECENT: usize = 50_000;
/// A component heard on two links within this (s) is heard on both at once.
pub const TWO_SOURCES_WITHIN_S: f64 = 1.0;
/// Frames of a component, received while two links deliver it, judged together.
pub const SOURCES_BLOCK: u32 = 1000;
/// Under this share of copies in a block: two sources.
pub const MIN_COPY_SHARE: f64 = 0.05;

/// What became of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// First delivery: on to the monitor.
    New,
    /// Another link delivered it already: dropped.
    Copy,
}

/// Per component: when each link last delivered a frame of it; the frames and copies of the
/// block under way, received while two links were delivering.
#[derive(Debug, Default)]
struct Component {
    last_on: BTreeMap<usize, f64>,
    frames: u32,
    copies: u32,
}

#[derive(Debug, Default)]
pub struct Merger {
    /// Frame key → (arrival time, link).
    recent: HashMap<u64, (f64, usize)>,
    /// The keys in arrival order, for expiry.
    order: VecDeque<(f64, u64)>,
    components: HashMap<(u8, u8), Component>,
    told: BTreeSet<u8>,
    two_sources: Vec<(u8, String)>,
    payload: Vec<u8>,
    /// Frames dropped as copies of another link's, per link.
    pub copies: BTreeMap<usize, u64>,
    /// Keys evicted before their window ended (more than [`MAX_RECENT`] frames in it).
    pub evicted: u64,
}

impl Merger {
    /// Frame `f` arrived on link `link` at `now` (s, any monotonic clock).
    pub fn accept(&mut self, f: &Frame, link: usize, now: f64) -> Verdict {
        while let Some(&(t, key)) = self.order.front() {
            if now - t <= COPY_WINDOW_S {
                break;
            }
            self.order.pop_front();
            if self.recent.get(&key).is_some_and(|&(at, _)| at == t) {
                self.recent.remove(&key);
            }
        }
        let key = self.key(f);
        let copy = matches!(self.recent.get(&key), Some(&(_, from)) if from != link);
        let c = self.components.entry((f.sysid, f.compid)).or_default();
        c.last_on.insert(link, now);
        let both = c
            .last_on
            .iter()
            .any(|(&l, &t)| l != link && now - t <= TWO_SOURCES_WITHIN_S);
        if both {
            c.frames += 1;
            c.copies += u32::from(copy);
        }
        if c.frames == SOURCES_BLOCK {
            let share = f64::from(c.copies) / f64::from(c.frames);
            (c.frames, c.copies) = (0, 0);
            if share < MIN_COPY_SHARE && self.told.insert(f.sysid) {
                let links: Vec<String> = c.last_on.keys().map(|l| format!("#{}", l + 1)).collect();
                self.two_sources.push((
                    f.sysid,
                    format!(
                        "system {} (component {}) arrives on links {} at once with {:.1} % of its frames in common (redundant links share most): two vehicles with one system id",
                        f.sysid,
                        f.compid,
                        links.join(" and "),
                        100.0 * share
                    ),
                ));
            }
        }
        if copy {
            *self.copies.entry(link).or_default() += 1;
            return Verdict::Copy;
        }
        // The same key again on the same link keeps its newest arrival; the older entry in
        // `order` then expires without removing it.
        self.recent.insert(key, (now, link));
        self.order.push_back((now, key));
        while self.order.len() > MAX_RECENT {
            if let Some((t, old)) = self.order.pop_front()
                && self.recent.get(&old).is_some_and(|&(at, _)| at == t)
            {
                self.recent.remove(&old);
                self.evicted += 1;
            }
        }
        Verdict::New
    }

    /// System ids found to come from two sources since last asked, with what to tell.
    pub fn take_two_sources(&mut self) -> Vec<(u8, String)> {
        std::mem::take(&mut self.two_sources)
    }

    /// All frames dropped as copies.
    pub fn copies_total(&self) -> u64 {
        self.copies.values().sum()
    }

    fn key(&mut self, f: &Frame) -> u64 {
        self.payload.resize(255, 0);
        let n = f
            .msg
            .ser(mavlink_core::MavlinkVersion::V2, &mut self.payload);
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (f.sysid, f.compid, f.seq, f.msg_id).hash(&mut h);
        self.payload[..n].hash(&mut h);
        h.finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::MavMessage;
    use crate::protocol::dialects::ahcmon::ATTITUDE_DATA;

    fn frame(sysid: u8, seq: u8, roll: f32) -> Frame {
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: u32::from(seq),
            roll,
            ..Default::default()
        });
        Frame {
            version: mavlink_core::MavlinkVersion::V2,
            sysid,
            compid: 1,
            seq,
            msg_id: 30,
            msg,
        }
    }

    /// Brute force: a frame is a copy exactly when the newest delivered (not dropped) equal
    /// frame, all five fields equal, came in on another link within the window.
    #[test]
    fn copies_are_exactly_the_equal_frames_of_other_links_within_the_window() {
        let mut m = Merger::default();
        let mut seen: Vec<(f64, usize, u8, u8, f32)> = Vec::new();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut t = 0.0;
        for _ in 0..5_000 {
            t += (next() % 100) as f64 * 1e-3;
            let (link, sysid, seq) = (
                (next() % 3) as usize,
                (next() % 2) as u8,
                (next() % 8) as u8,
            );
            let roll = (next() % 3) as f32;
            // The newest delivery of an equal frame decides.
            let want_copy = seen
                .iter()
                .rev()
                .find(|&&(_, _, s, q, r)| s == sysid && q == seq && r == roll)
                .is_some_and(|&(at, l, ..)| t - at <= COPY_WINDOW_S && l != link);
            let got = m.accept(&frame(sysid, seq, roll), link, t);
            assert_eq!(
                got == Verdict::Copy,
                want_copy,
                "t {t} link {link} seq {seq}"
            );
            if got == Verdict::New {
                seen.push((t, link, sysid, seq, roll));
            }
        }
        assert!(m.copies_total() > 100, "{} copies", m.copies_total());
    }

    #[test]
    fn two_lossy_copies_of_one_stream_are_one_stream() {
        let mut m = Merger::default();
        let (mut delivered, mut both) = (0, 0);
        for k in 0..10_000u32 {
            let f = frame(1, k as u8, k as f32);
            let t = f64::from(k) * 0.002;
            // Link 0 loses every 5th frame, link 1 every 3rd, 20 ms later.
            let on0 = k % 5 != 0;
            let on1 = k % 3 != 0;
            let mut new = 0;
            if on0 && m.accept(&f, 0, t) == Verdict::New {
                new += 1;
            }
            if on1 && m.accept(&f, 1, t + 0.02) == Verdict::New {
                new += 1;
            }
            assert_eq!(new, usize::from(on0 || on1), "frame {k}");
            delivered += new;
            both += usize::from(on0 && on1);
        }
        assert_eq!(m.copies_total(), both as u64);
        assert_eq!(delivered, 10_000 - 10_000 / 15 - 1);
        assert!(m.take_two_sources().is_empty());
    }

    #[test]
    fn one_system_id_from_two_vehicles_on_two_links_is_told_once() {
        let mut m = Merger::default();
        for k in 0..1_000u32 {
            let t = f64::from(k) * 0.01;
            assert_eq!(m.accept(&frame(7, k as u8, 1.0), 0, t), Verdict::New);
            assert_eq!(m.accept(&frame(7, k as u8, 2.0), 1, t), Verdict::New);
        }
        let told = m.take_two_sources();
        assert_eq!(told.len(), 1, "{told:?}");
        assert!(told[0].1.contains("links #1 and #2"), "{}", told[0].1);
        assert!(m.take_two_sources().is_empty());
    }

    #[test]
    fn memory_stays_bounded() {
        let mut m = Merger::default();
        for k in 0..(2 * MAX_RECENT as u32) {
            m.accept(&frame(1, k as u8, k as f32), 0, 0.0);
        }
        assert!(m.recent.len() <= MAX_RECENT && m.order.len() <= MAX_RECENT);
        assert_eq!(m.evicted, MAX_RECENT as u64);
    }
}
