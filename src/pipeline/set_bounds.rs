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
    let (l, m) = (filters.actuators(), filters.set_rows());
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

/// The set filter's static a_z row for an identified model, whose detectors take the rates
/// only: its vertical effect `vertical` (the geometry's) scaled by a fit on the stretch where
/// that determines it, and the trim; `None` without a_z on most of the stretch. Each a_z is
/// paired with the commands that acted over its period, `delay` samples late, as the rates are.
pub fn vertical_row(
    vertical: &[f64],
    samples: &[StoredSample],
    delay: usize,
) -> Option<(Vec<f64>, f64)> {
    let l = vertical.len().min(MAX_ACTUATORS);
    let pairs: Vec<(f64, &[f64])> = (1 + delay..samples.len())
        .filter_map(|k| Some((samples[k].az?, &samples[k - 1 - delay].u[..l])))
        .collect();
    if pairs.is_empty() || pairs.len() * 2 < samples.len() {
        return None;
    }
    crate::model::calibrate::vertical_row(&pairs, vertical)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimate::vehicle::build;
    use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};
    use crate::telemetry::Profile;

    fn stretch(n: usize) -> (Box<dyn VehicleFilters>, Vec<StoredSample>) {
        let profile = Profile::resolve("quad-x").unwrap();
        let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, 5)).unwrap();
        let samples = (0..n)
            .map(|_| {
                let s = sim.step();
                let mut u = [0.0; MAX_ACTUATORS];
                u[..4].copy_from_slice(&s.u[..4]);
                StoredSample {
                    t: s.t,
                    rates: [s.y[0], s.y[1], s.y[2]],
                    u,
                    az: Some(s.y[3]),
                }
            })
            .collect();
        (build(&profile, 0.02).unwrap(), samples)
    }

    /// The bounds are the margin times the largest residual (recomputed here by brute force)
    /// and its largest change over each lag, the latter capped at twice the level; the mean
    /// commands are the stretch's.
    #[test]
    fn bounds_are_the_stretch_s_largest_residuals_with_the_margin() {
        let (filters, samples) = stretch(600);
        let (bounds, mean) = measure(filters.as_ref(), &samples, 0.02, 0, false).unwrap();
        let e: Vec<[f64; 4]> = (1..samples.len())
            .map(|k| {
                let s = &samples[k];
                let y = [s.rates[0], s.rates[1], s.rates[2], s.az.unwrap()];
                filters.healthy_residual(&samples[k - 1].rates, &samples[k - 1].u[..4], &y)
            })
            .collect();
        for (b, &lag) in bounds.iter().zip(&LAGS) {
            for i in 0..4 {
                let largest = (lag..e.len())
                    .map(|k| {
                        if lag == 0 {
                            e[k][i]
                        } else {
                            e[k][i] - e[k - lag][i]
                        }
                        .abs()
                    })
                    .fold(0.0, f64::max);
                let want = (SET_BOUND_MARGIN * largest).min(2.0 * bounds[0][i]);
                assert!(
                    (b[i] - want).abs() < 1e-12,
                    "lag {lag} row {i}: {} vs {want}",
                    b[i]
                );
                assert!(b[i] > 0.0);
            }
        }
        let u0: f64 = samples.iter().map(|s| s.u[0]).sum::<f64>() / samples.len() as f64;
        assert!((mean[0] - u0).abs() < 1e-12);
    }

    /// The vertical row pairs each a_z with the commands `delay` samples before the ones that
    /// acted over its period: on an a_z made from commands three samples before (delay 2)
    /// exactly, its scale and trim come back with delay 2, not with delay 0; without a_z on
    /// most samples there is no row.
    #[test]
    fn the_vertical_row_pairs_a_z_with_the_delayed_commands() {
        let base = [-2.0, -2.0, -2.0, 0.0];
        let mut rng = crate::sim::rng::Rng::new(3);
        let u: Vec<[f64; MAX_ACTUATORS]> = (0..400)
            .map(|_| {
                let mut c = [0.0; MAX_ACTUATORS];
                c[..4].iter_mut().for_each(|v| *v = rng.uniform(0.5));
                c
            })
            .collect();
        let mut samples: Vec<StoredSample> = (0..u.len())
            .map(|k| StoredSample {
                t: 0.02 * k as f64,
                rates: [0.0; 3],
                u: u[k],
                az: (k >= 3)
                    .then(|| -9.8 + 1.5 * (0..4).map(|j| base[j] * u[k - 3][j]).sum::<f64>()),
            })
            .collect();
        let (gain, offset) = vertical_row(&base, &samples, 2).unwrap();
        for (g, b) in gain.iter().zip(base) {
            assert!((g - 1.5 * b).abs() < 1e-9, "{gain:?}");
        }
        assert!((offset + 9.8).abs() < 1e-9);
        let (gain, _) = vertical_row(&base, &samples, 0).unwrap();
        assert!((gain[0] - 1.5 * base[0]).abs() > 0.1, "{gain:?}");
        for s in samples.iter_mut().skip(150) {
            s.az = None;
        }
        assert!(vertical_row(&base, &samples, 2).is_none());
    }

    /// A stretch without an unbroken run longer than the longest lag gives no bounds (the
    /// profile's stated ones stand): every 20th sample is late by two periods.
    #[test]
    fn a_stretch_broken_too_often_gives_none() {
        let (filters, mut samples) = stretch(600);
        for (k, s) in samples.iter_mut().enumerate() {
            s.t += 0.04 * (k / 20) as f64;
        }
        assert!(measure(filters.as_ref(), &samples, 0.02, 0, false).is_none());
    }
}
