//! The five estimators of the paper over a [`Model`](crate::model::Model): UKF, MIT-UKF,
//! KF-UKF, ESMF and MIT-ESMF. Each is a struct with an allocation-free `step(u, y)` over
//! fixed-size nalgebra types.

/// Implements [`Estimator`] for one of the five filters from where its state lives: the
/// filter itself (`[]`), or its inner filter (`[ukf]` for the MIT-UKF and KF-UKF, `[esmf]`
/// for the MIT-ESMF); then the bounding method: `three_sigma` (Kalman filters, ±3σ) or
/// `projection` (set filters, the set's projection). Set filters also say when the data
/// contradicted the set (`contradicted: [where the set lives]`). Every filter's own step is
/// `try_step`.
macro_rules! impl_estimator {
    ($ty:ident<$($param:ident),*>, $name:literal, [$($inner:ident)?], $bounds:ident
        $(, contradicted: [$($set:ident)?])?) => {
        impl<Mo: crate::model::Model<N, M>, const N: usize, const M: usize $(, const $param: usize)*>
            crate::estimate::Estimator<N, M> for $ty<Mo, N, M $(, $param)*>
        {
            fn name(&self) -> &'static str {
                $name
            }
            fn step(
                &mut self,
                u: &[f64],
                y: &nalgebra::SVector<f64, M>,
            ) -> Result<(), crate::estimate::EstimatorError> {
                self.try_step(u, y).map(|_| ())
            }
            fn state(&self) -> &nalgebra::SVector<f64, N> {
                &self$(.$inner)?.x
            }
            fn bounds(&self, i: usize) -> (f64, f64) {
                self$(.$inner)?.$bounds(i)
            }
            fn process_noise(&self) -> &nalgebra::SVector<f64, N> {
                &self$(.$inner)?.process_noise
            }
            fn innovation(&self) -> &nalgebra::SVector<f64, M> {
                &self$(.$inner)?.innovation
            }
            $(
                fn contradicted(&self) -> bool {
                    self$(.$set)?.outcome.contradicted()
                }
            )?
        }
    };
}

pub mod ahc_set;
mod esmf;
mod kf_ukf;
pub mod linalg;
mod mit;
mod mit_esmf;
mod mit_ukf;
pub mod polygon;
mod ukf;
pub mod vehicle;

pub use esmf::{
    Esmf, EsmfOutcome, EsmfParams, ShapeStep, predict_shape, remainder_box, scale_block, shape_step,
};
pub use kf_ukf::{KfUkf, SlaveKfParams};
pub use mit::{
    AdaptationParams, GainTransition, InnovationWindow, Sandwich, Sensitivity, StepSchedule,
};
pub use mit_esmf::{MitEsmf, ShapeSensitivity};
pub use mit_ukf::{IdentifyParams, MitUkf};
pub use ukf::{Ukf, UkfParams};

use nalgebra::SVector;
use thiserror::Error;

/// What can go wrong in one estimator step. None of these panics; the caller decides
/// (the monitor emits a `filter_reset` decision and re-initialises the covariance).
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EstimatorError {
    #[error("matrix not positive definite in {stage}, even with jitter")]
    NotPositiveDefinite { stage: &'static str },
    #[error("input has {got} entries, the model expects {expected}")]
    InputDimension { expected: usize, got: usize },
    #[error("non-finite value in the {what}")]
    NonFinite { what: &'static str },
}

/// The common face of all five filters, used by `eval` and the monitor.
pub trait Estimator<const N: usize, const M: usize> {
    /// Short name: `ukf`, `kf-ukf`, `mit-ukf`, `esmf`, `mit-esmf`.
    fn name(&self) -> &'static str;
    /// One predict + update with the commanded inputs `u` and the measurement `y`.
    fn step(&mut self, u: &[f64], y: &SVector<f64, M>) -> Result<(), EstimatorError>;
    /// The state estimate (for the ESMF: the centre of the set).
    fn state(&self) -> &SVector<f64, N>;
    /// Bounds of coordinate `i`: ±3σ for the Kalman filters, the projection of the set for the ESMFs.
    fn bounds(&self, i: usize) -> (f64, f64);
    /// The diagonal of the process noise in force (adapted by the MIT and KF variants).
    fn process_noise(&self) -> &SVector<f64, N>;
    /// The last innovation `y - h(x⁻)`.
    fn innovation(&self) -> &SVector<f64, M>;
    /// Set filters: the last step's data (nearly) contradicted the predicted set — its
    /// consistency `δ_k` was at or below the jump threshold (0.9 by default; ≤ 0 is an outright
    /// contradiction) before any jump or inflation: the ESMF's explicit fault indication.
    /// Kalman filters: always false.
    fn contradicted(&self) -> bool {
        false
    }
}

pub(crate) fn check_inputs<const M: usize>(
    expected: usize,
    u: &[f64],
    y: &SVector<f64, M>,
) -> Result<(), EstimatorError> {
    check_commands(expected, u)?;
    if !y.iter().all(|v| v.is_finite()) {
        return Err(EstimatorError::NonFinite {
            what: "measurement",
        });
    }
    Ok(())
}

/// The inputs of a step without a measurement (a coast over a lost sample).
pub(crate) fn check_commands(expected: usize, u: &[f64]) -> Result<(), EstimatorError> {
    if u.len() != expected {
        return Err(EstimatorError::InputDimension {
            expected,
            got: u.len(),
        });
    }
    if !u.iter().all(|v| v.is_finite()) {
        return Err(EstimatorError::NonFinite { what: "input" });
    }
    Ok(())
}

/// The periods an outage spanned, as a reseat takes them: a NaN or negative count (no real
/// outage) grows nothing.
pub(crate) fn outage_periods(periods: f64) -> f64 {
    if periods.is_finite() {
        periods.max(0.0)
    } else {
        0.0
    }
}
