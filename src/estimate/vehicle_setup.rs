//! What a profile implies for the vehicle filters: their model, noise and a priori sets, and
//! each actuator's weighted effect on the measurements (which the diagnosis shares).

use super::*;
use crate::estimate::ahc_set::{AhcSetParams, LAGS};

/// Delta of range outputs (motors, throttle): random-walk std and prior std, as fractions of
/// the profile's (see `FilterSetup::from_profile`).
const RANGE_DELTA_Q_SCALE: f64 = 0.05;
const RANGE_DELTA_P0_SCALE: f64 = 0.1;

/// The filter set-up a profile implies.
#[derive(Debug, Clone)]
pub struct FilterSetup<const N: usize, const M: usize> {
    pub model: RateModel<N, M>,
    pub x0: SVector<f64, N>,
    pub kalman_p0: SMatrix<f64, N, N>,
    pub kalman_q: SVector<f64, N>,
    pub kalman_r: SMatrix<f64, M, M>,
    pub set_p0: SMatrix<f64, N, N>,
    pub set_q: SVector<f64, N>,
    pub set_r: SMatrix<f64, M, M>,
    /// Process-noise entries the MIT rules leave alone (the deltas of range outputs).
    pub fixed: [bool; N],
    /// The a priori box of the set filter: gamma within 1 +- 2 (from reversed to triple
    /// effect), delta within the command range (+-1 for a range output, +-2 about trim).
    pub box_centre: SVector<f64, N>,
    pub box_half: SVector<f64, N>,
    /// The set-membership filter's stated bounds (until a calibration stretch measures them:
    /// `VehicleFilters::set_residual_bounds`).
    pub set_params: AhcSetParams,
    /// The set filter's static a_z row when the model predicts the rates only: `g_z` per
    /// actuator and the trim (`VehicleFilters::set_vertical`).
    pub set_vertical: Option<([f64; crate::model::MAX_ACTUATORS], f64)>,
}

/// Without a calibration stretch's measurement, the bound of a row's healthy residual is this
/// many times the standard deviation the Kalman filter assumes for it (a Gaussian exceeds 4σ on
/// 6e-5 of samples), and of its change over any lag twice that.
const STATED_BOUND_SIGMAS: f64 = 4.0;

/// The fraction of its effect a calibrated model may be off by on each actuator (the set
/// filter's gains are bounded relative to the model within it).
pub const SET_MODEL_ERROR: f64 = 0.1;

/// Largest change per second of a gain or an offset the set filter follows without a
/// contradiction: a ramp to gain 0.6 over 8 s.
pub const SET_DRIFT_PER_S: f64 = 0.05;

impl<const N: usize, const M: usize> FilterSetup<N, M> {
    pub fn from_profile(profile: &Profile, dt: f64) -> Result<Self, RateModelError> {
        let model = match &profile.model.arx {
            Some(arx) => RateModel::<N, M>::from_arx(arx, dt)?,
            None => RateModel::<N, M>::new(&profile.rate_params(), dt)?,
        };
        let l = model.actuators();
        let noise = &profile.noise;
        // The profile's process noise is per step at its own rate; rescale to this dt.
        let rate_scale = (dt * profile.rate_hz).sqrt();
        let mut std_q = SVector::<f64, N>::zeros();
        let mut std_p0 = SVector::<f64, N>::zeros();
        for i in 0..3 {
            std_q[i] = noise.rate_process * rate_scale;
            std_p0[i] = INITIAL_STD[0];
        }
        for j in 0..l {
            // A motor or throttle (range output, normalised from its PWM minimum) that loses
            // thrust loses gain; an offset there is rare. Giving its delta a twentieth of the
            // random walk and a tenth of the prior spread makes a hover, where only the
            // effective output is identifiable, attribute a change to gamma.
            let range = profile.actuators[j].role.is_range();
            let (q_scale, p0_scale) = if range {
                (RANGE_DELTA_Q_SCALE, RANGE_DELTA_P0_SCALE)
            } else {
                (1.0, 1.0)
            };
            std_q[3 + j] = noise.gamma_process * rate_scale;
            std_q[3 + l + j] = noise.delta_process * rate_scale * q_scale;
            std_p0[3 + j] = INITIAL_STD[1];
            std_p0[3 + l + j] = INITIAL_STD[2] * p0_scale;
        }
        let mut fixed = [false; N];
        for j in 0..l {
            fixed[3 + l + j] = profile.actuators[j].role.is_range();
        }
        let mut box_centre = SVector::<f64, N>::zeros();
        let mut box_half = SVector::<f64, N>::repeat(f64::INFINITY);
        for j in 0..l {
            box_centre[3 + j] = 1.0;
            box_half[3 + j] = 2.0;
            box_half[3 + l + j] = if profile.actuators[j].role.is_range() {
                1.0
            } else {
                2.0
            };
        }
        let mut std_r = SVector::<f64, M>::zeros();
        for i in 0..3 {
            std_r[i] = noise.gyro;
        }
        if M == 4 {
            std_r[3] = noise.az;
        }
        let (n, m) = (N as f64, M as f64);
        let rate_sd = (std_q[0] * std_q[0] + 2.0 * std_r[0] * std_r[0]).sqrt();
        let mut level = [STATED_BOUND_SIGMAS * rate_sd; 4];
        level[3] = if M == 4 {
            STATED_BOUND_SIGMAS * std_r[3]
        } else {
            0.0
        };
        let mut residual_bound = [level.map(|b| 2.0 * b); LAGS.len()];
        residual_bound[0] = level;
        let set_params = AhcSetParams {
            residual_bound,
            drift_gamma: SET_DRIFT_PER_S * dt,
            drift_delta: SET_DRIFT_PER_S * dt,
            model_error: SET_MODEL_ERROR,
            command_ref: [0.0; crate::model::MAX_ACTUATORS],
        };
        // Set filters: the 3σ box of each noise enclosed by an ellipsoid (dimension × box²).
        Ok(Self {
            x0: model.healthy_state([0.0; 3]),
            kalman_p0: SMatrix::from_diagonal(&std_p0.component_mul(&std_p0)),
            kalman_q: std_q.component_mul(&std_q),
            kalman_r: SMatrix::from_diagonal(&std_r.component_mul(&std_r)),
            set_p0: SMatrix::from_diagonal(&(std_p0.component_mul(&std_p0) * 9.0 * n)),
            set_q: std_q.component_mul(&std_q) * 9.0 * n,
            set_r: SMatrix::from_diagonal(&(std_r.component_mul(&std_r) * 9.0 * m)),
            fixed,
            box_centre,
            box_half,
            set_params,
            set_vertical: None,
            model,
        })
    }
}

/// The noise the filters assume on a rate row per step at `dt`, and on a_z: what
/// [`weighted_effects`] and [`residual_weights`] divide by.
fn noise_sd(profile: &Profile, dt: f64) -> (f64, f64) {
    let rate_sd = (profile.noise.rate_process * (dt * profile.rate_hz).sqrt()).max(1e-9);
    (rate_sd, profile.noise.az.max(1e-9))
}

/// Inverse noise std of each measurement row, `[roll, pitch, yaw, a_z]` (a_z 0 when not
/// measured): the metric of [`weighted_effects`], for the healthy model's residuals.
pub fn residual_weights(profile: &Profile, dt: f64) -> [f64; 4] {
    let (rate_sd, az_sd) = noise_sd(profile, dt);
    let az = if profile.model.measure_az {
        1.0 / az_sd
    } else {
        0.0
    };
    [1.0 / rate_sd, 1.0 / rate_sd, 1.0 / rate_sd, az]
}

/// What one unit of each actuator's effective output does to the measurements over one step,
/// `[roll, pitch, yaw, a_z]` (a_z zero when not measured), each row divided by the noise the
/// filters assume on it: the metric in which the diagnosis asks which single actuator explains
/// the estimated deviations (see `diagnose::vehicle`).
#[allow(clippy::needless_range_loop)] // rows i of the effect, as in the model
pub fn weighted_effects(profile: &Profile, dt: f64) -> Vec<[f64; 4]> {
    let l = profile.actuators.len();
    let (rate_sd, az_sd) = noise_sd(profile, dt);
    let az = profile.model.measure_az;
    let mut out = vec![[0.0; 4]; l];
    match &profile.model.arx {
        Some(arx) => {
            for (j, o) in out.iter_mut().enumerate() {
                for i in 0..3 {
                    o[i] = arx.input[j][i] / rate_sd;
                }
                if az {
                    o[3] = arx.vertical.get(j).copied().unwrap_or(0.0) / az_sd;
                }
            }
        }
        None => {
            let p = profile.rate_params();
            for (j, o) in out.iter_mut().enumerate() {
                for i in 0..3 {
                    let d = p.damping[i];
                    let hold = if d * dt > 1e-12 {
                        -(-d * dt).exp_m1() / d
                    } else {
                        dt
                    };
                    o[i] = hold * p.effectiveness[j][i] / rate_sd;
                }
                if az {
                    o[3] = p.vertical[j] / az_sd;
                }
            }
        }
    }
    out
}

macro_rules! sized {
    ($profile:expr, $dt:expr, $l:expr, $m:expr; $(($ll:literal, $mm:literal, $n:literal, $s:literal)),*) => {
        match ($l, $m) {
            $(($ll, $mm) => Ok(Box::new(FilterPair::<$n, $mm, $s>::new(
                FilterSetup::from_profile($profile, $dt)?,
            )) as Box<dyn VehicleFilters>),)*
            (l, m) => Err(BuildError::Size { l, m }),
        }
    };
}

/// The vehicle's filters (both detectors and the set filter) for a profile at sample period `dt`.
pub fn build(profile: &Profile, dt: f64) -> Result<Box<dyn VehicleFilters>, BuildError> {
    let (l, m) = (profile.actuators.len(), profile.measurements());
    sized!(profile, dt, l, m;
        (2, 3, 7, 15), (3, 3, 9, 19), (4, 3, 11, 23), (6, 3, 15, 31), (8, 3, 19, 39),
        (2, 4, 7, 15), (3, 4, 9, 19), (4, 4, 11, 23), (6, 4, 15, 31), (8, 4, 19, 39))
}
