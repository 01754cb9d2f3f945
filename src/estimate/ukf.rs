//! Unscented Kalman filter with scaled sigma points (Van der Merwe; filterpy's
//! `MerweScaledSigmaPoints` ordering, so the golden test can compare step by step).

use super::linalg::{
    SparseRows, cholesky_jitter, identity_tail_start, sandwich_gain, sandwich_walk, symmetrize,
};
use super::{EstimatorError, check_commands, check_inputs};
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

/// Sigma-point scaling. Default alpha = 1, beta = 2, kappa = 0: lambda = 0, all weights ≥ 0
/// (a tiny alpha makes W0c ≈ -1e6 and costs orders of magnitude in accuracy).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UkfParams {
    pub alpha: f64,
    pub ut_beta: f64,
    pub kappa: f64,
    /// Floor on the AHC variances, so an unexcited filter does not go deaf to the next fault.
    pub ahc_variance_floor: f64,
    /// Robust update: an innovation whose NIS exceeds this moves the state only as far as one
    /// at this NIS would (Huber-style). A transient the model cannot explain (a fault's first
    /// steps, a gust) then moves the state a few sigma per step, in the direction the data
    /// keep pointing, instead of tens of sigma along whatever direction the prior makes
    /// cheapest. Infinite (off) for the paper's filters.
    pub innovation_clip_nis: f64,
}

impl Default for UkfParams {
    fn default() -> Self {
        Self {
            alpha: 1.0,
            ut_beta: 2.0,
            kappa: 0.0,
            ahc_variance_floor: 1e-10,
            innovation_clip_nis: f64::INFINITY,
        }
    }
}

/// An entry [`Ukf::reseat_entries`] takes: a coordinate of the state, a finite value and a
/// finite positive variance.
pub(crate) fn reseatable<const N: usize>(&(i, value, var): &(usize, f64, f64)) -> bool {
    i < N && value.is_finite() && var.is_finite() && var > 0.0
}

/// UKF over a model with `N` states, `M` measurements and `S = 2N + 1` sigma points.
#[derive(Debug, Clone)]
pub struct Ukf<Mo, const N: usize, const M: usize, const S: usize> {
    pub model: Mo,
    pub params: UkfParams,
    /// State estimate.
    pub x: SVector<f64, N>,
    /// State covariance.
    pub p: SMatrix<f64, N, N>,
    /// Diagonal of the process noise covariance.
    pub process_noise: SVector<f64, N>,
    /// Measurement noise covariance.
    pub r: SMatrix<f64, M, M>,
    wm: [f64; S],
    wc: [f64; S],
    sqrt_c: f64,
    sigmas: [SVector<f64, N>; S],
    sigmas_f: [SVector<f64, N>; S],
    /// Predicted state and covariance of the last step.
    pub x_prior: SVector<f64, N>,
    pub p_prior: SMatrix<f64, N, N>,
    /// Innovation covariance, gain, innovation and its normalised square of the last step.
    pub s: SMatrix<f64, M, M>,
    pub gain: SMatrix<f64, N, M>,
    pub innovation: SVector<f64, M>,
    pub nis: f64,
    /// Measurement matrix and offset of the current step (they depend on `u` when `a_z` is
    /// measured).
    pub h: SMatrix<f64, M, N>,
    pub h_offset: SVector<f64, M>,
    /// Entries the updates leave as they are (consider states, Schmidt's filter): their gain
    /// rows are zero, so their estimates and variances stay while their covariances with the
    /// rest still shape the others' update (the Joseph form holds for any gain).
    pub consider: [bool; N],
}

impl<Mo: Model<N, M>, const N: usize, const M: usize, const S: usize> Ukf<Mo, N, M, S> {
    pub fn new(
        model: Mo,
        params: UkfParams,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        process_noise: SVector<f64, N>,
        r: SMatrix<f64, M, M>,
    ) -> Self {
        assert!(S == 2 * N + 1, "Ukf: S must be 2N+1 (got N={N}, S={S})");
        // The structured products (`sandwich_walk`, `sandwich_gain`) assume a symmetric shape.
        let mut p0 = p0;
        symmetrize(&mut p0);
        let u0 = [0.0; crate::model::MAX_INPUTS];
        let u0 = &u0[..model.input_dim().min(crate::model::MAX_INPUTS)];
        let (h, h_offset) = (model.h_matrix(u0), model.h_offset(u0));
        let n = N as f64;
        let lambda = params.alpha * params.alpha * (n + params.kappa) - n;
        let c = n + lambda;
        let mut wm = [0.5 / c; S];
        let mut wc = [0.5 / c; S];
        wm[0] = lambda / c;
        wc[0] = lambda / c + (1.0 - params.alpha * params.alpha + params.ut_beta);
        Self {
            model,
            params,
            x: x0,
            p: p0,
            process_noise,
            r,
            wm,
            wc,
            sqrt_c: c.sqrt(),
            sigmas: [SVector::zeros(); S],
            sigmas_f: [SVector::zeros(); S],
            x_prior: x0,
            p_prior: p0,
            s: SMatrix::zeros(),
            gain: SMatrix::zeros(),
            innovation: SVector::zeros(),
            nis: 0.0,
            h,
            h_offset,
            consider: [false; N],
        }
    }

    fn draw_sigmas(
        x: &SVector<f64, N>,
        p: &SMatrix<f64, N, N>,
        sqrt_c: f64,
        out: &mut [SVector<f64, N>; S],
        stage: &'static str,
    ) -> Result<(), EstimatorError> {
        let l = cholesky_jitter(p, stage)?.l();
        out[0] = *x;
        for i in 0..N {
            let col = l.column(i) * sqrt_c;
            out[i + 1] = x + col;
            out[N + i + 1] = x - col;
        }
        Ok(())
    }

    /// Time update, then redraw the sigma points from the prediction (so Q reaches S). For an
    /// affine model the unscented transform is exact and the closed form is used instead
    /// (`F P Fᵀ + Q`; the update then uses `P Hᵀ` and `H P Hᵀ + R`): the same numbers, which
    /// `affine_closed_form_matches_sigma_points` checks.
    pub fn predict(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        self.h = self.model.h_matrix(u);
        self.h_offset = self.model.h_offset(u);
        if self.model.is_affine() {
            let f = self.model.jacobian(&self.x, u);
            let x = self.model.f(&self.x, u);
            let mut p = sandwich_walk(&f, &self.p, identity_tail_start(&f));
            for i in 0..N {
                p[(i, i)] += self.process_noise[i];
            }
            symmetrize(&mut p);
            // What the sigma points would have refused: a non-finite state, and (through
            // their Cholesky factor) a covariance that is not positive definite or not finite.
            if !x.iter().all(|v| v.is_finite()) {
                return Err(EstimatorError::NonFinite { what: "UKF state" });
            }
            cholesky_jitter(&p, "predict")?;
            self.x_prior = x;
            self.p_prior = p;
            self.x = x;
            self.p = p;
            return Ok(());
        }
        Self::draw_sigmas(&self.x, &self.p, self.sqrt_c, &mut self.sigmas, "predict")?;
        let mut x = SVector::<f64, N>::zeros();
        for i in 0..S {
            self.sigmas_f[i] = self.model.f(&self.sigmas[i], u);
            x += self.sigmas_f[i] * self.wm[i];
        }
        let mut p = SMatrix::<f64, N, N>::from_diagonal(&self.process_noise);
        for i in 0..S {
            let d = self.sigmas_f[i] - x;
            p.ger(self.wc[i], &d, &d, 1.0); // in place: no N×N temporaries
        }
        symmetrize(&mut p);
        self.x_prior = x;
        self.p_prior = p;
        self.x = x;
        self.p = p;
        Self::draw_sigmas(&self.x, &self.p, self.sqrt_c, &mut self.sigmas, "redraw")
    }

    /// Predicted measurement, innovation covariance `S` and cross-covariance `Pxy`.
    fn predicted_measurement(
        &self,
        sh: &SparseRows<M, N>,
    ) -> (SVector<f64, M>, SMatrix<f64, M, M>, SMatrix<f64, N, M>) {
        if self.model.is_affine() {
            let pxy = sh.right_t(&self.p);
            return (
                sh.apply(&self.x) + self.h_offset,
                sh.left(&pxy) + self.r,
                pxy,
            );
        }
        let mut y_pred = SVector::<f64, M>::zeros();
        let mut ys = [SVector::<f64, M>::zeros(); S];
        for ((yi, sigma), wm) in ys.iter_mut().zip(&self.sigmas).zip(&self.wm) {
            *yi = sh.apply(sigma) + self.h_offset;
            y_pred += *yi * *wm;
        }
        let mut s = self.r;
        let mut pxy = SMatrix::<f64, N, M>::zeros();
        for ((yi, sigma), wc) in ys.iter().zip(&self.sigmas).zip(&self.wc) {
            let dy = yi - y_pred;
            let dx = sigma - self.x;
            s.ger(*wc, &dy, &dy, 1.0);
            pxy.ger(*wc, &dx, &dy, 1.0);
        }
        (y_pred, s, pxy)
    }

    /// Measurement update from the redrawn sigma points; Joseph form (h is linear).
    pub fn update(&mut self, y: &SVector<f64, M>) -> Result<(), EstimatorError> {
        let sh = SparseRows::new(&self.h);
        let (y_pred, mut s, pxy) = self.predicted_measurement(&sh);
        symmetrize(&mut s);
        let s_chol = cholesky_jitter(&s, "innovation covariance")?;
        // K = Pxy S⁻¹  <=>  Kᵀ = S⁻¹ Pxyᵀ (S symmetric).
        let mut gain = s_chol.solve(&pxy.transpose()).transpose();
        for i in (0..N).filter(|&i| self.consider[i]) {
            gain.row_mut(i).fill(0.0);
        }
        let e = y - y_pred;
        self.nis = e.dot(&s_chol.solve(&e));
        let scale = if self.nis > self.params.innovation_clip_nis {
            (self.params.innovation_clip_nis / self.nis).sqrt()
        } else {
            1.0
        };
        self.x += gain * e * scale;
        // Joseph form (I - KH) P (I - KH)ᵀ + K R Kᵀ.
        let mut p = sandwich_gain(&self.p, &gain, &sh) + gain * self.r * gain.transpose();
        symmetrize(&mut p);
        for i in self.model.ahc_start()..N {
            if p[(i, i)] < self.params.ahc_variance_floor {
                p[(i, i)] = self.params.ahc_variance_floor;
            }
        }
        self.p = p;
        self.s = s;
        self.gain = gain;
        self.innovation = e;
        Ok(())
    }

    /// One full step. On error the state is left as it was before the step.
    pub fn try_step(&mut self, u: &[f64], y: &SVector<f64, M>) -> Result<(), EstimatorError> {
        check_inputs(self.model.input_dim(), u, y)?;
        let (x0, p0, h0, o0) = (self.x, self.p, self.h, self.h_offset);
        let r = self.predict(u).and_then(|_| self.update(y));
        if r.is_err() {
            self.x = x0;
            self.p = p0;
            self.h = h0;
            self.h_offset = o0;
        }
        r
    }

    /// A period without a measurement (lost on the link): the time update only. The gain is
    /// zeroed, since no update followed this prediction (the MIT-UKF's sensitivity transition
    /// `F (I - K H)` reads it). On error the state is left as it was.
    pub fn coast(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        check_commands(self.model.input_dim(), u)?;
        let (x0, p0, h0, o0) = (self.x, self.p, self.h, self.h_offset);
        let r = self.predict(u);
        if r.is_err() {
            self.x = x0;
            self.p = p0;
            self.h = h0;
            self.h_offset = o0;
        } else {
            self.gain = SMatrix::zeros();
        }
        r
    }

    /// After an outage too long to coast over (the outputs over it unknown): the first `k`
    /// coordinates (the rates) are re-measured rather than predicted, `rates` with variance
    /// `var` and no correlation with the rest; the rest keep their estimate, its variance grown
    /// by `periods` steps of their random walk.
    pub fn reseat(&mut self, rates: &[f64], var: &[f64], periods: f64) {
        let periods = super::outage_periods(periods);
        let k = rates.len().min(var.len()).min(N);
        for i in 0..k {
            self.set_entry(i, rates[i], var[i]);
        }
        for i in k..N {
            self.p[(i, i)] += periods * self.process_noise[i];
        }
        self.gain = SMatrix::zeros();
    }

    /// Set coordinates from knowledge outside the measurements: each `(i, value, var)` gets
    /// that value and variance (others are skipped: see `reseatable`), its covariance with
    /// every other coordinate cleared (the rest
    /// of `P` is a principal block of a positive matrix, so `P` stays positive). The last
    /// step's gain is cleared, as after [`Self::reseat`].
    pub fn reseat_entries(&mut self, entries: &[(usize, f64, f64)]) {
        for &(i, value, var) in entries.iter().filter(|e| reseatable::<N>(e)) {
            self.set_entry(i, value, var);
        }
        self.gain = SMatrix::zeros();
    }

    /// Coordinate `i` at `value` with variance `var`, uncorrelated with the rest.
    fn set_entry(&mut self, i: usize, value: f64, var: f64) {
        self.x[i] = value;
        for j in 0..N {
            self.p[(i, j)] = 0.0;
            self.p[(j, i)] = 0.0;
        }
        self.p[(i, i)] = var;
    }

    /// ±3σ bounds of coordinate `i`.
    pub fn three_sigma(&self, i: usize) -> (f64, f64) {
        let s = 3.0 * self.p[(i, i)].max(0.0).sqrt();
        (self.x[i] - s, self.x[i] + s)
    }
}

impl_estimator!(Ukf<S>, "ukf", [], three_sigma);
