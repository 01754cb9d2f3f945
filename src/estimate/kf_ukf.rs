//! KF-UKF (paper eq. 23-27): a slave linear Kalman filter estimates q = diag(Q) from the
//! windowed innovation variances. With the gains frozen, vdiag(S_k) is affine in a constant q:
//! `vdiag(S_k) = H_P q + B_P`, `H_P[j,i] = (H M_i Hᵀ)_jj` from the recursive sensitivity
//! (the one-step `H_P = H∘H` leaves the AHC entries unobservable), and `B_P = vdiag(S_k) - H_P q_k`.
//! As in the MIT-UKF, the rate entries are fitted to the innovation spread and the AHC entries
//! to the innovation mean (two sequential slave updates).

use super::MitUkf;
use super::mit::{AdaptationParams, InnovationWindow, Sensitivity};
use super::{EstimatorError, Ukf, UkfParams, check_inputs};
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlaveKfParams {
    /// Initial std of each q_i as a fraction of q0_i.
    pub initial_rel_std: f64,
    /// Random-walk std of each q_i per step as a fraction of q0_i.
    pub walk_rel_std: f64,
}

impl Default for SlaveKfParams {
    fn default() -> Self {
        Self {
            initial_rel_std: 1.0,
            walk_rel_std: 0.05,
        }
    }
}

#[derive(Debug, Clone)]
pub struct KfUkf<Mo, const N: usize, const M: usize, const S: usize> {
    pub ukf: Ukf<Mo, N, M, S>,
    pub adapt: AdaptationParams,
    pub slave: SlaveKfParams,
    pub window: InnovationWindow<M>,
    pub sensitivity: Sensitivity<N>,
    pub q0: SVector<f64, N>,
    /// Covariance of the slave filter's estimate of q.
    pub p_q: SMatrix<f64, N, N>,
}

impl<Mo: Model<N, M>, const N: usize, const M: usize, const S: usize> KfUkf<Mo, N, M, S> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model: Mo,
        params: UkfParams,
        adapt: AdaptationParams,
        slave: SlaveKfParams,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        q0: SVector<f64, N>,
        r: SMatrix<f64, M, M>,
    ) -> Self {
        let p_q = SMatrix::from_diagonal(&q0.map(|q| (slave.initial_rel_std * q).powi(2)));
        Self {
            ukf: Ukf::new(model, params, x0, p0, q0, r),
            window: InnovationWindow::new(adapt.window),
            adapt,
            slave,
            sensitivity: Sensitivity::new(),
            q0,
            p_q,
        }
    }

    pub fn try_step(&mut self, u: &[f64], y: &SVector<f64, M>) -> Result<(), EstimatorError> {
        check_inputs(self.ukf.model.input_dim(), u, y)?;
        let a = MitUkf::sensitivity_transition(&self.ukf, u);
        self.ukf.try_step(u, y)?;
        self.window.push(&self.ukf.innovation);
        self.sensitivity.propagate(&a, self.adapt.forgetting);
        // Slave KF time update: random walk on q.
        for i in 0..N {
            self.p_q[(i, i)] += (self.slave.walk_rel_std * self.q0[i]).powi(2);
        }
        if !self.window.is_full() {
            return Ok(());
        }
        // The same split as the MIT-UKF (see there): the rate entries explain the spread of the
        // innovations about their windowed mean, the AHC entries the mean itself.
        let h = self.ukf.h;
        let ahc = self.ukf.model.ahc_start();
        let mut h_rates = SMatrix::<f64, M, N>::zeros();
        let mut h_ahc = SMatrix::<f64, M, N>::zeros();
        for i in 0..N {
            let hmh = h * self.sensitivity.m[i] * h.transpose();
            for j in 0..M {
                if i < ahc {
                    h_rates[(j, i)] = hmh[(j, j)];
                } else {
                    h_ahc[(j, i)] = hmh[(j, j)];
                }
            }
        }
        let q = self.ukf.process_noise;
        let s_ahc = h_ahc * q;
        let spread = self.window.centered_covariance();
        let mu = self.window.mean();
        let n = self.window.len() as f64;
        let mut resid_rates = SVector::<f64, M>::zeros();
        let mut resid_ahc = SVector::<f64, M>::zeros();
        let mut r_rates = SMatrix::<f64, M, M>::zeros();
        let mut r_ahc = SMatrix::<f64, M, M>::zeros();
        for j in 0..M {
            let s_jj = self.ukf.s[(j, j)];
            // Model: vdiag(spread) = H_rates q + (vdiag(S) - S_ahc - H_rates q); vdiag(μμᵀ) = H_ahc q.
            resid_rates[j] = spread[(j, j)] - (s_jj - s_ahc[j]);
            resid_ahc[j] = mu[j] * mu[j] - s_ahc[j];
            // Variance of a sample variance of N Gaussian samples, 2σ⁴/N, and of a squared mean
            // of N samples, 2(σ²/N)².
            r_rates[(j, j)] = 2.0 * s_jj * s_jj / n;
            r_ahc[(j, j)] = 2.0 * (s_jj / n).powi(2);
        }
        self.slave_update(&h_rates, &resid_rates, &r_rates);
        self.slave_update(&h_ahc, &resid_ahc, &r_ahc);
        Ok(())
    }
}

impl_estimator!(KfUkf<S>, "kf-ukf", [ukf], three_sigma);

impl<Mo: Model<N, M>, const N: usize, const M: usize, const S: usize> KfUkf<Mo, N, M, S> {
    /// One linear KF measurement update of the slave filter on q, then projection.
    fn slave_update(
        &mut self,
        h_p: &SMatrix<f64, M, N>,
        resid: &SVector<f64, M>,
        r_v: &SMatrix<f64, M, M>,
    ) {
        let s_q = h_p * self.p_q * h_p.transpose() + r_v;
        let Some(chol) = s_q.cholesky() else {
            return; // slave update skipped; the UKF step itself succeeded
        };
        let gain = chol.solve(&(h_p * self.p_q)).transpose();
        let i_kh = SMatrix::<f64, N, N>::identity() - gain * h_p;
        self.p_q = i_kh * self.p_q * i_kh.transpose() + gain * r_v * gain.transpose();
        let dq = gain * resid;
        for i in 0..N {
            let q = self.ukf.process_noise[i] + dq[i];
            self.ukf.process_noise[i] = q.clamp(
                self.q0[i] * self.adapt.q_min_factor,
                self.q0[i] * self.adapt.q_max_factor,
            );
        }
    }
}
