//! Extended set-membership filter (paper eq. 28-32; Scholte & Campbell 2003).
//!
//! The state is known to lie in the ellipsoid `E(x, P) = {z : (z-x)ᵀ P⁻¹ (z-x) ≤ 1}` — `P` is a
//! *shape*, not a covariance. Prediction is a Minkowski sum (trace-optimal `mink_beta`) of the
//! linearised set, the process-noise set and the linearisation-error set; the update intersects
//! with the measurement set (paper's `rho`) and rescales by the consistency `δ_k`.
//! `δ_k ≤ 0` means the data contradict the sets: that is fault evidence, handled by the policy
//! in [`EsmfParams`] (`docs/estimators.md`).

use super::linalg::{
    SparseRows, cholesky_jitter, identity_tail_start, mirror_upper, sandwich_walk_in_place,
    sym_top_eigen, symmetrize,
};
use super::{EstimatorError, check_commands, check_inputs};
use crate::model::{BilinearTerm, Model};
use nalgebra::{SMatrix, SVector};

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EsmfParams {
    /// `δ_k` at or below this is "inconsistent".
    pub consistency_min: f64,
    /// On inconsistency, the previous set's AHC block is scaled by this and the step retried:
    /// the last measurement cannot be explained, so the AHC bounds must grow.
    pub inflation: f64,
    pub max_inflations: u32,
    /// Consecutive inconsistent steps (after all inflations) before the AHC block is reset to P0.
    pub reset_after: u32,
    /// When the consistency `δ_k` is at or below this, add the *jump set* — the prior set's
    /// AHC block — to the previous set (Minkowski sum) and redo the step, before any
    /// inflation: the data say the AHCs have probably left the set, and a fault moves them by
    /// at most what the prior allows. Without it an abrupt fault can leave the truth outside
    /// for several steps: the set shrinks (δ small) onto the wrong region without ever being
    /// contradicted. Default 0.9, from healthy Monte Carlo: over 600 000 healthy steps of the
    /// paper simulations (uniform and Gaussian noise, 20 seeds) δ never fell below 0.98; the
    /// first steps after a gamma fault give 0.08–0.6. `-inf` turns the jump off.
    pub jump_below: f64,
}

impl Default for EsmfParams {
    fn default() -> Self {
        Self {
            consistency_min: 1e-6,
            inflation: 4.0,
            max_inflations: 10,
            reset_after: 25,
            jump_below: 0.9,
        }
    }
}

/// Everything one ESMF shape update computes; kept so that the MIT-ESMF can differentiate it.
#[derive(Debug, Clone, Copy)]
pub struct ShapeStep<const N: usize, const M: usize> {
    pub apa: SMatrix<f64, N, N>,
    /// Linearisation-error set (diagonal) and its half-widths.
    pub q_bar: SVector<f64, N>,
    pub half_widths: SVector<f64, N>,
    /// Process set nested with the linearisation-error set (diagonal), and the nesting beta.
    pub q_hat: SVector<f64, N>,
    pub nest_beta: f64,
    pub mink_beta: f64,
    /// `Π = P_{k,k-1}`, and its products `H Π`, `H Π Hᵀ` (reused by the MIT-ESMF).
    pub pi: SMatrix<f64, N, N>,
    pub h_pi: SMatrix<f64, M, N>,
    pub h_pi_h: SMatrix<f64, M, M>,
    pub rho: f64,
    pub top_lambda: f64,
    pub top_vec: SVector<f64, M>,
    pub pi_prime: SMatrix<f64, N, N>,
    pub w: SMatrix<f64, M, M>,
    pub w_inv_e: SVector<f64, M>,
    pub gain: SMatrix<f64, N, M>,
    pub p_bar: SMatrix<f64, N, N>,
    pub consistency: f64,
}

impl<const N: usize, const M: usize> ShapeStep<N, M> {
    pub fn zeros() -> Self {
        Self {
            apa: SMatrix::zeros(),
            q_bar: SVector::zeros(),
            half_widths: SVector::zeros(),
            q_hat: SVector::zeros(),
            nest_beta: 1.0,
            mink_beta: 0.5,
            pi: SMatrix::zeros(),
            h_pi: SMatrix::zeros(),
            h_pi_h: SMatrix::zeros(),
            rho: 0.5,
            top_lambda: 0.0,
            top_vec: SVector::zeros(),
            pi_prime: SMatrix::zeros(),
            w: SMatrix::zeros(),
            w_inv_e: SVector::zeros(),
            gain: SMatrix::zeros(),
            p_bar: SMatrix::zeros(),
            consistency: 1.0,
        }
    }

    /// The updated shape `δ P̄`.
    pub fn p(&self) -> SMatrix<f64, N, N> {
        self.p_bar * self.consistency
    }
}

/// Range of the bilinear remainder `Σ c z_j z_k` over `dz ∈ E(0, P)`: for one term,
/// `dz_j dz_k ∈ [(P_jk - √(P_jj P_kk))/2, (P_jk + √(P_jj P_kk))/2]` (exact support; note the ½,
/// which a plain product bound drops). Returns the box centre (a shift of the predicted centre)
/// and half-widths per state row.
pub fn remainder_box<const N: usize>(
    terms: &[BilinearTerm],
    p: &SMatrix<f64, N, N>,
) -> (SVector<f64, N>, SVector<f64, N>) {
    let mut center = SVector::<f64, N>::zeros();
    let mut half = SVector::<f64, N>::zeros();
    for t in terms {
        let s = (p[(t.j, t.j)] * p[(t.k, t.k)]).max(0.0).sqrt();
        center[t.row] += 0.5 * t.coeff * p[(t.j, t.k)];
        half[t.row] += 0.5 * t.coeff.abs() * s;
    }
    (center, half)
}

/// Number of rows the remainder box spans (the enclosing ellipsoid of a d-box is d·diag(b²)).
pub fn remainder_dim<const N: usize>(half: &SVector<f64, N>) -> f64 {
    half.iter().filter(|b| **b > 0.0).count() as f64
}

/// One ESMF shape update (pure), written into `st` (every field is overwritten, so the
/// step's kilobytes of intermediate matrices are not copied around on the hot path): previous
/// shape `p_prev`, linearisation `a`, process set diag `q`, remainder half-widths,
/// measurement matrix `h` and set `r`, innovation `e`.
#[allow(clippy::too_many_arguments)]
pub fn shape_step<const N: usize, const M: usize>(
    st: &mut ShapeStep<N, M>,
    p_prev: &SMatrix<f64, N, N>,
    a: &SMatrix<f64, N, N>,
    q: &SVector<f64, N>,
    half_widths: &SVector<f64, N>,
    h: &SMatrix<f64, M, N>,
    r: &SMatrix<f64, M, M>,
    r_sqrt_lmax: f64,
    e: &SVector<f64, M>,
) -> Result<(), EstimatorError> {
    predict_shape(st, p_prev, a, q, half_widths);
    update_shape(st, h, r, r_sqrt_lmax, e)
}

/// The prediction half of [`shape_step`]: `Π`, the Minkowski sum of the linearised set, the
/// process set and the linearisation-error set (fills `apa` to `pi`).
pub fn predict_shape<const N: usize, const M: usize>(
    st: &mut ShapeStep<N, M>,
    p_prev: &SMatrix<f64, N, N>,
    a: &SMatrix<f64, N, N>,
    q: &SVector<f64, N>,
    half_widths: &SVector<f64, N>,
) {
    st.apa = *p_prev;
    sandwich_walk_in_place(a, &mut st.apa, identity_tail_start(a));
    symmetrize(&mut st.apa);
    st.half_widths = *half_widths;
    let d_r = remainder_dim(half_widths);
    st.q_bar = half_widths.map(|b| d_r * b * b);
    // Nest the process set with the linearisation-error set (trace-optimal Minkowski sum).
    let tr_qbar = st.q_bar.sum();
    if tr_qbar > 0.0 {
        let (s1, s2) = (tr_qbar.sqrt(), q.sum().sqrt());
        st.nest_beta = s2 / (s1 + s2);
        st.q_hat = st.q_bar / (1.0 - st.nest_beta) + q / st.nest_beta;
    } else {
        st.nest_beta = 1.0;
        st.q_hat = *q;
    }
    let (s, t) = (st.q_hat.sum().sqrt(), st.apa.trace().max(0.0).sqrt());
    st.mink_beta = if s + t > 0.0 { s / (s + t) } else { 0.5 };
    let beta = st.mink_beta;
    st.pi = st.apa / (1.0 - beta);
    for i in 0..N {
        st.pi[(i, i)] += st.q_hat[i] / beta;
    }
}

/// The update half of [`shape_step`]: intersect `Π` with the measurement set.
fn update_shape<const N: usize, const M: usize>(
    st: &mut ShapeStep<N, M>,
    h: &SMatrix<f64, M, N>,
    r: &SMatrix<f64, M, M>,
    r_sqrt_lmax: f64,
    e: &SVector<f64, M>,
) -> Result<(), EstimatorError> {
    // Paper's rho from the largest eigenvalues of the predicted output set and of R.
    let sh = SparseRows::new(h);
    st.h_pi = sh.right_t(&st.pi).transpose(); // Π symmetric
    let mut h_pi_h = sh.right_t(&st.h_pi);
    symmetrize(&mut h_pi_h);
    st.h_pi_h = h_pi_h;
    let (lam, vec) = sym_top_eigen(&h_pi_h);
    st.top_lambda = lam;
    st.top_vec = vec;
    st.rho = r_sqrt_lmax / (lam.max(0.0).sqrt() + r_sqrt_lmax);
    let rho = st.rho;
    st.pi_prime = st.pi / (1.0 - rho);
    let mut w = h_pi_h / (1.0 - rho) + r / rho;
    symmetrize(&mut w);
    st.w = w;
    let chol = cholesky_jitter(&w, "esmf W")?;
    st.w_inv_e = chol.solve(e);
    st.consistency = 1.0 - e.dot(&st.w_inv_e);
    let hpi = st.h_pi / (1.0 - rho);
    st.gain = chol.solve(&hpi).transpose();
    st.p_bar = st.pi_prime - st.gain * hpi;
    symmetrize(&mut st.p_bar);
    if !st.p_bar.iter().all(|v| v.is_finite()) {
        return Err(EstimatorError::NonFinite { what: "ESMF shape" });
    }
    Ok(())
}

/// The box-cut weights rho = k/40, k = 1..39, as (1/rho, 1/(1-rho)).
const BOX_RHO_GRID: [(f64, f64); 39] = {
    let mut g = [(0.0, 0.0); 39];
    let mut k = 0;
    while k < 39 {
        let rho = (k + 1) as f64 / 40.0;
        g[k] = (1.0 / rho, 1.0 / (1.0 - rho));
        k += 1;
    }
    g
};

#[path = "esmf_sets.rs"]
mod sets;
use sets::minkowski_add_diagonal;
pub use sets::{add_jump_set, add_jump_set_on, scale_block};

impl EsmfOutcome {
    /// The data (nearly) contradicted the predicted set: `δ_k` at or below the jump threshold
    /// before any jump or inflation.
    pub fn contradicted(&self) -> bool {
        self.jumped || self.inflations > 0 || !self.consistent
    }
}

/// What one ESMF step did, for diagnosis.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct EsmfOutcome {
    /// How many times the previous AHC block was inflated before the data became consistent.
    pub inflations: u32,
    /// False when no inflation made the data consistent (the step fell back to `P = P̄`).
    pub consistent: bool,
    /// The AHC block was reset to P0 after a run of inconsistent steps.
    pub reset: bool,
    /// The jump set was added to the previous set (see [`EsmfParams::jump_below`]).
    pub jumped: bool,
}

#[derive(Debug, Clone)]
pub struct Esmf<Mo, const N: usize, const M: usize> {
    pub model: Mo,
    pub params: EsmfParams,
    pub x: SVector<f64, N>,
    /// Shape matrix of the state set.
    pub p: SMatrix<f64, N, N>,
    p0: SMatrix<f64, N, N>,
    /// Diagonal of the process-noise shape.
    pub process_noise: SVector<f64, N>,
    /// Measurement-noise shape.
    pub r: SMatrix<f64, M, M>,
    r_sqrt_lmax: f64,
    /// The last step's intermediate quantities, and its inputs (for the MIT-ESMF).
    pub last: ShapeStep<N, M>,
    pub last_a: SMatrix<f64, N, N>,
    pub last_p_prev: SMatrix<f64, N, N>,
    pub outcome: EsmfOutcome,
    pub innovation: SVector<f64, M>,
    inconsistent_run: u32,
    /// Counters over the filter's life.
    pub inconsistent_steps: u64,
    pub resets: u64,
    /// Measurement matrix of the last step.
    pub h: SMatrix<f64, M, N>,
    /// A priori box per coordinate (centre, half-width; infinite = none): the set is
    /// intersected with it whenever its projection is wider (see `intersect_box`).
    pub box_centre: SVector<f64, N>,
    pub box_half: SVector<f64, N>,
    /// Box intersections done over the filter's life.
    pub box_cuts: u64,
}

impl<Mo: Model<N, M>, const N: usize, const M: usize> Esmf<Mo, N, M> {
    pub fn new(
        model: Mo,
        params: EsmfParams,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        process_noise: SVector<f64, N>,
        r: SMatrix<f64, M, M>,
    ) -> Self {
        let (lam, _) = sym_top_eigen(&r);
        // The structured products (`sandwich_walk`, `sandwich_gain`) assume a symmetric shape.
        let mut p0 = p0;
        symmetrize(&mut p0);
        Self {
            model,
            params,
            x: x0,
            p: p0,
            p0,
            process_noise,
            r,
            r_sqrt_lmax: lam.max(0.0).sqrt(),
            last: ShapeStep::zeros(),
            last_a: SMatrix::zeros(),
            h: SMatrix::zeros(),
            last_p_prev: p0,
            outcome: EsmfOutcome::default(),
            innovation: SVector::zeros(),
            inconsistent_run: 0,
            inconsistent_steps: 0,
            resets: 0,
            box_centre: SVector::zeros(),
            box_half: SVector::repeat(f64::INFINITY),
            box_cuts: 0,
        }
    }

    /// Intersect the set with the slabs `|z_i - c_i| <= r_i` wherever its projection on `i` is
    /// wider than the slab. Each cut is the set update with the scalar pseudo-measurement
    /// `c_i` of `z_i` bounded by `r_i` (the same outer ellipsoid as a measurement update, with
    /// the weight that makes `P_ii` smallest), so a truth inside both stays inside. It keeps
    /// directions the data do not see (gain against bias in a steady hover) from growing
    /// without end under the Minkowski prediction.
    pub fn intersect_box(&mut self) {
        // P comes in exactly symmetric and finite (the step symmetrises it and rejects a
        // non-finite shape). Between cuts only its upper triangle is kept current (mirrored
        // once at the end).
        let mut cut = false;
        for i in 0..N {
            let r = self.box_half[i];
            let pii = self.p[(i, i)];
            if !(r.is_finite() && pii > r * r) {
                continue;
            }
            let e = self.box_centre[i] - self.x[i];
            // Choose rho on a grid: the smallest trace of the result (the weight also inflates
            // every other direction by 1/(1-rho), so P_ii alone is the wrong measure).
            let trace = self.p.trace();
            // Column i of P from the upper triangle.
            let v = SVector::<f64, N>::from_fn(|r, _| self.p[(r.min(i), r.max(i))]);
            let col_sq = v.norm_squared();
            // Every grid point's size first (no branches: the divisions pipeline), then the
            // first smallest among the consistent ones (δ > 0).
            let (r2, e2) = (r * r, e * e);
            let mut sizes = [f64::INFINITY; BOX_RHO_GRID.len()];
            for (size, (inv_rho, inv_1mr)) in sizes.iter_mut().zip(BOX_RHO_GRID.iter()) {
                let inv_w = 1.0 / (pii * inv_1mr + r2 * inv_rho);
                let delta = 1.0 - e2 * inv_w;
                let s = delta * inv_1mr * (trace - col_sq * inv_1mr * inv_w);
                *size = if delta > 0.0 { s } else { f64::INFINITY };
            }
            let (mut k, mut best) = (usize::MAX, f64::INFINITY);
            for (j, &size) in sizes.iter().enumerate() {
                if size < best {
                    (k, best) = (j, size);
                }
            }
            if k == usize::MAX {
                continue;
            }
            let (inv_rho, inv_1mr) = BOX_RHO_GRID[k];
            // With Π = P/(1-ρ) and w = Π_ii + r²/ρ the update is
            // δ (Π - Π_i Π_iᵀ / w) = δ/(1-ρ) · (P - P_i P_iᵀ / ((1-ρ) w)): one symmetric rank-1
            // update in place, upper triangle mirrored (exactly symmetric).
            let w = pii * inv_1mr + r * r * inv_rho;
            let delta = 1.0 - e * e / w;
            let alpha = inv_1mr / w;
            let scale = delta * inv_1mr;
            let new_pii = scale * (pii - alpha * pii * pii);
            if !(alpha.is_finite() && scale.is_finite() && new_pii > 0.0) {
                continue;
            }
            // Upper triangle column by column (contiguous).
            let av = v * alpha;
            for (c, col) in self.p.as_mut_slice().chunks_exact_mut(N).enumerate() {
                for (x, a) in col[..=c].iter_mut().zip(av.iter()) {
                    *x = scale * (*x - a * v[c]);
                }
            }
            cut = true;
            self.x += v * (alpha * e);
            self.box_cuts += 1;
        }
        if cut {
            mirror_upper(&mut self.p);
        }
    }

    pub fn r_sqrt_lmax(&self) -> f64 {
        self.r_sqrt_lmax
    }

    /// One step. On error the set (`x`, `p`) is left as it was; the step's record (`last`,
    /// `last_a`, `h`, `last_p_prev`) may describe the failed attempt, which no caller reads
    /// (the MIT-ESMF returns at once, the monitor resets the filter).
    pub fn try_step(
        &mut self,
        u: &[f64],
        y: &SVector<f64, M>,
    ) -> Result<EsmfOutcome, EstimatorError> {
        check_inputs(self.model.input_dim(), u, y)?;
        // Inputs of the step are kept in `self` for the MIT-ESMF; they are built in place
        // (each N×N copy costs as much as a small product here).
        self.last_a = self.model.jacobian(&self.x, u);
        let fx = self.model.f(&self.x, u);
        self.h = self.model.h_matrix(u);
        let y = &(y - self.model.h_offset(u));
        let ahc = self.model.ahc_start();
        self.last_p_prev = self.p;
        let mut outcome = EsmfOutcome::default();
        let (mut x_prior, mut e);
        let (a, h, p_prev) = (&self.last_a, &self.h, &mut self.last_p_prev);
        // The intermediate quantities go straight into `self.last` (no copies of the matrices).
        let st = &mut self.last;
        loop {
            let (center, half) = remainder_box(self.model.bilinear_terms(), p_prev);
            x_prior = fx + center;
            e = y - h * x_prior;
            shape_step(
                st,
                p_prev,
                a,
                &self.process_noise,
                &half,
                h,
                &self.r,
                self.r_sqrt_lmax,
                &e,
            )?;
            if st.consistency <= self.params.jump_below && !outcome.jumped {
                add_jump_set(p_prev, &self.p0, ahc);
                outcome.jumped = true;
                continue;
            }
            if st.consistency > self.params.consistency_min {
                outcome.consistent = true;
                break;
            }
            if outcome.inflations >= self.params.max_inflations {
                break;
            }
            scale_block(p_prev, ahc, self.params.inflation.sqrt());
            outcome.inflations += 1;
        }
        let p = &mut self.p;
        if outcome.consistent {
            self.inconsistent_run = 0;
            *p = st.p_bar * st.consistency;
        } else {
            self.inconsistent_run += 1;
            self.inconsistent_steps += 1;
            *p = st.p_bar; // δ P̄ would not be positive definite
        }
        symmetrize(p);
        self.x = x_prior + st.gain * e;
        if self.inconsistent_run >= self.params.reset_after {
            for i in 0..N {
                for j in 0..N {
                    if i >= ahc || j >= ahc {
                        p[(i, j)] = self.p0[(i, j)];
                    }
                }
            }
            self.inconsistent_run = 0;
            self.resets += 1;
            outcome.reset = true;
        }
        self.intersect_box();
        self.innovation = e;
        self.outcome = outcome;
        Ok(outcome)
    }

    /// A period without a measurement (lost on the link): the prediction only, so the set
    /// grows by one period's process set and the next measurement is compared with the state
    /// at its own time. The intermediate record (`last`) holds the prediction; the MIT-ESMF
    /// reads it. On error the set is left as it was.
    pub fn coast(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        check_commands(self.model.input_dim(), u)?;
        self.last_a = self.model.jacobian(&self.x, u);
        let fx = self.model.f(&self.x, u);
        self.last_p_prev = self.p;
        let (center, half) = remainder_box(self.model.bilinear_terms(), &self.p);
        predict_shape(
            &mut self.last,
            &self.last_p_prev,
            &self.last_a,
            &self.process_noise,
            &half,
        );
        let mut p = self.last.pi;
        symmetrize(&mut p);
        let x = fx + center;
        if !(p.iter().all(|v| v.is_finite()) && x.iter().all(|v| v.is_finite())) {
            return Err(EstimatorError::NonFinite { what: "ESMF shape" });
        }
        self.x = x;
        self.p = p;
        self.intersect_box();
        Ok(())
    }

    /// After an outage too long to coast over (the outputs over it unknown): the first
    /// `rates.len()` coordinates are re-measured, within the measurement set `half_sq` (squared
    /// half-widths) about `rates`; the rest stay in their projection, grown by `periods` steps
    /// of the process set (the Minkowski sum of `periods` copies, `periods²` Q). The new set is
    /// the trace-optimal ellipsoid about the product of the two.
    pub fn reseat(&mut self, rates: &[f64], half_sq: &[f64], periods: f64) {
        let periods = super::outage_periods(periods);
        let k = rates.len().min(half_sq.len()).min(N);
        let mut rest = SMatrix::<f64, N, N>::zeros();
        let mut grown = SVector::<f64, N>::zeros();
        for i in k..N {
            for j in k..N {
                rest[(i, j)] = self.p[(i, j)];
            }
            grown[i] = (periods * periods * self.process_noise[i]).max(0.0);
        }
        // Projection ⊕ growth, then ⊗ the rates' set (trace-optimal λ).
        minkowski_add_diagonal(&mut rest, &grown, k..N);
        let tr_r: f64 = half_sq[..k].iter().sum::<f64>().max(0.0).sqrt();
        let tr_rest = rest.trace().max(0.0).sqrt();
        // Kept off 0 and 1: a zero-width part (no measurement noise, a point AHC set) would
        // divide by zero.
        let lambda = if tr_r + tr_rest > 0.0 {
            (tr_r / (tr_r + tr_rest)).clamp(1e-9, 1.0 - 1e-9)
        } else {
            0.5
        };
        self.p = rest / (1.0 - lambda);
        for i in 0..k {
            self.x[i] = rates[i];
            self.p[(i, i)] = half_sq[i] / lambda;
        }
        symmetrize(&mut self.p);
        self.inconsistent_run = 0;
        self.intersect_box();
    }

    /// Bounds of coordinate `i`: the set's projection `x_i ± √P_ii` (exact support function),
    /// clipped to the a priori box where there is one. The truth lies in both; the box cuts
    /// keep the set near the box but, being outer ellipsoids, not inside it.
    pub fn projection(&self, i: usize) -> (f64, f64) {
        let s = self.p[(i, i)].max(0.0).sqrt();
        let (lo, hi) = (self.x[i] - s, self.x[i] + s);
        let (c, r) = (self.box_centre[i], self.box_half[i]);
        if r.is_finite() && lo.max(c - r) <= hi.min(c + r) {
            (lo.max(c - r), hi.min(c + r))
        } else {
            (lo, hi)
        }
    }
}

impl_estimator!(Esmf<>, "esmf", [], projection, contradicted: []);
