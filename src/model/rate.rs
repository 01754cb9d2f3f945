//! The rate-effectiveness model for any vehicle (`docs/estimators.md`, the models):
//!
//! ```text
//! omega_dot = -D omega + G (Gamma u + Delta) + c          (3 rate rows)
//! a_z       =             g_z (Gamma u + Delta) + c_z     (optional 4th measurement)
//! ```
//!
//! with `l` actuators and the state `z = [p, q, r, gamma_1..gamma_l, delta_1..delta_l]`, so
//! `N = 3 + 2l`; `M = 3` (gyro only) or `M = 4` (gyro and vertical specific force). Linear in
//! `z` for a known `u`; the rates are discretised by zero-order hold of the diagonal damping.
//!
//! Internally the model is kept in its discrete form,
//!
//! ```text
//! omega_{k+1} = Phi omega_k + B (Gamma u_k + Delta) + E x_k + c_d
//! ```
//!
//! which the continuous model above fills with `Phi = exp(-D dt)`, `B = hold G`, `E = 0`. A
//! vehicle whose rate response is not first order (a helicopter's rotor flapping and servo lag)
//! uses an identified [`ArxParams`] instead: a full `Phi` (cross-axis coupling), full `B`, and
//! `x_k` the *measured* angular increment of the previous step (`y_k - y_{k-1}`), passed as
//! three extra inputs after the actuators' commands; `u_k` is then the command the
//! identification found acting now, i.e. the one sent `delay` samples earlier (the caller
//! delays it).

// Index loops mirror the matrix maths (rows i, actuators j) and read best that way.
#![allow(clippy::needless_range_loop)]

use nalgebra::{SMatrix, SVector};

use super::{BilinearTerm, Model};

/// Most actuators a model can have (an octocopter).
/// How far (relative) the sample period may be from the one an identified discrete model was
/// identified at.
pub const ARX_DT_TOLERANCE: f64 = 0.05;

pub const MAX_ACTUATORS: usize = 8;

/// Continuous-time parameters of the rate-effectiveness model.
#[derive(Debug, Clone, PartialEq)]
pub struct RateParams {
    /// Diagonal damping `D` (1/s) of p, q, r.
    pub damping: [f64; 3],
    /// Control effectiveness: one column `[roll, pitch, yaw]` (rad/s² per unit of normalised
    /// command) per actuator.
    pub effectiveness: Vec<[f64; 3]>,
    /// Vertical specific force per unit of command (m/s² per unit), one per actuator; used when
    /// `a_z` is measured.
    pub vertical: Vec<f64>,
    /// Trim offset `c` of the rate rows (rad/s²) and `c_z` of `a_z` (m/s²).
    pub offset: [f64; 3],
    pub vertical_offset: f64,
}

impl RateParams {
    pub fn actuators(&self) -> usize {
        self.effectiveness.len()
    }

    /// `G` scaled by `g` and `D` by `d` (model mismatch in the simulators).
    pub fn scaled(&self, d: f64, g: f64) -> Self {
        let mut out = self.clone();
        out.damping.iter_mut().for_each(|v| *v *= d);
        out.effectiveness
            .iter_mut()
            .for_each(|c| c.iter_mut().for_each(|v| *v *= g));
        out.vertical.iter_mut().for_each(|v| *v *= g);
        out
    }
}

/// An identified discrete rate model (see the module note): what
/// [`crate::model::calibrate::calibrate_arx`] fits when the profile asks for `dynamics = "arx"`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArxParams {
    /// Sample period the parameters hold for (s).
    pub dt: f64,
    /// Samples by which the commands act late (servo and rotor lag).
    pub delay: usize,
    /// `Phi`, rows p, q, r.
    pub phi: [[f64; 3]; 3],
    /// `E`: effect of the previous step's measured rate increment, rows p, q, r.
    pub previous_increment: [[f64; 3]; 3],
    /// `B`: one column `[roll, pitch, yaw]` (rad/s per step per unit of command) per actuator.
    pub input: Vec<[f64; 3]>,
    /// `c_d` (rad/s per step).
    pub offset: [f64; 3],
    /// Vertical specific force per unit of command and its trim (static, as in [`RateParams`]).
    pub vertical: Vec<f64>,
    pub vertical_offset: f64,
}

/// Why a [`RateModel`] cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RateModelError {
    #[error("state size {n} does not fit {l} actuators (needs 3 + 2 x {l})")]
    StateSize { n: usize, l: usize },
    #[error("{m} measurements: the model has 3 (gyro) or 4 (gyro and a_z)")]
    MeasurementSize { m: usize },
    #[error("{l} actuators: between 1 and {MAX_ACTUATORS} are supported")]
    Actuators { l: usize },
    #[error("vertical effectiveness has {got} entries for {l} actuators")]
    Vertical { got: usize, l: usize },
    #[error("non-finite or negative parameter ({what})")]
    Parameter { what: &'static str },
    #[error("the identified model is for dt {model} s, the samples come every {dt} s")]
    Period { model: f64, dt: f64 },
}

/// The discrete rate-effectiveness model with `N = 3 + 2l` states and `M` measurements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateModel<const N: usize, const M: usize> {
    l: usize,
    dt: f64,
    /// `Phi`.
    phi: [[f64; 3]; 3],
    /// Rows 0..3: `B` (discrete); row 3: `g_z`.
    g: [[f64; MAX_ACTUATORS]; 4],
    /// `E`, and whether the model takes the previous increment as input at all.
    previous_increment: [[f64; 3]; 3],
    exogenous: bool,
    /// Rows 0..3: `c_d`; 3: `c_z`.
    offset: [f64; 4],
}

impl<const N: usize, const M: usize> RateModel<N, M> {
    /// The sizes and the period every model must satisfy.
    fn check(l: usize, vertical: usize, dt: f64) -> Result<(), RateModelError> {
        if l == 0 || l > MAX_ACTUATORS {
            return Err(RateModelError::Actuators { l });
        }
        if N != 3 + 2 * l {
            return Err(RateModelError::StateSize { n: N, l });
        }
        if M != 3 && M != 4 {
            return Err(RateModelError::MeasurementSize { m: M });
        }
        if M == 4 && vertical != l {
            return Err(RateModelError::Vertical { got: vertical, l });
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(RateModelError::Parameter { what: "dt" });
        }
        Ok(())
    }

    pub fn new(params: &RateParams, dt: f64) -> Result<Self, RateModelError> {
        let l = params.actuators();
        Self::check(l, params.vertical.len(), dt)?;
        if params.damping.iter().any(|d| !d.is_finite() || *d < 0.0) {
            return Err(RateModelError::Parameter { what: "damping" });
        }
        let finite = params.effectiveness.iter().flatten().all(|v| v.is_finite())
            && params.vertical.iter().all(|v| v.is_finite())
            && params.offset.iter().all(|v| v.is_finite())
            && params.vertical_offset.is_finite();
        if !finite {
            return Err(RateModelError::Parameter {
                what: "effectiveness or offset",
            });
        }
        let mut phi = [[0.0; 3]; 3];
        let mut hold = [0.0; 3];
        for i in 0..3 {
            let d = params.damping[i];
            phi[i][i] = (-d * dt).exp();
            // -expm1 keeps precision for small D dt.
            hold[i] = if d * dt > 1e-12 {
                -(-d * dt).exp_m1() / d
            } else {
                dt
            };
        }
        let mut g = [[0.0; MAX_ACTUATORS]; 4];
        for (j, col) in params.effectiveness.iter().enumerate() {
            for i in 0..3 {
                g[i][j] = hold[i] * col[i];
            }
            if M == 4 {
                g[3][j] = params.vertical[j];
            }
        }
        let mut offset = [0.0; 4];
        for i in 0..3 {
            offset[i] = hold[i] * params.offset[i];
        }
        offset[3] = params.vertical_offset;
        Ok(Self {
            l,
            dt,
            phi,
            g,
            previous_increment: [[0.0; 3]; 3],
            exogenous: false,
            offset,
        })
    }

    /// The model of identified discrete parameters, at the period they were identified at.
    pub fn from_arx(params: &ArxParams, dt: f64) -> Result<Self, RateModelError> {
        let l = params.input.len();
        Self::check(l, params.vertical.len(), dt)?;
        // The parameters are per step: another period would need another identification.
        if params.dt.is_nan() || (params.dt - dt).abs() > ARX_DT_TOLERANCE * dt {
            return Err(RateModelError::Period {
                model: params.dt,
                dt,
            });
        }
        let finite = params
            .phi
            .iter()
            .chain(&params.previous_increment)
            .chain(&params.input)
            .flatten()
            .chain(&params.offset)
            .chain(&params.vertical)
            .all(|v| v.is_finite())
            && params.vertical_offset.is_finite();
        if !finite {
            return Err(RateModelError::Parameter {
                what: "identified model",
            });
        }
        let mut g = [[0.0; MAX_ACTUATORS]; 4];
        for (j, col) in params.input.iter().enumerate() {
            for i in 0..3 {
                g[i][j] = col[i];
            }
            if M == 4 {
                g[3][j] = params.vertical[j];
            }
        }
        let mut offset = [0.0; 4];
        offset[..3].copy_from_slice(&params.offset);
        offset[3] = params.vertical_offset;
        Ok(Self {
            l,
            dt,
            phi: params.phi,
            g,
            previous_increment: params.previous_increment,
            exogenous: true,
            offset,
        })
    }

    pub fn actuators(&self) -> usize {
        self.l
    }

    /// Index of `gamma_j` and `delta_j` in the state.
    pub fn gamma_index(&self, j: usize) -> usize {
        3 + j
    }
    pub fn delta_index(&self, j: usize) -> usize {
        3 + self.l + j
    }

    /// The healthy state for rates `omega`: gamma = 1, delta = 0.
    pub fn healthy_state(&self, omega: [f64; 3]) -> SVector<f64, N> {
        let mut z = SVector::<f64, N>::zeros();
        z.fixed_rows_mut::<3>(0).copy_from_slice(&omega);
        for j in 0..self.l {
            z[3 + j] = 1.0;
        }
        z
    }

    /// Effective actuation `gamma_j u_j + delta_j`.
    fn effective(&self, z: &SVector<f64, N>, u: &[f64], j: usize) -> f64 {
        z[3 + j] * u[j] + z[3 + self.l + j]
    }
}

impl<const N: usize, const M: usize> Model<N, M> for RateModel<N, M> {
    fn input_dim(&self) -> usize {
        self.l + if self.exogenous { 3 } else { 0 }
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn f(&self, z: &SVector<f64, N>, u: &[f64]) -> SVector<f64, N> {
        let mut out = *z;
        for i in 0..3 {
            let mut acc = self.offset[i];
            for k in 0..3 {
                acc += self.phi[i][k] * z[k];
            }
            for j in 0..self.l {
                acc += self.g[i][j] * self.effective(z, u, j);
            }
            if self.exogenous {
                for k in 0..3 {
                    acc += self.previous_increment[i][k] * u[self.l + k];
                }
            }
            out[i] = acc;
        }
        out
    }

    fn jacobian(&self, _z: &SVector<f64, N>, u: &[f64]) -> SMatrix<f64, N, N> {
        let mut a = SMatrix::<f64, N, N>::identity();
        for i in 0..3 {
            for k in 0..3 {
                a[(i, k)] = self.phi[i][k];
            }
            for j in 0..self.l {
                a[(i, 3 + j)] = self.g[i][j] * u[j];
                a[(i, 3 + self.l + j)] = self.g[i][j];
            }
        }
        a
    }

    fn h_matrix(&self, u: &[f64]) -> SMatrix<f64, M, N> {
        let mut h = SMatrix::<f64, M, N>::zeros();
        for i in 0..3 {
            h[(i, i)] = 1.0;
        }
        if M == 4 {
            for j in 0..self.l.min(u.len()) {
                h[(3, 3 + j)] = self.g[3][j] * u[j];
                h[(3, 3 + self.l + j)] = self.g[3][j];
            }
        }
        h
    }

    fn h_offset(&self, _u: &[f64]) -> SVector<f64, M> {
        let mut o = SVector::<f64, M>::zeros();
        if M == 4 {
            o[3] = self.offset[3];
        }
        o
    }

    fn bilinear_terms(&self) -> &[BilinearTerm] {
        &[]
    }

    fn ahc_start(&self) -> usize {
        3
    }

    fn is_affine(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad_params() -> RateParams {
        RateParams {
            damping: [2.0, 2.0, 0.5],
            effectiveness: vec![
                [-60.0, 60.0, 8.0],
                [60.0, -60.0, 8.0],
                [60.0, 60.0, -8.0],
                [-60.0, -60.0, -8.0],
            ],
            vertical: vec![-4.9; 4],
            offset: [0.0; 3],
            vertical_offset: 0.0,
        }
    }

    #[test]
    fn sizes_are_checked() {
        assert!(RateModel::<11, 4>::new(&quad_params(), 0.02).is_ok());
        assert_eq!(
            RateModel::<9, 4>::new(&quad_params(), 0.02),
            Err(RateModelError::StateSize { n: 9, l: 4 })
        );
        assert!(RateModel::<11, 5>::new(&quad_params(), 0.02).is_err());
        assert!(RateModel::<11, 4>::new(&quad_params(), -1.0).is_err());
    }

    #[test]
    fn zoh_matches_fine_integration_and_jacobian_matches_differences() {
        let m = RateModel::<11, 4>::new(&quad_params(), 0.02).unwrap();
        let mut z = m.healthy_state([0.1, -0.2, 0.05]);
        z[4] = 0.7;
        z[9] = 0.03;
        let u = [0.5, 0.55, 0.45, 0.52];
        // Fine Euler integration of the continuous model with the input held.
        let p = quad_params();
        let mut w = [z[0], z[1], z[2]];
        let steps = 20000;
        let h = 0.02 / steps as f64;
        for _ in 0..steps {
            for i in 0..3 {
                let mut acc = -p.damping[i] * w[i];
                for j in 0..4 {
                    acc += p.effectiveness[j][i] * (z[3 + j] * u[j] + z[7 + j]);
                }
                w[i] += h * acc;
            }
        }
        let next = m.f(&z, &u);
        for i in 0..3 {
            assert!(
                (next[i] - w[i]).abs() < 1e-5,
                "{i}: {} vs {}",
                next[i],
                w[i]
            );
        }
        let a = m.jacobian(&z, &u);
        for k in 0..11 {
            let mut dz = SVector::<f64, 11>::zeros();
            dz[k] = 1e-6;
            let fd = (m.f(&(z + dz), &u) - m.f(&(z - dz), &u)) / 2e-6;
            for i in 0..11 {
                assert!((fd[i] - a[(i, k)]).abs() < 1e-7, "({i},{k})");
            }
        }
        // a_z: g_z (gamma u + delta).
        let y = m.h(&z, &u);
        let az: f64 = (0..4).map(|j| -4.9 * (z[3 + j] * u[j] + z[7 + j])).sum();
        assert!((y[3] - az).abs() < 1e-12);
    }
}
