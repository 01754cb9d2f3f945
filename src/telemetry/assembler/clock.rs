//! The vehicle's clock: its own time stamps (`time_boot_ms`, u32 and u64 µs), unwrapped,
//! with stale and reordered messages dropped, a reboot told from a stale burst (the clock
//! goes back and stays back), a message far ahead held until the next confirms it, and the
//! autopilot's sequence numbers counting the frames lost on the way.

use super::{
    REBOOT_ARRIVAL_S, REBOOT_BACKSTEP_S, REBOOT_CONFIRM_S, REBOOT_HOLD_S, TelemetrySample,
    VehicleAssembler,
};
use crate::protocol::MavMessage;

/// Whether `t` can be on the same new clock as `first`, the first message seen on it.
fn on_new_clock(first: f64, t: f64) -> bool {
    (first - REBOOT_BACKSTEP_S..=first + REBOOT_CONFIRM_S).contains(&t)
}

/// Whether the arrival clock has run at least `needed` s from `since` to `now`; an unknown or
/// standing arrival clock tells nothing (true).
fn arrival_ran(since: Option<f64>, now: Option<f64>, needed: f64) -> bool {
    match (since, now) {
        (Some(a), Some(b)) if b != a => b - a >= needed,
        _ => true,
    }
}

/// Unwrap a u32 µs stamp (SERVO_OUTPUT_RAW wraps every 71.6 min) next to a reference time:
/// the latest reading not more than a second ahead of it. (Rounding to the nearest would put a
/// stamp just after a reboot, late in a wrap period, a whole period ahead: never "behind".)
fn unwrap_u32_us(stamp: u32, reference_s: Option<f64>) -> f64 {
    let raw = f64::from(stamp) * 1e-6;
    match reference_s {
        None => raw,
        Some(r) => {
            let span = 4_294_967_296e-6;
            raw + ((r + REBOOT_BACKSTEP_S - raw) / span).floor().max(0.0) * span
        }
    }
}

impl VehicleAssembler {
    /// More than a second behind the vehicle clock: stale, or the first message of a reboot.
    pub(super) fn behind(&self, t: f64) -> bool {
        self.clock.is_some_and(|c| t < c - REBOOT_BACKSTEP_S)
    }

    /// A u32 µs stamp (SERVO_OUTPUT_RAW, older RAW_IMU) on the vehicle clock. Unwrapped next to
    /// the clock it falls behind it after a reboot late in a wrap period (over 71.6 min of
    /// uptime: a stamp of 2 s read as 4297 s against a clock at 5000 s), never on the new
    /// boot's clock of its ATTITUDE, and the reboot was never confirmed: the rest of the log
    /// was dropped as reordered. So while a reboot is pending, a stamp behind the clock is
    /// unwrapped next to the new clock too, and taken so if it falls there.
    pub(super) fn unwrap_stamp(&self, stamp: u32) -> f64 {
        let t = unwrap_u32_us(stamp, self.clock);
        if self.behind(t)
            && let Some(first) = self.reboot_candidate
        {
            let on_new = unwrap_u32_us(stamp, Some(first));
            if on_new_clock(first, on_new) {
                return on_new;
            }
        }
        t
    }

    /// Advance the clock; false if `t` is stale (reordered) — the message is then dropped and
    /// counted. The first message of a new boot is dropped too, until the second confirms it.
    pub(super) fn tick(&mut self, t: f64) -> bool {
        let Some(c) = self.clock else {
            self.clock = Some(t);
            self.ticked = true;
            return true;
        };
        if !self.behind(t) {
            self.ticked = true;
            self.reboot_candidate = None;
            self.clock = Some(c.max(t));
            if self
                .clock_before_jump
                .is_some_and(|(_, target)| t > target + REBOOT_CONFIRM_S)
            {
                self.clock_before_jump = None;
            }
            return true;
        }
        // Back on the clock from before the last jump ahead: the jump's two messages were
        // forged or corrupt, not a clock that ran on (a reboot starts far behind it).
        if let Some((before, _)) = self.clock_before_jump
            && t >= before - REBOOT_BACKSTEP_S
        {
            self.clock_before_jump = None;
            self.counters.clock_jumps_refused += 1;
            self.ticked = true;
            self.reboot_candidate = None;
            self.clock = Some(t);
            // What the jump's messages left waiting to be paired is theirs.
            let after = |stamp: f64| stamp > t + REBOOT_BACKSTEP_S;
            if self.rates.is_some_and(|r| after(r.t)) {
                self.rates = None;
                self.rates_prev = None;
            }
            if self.outputs.is_some_and(|o| after(o.t)) {
                self.outputs = None;
            }
            if self.az.is_some_and(|a| after(a.t)) {
                self.az = None;
            }
            if self.pending.is_some_and(|p| after(p.t)) {
                self.pending = None;
            }
            if self.last_sample_t.is_some_and(after) {
                self.last_sample_t = None;
            }
            return true;
        }
        // The first message on the new clock, if this one is on it too.
        let first = self
            .reboot_candidate
            .filter(|&first| on_new_clock(first, t));
        let held_long = first.is_some_and(|first| t - first >= REBOOT_HOLD_S);
        let arrived_over = arrival_ran(self.arrival_at_candidate, self.arrival, REBOOT_ARRIVAL_S);
        if held_long && !arrived_over {
            self.counters.clock_jumps_refused += 1;
        }
        if !(held_long && arrived_over) {
            // Not (yet) enough of the new clock: dropped and counted.
            if first.is_none() {
                self.lost_at_reboot_candidate = self.lost_at_last_tick;
                self.held_at_reboot_candidate = 0;
                self.arrival_at_candidate = self.arrival;
            }
            self.reboot_candidate = Some(first.unwrap_or(t));
            self.counters.out_of_order += 1;
            self.held_at_reboot_candidate += 1;
            return false;
        }
        self.reboot_candidate = None;
        self.counters.reboots += 1;
        tracing::debug!(
            "sysid {}: rebooted (its clock went back and stayed back {REBOOT_HOLD_S} s)",
            self.info.sysid
        );
        // The new boot's first messages were not reordered: they confirmed it.
        let held = self
            .held_at_reboot_candidate
            .min(self.counters.out_of_order);
        self.counters.out_of_order -= held;
        self.counters.confirming_reboot += held;
        self.rebooted = true;
        if self.pending.take().is_some() {
            self.counters.dropped_at_reboot += 1;
        }
        self.rates = None;
        self.outputs = None;
        self.az = None;
        self.az_source = None;
        self.az_interval = None;
        self.az_last = [None; 4];
        self.last_sample_t = None;
        // The sequence starts afresh with this frame (`ticked` stays unset: `lost_frames` is
        // already what `lost_at_last_tick` holds).
        self.seq = None;
        self.counters.lost_frames = self.lost_at_reboot_candidate;
        self.clock = Some(t);
        self.clock_before_jump = None;
        true
    }

    /// Count the frames the autopilot's sequence numbers (one counter per sender, wrapping at
    /// 256) skipped. A number up to 63 behind the newest is a late frame, taken off the count
    /// unless it already came (a duplicate); any other is a jump forward over lost frames (an
    /// outage of up to 255 frames: beyond that the counter has wrapped unseen).
    pub fn on_sequence(&mut self, compid: u8, seq: u8) {
        if !self.is_autopilot_component(compid) {
            return;
        }
        self.count_sequence(seq);
        if std::mem::take(&mut self.ticked) {
            self.lost_at_last_tick = self.counters.lost_frames;
        }
    }

    pub(super) fn count_sequence(&mut self, seq: u8) {
        // Before the first frame nothing was missed: the whole window reads as arrived.
        let Some((newest, seen)) = self.seq else {
            self.seq = Some((seq, u64::MAX));
            return;
        };
        let behind = newest.wrapping_sub(seq);
        if behind < 64 {
            if seen & (1 << behind) == 0 {
                self.counters.lost_frames = self.counters.lost_frames.saturating_sub(1);
                self.seq = Some((newest, seen | 1 << behind));
            }
            return;
        }
        let ahead = seq.wrapping_sub(newest);
        self.counters.lost_frames += u64::from(ahead - 1);
        let seen = if ahead < 64 { seen << ahead | 1 } else { 1 };
        self.seq = Some((seq, seen));
    }

    /// The stamp of a message that advances the vehicle clock (the autopilot's rates and
    /// outputs): a u32 µs stamp unwrapped next to `near`, or next to the clock.
    pub(super) fn clock_stamp(
        &self,
        compid: u8,
        msg: &MavMessage,
        near: Option<f64>,
    ) -> Option<f64> {
        if !self.is_autopilot_component(compid) {
            return None;
        }
        match msg {
            MavMessage::ATTITUDE(a) => Some(f64::from(a.time_boot_ms) * 1e-3),
            MavMessage::SERVO_OUTPUT_RAW(s) if s.port == 0 => Some(match near {
                Some(_) => unwrap_u32_us(s.time_usec, near),
                None => self.unwrap_stamp(s.time_usec),
            }),
            MavMessage::ACTUATOR_OUTPUT_STATUS(s) => Some(s.time_usec as f64 * 1e-6),
            _ => None,
        }
    }

    /// Feed one message; complete instants are appended to `out` (in time order).
    ///
    /// A message stamped more than a second ahead of the clock (after a link outage, or one
    /// corrupt stamp) is held until the next: on the same clock, the jump is taken and both
    /// are used; otherwise it is dropped and counted. One CRC-valid ATTITUDE with a wild
    /// `time_boot_ms` used to move the clock days ahead, and the rest of the flight read as
    /// reordered.
    pub fn on_message(&mut self, compid: u8, msg: &MavMessage, out: &mut Vec<TelemetrySample>) {
        let stamp = self.clock_stamp(compid, msg, None);
        let ahead = stamp.filter(|&t| self.clock.is_some_and(|c| t > c + REBOOT_BACKSTEP_S));
        // Only the next message on a clock decides (not a heartbeat or an IMU message). A u32
        // µs stamp confirms if, unwrapped next to the held one, it falls next to it: a log that
        // starts with SERVO_OUTPUT_RAW after 71.6 min of uptime has its clock set a wrap period
        // or more behind the ATTITUDE's, and next to that clock the stamp reads a period off.
        if stamp.is_some()
            && let Some((held_t, held_compid, held)) = self.held_ahead.take()
        {
            let confirms = self
                .clock_stamp(compid, msg, Some(held_t))
                .is_some_and(|t| (t - held_t).abs() <= REBOOT_BACKSTEP_S);
            if confirms {
                self.clock_before_jump = self.clock.map(|before| (before, held_t));
                self.clock = Some(held_t);
                self.use_message(held_compid, &held, out);
                self.use_message(compid, msg, out);
                return;
            }
            self.counters.ahead_of_clock += 1;
        }
        if let Some(t) = ahead {
            self.held_ahead = Some((t, compid, msg.clone()));
            return;
        }
        // (A message off the clock passes while one is held: it cannot confirm or refute it.)
        self.use_message(compid, msg, out);
    }
}
