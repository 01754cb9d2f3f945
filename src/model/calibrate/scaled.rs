//! The profile's geometry scaled per axis to the vehicle ([`calibrate_scaled`]), and the
//! vertical specific force row.

use super::*;
use nalgebra::{DMatrix, DVector};

/// Which parts of a [`calibrate_scaled`] fit came from the data.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaledFit {
    pub params: RateParams,
    pub quality: FitQuality,
    /// Per axis (roll, pitch, yaw, then a_z when measured): the geometry's gain was rescaled
    /// and `D` identified (true), or only the offset was fitted to the profile's `D`/`G`
    /// because the stretch did not excite that axis (false).
    pub scaled: Vec<bool>,
    /// Per axis: the factor applied to the profile's `G` row.
    pub scale: Vec<f64>,
    /// Per rate axis (roll, pitch, yaw): the gusts the likelihood fit measured, the wind
    /// state's stationary standard deviation as an angular acceleration (rad/s²), where that
    /// fit was taken (its model holds on the axis); `None` elsewhere.
    pub gusts: [Option<f64>; 3],
}

/// Identify a vehicle's magnitudes against a profile's geometry: per axis, one gain factor on
/// the profile's `G` row, the damping and the offset (`omega_{k+1} = a omega_k + h (s G_i u +
/// c_i)`, instrumental variables as in [`calibrate`]). Far better conditioned than a free `G`:
/// an autopilot's own controller moves the actuators together along its axes, which a free
/// fit cannot separate. An axis the stretch does not excite (steady hover) keeps the profile's
/// `D` and `G` and gets only its offset `c`, which any stretch determines.
pub fn calibrate_scaled(
    samples: &[CalibrationSample],
    dt: f64,
    base: &RateParams,
) -> Result<ScaledFit, CalibrationError> {
    calibrate_scaled_within(samples, dt, base, MAX_EVALUATIONS)
}

/// [`calibrate_scaled`] with the likelihood fit's search stopped after `max_evaluations` per
/// run (of two): a cheaper, slightly less converged fit for a measurement repeated in flight.
pub fn calibrate_scaled_within(
    samples: &[CalibrationSample],
    dt: f64,
    base: &RateParams,
    max_evaluations: usize,
) -> Result<ScaledFit, CalibrationError> {
    let l = base.actuators();
    let need = 50;
    if samples.len() < need + 2 {
        return Err(CalibrationError::TooFew {
            got: samples.len(),
            need: need + 2,
            l,
        });
    }
    let ok = all_finite(samples, l);
    if !ok {
        return Err(CalibrationError::NonFinite);
    }
    let rows = unbroken_rows(samples, 1, 1);
    let n = rows.len();
    if n < need {
        return Err(CalibrationError::TooFew {
            got: n + 2,
            need: need + 2,
            l,
        });
    }
    let mut params = base.clone();
    let mut quality = FitQuality {
        r_squared: vec![],
        residual_std: vec![],
        samples: n,
    };
    let mut scaled = vec![];
    let mut scale = vec![];
    let mut gusts = [None; 3];
    let drive = |axis: usize, u: &[f64]| -> f64 {
        (0..l).map(|j| base.effectiveness[j][axis] * u[j]).sum()
    };
    for axis in 0..3 {
        let mut x = DMatrix::<f64>::zeros(n, 3);
        let mut z = DMatrix::<f64>::zeros(n, 3);
        let mut y = DVector::<f64>::zeros(n);
        for (r, &k) in rows.iter().enumerate() {
            let g = drive(axis, samples[k + 1].u);
            x[(r, 0)] = samples[k].rates[axis];
            z[(r, 0)] = samples[k - 1].rates[axis];
            x[(r, 1)] = g;
            z[(r, 1)] = g;
            x[(r, 2)] = 1.0;
            z[(r, 2)] = 1.0;
            y[r] = samples[k + 1].rates[axis];
        }
        let physical = |(beta, r2, sd): (DVector<f64>, f64, f64)| {
            let a = beta[0];
            if !(a > 0.0 && a < 1.0) {
                return None;
            }
            let d = -a.ln() / dt;
            let hold = (1.0 - a) / d;
            let s = beta[1] / hold;
            // A factor far from the geometry's is an unexcited axis fitting noise.
            (0.1..=10.0)
                .contains(&s)
                .then_some((d, s, beta[2] / hold, r2, sd))
        };
        // The maximum-likelihood fit with the wind as a state (see `pem`) replaces the plain
        // instrumented one where the axis is excited (the plain fit is physical) and the fit's
        // model holds: its innovations white by the Ljung-Box test at 0.1 % (the simulated
        // flights give 4-13, as white innovations should; ArduPilot SITL's, whose motors and
        // rate filtering a first-order model lacks, 50-230). Where the model does not hold, the
        // plain fit is the better one-step predictor, which is what the filters use. A fit
        // that predicts the rates one step ahead far worse than the plain one (residual std
        // over MAX_WIND_MISFIT times) is a search gone wrong: the plain one stands too.
        let plain = instrumental(&x, &z, &y).and_then(physical);
        let a0 = plain.map_or((-base.damping[axis] * dt).exp(), |p| (-p.0 * dt).exp());
        let wind = plain
            .and_then(|_| {
                let rows = Row::of(samples, axis, |u| drive(axis, u));
                fit_axis_within(&rows, a0, max_evaluations)
            })
            .filter(|f| f.whiteness <= WHITENESS_LIMIT)
            .and_then(|f| {
                let beta = DVector::from_column_slice(&[f.a, f.beta, f.c]);
                let (r2, sd) = fit_quality(&x, &y, &beta);
                physical((beta, r2, sd)).map(|w| (w, f))
            });
        let fitted = match (plain, wind) {
            (Some(p), Some((w, _))) if w.4 > MAX_WIND_MISFIT * p.4 => Some(p),
            (_, Some((w, f))) => {
                gusts[axis] = Some(f.gust_std(dt));
                Some(w)
            }
            (p, None) => p,
        };
        match fitted {
            Some((d, s, c, r2, sd)) => {
                params.damping[axis] = d;
                for col in params.effectiveness.iter_mut() {
                    col[axis] *= s;
                }
                params.offset[axis] = c;
                quality.r_squared.push(r2);
                quality.residual_std.push(sd);
                scaled.push(true);
                scale.push(s);
            }
            None => {
                // Offset only, on the profile's D and G.
                let d = base.damping[axis];
                let a = (-d * dt).exp();
                let hold = if d * dt > 1e-12 { (1.0 - a) / d } else { dt };
                let mut sum = 0.0;
                // The rows' steps (k to k+1), which lie within unbroken runs.
                for &k in &rows {
                    let s0 = &samples[k];
                    let s1 = &samples[k + 1];
                    sum += (s1.rates[axis] - a * s0.rates[axis]) / hold - drive(axis, s1.u);
                }
                let c = sum / n as f64;
                params.offset[axis] = c;
                let mut rss = 0.0;
                let mut tss = 0.0;
                let mean =
                    samples.iter().map(|s| s.rates[axis]).sum::<f64>() / samples.len() as f64;
                for &k in &rows {
                    let (s0, s1) = (&samples[k], &samples[k + 1]);
                    let pred = a * s0.rates[axis] + hold * (drive(axis, s1.u) + c);
                    rss += (s1.rates[axis] - pred).powi(2);
                    tss += (s1.rates[axis] - mean).powi(2);
                }
                quality
                    .r_squared
                    .push(if tss > 0.0 { 1.0 - rss / tss } else { 1.0 });
                quality.residual_std.push((rss / n as f64).sqrt());
                scaled.push(false);
                scale.push(1.0);
            }
        }
    }
    let with_az: Vec<_> = samples
        .iter()
        .filter(|s| s.measured)
        .filter_map(|s| s.az.map(|a| (a, s.u)))
        .collect();
    if let Some(v) = fit_vertical(&with_az, &base.vertical) {
        params.vertical = v.vertical;
        params.vertical_offset = v.offset;
        quality.r_squared.push(v.r_squared);
        quality.residual_std.push(v.residual_std);
        scaled.push(v.scaled);
        scale.push(v.scale);
    }
    Ok(ScaledFit {
        params,
        quality,
        scaled,
        scale,
        gusts,
    })
}

/// The vertical specific force row fitted against the profile's geometry: one factor on its
/// `g_z` and the trim, or the trim alone when the factor is implausible (no vertical excitation).
pub(super) struct VerticalFit {
    pub(super) vertical: Vec<f64>,
    pub(super) offset: f64,
    pub(super) r_squared: f64,
    pub(super) residual_std: f64,
    pub(super) scaled: bool,
    pub(super) scale: f64,
}

/// How much larger the maximum-likelihood fit's one-step residual (its coefficients without the
/// wind state) may be than the plain instrumented fit's, on the same rows, for it to be taken: a
/// fit of the same vehicle with the wind modelled predicts nearly as well one step ahead.
const MAX_WIND_MISFIT: f64 = 3.0;

/// Largest standard error of a fitted scale, relative to the scale, for it to replace the
/// geometry's.
pub(super) const MAX_SCALE_REL_ERROR: f64 = 0.1;

/// Standard error of the first coefficient of a fit on `[g, 1]` columns, with the residuals'
/// lag-1 autocorrelation `r1` widening it by `√((1 + r1)/(1 - r1))`: the AR(1) factor for a
/// regressor as persistent as the residual, an upper bound (conservative) for a faster one.
pub(super) fn slope_std_error(x: &DMatrix<f64>, y: &DVector<f64>, beta: &DVector<f64>) -> f64 {
    let n = y.len();
    let resid = y - x * beta;
    let rss = resid.norm_squared();
    if n < 3 {
        return f64::INFINITY;
    }
    if rss <= 0.0 {
        return 0.0;
    }
    let lag1: f64 = (1..n).map(|k| resid[k] * resid[k - 1]).sum();
    let r1 = (lag1 / rss).clamp(0.0, 0.999);
    let g = x.column(0);
    let mean = g.mean();
    let sxx: f64 = g.iter().map(|v| (v - mean).powi(2)).sum();
    if sxx <= 0.0 {
        return f64::INFINITY;
    }
    let var = rss / (n - 2) as f64 / sxx;
    (var * (1.0 + r1) / (1.0 - r1)).sqrt()
}

pub(super) fn fit_vertical(
    with_az: &[(f64, &[f64])],
    base_vertical: &[f64],
) -> Option<VerticalFit> {
    let l = with_az.first()?.1.len();
    if base_vertical.len() != l {
        return None;
    }
    let gz = |u: &[f64]| -> f64 { (0..l).map(|j| base_vertical[j] * u[j]).sum() };
    let mut x = DMatrix::<f64>::zeros(with_az.len(), 2);
    let mut y = DVector::<f64>::zeros(with_az.len());
    for (k, (a, u)) in with_az.iter().enumerate() {
        x[(k, 0)] = gz(u);
        x[(k, 1)] = 1.0;
        y[k] = *a;
    }
    // The scale must be determined by the data: its standard error, widened for residuals
    // correlated in time (gusts, a climb: AR(1) variance factor (1 + r1)/(1 - r1)), within a
    // tenth of it. A hover whose summed thrust barely moves fits a_z's noise with any scale
    // (measured: x0.14 at R² = 0.01 in gusts), and then keeps the geometry's.
    let fitted = least_squares(&x, &y).filter(|(beta, _, _)| {
        (0.1..=10.0).contains(&beta[0])
            && slope_std_error(&x, &y, beta) <= MAX_SCALE_REL_ERROR * beta[0]
    });
    Some(match fitted {
        Some((beta, r2, sd)) => VerticalFit {
            vertical: base_vertical.iter().map(|v| v * beta[0]).collect(),
            offset: beta[1],
            r_squared: r2,
            residual_std: sd,
            scaled: true,
            scale: beta[0],
        },
        None => {
            let n = with_az.len() as f64;
            let c = with_az.iter().map(|(a, u)| a - gz(u)).sum::<f64>() / n;
            let mean = with_az.iter().map(|(a, _)| a).sum::<f64>() / n;
            let rss: f64 = with_az.iter().map(|(a, u)| (a - gz(u) - c).powi(2)).sum();
            let tss: f64 = with_az.iter().map(|(a, _)| (a - mean).powi(2)).sum();
            VerticalFit {
                vertical: base_vertical.to_vec(),
                offset: c,
                r_squared: if tss > 0.0 { 1.0 - rss / tss } else { 1.0 },
                residual_std: (rss / n).sqrt(),
                scaled: false,
                scale: 1.0,
            }
        }
    })
}
