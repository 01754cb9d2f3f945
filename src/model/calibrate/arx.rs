//! The identified discrete model ([`calibrate_arx`]): rate increments on delayed commands.

use super::*;
use nalgebra::{DMatrix, DVector};

/// An identified discrete model and how well it predicted the rate increments.
#[derive(Debug, Clone, PartialEq)]
pub struct ArxFit {
    pub params: ArxParams,
    /// R² and residual std of the rate *increments* (roll, pitch, yaw; rad/s per step), then
    /// of a_z when measured. Increments, not rates: a rate is mostly its previous value, which
    /// makes any model look good.
    pub quality: FitQuality,
    /// The a_z row was rescaled from the geometry (true) or only its trim fitted (false).
    pub vertical_scaled: bool,
}

/// Identify a discrete rate model with full cross-axis coupling, full effectiveness, the
/// previous measured increment and a command delay (chosen among 0..=`max_delay` samples by
/// the smallest normalised residual) from consecutive samples at period `dt`:
///
/// ```text
/// w_k - w_{k-1} = (Phi - I) w_{k-1} + E (w_{k-1} - w_{k-2}) + B u_{k-d} + c
/// ```
///
/// For vehicles whose rate response is not first order: a helicopter's rotor flaps with a lag
/// and couples roll and pitch, and its servos act late; a first-order model with the geometry's
/// `G` leaves most of the increment unexplained there (R² 0.0-0.7 against 0.98-1.00 for this
/// form on the ArduPilot TradHeli SITL). The a_z row stays static and geometric ([`calibrate_scaled`]).
pub fn calibrate_arx(
    samples: &[CalibrationSample],
    dt: f64,
    max_delay: usize,
    base: &RateParams,
) -> Result<ArxFit, CalibrationError> {
    let l = base.actuators();
    let cols = 7 + l;
    let need = 10 * cols + max_delay + 2;
    if samples.len() < need {
        return Err(CalibrationError::TooFew {
            got: samples.len(),
            need,
            l,
        });
    }
    let ok = all_finite(samples, l);
    if !ok {
        return Err(CalibrationError::NonFinite);
    }
    // Rows k with samples k - first ..= k unbroken: all delays are fitted on the same rows so
    // their residuals compare.
    let first = max_delay.max(2);
    let row_ks = unbroken_rows(samples, first, 0);
    let rows = row_ks.len();
    if rows + first < need {
        return Err(CalibrationError::TooFew {
            got: rows + first,
            need,
            l,
        });
    }
    // Per axis the coefficients and (R², residual std); and the summed unexplained fraction.
    type DelayFit = (Vec<DVector<f64>>, Vec<(f64, f64)>, f64);
    let fit_delay = |d: usize| -> Option<DelayFit> {
        let mut betas = vec![];
        let mut q = vec![];
        let mut score = 0.0;
        for axis in 0..3 {
            let mut x = DMatrix::<f64>::zeros(rows, cols);
            let mut y = DVector::<f64>::zeros(rows);
            for (r, &k) in row_ks.iter().enumerate() {
                let (w2, w1, w0) = (
                    &samples[k - 2].rates,
                    &samples[k - 1].rates,
                    &samples[k].rates,
                );
                for i in 0..3 {
                    x[(r, i)] = w1[i];
                    x[(r, 3 + i)] = w1[i] - w2[i];
                }
                x[(r, 6)] = 1.0;
                for j in 0..l {
                    x[(r, 7 + j)] = samples[k - d].u[j];
                }
                y[r] = w0[axis] - w1[axis];
            }
            // Plain least squares, not instrumented: the lagged rates that would serve as
            // instruments are correlated with wind (a coloured disturbance), which made the
            // instrumented fit unstable on our gusty helicopter flights (spectral radius 1.05,
            // measured); gyro noise is small against manoeuvre rates.
            let (beta, r2, sd) = least_squares(&x, &y)?;
            score += 1.0 - r2;
            betas.push(beta);
            q.push((r2, sd));
        }
        Some((betas, q, score))
    };
    let mut best: Option<(usize, DelayFit)> = None;
    for d in 0..=max_delay {
        if let Some(fit) = fit_delay(d)
            && best.as_ref().is_none_or(|x| fit.2 < x.1.2)
        {
            best = Some((d, fit));
        }
    }
    let (delay, (betas, q, _)) = best.ok_or(CalibrationError::NoDelayFits)?;
    let mut params = ArxParams {
        dt,
        delay,
        phi: [[0.0; 3]; 3],
        previous_increment: [[0.0; 3]; 3],
        input: vec![[0.0; 3]; l],
        offset: [0.0; 3],
        vertical: base.vertical.clone(),
        vertical_offset: base.vertical_offset,
    };
    for (axis, beta) in betas.iter().enumerate() {
        for i in 0..3 {
            params.phi[axis][i] = beta[i] + if i == axis { 1.0 } else { 0.0 };
            params.previous_increment[axis][i] = beta[3 + i];
        }
        params.offset[axis] = beta[6];
        for j in 0..l {
            params.input[j][axis] = beta[7 + j];
        }
    }
    // The identified rate dynamics must be stable (spectral radius of the companion form
    // below 1), or the filters would diverge on a model of noise.
    if let Some(rho) = arx_spectral_radius(&params)
        && rho >= 1.0
    {
        return Err(CalibrationError::UnstableModel { radius: rho });
    }
    let mut quality = FitQuality {
        r_squared: q.iter().map(|v| v.0).collect(),
        residual_std: q.iter().map(|v| v.1).collect(),
        samples: rows,
    };
    let with_az: Vec<_> = row_ks
        .iter()
        .filter_map(|&k| samples[k].az.map(|a| (a, samples[k - delay].u)))
        .collect();
    let mut vertical_scaled = false;
    if let Some(v) = fit_vertical(&with_az, &base.vertical) {
        params.vertical = v.vertical;
        params.vertical_offset = v.offset;
        quality.r_squared.push(v.r_squared);
        quality.residual_std.push(v.residual_std);
        vertical_scaled = v.scaled;
    }
    Ok(ArxFit {
        params,
        quality,
        vertical_scaled,
    })
}

/// Spectral radius of `w_k = Phi w_{k-1} + E (w_{k-1} - w_{k-2})` (6×6 companion matrix).
pub(super) fn arx_spectral_radius(p: &ArxParams) -> Option<f64> {
    let mut a = DMatrix::<f64>::zeros(6, 6);
    for i in 0..3 {
        for k in 0..3 {
            a[(i, k)] = p.phi[i][k] + p.previous_increment[i][k];
            a[(i, 3 + k)] = -p.previous_increment[i][k];
        }
        a[(3 + i, i)] = 1.0;
    }
    let ev = a.complex_eigenvalues();
    ev.iter().map(|c| c.norm()).reduce(f64::max)
}
