//! Frames → telemetry samples, per vehicle (system id), on the vehicle's own clock.
//!
//! A sample needs body rates (ATTITUDE) and actuator outputs (SERVO_OUTPUT_RAW or
//! ACTUATOR_OUTPUT_STATUS) for the same instant; a vertical specific force from HIGHRES_IMU,
//! SCALED_IMU* or RAW_IMU is added when one is that recent. Outputs older than the skew
//! tolerance are never reused silently: the rates wait for fresh outputs, and an instant that
//! never gets them is counted as `unmatched`.

use crate::protocol::dialects::ahcmon::{MavAutopilot, MavMessage, MavModeFlag, MavType};
use crate::telemetry::identity;
use serde::Serialize;
use std::collections::BTreeMap;

/// Standard gravity (ArduPilot's GRAVITY_MSS): RAW_IMU / SCALED_IMU accelerations are in mG.
mod clock;
mod pairing;
mod record;

const G0: f64 = 9.80665;
/// Largest backwards step of the vehicle clock treated as reordering; more is a reboot once
/// messages on the new clock have covered `REBOOT_HOLD_S` of it with no message on the old
/// clock in between (a lagging second link sends bursts of old instants, not a clock that
/// runs on), all within `REBOOT_CONFIRM_S` of the first.
const REBOOT_BACKSTEP_S: f64 = 1.0;
pub const REBOOT_HOLD_S: f64 = 0.5;
const REBOOT_CONFIRM_S: f64 = 5.0;
/// Where frames carry their arrival time (a live link's, a tlog's receive stamps), a new
/// boot's clock is confirmed only once its messages have arrived over at least this long, with
/// none on the old clock in between: two forged ATTITUDEs sent back to back, stamped 1.0 and
/// 1.6 s, used to confirm a "reboot" and reset the filters; a real vehicle's messages on the
/// old clock keep coming within it and refute them. An arrival clock that stands still (a log
/// written without receive times) tells nothing. (A jump ahead is not held to the arrival
/// clock: logs whose message types stamp from clocks seconds apart make such jumps; one that
/// the next messages go back on is undone instead, see `clock_before_jump`.)
pub const REBOOT_ARRIVAL_S: f64 = 0.25;

/// Most parameters kept per vehicle (ArduPilot and PX4 have 1,000-1,500): a new name past
/// these is dropped and counted, a known one still updated, so a flood of made-up names
/// (300,000 grew the memory by 26 MB) neither grows the state nor displaces the real ones.
pub const MAX_PARAMS: usize = 4096;

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
    /// PARAM_VALUE of new names past [`MAX_PARAMS`], dropped.
    pub params_dropped: u64,
    /// Jumps of the vehicle clock refused: a new boot's whose messages did not arrive over
    /// [`REBOOT_ARRIVAL_S`] (each message that would have confirmed it, dropped), and jumps
    /// ahead undone by the next messages.
    pub clock_jumps_refused: u64,
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
    /// Samples whose rates were interpolated between the two rate instants around their
    /// outputs' instant (streams not co-timed: slower outputs, or another clock).
    pub interpolated: u64,
    /// Output messages no sample was made of: no rates within the skew tolerance, and no
    /// two consecutive rate instants around them (counted when the rates come at least as
    /// often as the outputs; otherwise the rate instants are `unmatched`).
    pub unpaired_outputs: u64,
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
    /// The board's identity (`telemetry::identity`), from the first message that gives one.
    pub board_uid: Option<String>,
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
    /// The rates' stamp is ATTITUDE's millisecond `time_boot_ms`, coarser than the outputs'
    /// microsecond one: a co-timed sample then takes the outputs' stamp (`pairing.rs`).
    rates_ms_clock: bool,
    /// The rate instant before `rates`: with it, outputs stamped between two rate instants
    /// get rates interpolated to their own instant (`pairing.rs`).
    rates_prev: Option<Stamped<([f64; 3], [f64; 3])>>,
    outputs: Option<Stamped<[u16; 16]>>,
    outputs_used: bool,
    /// Smoothed interval between output messages (s), once seen.
    output_period: Option<f64>,
    /// The latest attitude of a log that records it apart from the rates.
    attitude: [f64; 3],
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
    /// The arrival time of the frame being read (s, any origin; `None`: not known) and of the
    /// reboot candidate's first ([`REBOOT_ARRIVAL_S`]).
    arrival: Option<f64>,
    arrival_at_candidate: Option<f64>,
    /// The clock before the last jump ahead and the jump's target, until the clock has run
    /// `REBOOT_CONFIRM_S` past it: a message back on the old clock undoes the jump (two forged
    /// frames far ahead, then the real stream) instead of reading as a reboot.
    clock_before_jump: Option<(f64, f64)>,
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
            rates_ms_clock: false,
            rates_prev: None,
            outputs: None,
            outputs_used: false,
            output_period: None,
            attitude: [0.0; 3],
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
            arrival: None,
            arrival_at_candidate: None,
            clock_before_jump: None,
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

    fn use_message(&mut self, compid: u8, msg: &MavMessage, out: &mut Vec<TelemetrySample>) {
        let rate_instant = match msg {
            MavMessage::ATTITUDE(a) if self.is_autopilot_component(compid) => {
                Some(f64::from(a.time_boot_ms) * 1e-3)
            }
            _ => None,
        };
        self.release_pending(rate_instant, out);
        let emitted = self.message(compid, msg);
        self.deliver(emitted, out);
    }

    /// A new rate instant releases a sample still waiting for its a_z, without it; one from
    /// a clock far behind (stale, or a reboot) does not.
    fn release_pending(&mut self, rate_instant: Option<f64>, out: &mut Vec<TelemetrySample>) {
        if rate_instant.is_some_and(|t| !self.behind(t)) {
            out.extend(self.pending.take());
        }
    }

    /// A sample just made goes out, or waits for its instant's a_z when the vehicle sends one;
    /// a waiting sample takes an a_z that has come.
    fn deliver(&mut self, emitted: Option<TelemetrySample>, out: &mut Vec<TelemetrySample>) {
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
                    if self.info.params.len() < MAX_PARAMS || self.info.params.contains_key(name) {
                        self.info.params.insert(name.to_string(), p.param_value);
                    } else {
                        self.counters.params_dropped += 1;
                    }
                }
                None
            }
            MavMessage::STATUSTEXT(s) => {
                let text = s.text.to_str().unwrap_or("");
                self.note_text(text);
                None
            }
            MavMessage::AUTOPILOT_VERSION(v) => {
                if self.info.board_uid.is_none() {
                    self.info.board_uid = identity::from_autopilot_version(v.uid, &v.uid2);
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
                let rates = [v[0], v[1], v[2]].map(f64::from);
                let att = [v[3], v[4], v[5]].map(f64::from);
                self.rates_ms_clock = true;
                self.on_rates(t, rates, att)
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
        self.on_frame_at(sysid, compid, msg, None, out);
    }

    /// [`Self::on_frame`] with the frame's arrival time (s, any origin): jumps of the
    /// vehicle clock must agree with it ([`REBOOT_ARRIVAL_S`]).
    pub fn on_frame_at(
        &mut self,
        sysid: u8,
        compid: u8,
        msg: &MavMessage,
        arrival: Option<f64>,
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
            v.arrival = arrival.filter(|a| a.is_finite());
            v.on_message(compid, msg, out);
        }
    }

    /// One record of a vehicle's own log (DataFlash, ULog: one vehicle per file).
    pub fn on_record(
        &mut self,
        sysid: u8,
        record: &crate::telemetry::Record,
        out: &mut Vec<TelemetrySample>,
    ) {
        self.vehicles
            .entry(sysid)
            .or_insert_with(|| VehicleAssembler::new(sysid, self.cfg))
            .on_record(record, out);
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
mod tests;
