//! The paper's helicopter, rates only: `z = [p, q, r, gamma_lon, delta_lon]`, `y = [p, q, r]`,
//! `u = [theta_M, theta_lat, theta_lon, theta_T]` (rad of blade / swash angle about neutral).
//!
//! Continuous rotational dynamics with quasi-steady flapping (paper eq. 9, 11, 12 structure;
//! coefficients from the X-Cell 60 geometry, see `docs/estimators.md` — physically
//! reasonable, *not* identified from a real vehicle):
//!
//! ```text
//! p' = L_p p + L_lat u_lat + c_p + c1 q r
//! q' = M_q q + M_lon (gamma u_lon + delta) + c_q + c2 p r
//! r' = N_r r + N_ped u_T + N_col u_M + c_r + c3 p q
//! ```
//!
//! Discretisation: exact zero-order hold of the (diagonal) linear part with the input held over
//! the step, plus the gyroscopic terms integrated by one Euler step. The simulator uses this very
//! map, so the reproduction scenarios have no model error, and the transition stays exactly
//! quadratic (constant Hessian) for the ESMF.

use super::{BilinearTerm, Model};
use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// Physical parameters of the paper helicopter (SI units, rates in rad/s, inputs in rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperHeliParams {
    /// Roll damping L_p (1/s).
    pub l_p: f64,
    /// Pitch damping M_q (1/s).
    pub m_q: f64,
    /// Yaw damping N_r (1/s).
    pub n_r: f64,
    /// Lateral cyclic effectiveness (1/s² per rad).
    pub l_lat: f64,
    /// Longitudinal cyclic effectiveness (1/s² per rad).
    pub m_lon: f64,
    /// Tail pitch effectiveness (1/s² per rad).
    pub n_ped: f64,
    /// Collective-to-yaw coupling (1/s² per rad).
    pub n_col: f64,
    /// Gyroscopic coefficients (Iyy-Izz)/Ixx, (Izz-Ixx)/Iyy, (Ixx-Iyy)/Izz.
    pub gyro: [f64; 3],
    /// Trim moments [c_p, c_q, c_r] (rad/s²) that the trim inputs cancel.
    pub trim_moment: [f64; 3],
}

impl PaperHeliParams {
    /// The X-Cell 60 based values (`docs/estimators.md`) with zero trim moment.
    pub fn xcell60() -> Self {
        let (ixx, iyy, izz) = (0.18, 0.34, 0.28);
        // Rotor moment stiffness K_beta + T_mr h_mr, flapping time constant and gains.
        let k_m = 54.0 + 80.44 * 0.235;
        let tau_f = 0.1;
        let (a_lon, b_lat) = (4.2, 4.2);
        Self {
            l_p: -k_m * tau_f / ixx,
            m_q: -k_m * tau_f / iyy,
            n_r: -3.0,
            l_lat: k_m * b_lat / ixx,
            m_lon: k_m * a_lon / iyy,
            n_ped: 107.0,
            n_col: -20.0,
            gyro: [(iyy - izz) / ixx, (izz - ixx) / iyy, (ixx - iyy) / izz],
            trim_moment: [0.0; 3],
        }
    }

    /// The same without gyroscopic coupling: the augmented model is then exactly linear in z,
    /// and the UKF must equal a linear Kalman filter (a test oracle).
    pub fn linear(mut self) -> Self {
        self.gyro = [0.0; 3];
        self
    }

    /// Set the trim moments so that `u_trim` holds zero rates with healthy actuators.
    pub fn trimmed_for(mut self, u_trim: &[f64; 4]) -> Self {
        self.trim_moment = [
            -self.l_lat * u_trim[1],
            -self.m_lon * u_trim[2],
            -(self.n_ped * u_trim[3] + self.n_col * u_trim[0]),
        ];
        self
    }

    /// Continuous rate accelerations for effective inputs (used by the LQR design).
    pub fn damping(&self) -> [f64; 3] {
        [self.l_p, self.m_q, self.n_r]
    }
}

/// Input indices of `u`.
pub const U_COLLECTIVE: usize = 0;
pub const U_LAT: usize = 1;
pub const U_LON: usize = 2;
pub const U_TAIL: usize = 3;

/// The paper helicopter discretised at `dt`.
#[derive(Debug, Clone)]
pub struct PaperHeli {
    pub params: PaperHeliParams,
    dt: f64,
    /// exp(a dt) per rate axis.
    phi: [f64; 3],
    /// (exp(a dt) - 1) / a per rate axis: the ZOH input gain.
    zoh: [f64; 3],
    terms: [BilinearTerm; 3],
    n_terms: usize,
}

impl PaperHeli {
    pub fn new(params: PaperHeliParams, dt: f64) -> Self {
        let a = params.damping();
        let mut phi = [0.0; 3];
        let mut zoh = [0.0; 3];
        for i in 0..3 {
            phi[i] = (a[i] * dt).exp();
            // a -> 0 limit is dt (pure integrator).
            zoh[i] = if a[i].abs() < 1e-12 {
                dt
            } else {
                (phi[i] - 1.0) / a[i]
            };
        }
        let g = params.gyro;
        let all = [
            BilinearTerm {
                row: 0,
                j: 1,
                k: 2,
                coeff: dt * g[0],
            },
            BilinearTerm {
                row: 1,
                j: 0,
                k: 2,
                coeff: dt * g[1],
            },
            BilinearTerm {
                row: 2,
                j: 0,
                k: 1,
                coeff: dt * g[2],
            },
        ];
        let mut terms = all;
        let mut n_terms = 0;
        for t in all {
            if t.coeff != 0.0 {
                terms[n_terms] = t;
                n_terms += 1;
            }
        }
        Self {
            params,
            dt,
            phi,
            zoh,
            terms,
            n_terms,
        }
    }

    /// Discrete rate-transition factors exp(a dt) (for the controller design).
    pub fn phi(&self) -> [f64; 3] {
        self.phi
    }

    /// ZOH input gains (exp(a dt) - 1)/a.
    pub fn zoh(&self) -> [f64; 3] {
        self.zoh
    }
}

impl Model<5, 3> for PaperHeli {
    fn input_dim(&self) -> usize {
        4
    }

    fn dt(&self) -> f64 {
        self.dt
    }

    fn f(&self, z: &SVector<f64, 5>, u: &[f64]) -> SVector<f64, 5> {
        let pp = &self.params;
        let (p, q, r, gamma, delta) = (z[0], z[1], z[2], z[3], z[4]);
        let g = pp.gyro;
        let dt = self.dt;
        let u_lon_eff = gamma * u[U_LON] + delta;
        SVector::<f64, 5>::new(
            self.phi[0] * p
                + self.zoh[0] * (pp.l_lat * u[U_LAT] + pp.trim_moment[0])
                + dt * g[0] * q * r,
            self.phi[1] * q
                + self.zoh[1] * (pp.m_lon * u_lon_eff + pp.trim_moment[1])
                + dt * g[1] * p * r,
            self.phi[2] * r
                + self.zoh[2]
                    * (pp.n_ped * u[U_TAIL] + pp.n_col * u[U_COLLECTIVE] + pp.trim_moment[2])
                + dt * g[2] * p * q,
            gamma,
            delta,
        )
    }

    fn jacobian(&self, z: &SVector<f64, 5>, u: &[f64]) -> SMatrix<f64, 5, 5> {
        let g = self.params.gyro;
        let dt = self.dt;
        let (p, q, r) = (z[0], z[1], z[2]);
        let b = self.zoh[1] * self.params.m_lon;
        #[rustfmt::skip]
        let jac = SMatrix::<f64, 5, 5>::new(
            self.phi[0],  dt * g[0] * r, dt * g[0] * q, 0.0,           0.0,
            dt * g[1] * r, self.phi[1],  dt * g[1] * p, b * u[U_LON],  b,
            dt * g[2] * q, dt * g[2] * p, self.phi[2],  0.0,           0.0,
            0.0,           0.0,           0.0,          1.0,           0.0,
            0.0,           0.0,           0.0,          0.0,           1.0,
        );
        jac
    }

    fn h_matrix(&self, _u: &[f64]) -> SMatrix<f64, 3, 5> {
        SMatrix::<f64, 3, 5>::identity()
    }

    fn bilinear_terms(&self) -> &[BilinearTerm] {
        &self.terms[..self.n_terms]
    }

    fn ahc_start(&self) -> usize {
        3
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobian_matches_finite_differences() {
        let m = PaperHeli::new(
            PaperHeliParams::xcell60().trimmed_for(&[0.1, 0.0, 0.05, 0.05]),
            0.02,
        );
        let z = SVector::<f64, 5>::new(0.3, -0.2, 0.5, 0.8, 0.01);
        let u = [0.1, 0.01, 0.04, 0.06];
        let jac = m.jacobian(&z, &u);
        for j in 0..5 {
            let h = 1e-6;
            let mut zp = z;
            let mut zm = z;
            zp[j] += h;
            zm[j] -= h;
            let col = (m.f(&zp, &u) - m.f(&zm, &u)) / (2.0 * h);
            for i in 0..5 {
                assert!(
                    (col[i] - jac[(i, j)]).abs() < 1e-7,
                    "d f{i}/d z{j}: fd {} vs {}",
                    col[i],
                    jac[(i, j)]
                );
            }
        }
    }

    #[test]
    fn bilinear_terms_are_the_whole_nonlinearity() {
        // f(z) - J(0) z - f(0) must equal the sum of the bilinear terms.
        let m = PaperHeli::new(PaperHeliParams::xcell60(), 0.02);
        let z = SVector::<f64, 5>::new(0.7, -0.4, 1.1, 0.6, 0.02);
        let u = [0.1, 0.02, 0.05, 0.03];
        let zero = SVector::<f64, 5>::zeros();
        let lin = m.f(&zero, &u) + m.jacobian(&zero, &u) * z;
        let mut quad = SVector::<f64, 5>::zeros();
        for t in m.bilinear_terms() {
            quad[t.row] += t.coeff * z[t.j] * z[t.k];
        }
        let resid = m.f(&z, &u) - lin - quad;
        assert!(resid.amax() < 1e-14, "residual {resid}");
    }

    #[test]
    fn zoh_matches_fine_integration_of_linear_part() {
        // Without gyro terms the discrete map is the exact ZOH solution: compare with 10^4 Euler substeps.
        let p = PaperHeliParams::xcell60().linear();
        let m = PaperHeli::new(p, 0.02);
        let z = SVector::<f64, 5>::new(0.2, -0.1, 0.3, 0.7, 0.01);
        let u = [0.1, 0.01, 0.04, 0.06];
        let next = m.f(&z, &u);
        let (mut pr, mut qr, mut rr) = (z[0], z[1], z[2]);
        let n = 100_000;
        let h = 0.02 / n as f64;
        for _ in 0..n {
            pr += h * (p.l_p * pr + p.l_lat * u[1]);
            qr += h * (p.m_q * qr + p.m_lon * (z[3] * u[2] + z[4]));
            rr += h * (p.n_r * rr + p.n_ped * u[3] + p.n_col * u[0]);
        }
        assert!(
            (next[0] - pr).abs() < 1e-4
                && (next[1] - qr).abs() < 1e-4
                && (next[2] - rr).abs() < 1e-4
        );
    }
}
