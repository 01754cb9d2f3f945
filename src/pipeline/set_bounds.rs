//! The set filter's stated bounds, measured on the calibration stretch: the largest healthy
//! residual of each row, and the largest change of it over each lag, times a margin.

use super::calibrating::StoredSample;
use crate::estimate::ahc_set::LAGS;
use crate::estimate::vehicle::VehicleFilters;
use crate::model::{MAX_ACTUATORS, MAX_INPUTS};

/// The margin over the stretch's largest values. Extremes grow with the number of samples: for
/// Gaussian-like residuals the largest of n grows as `√(2 ln n)`, 1.29 times from a 30 s
/// stretch at 50 Hz (1,500) to an hour (180,000); the rest covers manoeuvres larger than the
/// stretch's.
pub const SET_BOUND_MARGIN: f64 = 1.5;

/// Pairs further apart than this many periods are not one step (a hole).
const MAX_INTERVAL: f64 = 1.5;

/// The bounds and each actuator's mean command, or `None` when the stretch has no run long
/// enough for the longest lag.
pub fn measure(
    filters: &dyn VehicleFilters,
    samples: &[StoredSample],
    dt: f64,
    delay: usize,
    exogenous: bool,
) -> Option<([[f64; 4]; LAGS.len()], [f64; MAX_ACTUATORS])> {
    let (l, m) = (filters.actuators(), filters.measurements());
    let n_in = filters.inputs();
    let longest = *LAGS.last()?;
    let mut bounds = [[0.0f64; 4]; LAGS.len()];
    // The residuals of the current run of consecutive samples.
    let mut run: Vec<[f64; 4]> = Vec::with_capacity(samples.len());
    let mut longest_run = 0;
    // Sample k's step needs k - 1 (its rates and acting commands), k - 1 - delay (the delayed
    // ones) and, for an identified model, k - 2 (the previous increment).
    let back = (delay + 1).max(if exogenous { 2 } else { 1 });
    for k in 0..samples.len() {
        let regular = k >= back
            && (k - back..k).all(|i| samples[i + 1].t - samples[i].t <= MAX_INTERVAL * dt);
        let y_az = if m == 4 { samples[k].az } else { Some(0.0) };
        let (true, Some(az)) = (regular, y_az) else {
            longest_run = longest_run.max(run.len());
            run.clear();
            continue;
        };
        let mut input = [0.0; MAX_INPUTS];
        input[..l].copy_from_slice(&samples[k - 1 - delay].u[..l.min(MAX_ACTUATORS)]);
        if exogenous {
            for i in 0..3 {
                input[l + i] = samples[k - 1].rates[i] - samples[k - 2].rates[i];
            }
        }
        let s = &samples[k];
        let y = [s.rates[0], s.rates[1], s.rates[2], az];
        let e = filters.healthy_residual(&samples[k - 1].rates, &input[..n_in], &y[..m]);
        if e.iter().any(|v| !v.is_finite()) {
            longest_run = longest_run.max(run.len());
            run.clear();
            continue;
        }
        run.push(e);
        let now = run.len() - 1;
        for (b, &lag) in bounds.iter_mut().zip(&LAGS) {
            if lag > now {
                break;
            }
            let then = run[now - lag];
            for i in 0..m {
                let d = if lag == 0 { e[i] } else { e[i] - then[i] };
                b[i] = b[i].max(d.abs());
            }
        }
    }
    longest_run = longest_run.max(run.len());
    if longest_run <= longest {
        return None;
    }
    for b in &mut bounds {
        for v in b.iter_mut() {
            *v *= SET_BOUND_MARGIN;
        }
    }
    // A change over a lag is at most twice the level.
    let level = bounds[0];
    for b in bounds.iter_mut().skip(1) {
        for i in 0..4 {
            b[i] = b[i].min(2.0 * level[i]);
        }
    }
    let mut mean = [0.0; MAX_ACTUATORS];
    for s in samples {
        for (m, u) in mean.iter_mut().zip(&s.u).take(l) {
            *m += u / samples.len() as f64;
        }
    }
    Some((bounds, mean))
}
