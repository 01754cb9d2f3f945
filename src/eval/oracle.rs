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

/// One rate axis: a two-state Kalman filter `[omega, gust]` and the error states of `K`
/// signatures (they share the filter's covariance and gains, which the signature does not move).
#[derive(Debug, Clone, Copy)]
struct RateAxis<const K: usize> {
    decay: f64,
    hold: f64,
    a: f64,
    /// Variance of the gust's innovation per step, and of the gyro's noise.
    w: f64,
    r: f64,
    p: [[f64; 2]; 2],
    e: [[f64; 2]; K],
}

impl<const K: usize> RateAxis<K> {
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
            e: [[0.0; 2]; K],
        }
    }

    /// One step with each signature's acceleration `s[k]` over it; returns the innovation
    /// means and their variance.
    fn step(&mut self, s: &[f64; K]) -> ([f64; K], f64) {
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
        let s_cov = pp[0][0] + self.r;
        let gain = [pp[0][0] / s_cov, pp[1][0] / s_cov];
        let mut m = [0.0; K];
        for (ek, (mk, sk)) in self.e.iter_mut().zip(m.iter_mut().zip(s)) {
            let e = [d * ek[0] + h * a * ek[1] + h * sk, a * ek[1]];
            *mk = e[0];
            *ek = [e[0] - gain[0] * e[0], e[1] - gain[1] * e[0]];
        }
        // P = (I - K H) P⁻ with H = [1, 0].
        self.p = [
            [(1.0 - gain[0]) * pp[0][0], (1.0 - gain[0]) * pp[0][1]],
            [pp[1][0] - gain[1] * pp[0][0], pp[1][1] - gain[1] * pp[0][1]],
        ];
        (m, s_cov)
    }
}

/// The vertical axis: the gust alone, measured with a_z.
#[derive(Debug, Clone, Copy)]
struct VerticalAxis<const K: usize> {
    a: f64,
    w: f64,
    r: f64,
    p: f64,
    e: [f64; K],
}

impl<const K: usize> VerticalAxis<K> {
    fn new(a: f64, gust_sd: f64, az_sd: f64) -> Self {
        Self {
            a,
            w: (1.0 - a * a) * gust_sd * gust_sd,
            r: az_sd * az_sd,
            p: gust_sd * gust_sd,
            e: [0.0; K],
        }
    }

    fn step(&mut self, direct: &[f64; K]) -> ([f64; K], f64) {
        let pp = self.a * self.a * self.p + self.w;
        let s_cov = pp + self.r;
        let gain = pp / s_cov;
        let mut m = [0.0; K];
        for (ek, (mk, dk)) in self.e.iter_mut().zip(m.iter_mut().zip(direct)) {
            let e = self.a * *ek;
            *mk = e + dk;
            *ek = e - gain * *mk;
        }
        self.p = (1.0 - gain) * pp;
        (m, s_cov)
    }
}

/// The filters of every axis for `K` signatures and the Gram matrix of their innovation
/// means, `G_ab = Σ_k m_a,kᵀ S_k⁻¹ m_b,k`.
#[derive(Debug, Clone)]
struct Matched<const K: usize> {
    truth: RateParams,
    axes: [RateAxis<K>; 3],
    vertical: Option<VerticalAxis<K>>,
    gram: [[f64; K]; K],
}

impl<const K: usize> Matched<K> {
    fn new(truth: RateParams, noise: OracleNoise) -> Self {
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
        let vertical = noise
            .az_sd
            .map(|sd| VerticalAxis::new(a, noise.gust_sd[3], sd));
        Self {
            truth,
            axes,
            vertical,
            gram: [[0.0; K]; K],
        }
    }

    /// One step: `deviation[k][j]` is signature k's effective-output deviation of actuator j.
    fn step(&mut self, deviation: &[&[f64]; K]) {
        let add = |gram: &mut [[f64; K]; K], m: [f64; K], s_cov: f64| {
            for a in 0..K {
                for b in 0..K {
                    gram[a][b] += m[a] * m[b] / s_cov;
                }
            }
        };
        for (i, axis) in self.axes.iter_mut().enumerate() {
            let s = std::array::from_fn(|k| {
                (self.truth.effectiveness.iter())
                    .zip(deviation[k])
                    .map(|(b, d)| b[i] * d)
                    .sum()
            });
            let (m, s_cov) = axis.step(&s);
            add(&mut self.gram, m, s_cov);
        }
        if let Some(v) = self.vertical.as_mut() {
            let direct = std::array::from_fn(|k| {
                (self.truth.vertical.iter())
                    .zip(deviation[k])
                    .map(|(b, d)| b * d)
                    .sum()
            });
            let (m, s_cov) = v.step(&direct);
            add(&mut self.gram, m, s_cov);
        }
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
pub struct Oracle(Matched<1>);

impl Oracle {
    pub fn new(truth: RateParams, noise: OracleNoise) -> Self {
        Self(Matched::new(truth, noise))
    }

    /// One simulator step: `deviation[j]` is actuator j's true `(gamma - 1) u + delta` over it
    /// (0 for a healthy one).
    pub fn step(&mut self, deviation: &[f64]) {
        self.0.step(&[deviation]);
    }

    /// The non-centrality so far.
    pub fn lambda(&self) -> f64 {
        self.0.gram[0][0]
    }
}

/// How well the best classifier there is could tell one actuator's fault from a change of
/// the other kinds on the same actuator from the same onset: the oracle above, for the fault's
/// signature `s` and the two one-parameter alternatives, a gain change (`(γ' - 1) u` along the
/// flown command) and an offset (`δ'`). The alternative of a kind closest to the fault, in the
/// matched filter's metric, leaves `lambda_sep = G_ss - G_sa² / G_aa` of it: the non-centrality
/// of the test between the fault and that alternative (its best size known). A class the
/// data separate by less than [`DETECTABLE_LAMBDA`] is one no monitor can be asked to tell.
#[derive(Debug, Clone)]
pub struct KindOracle {
    matched: Matched<3>,
    actuator: usize,
    deviation: Vec<f64>,
    gain: Vec<f64>,
    offset: Vec<f64>,
}

/// The kinds a fault can be told from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Alternative {
    Gain,
    Offset,
}

impl KindOracle {
    /// For actuator `actuator` of `actuators`.
    pub fn new(truth: RateParams, noise: OracleNoise, actuator: usize, actuators: usize) -> Self {
        Self {
            matched: Matched::new(truth, noise),
            actuator,
            deviation: vec![0.0; actuators],
            gain: vec![0.0; actuators],
            offset: vec![0.0; actuators],
        }
    }

    /// One simulator step: the actuator's true deviation and its command, and whether the
    /// fault has begun (the alternatives start with it).
    pub fn step(&mut self, deviation: f64, command: f64, begun: bool) {
        let j = self.actuator;
        self.deviation[j] = deviation;
        self.gain[j] = if begun { command } else { 0.0 };
        self.offset[j] = if begun { 1.0 } else { 0.0 };
        self.matched
            .step(&[&self.deviation, &self.gain, &self.offset]);
    }

    /// What of the fault's non-centrality the best alternative of `kind` leaves.
    pub fn lambda_from(&self, kind: Alternative) -> f64 {
        let g = &self.matched.gram;
        let a = match kind {
            Alternative::Gain => 1,
            Alternative::Offset => 2,
        };
        if g[a][a] > 0.0 {
            (g[0][0] - g[0][a] * g[0][a] / g[a][a]).max(0.0)
        } else {
            g[0][0]
        }
    }
}

/// Signatures the isolation oracle follows: the fault, and a gain change and an offset of
/// every other actuator.
const ISOLATION_K: usize = 1 + 2 * (crate::model::MAX_ACTUATORS - 1);

/// How well the best detector there is could tell which actuator is faulty: the oracle above,
/// for the fault's signature and, for every other actuator, any change of its gain and offset
/// from the same onset (two parameters, their best sizes known). The closest other actuator
/// leaves `lambda_iso = G_ss - gᵀ A⁻¹ g` of the fault's non-centrality (`A` the Gram matrix of
/// that actuator's two alternatives, `g` their products with the fault): where it is under
/// [`DETECTABLE_LAMBDA`], no monitor can be asked to name the actuator (a hexacopter's motor
/// giving more thrust against its opposite giving less, told apart by a_z alone).
#[derive(Debug, Clone)]
pub struct IsolationOracle {
    matched: Matched<ISOLATION_K>,
    actuator: usize,
    signals: [Vec<f64>; ISOLATION_K],
}

impl IsolationOracle {
    /// For actuator `actuator` of `actuators` (at most `MAX_ACTUATORS`).
    pub fn new(truth: RateParams, noise: OracleNoise, actuator: usize, actuators: usize) -> Self {
        Self {
            matched: Matched::new(truth, noise),
            actuator,
            signals: std::array::from_fn(|_| vec![0.0; actuators]),
        }
    }

    /// Signature slot of other actuator `k`'s gain (its offset is the next one).
    fn slot(&self, k: usize) -> usize {
        1 + 2 * if k < self.actuator { k } else { k - 1 }
    }

    /// One simulator step: the faulty actuator's true deviation, every actuator's command, and
    /// whether the fault has begun (the alternatives start with it).
    pub fn step(&mut self, deviation: f64, commands: &[f64], begun: bool) {
        let j = self.actuator;
        self.signals[0][j] = deviation;
        for (k, &u) in commands.iter().enumerate().take(self.signals[0].len()) {
            if k == j {
                continue;
            }
            let a = self.slot(k);
            self.signals[a][k] = if begun { u } else { 0.0 };
            self.signals[a + 1][k] = if begun { 1.0 } else { 0.0 };
        }
        let refs: [&[f64]; ISOLATION_K] = std::array::from_fn(|i| self.signals[i].as_slice());
        self.matched.step(&refs);
    }

    /// What of the fault's non-centrality the closest other actuator's change leaves.
    pub fn lambda(&self) -> f64 {
        let g = &self.matched.gram;
        let l = self.signals[0].len();
        let mut least = g[0][0];
        for k in (0..l).filter(|&k| k != self.actuator) {
            let (a, b) = (self.slot(k), self.slot(k) + 1);
            let (aa, bb, ab) = (g[a][a], g[b][b], g[a][b]);
            let (sa, sb) = (g[0][a], g[0][b]);
            let det = aa * bb - ab * ab;
            let explained = if det > 1e-12 * aa * bb {
                (bb * sa * sa - 2.0 * ab * sa * sb + aa * sb * sb) / det
            } else if aa >= bb && aa > 0.0 {
                sa * sa / aa
            } else if bb > 0.0 {
                sb * sb / bb
            } else {
                0.0
            };
            least = least.min((g[0][0] - explained).max(0.0));
        }
        least
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two actuators on three rate axes, in the built-in weather's gusts.
    fn two_actuators() -> (RateParams, OracleNoise) {
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
        (truth, noise)
    }

    /// The recursion against a plain Kalman filter run on the noise-free response to the
    /// fault: with no noise and no gust the filter's innovations are exactly their means
    /// under the fault, so `Σ innovation² / S` must equal the oracle's `lambda`.
    #[test]
    fn lambda_matches_a_kalman_filter_run_on_noise_free_data() {
        let (truth, noise) = two_actuators();
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
    /// The class oracle: a fault of one kind leaves nothing against an alternative of its own
    /// kind; a gain change is an offset while the command stands still, and tells itself from
    /// one as much as the command moves; the sum it leaves is at most the fault's lambda.
    #[test]
    fn kind_separation_is_what_the_command_moves() {
        let (truth, noise) = two_actuators();
        // Actuator 1 from step 50, with a command swinging by `amp` about 0.5.
        let run = |gain: bool, amp: f64| {
            let mut o = KindOracle::new(truth.clone(), noise, 1, 2);
            for k in 0..300 {
                let u = 0.5 + amp * (k as f64 * 0.1).sin();
                let begun = k >= 50;
                let deviation = match (begun, gain) {
                    (false, _) => 0.0,
                    (true, true) => -0.3 * u,
                    (true, false) => -0.15,
                };
                o.step(deviation, u, begun);
            }
            o
        };
        let offset = run(false, 0.1);
        assert!(
            offset.lambda_from(Alternative::Offset) < 1e-6 * offset.lambda_from(Alternative::Gain)
        );
        let gain = run(true, 0.1);
        assert!(gain.lambda_from(Alternative::Gain) < 1e-6 * gain.lambda_from(Alternative::Offset));
        let still = run(true, 0.0);
        assert!(
            still.lambda_from(Alternative::Offset) < 1e-9,
            "{}",
            still.lambda_from(Alternative::Offset)
        );
        let (small, big) = (run(true, 0.05), run(true, 0.1));
        let ratio = big.lambda_from(Alternative::Offset) / small.lambda_from(Alternative::Offset);
        assert!((3.0..5.0).contains(&ratio), "{ratio}");
        // The fault's own lambda is the detection oracle's.
        let mut detect = Oracle::new(truth.clone(), noise);
        for k in 0..300 {
            let u = 0.5 + 0.1 * (k as f64 * 0.1).sin();
            detect.step(&[0.0, if k >= 50 { -0.3 * u } else { 0.0 }]);
        }
        let total = gain.matched.gram[0][0];
        assert!((total - detect.lambda()).abs() < 1e-9 * total);
        assert!(gain.lambda_from(Alternative::Offset) <= total);
    }

    /// The isolation oracle: an actuator whose effect another's repeats (opposite sign) cannot
    /// be told from it; one whose effect no other shares is told apart as well as it is
    /// detected; a third actuator sharing part of the effect leaves the part it does not share.
    #[test]
    fn isolation_is_what_no_other_actuator_can_explain() {
        let (mut truth, noise) = two_actuators();
        let run = |truth: &RateParams, l: usize, phase: f64| {
            let mut iso = IsolationOracle::new(truth.clone(), noise, 1, l);
            let mut detect = Oracle::new(truth.clone(), noise);
            for k in 0..300 {
                let begun = k >= 50;
                let u: Vec<f64> = (0..l)
                    .map(|j| 0.5 + 0.1 * (k as f64 * 0.1 + phase * j as f64).sin())
                    .collect();
                let deviation = if begun { -0.3 * u[1] } else { 0.0 };
                iso.step(deviation, &u, begun);
                let mut dev = vec![0.0; l];
                dev[1] = deviation;
                detect.step(&dev);
            }
            (iso.lambda(), detect.lambda())
        };
        // Actuators 0 and 1 on separate axes: nothing of 1's fault is 0's.
        truth.effectiveness = vec![[10.0, 0.0, 0.0], [0.0, 20.0, -5.0]];
        let (iso, lambda) = run(&truth, 2, 1.0);
        assert!(
            lambda > 100.0 && (iso - lambda).abs() < 1e-9 * lambda,
            "{iso} {lambda}"
        );
        // Actuator 0 the mirror of 1 with the same command: its gain repeats 1's gain change
        // exactly; with another command, only the part along its command and a constant.
        truth.effectiveness = vec![[0.0, -20.0, 5.0], [0.0, 20.0, -5.0]];
        let (iso, lambda) = run(&truth, 2, 0.0);
        assert!(iso < 1e-9 * lambda, "{iso} {lambda}");
        let (iso, lambda) = run(&truth, 2, 1.0);
        assert!(iso > 1e-3 * lambda && iso < 0.5 * lambda, "{iso} {lambda}");
        // A third actuator sharing 1's pitch but not its yaw: what is left is yaw's part.
        truth.effectiveness = vec![[10.0, 0.0, 0.0], [0.0, 20.0, -5.0], [0.0, 20.0, 0.0]];
        let (iso, lambda) = run(&truth, 3, 1.0);
        assert!(iso > 0.0 && iso < 0.5 * lambda, "{iso} {lambda}");
    }
}
