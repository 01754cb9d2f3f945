//! Monte-Carlo calibration of a vehicle's decision threshold on healthy flights (issue 4:
//! "thresholds calibrated on healthy Monte-Carlo sims, not tuned to the fault scenarios").
//!
//! Each healthy scenario is flown with seeds the tests and `eval` do not use, and with no
//! decisions (a decision would make the filters forget an actuator and change the traces); every step's
//! attributed deviation of every actuator and filter is kept after the warm-up. For each such
//! trace the smallest threshold at which the diagnosis' CUSUM would never alarm is found by
//! bisection (the CUSUM only falls as the threshold rises); the largest over traces, times a
//! margin, is the vehicle's threshold. The gain statistic of angle outputs (its own CUSUM term,
//! see `diagnose::vehicle`) is calibrated the same way into the gain threshold.

use super::EvalError;
use super::vehicle::run_vehicle_scenario;
use crate::diagnose::vehicle::{Decision, DiagnosisParams};
use crate::estimate::vehicle::AhcEstimate;
use crate::output::Sink;
use crate::pipeline::PipelineConfig;
use crate::scenario::NamedScenario;
use crate::telemetry::Profile;
use rayon::prelude::*;

/// First seed of the calibration flights: far from the scenarios' own seeds (1, 2, ...), which
/// the tests and the README's eval use, so the threshold is judged on flights it never saw.
pub const CALIBRATION_FIRST_SEED: u64 = 1001;
/// Factor between the largest alarm-free threshold seen and the one recommended.
pub const MARGIN: f64 = 1.25;

/// The calibration of one healthy scenario.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ThresholdCalibration {
    pub scenario: String,
    pub vehicle: String,
    pub seeds: Vec<u64>,
    /// Per filter (MIT-UKF, MIT-ESMF): the smallest threshold with no alarm on any flight;
    /// null for a filter whose statistic stayed 0.
    pub alarm_free: [Option<f64>; 2],
    /// Per filter: the largest detection statistic seen after the warm-up.
    pub max_abs_deviation: [f64; 2],
    /// `MARGIN` × the larger of `alarm_free`; null when the statistic stayed 0 throughout
    /// (nothing to calibrate: a vehicle with only motors has no gain statistic).
    pub recommended: Option<f64>,
    /// The same three for the gain statistic.
    pub gain_alarm_free: [Option<f64>; 2],
    pub max_abs_gain_gap: [f64; 2],
    pub gain_recommended: Option<f64>,
    /// Per rate axis, the gusts the in-flight calibration measured on these flights (flown
    /// through the pipeline `replay` runs; rad/s²), the axes' means at the strongest flight's
    /// level: the profile's `diagnosis.gusts`, up to which the threshold's false-alarm rate
    /// holds (rule T1). Null where no flight's
    /// fit measured the axis (a helicopter's identified model has no wind state).
    pub gusts: [Option<f64>; 3],
}

/// The gusts the in-flight calibration measures on the first `GUST_FLIGHT_S` of `named` with
/// `seed`, flown through the pipeline as a user's log is.
fn measured_gusts(named: &NamedScenario, seed: u64) -> Result<[Option<f64>; 3], EvalError> {
    struct Quiet;
    impl Sink for Quiet {
        fn decision(&mut self, _: &Decision) {}
    }
    let mut short = named.clone();
    short.scenario.duration_s = short.scenario.duration_s.min(GUST_FLIGHT_S);
    let monitor = super::matrix::fly(&short, seed, PipelineConfig::default(), &mut Quiet, |_| {})?;
    Ok((monitor.pipelines.values())
        .find_map(|p| p.fit.as_ref().map(|f| f.gusts))
        .unwrap_or([None; 3]))
}

/// Long enough for the default calibration stretch (20 s from 3 s after take-off) to end.
const GUST_FLIGHT_S: f64 = 40.0;

/// The smallest threshold at which `S ← max(0, S + (|e|/threshold − 1) dt)` stays at or below
/// `h` over the whole trace.
pub fn alarm_free_threshold(trace: &[f32], dt: f64, h: f64) -> f64 {
    let alarms = |th: f64| {
        let mut s = 0.0;
        trace.iter().any(|&e| {
            s = (s + (f64::from(e).abs() / th - 1.0) * dt).max(0.0);
            s > h
        })
    };
    let (mut lo, mut hi) = (1e-4, 1e-4);
    while alarms(hi) {
        hi *= 2.0;
        if hi > 1e3 {
            return f64::INFINITY;
        }
    }
    if !alarms(lo) {
        return lo;
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if alarms(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Keeps every step's statistics after the warm-up: `traces[statistic][filter][actuator]`
/// (statistic 0: `hypot(deviation, excursion)`, 1: the gain statistic).
struct Collect {
    warmup_s: f64,
    traces: [[Vec<Vec<f32>>; 2]; 2],
}

impl Sink for Collect {
    fn estimates(&mut self, t: f64, _: u8, est: &[&[AhcEstimate]; 3], _: &Profile) {
        if t < self.warmup_s {
            return;
        }
        // The detectors' statistics (the set filter decides nothing).
        for (f, row) in est.iter().take(2).enumerate() {
            for (k, traces) in self.traces.iter_mut().enumerate() {
                if traces[f].len() < row.len() {
                    traces[f].resize(row.len(), Vec::new());
                }
                for (j, e) in row.iter().enumerate() {
                    let stat = if k == 0 {
                        e.deviation.hypot(e.excursion)
                    } else {
                        e.gain_gap
                    };
                    traces[f][j].push(stat as f32);
                }
            }
        }
    }
    fn decision(&mut self, _: &Decision) {}
}

/// Fly `named` (a healthy vehicle scenario) with `seeds` and calibrate its threshold.
pub fn calibrate_threshold(
    named: &NamedScenario,
    seeds: &[u64],
) -> Result<ThresholdCalibration, EvalError> {
    let params = DiagnosisParams::default();
    if named.scenario.first_fault().is_some() {
        return Err(EvalError::Sim(
            named.name.clone(),
            "has a fault: thresholds are calibrated on healthy flights only".into(),
        ));
    }
    let dt = named.scenario.dt();
    // Per seed, statistic and filter: (alarm-free threshold, largest value).
    type PerSeed = ([[(f64, f64); 2]; 2], [Option<f64>; 3]);
    let per_seed: Vec<Result<PerSeed, EvalError>> = seeds
        .par_iter()
        .map(|&seed| {
            let mut sink = Collect {
                warmup_s: params.warmup_s,
                traces: Default::default(),
            };
            // An infinite threshold: no decision feeds back into the filters calibrated on.
            run_vehicle_scenario(named, seed, false, Some(f64::INFINITY), &mut sink)?;
            let gusts = measured_gusts(named, seed)?;
            let mut out = [[(0.0f64, 0.0f64); 2]; 2];
            for (k, per_filter) in out.iter_mut().enumerate() {
                for (f, slot) in per_filter.iter_mut().enumerate() {
                    for tr in &sink.traces[k][f] {
                        slot.0 = slot.0.max(alarm_free_threshold(tr, dt, params.cusum_h_s));
                        let m = tr.iter().fold(0.0f64, |a, &e| a.max(f64::from(e).abs()));
                        slot.1 = slot.1.max(m);
                    }
                }
            }
            Ok((out, gusts))
        })
        .collect();
    let mut alarm_free = [[0.0f64; 2]; 2];
    let mut max_abs = [[0.0f64; 2]; 2];
    let mut per_flight_gusts = vec![];
    for r in per_seed {
        let (r, g) = r?;
        per_flight_gusts.push(g);
        for k in 0..2 {
            for f in 0..2 {
                alarm_free[k][f] = alarm_free[k][f].max(r[k][f].0);
                max_abs[k][f] = max_abs[k][f].max(r[k][f].1);
            }
        }
    }
    // A statistic that stayed 0 has nothing to calibrate (the bisection's floor would read as a
    // real threshold): no recommendation.
    let recommend = |k: usize| {
        (max_abs[k].iter().any(|&m| m > 0.0))
            .then(|| MARGIN * alarm_free[k][0].max(alarm_free[k][1]))
    };
    let seen = |k: usize| -> [Option<f64>; 2] {
        std::array::from_fn(|f| (max_abs[k][f] > 0.0).then_some(alarm_free[k][f]))
    };
    Ok(ThresholdCalibration {
        gusts: strongest_gusts(&per_flight_gusts),
        scenario: named.name.clone(),
        vehicle: named.scenario.vehicle.clone(),
        seeds: seeds.to_vec(),
        alarm_free: seen(0),
        max_abs_deviation: max_abs[0],
        recommended: recommend(0),
        gain_alarm_free: seen(1),
        max_abs_gain_gap: max_abs[1],
        gain_recommended: recommend(1),
    })
}

/// Rule T1's reference from the gusts measured on each flight: their mean per axis (the
/// gusts' shape; one 20 s stretch reads an axis' gusts to about 20 %), scaled to the strongest
/// flight's level (`DiagnosisSpec::gust_level` of its gusts against that shape): the threshold
/// was alarm-free on every flight up to that level.
fn strongest_gusts(flights: &[[Option<f64>; 3]]) -> [Option<f64>; 3] {
    let shape: [Option<f64>; 3] = std::array::from_fn(|i| {
        let seen: Vec<f64> = flights.iter().filter_map(|g| g[i]).collect();
        (!seen.is_empty()).then(|| seen.iter().sum::<f64>() / seen.len() as f64)
    });
    let strongest = (flights.iter())
        .filter_map(|g| crate::telemetry::profile::DiagnosisSpec::gust_level(g, &shape))
        .fold(0.0f64, f64::max);
    shape.map(|g| g.map(|g| g * strongest).filter(|g| *g > 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alarm_free_threshold_is_the_cusum_boundary() {
        // 0.5 s at 0.1, else 0: the CUSUM at threshold th gains (0.1/th - 1) x 0.5 s.
        let mut tr = vec![0.0f32; 100];
        tr.extend(vec![0.1f32; 25]);
        tr.extend(vec![0.0f32; 100]);
        let th = alarm_free_threshold(&tr, 0.02, 0.25);
        // (0.1/th - 1) * 0.5 = 0.25  ->  th = 0.1 / 1.5
        assert!((th - 0.1 / 1.5).abs() < 1e-3, "{th}");
        let s_at = |th: f64| (0.1 / th - 1.0) * 0.5;
        assert!(s_at(th * 1.01) <= 0.25 && s_at(th * 0.99) > 0.25);
    }
}
