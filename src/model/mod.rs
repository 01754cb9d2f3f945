//! Discrete-time augmented models `z_{k+1} = f(z_k, u_k) + w_k`, `y_k = H z_k + v_k`.
//!
//! The state `z` holds the body rates first and the actuator health coefficients (AHCs) after
//! them. Every model ahcmon uses is *at most quadratic* in `z` for a known input `u`: linear in
//! the AHCs (because `gamma * u` is linear in `gamma` when `u` is known) plus optional bilinear
//! gyroscopic terms. That is what the ESMF needs for an exact linearisation-error bound (a
//! constant Hessian), so the trait exposes those terms explicitly.

pub mod calibrate;
mod paper_heli;
mod rate;

pub use paper_heli::{PaperHeli, PaperHeliParams};
pub use rate::{ARX_DT_TOLERANCE, ArxParams, MAX_ACTUATORS, RateModel, RateModelError, RateParams};

/// Longest input vector any model takes.
pub const MAX_INPUTS: usize = MAX_ACTUATORS + 3;

use nalgebra::{SMatrix, SVector};

/// `f_row += coeff * z[j] * z[k]`: one bilinear term of the state transition.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BilinearTerm {
    pub row: usize,
    pub j: usize,
    pub k: usize,
    pub coeff: f64,
}

/// A discrete-time augmented model with `N` states and `M` (linear) measurements.
pub trait Model<const N: usize, const M: usize> {
    /// Number of entries `u` must have.
    fn input_dim(&self) -> usize;
    /// Sample period (s) the model was discretised at.
    fn dt(&self) -> f64;
    /// State transition. `u.len()` equals [`Model::input_dim`] (checked by the filters).
    fn f(&self, z: &SVector<f64, N>, u: &[f64]) -> SVector<f64, N>;
    /// `df/dz` at `(z, u)`.
    fn jacobian(&self, z: &SVector<f64, N>, u: &[f64]) -> SMatrix<f64, N, N>;
    /// The measurement matrix for input `u`: measurements are affine in the state for a known
    /// input (gyro rates; a vertical specific force that depends on `gamma * u + delta`).
    fn h_matrix(&self, u: &[f64]) -> SMatrix<f64, M, N>;
    /// The measurement's offset for input `u` (a trim specific force); zero by default.
    fn h_offset(&self, _u: &[f64]) -> SVector<f64, M> {
        SVector::zeros()
    }
    /// The bilinear terms of `f` (empty for a linear model). Their Hessian is constant.
    fn bilinear_terms(&self) -> &[BilinearTerm];
    /// Index of the first AHC in the state; AHCs occupy `ahc_start()..N`.
    fn ahc_start(&self) -> usize;
    /// True when `f` is affine in `z` for a known `u` (`f(z, u) = F(u) z + b(u)`, no bilinear
    /// terms, `jacobian` independent of `z`). The unscented transform of an affine map is
    /// exact, so the UKF then propagates mean and covariance in closed form: the same numbers
    /// as its sigma points give, at a fraction of the cost.
    fn is_affine(&self) -> bool {
        false
    }
    /// Measurement function.
    fn h(&self, z: &SVector<f64, N>, u: &[f64]) -> SVector<f64, M> {
        self.h_matrix(u) * z + self.h_offset(u)
    }
}
