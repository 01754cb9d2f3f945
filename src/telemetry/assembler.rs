//! Frames → telemetry samples, per vehicle (system id), on the vehicle's own clock.
//!
//! A sample needs body rates (ATTITUDE) and actuator outputs (SERVO_OUTPUT_RAW or
//! ACTUATOR_OUTPUT_STATUS) for the same instant; a vertical specific force from HIGHRES_IMU,
//! SCALED_IMU* or RAW_IMU is added when one is that recent. Outputs older than the skew
//! tolerance are never reused silently: the rates wait for fresh outputs, and an instant that
//! never gets them is counted as `unmatched`.

use crate::protocol::dialects::ahcmon::{MavAutopilot, MavMessage, MavModeFlag, MavType};
use serde::Serialize;
use std::collections::BTreeMap;

/// Standard gravity (ArduPilot's GRAVITY_MSS): RAW_IMU / SCALED_IMU accelerations are in mG.
const G0: f64 = 9.80665;
/// Largest backwards step of the vehicle clock treated as reordering; more is a reboot once
/// messages on the new clock have covered `REBOOT_HOLD_S` of it with no message on the old
/// clock in between (a lagging second link sends bursts of old instants, not a clock that
/// runs on), all within `REBOOT_CONFIRM_S` of the first.
const REBOOT_BACKSTEP_S: f64 = 1.0;
pub const REBOOT_HOLD_S: f64 = 0.5;
const REBOOT_CONFIRM_S: f64 = 5.0;

/// One instant of one vehicle: what an estimator step needs, before normalisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TelemetrySample {
    /// Vehicle time (s since boot).
    pub t: f64,
    /// Body rates p, q, r (rad/s).
    pub rates: [f64; 3],
    /// Roll, pitch, yaw (rad).
    pub attitude: [f64; 3],
    /// Vertical specific force (m/s², body z, down positive; about -9.8 in hover).
    pub az: Option<f64>,
    /// Output PWM (µs) of channels 1..16; 0 = not sent.
    pub pwm: [u16; 16],
    pub armed: bool,
    /// Height above home (m), when the vehicle sends GLOBAL_POSITION_INT.
    pub rel_alt: Option<f64>,
}

/// What the telemetry layer dropped or repaired, per vehicle.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct TelemetryCounters {
    pub samples: u64,
    /// Rate instants for which no outputs of the same instant arrived.
    pub unmatched: u64,
    /// Messages older than the last sample (reordered) or at the same instant (duplicates).
    pub out_of_order: u64,
    pub duplicates: u64,
    /// Vehicle clock jumped back by more than a second (confirmed by a second message).
    pub reboots: u64,
    /// Messages stamped more than a second ahead of the vehicle clock that no second message
    /// on the same clock had confirmed: dropped. One corrupt stamp (a CRC-valid ATTITUDE with
    /// a wild `time_boot_ms`) used to move the clock far ahead, and everything after it was
    /// "reordered"; after a link outage of over a second the first message is one of these.
    pub ahead_of_clock: u64,
    /// Samples still waiting for their a_z when the vehicle rebooted: dropped, not fed to the
    /// new boot's filters.
    pub dropped_at_reboot: u64,
    /// Messages of a new boot's first `REBOOT_HOLD_S`, dropped while they confirm the reboot
    /// (not counted as reordered once it is confirmed).
    pub confirming_reboot: u64,
    /// Frames of the autopilot its sequence numbers say never arrived intact: lost on the link,
    /// dropped above as corrupt (bad CRC) or of an unknown message id, or left out of the log. A frame that arrives late is
    /// taken off again. An outage of 256 frames or more wraps the counter and is not seen, and
    /// two links merged (each with its own counter) make the count meaningless.
    pub lost_frames: u64,
    /// Messages with NaN / inf in the fields we use.
    pub non_finite: u64,
    /// Rate (ATTITUDE) and output (SERVO_OUTPUT_RAW port 0, ACTUATOR_OUTPUT_STATUS) messages
    /// received: far fewer outputs than rates leave most rate instants unmatched.
    pub rate_messages: u64,
    pub output_messages: u64,
}

/// What the vehicle said about itself: heartbeat and parameters.
#[derive(Debug, Clone, Default)]
pub struct VehicleInfo {
    pub sysid: u8,
    /// The autopilot's component id (from its heartbeat); other components are ignored.
    pub compid: Option<u8>,
    pub mav_type: Option<MavType>,
    pub autopilot: Option<MavAutopilot>,
    pub armed: bool,
    pub params: BTreeMap<String, f32>,
    pub statustext: Vec<String>,
}

impl VehicleInfo {
    pub fn param(&self, name: &str) -> Option<f64> {
        self.params.get(name).map(|v| f64::from(*v))
    }
}

/// Maximum time between the rates and the outputs of one sample.
#[derive(Debug, Clone, Copy)]
pub struct AssemblerConfig {
    pub max_skew_s: f64,
}

impl Default for AssemblerConfig {
    fn default() -> Self {
        // ArduPilot stamps ATTITUDE and SERVO_OUTPUT_RAW from the same loop (skew < 1 ms in
        // the SITL logs); 15 ms is under one period at 50 Hz, so a pair is never a
        // neighbour's outputs.
        Self { max_skew_s: 0.015 }
    }
}

#[derive(Debug, Clone, Copy)]
struct Stamped<T> {
    t: f64,
    v: T,
}

/// One vehicle's assembler.
#[derive(Debug)]
pub struct VehicleAssembler {
    cfg: AssemblerConfig,
    pub info: VehicleInfo,
    pub counters: TelemetryCounters,
    rates: Option<Stamped<([f64; 3], [f64; 3])>>,
    rates_used: bool,
    outputs: Option<Stamped<[u16; 16]>>,
    az: Option<Stamped<f64>>,
    /// The message a_z is taken from (see `on_az`), its last interval (s), and the last stamp
    /// of each source.
    az_source: Option<AzSource>,
    az_interval: Option<f64>,
    az_last: [Option<f64>; 4],
    rel_alt: Option<f64>,
    last_sample_t: Option<f64>,
    /// Latest vehicle time seen (s), for reboot detection and u32 µs unwrapping.
    clock: Option<f64>,
    /// Set when a reboot was seen; the caller resets its filters.
    pub rebooted: bool,
    /// The first of the messages more than a second behind the clock since the last one on
    /// it: a reboot once they cover `REBOOT_HOLD_S` (stale copies from a second link do not).
    reboot_candidate: Option<f64>,
    /// The last message stamped more than a second ahead of the clock (its stamp, component
    /// and the message), held until the next one confirms the jump.
    held_ahead: Option<(f64, u8, MavMessage)>,
    /// The vehicle sends IMU accelerations: a complete instant waits for its a_z.
    has_imu: bool,
    /// Smoothed interval between rate instants (s), once seen: the pairing tolerance stays
    /// under half of it, so at high rates (`--request-rates 100`) a pair is never a
    /// neighbour's.
    rate_period: Option<f64>,
    pending: Option<TelemetrySample>,
    /// The autopilot's newest frame sequence number, and which of the 64 before it arrived
    /// (bit i: sequence number `newest - i`).
    seq: Option<(u8, u64)>,
    /// `lost_frames` when the first message of a possible reboot came: a confirmed reboot
    /// restarts the sequence, and what its jump counted is taken back.
    lost_at_reboot_candidate: u64,
    /// `lost_frames` after the last frame that advanced the clock. The new boot's first frames
    /// are often unstamped (HEARTBEAT): their sequence jump comes before the first message
    /// that makes the reboot a candidate, and is taken back from here.
    lost_at_last_tick: u64,
    /// The frame being read advanced the clock (set by `tick`, read by `on_sequence`).
    ticked: bool,
    /// Messages dropped since then (counted as reordered until the reboot is confirmed).
    held_at_reboot_candidate: u64,
}

/// Where a_z comes from: one message type per run (see `VehicleAssembler::on_az`), in order
/// of preference.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum AzSource {
    HighresImu,
    RawImu,
    ScaledImu,
    ScaledImu2,
}

/// A locked a_z source silent this long (s) gives way to another.
const AZ_SOURCE_SILENT_S: f64 = 1.0;

/// Whether `t` can be on the same new clock as `first`, the first message seen on it.
fn on_new_clock(first: f64, t: f64) -> bool {
    (first - REBOOT_BACKSTEP_S..=first + REBOOT_CONFIRM_S).contains(&t)
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
    /// The latest vehicle time seen (s), from any stamped message; `None` before one.
    pub fn clock(&self) -> Option<f64> {
        self.clock
    }

    pub fn new(sysid: u8, cfg: AssemblerConfig) -> Self {
        Self {
            cfg,
            info: VehicleInfo {
                sysid,
                ..Default::default()
            },
            counters: TelemetryCounters::default(),
            rates: None,
            rates_used: false,
            outputs: None,
            az: None,
            az_source: None,
            az_interval: None,
            az_last: [None; 4],
            rel_alt: None,
            last_sample_t: None,
            clock: None,
            rebooted: false,
            reboot_candidate: None,
            held_ahead: None,
            has_imu: false,
            rate_period: None,
            pending: None,
            seq: None,
            lost_at_reboot_candidate: 0,
            lost_at_last_tick: 0,
            ticked: false,
            held_at_reboot_candidate: 0,
        }
    }

    fn is_autopilot_component(&self, compid: u8) -> bool {
        match self.info.compid {
            Some(c) => c == compid,
            // Before the autopilot's heartbeat: MAV_COMP_ID_AUTOPILOT1.
            None => compid == 1,
        }
    }

    /// More than a second behind the vehicle clock: stale, or the first message of a reboot.
    fn behind(&self, t: f64) -> bool {
        self.clock.is_some_and(|c| t < c - REBOOT_BACKSTEP_S)
    }

    /// A u32 µs stamp (SERVO_OUTPUT_RAW, older RAW_IMU) on the vehicle clock. Unwrapped next to
    /// the clock it falls behind it after a reboot late in a wrap period (over 71.6 min of
    /// uptime: a stamp of 2 s read as 4297 s against a clock at 5000 s), never on the new
    /// boot's clock of its ATTITUDE, and the reboot was never confirmed: the rest of the log
    /// was dropped as reordered. So while a reboot is pending, a stamp behind the clock is
    /// unwrapped next to the new clock too, and taken so if it falls there.
    fn unwrap_stamp(&self, stamp: u32) -> f64 {
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
    fn tick(&mut self, t: f64) -> bool {
        let Some(c) = self.clock else {
            self.clock = Some(t);
            self.ticked = true;
            return true;
        };
        if !self.behind(t) {
            self.ticked = true;
            self.reboot_candidate = None;
            self.clock = Some(c.max(t));
            return true;
        }
        // The first message on the new clock, if this one is on it too.
        let first = self
            .reboot_candidate
            .filter(|&first| on_new_clock(first, t));
        if !first.is_some_and(|first| t - first >= REBOOT_HOLD_S) {
            // Not (yet) enough of the new clock: dropped and counted.
            if first.is_none() {
                self.lost_at_reboot_candidate = self.lost_at_last_tick;
                self.held_at_reboot_candidate = 0;
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

    fn count_sequence(&mut self, seq: u8) {
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
    fn clock_stamp(&self, compid: u8, msg: &MavMessage, near: Option<f64>) -> Option<f64> {
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

    fn use_message(&mut self, compid: u8, msg: &MavMessage, out: &mut Vec<TelemetrySample>) {
        // A new rate instant releases a sample still waiting for its a_z, without it; one from
        // a clock far behind (stale, or a reboot) does not.
        if let MavMessage::ATTITUDE(a) = msg
            && self.is_autopilot_component(compid)
            && !self.behind(f64::from(a.time_boot_ms) * 1e-3)
        {
            out.extend(self.pending.take());
        }
        let emitted = self.message(compid, msg);
        let max_skew = self.max_skew();
        if let (Some(p), Some(a)) = (self.pending.as_mut(), self.az)
            && (a.t - p.t).abs() <= max_skew
        {
            p.az = Some(a.v);
            out.extend(self.pending.take());
        }
        if let Some(s) = emitted {
            if self.has_imu && s.az.is_none() {
                // Usually sent just after the outputs: wait for this instant's a_z.
                out.extend(self.pending.replace(s));
            } else {
                out.push(s);
            }
        }
    }

    /// A sample still waiting for its a_z, released without it (end of input).
    pub fn flush(&mut self, out: &mut Vec<TelemetrySample>) {
        out.extend(self.pending.take());
        if self.held_ahead.take().is_some() {
            self.counters.ahead_of_clock += 1;
        }
    }

    fn message(&mut self, compid: u8, msg: &MavMessage) -> Option<TelemetrySample> {
        match msg {
            MavMessage::HEARTBEAT(hb) => {
                let is_autopilot = hb.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
                    && !matches!(
                        hb.mavtype,
                        MavType::MAV_TYPE_GCS
                            | MavType::MAV_TYPE_ONBOARD_CONTROLLER
                            | MavType::MAV_TYPE_GIMBAL
                            | MavType::MAV_TYPE_ADSB
                            | MavType::MAV_TYPE_CAMERA
                    );
                // The first autopilot heartbeat names the component; the autopilot's own id
                // (MAV_COMP_ID_AUTOPILOT1) takes over from another that claimed to be one (a
                // companion computer's heartbeat first used to hide every sample of the
                // vehicle behind it).
                if is_autopilot && self.info.compid.is_none_or(|c| c == compid || compid == 1) {
                    self.info.compid = Some(compid);
                    self.info.mav_type = Some(hb.mavtype);
                    self.info.autopilot = Some(hb.autopilot);
                    self.info.armed = hb
                        .base_mode
                        .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
                }
                None
            }
            _ if !self.is_autopilot_component(compid) => None,
            MavMessage::PARAM_VALUE(p) => {
                let name = p.param_id.to_str().unwrap_or("").trim_end_matches('\0');
                if !name.is_empty() && p.param_value.is_finite() {
                    self.info.params.insert(name.to_string(), p.param_value);
                }
                None
            }
            MavMessage::STATUSTEXT(s) => {
                if self.info.statustext.len() < 1000 {
                    self.info
                        .statustext
                        .push(s.text.to_str().unwrap_or("").to_string());
                }
                None
            }
            MavMessage::GLOBAL_POSITION_INT(g) => {
                self.rel_alt = Some(f64::from(g.relative_alt) * 1e-3);
                None
            }
            MavMessage::ATTITUDE(a) => {
                let v = [a.rollspeed, a.pitchspeed, a.yawspeed, a.roll, a.pitch, a.yaw];
                if v.iter().any(|x| !x.is_finite()) {
                    self.counters.non_finite += 1;
                    return None;
                }
                let t = f64::from(a.time_boot_ms) * 1e-3;
                if !self.tick(t) {
                    return None;
                }
                self.counters.rate_messages += 1;
                if let Some(last) = self.last_sample_t {
                    if t < last {
                        self.counters.out_of_order += 1;
                        return None;
                    }
                    if t == last {
                        self.counters.duplicates += 1;
                        return None;
                    }
                }
                if let Some(prev) = self.rates
                    && !self.rates_used
                {
                    // Rates still waiting for their outputs are newer, or the same instant.
                    if t < prev.t {
                        self.counters.out_of_order += 1;
                        return None;
                    }
                    if t == prev.t {
                        self.counters.duplicates += 1;
                        return None;
                    }
                    self.counters.unmatched += 1;
                }
                if let Some(prev) = self.rates {
                    self.learn_rate_period(t - prev.t);
                }
                let rates = [v[0], v[1], v[2]].map(f64::from);
                let att = [v[3], v[4], v[5]].map(f64::from);
                self.rates = Some(Stamped { t, v: (rates, att) });
                self.rates_used = false;
                self.try_emit()
            }
            MavMessage::SERVO_OUTPUT_RAW(s) => {
                // port 0 carries outputs 1..16; other ports are further banks we do not map.
                if s.port != 0 {
                    return None;
                }
                let t = self.unwrap_stamp(s.time_usec);
                if !self.tick(t) {
                    return None;
                }
                let pwm = [
                    s.servo1_raw,
                    s.servo2_raw,
                    s.servo3_raw,
                    s.servo4_raw,
                    s.servo5_raw,
                    s.servo6_raw,
                    s.servo7_raw,
                    s.servo8_raw,
                    s.servo9_raw,
                    s.servo10_raw,
                    s.servo11_raw,
                    s.servo12_raw,
                    s.servo13_raw,
                    s.servo14_raw,
                    s.servo15_raw,
                    s.servo16_raw,
                ];
                self.set_outputs(t, pwm)
            }
            MavMessage::ACTUATOR_OUTPUT_STATUS(s) => {
                // PX4: the outputs' values (PWM µs for PWM outputs) in `actuator[]`; `active`
                // is the number of outputs (PX4's ACTUATOR_OUTPUT_STATUS stream sends
                // `actuator_outputs.noutputs`), not a bitmask, and 0 marks an unused channel.
                let t = s.time_usec as f64 * 1e-6;
                if !self.tick(t) {
                    return None;
                }
                let active = usize::try_from(s.active).unwrap_or(usize::MAX);
                let mut pwm = [0u16; 16];
                for (k, p) in pwm.iter_mut().enumerate().take(active) {
                    let v = s.actuator[k];
                    if v.is_finite() && (1.0..65535.0).contains(&v) {
                        *p = v.round() as u16;
                    }
                }
                self.set_outputs(t, pwm)
            }
            MavMessage::HIGHRES_IMU(m) => {
                self.on_az(AzSource::HighresImu, m.time_usec as f64 * 1e-6, f64::from(m.zacc))
            }
            MavMessage::SCALED_IMU(m) => self.on_az(
                AzSource::ScaledImu,
                f64::from(m.time_boot_ms) * 1e-3,
                f64::from(m.zacc) * 1e-3 * G0,
            ),
            MavMessage::SCALED_IMU2(m) => self.on_az(
                AzSource::ScaledImu2,
                f64::from(m.time_boot_ms) * 1e-3,
                f64::from(m.zacc) * 1e-3 * G0,
            ),
            MavMessage::RAW_IMU(m)
                // RAW_IMU is in mG only on ArduPilot (elsewhere raw sensor units).
                if self.info.autopilot.is_none_or(|a| a == MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA) =>
            {
                // Older ArduPilot stamps it with the 32-bit micros(), which wraps every 71.6
                // min; a stamp that fits in 32 bits is unwrapped like SERVO_OUTPUT_RAW's.
                let t = match u32::try_from(m.time_usec) {
                    Ok(us) => self.unwrap_stamp(us),
                    Err(_) => m.time_usec as f64 * 1e-6,
                };
                self.on_az(AzSource::RawImu, t, f64::from(m.zacc) * 1e-3 * G0)
            }
            _ => None,
        }
    }

    /// The pairing tolerance (s): the configured one, or under half the rate period if shorter.
    pub fn max_skew(&self) -> f64 {
        self.rate_period
            .map_or(self.cfg.max_skew_s, |p| self.cfg.max_skew_s.min(0.45 * p))
    }

    /// Smooth the interval between rate instants; a lost instant (a longer interval) does not
    /// stretch it.
    fn learn_rate_period(&mut self, dt: f64) {
        if !(dt > 0.0 && dt < 1.0) {
            return;
        }
        self.rate_period = Some(match self.rate_period {
            None => dt,
            Some(p) if dt < 1.5 * p => 0.9 * p + 0.1 * dt,
            // Longer: a hole, or the stream slowed down; adapt slowly from below.
            Some(p) => p * 1.02,
        });
    }

    /// New outputs, unless older than those held (a reordered message: counted, dropped).
    fn set_outputs(&mut self, t: f64, pwm: [u16; 16]) -> Option<TelemetrySample> {
        self.counters.output_messages += 1;
        if self.outputs.is_some_and(|o| t < o.t) {
            self.counters.out_of_order += 1;
            return None;
        }
        self.outputs = Some(Stamped { t, v: pwm });
        self.try_emit()
    }

    fn on_az(&mut self, source: AzSource, t: f64, az: f64) -> Option<TelemetrySample> {
        if !az.is_finite() {
            self.counters.non_finite += 1;
            return None;
        }
        // One IMU: ArduPilot streams RAW_IMU (IMU 1, µs stamps) with SCALED_IMU2/3 (other IMUs,
        // ms stamps) and their biases differ, so a_z comes from one source. A preferred one
        // takes over once it comes about as often as the one in use (it may start later, e.g.
        // after a rate request; a slower one would leave a_z sparse); a less preferred one only
        // after the source in use has been silent for AZ_SOURCE_SILENT_S.
        let k = source as usize;
        let own_interval = self.az_last[k].map(|p| t - p);
        self.az_last[k] = Some(t);
        if let (Some(locked), Some(prev)) = (self.az_source, self.az)
            && source != locked
        {
            let silent = t - prev.t >= AZ_SOURCE_SILENT_S;
            let as_often = own_interval
                .is_some_and(|i| i > 0.0 && i <= 1.5 * self.az_interval.unwrap_or(f64::INFINITY));
            if !(silent || (source < locked && as_often)) {
                return None;
            }
            self.az_interval = own_interval;
        } else if let Some(prev) = self.az {
            if t <= prev.t {
                return None;
            }
            self.az_interval = Some(t - prev.t);
        }
        self.az_source = Some(source);
        self.az = Some(Stamped { t, v: az });
        self.has_imu = true;
        None
    }

    fn try_emit(&mut self) -> Option<TelemetrySample> {
        let rates = self.rates?;
        let outputs = self.outputs?;
        let max_skew = self.max_skew();
        if self.rates_used || (rates.t - outputs.t).abs() > max_skew {
            return None;
        }
        self.rates_used = true;
        self.last_sample_t = Some(rates.t);
        self.counters.samples += 1;
        let az = self
            .az
            .filter(|a| (a.t - rates.t).abs() <= max_skew)
            .map(|a| a.v);
        Some(TelemetrySample {
            t: rates.t,
            rates: rates.v.0,
            attitude: rates.v.1,
            az,
            pwm: outputs.v,
            armed: self.info.armed,
            rel_alt: self.rel_alt,
        })
    }
}

/// Assemblers for every vehicle seen, keyed by system id.
#[derive(Debug, Default)]
pub struct Assembler {
    pub cfg: AssemblerConfig,
    pub vehicles: BTreeMap<u8, VehicleAssembler>,
}

impl Assembler {
    pub fn new(cfg: AssemblerConfig) -> Self {
        Self {
            cfg,
            vehicles: BTreeMap::new(),
        }
    }

    /// Feed one frame; complete samples of its vehicle are appended to `out`. GCS traffic
    /// (sysid 255 and MAV_TYPE_GCS heartbeats) never makes a vehicle.
    pub fn on_frame(
        &mut self,
        sysid: u8,
        compid: u8,
        msg: &MavMessage,
        out: &mut Vec<TelemetrySample>,
    ) {
        if sysid == 255 || sysid == 0 {
            return;
        }
        if !self.vehicles.contains_key(&sysid) {
            // Only an autopilot's heartbeat or a rate message makes a new vehicle.
            let vehicle_like = match msg {
                MavMessage::HEARTBEAT(hb) => {
                    hb.autopilot != MavAutopilot::MAV_AUTOPILOT_INVALID
                        && hb.mavtype != MavType::MAV_TYPE_GCS
                }
                MavMessage::ATTITUDE(_) | MavMessage::SERVO_OUTPUT_RAW(_) => compid == 1,
                _ => false,
            };
            if !vehicle_like {
                return;
            }
            self.vehicles
                .insert(sysid, VehicleAssembler::new(sysid, self.cfg));
        }
        if let Some(v) = self.vehicles.get_mut(&sysid) {
            v.on_message(compid, msg, out);
        }
    }

    /// A frame's sequence number, for a vehicle already seen (see
    /// [`VehicleAssembler::on_sequence`]).
    pub fn on_sequence(&mut self, sysid: u8, compid: u8, seq: u8) {
        if let Some(v) = self.vehicles.get_mut(&sysid) {
            v.on_sequence(compid, seq);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::dialects::ahcmon::{ATTITUDE_DATA, RAW_IMU_DATA, SERVO_OUTPUT_RAW_DATA};

    fn attitude(ms: u32) -> MavMessage {
        MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: ms,
            rollspeed: 0.1,
            ..Default::default()
        })
    }

    fn outputs(ms: u32, pwm: u16) -> MavMessage {
        MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            // The autopilot's 32-bit micros() wraps every 71.6 min.
            time_usec: ms.wrapping_mul(1000),
            servo1_raw: pwm,
            ..Default::default()
        })
    }

    fn imu(ms: u32) -> MavMessage {
        MavMessage::RAW_IMU(RAW_IMU_DATA {
            time_usec: u64::from(ms) * 1000,
            zacc: -1000,
            ..Default::default()
        })
    }

    /// Feed `msgs` from the autopilot component; the samples that come out.
    fn feed(a: &mut VehicleAssembler, msgs: &[MavMessage]) -> Vec<TelemetrySample> {
        let mut out = Vec::new();
        for m in msgs {
            a.on_message(1, m, &mut out);
        }
        out
    }

    #[test]
    fn a_z_stays_with_one_imu() {
        use crate::protocol::dialects::ahcmon::SCALED_IMU2_DATA;
        let imu2 = |ms: u32| {
            MavMessage::SCALED_IMU2(SCALED_IMU2_DATA {
                time_boot_ms: ms,
                zacc: -1100,
                ..Default::default()
            })
        };
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        // ArduPilot's RAW_SENSORS stream: RAW_IMU (IMU 1, -1000 mG) and SCALED_IMU2 (IMU 2,
        // -1100 mG) of the same instant; IMU 2's ms stamp is not older, so it used to win.
        let got = feed(
            &mut a,
            &[imu(1000), imu2(1000), attitude(1000), outputs(1000, 1500)],
        );
        assert_eq!(got.len(), 1);
        assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
        // IMU 1 silent for over a second: IMU 2 takes over.
        let got = feed(&mut a, &[imu2(2100), attitude(2100), outputs(2100, 1500)]);
        assert!(
            (got[0].az.unwrap() + 1.1 * G0).abs() < 1e-9,
            "{:?}",
            got[0].az
        );
        // IMU 1 back (e.g. its rate requested): the preferred source takes over at once.
        let got = feed(
            &mut a,
            &[imu(2120), imu2(2120), attitude(2120), outputs(2120, 1500)],
        );
        assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
        // RAW_IMU at 2 Hz against SCALED_IMU2 at 50 Hz: the slow one does not take a_z.
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut a, &[imu2(1000), imu2(1020), imu(1030), imu2(1040)]);
        let got = feed(
            &mut a,
            &[imu(1530), imu2(1540), attitude(1540), outputs(1540, 1500)],
        );
        assert!(
            (got[0].az.unwrap() + 1.1 * G0).abs() < 1e-9,
            "{:?}",
            got[0].az
        );
        // SCALED_IMU2 first and slow, RAW_IMU later at 50 Hz: RAW_IMU takes over from its
        // second message.
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut a, &[imu2(1000), imu2(1500), imu(1500)]);
        let got = feed(&mut a, &[imu(1520), attitude(1520), outputs(1520, 1500)]);
        assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
    }

    #[test]
    fn a_32_bit_raw_imu_stamp_is_unwrapped() {
        // Older ArduPilot: RAW_IMU.time_usec is micros() (u32), wrapped after 4294.97 s, like
        // SERVO_OUTPUT_RAW's; ATTITUDE's ms stamp is not.
        let ms = 4_300_000u32;
        let wrapped = (u64::from(ms) * 1000 % (1u64 << 32)) as u32;
        let servo = MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            time_usec: wrapped,
            servo1_raw: 1500,
            ..Default::default()
        });
        let raw = MavMessage::RAW_IMU(RAW_IMU_DATA {
            time_usec: u64::from(wrapped),
            zacc: -1000,
            ..Default::default()
        });
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(
            &mut a,
            &[attitude(ms - 20), raw.clone(), attitude(ms), servo],
        );
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].t, 4300.0);
        assert!(
            got[0].az.is_some_and(|z| (z + G0).abs() < 1e-9),
            "{:?}",
            got[0].az
        );
    }

    #[test]
    fn px4_actuator_output_status_counts_its_active_outputs() {
        use crate::protocol::dialects::ahcmon::ACTUATOR_OUTPUT_STATUS_DATA;
        // PX4 sets `active` to the number of outputs (4 on a quad), not a bitmask (4 = 0b100
        // would leave only output 3).
        let mut actuator = [0.0f32; 32];
        actuator[..5].copy_from_slice(&[1510.4, 1520.0, 1530.0, 1540.0, 1550.0]);
        let px4 = |active: u32, actuator: [f32; 32]| {
            MavMessage::ACTUATOR_OUTPUT_STATUS(ACTUATOR_OUTPUT_STATUS_DATA {
                time_usec: 1_000_000,
                active,
                actuator,
            })
        };
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(&mut a, &[attitude(1000), px4(4, actuator)]);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].pwm[..6], [1510, 1520, 1530, 1540, 0, 0]);
        assert_eq!(a.counters.output_messages, 1);
        // A channel inside the count that reads 0 is unused, and NaN is never a PWM.
        actuator[1] = 0.0;
        actuator[2] = f32::NAN;
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(&mut a, &[attitude(1000), px4(8, actuator)]);
        assert_eq!(got[0].pwm[..6], [1510, 0, 0, 1540, 1550, 0]);
    }

    #[test]
    fn duplicates_and_reordered_messages_are_counted_not_used() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(&mut a, &[attitude(1000), outputs(1000, 1500)]);
        assert_eq!(got.len(), 1);
        // The same instant again, and an older one: dropped and counted.
        let got = feed(
            &mut a,
            &[attitude(1000), attitude(980), outputs(1000, 1500)],
        );
        assert!(got.is_empty());
        assert_eq!((a.counters.duplicates, a.counters.out_of_order), (1, 1));
        // Rates waiting for their outputs are not replaced by older or repeated rates.
        let got = feed(&mut a, &[attitude(1040), attitude(1020), attitude(1040)]);
        assert!(got.is_empty());
        assert_eq!((a.counters.duplicates, a.counters.out_of_order), (2, 2));
        // Outputs older than those held do not replace them; the waiting rates then pair with
        // their own instant's outputs.
        let got = feed(&mut a, &[outputs(1040, 1600), outputs(1000, 1400)]);
        assert_eq!(got.len(), 1);
        assert_eq!((got[0].t, got[0].pwm[0]), (1.04, 1600));
        assert_eq!(a.counters.out_of_order, 3);
        assert_eq!(a.counters.unmatched, 0);
    }

    #[test]
    fn at_100_hz_rates_never_pair_with_the_next_instants_outputs() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        // 100 Hz, outputs stamped with their own instant, in step.
        for k in 0..20 {
            let ms = 1000 + 10 * k;
            assert_eq!(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]).len(), 1);
        }
        // The outputs of one instant are lost; rates wait and the next instant's outputs
        // (10 ms later, inside the 15 ms default) must not be taken for them.
        let got = feed(
            &mut a,
            &[attitude(1200), attitude(1210), outputs(1210, 1600)],
        );
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].t, 1.21);
        let got = feed(&mut a, &[attitude(1220), outputs(1230, 1700)]);
        assert!(got.is_empty(), "paired with a neighbour: {got:?}");
        assert_eq!(a.counters.unmatched, 1);
    }

    #[test]
    fn one_stale_message_is_not_a_reboot() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut a, &[attitude(600_000), outputs(600_000, 1500)]);
        // A copy from a second link, 5 s late, then the stream goes on.
        let got = feed(
            &mut a,
            &[attitude(595_000), attitude(600_020), outputs(600_020, 1500)],
        );
        assert_eq!(got.len(), 1);
        assert!(!a.rebooted);
        assert_eq!((a.counters.reboots, a.counters.out_of_order), (0, 1));
    }

    #[test]
    fn a_reboot_drops_the_sample_waiting_for_its_az_and_starts_the_new_clock() {
        // Late in a u32-µs wrap period of SERVO_OUTPUT_RAW (3000 s of uptime), so that the
        // outputs' stamps after the reboot must unwrap behind the clock too.
        let up = 3_000_000;
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(&mut a, &[attitude(up), outputs(up, 1500), imu(up)]);
        assert_eq!(got.len(), 1);
        // The next instant's IMU message is lost; then the vehicle reboots.
        let got = feed(&mut a, &[attitude(up + 20), outputs(up + 20, 1500)]);
        assert!(got.is_empty(), "waits for its a_z");
        let mut after = vec![];
        for k in 0..60 {
            let ms = 2_000 + 20 * k;
            after.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500), imu(ms)]));
        }
        assert!(a.rebooted);
        assert_eq!(a.counters.reboots, 1);
        assert_eq!(a.counters.dropped_at_reboot, 1);
        // The new boot's first half second (25 instants of ATTITUDE and outputs, the clock's
        // messages) confirmed it: not reordered.
        assert_eq!(
            (a.counters.out_of_order, a.counters.confirming_reboot),
            (0, 50)
        );
        // Nothing of the old boot comes out after it; the new clock's instants do, once half a
        // second of it has confirmed the reboot.
        assert!(after.iter().all(|s| s.t < 10.0), "{after:?}");
        assert!(after.len() >= 30, "{}", after.len());
    }

    #[test]
    fn a_reboot_after_a_u32_wrap_period_of_uptime_is_seen_and_the_new_flight_kept() {
        // 5000 s of uptime: SERVO_OUTPUT_RAW's µs stamps have wrapped once, and the new boot's
        // (2 s) unwrapped next to the old clock read 4297 s. The reboot was never confirmed
        // and every later message was dropped as reordered.
        let up = 5_000_000;
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let got = feed(&mut a, &[attitude(up), outputs(up, 1500)]);
        assert_eq!(
            got.len(),
            1,
            "the old boot's stamps unwrap next to its clock"
        );
        let mut after = vec![];
        for k in 0..100 {
            let ms = 2_000 + 20 * k;
            after.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
        }
        assert_eq!(a.counters.reboots, 1);
        assert!(after.iter().all(|s| s.t < 10.0), "{after:?}");
        // Half a second of the new clock confirms the reboot; the rest of it comes out.
        assert!(after.len() >= 70, "{}", after.len());
        // The same with the outputs first at each instant.
        let mut b = VehicleAssembler::new(1, AssemblerConfig::default());
        feed(&mut b, &[outputs(up, 1500), attitude(up)]);
        let mut after = vec![];
        for k in 0..100 {
            let ms = 2_000 + 20 * k;
            after.extend(feed(&mut b, &[outputs(ms, 1500), attitude(ms)]));
        }
        assert_eq!(b.counters.reboots, 1);
        assert!(after.len() >= 70, "{}", after.len());
    }

    #[test]
    fn one_message_stamped_far_ahead_does_not_move_the_clock() {
        // A CRC-valid ATTITUDE with a wild time_boot_ms (2^31 ms) in a steady stream: it used
        // to move the clock 24 days ahead, and the rest of the flight read as reordered.
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut got = vec![];
        for k in 0..200 {
            let ms = 60_000 + 20 * k;
            if k == 50 {
                got.extend(feed(&mut a, &[attitude(1 << 31)]));
            }
            got.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
        }
        assert_eq!(got.len(), 200);
        assert!(got.iter().all(|s| s.t < 70.0));
        assert_eq!(a.counters.ahead_of_clock, 1);
        assert_eq!((a.counters.out_of_order, a.counters.reboots), (0, 0));
    }

    #[test]
    fn a_log_that_starts_with_wrapped_output_stamps_takes_the_attitude_clock() {
        // 21 h of uptime (as in rust-mavlink-log.tlog): the first message, SERVO_OUTPUT_RAW,
        // sets the clock from its wrapped µs stamp, 17 wrap periods behind the ATTITUDE's.
        let up = 76_674_000;
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut got = feed(&mut a, &[outputs(up - 250, 1500)]);
        for k in 0..50 {
            let ms = up + 250 * k;
            got.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
        }
        assert_eq!(got.len(), 50);
        assert!(got.iter().all(|s| s.t > 76_000.0), "{:?}", got[0]);
        assert_eq!((a.counters.ahead_of_clock, a.counters.out_of_order), (0, 0));
    }

    #[test]
    fn after_a_link_outage_the_stream_goes_on_from_its_second_message() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut got = vec![];
        for k in (0..50).chain(150..200) {
            // 2 s with nothing between k = 49 and k = 150; an IMU message between each
            // instant's rates and outputs (it is on no clock and decides nothing).
            let ms = 60_000 + 20 * k;
            got.extend(feed(&mut a, &[attitude(ms), imu(ms), outputs(ms, 1500)]));
        }
        // The first message after the outage waits for a second on its clock, then both count.
        assert_eq!(a.counters.ahead_of_clock, 0);
        assert_eq!(got.len(), 100);
        assert_eq!(a.counters.out_of_order, 0);
    }

    #[test]
    fn a_lagging_links_bursts_of_old_instants_are_no_reboot() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        for k in 0..100 {
            let ms = 600_000 + 20 * k;
            feed(&mut a, &[attitude(ms), outputs(ms, 1500)]);
            // The same flight through a second link, 3 s late, in bursts between live ones.
            if k % 10 == 0 {
                feed(&mut a, &[attitude(ms - 3000), outputs(ms - 3000, 1500)]);
            }
        }
        assert!(!a.rebooted);
        assert_eq!(a.counters.reboots, 0);
        assert_eq!(a.counters.samples, 100);
        assert_eq!(a.counters.out_of_order, 20);
    }

    #[test]
    fn sequence_numbers_count_lost_frames_across_the_wrap_and_take_late_ones_off() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut feed = |seqs: &[u8]| {
            for &s in seqs {
                a.on_sequence(1, s);
            }
            a.counters.lost_frames
        };
        // 253, 254 lost; the wrap from 255 to 0 loses nothing.
        assert_eq!(feed(&[250, 251, 252, 255, 0, 1]), 2);
        // A duplicate is no loss; a late frame (5 after 7) is taken off, its duplicate not.
        assert_eq!(feed(&[1, 3, 4, 7, 5, 5]), 2 + 1 + 2 - 1);
        // An outage of 150 frames (a second or two of radio dropout), then a stream with one
        // more lost.
        assert_eq!(feed(&[158, 159, 161]), 4 + 150 + 1);
        // A jump of 64 or more clears the window: what came before it is not "late".
        assert_eq!(feed(&[240, 100]), 155 + 78 + 115);
        // Another component's counter is not the autopilot's.
        a.on_sequence(2, 100);
        assert_eq!(a.counters.lost_frames, 348);
    }

    /// A frame from before the first one is not a late arrival of something counted lost.
    #[test]
    fn a_frame_older_than_the_first_takes_no_loss_off() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        for s in [10, 12, 5] {
            a.on_sequence(1, s);
        }
        assert_eq!(a.counters.lost_frames, 1);
    }

    /// A reboot restarts the sequence: the jump to the new boot's numbers is no loss.
    #[test]
    fn a_reboot_takes_back_the_jump_of_its_sequence() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut out = vec![];
        let send = |a: &mut VehicleAssembler, out: &mut Vec<TelemetrySample>, ms: u32, seq: u8| {
            a.on_message(1, &attitude(ms), out);
            a.on_sequence(1, seq);
        };
        for (k, ms) in (100_000..110_000).step_by(20).enumerate() {
            send(&mut a, &mut out, ms, k as u8);
        }
        assert_eq!(a.counters.lost_frames, 0);
        // The new boot's counter starts at 0 (and one of its frames, at 2 s, is lost).
        for (k, ms) in (1_000..3_000).step_by(20).enumerate() {
            send(&mut a, &mut out, ms, (k + usize::from(ms >= 2_000)) as u8);
        }
        assert_eq!(a.counters.reboots, 1);
        assert_eq!(a.counters.lost_frames, 1);
    }

    /// The same when the new boot speaks first with unstamped frames (a HEARTBEAT, as
    /// ArduPilot and our simulator do): their jump comes before the reboot is suspected. A
    /// loss of the old boot before its last stamped frame stays counted.
    #[test]
    fn a_reboot_takes_back_the_jump_of_the_new_boots_unstamped_frames() {
        use crate::protocol::dialects::ahcmon::HEARTBEAT_DATA;
        let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut out = vec![];
        let send = |a: &mut VehicleAssembler, out: &mut Vec<_>, msg: &MavMessage, seq: &mut u8| {
            a.on_message(1, msg, out);
            a.on_sequence(1, *seq);
            *seq = seq.wrapping_add(1);
        };
        // 5593 frames (the last numbered 5592 mod 256 = 216), two lost near the end.
        let mut seq = 0u8;
        for (k, ms) in (100_000..100_000 + 20 * 5593).step_by(20).enumerate() {
            if k == 5590 {
                seq = seq.wrapping_add(2);
            }
            send(&mut a, &mut out, &attitude(ms), &mut seq);
        }
        assert_eq!(a.counters.lost_frames, 2);
        let mut seq = 0u8;
        send(&mut a, &mut out, &heartbeat, &mut seq);
        send(&mut a, &mut out, &heartbeat, &mut seq);
        for ms in (1_000..3_000).step_by(20) {
            send(&mut a, &mut out, &attitude(ms), &mut seq);
        }
        assert_eq!(a.counters.reboots, 1);
        assert_eq!(a.counters.lost_frames, 2);
    }

    /// Another component claiming to be the autopilot first does not hide the autopilot's
    /// (component 1) samples.
    #[test]
    fn the_autopilot_component_takes_over_from_an_earlier_claimant() {
        use crate::protocol::dialects::ahcmon::HEARTBEAT_DATA;
        let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            ..Default::default()
        });
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut out = vec![];
        a.on_message(2, &heartbeat, &mut out);
        assert_eq!(a.info.compid, Some(2));
        a.on_message(1, &heartbeat, &mut out);
        assert_eq!(a.info.compid, Some(1));
        // Component 2 cannot take it back.
        a.on_message(2, &heartbeat, &mut out);
        assert_eq!(a.info.compid, Some(1));
        for ms in (1000..1100).step_by(20) {
            a.on_message(1, &attitude(ms), &mut out);
            a.on_message(1, &outputs(ms, 1500), &mut out);
        }
        assert_eq!(out.len(), 5);
    }
}
