//! MIT-ESMF: the ESMF with diag(Q) adapted by gradient descent on `J_k = (1 - δ_k) tr P_k`
//! (paper eq. 33). The gradient is the exact forward-mode derivative of one shape update —
//! through the nesting beta, the Minkowski beta, rho, W and δ — applied to a recursively
//! propagated sensitivity `dP_{k-1}/dq_i` (so the AHC entries adapt; with the one-step
//! sensitivity their gradient only ever pushes them down). What is held fixed is what the MIT
//! rule holds fixed: the innovation and the linearisation point (the state estimate).
//!
//! Only the AHC entries of q adapt. For a directly measured coordinate the loss has no
//! minimum: once its predicted extent exceeds the measurement's, `P̄_ii` is capped by the
//! measurement set while `1 - δ = eᵀW⁻¹e` falls as `1/q_i`, so `J` falls for ever as `q_i`
//! grows (measured on paper-fig9: rate entries ×540 in 40 s, gamma bounds ±20, no
//! detection). Holding them at q0 keeps the rate sets honest and leaves the AHC process set,
//! the part the data cannot give directly, to the adaptation.

use super::esmf::{EsmfOutcome, ShapeStep, remainder_dim, scale_block};
use super::mit::{AdaptationParams, StepSchedule, log_step};
use super::{Esmf, EsmfParams, EstimatorError};
use crate::model::{BilinearTerm, Model};
use nalgebra::{SMatrix, SVector};

/// `dP_k/dq_i` for every i, and the one-step derivative rules.
#[derive(Debug, Clone)]
pub struct ShapeSensitivity<const N: usize> {
    pub dp: [SMatrix<f64, N, N>; N],
    /// Entries whose sensitivity is not needed (q_i held fixed): their gradient is 0 and
    /// their `dP/dq_i` stays zero, which saves most of the cost when several are fixed.
    pub skip: [bool; N],
}

impl<const N: usize> Default for ShapeSensitivity<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> ShapeSensitivity<N> {
    pub fn new() -> Self {
        Self {
            dp: [SMatrix::zeros(); N],
            skip: [false; N],
        }
    }

    pub fn clear(&mut self) {
        self.dp = [SMatrix::zeros(); N];
    }

    /// Gradient `dJ_k/dq_i` of this step for every i, and `dP_k/dq_i` stored for the next one.
    /// `p_prev` is the previous shape as used by the step (after any inflation), `q` the
    /// process-noise diagonal in force, `st` the step's intermediate quantities.
    #[allow(clippy::too_many_arguments)]
    pub fn gradient_and_propagate<const M: usize>(
        &mut self,
        st: &ShapeStep<N, M>,
        p_prev: &SMatrix<f64, N, N>,
        a: &SMatrix<f64, N, N>,
        terms: &[BilinearTerm],
        h: &SMatrix<f64, M, N>,
        r: &SMatrix<f64, M, M>,
        r_sqrt_lmax: f64,
        q: &SVector<f64, N>,
        forgetting: f64,
    ) -> SVector<f64, N> {
        let mut grad = SVector::<f64, N>::zeros();
        let pc = PredictionConstants::new(st, q, a);
        let (rho, delta) = (st.rho, st.consistency);
        let (lam_sqrt, w) = (st.top_lambda.max(0.0).sqrt(), st.w_inv_e);
        let krk = st.gain * r * st.gain.transpose();
        let tr_p = st.p_bar.trace() * delta;
        // Products every i reuses: H Π, H Π Hᵀ, H AP_{k-1}Aᵀ.
        let (h_pi, h_pi_h) = (st.h_pi, st.h_pi_h);
        let sh = super::linalg::SparseRows::new(h);
        let h_apa = sh.right_t(&st.apa).transpose(); // symmetric
        let k_t = st.gain.transpose();
        let skip = self.skip;
        for i in (0..N).filter(|&i| !skip[i]) {
            let (c_a, c_apa, d_diag) =
                self.prediction_derivative(i, &pc, st, p_prev, a, terms, q, forgetting);
            let a_dp_a = &mut self.dp[i];
            let mut h_dpi = sh.right_t(a_dp_a).transpose() * c_a + h_apa * c_apa;
            for j in 0..N {
                for m in 0..M {
                    h_dpi[(m, j)] += h[(m, j)] * d_diag[j];
                }
            }
            let h_dpi_h = sh.right_t(&h_dpi);
            // rho through the top eigenvalue of H Π Hᵀ (simple eigenvalue assumed).
            let dlam = st.top_vec.dot(&(h_dpi_h * st.top_vec));
            let drho = if lam_sqrt > 0.0 {
                -r_sqrt_lmax * (dlam / (2.0 * lam_sqrt)) / (r_sqrt_lmax + lam_sqrt).powi(2)
            } else {
                0.0
            };
            // dΠ' = dΠ/(1-ρ) + Π dρ/(1-ρ)², and its products with H from the ones above.
            let (c_pi, c_rho) = (1.0 / (1.0 - rho), drho / (1.0 - rho).powi(2));
            let h_dpip = h_dpi * c_pi + h_pi * c_rho;
            let h_dpip_h = h_dpi_h * c_pi + h_pi_h * c_rho;
            let dw = h_dpip_h - r * (drho / (rho * rho));
            let ddelta = w.dot(&(dw * w));
            // dP̄ = G dΠ' Gᵀ - K R Kᵀ dρ/ρ², G = I - K H, expanded as
            // dΠ' - K(H dΠ') - (K(H dΠ'))ᵀ + K(H dΠ' Hᵀ)Kᵀ - K R Kᵀ dρ/ρ²; then
            // dP = dδ P̄ + δ dP̄, assembled in one pass over the upper triangle and mirrored
            // (exactly symmetric).
            // -K X - (K X)ᵀ + K C Kᵀ (X = H dΠ', C = H dΠ' Hᵀ) entry by entry on the upper
            // triangle: -K_r·(X - C Kᵀ)_c - K_c·X_r, two length-M dot products.
            let z = h_dpip - h_dpip_h * k_t;
            let c_krk = drho / (rho * rho);
            let (ca, capa) = (c_a * c_pi, c_apa * c_pi);
            // Column by column over the upper triangle (contiguous slices), then mirrored.
            let (apa, pi) = (st.apa.as_slice(), st.pi.as_slice());
            let (krk, p_bar) = (krk.as_slice(), st.p_bar.as_slice());
            let mut trace = 0.0;
            for (c, col) in a_dp_a.as_mut_slice().chunks_exact_mut(N).enumerate() {
                let (k_c, z_c) = (k_t.column(c), z.column(c));
                for (rr, x) in col[..=c].iter_mut().enumerate() {
                    let idx = c * N + rr;
                    let mut dpi_prime = ca * *x + capa * apa[idx] + c_rho * pi[idx];
                    if rr == c {
                        dpi_prime += c_pi * d_diag[c];
                    }
                    let gain_terms = k_t.column(rr).dot(&z_c) + k_c.dot(&h_dpip.column(rr));
                    let dp_bar = dpi_prime - gain_terms - c_krk * krk[idx];
                    *x = ddelta * p_bar[idx] + delta * dp_bar;
                }
                trace += col[c];
            }
            super::linalg::mirror_upper(a_dp_a);
            grad[i] = -ddelta * tr_p + (1.0 - delta) * trace;
        }
        grad
    }
}

/// The scalars of one prediction that every `dΠ/dq_i` reuses.
struct PredictionConstants {
    d_r: f64,
    tr_qbar: f64,
    /// `√tr Q̄`, `√tr Q`, `√tr Q̂`, `√tr APAᵀ`.
    s1: f64,
    s2: f64,
    s_hat: f64,
    t: f64,
    walk_from: usize,
}

impl PredictionConstants {
    fn new<const N: usize, const M: usize>(
        st: &ShapeStep<N, M>,
        q: &SVector<f64, N>,
        a: &SMatrix<f64, N, N>,
    ) -> Self {
        let tr_qbar = st.q_bar.sum();
        Self {
            d_r: remainder_dim(&st.half_widths),
            tr_qbar,
            s1: tr_qbar.sqrt(),
            s2: q.sum().sqrt(),
            s_hat: st.q_hat.sum().sqrt(),
            t: st.apa.trace().max(0.0).sqrt(),
            walk_from: super::linalg::identity_tail_start(a),
        }
    }
}

impl<const N: usize> ShapeSensitivity<N> {
    /// The derivative of the prediction `Π` w.r.t. `q_i`, as
    /// `dΠ = c_a·A dP_{k-1} Aᵀ + c_apa·APAᵀ + diag(d_diag)`: returns `(c_a, c_apa, d_diag)`
    /// and leaves `A dP_{k-1} Aᵀ` in `self.dp[i]`.
    #[allow(clippy::too_many_arguments)]
    fn prediction_derivative<const M: usize>(
        &mut self,
        i: usize,
        pc: &PredictionConstants,
        st: &ShapeStep<N, M>,
        p_prev: &SMatrix<f64, N, N>,
        a: &SMatrix<f64, N, N>,
        terms: &[BilinearTerm],
        q: &SVector<f64, N>,
        forgetting: f64,
    ) -> (f64, f64, SVector<f64, N>) {
        let beta = st.mink_beta;
        let dp_prev = &self.dp[i];
        // Linearisation-error set: Q̄_rr = d_r b_r², b_r = Σ |c|/2 √(P_jj P_kk).
        let mut db = SVector::<f64, N>::zeros();
        for term in terms {
            let prod = p_prev[(term.j, term.j)] * p_prev[(term.k, term.k)];
            if prod > 0.0 {
                db[term.row] += 0.25
                    * forgetting
                    * term.coeff.abs()
                    * (dp_prev[(term.j, term.j)] * p_prev[(term.k, term.k)]
                        + p_prev[(term.j, term.j)] * dp_prev[(term.k, term.k)])
                    / prod.sqrt();
            }
        }
        // d(A P Aᵀ) = λ A dP_{k-1} Aᵀ (λ: forgetting), computed over dP_{k-1} (read only
        // above), which the caller then overwrites with dP_k. The matrix is never formed
        // scaled: every use carries λ in its coefficient.
        let a_dp_a = &mut self.dp[i];
        super::linalg::sandwich_walk_in_place(a, a_dp_a, pc.walk_from);
        let dqbar = st.half_widths.component_mul(&db) * (2.0 * pc.d_r);
        let mut dq = SVector::<f64, N>::zeros();
        dq[i] = 1.0;
        let dq_hat = if pc.tr_qbar > 0.0 {
            let (s1, s2) = (pc.s1, pc.s2);
            let nb = st.nest_beta;
            let ds1 = dqbar.sum() / (2.0 * s1);
            let ds2 = 1.0 / (2.0 * s2);
            let dnb = (s1 * ds2 - s2 * ds1) / (s1 + s2).powi(2);
            dqbar / (1.0 - nb) + st.q_bar * (dnb / (1.0 - nb).powi(2)) + dq / nb
                - q * (dnb / (nb * nb))
        } else {
            dq
        };
        let (s_hat, t) = (pc.s_hat, pc.t);
        let ds_hat = dq_hat.sum() / (2.0 * s_hat);
        let dt = if t > 0.0 {
            forgetting * a_dp_a.trace() / (2.0 * t)
        } else {
            0.0
        };
        let dbeta = (t * ds_hat - s_hat * dt) / (s_hat + t).powi(2);
        let c_a = forgetting / (1.0 - beta);
        let c_apa = dbeta / (1.0 - beta).powi(2);
        let d_diag = dq_hat / beta - st.q_hat * (dbeta / (beta * beta));
        (c_a, c_apa, d_diag)
    }

    /// `dP/dq_i` carried through a prediction without an update (a coast over a lost sample,
    /// whose set is `Π`): the exact derivative of the Minkowski sum, betas included (before the
    /// a priori box cut, which no sensitivity differentiates, after a step either). `st` holds
    /// the prediction's quantities (`predict_shape`), `p_prev` the shape it started from.
    pub fn propagate_prediction<const M: usize>(
        &mut self,
        st: &ShapeStep<N, M>,
        p_prev: &SMatrix<f64, N, N>,
        a: &SMatrix<f64, N, N>,
        terms: &[BilinearTerm],
        q: &SVector<f64, N>,
        forgetting: f64,
    ) {
        let pc = PredictionConstants::new(st, q, a);
        let skip = self.skip;
        for i in (0..N).filter(|&i| !skip[i]) {
            let (c_a, c_apa, d_diag) =
                self.prediction_derivative(i, &pc, st, p_prev, a, terms, q, forgetting);
            let dp = &mut self.dp[i];
            *dp *= c_a;
            *dp += st.apa * c_apa;
            for j in 0..N {
                dp[(j, j)] += d_diag[j];
            }
        }
    }
}

#[derive(Debug, Clone)]
pub struct MitEsmf<Mo, const N: usize, const M: usize> {
    pub esmf: Esmf<Mo, N, M>,
    pub adapt: AdaptationParams,
    pub sensitivity: ShapeSensitivity<N>,
    pub schedule: StepSchedule,
    pub q0: SVector<f64, N>,
    /// Entries the adaptation leaves at q0 (see `MitUkf::fixed`); the measured coordinates
    /// by default (see the module note).
    pub fixed: [bool; N],
    pub gradient: SVector<f64, N>,
    steps: u64,
}

impl<Mo: Model<N, M>, const N: usize, const M: usize> MitEsmf<Mo, N, M> {
    pub fn new(
        model: Mo,
        params: EsmfParams,
        adapt: AdaptationParams,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        q0: SVector<f64, N>,
        r: SMatrix<f64, M, M>,
    ) -> Self {
        let ahc = model.ahc_start();
        Self {
            fixed: std::array::from_fn(|i| i < ahc),
            esmf: Esmf::new(model, params, x0, p0, q0, r),
            adapt,
            sensitivity: ShapeSensitivity::new(),
            schedule: StepSchedule::new(),
            q0,
            gradient: SVector::zeros(),
            steps: 0,
        }
    }

    pub fn try_step(
        &mut self,
        u: &[f64],
        y: &SVector<f64, M>,
    ) -> Result<EsmfOutcome, EstimatorError> {
        let out = self.esmf.try_step(u, y)?;
        self.steps += 1;
        // The schedule's change detector: 1 - δ is the set analogue of a normalised innovation.
        // A jumped step was (nearly) contradicted before the jump made it consistent: count it
        // as change evidence like an inconsistent one.
        let nis_like = if out.consistent && !out.jumped {
            (1.0 - self.esmf.last.consistency) * M as f64
        } else {
            4.0 * M as f64
        };
        self.schedule.observe(nis_like, M, &self.adapt);
        if out.inflations > 0 {
            let s = self
                .esmf
                .params
                .inflation
                .sqrt()
                .powi(out.inflations as i32);
            let ahc = self.esmf.model.ahc_start();
            for dp in self.sensitivity.dp.iter_mut() {
                scale_block(dp, ahc, s);
            }
        }
        // A jump or a reset replaces the set by one the old sensitivities do not describe.
        if !out.consistent || out.reset || out.jumped {
            self.sensitivity.clear();
            self.gradient = SVector::zeros();
            return Ok(out);
        }
        let e = &self.esmf;
        self.sensitivity.skip = self.fixed;
        self.gradient = self.sensitivity.gradient_and_propagate(
            &e.last,
            &e.last_p_prev,
            &e.last_a,
            e.model.bilinear_terms(),
            &e.h,
            &e.r,
            e.r_sqrt_lmax(),
            &e.process_noise,
            self.adapt.forgetting,
        );
        if self.steps as usize > self.adapt.window {
            let eta = self.schedule.eta(&self.adapt);
            let loss = (1.0 - self.esmf.last.consistency) * self.esmf.p.trace();
            for i in (0..N).filter(|&i| !self.fixed[i]) {
                let q = self.esmf.process_noise[i];
                self.esmf.process_noise[i] =
                    log_step(q, self.gradient[i], eta, loss, self.q0[i], &self.adapt);
            }
        }
        Ok(out)
    }
}

impl<Mo: Model<N, M>, const N: usize, const M: usize> MitEsmf<Mo, N, M> {
    /// A period without a measurement (lost on the link): the ESMF's prediction only. With no
    /// measurement there is no loss to descend, so q stays; the sensitivities are carried
    /// through the prediction, so the next step's gradient is about the set it starts from.
    pub fn coast(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        self.esmf.coast(u)?;
        let e = &self.esmf;
        self.sensitivity.skip = self.fixed;
        self.sensitivity.propagate_prediction(
            &e.last,
            &e.last_p_prev,
            &e.last_a,
            e.model.bilinear_terms(),
            &e.process_noise,
            self.adapt.forgetting,
        );
        Ok(())
    }
}

impl<Mo: Model<N, M>, const N: usize, const M: usize> MitEsmf<Mo, N, M> {
    /// [`Esmf::reseat`]; the new set is not one the sensitivities describe, so they start over
    /// (as after a jump or a reset).
    pub fn reseat(&mut self, rates: &[f64], half_sq: &[f64], periods: f64) {
        self.esmf.reseat(rates, half_sq, periods);
        self.sensitivity.clear();
        self.gradient = SVector::zeros();
    }
}

impl_estimator!(MitEsmf<>, "mit-esmf", [esmf], projection, contradicted: [esmf]);
