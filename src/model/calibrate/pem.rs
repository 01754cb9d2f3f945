//! One rate axis fitted by maximum likelihood with the wind as a first-order (AR(1)) state: the
//! prediction-error method.
//!
//! The axis in the form [`calibrate_scaled`](super::calibrate_scaled) fits,
//!
//! ```text
//! ω_{k+1} = a ω_k + β g_{k+1} + c' + w_k,    w_{k+1} = φ w_k + ε_k,    y_k = ω_k + n_k,
//! ```
//!
//! with `g` the profile's drive of the axis, the wind `w` (ε white, variance `q`) and the gyro
//! noise `n` (white, variance `r`). The autopilot reacts to what the wind did, so commands and
//! rates are correlated with the wind's next push: least squares on `y_{k+1}` against
//! `(y_k, g, 1)` mistakes the wind for weaker actuators and less damping, and the fit on
//! quasi-differenced rows (Cochrane-Orcutt) that removes that bias keeps only the rows' fast
//! part, whose instruments are weak (its factor's standard error over 30 s of flight is
//! 0.2-0.3). The Kalman filter of this model turns the measurements into innovations that
//! are white with known variance when the parameters are the true ones, so the Gaussian
//! likelihood of the innovations is the exact likelihood, consistent and efficient (the
//! filter weighs the slow part that the wind shares and the fast part that it does not as
//! their noise says).
//!
//! The innovations are affine in `(β, c')` for fixed `(a, φ, q/r)` (the filter's gains do
//! not depend on them), so those two are solved in closed form (weighted least squares on
//! three filter runs: the measurements, the drive and a constant), and `r` too (the
//! innovations' scale); a Nelder-Mead search runs over the other three. No allocation per
//! likelihood evaluation.

use super::CalibrationSample;

/// What one sample contributes to the filter: the measurement `y`, the drive `g` that acted
/// over the step ending at it, and how it joins the one before.
#[derive(Debug, Clone, Copy)]
pub(super) struct Row {
    pub y: f64,
    pub g: f64,
    pub link: Link,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Link {
    /// The first sample, or one after a hole longer than [`MAX_BRIDGED_STEPS`] periods (this
    /// many): the rate starts again from the measurement, the wind carries over the hole.
    Restart(u64),
    /// Measured this many periods (2 to [`MAX_BRIDGED_STEPS`]) after the previous sample: the
    /// filter predicts across the hole with the commands interpolated between the two, and
    /// updates. Restarting the rate instead leaves its tie to the wind behind, which biased
    /// the fit like least squares (a 10 % loss: factors x0.79-0.92 against x0.91-1.01).
    Across(u64),
    /// One period after the previous sample, measured: predict and update.
    Next,
    /// One period after the previous sample, filled into a short hole: predict only.
    Filled,
}

impl Row {
    /// The rows of one axis: `drive` maps a sample's commands to the axis' drive.
    pub fn of(
        samples: &[CalibrationSample],
        axis: usize,
        drive: impl Fn(&[f64]) -> f64,
    ) -> Vec<Row> {
        let mut prev_step = None;
        samples
            .iter()
            .map(|s| {
                let link = match prev_step {
                    Some(p) if s.follows_previous && s.step == p + 1 => {
                        if s.measured {
                            Link::Next
                        } else {
                            Link::Filled
                        }
                    }
                    Some(p) => match s.step.saturating_sub(p).max(1) {
                        steps @ 2..=MAX_BRIDGED_STEPS if s.measured => Link::Across(steps),
                        steps => Link::Restart(steps),
                    },
                    None => Link::Restart(0),
                };
                prev_step = Some(s.step);
                Row {
                    y: s.rates[axis],
                    g: drive(s.u),
                    link,
                }
            })
            .collect()
    }
}

/// The fit: the axis' coefficients and the wind's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct PemFit {
    pub a: f64,
    pub beta: f64,
    pub c: f64,
    pub phi: f64,
    /// Standard deviations of the wind's fresh push per step and of the measurement noise.
    pub wind_std: f64,
    pub noise_std: f64,
    /// Ljung-Box statistic of the normalised innovations over lags 1 to [`WHITENESS_LAGS`]:
    /// about χ² with that many degrees of freedom when the model holds (see [`fit_axis_within`]).
    pub whiteness: f64,
}

impl PemFit {
    /// The wind as the gusts that make it: the stationary standard deviation of `w`
    /// (`wind_std / √(1-φ²)`) over the step's hold `(1-a)/d` (`d = -ln a / dt`), an angular
    /// acceleration (rad/s²) held over each step as the simulator's gusts are.
    pub fn gust_std(&self, dt: f64) -> f64 {
        let d = -self.a.ln() / dt;
        let hold = (1.0 - self.a) / d;
        self.wind_std / (1.0 - self.phi * self.phi).max(1e-12).sqrt() / hold
    }
}

/// The wind after a restart `steps` periods on (0: unknown): the share `φ^steps` of its
/// estimate that carries over (none for an unknown span), and its variance, which relaxes
/// towards the stationary one by the same share.
fn restarted_wind(phi: f64, steps: u64, stationary: f64, p11: f64) -> (f64, f64) {
    let carry = if steps == 0 {
        0.0
    } else {
        phi.powi(steps.min(i32::MAX as u64) as i32)
    };
    (
        carry,
        carry * carry * p11 + (1.0 - carry * carry) * stationary,
    )
}

/// One step of the state's covariance `(P00, P01, P11)` (rate, wind) in units of `r`: the rate
/// takes `a` of itself and the wind, the wind `φ` of itself and a fresh push of variance `q`.
fn predicted_covariance(
    a: f64,
    phi: f64,
    q: f64,
    (p00, p01, p11): (f64, f64, f64),
) -> (f64, f64, f64) {
    (
        a * a * p00 + 2.0 * a * p01 + p11,
        phi * (a * p01 + p11),
        phi * phi * p11 + q,
    )
}

/// Lags of the innovations' whiteness check.
pub(super) const WHITENESS_LAGS: usize = 10;

/// χ² with [`WHITENESS_LAGS`] degrees of freedom at 99.9 %: innovations whiter than this are
/// taken for the model holding (a model that holds fails it on one axis in a thousand).
pub(super) const WHITENESS_LIMIT: f64 = 29.59;

/// The longest hole (in sample periods) predicted across with interpolated commands: about the
/// longest a short hole of the telemetry is filled over (`pipeline::holes`).
pub(super) const MAX_BRIDGED_STEPS: u64 = 8;

/// Most wind correlation per step searched (a time constant of 50 s at 50 Hz): beyond it the
/// wind is a drifting offset, which the filter follows as well.
const PHI_MAX: f64 = 0.9996;

/// Likelihood evaluations of the search (each a pass over the rows); the search restarts once
/// from its best point, as Nelder-Mead's simplex can collapse early.
pub(super) const MAX_EVALUATIONS: usize = 600;

/// [`fit_axis_within`] with the calibration's budget.
#[cfg(test)]
pub(super) fn fit_axis(rows: &[Row], a0: f64) -> Option<PemFit> {
    fit_axis_within(rows, a0, MAX_EVALUATIONS)
}

/// Fit one axis from its rows, the search starting from the decay `a0` (a plain fit's or the
/// profile's), each of its two runs stopped after `max_evaluations`.
/// `None` when too few rows were measured or no starting point gives a finite likelihood.
pub(super) fn fit_axis_within(rows: &[Row], a0: f64, max_evaluations: usize) -> Option<PemFit> {
    if rows.iter().filter(|r| r.link == Link::Next).count() < 20 {
        return None;
    }
    // Search space: a, φ and ln(q/r); start with a wind as strong as the noise, slow.
    let start = [a0.clamp(0.05, 0.999), 0.9, 0.0];
    let step = [0.02_f64.min(0.5 * (1.0 - start[0])), 0.05, 1.5];
    let cost = |p: &[f64; 3]| concentrated(rows, p).map_or(f64::INFINITY, |c| c.cost);
    let (first, _) = nelder_mead(cost, start, step, max_evaluations);
    let (best, value) = nelder_mead(cost, first, step.map(|s| 0.2 * s), max_evaluations);
    if !value.is_finite() {
        return None;
    }
    let c = concentrated(rows, &best)?;
    Some(PemFit {
        a: best[0],
        beta: c.beta,
        c: c.c,
        phi: best[1],
        wind_std: (c.r * best[2].exp()).sqrt(),
        noise_std: c.r.sqrt(),
        whiteness: ljung_box(&innovations(rows, &best, c.beta, c.c)),
    })
}

/// The normalised innovations `e / √S` of the filter at `(a, φ, ln(q/r))` with gain `beta` and
/// offset `c`, over the updated rows (a restart starts a new run; the statistic ignores the
/// seams).
fn innovations(rows: &[Row], p: &[f64; 3], beta: f64, c: f64) -> Vec<f64> {
    let [a, phi, log_ratio] = *p;
    let q = log_ratio.exp();
    let stationary = q / (1.0 - phi * phi);
    let (mut x0, mut x1) = (0.0f64, 0.0f64);
    let (mut p00, mut p01, mut p11) = (1.0, 0.0, stationary);
    let mut prev_g = 0.0;
    let mut out = Vec::with_capacity(rows.len());
    for row in rows {
        let steps = match row.link {
            Link::Restart(steps) => {
                let carry;
                (carry, p11) = restarted_wind(phi, steps, stationary, p11);
                x0 = row.y;
                x1 *= carry;
                (p00, p01) = (1.0, 0.0);
                prev_g = row.g;
                continue;
            }
            Link::Across(steps) => steps,
            Link::Next | Link::Filled => 1,
        };
        for i in 1..=steps {
            let g = prev_g + (row.g - prev_g) * i as f64 / steps as f64;
            x0 = a * x0 + x1 + beta * g + c;
            x1 *= phi;
            (p00, p01, p11) = predicted_covariance(a, phi, q, (p00, p01, p11));
        }
        prev_g = row.g;
        if row.link == Link::Filled {
            continue;
        }
        let s = p00 + 1.0;
        let e = row.y - x0;
        out.push(e / s.sqrt());
        let (k0, k1) = (p00 / s, p01 / s);
        x0 += k0 * e;
        x1 += k1 * e;
        p11 -= k1 * p01;
        p01 -= k0 * p01;
        p00 -= k0 * p00;
    }
    out
}

/// Ljung-Box `n (n + 2) Σ ρ_k² / (n - k)` over lags 1 to [`WHITENESS_LAGS`].
fn ljung_box(e: &[f64]) -> f64 {
    let n = e.len();
    if n <= 2 * WHITENESS_LAGS {
        return f64::INFINITY;
    }
    let mean = e.iter().sum::<f64>() / n as f64;
    let var: f64 = e.iter().map(|v| (v - mean).powi(2)).sum();
    if var.is_nan() || var <= 0.0 {
        return f64::INFINITY;
    }
    (1..=WHITENESS_LAGS)
        .map(|k| {
            let rho = (k..n)
                .map(|i| (e[i] - mean) * (e[i - k] - mean))
                .sum::<f64>()
                / var;
            rho * rho / (n - k) as f64
        })
        .sum::<f64>()
        * (n * (n + 2)) as f64
}

/// The likelihood at `(a, φ, ln(q/r))` with `β`, `c'` and `r` at their best.
struct Concentrated {
    cost: f64,
    beta: f64,
    c: f64,
    r: f64,
}

/// A measured row's part of the covariance recursion, from the predicted covariance: the
/// innovation variance `S`, the gains, `ln S` and the updated covariance.
#[derive(Debug, Clone, Copy)]
struct MeasuredStep {
    s: f64,
    k0: f64,
    k1: f64,
    ln_s: f64,
    updated: (f64, f64, f64),
}

fn measured_step((p00, p01, p11): (f64, f64, f64)) -> MeasuredStep {
    let s = p00 + 1.0;
    let (k0, k1) = (p00 / s, p01 / s);
    MeasuredStep {
        s,
        k0,
        k1,
        ln_s: s.ln(),
        updated: (p00 - k0 * p00, p01 - k0 * p01, p11 - k1 * p01),
    }
}

fn same_bits(x: (f64, f64, f64), y: (f64, f64, f64)) -> bool {
    x.0.to_bits() == y.0.to_bits()
        && x.1.to_bits() == y.1.to_bits()
        && x.2.to_bits() == y.2.to_bits()
}

/// One filter run per input (the measurements; the drive with gain 1; a constant 1), sharing
/// the covariance recursion (in units of `r`). Returns `None` outside the model's range or
/// when the drive and the constant cannot be told apart.
fn concentrated(rows: &[Row], p: &[f64; 3]) -> Option<Concentrated> {
    concentrated_with(rows, p, true)
}

/// [`concentrated`]; `reuse` takes a one-period measured row's covariance step from the last
/// such row's when it starts from the same covariance, bit for bit. The recursion does not
/// depend on the data and usually settles within tens of rows to a fixed point, after which
/// every row's step is the last one's: the same numbers without the divisions and logarithm on
/// the recursion's serial path (where it does not settle, nothing is reused).
#[allow(clippy::many_single_char_names)]
fn concentrated_with(rows: &[Row], p: &[f64; 3], reuse: bool) -> Option<Concentrated> {
    let [a, phi, log_ratio] = *p;
    if !(a > 0.0 && a < 1.0 && (0.0..=PHI_MAX).contains(&phi) && log_ratio.abs() < 30.0) {
        return None;
    }
    let q = log_ratio.exp();
    let stationary = q / (1.0 - phi * phi);
    // State (rate, wind) per run: measurements, drive, constant. Covariance shared.
    let mut x = [[0.0f64; 2]; 3];
    let (mut p00, mut p01, mut p11) = (1.0, 0.0, stationary);
    // Σ e_i e_j / S over updated rows, and Σ ln S.
    let mut m = [[0.0f64; 3]; 3];
    let (mut log_det, mut count) = (0.0, 0usize);
    let mut prev_g = 0.0;
    // The last one-period measured row's covariance before its prediction, and its step.
    let mut last: Option<((f64, f64, f64), MeasuredStep)> = None;
    for row in rows {
        let steps = match row.link {
            Link::Restart(steps) => {
                let carry;
                (carry, p11) = restarted_wind(phi, steps, stationary, p11);
                for (run, xr) in x.iter_mut().enumerate() {
                    xr[0] = if run == 0 { row.y } else { 0.0 };
                    xr[1] *= carry;
                }
                (p00, p01) = (1.0, 0.0);
                prev_g = row.g;
                continue;
            }
            Link::Across(steps) => steps,
            Link::Next | Link::Filled => 1,
        };
        for i in 1..=steps {
            let g = prev_g + (row.g - prev_g) * i as f64 / steps as f64;
            for (xr, input) in x.iter_mut().zip([0.0, g, 1.0]) {
                xr[0] = a * xr[0] + xr[1] + input;
                xr[1] *= phi;
            }
        }
        prev_g = row.g;
        let step = match last {
            Some((from, step))
                if reuse && row.link == Link::Next && same_bits(from, (p00, p01, p11)) =>
            {
                step
            }
            _ => {
                let from = (p00, p01, p11);
                for _ in 0..steps {
                    (p00, p01, p11) = predicted_covariance(a, phi, q, (p00, p01, p11));
                }
                if row.link == Link::Filled {
                    continue;
                }
                let step = measured_step((p00, p01, p11));
                if row.link == Link::Next {
                    last = Some((from, step));
                }
                step
            }
        };
        (p00, p01, p11) = step.updated;
        let MeasuredStep { s, k0, k1, .. } = step;
        let measured = [row.y, 0.0, 0.0];
        let mut e = [0.0; 3];
        for ((xr, ei), y) in x.iter_mut().zip(&mut e).zip(measured) {
            *ei = y - xr[0];
            xr[0] += k0 * *ei;
            xr[1] += k1 * *ei;
        }
        for i in 0..3 {
            for j in i..3 {
                m[i][j] += e[i] * e[j] / s;
            }
        }
        log_det += step.ln_s;
        count += 1;
    }
    // The innovations are e0 + β e1 + c e2 (the drive's and constant's runs enter negated, as
    // predicted responses): minimise Σ (e0 + β e1 + c e2)² / S.
    let (g11, g12, g22) = (m[1][1], m[1][2], m[2][2]);
    let det = g11 * g22 - g12 * g12;
    if det.is_nan() || det <= 1e-12 * g11 * g22 || count == 0 {
        return None;
    }
    let (b1, b2) = (-m[0][1], -m[0][2]);
    let beta = (g22 * b1 - g12 * b2) / det;
    let c = (g11 * b2 - g12 * b1) / det;
    let weighted = m[0][0] - beta * b1 - c * b2;
    let n = count as f64;
    let r = weighted / n;
    if !(r > 0.0 && r.is_finite()) {
        return None;
    }
    Some(Concentrated {
        cost: 0.5 * n * r.ln() + 0.5 * log_det,
        beta,
        c,
        r,
    })
}

/// Nelder-Mead minimisation of `f` from `x0` with initial simplex steps `step` (standard
/// coefficients: reflection 1, expansion 2, contraction and shrink ½). Returns the best point
/// and value after at most `max_evals` evaluations, or earlier once the simplex's values agree
/// within 1e-9 (relative) and its points within 1e-7 of a step.
fn nelder_mead<const D: usize>(
    f: impl Fn(&[f64; D]) -> f64,
    x0: [f64; D],
    step: [f64; D],
    max_evals: usize,
) -> ([f64; D], f64) {
    let mut pts = vec![x0; D + 1];
    for (i, p) in pts.iter_mut().skip(1).enumerate() {
        p[i] += step[i];
    }
    let mut vals: Vec<f64> = pts.iter().map(&f).collect();
    let mut evals = D + 1;
    let along = |from: &[f64; D], to: &[f64; D], t: f64| -> [f64; D] {
        std::array::from_fn(|i| from[i] + t * (to[i] - from[i]))
    };
    while evals < max_evals {
        let mut order: Vec<usize> = (0..=D).collect();
        order.sort_by(|&i, &j| vals[i].total_cmp(&vals[j]));
        pts = order.iter().map(|&i| pts[i]).collect();
        vals = order.iter().map(|&i| vals[i]).collect();
        let (best, worst) = (vals[0], vals[D]);
        let spread = (0..D).all(|i| {
            pts.iter()
                .all(|p| (p[i] - pts[0][i]).abs() <= 1e-7 * step[i].abs().max(1e-12))
        });
        if (worst - best).abs() <= 1e-9 * best.abs().max(1.0) && spread || !best.is_finite() {
            break;
        }
        let centroid: [f64; D] =
            std::array::from_fn(|i| pts[..D].iter().map(|p| p[i]).sum::<f64>() / D as f64);
        let reflected = along(&centroid, &pts[D], -1.0);
        let fr = f(&reflected);
        evals += 1;
        if fr < vals[0] {
            let expanded = along(&centroid, &pts[D], -2.0);
            let fe = f(&expanded);
            evals += 1;
            (pts[D], vals[D]) = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < vals[D - 1] {
            (pts[D], vals[D]) = (reflected, fr);
        } else {
            let toward = if fr < vals[D] { reflected } else { pts[D] };
            let contracted = along(&centroid, &toward, 0.5);
            let fc = f(&contracted);
            evals += 1;
            if fc < vals[D].min(fr) {
                (pts[D], vals[D]) = (contracted, fc);
            } else {
                for i in 1..=D {
                    pts[i] = along(&pts[0], &pts[i], 0.5);
                    vals[i] = f(&pts[i]);
                }
                evals += D;
            }
        }
    }
    let i = (0..=D)
        .min_by(|&i, &j| vals[i].total_cmp(&vals[j]))
        .unwrap_or(0);
    (pts[i], vals[i])
}

#[cfg(test)]
#[path = "pem_tests.rs"]
mod tests;
