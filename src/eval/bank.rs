//! The paper filter bank: the five filters on the paper model, configured from the noise
//! levels a user would know at the start (the scenario's *nominal* noise, never the changes
//! or the faults that come later). One configuration for every scenario: no per-scenario tuning.

use crate::estimate::{
    AdaptationParams, Esmf, EsmfParams, Estimator, KfUkf, MitEsmf, MitUkf, SlaveKfParams, Ukf,
    UkfParams,
};
use crate::model::PaperHeli;
use crate::sim::noise::NoiseSchedule;
use nalgebra::{SMatrix, SVector};

pub type PaperFilter = Box<dyn Estimator<5, 3> + Send>;

/// Filter names in the order [`paper_bank`] returns them.
pub const FILTERS: [&str; 5] = ["ukf", "kf-ukf", "mit-ukf", "esmf", "mit-esmf"];

/// Random-walk std per step of the AHCs: gamma, and delta in input units. Delta is scaled by a
/// typical input magnitude (0.05 rad) so that both move the rates alike.
pub const GAMMA_WALK_STD: f64 = 1e-3;
pub const INPUT_SCALE_RAD: f64 = 0.05;
pub const DELTA_WALK_STD: f64 = GAMMA_WALK_STD * INPUT_SCALE_RAD;
/// Initial 1σ uncertainty: rates (rad/s), gamma, delta (rad).
pub const INITIAL_STD: [f64; 5] = [0.01, 0.01, 0.01, 0.1, 0.01];

/// Noise models the filters are given.
#[derive(Debug, Clone, Copy)]
pub struct BankNoise {
    /// Variance of the process noise on each rate, and of the measurement noise.
    pub process_var: f64,
    pub measurement_var: f64,
    /// Per-axis bound (half-width) of the same noises for the set filters.
    pub process_bound: f64,
    pub measurement_bound: f64,
}

impl BankNoise {
    pub fn nominal(process: &NoiseSchedule, measurement: &NoiseSchedule) -> Self {
        let (pn, mn) = (process.nominal(), measurement.nominal());
        Self {
            process_var: process.variance(pn),
            measurement_var: measurement.variance(mn),
            process_bound: process.bound(pn),
            measurement_bound: measurement.bound(mn),
        }
    }

    /// Kalman process noise diagonal.
    pub fn kalman_q(&self) -> SVector<f64, 5> {
        let v = self.process_var;
        SVector::from([v, v, v, GAMMA_WALK_STD.powi(2), DELTA_WALK_STD.powi(2)])
    }

    pub fn kalman_r(&self) -> SMatrix<f64, 3, 3> {
        SMatrix::identity() * self.measurement_var
    }

    /// Set-filter process shape: the 5-D box of half-widths (rate bound, 3σ of the AHC walk)
    /// enclosed by the ellipsoid d·diag(half-width²), d = 5.
    pub fn set_q(&self) -> SVector<f64, 5> {
        let b = self.process_bound;
        SVector::from([
            b * b,
            b * b,
            b * b,
            (3.0 * GAMMA_WALK_STD).powi(2),
            (3.0 * DELTA_WALK_STD).powi(2),
        ]) * 5.0
    }

    /// Set-filter measurement shape: a 3-D box enclosed by 3·diag(b²).
    pub fn set_r(&self) -> SMatrix<f64, 3, 3> {
        SMatrix::identity() * (3.0 * self.measurement_bound.powi(2))
    }
}

pub fn x0() -> SVector<f64, 5> {
    SVector::from([0.0, 0.0, 0.0, 1.0, 0.0])
}

pub fn kalman_p0() -> SMatrix<f64, 5, 5> {
    SMatrix::from_diagonal(&SVector::from(INITIAL_STD.map(|s| s * s)))
}

/// The initial set encloses the 3σ box of the Kalman prior.
pub fn set_p0() -> SMatrix<f64, 5, 5> {
    SMatrix::from_diagonal(&SVector::from(INITIAL_STD.map(|s| 5.0 * (3.0 * s).powi(2))))
}

pub fn paper_bank(model: &PaperHeli, noise: &BankNoise) -> Vec<PaperFilter> {
    let ukf = UkfParams::default();
    let adapt = AdaptationParams::default();
    vec![
        Box::new(Ukf::<_, 5, 3, 11>::new(
            model.clone(),
            ukf,
            x0(),
            kalman_p0(),
            noise.kalman_q(),
            noise.kalman_r(),
        )),
        Box::new(KfUkf::<_, 5, 3, 11>::new(
            model.clone(),
            ukf,
            adapt,
            SlaveKfParams::default(),
            x0(),
            kalman_p0(),
            noise.kalman_q(),
            noise.kalman_r(),
        )),
        Box::new(MitUkf::<_, 5, 3, 11>::new(
            model.clone(),
            ukf,
            adapt,
            x0(),
            kalman_p0(),
            noise.kalman_q(),
            noise.kalman_r(),
        )),
        Box::new(Esmf::new(
            model.clone(),
            EsmfParams::default(),
            x0(),
            set_p0(),
            noise.set_q(),
            noise.set_r(),
        )),
        Box::new(MitEsmf::new(
            model.clone(),
            EsmfParams::default(),
            adapt,
            x0(),
            set_p0(),
            noise.set_q(),
            noise.set_r(),
        )),
    ]
}
