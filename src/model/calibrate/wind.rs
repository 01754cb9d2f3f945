//! The rate regressor instrumented by the previous sample, with the gusts' colour (AR(1)) fitted
//! alongside: the least-squares fit a gusty flight does not bias.

use super::*;
use nalgebra::{DMatrix, DVector};

/// Instrumental variables: the measured rate regressor carries the gyro noise, which biases
/// plain least squares towards less damping (errors in variables; 9 % on a yaw axis with
/// D dt = 0.03 in our test). The previous measured rate is correlated with the true rate but not
/// with this step's noise, so `(Zᵀ X) β = Zᵀ y` is consistent.
pub(super) fn instrumental(
    x: &DMatrix<f64>,
    z: &DMatrix<f64>,
    y: &DVector<f64>,
) -> Option<(DVector<f64>, f64, f64)> {
    let a = z.transpose() * x;
    let svd = a.clone().svd(true, true);
    let (s_max, s_min) = (svd.singular_values.max(), svd.singular_values.min());
    if s_max.is_nan() || s_max <= 0.0 || s_min < 1e-10 * s_max {
        return None;
    }
    let beta = svd.solve(&(z.transpose() * y), 1e-14 * s_max).ok()?;
    let (r2, sd) = fit_quality(x, y, &beta);
    Some((beta, r2, sd))
}

/// [`instrumental`] with a first-order (AR(1)) disturbance taken out: wind is coloured, so the
/// equation error of one step is correlated with the previous ones, and through the autopilot
/// (which reacts to what the wind did) with the commands and rates, which biases the fit
/// (simulated gusty quad and plane, true factor 0.9: x0.59-0.81 on roll and pitch).
/// Quasi-differencing every row with the error's AR(1) coefficient `phi`, estimated from its
/// lag-3 over lag-2 autocovariance (`y_k - phi y_{k-1}` on `x_k - phi x_{k-1}`, Cochrane-Orcutt,
/// iterated) leaves the wind's fresh part, which nothing before it knew. `step[i]`: row i's
/// position in sample periods. A short hole (lost samples) is bridged: `m` steps after the row
/// before it, a row is differenced with `phi^m` and weighted by the inverse standard deviation
/// of the `m` fresh wind terms that leaves (a link that lost one sample in ten used to leave
/// three rows in ten, and the gusty quad's and plane's factors went 13 % off on average).
/// Returns the fit on the original rows and the coefficients' standard errors (of the
/// quasi-differenced fit).
pub(super) fn instrumental_ar1(
    x: &DMatrix<f64>,
    z: &DMatrix<f64>,
    y: &DVector<f64>,
    step: &[u64],
) -> Option<WindFit> {
    let (mut beta, _, _) = instrumental(x, z, y)?;
    let mut std_errors = instrumental_std_errors(x, z, y, &beta)?;
    let apart = |i: usize| step[i].saturating_sub(step[i - 1]);
    // The wind's correlation is read on rows i-3..=i that are consecutive steps; the
    // differenced rows need only rows i-3..=i each within a bridged hole of the one before.
    let consecutive = |i: usize| (i - 2..=i).all(|j| apart(j) == 1);
    let bridged = |i: usize| (i - 2..=i).all(|j| (1..=MAX_BRIDGED_STEPS).contains(&apart(j)));
    let pairs: Vec<usize> = (3..y.len()).filter(|&i| consecutive(i)).collect();
    let rows: Vec<usize> = (3..y.len()).filter(|&i| bridged(i)).collect();
    // Columns whose regressor is one value on every row, with the same instrument.
    let constant: Vec<bool> = (0..x.ncols().min(z.ncols()))
        .map(|c| (0..y.len()).all(|i| x[(i, c)] == x[(0, c)] && z[(i, c)] == x[(0, c)]))
        .collect();
    if pairs.len() > 2 * x.ncols() && rows.len() > 2 * x.ncols() {
        for iteration in 0..AR1_ITERATIONS {
            let r = y - x * &beta;
            // The wind's correlation from lags 2 and 3: the measurement noise in the rows makes
            // the equation error MA(1) on top of the AR(1) wind, which lowers lags 0 and 1 only.
            let (num, den) = pairs.iter().fold((0.0, 0.0), |(a, b), &i| {
                (a + r[i] * r[i - 3], b + r[i] * r[i - 2])
            });
            // Only a disturbance that persists over two steps (lag-2 correlation of a tenth or
            // more) is modelled; white errors need no correction, and their lag ratio is noise.
            let power: f64 = pairs.iter().map(|&i| r[i] * r[i]).sum();
            if den <= 0.0 || (iteration == 0 && den <= MIN_LAG2_CORRELATION * power) {
                break;
            }
            let phi = (num / den).clamp(0.0, 0.999);
            let m = rows.len();
            let mut xq = DMatrix::<f64>::zeros(m, x.ncols());
            let mut zq = DMatrix::<f64>::zeros(m, z.ncols());
            let mut yq = DVector::<f64>::zeros(m);
            for (row, &i) in rows.iter().enumerate() {
                // Over a hole of `steps` periods the wind carries phi^steps and leaves `steps`
                // fresh terms (variance 1 + phi² + ... in units of one step's): the weight
                // evens the rows out (1 for consecutive ones).
                let steps = apart(i) as i32;
                let carry = phi.powi(steps);
                let weight = if steps == 1 {
                    1.0
                } else {
                    1.0 / (0..steps).map(|j| phi.powi(2 * j)).sum::<f64>().sqrt()
                };
                let carry_z = phi.powi(apart(i - 2) as i32);
                for c in 0..x.ncols() {
                    xq[(row, c)] = weight * (x[(i, c)] - carry * x[(i - 1, c)]);
                }
                // Instruments two rows older: free of the measurement noise in this row's
                // quasi-difference (which reaches back to row i-1's sample) and of the wind
                // since then. A constant column (the offset) is its own instrument: across a
                // hole its differenced value 1 - phi^m is not the older rows' 1 - phi^m', and
                // with phi near 1 that mismatch left the offset unidentified (a quad's roll
                // offset fitted at -15.9, R² -4.7, on 5 % random loss).
                for c in 0..z.ncols() {
                    zq[(row, c)] = if constant[c] {
                        xq[(row, c)]
                    } else {
                        weight * (z[(i - 2, c)] - carry_z * z[(i - 3, c)])
                    };
                }
                yq[row] = weight * (y[i] - carry * y[i - 1]);
            }
            // A singular late iteration keeps the last good one.
            let Some((b, _, _)) = instrumental(&xq, &zq, &yq) else {
                break;
            };
            let Some(se) = instrumental_std_errors(&xq, &zq, &yq, &b) else {
                break;
            };
            (beta, std_errors) = (b, se);
        }
    }
    let (r_squared, residual_std) = fit_quality(x, y, &beta);
    Some(WindFit {
        beta,
        r_squared,
        residual_std,
        std_errors,
    })
}

/// What [`instrumental_ar1`] returns.
pub(super) struct WindFit {
    pub(super) beta: DVector<f64>,
    pub(super) r_squared: f64,
    pub(super) residual_std: f64,
    pub(super) std_errors: DVector<f64>,
}

/// Standard errors of an instrumented fit: `σ² (ZᵀX)⁻¹ ZᵀZ (XᵀZ)⁻¹` on the diagonal. White
/// errors are assumed; after quasi-differencing the gyro noise still leaves a short moving
/// average, so these are somewhat small, which makes the 2σ switch in `calibrate_scaled` lean
/// towards the wind-modelled fit. None when a variance is not finite.
pub(super) fn instrumental_std_errors(
    x: &DMatrix<f64>,
    z: &DMatrix<f64>,
    y: &DVector<f64>,
    beta: &DVector<f64>,
) -> Option<DVector<f64>> {
    let resid = y - x * beta;
    let dof = (y.len() as f64 - x.ncols() as f64).max(1.0);
    let sigma2 = resid.norm_squared() / dof;
    let zx_inv = (z.transpose() * x).try_inverse()?;
    let cov = &zx_inv * (z.transpose() * z) * zx_inv.transpose() * sigma2;
    let var = cov.diagonal();
    var.iter()
        .all(|v| v.is_finite())
        .then(|| var.map(|v| v.max(0.0).sqrt()))
}

/// The longest hole (sample periods between two fit rows) [`instrumental_ar1`] differences
/// across: one lost sample leaves five (its row, the one whose outputs it carried and the rows
/// on either side that need it), two in a row six.
pub(super) const MAX_BRIDGED_STEPS: u64 = 8;

/// How much larger the wind-modelled fit's one-step residual may be than the plain fit's
/// (both on the same rows) for it to be taken: a consistent fit of the same vehicle predicts
/// nearly as well (measured on the gusty test flights, lossy or not: at most 1.48, on a weakly
/// damped yaw axis; the offset left unidentified across holes gave 36).
pub(super) const MAX_WIND_MISFIT: f64 = 3.0;

/// Cochrane-Orcutt iterations of [`instrumental_ar1`].
pub(super) const AR1_ITERATIONS: usize = 5;

/// Lag-2 correlation of the equation error from which [`instrumental_ar1`] models it.
pub(super) const MIN_LAG2_CORRELATION: f64 = 0.1;
