//! How detectable a simulated fault is at all: the non-centrality of the best detector there
//! is, one that knows everything the monitor does not.
//!
//! The oracle knows the simulator's true model (damping, effectiveness and offsets with the
//! scenario's mismatch), the gust process (first-order, its time constant and size), the
//! sensor noise, every healthy actuator's gamma = 1 and delta = 0, and the fault's whole
//! signature: which actuator, from when, and its effective-output deviation
//! `(gamma - 1) u + delta` at every step along the flight that was flown. The rate axes and
//! the vertical axis are then independent linear Gaussian systems: per rate axis the state
//! `[omega, gust]` with
//!
//! ```text
//! gust_{k+1}  = a gust_k + w_k                       (a = exp(-dt/tau))
//! omega_{k+1} = decay omega_k + hold (gust_{k+1} + c_k + s_k)
//! y_k         = omega_k + n_k
//! ```
//!
//! (`s_k = Σ_j B_j,i dev_j,k` the fault's acceleration), and for a_z the gust alone, seen
//! directly with the fault's `Σ_j V_j dev_j,k` added to the measurement. Against a known
//! signature the likelihood-ratio test is the matched filter on the Kalman filter's
//! innovations; its statistic is normal with unit variance, centred on 0 when healthy and on
//! `sqrt(lambda)` under the fault, where
//!
//! ```text
//! lambda = Σ_k m_kᵀ S_k⁻¹ m_k
//! ```
//!
//! and `m_k` is the innovation's mean under the fault: the signature run through the
//! filter's error dynamics (`e⁻ = F e + G s`, `m = H e⁻ (+ D s)`, `e = e⁻ - K m`). No detector
//! that knows less (the monitor knows neither the onset, the actuator, the kind nor the size)
//! can separate the fault from health better, so a fault with a small `lambda` is one no
//! monitor can be asked to find. The filter runs from the flight's start, so it has reached
//! its steady state by the onset.

use crate::model::RateParams;

/// Standard normal quantiles that set [`DETECTABLE_LAMBDA`]: a false-alarm probability of
/// 1e-6 per test (one in about 280 hours at one test a second) and a power of 95 %.
const Z_FALSE_ALARM: f64 = 4.753;
const Z_POWER: f64 = 1.645;

/// A fault is oracle-detectable when the matched filter reaches the false-alarm level above
/// with 95 % power: `lambda >= (4.753 + 1.645)² ≈ 40.9`.
pub const DETECTABLE_LAMBDA: f64 = (Z_FALSE_ALARM + Z_POWER) * (Z_FALSE_ALARM + Z_POWER);

/// One rate axis: a two-state Kalman filter `[omega, gust]` and the signature's error state.
#[derive(Debug, Clone, Copy)]
struct RateAxis {
    decay: f64,
    hold: f64,
    a: f64,
    /// Variance of the gust's innovation per step, and of the gyro's noise.
    w: f64,
    r: f64,
    p: [[f64; 2]; 2],
    e: [f64; 2],
}

impl RateAxis {
    fn new(damping: f64, dt: f64, a: f64, gust_sd: f64, gyro_sd: f64) -> Self {
        let hold = if damping * dt > 1e-12 {
            -(-damping * dt).exp_m1() / damping
        } else {
            dt
        };
        let w = (1.0 - a * a) * gust_sd * gust_sd;
        Self {
            decay: (-damping * dt).exp(),
            hold,
            a,
            w,
            r: gyro_sd * gyro_sd,
            p: [[gyro_sd * gyro_sd, 0.0], [0.0, gust_sd * gust_sd]],
            e: [0.0; 2],
        }
    }

    /// One step with the fault's acceleration `s` over it; returns `m² / S`.
    fn step(&mut self, s: f64) -> f64 {
        let (d, h, a) = (self.decay, self.hold, self.a);
        // F = [[d, h a], [0, a]]; Q = w [[h², h], [h, 1]].
        let f = [[d, h * a], [0.0, a]];
        let mut pp = [[0.0; 2]; 2];
        for (i, row) in pp.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                let mut acc = 0.0;
                for k in 0..2 {
                    for l in 0..2 {
                        acc += f[i][k] * self.p[k][l] * f[j][l];
                    }
                }
                *v = acc;
            }
        }
        pp[0][0] += self.w * h * h;
        pp[0][1] += self.w * h;
        pp[1][0] += self.w * h;
        pp[1][1] += self.w;
        let e = [d * self.e[0] + h * a * self.e[1] + h * s, a * self.e[1]];
        let s_cov = pp[0][0] + self.r;
        let m = e[0];
        let k = [pp[0][0] / s_cov, pp[1][0] / s_cov];
        self.e = [e[0] - k[0] * m, e[1] - k[1] * m];
        // P = (I - K H) P⁻ with H = [1, 0].
        self.p = [
            [(1.0 - k[0]) * pp[0][0], (1.0 - k[0]) * pp[0][1]],
            [pp[1][0] - k[1] * pp[0][0], pp[1][1] - k[1] * pp[0][1]],
        ];
        m * m / s_cov
    }
}

/// The vertical axis: the gust alone, measured with a_z.
#[derive(Debug, Clone, Copy)]
struct VerticalAxis {
    a: f64,
    w: f64,
    r: f64,
    p: f64,
    e: f64,
}

impl VerticalAxis {
    fn step(&mut self, direct: f64) -> f64 {
        let pp = self.a * self.a * self.p + self.w;
        let e = self.a * self.e;
        let m = e + direct;
        let s_cov = pp + self.r;
        let k = pp / s_cov;
        self.e = e - k * m;
        self.p = (1.0 - k) * pp;
        m * m / s_cov
    }
}

/// What the oracle needs of the simulated flight.
#[derive(Debug, Clone, Copy)]
pub struct OracleNoise {
    pub dt: f64,
    /// Gust correlation time (s) and standard deviations [roll, pitch, yaw, vertical].
    pub gust_tau_s: f64,
    pub gust_sd: [f64; 4],
    pub gyro_sd: f64,
    /// a_z noise; `None` when a_z is not measured.
    pub az_sd: Option<f64>,
}

/// The matched filter's non-centrality, accumulated step by step along a flight.
#[derive(Debug, Clone)]
pub struct Oracle {
    truth: RateParams,
    axes: [RateAxis; 3],
    vertical: Option<VerticalAxis>,
    lambda: f64,
}

impl Oracle {
    pub fn new(truth: RateParams, noise: OracleNoise) -> Self {
        let a = (-noise.dt / noise.gust_tau_s.max(noise.dt)).exp();
        let axes = std::array::from_fn(|i| {
            RateAxis::new(
                truth.damping[i],
                noise.dt,
                a,
                noise.gust_sd[i],
                noise.gyro_sd,
            )
        });
        let vertical = noise.az_sd.map(|sd| VerticalAxis {
            a,
            w: (1.0 - a * a) * noise.gust_sd[3] * noise.gust_sd[3],
            r: sd * sd,
            p: noise.gust_sd[3] * noise.gust_sd[3],
            e: 0.0,
        });
        Self {
            truth,
            axes,
            vertical,
            lambda: 0.0,
        }
    }

    /// One simulator step: `deviation[j]` is actuator j's true `(gamma - 1) u + delta` over it
    /// (0 for a healthy one).
    pub fn step(&mut self, deviation: &[f64]) {
        for (i, axis) in self.axes.iter_mut().enumerate() {
            let s: f64 = (self.truth.effectiveness.iter())
                .zip(deviation)
                .map(|(b, d)| b[i] * d)
                .sum();
            self.lambda += axis.step(s);
        }
        if let Some(v) = self.vertical.as_mut() {
            let s: f64 = (self.truth.vertical.iter())
                .zip(deviation)
                .map(|(b, d)| b * d)
                .sum();
            self.lambda += v.step(s);
        }
    }

    /// The non-centrality so far.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recursion against a plain Kalman filter run on the noise-free response to the
    /// fault: with no noise and no gust the filter's innovations are exactly their means
    /// under the fault, so `Σ innovation² / S` must equal the oracle's `lambda`.
    #[test]
    fn lambda_matches_a_kalman_filter_run_on_noise_free_data() {
        let truth = RateParams {
            damping: [3.0, 2.0, 1.0],
            effectiveness: vec![[10.0, -5.0, 2.0], [0.0, 4.0, -1.0]],
            vertical: vec![],
            offset: [0.0; 3],
            vertical_offset: 0.0,
        };
        let noise = OracleNoise {
            dt: 0.02,
            gust_tau_s: 1.0,
            gust_sd: [0.5, 0.5, 0.15, 0.3],
            gyro_sd: 0.01,
            az_sd: None,
        };
        let dev_at = |k: usize| if k >= 100 { [0.0, -0.2] } else { [0.0, 0.0] };
        let mut oracle = Oracle::new(truth.clone(), noise);
        let mut brute = 0.0;
        let a = (-noise.dt / noise.gust_tau_s).exp();
        for i in 0..3 {
            let d = truth.damping[i];
            let (decay, hold) = ((-d * noise.dt).exp(), (1.0 - (-d * noise.dt).exp()) / d);
            let w = (1.0 - a * a) * noise.gust_sd[i].powi(2);
            let r = noise.gyro_sd.powi(2);
            let f = nalgebra::Matrix2::new(decay, hold * a, 0.0, a);
            let q = nalgebra::Matrix2::new(hold * hold, hold, hold, 1.0) * w;
            let mut p = nalgebra::Matrix2::new(r, 0.0, 0.0, noise.gust_sd[i].powi(2));
            let mut x = nalgebra::Vector2::zeros();
            let mut omega = 0.0;
            for k in 0..500 {
                let s: f64 = (0..2)
                    .map(|j| truth.effectiveness[j][i] * dev_at(k)[j])
                    .sum();
                omega = decay * omega + hold * s;
                x = f * x;
                p = f * p * f.transpose() + q;
                let s_cov = p[(0, 0)] + r;
                let innovation = omega - x[0];
                brute += innovation * innovation / s_cov;
                let gain = p.column(0) / s_cov;
                x += gain * innovation;
                p -= gain * p.row(0);
            }
        }
        for k in 0..500 {
            oracle.step(&dev_at(k));
        }
        assert!(brute > 10.0, "the fault is visible: {brute}");
        let rel = (oracle.lambda() - brute).abs() / brute;
        assert!(
            rel < 1e-9,
            "recursion {} vs filter run {brute}",
            oracle.lambda()
        );
    }

    #[test]
    fn no_fault_no_lambda_and_bigger_faults_more() {
        let truth = RateParams {
            damping: [3.0; 3],
            effectiveness: vec![[10.0, 0.0, 1.0]],
            vertical: vec![],
            offset: [0.0; 3],
            vertical_offset: 0.0,
        };
        let noise = OracleNoise {
            dt: 0.02,
            gust_tau_s: 1.0,
            gust_sd: [0.5, 0.5, 0.15, 0.0],
            gyro_sd: 0.01,
            az_sd: None,
        };
        let run = |size: f64| {
            let mut o = Oracle::new(truth.clone(), noise);
            for _ in 0..250 {
                o.step(&[size]);
            }
            o.lambda()
        };
        assert_eq!(run(0.0), 0.0);
        // lambda is quadratic in the signature's size.
        let (small, big) = (run(0.01), run(0.02));
        assert!((big / small - 4.0).abs() < 1e-9, "{small} {big}");
        assert!((DETECTABLE_LAMBDA - 40.9).abs() < 0.05);
    }
}
