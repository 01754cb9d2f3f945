//! The calibration stage: a healthy stretch of flight stored, then the vehicle's magnitudes
//! fitted against the profile's geometry (or, for `dynamics = "arx"`, a discrete model
//! identified), or a profile `ahcmon calibrate` identified used as it is.

use super::holes::fill_short_holes;
use super::running::U_HISTORY;
use super::{Stage, VehiclePipeline};
use crate::diagnose::vehicle::gate::AxisFailure;
use crate::model::MAX_ACTUATORS;
use crate::model::calibrate::{CalibrationSample, calibrate_arx, calibrate_scaled};
use crate::output::Sink;
use crate::telemetry::profile::MAX_GUST_FACTOR;
use crate::telemetry::profile::{Dynamics, VehicleKind};
use crate::telemetry::{Profile, TelemetrySample};

#[derive(Clone, Copy)]
pub(super) struct StoredSample {
    pub(super) t: f64,
    pub(super) rates: [f64; 3],
    pub(super) u: [f64; MAX_ACTUATORS],
    pub(super) az: Option<f64>,
}

/// Longest command delay the identification considers (s).
const MAX_DELAY_S: f64 = 0.12;
/// Longest interval between two calibration samples, in median sample periods, that still
/// counts as one step: a dropped sample doubles it, and the change over it is not one step's.
const CALIBRATION_MAX_INTERVAL: f64 = 1.5;

/// A calibration stretch shorter than this (s) is warned about.
const SHORT_CALIBRATION_S: f64 = 10.0;
/// The time constant (s) of the autopilots' default attitude loops, which the outputs follow:
/// ArduCopter's and TradHeli's angle P of 4.5 /s (ATC_ANG_RLL_P, ATC_ANG_PIT_P) for rotorcraft;
/// ArduPlane's RLL2SRV_TCONST and PTCH2SRV_TCONST of 0.5 s for planes (PX4's are shorter:
/// MC_ROLL_P 6.5 /s, FW_R_TC 0.4 s, so for PX4 the rule below is necessary, not sufficient).
fn command_time_constant_s(kind: VehicleKind) -> f64 {
    match kind {
        VehicleKind::Multirotor | VehicleKind::Helicopter => 1.0 / 4.5,
        VehicleKind::Plane => 0.5,
    }
}

/// The longest sample period the model supports, as a fraction of the command time constant.
/// The model holds each sample's outputs over the step to the next; an output following a
/// first-order response of time constant `tau` averages over a step `dt` to within `dt/(2 tau)`
/// of its change of the held value, so at `dt = tau/2` a quarter of every command change is
/// misattributed: as much as the smallest loss decided (gain 0.75). Slower, no fault decision
/// is supported.
const MAX_PERIOD_PER_TIME_CONSTANT: f64 = 0.5;

/// The slowest sample rate (Hz) a vehicle of `kind` can be estimated at.
pub fn min_sample_rate_hz(kind: VehicleKind) -> f64 {
    1.0 / (MAX_PERIOD_PER_TIME_CONSTANT * command_time_constant_s(kind))
}

/// Rate spread (standard deviation, rad/s) above which a calibration stretch manoeuvred: about
/// 3° of rate a second, several times a still hover's gust response and a few times less than
/// a manoeuvre's (the figures: docs/tuning-log.md).
const MOVED_RATE_STD: f64 = 0.05;

/// The standard deviation of one rate axis over a calibration stretch.
fn rate_spread(samples: &[CalibrationSample], axis: usize) -> f64 {
    let n = samples.len().max(1) as f64;
    let mean = samples.iter().map(|s| s.rates[axis]).sum::<f64>() / n;
    (samples
        .iter()
        .map(|s| (s.rates[axis] - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// The calibrated profile's rate and noise levels: the process noise from what the model could
/// not explain on the healthy stretch (rates, then a_z), but never below the profile's: a calm
/// stretch (a still hover) would otherwise make the filters trust the model more than any
/// manoeuvre or fault transient deserves.
fn set_noise_from_fit(calibrated: &mut Profile, residual_std: &[f64], dt: f64) {
    calibrated.rate_hz = (1e3 / dt).round() / 1e3;
    let rates = &residual_std[..3.min(residual_std.len())];
    let rate_sd = (rates.iter().map(|x| x * x).sum::<f64>() / rates.len().max(1) as f64).sqrt();
    calibrated.noise.rate_process = rate_sd.max(calibrated.noise.rate_process);
    if calibrated.model.measure_az
        && let Some(sd) = residual_std.get(3)
    {
        calibrated.noise.az = sd.max(calibrated.noise.az);
    }
}

/// The sample period: the median interval among those near the shortest common one (within
/// half of the lower quartile's either way). A plain median reads a period twice as long when
/// every third sample is lost (intervals 20, 40, 20, 40 ms: the filters then ran 20 ms steps as
/// 40 ms ones); the quartile stands while fewer than three intervals in four span a hole.
pub(super) fn sample_period(ts: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = ts.collect();
    let mut d: Vec<f64> = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return 0.02;
    }
    d.sort_by(f64::total_cmp);
    let quartile = d[d.len() / 4];
    let near: Vec<f64> = d
        .iter()
        .copied()
        .filter(|x| (0.5 * quartile..=1.5 * quartile).contains(x))
        .collect();
    near[near.len() / 2]
}

fn kind_name(kind: VehicleKind) -> &'static str {
    match kind {
        VehicleKind::Multirotor => "multirotor",
        VehicleKind::Helicopter => "helicopter",
        VehicleKind::Plane => "plane",
    }
}

impl VehiclePipeline {
    /// A sample of the healthy stretch: stored until the stretch is complete.
    pub(super) fn calibrating(&mut self, s: &TelemetrySample, sink: &mut dyn Sink) {
        let Stage::Calibrating {
            profile,
            samples,
            raw,
        } = &mut self.stage
        else {
            return;
        };
        let warned = &mut self.warned_missing_output;
        let Some(u) = Self::commands(&mut self.counters, warned, self.sysid, profile, s, sink)
        else {
            return;
        };
        samples.push(StoredSample {
            t: s.t,
            rates: s.rates,
            u,
            az: s.az,
        });
        raw.push(*s);
        let start = samples[0].t;
        if let Some(until) = self.cfg.calibrate_until
            && until <= start
        {
            self.fail(
                format!(
                    "the calibration stretch was chosen to end at t={until} s, before it can start (airborne and settled at t={start:.2} s): give a later end"
                ),
                sink,
            );
            return;
        }
        let done = match self.cfg.calibrate_until {
            Some(until) => s.t >= until,
            None => s.t - start >= Self::stretch_s(&self.cfg, profile).unwrap_or(f64::INFINITY),
        };
        if done {
            if self.cfg.fit_in_background {
                self.fit_in_background(Self::end_calibration, sink);
            } else {
                self.end_calibration(sink);
            }
        }
    }

    /// The stretch is complete: fit, and start estimating.
    fn end_calibration(&mut self, sink: &mut dyn Sink) {
        let Stage::Calibrating {
            profile,
            samples,
            raw,
        } = &mut self.stage
        else {
            return;
        };
        let profile = (**profile).clone();
        let samples = std::mem::take(samples);
        self.stretch = std::mem::take(raw);
        self.start_running(profile, &samples, sink);
        self.stretch = Vec::new();
    }

    /// The calibration stretch was unusable (too short, too many holes): not the vehicle, so
    /// the next stretch may do; a stretch the user chose is not retried.
    fn calibration_failed(&mut self, why: String, sink: &mut dyn Sink) {
        if self.cfg.calibrate_until.is_some() {
            self.fail(format!("calibration failed: {why}"), sink);
        } else {
            sink.message(
                self.sysid,
                &format!("calibration failed: {why}; trying again on the next stretch"),
            );
            self.set_stage(Stage::Grounded, "the calibration failed");
        }
    }

    fn start_running(&mut self, profile: Profile, samples: &[StoredSample], sink: &mut dyn Sink) {
        let dt = sample_period(samples.iter().map(|s| s.t));
        let need_hz = min_sample_rate_hz(profile.vehicle);
        if 1.0 / dt < need_hz {
            let t = samples.last().map_or(0.0, |s| s.t);
            self.cannot_estimate(
                t,
                format!(
                    "the samples (rates with outputs) come at {:.1} Hz, every {:.0} ms; a {} needs >= {need_hz:.1} Hz, for its commands change within a step (the rule: docs/diagnosis.md); raise the stream rates (the ground station's, ArduPilot's SRn_/MAVn_ parameters, --request-rates) or the log's rates",
                    1.0 / dt,
                    dt * 1e3,
                    kind_name(profile.vehicle)
                ),
                sink,
            );
            return;
        }
        let l = profile.actuators.len();
        let mut profile = profile;
        // a_z is measured if the vehicle sends an IMU with most samples; those without it are
        // left out and counted (a link that lost one RAW_IMU in ten or more used to switch the whole
        // run to rates only, leaving a multirotor's thrust direction unobserved).
        let with_az = samples.iter().filter(|s| s.az.is_some()).count();
        if profile.model.measure_az && with_az * 2 < samples.len() {
            let why = if with_az == 0 {
                "no IMU acceleration with the rates (HIGHRES_IMU / SCALED_IMU / RAW_IMU)"
                    .to_string()
            } else {
                format!(
                    "IMU acceleration with only {with_az} of {} calibration samples",
                    samples.len()
                )
            };
            sink.message(self.sysid, &format!("{why}; estimating from rates only"));
            profile.model.measure_az = false;
        }
        // An identified model predicts the rates only: a static a_z row cannot follow a
        // helicopter's vertical manoeuvres (the collective's response lags with the rotor), and
        // its errors, slow and correlated with the manoeuvre, would pull the swash servos'
        // estimates. Isolation works in the observable space instead, where what rates cannot
        // see is never blamed on one actuator.
        if profile.model.dynamics == Dynamics::Arx && profile.model.measure_az {
            profile.model.measure_az = false;
        }
        if Self::as_is(&self.cfg, &profile) {
            self.run_identified(profile, samples, dt, sink);
            return;
        }
        // The outputs of sample k act until sample k+1: pair each rate with the previous outputs.
        // A pair whose interval is not one period (a dropped or late sample, a link gap) is left
        // out; the next pair then starts a new run, so no fit row spans the hole. A sample
        // without a_z still serves the rate axes (left out of the rates' runs, one IMU message
        // lost in ten halved the rows the wind-robust fit could use and biased a gusty quad's
        // roll factor from 1.04 to 0.75) and is only left out of the a_z fit.
        let measure_az = profile.model.measure_az;
        let max_span = MAX_PERIOD_PER_TIME_CONSTANT * command_time_constant_s(profile.vehicle);
        let (grid, filled) = fill_short_holes(samples, dt, CALIBRATION_MAX_INTERVAL, max_span);
        self.counters.calibration_filled += filled;
        let mut shifted: Vec<CalibrationSample> = Vec::with_capacity(grid.len());
        let (mut kept_previous, mut gaps) = (false, 0u64);
        // Each kept sample's position in periods: one after a kept predecessor, else as many as
        // passed (rounded, at least one).
        let mut last_kept: Option<(f64, u64)> = None;
        for pair in grid.windows(2) {
            let (w, measured) = ([&pair[0].0, &pair[1].0], pair[1].1);
            let interval = w[1].t - w[0].t;
            let regular = interval > 0.0 && interval <= CALIBRATION_MAX_INTERVAL * dt;
            gaps += u64::from(!regular);
            let az = if measure_az { w[1].az } else { None };
            let keep = regular;
            self.counters.missing_az +=
                u64::from(regular && measured && measure_az && az.is_none());
            if keep {
                let step = match last_kept {
                    None => 0,
                    Some((_, step)) if kept_previous => step + 1,
                    Some((t, step)) => step + (((w[1].t - t) / dt).round() as u64).max(1),
                };
                last_kept = Some((w[1].t, step));
                shifted.push(CalibrationSample {
                    rates: w[1].rates,
                    u: &w[0].u[..l],
                    az,
                    follows_previous: kept_previous,
                    step,
                    measured,
                });
            }
            kept_previous = keep;
        }
        if filled > 0 {
            sink.message(
                self.sysid,
                &format!(
                    "calibration: {filled} lost samples filled in by straight lines over holes up to {:.0} ms (the fit takes them as history, not as increments)",
                    max_span * 1e3
                ),
            );
        }
        if gaps > 0 {
            self.counters.calibration_gaps += gaps;
            sink.message(
                self.sysid,
                &format!(
                    "calibration: {gaps} gaps in the telemetry (intervals over {CALIBRATION_MAX_INTERVAL} sample periods, or not increasing); the fit leaves out the steps across them"
                ),
            );
        }
        let base = profile.rate_params();
        // Too few usable samples where the stretch had many: the holes left too few runs.
        let holes_note = |e: &crate::model::calibrate::CalibrationError| match e {
            crate::model::calibrate::CalibrationError::TooFew { .. } if gaps + filled > 0 => {
                format!(
                    "; the stretch had {} samples, but a fit row spans consecutive measured ones and its {gaps} gaps and {filled} lost samples leave too few unbroken runs (the link loses too many)",
                    samples.len()
                )
            }
            // In flight time, which a stretch is chosen by.
            crate::model::calibrate::CalibrationError::TooFew { need, .. } => format!(
                " (at a sample every {:.0} ms: {:.1} s of flight after the {} s settle)",
                dt * 1e3,
                *need as f64 * dt,
                self.cfg.settle_s
            ),
            _ => String::new(),
        };
        let identified = if profile.model.dynamics == Dynamics::Arx {
            // Above ~58 Hz the history, not MAX_DELAY_S, bounds the delay searched.
            let max_delay = ((MAX_DELAY_S / dt).round() as usize).min(U_HISTORY - 1);
            match calibrate_arx(&shifted, dt, max_delay, &base) {
                Ok(f) => Some(f),
                // On a stretch with many holes (over one interval in twenty) the scaled
                // geometry, fitted on the same holes, is no fallback: it fits the holes' steps
                // too. The next stretch may do better.
                Err(e) if gaps * 20 > samples.len() as u64 => {
                    let why = match holes_note(&e) {
                        note if !note.is_empty() => format!("the identified model needs {e}{note}"),
                        _ => format!(
                            "the identified model failed ({e}) on a stretch with {gaps} gaps in {} samples (the link loses too many)",
                            samples.len()
                        ),
                    };
                    self.calibration_failed(why, sink);
                    return;
                }
                Err(e) => {
                    sink.message(
                        self.sysid,
                        &format!(
                            "warning: the identified model failed ({e}{}); using the profile's geometry, scaled per axis",
                            holes_note(&e)
                        ),
                    );
                    None
                }
            }
        } else {
            None
        };
        // Rate axes the model does not explain (rule G2): fitted worse than a constant would
        // (a profile that is not this vehicle's, or a stretch that was not healthy flight; an
        // offset-only axis, which a steady hover does not excite, has little to explain and
        // passes down to R² = -1), or left offset-only though the vehicle moved on it.
        let mut failing: Vec<AxisFailure> = Vec::new();
        let worse = |axis: usize, r2: f64| AxisFailure {
            axis,
            why: format!("R²={r2:.2}, worse than a constant"),
        };
        // Said after the fit's summary: rule T1's raised threshold.
        let mut gust_note = None;
        let (calibrated, fit, summary) = if let Some(arx) = identified {
            let mut calibrated = profile.clone();
            set_noise_from_fit(&mut calibrated, &arx.quality.residual_std, dt);
            let axes = ["roll", "pitch", "yaw", "a_z"];
            let mut parts: Vec<String> = arx.quality.r_squared[..3]
                .iter()
                .enumerate()
                .map(|(i, r2)| format!("{} increment R²={r2:.2}", axes[i]))
                .collect();
            if let Some(r2) = arx.quality.r_squared.get(3) {
                let how = if arx.vertical_scaled {
                    "scaled"
                } else {
                    "offset only"
                };
                parts.push(format!("a_z {how} R²={r2:.2}"));
            }
            for (i, r2) in arx.quality.r_squared[..3].iter().enumerate() {
                if *r2 < 0.0 {
                    failing.push(worse(i, *r2));
                }
            }
            let summary = format!(
                "identified model, command delay {} ms: {}",
                (arx.params.delay as f64 * dt * 1e3).round(),
                parts.join(", ")
            );
            calibrated.model.arx = Some(arx.params.clone());
            self.arx = Some(arx);
            (calibrated, None, summary)
        } else {
            let fit = match calibrate_scaled(&shifted, dt, &base) {
                Ok(f) => f,
                Err(e) => {
                    self.calibration_failed(format!("{e}{}", holes_note(&e)), sink);
                    return;
                }
            };
            let mut calibrated = profile.with_rate_params(&fit.params);
            set_noise_from_fit(&mut calibrated, &fit.quality.residual_std, dt);
            // Rule T1, applied where the diagnosis starts (`running::start_stage`): said here,
            // after the fit's summary. The profile keeps the threshold it was calibrated with.
            if let Some(factor) = calibrated.diagnosis.gust_factor(&fit.gusts) {
                let spec = &calibrated.diagnosis;
                let show = |g: [Option<f64>; 3]| {
                    g.map(|g| g.map_or("-".into(), |g| format!("{g:.2}")))
                        .join(", ")
                };
                let capped = if factor >= MAX_GUST_FACTOR {
                    format!(
                        " (at most x{MAX_GUST_FACTOR}: stronger gusts are beyond what the rule was checked on, and may be a slow drift rather than gusts)"
                    )
                } else {
                    String::new()
                };
                gust_note = Some(format!(
                    "gusts x{factor:.2} those the thresholds were set on (roll, pitch, yaw {} against {} rad/s²): the deviation threshold is raised from {:.3} to {:.3}{capped}, to keep its false-alarm rate (rule T1)",
                    show(fit.gusts),
                    show(spec.gusts.map_or([None; 3], |g| g.map(Some))),
                    spec.threshold,
                    spec.threshold * factor
                ));
            }
            let axes = ["roll", "pitch", "yaw", "a_z"];
            for (i, (r2, scaled)) in (fit.quality.r_squared.iter().zip(&fit.scaled))
                .take(3)
                .enumerate()
            {
                let spread = rate_spread(&shifted, i);
                if *r2 < if *scaled { 0.0 } else { -1.0 } {
                    failing.push(worse(i, *r2));
                } else if !scaled && spread >= MOVED_RATE_STD {
                    // Left offset-only though the vehicle manoeuvred: the commands did not
                    // explain its motion on this geometry (a fault in the stretch, or another
                    // frame).
                    failing.push(AxisFailure {
                        axis: i,
                        why: format!(
                            "it moved (rate spread {spread:.2} rad/s) but the commands do not explain that motion on the geometry of {}",
                            profile.name
                        ),
                    });
                }
            }
            let summary: Vec<String> = fit
                .scaled
                .iter()
                .enumerate()
                .map(|(i, sc)| {
                    format!(
                        "{} {} R²={:.2}",
                        axes[i],
                        if *sc {
                            format!("x{:.2}", fit.scale[i])
                        } else {
                            "offset only".into()
                        },
                        fit.quality.r_squared[i]
                    )
                })
                .collect();
            let mut summary = summary.join(", ");
            if fit.gusts.iter().any(Option::is_some) {
                let gusts = fit
                    .gusts
                    .map(|g| g.map_or("-".into(), |g| format!("{g:.2}")));
                summary += &format!("; gusts {} rad/s²", gusts.join(", "));
            }
            (calibrated, Some(fit), summary)
        };
        let span = samples.last().map_or(0.0, |s| s.t) - samples[0].t;
        sink.message(
            self.sysid,
            &format!(
                "calibrated on {span:.1} s ({} samples, dt {:.1} ms): {}",
                samples.len(),
                dt * 1e3,
                summary
            ),
        );
        if let Some(note) = gust_note {
            sink.message(self.sysid, &note);
        }
        // Said where the actuators are judged or not (`running::start_stage`, rule G2).
        self.failing_axes = failing;
        self.failing_said = false;
        // A stretch cut short (by --calibrate-until / --calibrate-s) still fits, but loosely.
        if span < SHORT_CALIBRATION_S {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the calibration stretch is only {span:.1} s (the default is 20 s from {} s after take-off): a short stretch leaves the model loose, and healthy actuators may read off",
                    self.cfg.settle_s
                ),
            );
        }
        self.run_with(calibrated, fit, samples, dt, sink);
    }

    /// A profile `ahcmon calibrate` wrote: its model is this vehicle's, identified on a healthy
    /// stretch, and is used as it is (a fault present from the take-off is then seen, where a
    /// calibration in flight would take it as the vehicle's normal).
    fn run_identified(
        &mut self,
        profile: Profile,
        samples: &[StoredSample],
        dt: f64,
        sink: &mut dyn Sink,
    ) {
        // A helicopter's discrete model holds only at the rate it was identified at (the filters
        // refuse one more than 5 % off): calibrate in flight instead, on the samples so far.
        if let Some(arx) = &profile.model.arx
            && (arx.dt - dt).abs() > crate::model::ARX_DT_TOLERANCE * dt
        {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the telemetry comes every {:.1} ms, the profile's identified model is for {:.1} ms: calibrating in flight instead ({} s)",
                    dt * 1e3,
                    arx.dt * 1e3,
                    self.cfg.calibrate_s
                ),
            );
            let mut profile = profile;
            profile.identified = false;
            let stage = Stage::Calibrating {
                profile: Box::new(profile),
                samples: samples.to_vec(),
                raw: std::mem::take(&mut self.stretch),
            };
            self.set_stage(stage, "the identified model is for another rate");
            return;
        }
        let expected = 1.0 / profile.rate_hz;
        if ((dt - expected) / expected).abs() > 0.1 {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the telemetry comes every {:.1} ms, the profile's model was identified at {:.1} ms: its noise levels (and a helicopter's discrete model) are for another rate; calibrate at this rate (ahcmon calibrate, or --calibrate-until)",
                    dt * 1e3,
                    expected * 1e3
                ),
            );
        }
        sink.message(
            self.sysid,
            &format!(
                "estimating with the profile's identified model ({}), not calibrated in flight",
                profile.name
            ),
        );
        self.run_with(profile, None, samples, dt, sink);
    }
}
