//! Rule T1 over the whole flight: the gusts measured again on every further stretch of flight
//! as long as the calibration's, and the deviation threshold scaled by their pooled level.
//!
//! The calibration reads the gusts on one 20 s stretch, each axis to about 20 % (the three
//! together to about 12 %): a rough flight whose stretch came in a lull reads as calm and keeps
//! the threshold of calmer air for the rest of the flight. Each further stretch measures them
//! the same way (the likelihood fit's wind state, [`calibrate_scaled`]); the level is pooled
//! over the stretches as a variance (the mean of the squared levels weighted by the stretches'
//! lengths, the calibration's included), so its spread falls as one over the square root of
//! the time measured, and the threshold rises with it:
//! `threshold = base × clamp(level, 1, MAX_GUST_FACTOR)`, never lowered in a flight (a level
//! pooled over few stretches is still noisy). Nothing is measured while a fault is in force
//! (the fault's residual is not wind): a stretch a fault interrupts is measured up to
//! [`EVIDENCE_MARGIN_S`] before the earliest evidence of that fault (its alarms, its
//! decision, the data's estimate of its change's start) if at least half a stretch is left,
//! so that a fault found soon after the calibration does not leave the flight at the
//! calibration's reading for good. A stretch with too few unbroken samples is not measured.

use super::calibrating::StoredSample;
use crate::model::calibrate::{CalibrationSample, calibrate_scaled_within};
use crate::model::{MAX_ACTUATORS, RateParams};
use crate::telemetry::profile::{DiagnosisSpec, MAX_GUST_FACTOR};

/// A factor that moved this much from the one last said is said again.
const SAY_STEP: f64 = 0.1;
/// The likelihood search's evaluations per run in flight (the calibration's 600 converge to
/// 1e-9; the level needs a per cent, and a stretch's own spread is about 12 %).
const EVALUATIONS: usize = 150;
/// Every stretch is measured until this many are pooled (5 minutes at 20 s: the level then
/// known to about 3 %), then one in [`LATER_EVERY`] (every 5 minutes at 20 s), which follows a
/// change of the weather: a fit costs about what 5 s of the filters do.
const POOLED_FULLY: usize = 15;
const LATER_EVERY: usize = 15;
/// A stretch a fault interrupts ends this long before the fault's earliest evidence: the
/// data's estimate of a change's start is good to a fraction of a second, and a filter's
/// alarm comes after the change.
const EVIDENCE_MARGIN_S: f64 = 1.0;

pub(super) struct GustWatch {
    base: RateParams,
    reference: [Option<f64>; 3],
    /// The deviation threshold before rule T1.
    pub(super) base_threshold: f64,
    dt: f64,
    actuators: usize,
    stretch: Vec<StoredSample>,
    /// Samples a stretch takes (the calibration's).
    stretch_len: usize,
    /// Σ weight × level², Σ weight (a stretch's length over the calibration's) and how many
    /// stretches (the calibration's included).
    sum_sq: f64,
    weight: f64,
    stretches: usize,
    /// Stretches completed since the calibration (measured or not).
    completed: usize,
    /// The factor in force and the one last said.
    pub(super) factor: f64,
    said: f64,
    /// The calibration stretch's last sample: the stretches start after it.
    pub(super) from_t: f64,
}

impl GustWatch {
    /// `None` where rule T1 does not apply: no gusts measured at the calibration, or a profile
    /// without reference gusts.
    pub(super) fn new(
        spec: &DiagnosisSpec,
        base: RateParams,
        calibration_gusts: &[Option<f64>; 3],
        base_threshold: f64,
        stretch_len: usize,
        dt: f64,
        from_t: f64,
    ) -> Option<Self> {
        let reference = spec.gusts?.map(Some);
        let level = DiagnosisSpec::gust_level(calibration_gusts, &reference)?;
        let factor = factor_of(level);
        Some(Self {
            actuators: base.actuators(),
            base,
            reference,
            base_threshold,
            dt,
            stretch: Vec::with_capacity(stretch_len),
            stretch_len: stretch_len.max(2),
            sum_sq: level * level,
            weight: 1.0,
            stretches: 1,
            completed: 0,
            factor,
            said: factor,
            from_t,
        })
    }

    /// One sample of flight. `fault_since`: a fault is in force, its earliest evidence at
    /// that time; the stretch under way ends (measured up to before that evidence if enough
    /// of it is left). Returns the new factor when a measured stretch moved it.
    pub(super) fn push(
        &mut self,
        t: f64,
        rates: [f64; 3],
        u: [f64; MAX_ACTUATORS],
        fault_since: Option<f64>,
    ) -> Option<f64> {
        if let Some(since) = fault_since {
            let healthy = (self.stretch).partition_point(|s| s.t < since - EVIDENCE_MARGIN_S);
            self.stretch.truncate(healthy);
            let factor = (2 * healthy >= self.stretch_len)
                .then(|| self.completed_stretch())
                .flatten();
            self.stretch.clear();
            return factor;
        }
        self.stretch.push(StoredSample {
            t,
            rates,
            u,
            az: None,
        });
        if self.stretch.len() < self.stretch_len {
            return None;
        }
        let factor = self.completed_stretch();
        self.stretch.clear();
        factor
    }

    /// The stretch in store is complete (or as complete as a fault lets it be): measured when
    /// due and pooled by its length. Returns the new factor when it moved.
    fn completed_stretch(&mut self) -> Option<f64> {
        self.completed += 1;
        let due = self.stretches < POOLED_FULLY || self.completed.is_multiple_of(LATER_EVERY);
        let level = if due { self.measure() } else { None }?;
        let weight = self.stretch.len() as f64 / self.stretch_len as f64;
        self.sum_sq += weight * level * level;
        self.weight += weight;
        self.stretches += 1;
        // Only ever raised: a level pooled over few stretches is still noisy, and one read
        // low would bring back the false alarms of a calm reading.
        let factor = factor_of((self.sum_sq / self.weight).sqrt()).max(self.factor);
        (factor != std::mem::replace(&mut self.factor, factor)).then_some(factor)
    }

    /// Whether `factor` moved far enough from the one last said to be said (and note it said).
    pub(super) fn worth_saying(&mut self, factor: f64) -> bool {
        let say = (factor - self.said).abs() >= SAY_STEP;
        if say {
            self.said = factor;
        }
        say
    }

    pub(super) fn stretches(&self) -> usize {
        self.stretches
    }

    /// The flight time the pooled level was measured on (s), the calibration's included.
    pub(super) fn measured_s(&self) -> f64 {
        self.weight * self.stretch_len as f64 * self.dt
    }

    /// The stretch's gust level against the reference, as the calibration fits it; `None`
    /// when the fit cannot be taken (too few unbroken samples, no axis with a wind state).
    fn measure(&self) -> Option<f64> {
        // The outputs of sample k act until sample k+1 (as at the calibration); a pair that is
        // not one period apart starts a new run.
        let mut rows: Vec<CalibrationSample> = Vec::with_capacity(self.stretch.len());
        // Each kept sample's position in periods: one after a kept predecessor, else as many
        // as passed since the last kept one (so the wind's carry-over spans the hole).
        let mut follows = false;
        let mut last_kept: Option<(f64, u64)> = None;
        for pair in self.stretch.windows(2) {
            let interval = pair[1].t - pair[0].t;
            let regular = interval > 0.0 && interval <= 1.5 * self.dt;
            if regular {
                let step = match last_kept {
                    None => 0,
                    Some((_, step)) if follows => step + 1,
                    Some((t, step)) => step + (((pair[1].t - t) / self.dt).round() as u64).max(1),
                };
                last_kept = Some((pair[1].t, step));
                rows.push(CalibrationSample {
                    rates: pair[1].rates,
                    u: &pair[0].u[..self.actuators],
                    az: None,
                    follows_previous: follows,
                    step,
                    measured: true,
                });
            }
            follows = regular;
        }
        let fit = calibrate_scaled_within(&rows, self.dt, &self.base, EVALUATIONS).ok()?;
        DiagnosisSpec::gust_level(&fit.gusts, &self.reference)
    }
}

/// The threshold's factor for a gust level: over 1 only, at most [`MAX_GUST_FACTOR`].
fn factor_of(level: f64) -> f64 {
    if level.is_nan() {
        1.0
    } else {
        level.clamp(1.0, MAX_GUST_FACTOR)
    }
}

#[cfg(test)]
mod tests {
    // Test code: a failed unwrap is the failure report.
    #![allow(clippy::unwrap_used)]
    use super::*;
    use crate::sim::vehicle::{Gusts, VehicleSim, VehicleSimConfig};
    use crate::telemetry::Profile;

    const DT: f64 = 0.02;
    /// The calibration's stretch: 20 s.
    const STRETCH: usize = 1000;

    /// A watch on the quad X profile whose calibration read the gusts at `calibration_level`
    /// times the profile's reference, fed `stretches` stretches of the simulated quad in
    /// `gusts` times the matrix's built-in gusts; `fault_in_force` for every sample.
    fn watch_over(
        calibration_level: f64,
        gusts: f64,
        stretches: usize,
        fault_in_force: bool,
    ) -> GustWatch {
        let fault_since = |_: f64| fault_in_force.then_some(0.0);
        watch_flying(calibration_level, gusts, stretches * STRETCH, fault_since)
    }

    /// As [`watch_over`], `samples` samples, with a fault in force from when `fault_since`
    /// (of the sample's time) gives its evidence.
    fn watch_flying(
        calibration_level: f64,
        gusts: f64,
        samples: usize,
        fault_since: impl Fn(f64) -> Option<f64>,
    ) -> GustWatch {
        let profile = Profile::resolve("quad-x").unwrap();
        let reference = profile.diagnosis.gusts.unwrap();
        let mut watch = GustWatch::new(
            &profile.diagnosis,
            profile.rate_params(),
            &reference.map(|g| Some(g * calibration_level)),
            0.07,
            STRETCH,
            DT,
            0.0,
        )
        .unwrap();
        let mut cfg = VehicleSimConfig::calm(profile.clone(), DT, 7);
        cfg.gusts = Some(Gusts {
            angular: [0.5 * gusts, 0.5 * gusts, 0.15 * gusts],
            vertical: 0.3 * gusts,
            tau_s: 1.0,
        });
        let mut sim = VehicleSim::new(cfg).unwrap();
        // A sample's outputs act over the period after it (as telemetry pairs them): the
        // simulator's act over the period that ends at its sample.
        let mut previous = sim.step();
        for _ in 0..samples {
            let s = sim.step();
            let mut u = [0.0; MAX_ACTUATORS];
            u[..4].copy_from_slice(&s.u[..4]);
            let rates = [previous.y[0], previous.y[1], previous.y[2]];
            watch.push(previous.t, rates, u, fault_since(previous.t));
            previous = s;
        }
        watch
    }

    /// A rough flight (1.5 times the built-in gusts) whose calibration stretch read them as
    /// calm (level 1): the stretches after it raise the factor toward the flight's level. The
    /// reference is the strongest of the threshold flights' 20 s readings, about 1.1 times
    /// their mean, so 1.5 times the gusts read about 1.35 of it; pooled over 10 stretches and
    /// the calibration's 1.0, about 1.3.
    #[test]
    fn a_rough_flight_read_calm_at_its_calibration_raises_the_threshold_as_it_flies() {
        let watch = watch_over(1.0, 1.5, 10, false);
        assert_eq!(watch.stretches(), 11);
        assert!(
            watch.factor > 1.15 && watch.factor < 1.6,
            "factor {}",
            watch.factor
        );
    }

    /// In the built-in gusts the pooled level stays under the reference (the strongest
    /// reading): the threshold is not raised; one a calibration raised is not lowered.
    #[test]
    fn the_built_in_gusts_leave_the_threshold_as_calibrated() {
        let watch = watch_over(1.0, 1.0, 10, false);
        assert_eq!(watch.stretches(), 11);
        assert_eq!(watch.factor, 1.0);
        let strong = watch_over(1.6, 1.0, 10, false);
        assert_eq!(strong.stretches(), 11);
        assert_eq!(strong.factor, 1.6);
    }

    /// With a fault in force nothing is measured: the fault's residual is not wind.
    #[test]
    fn no_stretch_is_measured_while_a_fault_is_in_force() {
        let watch = watch_over(1.0, 1.5, 3, true);
        assert_eq!(watch.stretches(), 1);
        assert_eq!(watch.factor, 1.0);
    }

    /// A fault decided 16 s into a stretch, its evidence from 15 s: the 14 s before that
    /// evidence less the margin are measured and pooled, at 0.7 of a stretch's weight; one
    /// decided 9 s in leaves too little, and nothing is measured.
    #[test]
    fn a_stretch_a_fault_interrupts_is_measured_up_to_its_evidence() {
        let fault_since =
            |decided: f64, evidence: f64| move |t: f64| (t >= decided).then_some(evidence);
        let samples = STRETCH;
        let long = watch_flying(1.0, 1.5, samples, fault_since(16.0, 15.0));
        assert_eq!(long.stretches(), 2);
        assert!((long.weight - 1.7).abs() < 0.01, "weight {}", long.weight);
        assert!(long.factor > 1.05, "factor {}", long.factor);
        let short = watch_flying(1.0, 1.5, samples, fault_since(9.0, 8.5));
        assert_eq!(short.stretches(), 1);
        assert_eq!(short.factor, 1.0);
    }
}
