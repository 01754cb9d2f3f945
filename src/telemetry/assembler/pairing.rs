//! Rates and outputs → one sample per instant.
//!
//! Co-timed streams (ArduPilot stamps ATTITUDE, RATE and the outputs from one loop) pair
//! directly: rates and outputs within the skew tolerance are one sample at the rates'
//! instant, or at the outputs' when the rates carry only a millisecond stamp (ATTITUDE's
//! `time_boot_ms`) and the outputs a microsecond one. Streams that are not co-timed (outputs logged slower than the rates, PX4's
//! outputs a few ms after the gyro sample, a slow telemetry stream) pair by interpolation:
//! outputs stamped between two *consecutive* rate instants (no more than 1.5 rate periods
//! apart, so no rate instant was lost between them) make a sample at the outputs' own
//! instant, with the rates interpolated linearly between the two. The command is what the
//! model holds over a step, so it is never interpolated; the rates are the state the model
//! predicts, and within one rate period they are smooth enough for a straight line (their
//! error is second order in the period). Each output message makes at most one sample, each
//! rate instant at most one co-timed sample.

use super::{Stamped, TelemetrySample, VehicleAssembler};

/// Two rate instants further apart than this many rate periods have a lost one between
/// them: outputs between them are not interpolated.
const INTERPOLATE_MAX_PERIODS: f64 = 1.5;

/// Smooth an interval estimate; a longer interval (a lost message, or a stream that slowed
/// down) does not stretch it at once.
fn learn_period(period: &mut Option<f64>, dt: f64) {
    if !(dt > 0.0 && dt < 1.0) {
        return;
    }
    *period = Some(match *period {
        None => dt,
        Some(p) if dt < 1.5 * p => 0.9 * p + 0.1 * dt,
        Some(p) => p * 1.02,
    });
}

fn lerp3(a: &[f64; 3], b: &[f64; 3], w: f64) -> [f64; 3] {
    [0, 1, 2].map(|i| a[i] + w * (b[i] - a[i]))
}

/// Angles interpolated the short way round (yaw wraps at ±π).
fn lerp_angles(a: &[f64; 3], b: &[f64; 3], w: f64) -> [f64; 3] {
    use std::f64::consts::{PI, TAU};
    [0, 1, 2].map(|i| {
        let d = (b[i] - a[i] + PI).rem_euclid(TAU) - PI;
        a[i] + w * d
    })
}

impl VehicleAssembler {
    /// The pairing tolerance (s): the configured one, or under half the rate period if shorter.
    pub fn max_skew(&self) -> f64 {
        self.rate_period
            .map_or(self.cfg.max_skew_s, |p| self.cfg.max_skew_s.min(0.45 * p))
    }

    /// Outputs slower than the rates (by more than half again): rate instants without outputs
    /// are expected then, not `unmatched`.
    fn outputs_slower(&self) -> bool {
        matches!((self.output_period, self.rate_period), (Some(o), Some(r)) if o > 1.5 * r)
    }

    /// A rate instant at `t` (s): rates (rad/s) and attitude (rad).
    pub(super) fn on_rates(
        &mut self,
        t: f64,
        rates: [f64; 3],
        attitude: [f64; 3],
    ) -> Option<TelemetrySample> {
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
        if let Some(prev) = self.rates {
            // Rates still waiting for their outputs are newer, or the same instant.
            if t < prev.t {
                self.counters.out_of_order += 1;
                return None;
            }
            if t == prev.t {
                self.counters.duplicates += 1;
                return None;
            }
            if !self.rates_used && !self.outputs_slower() {
                self.counters.unmatched += 1;
            }
            learn_period(&mut self.rate_period, t - prev.t);
        }
        self.rates_prev = self.rates;
        self.rates = Some(Stamped {
            t,
            v: (rates, attitude),
        });
        self.rates_used = false;
        self.try_emit().or_else(|| self.try_interpolate())
    }

    /// New outputs, unless older than those held (a reordered message: counted, dropped).
    pub(super) fn set_outputs(&mut self, t: f64, pwm: [u16; 16]) -> Option<TelemetrySample> {
        self.counters.output_messages += 1;
        if let Some(o) = self.outputs {
            if t < o.t {
                self.counters.out_of_order += 1;
                return None;
            }
            if !self.outputs_used && !self.outputs_slower() {
                // Superseded before any sample was made of them.
                self.counters.unpaired_outputs += 1;
            }
            learn_period(&mut self.output_period, t - o.t);
        }
        self.outputs = Some(Stamped { t, v: pwm });
        self.outputs_used = false;
        self.try_emit().or_else(|| self.try_interpolate())
    }

    /// Rates and outputs of the same instant (within the skew tolerance).
    pub(super) fn try_emit(&mut self) -> Option<TelemetrySample> {
        let rates = self.rates?;
        let outputs = self.outputs?;
        let max_skew = self.max_skew();
        if self.rates_used || self.outputs_used || (rates.t - outputs.t).abs() > max_skew {
            return None;
        }
        // The finer clock of the two: a millisecond stamp cannot carry a 2.5 ms period (at
        // 400 Hz ATTITUDE's intervals read 2 and 3 ms), the outputs' microsecond one can.
        let t = if self.rates_ms_clock {
            outputs.t
        } else {
            rates.t
        };
        if self.last_sample_t.is_some_and(|last| t <= last) {
            return None;
        }
        self.rates_used = true;
        self.outputs_used = true;
        Some(self.sample(t, rates.v.0, rates.v.1, outputs.v))
    }

    /// Outputs between two consecutive rate instants: a sample at the outputs' instant.
    fn try_interpolate(&mut self) -> Option<TelemetrySample> {
        let outputs = self.outputs?;
        let (a, b) = (self.rates_prev?, self.rates?);
        let period = self.rate_period?;
        if self.outputs_used
            || !(a.t < outputs.t && outputs.t < b.t)
            || b.t - a.t > INTERPOLATE_MAX_PERIODS * period
            || self.last_sample_t.is_some_and(|last| outputs.t <= last)
        {
            return None;
        }
        let w = (outputs.t - a.t) / (b.t - a.t);
        self.outputs_used = true;
        self.counters.interpolated += 1;
        let rates = lerp3(&a.v.0, &b.v.0, w);
        let attitude = lerp_angles(&a.v.1, &b.v.1, w);
        Some(self.sample(outputs.t, rates, attitude, outputs.v))
    }

    fn sample(
        &mut self,
        t: f64,
        rates: [f64; 3],
        attitude: [f64; 3],
        pwm: [u16; 16],
    ) -> TelemetrySample {
        self.last_sample_t = Some(t);
        self.counters.samples += 1;
        let max_skew = self.max_skew();
        let az = self.az.filter(|a| (a.t - t).abs() <= max_skew).map(|a| a.v);
        TelemetrySample {
            t,
            rates,
            attitude,
            az,
            pwm,
            armed: self.info.armed,
            rel_alt: self.rel_alt,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::telemetry::AssemblerConfig;

    fn pwm(v: u16) -> [u16; 16] {
        let mut p = [0; 16];
        p[0] = v;
        p
    }

    #[test]
    fn outputs_between_two_rate_instants_get_the_rates_of_their_instant() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        // Rates at 100 Hz, outputs at 10 Hz stamped half way between two rate instants
        // (beyond the skew tolerance, 0.45 of the rate period, from both).
        let mut samples = Vec::new();
        for k in 0..100 {
            let t = 1.0 + 0.01 * f64::from(k);
            let p = f64::from(k); // a ramp: interpolation is exact on it
            samples.extend(a.on_rates(t, [p, -p, 0.5 * p], [0.0; 3]));
            if k % 10 == 3 {
                samples.extend(a.set_outputs(t + 0.005, pwm(1500 + k as u16)));
            }
        }
        assert_eq!(samples.len(), 10, "{samples:?}");
        for s in &samples {
            let k = ((s.t - 1.0) / 0.01 + 1e-9).floor();
            assert_eq!(f64::from(s.pwm[0] - 1500), k);
            let want = (s.t - 1.0) / 0.01;
            assert!((s.rates[0] - want).abs() < 1e-9, "{} vs {want}", s.rates[0]);
            assert!((s.rates[1] + want).abs() < 1e-9);
        }
        assert_eq!(a.counters.interpolated, 10);
        // Until the second output message shows the outputs' period, rate instants without
        // outputs count as unmatched (the 13 before it); none after.
        assert_eq!(a.counters.unmatched, 13);
    }

    #[test]
    fn no_interpolation_across_a_lost_rate_instant() {
        let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
        let mut n = 0;
        for k in 0..20 {
            let t = 1.0 + 0.02 * f64::from(k);
            n += a.on_rates(t, [0.0; 3], [0.0; 3]).into_iter().count();
            n += a.set_outputs(t, pwm(1500)).into_iter().count();
        }
        assert_eq!(n, 20);
        // The rate instant at 1.40 is lost; its outputs lie between 1.38 and 1.42 (2 periods).
        n += a.set_outputs(1.40, pwm(1500)).into_iter().count();
        n += a.on_rates(1.42, [0.0; 3], [0.0; 3]).into_iter().count();
        n += a.set_outputs(1.42, pwm(1500)).into_iter().count();
        assert_eq!(n, 21, "the outputs at 1.40 make no sample");
        assert_eq!(a.counters.interpolated, 0);
        assert_eq!(a.counters.unpaired_outputs, 1);
    }

    #[test]
    fn yaw_is_interpolated_the_short_way_round() {
        let y = lerp_angles(&[0.0, 0.0, 3.1], &[0.0, 0.0, -3.1], 0.5);
        assert!((y[2].abs() - std::f64::consts::PI).abs() < 1e-9, "{y:?}");
    }
}
