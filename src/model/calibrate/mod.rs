//! Calibration: `D`, `G` and `c` of the rate-effectiveness model identified by least squares
//! from a healthy stretch of samples (rates and commands at a fixed period).
//!
//! Each axis is fitted in its exact zero-order-hold form, `w_{k+1} = a w_k + Σ b_j u_j + c'`,
//! which is the finite-difference fit without the Euler error; then `D = -ln(a) / dt`,
//! `G = b / hold`, `c = c' / hold` with `hold = (1 - a) / D`. The vertical specific force row
//! (when present) is `a_z = Σ g_z,j u_j + c_z`. The rate regressor is instrumented by the
//! previous sample (see `instrumental`); [`calibrate_arx`] says why it is not. The in-flight
//! calibration against a profile's geometry ([`calibrate_scaled`]) fits each rate axis by
//! maximum likelihood with the wind as a state (`pem`), which the instrumented fit only starts.

use super::{ArxParams, RateParams};
use nalgebra::{DMatrix, DVector};
use thiserror::Error;

mod arx;
mod pem;
mod scaled;

pub use arx::{ArxFit, calibrate_arx};
use pem::{MAX_EVALUATIONS, Row, WHITENESS_LIMIT, fit_axis_within};
use scaled::fit_vertical;
pub use scaled::{ScaledFit, calibrate_scaled, calibrate_scaled_within};

/// A static a_z row, `a_z = c_z + Σ_j g_z,j u_j`, on `(a_z, commands)` pairs: the geometry's
/// `base_vertical` scaled where the pairs determine the scale, else as it is, and the trim.
pub fn vertical_row(with_az: &[(f64, &[f64])], base_vertical: &[f64]) -> Option<(Vec<f64>, f64)> {
    scaled::fit_vertical(with_az, base_vertical).map(|v| (v.vertical, v.offset))
}

#[derive(Debug, Error, PartialEq)]
pub enum CalibrationError {
    #[error("{got} usable samples: at least {need} are needed for {l} actuators")]
    TooFew { got: usize, need: usize, l: usize },
    #[error("the commands do not excite axis {axis} enough to identify it (rank-deficient fit)")]
    NotExcited { axis: usize },
    #[error(
        "axis {axis}: identified decay {a} is not in (0, 1]; the stretch is not healthy or not at one rate"
    )]
    Unstable { axis: usize, a: f64 },
    #[error("non-finite sample")]
    NonFinite,
    #[error(
        "the identified rate model is unstable (spectral radius {radius:.3}); the stretch is not healthy or not at one rate"
    )]
    UnstableModel { radius: f64 },
    #[error("no command delay gives a full-rank fit: the commands do not excite the rates")]
    NoDelayFits,
}

/// How well each row fitted: R² and the residual standard deviation (rad/s per step, m/s²).
#[derive(Debug, Clone, PartialEq)]
pub struct FitQuality {
    pub r_squared: Vec<f64>,
    pub residual_std: Vec<f64>,
    pub samples: usize,
}

/// One sample: rates at the end of the step, the commands applied over it, optional a_z.
#[derive(Debug, Clone, Copy)]
pub struct CalibrationSample<'a> {
    pub rates: [f64; 3],
    pub u: &'a [f64],
    pub az: Option<f64>,
    /// This sample comes one period after the previous one in the slice (false after a gap
    /// in the telemetry). A fit row spans several consecutive samples; rows across a gap
    /// would take the change over the gap for one step's, so they are left out.
    pub follows_previous: bool,
    /// The sample's position on the telemetry clock, in sample periods (its time over the
    /// period, rounded): samples on either side of a hole are as many steps apart as periods
    /// passed. Only differences are used.
    pub step: u64,
    /// Measured, not filled into a short hole of the telemetry: a filled sample serves as a
    /// row's history, never as the increment a row fits.
    pub measured: bool,
}

/// For every sample, the index where its unbroken run of samples starts.
fn run_starts(samples: &[CalibrationSample]) -> Vec<usize> {
    let mut starts = Vec::with_capacity(samples.len());
    for (k, s) in samples.iter().enumerate() {
        let start = if k > 0 && s.follows_previous {
            starts[k - 1]
        } else {
            k
        };
        starts.push(start);
    }
    starts
}

/// The indices `k` for which samples `k - before ..= k + after` are one unbroken run and the
/// samples a row's target and instruments come from (`k - 1 ..= k + after`) were measured:
/// a filled sample is a straight line through its neighbours, so as the far end of an
/// increment it would make the target that line's slope, and as an instrument it would carry
/// the regressor's own noise. Older history (the arx fit's earlier increments) may be filled.
fn unbroken_rows(samples: &[CalibrationSample], before: usize, after: usize) -> Vec<usize> {
    let starts = run_starts(samples);
    (before..samples.len().saturating_sub(after))
        .filter(|&k| starts[k + after] + before <= k)
        .filter(|&k| {
            samples[k - before.min(1)..=k + after]
                .iter()
                .all(|s| s.measured)
        })
        .collect()
}

/// Identify the model from consecutive samples at period `dt`. With `fit_offset = false` the
/// trim offsets are held at zero (use it when the commands sum to a near-constant, as a
/// hovering multirotor's do, which makes an offset collinear with them).
pub fn calibrate(
    samples: &[CalibrationSample],
    dt: f64,
    fit_offset: bool,
) -> Result<(RateParams, FitQuality), CalibrationError> {
    let l = samples.first().map_or(0, |s| s.u.len());
    let cols = 1 + l + fit_offset as usize;
    let need = 10 * cols;
    if samples.len() < need + 1 {
        return Err(CalibrationError::TooFew {
            got: samples.len(),
            need: need + 1,
            l,
        });
    }
    let ok = samples.iter().all(|s| {
        s.rates.iter().all(|v| v.is_finite())
            && s.u.iter().all(|v| v.is_finite())
            && s.az.is_none_or(f64::is_finite)
    });
    if !ok || samples.iter().any(|s| s.u.len() != l) {
        return Err(CalibrationError::NonFinite);
    }
    // Rows start at k = 1 so that the previous rate can serve as the instrument.
    let rows = unbroken_rows(samples, 1, 1);
    let n = rows.len();
    // Unbroken, need + 1 samples give need - 1 rows (the first check's bar).
    if n + 1 < need {
        return Err(CalibrationError::TooFew {
            got: n + 2,
            need: need + 1,
            l,
        });
    }
    let mut params = RateParams {
        damping: [0.0; 3],
        effectiveness: vec![[0.0; 3]; l],
        vertical: vec![],
        offset: [0.0; 3],
        vertical_offset: 0.0,
    };
    let mut quality = FitQuality {
        r_squared: vec![],
        residual_std: vec![],
        samples: n,
    };
    for axis in 0..3 {
        let mut x = DMatrix::<f64>::zeros(n, cols);
        let mut z = DMatrix::<f64>::zeros(n, cols);
        let mut y = DVector::<f64>::zeros(n);
        for (r, &k) in rows.iter().enumerate() {
            // Row r: the step from sample k to k+1 under the commands of sample k+1.
            x[(r, 0)] = samples[k].rates[axis];
            z[(r, 0)] = samples[k - 1].rates[axis];
            for j in 0..l {
                x[(r, 1 + j)] = samples[k + 1].u[j];
                z[(r, 1 + j)] = samples[k + 1].u[j];
            }
            if fit_offset {
                x[(r, 1 + l)] = 1.0;
                z[(r, 1 + l)] = 1.0;
            }
            y[r] = samples[k + 1].rates[axis];
        }
        let (beta, r2, sd) =
            instrumental(&x, &z, &y).ok_or(CalibrationError::NotExcited { axis })?;
        let a = beta[0];
        if !(a > 0.0 && a <= 1.0) {
            return Err(CalibrationError::Unstable { axis, a });
        }
        let d = -a.ln() / dt;
        let hold = if d * dt > 1e-12 { (1.0 - a) / d } else { dt };
        params.damping[axis] = d;
        for j in 0..l {
            params.effectiveness[j][axis] = beta[1 + j] / hold;
        }
        if fit_offset {
            params.offset[axis] = beta[1 + l] / hold;
        }
        quality.r_squared.push(r2);
        quality.residual_std.push(sd);
    }
    if samples.iter().all(|s| s.az.is_some()) {
        // Measured samples only: a filled a_z is a straight line, not a measurement.
        let measured: Vec<&CalibrationSample> = samples.iter().filter(|s| s.measured).collect();
        let cols = l + fit_offset as usize;
        let mut x = DMatrix::<f64>::zeros(measured.len(), cols);
        let mut y = DVector::<f64>::zeros(measured.len());
        for (k, s) in measured.iter().enumerate() {
            for j in 0..l {
                x[(k, j)] = s.u[j];
            }
            if fit_offset {
                x[(k, l)] = 1.0;
            }
            y[k] = s.az.unwrap_or(0.0);
        }
        let (beta, r2, sd) =
            least_squares(&x, &y).ok_or(CalibrationError::NotExcited { axis: 3 })?;
        params.vertical = beta.iter().take(l).copied().collect();
        if fit_offset {
            params.vertical_offset = beta[l];
        }
        quality.r_squared.push(r2);
        quality.residual_std.push(sd);
    }
    Ok((params, quality))
}

/// Instrumental variables: the measured rate regressor carries the gyro noise, which biases
/// plain least squares towards less damping (errors in variables; 9 % on a yaw axis with
/// D dt = 0.03 in our test). The previous measured rate is correlated with the true rate but not
/// with this step's noise, so `(Zᵀ X) β = Zᵀ y` is consistent.
fn instrumental(
    x: &DMatrix<f64>,
    z: &DMatrix<f64>,
    y: &DVector<f64>,
) -> Option<(DVector<f64>, f64, f64)> {
    let a = z.transpose() * x;
    let zy = z.transpose() * y;
    // nalgebra's SVD panics on NaN and never returns on an infinity.
    if !(all_entries_finite(&a) && zy.iter().all(|v| v.is_finite())) {
        return None;
    }
    let svd = a.clone().svd(true, true);
    let (s_max, s_min) = (svd.singular_values.max(), svd.singular_values.min());
    if s_max.is_nan() || s_max <= 0.0 || s_min < 1e-10 * s_max {
        return None;
    }
    let beta = svd.solve(&zy, 1e-14 * s_max).ok()?;
    let (r2, sd) = fit_quality(x, y, &beta);
    Some((beta, r2, sd))
}

fn all_entries_finite(m: &DMatrix<f64>) -> bool {
    m.iter().all(|v| v.is_finite())
}

/// Every sample has `l` commands and finite numbers.
fn all_finite(samples: &[CalibrationSample], l: usize) -> bool {
    samples.iter().all(|s| {
        s.u.len() == l
            && s.rates.iter().all(|v| v.is_finite())
            && s.u.iter().all(|v| v.is_finite())
            && s.az.is_none_or(f64::is_finite)
    })
}

/// R² and residual standard deviation (per degree of freedom) of a linear fit.
fn fit_quality(x: &DMatrix<f64>, y: &DVector<f64>, beta: &DVector<f64>) -> (f64, f64) {
    let resid = y - x * beta;
    let mean = y.mean();
    let tss: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let rss = resid.norm_squared();
    let r2 = if tss > 0.0 { 1.0 - rss / tss } else { 1.0 };
    let dof = (y.len() as f64 - x.ncols() as f64).max(1.0);
    (r2, (rss / dof).sqrt())
}

/// Least squares by SVD with a rank check; returns (coefficients, R², residual std).
fn least_squares(x: &DMatrix<f64>, y: &DVector<f64>) -> Option<(DVector<f64>, f64, f64)> {
    // nalgebra's SVD panics on NaN and never returns on an infinity.
    if !(all_entries_finite(x) && y.iter().all(|v| v.is_finite())) {
        return None;
    }
    let svd = x.clone().svd(true, true);
    let s_max = svd.singular_values.max();
    let s_min = svd.singular_values.min();
    if s_max.is_nan() || s_max <= 0.0 || s_min < 1e-9 * s_max {
        return None;
    }
    let beta = svd.solve(y, 1e-12 * s_max).ok()?;
    let (r2, sd) = fit_quality(x, y, &beta);
    Some((beta, r2, sd))
}

#[cfg(test)]
mod tests;
