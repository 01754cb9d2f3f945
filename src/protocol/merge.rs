//! Several links into one monitor that carry the *same frames* by two paths: a vehicle port
//! split to two radios, a forward (mavlink-router, MAVProxy `--out`) beside the radio it
//! forwards. A frame another link has already delivered is dropped, so each link fills the
//! other's gaps. (Two ports of one autopilot are not that: each port numbers and times its
//! own frames, so no frame is a copy; see *Two sources*.)
//!
//! **Copy.** A frame is a copy when a frame with the same system id, component id, sequence
//! number, message id and payload came in on *another* link within [`COPY_WINDOW_S`]. The
//! sender numbers its frames per component and port, so the two paths' copies of one frame
//! agree on all five; two different frames agree on all five only when a component sends the
//! same payload again 256·k frames later inside the window, a repeat that carries nothing
//! new. The payload is compared as MAVLink 2 serialises it, so a v1 and a v2 copy match.
//!
//! **Late.** A frame no link delivered before is still dropped when a *newer* frame of its
//! component came in on another link: by sequence number (ahead by 1-127, half the wrap), or,
//! for the messages that carry the vehicle's clock (ATTITUDE, SERVO_OUTPUT_RAW, RAW_IMU,
//! HIGHRES_IMU, ACTUATOR_OUTPUT_STATUS), by that stamp against the newest of its message, which
//! holds for a path any number of frames behind. The filters step forward in time and would
//! drop such a frame as out of order, and counted there it would read as a mixed stream. So a
//! gap is filled when the other path's copy comes before the sender's next frame. A link's own
//! reordering (the newest frame was its own) is left to the monitor to count, as with one
//! link.
//!
//! **Two sources.** Two paths of one stream share most frames: losing p₁ and p₂ of them, a
//! share (1-p₁)(1-p₂) / ((1-p₁)+(1-p₂)) of what arrives is copies, 40 % at a fifth lost on
//! each and 5 % only at 90 % lost on both. Two vehicles with one system id, or two ports of
//! one autopilot, share only frames that happen to be equal (3.2 % between a simulated
//! helicopter and quad at rest and flying). A component's frames are judged in blocks of
//! [`SOURCES_BLOCK`] received while two links deliver it (within [`TWO_SOURCES_WITHIN_S`] of
//! each other); a block with under [`MIN_COPY_SHARE`] copies is said once per system id
//! ([`Merger::take_two_sources`]).
//!
//! Memory is bounded: the frames of the last [`COPY_WINDOW_S`] are kept as 8-byte keys, at most
//! [`MAX_RECENT`] of them (older ones evicted first, counted).

use super::Frame;
use mavlink_core::Message as _;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::hash::{Hash, Hasher};

/// How long a delivered frame is remembered for its copies (s): paths to one vehicle differ
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
    /// Another link delivered a newer frame of its component already: dropped.
    Late,
}

/// A message's stamp on the vehicle's clock, as sent (wrapping u32 or u64).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stamp {
    Wrapping(u32),
    Wide(u64),
}

impl Stamp {
    fn of(msg: &super::MavMessage) -> Option<Self> {
        use super::MavMessage as M;
        Some(match msg {
            M::ATTITUDE(m) => Stamp::Wrapping(m.time_boot_ms),
            M::SERVO_OUTPUT_RAW(m) => Stamp::Wrapping(m.time_usec),
            M::RAW_IMU(m) => Stamp::Wide(m.time_usec),
            M::HIGHRES_IMU(m) => Stamp::Wide(m.time_usec),
            M::ACTUATOR_OUTPUT_STATUS(m) => Stamp::Wide(m.time_usec),
            _ => return None,
        })
    }

    /// Not after `newest` (a u32 stamp within half its wrap).
    fn not_after(self, newest: Stamp) -> bool {
        match (self, newest) {
            (Stamp::Wrapping(s), Stamp::Wrapping(n)) => n.wrapping_sub(s) < 1 << 31,
            (Stamp::Wide(s), Stamp::Wide(n)) => s <= n,
            _ => false,
        }
    }
}

/// Per component: when each link last delivered a frame of it; the newest sequence number
/// passed on and its link; per stamped message id the newest stamp passed on and its link; the
/// frames and copies of the block under way, received while two links were delivering.
#[derive(Debug, Default)]
struct Component {
    last_on: BTreeMap<usize, f64>,
    newest: Option<(u8, usize)>,
    stamps: Vec<(u32, Stamp, usize)>,
    frames: u32,
    copies: u32,
}

#[derive(Debug, Default)]
pub struct Merger {
    /// The links' names, for what is said.
    names: Vec<String>,
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
    /// Frames dropped as late.
    pub late: u64,
    /// Keys evicted before their window ended (more than [`MAX_RECENT`] frames in it).
    pub evicted: u64,
}

impl Merger {
    /// A merger of links with these names (in the order of their indices).
    pub fn new(names: Vec<String>) -> Self {
        Self {
            names,
            ..Self::default()
        }
    }

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
        let at_once = |l: usize, t: f64| l != link && now - t <= TWO_SOURCES_WITHIN_S;
        if c.last_on.iter().any(|(&l, &t)| at_once(l, t)) {
            c.frames += 1;
            c.copies += u32::from(copy);
        }
        if c.frames == SOURCES_BLOCK {
            let share = f64::from(c.copies) / f64::from(c.frames);
            (c.frames, c.copies) = (0, 0);
            if share < MIN_COPY_SHARE && self.told.insert(f.sysid) {
                let name = |l: usize| {
                    self.names
                        .get(l)
                        .cloned()
                        .unwrap_or_else(|| format!("link {}", l + 1))
                };
                let mut links = vec![name(link)];
                links.extend(
                    c.last_on
                        .iter()
                        .filter(|&(&l, &t)| at_once(l, t))
                        .map(|(&l, _)| name(l)),
                );
                self.two_sources.push((
                    f.sysid,
                    format!(
                        "system {} (component {}) arrives on {} at once with {:.1} % of its frames in common (two paths of one stream share most): two vehicles with one system id, or two ports of one autopilot (each numbers its own frames); give the monitor one path per vehicle port",
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
        let behind_by_seq = c.newest.is_some_and(|(newest, from)| {
            from != link && (1..128).contains(&newest.wrapping_sub(f.seq))
        });
        let stamp = Stamp::of(&f.msg);
        let slot = c.stamps.iter().position(|&(id, ..)| id == f.msg_id);
        let behind_by_stamp = matches!((stamp, slot), (Some(s), Some(k))
            if c.stamps[k].2 != link && s.not_after(c.stamps[k].1));
        if behind_by_seq || behind_by_stamp {
            self.late += 1;
            return Verdict::Late;
        }
        c.newest = Some((f.seq, link));
        match (stamp, slot) {
            (Some(s), Some(k)) => c.stamps[k] = (f.msg_id, s, link),
            (Some(s), None) => c.stamps.push((f.msg_id, s, link)),
            _ => {}
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

    /// An ATTITUDE stamped `roll` ms (the tests' rolls count up).
    fn frame(sysid: u8, seq: u8, roll: f32) -> Frame {
        stamped(sysid, seq, roll, roll as u32)
    }

    fn stamped(sysid: u8, seq: u8, roll: f32, time_boot_ms: u32) -> Frame {
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms,
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
    /// frame, all five fields equal, came in on another link within the window; otherwise
    /// late exactly when its component's newest delivered frame came from another link with a
    /// sequence number ahead of it (by 1-127) or a stamp not before its own (u32 stamps
    /// compared across their wrap).
    #[test]
    fn copies_are_exactly_the_equal_frames_of_other_links_within_the_window() {
        let mut m = Merger::default();
        let mut seen: Vec<(f64, usize, u8, u8, f32, u32)> = Vec::new();
        // Stamps near each other, across the u32 wrap and half a wrap apart.
        let stamps = [0, 1, 2, 3, u32::MAX - 1, u32::MAX, 1 << 31, (1 << 31) + 1];
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
            let stamp = stamps[(next() % 8) as usize];
            // The newest delivery of an equal frame decides.
            let copy = seen
                .iter()
                .rev()
                .find(|&&(_, _, s, q, r, st)| s == sysid && q == seq && r == roll && st == stamp)
                .is_some_and(|&(at, l, ..)| t - at <= COPY_WINDOW_S && l != link);
            let late = seen
                .iter()
                .rev()
                .find(|&&(_, _, s, ..)| s == sysid)
                .is_some_and(|&(_, l, _, q, _, st)| {
                    l != link
                        && ((1..128).contains(&q.wrapping_sub(seq))
                            || st.wrapping_sub(stamp) < 1 << 31)
                });
            let want = match (copy, late) {
                (true, _) => Verdict::Copy,
                (false, true) => Verdict::Late,
                _ => Verdict::New,
            };
            let got = m.accept(&stamped(sysid, seq, roll, stamp), link, t);
            assert_eq!(got, want, "t {t} link {link} seq {seq} stamp {stamp}");
            if got == Verdict::New {
                seen.push((t, link, sysid, seq, roll, stamp));
            }
        }
        assert!(m.copies_total() > 20, "{} copies", m.copies_total());
        assert!(m.late > 100, "{} late", m.late);
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
            // Two boots' clocks: one vehicle's frames are behind the other's, and dropped.
            assert_ne!(m.accept(&frame(7, k as u8, 1.0), 0, t), Verdict::Copy);
            assert_ne!(m.accept(&frame(7, k as u8, 2.0), 1, t), Verdict::Copy);
        }
        let told = m.take_two_sources();
        assert_eq!(told.len(), 1, "{told:?}");
        assert!(
            told[0].1.contains("on link 1 and link 2 at once"),
            "{}",
            told[0].1
        );
        assert!(m.take_two_sources().is_empty());
    }

    /// The second path three frames behind: a gap of the first is filled only by a frame
    /// that comes before the sender's next one, which at three frames behind is never.
    #[test]
    fn a_slower_path_s_fills_after_a_newer_frame_are_late() {
        let mut m = Merger::default();
        let (mut new, mut late) = (0, 0);
        let on0 = |k: u32| !k.is_multiple_of(5);
        for k in 0..3_000u32 {
            let t = f64::from(k) * 0.002;
            if on0(k) {
                assert_eq!(m.accept(&frame(1, k as u8, k as f32), 0, t), Verdict::New);
                new += 1;
            }
            if k >= 3 {
                let j = k - 3;
                let got = m.accept(&frame(1, j as u8, j as f32), 1, t);
                let want = if on0(j) { Verdict::Copy } else { Verdict::Late };
                assert_eq!(got, want, "frame {j}");
                late += u64::from(!on0(j));
            }
        }
        assert_eq!((new, m.late), (2_400, late));
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
