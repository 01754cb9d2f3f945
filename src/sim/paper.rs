//! The paper's simulation (its Section 5): the helicopter in forward flight under an LQR, with
//! the actuator fault module and process / measurement noise schedules.
//!
//! Rates follow exactly the estimator's discrete model ([`PaperHeli`]), plus process noise; the
//! slow states follow `u' = X_u (u - u0) - g θ`, `φ' = p`, `θ' = q` (one Euler step), which is
//! what makes the LQR give up some speed when the elevator servo loses effectiveness (paper Fig. 6).

use super::fault::{Fault, health_of};
use super::lqr::dlqr;
use super::noise::NoiseSchedule;
use super::rng::Rng;
use crate::model::{Model, PaperHeli, PaperHeliParams};
use nalgebra::{SMatrix, SVector};

/// Input names of the paper helicopter, in the order of `u`.
pub const ACTUATORS: [&str; 4] = ["collective", "lat", "lon", "tail"];
/// The actuator whose AHCs the paper estimates.
pub const ESTIMATED: usize = 2;

const GRAVITY: f64 = 9.81;
/// Speed damping X_u (1/s): order of magnitude for a small helicopter.
const X_U: f64 = -0.05;

/// Pitch-attitude reference dither (sum of sines) for excitation.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Dither {
    pub amplitude_rad: f64,
    pub freqs_hz: Vec<f64>,
}

impl Dither {
    pub fn at(&self, t: f64) -> f64 {
        if self.freqs_hz.is_empty() {
            return 0.0;
        }
        let n = self.freqs_hz.len() as f64;
        self.freqs_hz
            .iter()
            .map(|f| (std::f64::consts::TAU * f * t).sin())
            .sum::<f64>()
            * self.amplitude_rad
            / n.sqrt()
    }
}

#[derive(Debug, Clone)]
pub struct PaperSimConfig {
    pub dt: f64,
    pub forward_speed: f64,
    pub process_noise: NoiseSchedule,
    pub measurement_noise: NoiseSchedule,
    pub faults: Vec<Fault>,
    pub dither: Option<Dither>,
    pub seed: u64,
}

/// One sample the estimators see, plus the truth.
#[derive(Debug, Clone, Copy)]
pub struct PaperSample {
    /// Time (s) of the measurement.
    pub t: f64,
    /// Commanded inputs [collective, lat, lon, tail] (rad) applied over the step.
    pub u: [f64; 4],
    /// Measured rates [p, q, r] (rad/s) at the end of the step.
    pub y: SVector<f64, 3>,
    /// True (gamma, delta) of each actuator during the step.
    pub truth: [(f64, f64); 4],
    /// Forward speed (m/s) at the end of the step.
    pub speed: f64,
}

/// Trim inputs at a forward speed (rad): collective for hover thrust, forward (nose-down,
/// negative) cyclic growing with speed against the nose-up trim moment, tail pitch for torque.
/// Order-of-magnitude values, stated as such.
pub fn trim_inputs(forward_speed: f64) -> [f64; 4] {
    [0.1, 0.0, -0.005 * forward_speed, 0.05]
}

pub fn paper_params(forward_speed: f64) -> PaperHeliParams {
    PaperHeliParams::xcell60().trimmed_for(&trim_inputs(forward_speed))
}

pub struct PaperSim {
    cfg: PaperSimConfig,
    pub model: PaperHeli,
    gain: SMatrix<f64, 3, 6>,
    u_trim: [f64; 4],
    rng: Rng,
    /// [u, p, q, r, φ, θ]
    state: [f64; 6],
    k: u64,
}

impl PaperSim {
    pub fn new(cfg: PaperSimConfig) -> Result<Self, String> {
        let params = paper_params(cfg.forward_speed);
        let model = PaperHeli::new(params, cfg.dt);
        let gain = design_lqr(&model, cfg.dt).ok_or("LQR design did not converge")?;
        let u_trim = trim_inputs(cfg.forward_speed);
        let rng = Rng::new(cfg.seed);
        let state = [cfg.forward_speed, 0.0, 0.0, 0.0, 0.0, 0.0];
        Ok(Self {
            cfg,
            model,
            gain,
            u_trim,
            rng,
            state,
            k: 0,
        })
    }

    pub fn time(&self) -> f64 {
        self.k as f64 * self.cfg.dt
    }

    pub fn step(&mut self) -> PaperSample {
        let t = self.time();
        let dt = self.cfg.dt;
        let s = self.state;
        let theta_ref = self.cfg.dither.as_ref().map_or(0.0, |d| d.at(t));
        let err = SVector::<f64, 6>::from([
            s[0] - self.cfg.forward_speed,
            s[1],
            s[2],
            s[3],
            s[4],
            s[5] - theta_ref,
        ]);
        let du = -(self.gain * err);
        let u = [
            self.u_trim[0],
            self.u_trim[1] + du[0],
            self.u_trim[2] + du[1],
            self.u_trim[3] + du[2],
        ];
        let mut truth = [(1.0, 0.0); 4];
        let mut u_eff = [0.0; 4];
        for i in 0..4 {
            truth[i] = health_of(&self.cfg.faults, ACTUATORS[i], t);
            u_eff[i] = truth[i].0 * u[i] + truth[i].1;
        }
        // Same discrete map as the estimator, with the faulted inputs applied as healthy ones.
        let z = SVector::<f64, 5>::new(s[1], s[2], s[3], 1.0, 0.0);
        let next = self.model.f(&z, &u_eff);
        let mut rates = [next[0], next[1], next[2]];
        for r in rates.iter_mut() {
            *r += self.cfg.process_noise.sample(&mut self.rng, t);
        }
        let speed = s[0] + dt * (X_U * (s[0] - self.cfg.forward_speed) - GRAVITY * s[5]);
        self.state = [
            speed,
            rates[0],
            rates[1],
            rates[2],
            s[4] + dt * s[1],
            s[5] + dt * s[2],
        ];
        self.k += 1;
        let t_meas = self.time();
        let mut y = SVector::<f64, 3>::from(rates);
        for v in y.iter_mut() {
            *v += self.cfg.measurement_noise.sample(&mut self.rng, t_meas);
        }
        PaperSample {
            t: t_meas,
            u,
            y,
            truth,
            speed,
        }
    }
}

/// LQR on [u, p, q, r, φ, θ] with inputs [lat, lon, tail], Bryson weights
/// (1 m/s, 1 rad/s, 0.2 rad of attitude, 0.1 rad of cyclic / tail pitch).
fn design_lqr(model: &PaperHeli, dt: f64) -> Option<SMatrix<f64, 3, 6>> {
    let p = model.params;
    let (phi, zoh) = (model.phi(), model.zoh());
    #[rustfmt::skip]
    let a = SMatrix::<f64, 6, 6>::from_row_slice(&[
        1.0 + dt * X_U, 0.0,    0.0,    0.0,    0.0, -GRAVITY * dt,
        0.0,            phi[0], 0.0,    0.0,    0.0, 0.0,
        0.0,            0.0,    phi[1], 0.0,    0.0, 0.0,
        0.0,            0.0,    0.0,    phi[2], 0.0, 0.0,
        0.0,            dt,     0.0,    0.0,    1.0, 0.0,
        0.0,            0.0,    dt,     0.0,    0.0, 1.0,
    ]);
    #[rustfmt::skip]
    let b = SMatrix::<f64, 6, 3>::from_row_slice(&[
        0.0,                0.0,                0.0,
        zoh[0] * p.l_lat,   0.0,                0.0,
        0.0,                zoh[1] * p.m_lon,   0.0,
        0.0,                0.0,                zoh[2] * p.n_ped,
        0.0,                0.0,                0.0,
        0.0,                0.0,                0.0,
    ]);
    let q = SMatrix::<f64, 6, 6>::from_diagonal(&SVector::<f64, 6>::from([
        1.0, 1.0, 1.0, 1.0, 25.0, 25.0,
    ]));
    let r = SMatrix::<f64, 3, 3>::identity() * 100.0;
    dlqr(&a, &b, &q, &r)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::noise::NoiseKind;

    fn cfg(faults: Vec<Fault>) -> PaperSimConfig {
        PaperSimConfig {
            dt: 0.02,
            forward_speed: 10.0,
            process_noise: NoiseSchedule::constant(NoiseKind::Gaussian, 1e-4),
            measurement_noise: NoiseSchedule::constant(NoiseKind::Gaussian, 3e-6),
            faults,
            dither: None,
            seed: 1,
        }
    }

    #[test]
    fn healthy_flight_holds_speed_and_fault_costs_speed() {
        let mut sim = PaperSim::new(cfg(vec![])).unwrap();
        let mut last = None;
        for _ in 0..2000 {
            last = Some(sim.step());
        }
        let healthy = last.unwrap();
        assert!(
            (healthy.speed - 10.0).abs() < 0.5,
            "speed {}",
            healthy.speed
        );
        let fault: Fault = toml::from_str("actuator='lon'\nt=10.0\ngamma=0.5").unwrap();
        let mut sim = PaperSim::new(cfg(vec![fault])).unwrap();
        let mut last = None;
        for _ in 0..2000 {
            last = Some(sim.step());
        }
        let faulty = last.unwrap();
        assert_eq!(faulty.truth[ESTIMATED], (0.5, 0.0));
        // The LQR only partly compensates (paper Fig. 6: about 8 m/s).
        assert!(
            faulty.speed < healthy.speed - 0.5,
            "speed after fault {}",
            faulty.speed
        );
        assert!(faulty.speed > 5.0, "speed after fault {}", faulty.speed);
    }
}
