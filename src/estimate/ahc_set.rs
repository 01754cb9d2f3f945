//! The guaranteed estimator of a vehicle's actuator health coefficients: bounded-error
//! (set-membership) estimation of each actuator's `(γ_j, δ_j)` on the rate-effectiveness
//! model with the rates *measured* (`docs/estimators.md`, the set-membership AHC filter).
//!
//! With the previous measured rates `y_{k-1}` every measured row is affine in the effective
//! outputs `η_j = γ_j u_j + δ_j`:
//!
//! ```text
//! r_k = y_k - f(y_{k-1}, γ = 0, δ = 0, u_k) = B η_k + e_k,      |e_{k,i}| ≤ σ_i
//! ```
//!
//! (rows p, q, r and, measured, a_z; `B` the model's effect of one unit of output on each row
//! over a step). A model that predicts the rates only (an identified helicopter's) may still
//! give the set a static a_z row ([`AhcSet::with_vertical`]): `a_z - c_z = Σ g_z,j η_j + e`, its
//! bound measured like the others'; it bounds the levels, not the changes (see below). `e` is
//! what the healthy model leaves unexplained on a step (gusts, model error, the gyro's noise on
//! both samples); `σ(0)` is its stated bound, `σ(m)` that of its change
//! over `m` samples (both from the calibration stretch, with a margin).
//!
//! **Each sample bounds each output.** When `B` has full column rank (at least as many
//! measured rows as actuators, independent), any left inverse `L` gives `η = L(r - e)`, so
//! `z_j = (L r)_j` bounds `η_j` within `Σ_i |L_ji| σ_i`; `L` is the weighted least-squares
//! one, `(Bᵀ W B)⁻¹ Bᵀ W` with `W = diag(σ⁻²)`. Otherwise (more actuators than rows) each row
//! bounds each output by interval arithmetic over the others' current ranges.
//!
//! **Changes bound the gain.** Gusts are slow: the unexplained part changes over `m` samples by
//! far less than its level. So beside the level, `|z_k - γ u_k - δ| ≤ Σ_i |L_ji| σ_i(0)`, each
//! sample compares its output with those `m` samples before ([`LAGS`]):
//! `|z_k - z_{k-m} - γ (u_k - u_{k-m})| ≤ Σ_i |L_ji| σ_i(m)` (plus the drift over the lag) bounds
//! the gain alone, the bias and the wind's level cancelling. A bias and a steady wind are the
//! same thing to the rates: the bias' bound cannot be narrower than the wind's level.
//!
//! **Each actuator's set is a polygon.** A bound `lo ≤ γ u + δ ≤ hi` is a strip in the
//! `(γ, δ)` plane (a gain bound a vertical one); the intersection of all of them with the a
//! priori box is the exact feasible set, a convex polygon ([`super::polygon`], at most [`VERTICES`] vertices, grown to fewer when
//! needed). Between samples `γ` and `δ` may move by at most the stated drift per step (a
//! Minkowski sum with that box, exact): the bound of a slow fault. A faster change (a step
//! fault) leaves the polygon; a sample whose strip misses it *contradicts* that actuator, whose
//! set then starts again from the a priori box and this sample, its bounds widened by
//! [`CONTRADICTION_GROWTH`] (the contradiction may be the stated bounds', not the actuator's).
//!
//! So the bounds are guaranteed while `|e| ≤ σ` and each coefficient moves by at most the drift
//! per step, and re-established after a jump from the first sample that contradicts it. A
//! direction the data do not see keeps the extent it had plus the drift and stops at the a
//! priori box; nothing is inflated by a factor.

// Index loops mirror the maths (rows i, actuators j) and read best that way.
#![allow(clippy::needless_range_loop)]

use super::polygon::Polygon;
use super::{EstimatorError, check_commands};
use crate::model::{MAX_ACTUATORS, Model, RateModel};
use nalgebra::{DMatrix, SVector};

/// Vertices of each actuator's polygon (an outer bound within 0.5 % of the exact set's area
/// on the polygon tests' problems; 12 gave 19 %).
pub const VERTICES: usize = 16;

/// A contradiction is a fault faster than the drift or a stated bound too small (a model
/// error larger than the calibration stretch showed: measured on ArduCopter SITL's hover
/// around a motor fault, whose thrust curve is not the model's straight line). Each one
/// widens that actuator's bounds by this factor, so the guarantee is kept where the model is
/// worse than stated, at the price of width.
const CONTRADICTION_GROWTH: f64 = 1.5;

/// The lags (in samples) over which changes of the outputs are compared; 0 is the level.
pub const LAGS: [usize; 7] = [0, 1, 2, 4, 8, 16, 32];
const HISTORY: usize = 33;

/// The stated bounds the guarantee rests on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AhcSetParams {
    /// Per lag of [`LAGS`], per measured row `[p, q, r, a_z]`: the bound of the healthy
    /// model's unexplained part `e_k` (lag 0) and of its change `e_k - e_{k-m}` over `m`
    /// samples.
    pub residual_bound: [[f64; 4]; LAGS.len()],
    /// Largest change of each gamma and each delta in one step.
    pub drift_gamma: f64,
    pub drift_delta: f64,
    /// The model's effectiveness is known to within this fraction: an output `ε |u - u_ref|`
    /// away from the calibration's mean command `u_ref` is unexplained by the model's error,
    /// not by the actuator (a gain is bounded relative to the calibrated model, to `±ε`).
    pub model_error: f64,
    /// Each actuator's mean command over the calibration stretch.
    pub command_ref: [f64; MAX_ACTUATORS],
}

/// One past sample of every actuator: its output bound's centre `z` and its command.
#[derive(Debug, Clone, Copy, Default)]
struct Past {
    z: [f64; MAX_ACTUATORS],
    u: [f64; MAX_ACTUATORS],
}

/// Set-membership AHC estimator of a vehicle with `N = 3 + 2l` model states and `M` measured
/// rows (and, with `M` = 3, perhaps a static a_z row: [`AhcSet::with_vertical`]).
#[derive(Debug, Clone)]
pub struct AhcSet<const N: usize, const M: usize> {
    pub model: RateModel<N, M>,
    pub params: AhcSetParams,
    l: usize,
    polygons: [Polygon<VERTICES>; MAX_ACTUATORS],
    /// The a priori box per actuator: `[γ, δ]` low and high.
    prior_lo: [[f64; 2]; MAX_ACTUATORS],
    prior_hi: [[f64; 2]; MAX_ACTUATORS],
    /// `B`: rows × actuators; the rows in use (`M`, or 4 with a vertical row).
    effect: [[f64; MAX_ACTUATORS]; 4],
    rows: usize,
    /// A static a_z row's trim `c_z`, for a model that predicts the rates only.
    vertical_offset: Option<f64>,
    /// A left inverse of `B` (actuators × rows) when it has full column rank, and each
    /// actuator's bound per lag through it (`Σ_i |L_ji| σ_i(m)`).
    left_inverse: Option<[[f64; 4]; MAX_ACTUATORS]>,
    output_bound: [[f64; LAGS.len()]; MAX_ACTUATORS],
    /// The previous sample's measured rates (none after a hole: no bound then).
    previous: Option<[f64; 3]>,
    /// The last `HISTORY` samples (ring), and per actuator how many of them follow its last
    /// restart without a hole.
    history: [Past; HISTORY],
    newest: usize,
    valid: [usize; MAX_ACTUATORS],
    /// Samples that contradicted some actuator's set since the start, and per actuator on the
    /// last sample.
    pub contradictions: u64,
    pub contradicted: [bool; MAX_ACTUATORS],
    /// The last sample's bound of each output, `(lo, hi)`.
    pub output_bounds: [(f64, f64); MAX_ACTUATORS],
}

impl<const N: usize, const M: usize> AhcSet<N, M> {
    /// `prior_lo..prior_hi`: the a priori box of each actuator's `[γ, δ]`.
    pub fn new(
        model: RateModel<N, M>,
        params: AhcSetParams,
        prior_lo: &[[f64; 2]],
        prior_hi: &[[f64; 2]],
    ) -> Self {
        let l = model.actuators();
        let mut effect = [[0.0; MAX_ACTUATORS]; 4];
        let z0 = SVector::<f64, N>::zeros();
        let ones = [1.0; crate::model::MAX_INPUTS];
        let u = &ones[..model.input_dim()];
        let a = model.jacobian(&z0, u);
        let h = model.h_matrix(u);
        for j in 0..l {
            for i in 0..3 {
                effect[i][j] = a[(i, 3 + l + j)];
            }
            if M == 4 {
                effect[3][j] = h[(3, 3 + l + j)];
            }
        }
        let mut lo = [[0.0; 2]; MAX_ACTUATORS];
        let mut hi = [[0.0; 2]; MAX_ACTUATORS];
        lo[..l].copy_from_slice(&prior_lo[..l]);
        hi[..l].copy_from_slice(&prior_hi[..l]);
        let mut polygons = [Polygon::from_box([0.0; 2], [0.0; 2]); MAX_ACTUATORS];
        for j in 0..l {
            polygons[j] = Polygon::from_box(lo[j], hi[j]);
        }
        let mut set = Self {
            left_inverse: None,
            output_bound: [[f64::INFINITY; LAGS.len()]; MAX_ACTUATORS],
            rows: M,
            vertical_offset: None,
            model,
            params,
            l,
            polygons,
            prior_lo: lo,
            prior_hi: hi,
            effect,
            previous: None,
            history: [Past::default(); HISTORY],
            newest: 0,
            valid: [0; MAX_ACTUATORS],
            contradictions: 0,
            contradicted: [false; MAX_ACTUATORS],
            output_bounds: [(f64::NEG_INFINITY, f64::INFINITY); MAX_ACTUATORS],
        };
        set.bound_per_lag();
        set
    }

    /// A static a_z row for a model of the rates only (`M` = 3): `g_z,j` per unit of each
    /// output and the trim `c_z`. Taken only with a stated bound of its residual at every lag
    /// (measured on a calibration stretch); then `try_step_az` takes a_z.
    pub fn with_vertical(mut self, gain: &[f64], offset: f64) -> Self {
        let bounded = self
            .params
            .residual_bound
            .iter()
            .all(|b| b[3].is_finite() && b[3] > 0.0);
        let gain = &gain[..self.l.min(gain.len())];
        let acts = gain.iter().all(|g| g.is_finite()) && gain.iter().any(|g| g.abs() > 1e-12);
        if M != 3 || gain.len() < self.l || !acts || !bounded || !offset.is_finite() {
            return self;
        }
        self.effect[3][..self.l].copy_from_slice(&gain[..self.l]);
        self.rows = 4;
        self.vertical_offset = Some(offset);
        self.bound_per_lag();
        self
    }

    /// The rows a step takes (3 or 4).
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// The left inverse of `B` and each output's bound through it per lag.
    fn bound_per_lag(&mut self) {
        let (l, rows) = (self.l, self.rows);
        self.left_inverse = left_inverse(&self.effect, l, rows, &self.params.residual_bound[0]);
        self.output_bound = [[f64::INFINITY; LAGS.len()]; MAX_ACTUATORS];
        if let Some(li) = &self.left_inverse {
            for j in 0..l {
                for (k, bound) in self.params.residual_bound.iter().enumerate() {
                    self.output_bound[j][k] = (0..rows).map(|i| li[j][i].abs() * bound[i]).sum();
                }
            }
        }
    }

    pub fn actuators(&self) -> usize {
        self.l
    }

    /// Whether each sample bounds each output on its own (`B` of full column rank).
    pub fn separates_outputs(&self) -> bool {
        self.left_inverse.is_some()
    }

    /// Actuator `j`'s polygon.
    pub fn polygon(&self, j: usize) -> &Polygon<VERTICES> {
        &self.polygons[j]
    }

    /// Bounds of actuator `j`'s gamma (`coefficient` 0) or delta (1).
    pub fn bounds(&self, j: usize, coefficient: usize) -> (f64, f64) {
        let p = &self.polygons[j];
        if coefficient == 0 {
            p.range(1.0, 0.0)
        } else {
            p.range(0.0, 1.0)
        }
    }

    /// Actuator `j`'s recent command `ū` (the mean over the samples since its set last
    /// restarted, at most [`HISTORY`]; the calibration's mean before any) and the bounds of its
    /// effective output less the healthy one there, `(γ - 1) ū + δ`: the polygon's extent
    /// along the strips the latest samples cut. Near one operating point they are nearly
    /// parallel, so this is bounded long before `γ` and `δ` are apart (a steady hover leaves them
    /// free to trade along `γ u + δ`); and it is taken at the command now in force, since after
    /// a loss the controller moves the command and the old operating point's output can stay
    /// healthy-looking (a gain lost and a bias gained meet there). Guaranteed as the polygon is:
    /// with the truth's point inside it, the truth's value at any command is inside its range.
    pub fn output_range(&self, j: usize) -> (f64, f64, f64) {
        let n = self.valid[j].min(HISTORY);
        let u = if n == 0 {
            self.params.command_ref[j]
        } else {
            (0..n)
                .map(|k| self.history[(self.newest + HISTORY - k) % HISTORY].u[j])
                .sum::<f64>()
                / n as f64
        };
        let (lo, hi) = self.polygons[j].range(u, 1.0);
        (u, lo - u, hi - u)
    }

    /// Whether actuator `j`'s output range `(u, lo, hi)` ([`Self::output_range`]) is still
    /// (nearly) the a priori box's along that direction: no sample has bounded it by a tenth.
    pub fn output_unexcited(&self, j: usize, (u, lo, hi): (f64, f64, f64)) -> bool {
        let [box_lo, box_hi] = [self.prior_lo[j], self.prior_hi[j]];
        let box_extent = (box_hi[0] - box_lo[0]) * u.abs() + (box_hi[1] - box_lo[1]);
        hi - lo >= 0.9 * box_extent
    }

    /// The centroid of actuator `j`'s polygon: `[γ, δ]`.
    pub fn centre(&self, j: usize) -> [f64; 2] {
        self.polygons[j].centroid()
    }

    /// Whether actuator `j`'s gamma (0) or delta (1) bounds are still (nearly) the a priori
    /// box's: the data have not narrowed them by a tenth.
    pub fn unexcited(&self, j: usize, coefficient: usize) -> bool {
        let (lo, hi) = self.bounds(j, coefficient);
        hi - lo >= 0.9 * (self.prior_hi[j][coefficient] - self.prior_lo[j][coefficient])
    }

    /// One sample: the commands that acted over the step (as the model takes them) and the
    /// measurement.
    pub fn try_step(&mut self, u: &[f64], y: &SVector<f64, M>) -> Result<(), EstimatorError> {
        self.try_step_az(u, y, None)
    }

    /// [`Self::try_step`] with the a_z of a vertical row ([`Self::with_vertical`]); without it
    /// such a set bounds nothing this step (its coefficients drift).
    pub fn try_step_az(
        &mut self,
        u: &[f64],
        y: &SVector<f64, M>,
        az: Option<f64>,
    ) -> Result<(), EstimatorError> {
        check_commands(self.model.input_dim(), u)?;
        if !(y.iter().all(|v| v.is_finite()) && az.is_none_or(f64::is_finite)) {
            return Err(EstimatorError::NonFinite {
                what: "measurement",
            });
        }
        let l = self.l;
        let (dg, dd) = (self.params.drift_gamma, self.params.drift_delta);
        for p in &mut self.polygons[..l] {
            p.grow(dg, dd);
        }
        self.contradicted = [false; MAX_ACTUATORS];
        let rates = [y[0], y[1], y[2]];
        let vertical = match (self.vertical_offset, az) {
            (Some(c), Some(a)) => Some(a - c),
            _ => None,
        };
        let Some(previous) = self.previous.replace(rates) else {
            self.valid = [0; MAX_ACTUATORS];
            self.keep_in_prior();
            return Ok(());
        };
        // No a_z: nothing bounded this step (the recent command's window goes on: the row
        // takes no changes, which the window would otherwise have to restart for).
        if self.vertical_offset.is_some() && vertical.is_none() {
            self.keep_in_prior();
            return Ok(());
        }
        let mut z0 = SVector::<f64, N>::zeros();
        z0.fixed_rows_mut::<3>(0).copy_from_slice(&previous);
        let known = self.model.f(&z0, u);
        let mut r = [0.0; 4];
        for i in 0..3 {
            r[i] = y[i] - known[i];
        }
        if M == 4 {
            r[3] = y[3] - self.model.h_offset(u)[3];
        } else if let Some(v) = vertical {
            r[3] = v;
        }
        self.bound_outputs(&r, u);
        let mut now = Past::default();
        for j in 0..l {
            let (lo, hi) = self.output_bounds[j];
            now.z[j] = 0.5 * (lo + hi);
            now.u[j] = u[j];
        }
        let mut any = false;
        let eps = self.params.model_error;
        for j in 0..l {
            let (lo, hi) = self.output_bounds[j];
            if !(lo.is_finite() && hi.is_finite()) {
                continue;
            }
            let model = eps * (u[j] - self.params.command_ref[j]).abs();
            let (lo, hi) = (lo - model, hi + model);
            let mut trial = self.polygons[j];
            let level =
                |p: &mut Polygon<VERTICES>| p.clip([u[j], 1.0], hi) && p.clip([-u[j], -1.0], -lo);
            let mut consistent = level(&mut trial) && self.cut_changes(j, &now, &mut trial);
            if !consistent {
                // Faster than the drift: the actuator's set starts again from this sample.
                self.contradicted[j] = true;
                any = true;
                // Or the stated bounds were too small for this vehicle: they grow.
                for b in &mut self.output_bound[j] {
                    *b *= CONTRADICTION_GROWTH;
                }
                self.valid[j] = 0;
                trial = Polygon::from_box(self.prior_lo[j], self.prior_hi[j]);
                consistent = level(&mut trial);
                if !consistent {
                    trial = Polygon::from_box(self.prior_lo[j], self.prior_hi[j]);
                }
            }
            self.polygons[j] = trial;
            self.valid[j] = (self.valid[j] + 1).min(HISTORY);
        }
        self.newest = (self.newest + 1) % HISTORY;
        self.history[self.newest] = now;
        self.contradictions += any as u64;
        self.keep_in_prior();
        if !self.polygons[..l].iter().all(|p| p.is_finite()) {
            self.restart();
            return Err(EstimatorError::NonFinite { what: "set" });
        }
        Ok(())
    }

    /// Cut actuator `j`'s polygon by the gain bounds of this sample's changes since the stored
    /// ones (see the module note). False when a cut leaves nothing.
    fn cut_changes(&self, j: usize, now: &Past, p: &mut Polygon<VERTICES>) -> bool {
        // A static a_z row beside a dynamic model of the rates errs by the vertical response it
        // does not model, which moves with the commands: its changes are not bounded apart
        // from the command's changes, as these cuts need.
        if self.left_inverse.is_none() || self.vertical_offset.is_some() {
            return true;
        }
        let (dg, dd) = (self.params.drift_gamma, self.params.drift_delta);
        for (k, &m) in LAGS.iter().enumerate().skip(1) {
            if m > self.valid[j] {
                break;
            }
            let then = &self.history[(self.newest + HISTORY + 1 - m) % HISTORY];
            let du = now.u[j] - then.u[j];
            let dz = now.z[j] - then.z[j];
            // The coefficients then may differ from now's by the drift over the lag; the model's
            // error is its effectiveness' on the change.
            let bound = self.output_bound[j][k]
                + m as f64 * (dg * then.u[j].abs() + dd)
                + self.params.model_error * du.abs();
            if du.abs() * 4.0 < bound {
                continue;
            }
            if !(p.clip([du, 0.0], dz + bound) && p.clip([-du, 0.0], -(dz - bound))) {
                return false;
            }
        }
        true
    }

    /// Each output's bound from this sample's unexplained rows `r` (see the module note).
    fn bound_outputs(&mut self, r: &[f64; 4], u: &[f64]) {
        let l = self.l;
        let sigma = self.params.residual_bound[0];
        if let Some(li) = &self.left_inverse {
            for j in 0..l {
                let centre: f64 = (0..self.rows).map(|i| li[j][i] * r[i]).sum();
                let half = self.output_bound[j][0];
                self.output_bounds[j] = (centre - half, centre + half);
            }
            return;
        }
        // Interval arithmetic: each row bounds each output given the others' ranges; two passes
        // let a narrowed output narrow the rest.
        let mut range = [(0.0, 0.0); MAX_ACTUATORS];
        for j in 0..l {
            range[j] = self.polygons[j].range(u[j], 1.0);
        }
        for _ in 0..2 {
            for i in 0..self.rows {
                for j in 0..l {
                    let b = self.effect[i][j];
                    if b.abs() < 1e-12 {
                        continue;
                    }
                    let (mut rest_lo, mut rest_hi) = (0.0, 0.0);
                    for k in (0..l).filter(|&k| k != j) {
                        let e = self.effect[i][k];
                        let (a, c) = (e * range[k].0, e * range[k].1);
                        rest_lo += a.min(c);
                        rest_hi += a.max(c);
                    }
                    // b η_j = r - rest - e.
                    let x = (r[i] - rest_hi - sigma[i]) / b;
                    let z = (r[i] - rest_lo + sigma[i]) / b;
                    range[j] = (range[j].0.max(x.min(z)), range[j].1.min(x.max(z)));
                }
            }
        }
        self.output_bounds[..l].copy_from_slice(&range[..l]);
    }

    fn keep_in_prior(&mut self) {
        for j in 0..self.l {
            let (lo, hi) = (self.prior_lo[j], self.prior_hi[j]);
            let p = &mut self.polygons[j];
            for (a, b) in [
                ([1.0, 0.0], hi[0]),
                ([-1.0, 0.0], -lo[0]),
                ([0.0, 1.0], hi[1]),
                ([0.0, -1.0], -lo[1]),
            ] {
                p.clip(a, b);
            }
        }
    }

    /// A period whose sample was lost: the coefficients may drift; the next sample has no
    /// previous rates to predict from.
    pub fn coast(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        check_commands(self.model.input_dim(), u)?;
        self.drift_over(1.0);
        self.previous = None;
        Ok(())
    }

    /// After an outage of `periods` steps: the rates are measured again.
    pub fn reseat(&mut self, rates: &[f64; 3], periods: f64) {
        self.drift_over(super::outage_periods(periods));
        self.previous = Some(*rates);
        self.valid = [0; MAX_ACTUATORS];
    }

    fn drift_over(&mut self, periods: f64) {
        let (dg, dd) = (self.params.drift_gamma, self.params.drift_delta);
        for p in &mut self.polygons[..self.l] {
            p.grow(dg * periods, dd * periods);
        }
        self.keep_in_prior();
    }

    /// Actuator `j` may have changed by anything: its set is the a priori box again.
    pub fn forget(&mut self, j: usize) {
        if j < self.l {
            self.polygons[j] = Polygon::from_box(self.prior_lo[j], self.prior_hi[j]);
            self.valid[j] = 0;
        }
    }

    /// Every actuator back to the a priori box.
    pub fn restart(&mut self) {
        for j in 0..self.l {
            self.forget(j);
        }
        self.previous = None;
    }
}
/// `(Bᵀ W B)⁻¹ Bᵀ W`, `W = diag(σ⁻²)`, when `B` (the first `m` rows, `l` columns) has full
/// column rank (its weighted singular values within 1e-9 of each other's scale).
fn left_inverse(
    effect: &[[f64; MAX_ACTUATORS]; 4],
    l: usize,
    m: usize,
    sigma: &[f64; 4],
) -> Option<[[f64; 4]; MAX_ACTUATORS]> {
    if l > m || sigma[..m].iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        return None;
    }
    let b = DMatrix::from_fn(m, l, |i, j| effect[i][j] / sigma[i]);
    // nalgebra's SVD panics on NaN and never returns on an infinity.
    if !b.iter().all(|v| v.is_finite()) {
        return None;
    }
    let sv = b.clone().svd(false, false).singular_values;
    let (smax, smin) = (sv.max(), sv.min());
    if !(smax.is_finite() && smin > 1e-9 * smax) {
        return None;
    }
    let normal = (b.transpose() * &b).try_inverse()?;
    let weighted = normal * b.transpose();
    let mut out = [[0.0; 4]; MAX_ACTUATORS];
    for j in 0..l {
        for i in 0..m {
            out[j][i] = weighted[(j, i)] / sigma[i];
        }
    }
    Some(out)
}

#[cfg(test)]
#[path = "ahc_set_tests.rs"]
mod tests;
