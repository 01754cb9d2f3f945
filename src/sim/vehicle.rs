//! Vehicle simulators for any profile (quad, hexa, H3-120 helicopter, plane): the
//! rate-effectiveness dynamics with the *simulator's* parameters (the profile's, scaled by the
//! scenario's model mismatch), a cascaded attitude → rate controller with integrators and a
//! mixer like an autopilot's (so a fault shows up as the controller shifting its commands to hide
//! it), a vertical-speed hold on the thrust direction, attitude-reference dither and manoeuvres,
//! wind gusts (a disturbance that is not a fault), actuator faults and sensor noise.
//!
//! Pure: no I/O. The rates are advanced with the zero-order hold of the diagonal damping (the
//! discretisation the filters use), the gust torque held over the step.

// Index loops mirror the matrix maths (rows i, actuators j) and read best that way.
#![allow(clippy::needless_range_loop)]

use super::fault::{Fault, health_of};
use super::rng::Rng;
use crate::model::{MAX_ACTUATORS, RateParams};
use crate::telemetry::{Profile, VehicleKind};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

const GRAVITY: f64 = 9.81;

/// Wind gusts: a first-order (Ornstein-Uhlenbeck) angular and vertical acceleration per axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gusts {
    /// Standard deviation of the angular acceleration [roll, pitch, yaw] (rad/s²).
    pub angular: [f64; 3],
    /// Standard deviation of the vertical acceleration (m/s²).
    #[serde(default)]
    pub vertical: f64,
    /// Correlation time (s).
    pub tau_s: f64,
}

/// Simulator parameters scaled against the monitor's profile.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelMismatch {
    #[serde(default = "one")]
    pub damping: f64,
    #[serde(default = "one")]
    pub effectiveness: f64,
}

fn one() -> f64 {
    1.0
}

/// Attitude-reference dither (sum of sines) on roll, pitch and yaw (yaw as a rate reference).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AttitudeDither {
    /// Amplitude per axis [roll (rad), pitch (rad), yaw rate (rad/s)].
    pub amplitude: [f64; 3],
    /// Frequencies (Hz); each axis uses them scaled by 1, 1.37, 1.83 so the axes decorrelate.
    pub freqs_hz: Vec<f64>,
}

impl AttitudeDither {
    pub fn at(&self, t: f64) -> [f64; 3] {
        let mut out = [0.0; 3];
        if self.freqs_hz.is_empty() {
            return out;
        }
        let norm = (self.freqs_hz.len() as f64).sqrt();
        for (axis, scale) in [1.0, 1.37, 1.83].iter().enumerate() {
            let s: f64 = self
                .freqs_hz
                .iter()
                .enumerate()
                .map(|(i, f)| (std::f64::consts::TAU * f * scale * t + 0.7 * i as f64).sin())
                .sum();
            out[axis] = self.amplitude[axis] * s / norm;
        }
        out
    }
}

/// A manoeuvre: an attitude (and yaw-rate) reference held from `t` for `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manoeuvre {
    pub t: f64,
    pub duration_s: f64,
    #[serde(default)]
    pub roll_deg: f64,
    #[serde(default)]
    pub pitch_deg: f64,
    #[serde(default)]
    pub yaw_rate_dps: f64,
}

#[derive(Debug, Clone)]
pub struct VehicleSimConfig {
    pub profile: Profile,
    pub dt: f64,
    pub mismatch: ModelMismatch,
    pub gusts: Option<Gusts>,
    pub dither: Option<AttitudeDither>,
    pub manoeuvres: Vec<Manoeuvre>,
    pub faults: Vec<Fault>,
    /// Sensor noise standard deviations (gyro rad/s, a_z m/s²).
    pub gyro_noise: f64,
    pub az_noise: f64,
    /// Gusts' driving noise and sensor noise uniform with the stated standard deviations
    /// (bounded: `√3 σ`) instead of Gaussian.
    pub bounded_noise: bool,
    pub seed: u64,
}

impl VehicleSimConfig {
    /// A calm, exact-model flight with the standard attitude dither (0.05/0.05/0.1 rad at
    /// 0.3/0.7/1.1 Hz) and typical sensor noise: what benchmarks and calibration checks fly.
    pub fn calm(profile: Profile, dt: f64, seed: u64) -> Self {
        Self {
            profile,
            dt,
            mismatch: ModelMismatch {
                damping: 1.0,
                effectiveness: 1.0,
            },
            gusts: None,
            dither: Some(AttitudeDither {
                amplitude: [0.05, 0.05, 0.1],
                freqs_hz: vec![0.3, 0.7, 1.1],
            }),
            manoeuvres: vec![],
            faults: vec![],
            gyro_noise: 0.003,
            az_noise: 0.3,
            bounded_noise: false,
            seed,
        }
    }
}

/// One telemetry sample plus the truth.
#[derive(Debug, Clone, Copy)]
pub struct VehicleSample {
    pub t: f64,
    /// Commanded (normalised) outputs applied over the step.
    pub u: [f64; MAX_ACTUATORS],
    /// Measured [p, q, r, a_z] at the end of the step (a_z only when the profile measures it).
    pub y: [f64; 4],
    /// True gamma and delta per actuator.
    pub gamma: [f64; MAX_ACTUATORS],
    pub delta: [f64; MAX_ACTUATORS],
    /// Attitude [roll, pitch, yaw] (rad) and vertical speed (m/s, down positive).
    pub attitude: [f64; 3],
    pub climb_down: f64,
}

/// The simulated vehicle with its autopilot-like controller.
pub struct VehicleSim {
    cfg: VehicleSimConfig,
    l: usize,
    rows: usize,
    truth: RateParams,
    nominal: RateParams,
    /// Nominal mixer: `u = u_pref + mix (demand - G u_pref)`.
    mix: DMatrix<f64>,
    u_pref: Vec<f64>,
    g_full: DMatrix<f64>,
    rng: Rng,
    omega: [f64; 3],
    /// The last measured rates: what the autopilot's rate loop acts on (its gyro), as the
    /// telemetry reports them.
    measured_rates: [f64; 3],
    attitude: [f64; 3],
    w: f64,
    rate_integral: [f64; 3],
    w_integral: f64,
    gust: [f64; 4],
    k: u64,
}

/// Attitude P, rate PI gains (1/s, 1/s, 1/s²) and the vertical-speed loop.
const ATT_P: [f64; 3] = [4.5, 4.5, 4.5];
const RATE_P: [f64; 3] = [20.0, 20.0, 8.0];
const RATE_I: [f64; 3] = [60.0, 60.0, 10.0];
const W_P: f64 = 2.0;
const W_I: f64 = 1.0;
const MAX_RATE: f64 = 3.0;

impl VehicleSim {
    pub fn new(cfg: VehicleSimConfig) -> Result<Self, String> {
        let nominal = cfg.profile.rate_params();
        let truth = nominal.scaled(cfg.mismatch.damping, cfg.mismatch.effectiveness);
        let l = nominal.actuators();
        let rows = cfg.profile.measurements();
        let mut g_full = DMatrix::<f64>::zeros(rows, l);
        for j in 0..l {
            for i in 0..3 {
                g_full[(i, j)] = nominal.effectiveness[j][i];
            }
            if rows == 4 {
                g_full[(3, j)] = nominal.vertical[j];
            }
        }
        let mix = g_full
            .clone()
            .pseudo_inverse(1e-9)
            .map_err(|e| format!("mixer: {e}"))?;
        let u_pref = (0..l)
            .map(|j| {
                if cfg.profile.actuators[j].role.is_range() {
                    0.5
                } else {
                    0.0
                }
            })
            .collect();
        if !(cfg.dt.is_finite() && cfg.dt > 0.0) {
            return Err("dt must be positive".into());
        }
        let rng = Rng::new(cfg.seed);
        Ok(Self {
            l,
            rows,
            truth,
            nominal,
            mix,
            u_pref,
            g_full,
            rng,
            omega: [0.0; 3],
            measured_rates: [0.0; 3],
            attitude: [0.0; 3],
            w: 0.0,
            rate_integral: [0.0; 3],
            w_integral: 0.0,
            gust: [0.0; 4],
            k: 0,
            cfg,
        })
    }

    pub fn actuators(&self) -> usize {
        self.l
    }

    pub fn time(&self) -> f64 {
        self.k as f64 * self.cfg.dt
    }

    fn reference(&self, t: f64) -> [f64; 3] {
        let mut r = self.cfg.dither.as_ref().map_or([0.0; 3], |d| d.at(t));
        for m in &self.cfg.manoeuvres {
            if t >= m.t && t < m.t + m.duration_s {
                r[0] += m.roll_deg.to_radians();
                r[1] += m.pitch_deg.to_radians();
                r[2] += m.yaw_rate_dps.to_radians();
            }
        }
        r
    }

    /// The autopilot: attitude P → rate PI on the measured rates (its gyro; the attitude is
    /// its estimator's, taken as true) with the nominal damping and trim fed forward →
    /// demanded accelerations → mixer → saturated commands.
    fn control(&mut self, t: f64) -> [f64; MAX_ACTUATORS] {
        let dt = self.cfg.dt;
        let r = self.reference(t);
        let mut rate_target = [0.0; 3];
        for i in 0..2 {
            rate_target[i] = (ATT_P[i] * (r[i] - self.attitude[i])).clamp(-MAX_RATE, MAX_RATE);
        }
        rate_target[2] = r[2];
        let mut demand = vec![0.0; self.rows];
        for i in 0..3 {
            let rate = self.measured_rates[i];
            let e = rate_target[i] - rate;
            self.rate_integral[i] = (self.rate_integral[i] + e * dt).clamp(-2.0, 2.0);
            demand[i] =
                RATE_P[i] * e + RATE_I[i] * self.rate_integral[i] + self.nominal.damping[i] * rate
                    - self.nominal.offset[i];
        }
        if self.rows == 4 {
            // Hold vertical speed at zero: a_z demand (down positive w, specific force up negative).
            self.w_integral = (self.w_integral + self.w * dt).clamp(-5.0, 5.0);
            let tilt = (self.attitude[0].cos() * self.attitude[1].cos()).max(0.5);
            demand[3] = (-GRAVITY - W_P * self.w - W_I * self.w_integral) / tilt
                - self.nominal.vertical_offset;
        }
        let mut g_pref = vec![0.0; self.rows];
        for i in 0..self.rows {
            for j in 0..self.l {
                g_pref[i] += self.g_full[(i, j)] * self.u_pref[j];
            }
        }
        let mut u = [0.0; MAX_ACTUATORS];
        for j in 0..self.l {
            let mut v = self.u_pref[j];
            for i in 0..self.rows {
                v += self.mix[(j, i)] * (demand[i] - g_pref[i]);
            }
            let (lo, hi) = self.cfg.profile.command_range(j);
            u[j] = v.clamp(lo, hi);
        }
        u
    }

    /// One draw of unit standard deviation: Gaussian, or uniform on `±√3`.
    fn noise(&mut self) -> f64 {
        if self.cfg.bounded_noise {
            self.rng.uniform(3f64.sqrt())
        } else {
            self.rng.normal()
        }
    }

    pub fn step(&mut self) -> VehicleSample {
        let t = self.time();
        let dt = self.cfg.dt;
        let u = self.control(t);
        let mut gamma = [1.0; MAX_ACTUATORS];
        let mut delta = [0.0; MAX_ACTUATORS];
        let mut eff = [0.0; MAX_ACTUATORS];
        for j in 0..self.l {
            let (g, d) = health_of(&self.cfg.faults, &self.cfg.profile.actuators[j].name, t);
            gamma[j] = g;
            delta[j] = d;
            eff[j] = g * u[j] + d;
        }
        // Gusts: OU processes, held over the step.
        if let Some((angular, vertical, tau_s)) = self
            .cfg
            .gusts
            .as_ref()
            .map(|g| (g.angular, g.vertical, g.tau_s))
        {
            let a = (-dt / tau_s.max(dt)).exp();
            let b = (1.0 - a * a).sqrt();
            for i in 0..3 {
                self.gust[i] = a * self.gust[i] + b * angular[i] * self.noise();
            }
            self.gust[3] = a * self.gust[3] + b * vertical * self.noise();
        }
        let p = &self.truth;
        let mut next = [0.0; 3];
        for i in 0..3 {
            let mut acc = p.offset[i] + self.gust[i];
            for j in 0..self.l {
                acc += p.effectiveness[j][i] * eff[j];
            }
            let d = p.damping[i];
            let decay = (-d * dt).exp();
            let hold = if d * dt > 1e-12 {
                -(-d * dt).exp_m1() / d
            } else {
                dt
            };
            next[i] = decay * self.omega[i] + hold * acc;
        }
        let mut az = p.vertical_offset + self.gust[3];
        for j in 0..self.l {
            az += p.vertical.get(j).copied().unwrap_or(0.0) * eff[j];
        }
        // Trapezoidal attitude; vertical speed from the specific force along the tilted thrust.
        for i in 0..3 {
            self.attitude[i] += 0.5 * dt * (self.omega[i] + next[i]);
        }
        if self.rows == 4 {
            let tilt = self.attitude[0].cos() * self.attitude[1].cos();
            self.w += dt * (az * tilt + GRAVITY);
        }
        self.omega = next;
        self.k += 1;
        let mut y = [0.0; 4];
        for i in 0..3 {
            y[i] = next[i] + self.cfg.gyro_noise * self.noise();
            self.measured_rates[i] = y[i];
        }
        if self.rows == 4 {
            y[3] = az + self.cfg.az_noise * self.noise();
        }
        VehicleSample {
            t: self.time(),
            u,
            y,
            gamma,
            delta,
            attitude: self.attitude,
            climb_down: self.w,
        }
    }

    pub fn vehicle(&self) -> VehicleKind {
        self.cfg.profile.vehicle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(profile: &str, faults: Vec<Fault>) -> VehicleSimConfig {
        let profile = Profile::resolve(profile).unwrap();
        VehicleSimConfig {
            dt: 1.0 / profile.rate_hz,
            profile,
            mismatch: ModelMismatch {
                damping: 1.1,
                effectiveness: 0.9,
            },
            gusts: Some(Gusts {
                angular: [1.0, 1.0, 0.3],
                vertical: 0.5,
                tau_s: 1.0,
            }),
            dither: Some(AttitudeDither {
                amplitude: [0.03, 0.03, 0.05],
                freqs_hz: vec![0.3, 0.7, 1.1],
            }),
            manoeuvres: vec![],
            faults,
            gyro_noise: 0.003,
            az_noise: 0.3,
            bounded_noise: false,
            seed: 3,
        }
    }

    /// Every vehicle holds its attitude under gusts and mismatch, and after a gain fault the
    /// controller hides it by moving the faulty actuator's command (as on a real vehicle).
    #[test]
    fn controller_holds_attitude_and_compensates_a_fault() {
        for (profile, actuator) in [
            ("quad-x", "motor1"),
            ("hexa-x", "motor3"),
            ("heli-h3-120", "swash2"),
            ("plane", "elevator"),
        ] {
            let fault: Fault =
                toml::from_str(&format!("actuator='{actuator}'\nt=20.0\ngamma=0.6")).unwrap();
            let mut sim = VehicleSim::new(cfg(profile, vec![fault])).unwrap();
            let j = sim.cfg.profile.actuator_index(actuator).unwrap();
            let (mut before, mut after, mut worst) = (0.0, 0.0, 0.0f64);
            for k in 0..2000 {
                let s = sim.step();
                worst = worst.max(s.attitude[0].abs()).max(s.attitude[1].abs());
                if (500..1000).contains(&k) {
                    before += s.u[j] / 500.0;
                }
                if k >= 1500 {
                    after += s.u[j] / 500.0;
                }
                assert!(s.y.iter().all(|v| v.is_finite()));
            }
            assert!(worst < 0.3, "{profile}: attitude excursion {worst}");
            // The command moves away from zero to make up the lost gain.
            assert!(
                after.abs() > before.abs() * 1.2 || (after - before).abs() > 0.02,
                "{profile}: command before {before}, after {after}"
            );
        }
    }
}
