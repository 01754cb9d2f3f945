//! What the data of a vehicle fault scenario can carry: the smallest gamma error any
//! estimator can reach, from an oracle Kalman filter that knows what the monitor does not.
//!
//! The oracle knows the simulator's true model (`D`, `G` with the scenario's mismatch), the
//! gust process (first-order, its time constant and size) and the sensor noise, the onset of
//! the fault and which actuator it hits. It estimates every actuator's `gamma` and `delta` as
//! constants from t = 0 with a flat prior, and restarts the faulty actuator's pair (flat
//! again) at the onset. The model is linear and Gaussian, so this Kalman filter is the
//! efficient estimator: its covariance is the Cramér-Rao bound, and its actual errors (shown
//! next to it) check that the oracle is right.
//!
//! The monitor's filters know none of this (a nominal model, gusts as white noise, no onset),
//! so their errors can only be larger: where the oracle's sigma is near the tolerance, no
//! filter meets it. One caveat: the simulator's controller flies on the true state, so its
//! commands say a little about the noise-free rates, which the oracle (like the monitor) takes
//! as given inputs and does not invert. It is worth little: with gyros 300 times quieter the
//! hexa motor 3 sigma at onset + 5 s goes from 0.046 to 0.044.
//!
//! Two switches take one piece of knowledge away at a time, to see what each is worth:
//! `--nominal-model` uses the profile's `D` and `G` (what the monitor has), `--white-gusts`
//! drops the gust states and counts each step's gust as white rate noise of the same size
//! (what the monitor's filters assume). With either, the filter is no longer the efficient one
//! and its sigma is no longer a bound: read the actual error then. `--known-healthy` adds one:
//! every actuator's healthy gamma and delta exactly (only the faulty pair, from the onset, is
//! unknown), the best a monitor's priors and the flight before the fault could tell it.
//!
//! `--against ACTUATOR` runs the same oracle a second time, restarting that actuator's pair at
//! the onset instead, and prints twice the log-likelihood ratio of the measurements since the
//! onset between the two: how clearly the data name the right actuator (the change test asks
//! 20 of its own reading).
//!
//! `cargo run --release --example oracle_bound -- hexa-x-motor3-loe --seeds 10`

// A developer tool: a failed unwrap ends it with the reason.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::eval::vehicle::sim_config;
use ahcmon::sim::vehicle::VehicleSim;
use anyhow::{Context, Result, bail};
use nalgebra::{DMatrix, DVector};

/// Times after the onset (s) at which the bound is reported.
const MARKS_S: [f64; 5] = [1.0, 2.0, 5.0, 10.0, 20.0];
/// Prior variances of gamma and delta (flat against what the data give).
const FLAT_GAMMA_VAR: f64 = 10.0;
const FLAT_DELTA_VAR: f64 = 1.0;
/// The tolerance of issue 4's gamma line.
const TOLERANCE: f64 = 0.05;

/// What one seed's oracle gives at one mark.
#[derive(Clone, Copy)]
struct Mark {
    /// Sigma of the restarted actuator's gamma, and its actual error.
    sigma: f64,
    error: f64,
    /// Sigma and actual error of its effective output `gamma u + delta` at that step's command.
    output_sigma: f64,
    output_error: f64,
    /// Log-likelihood of the measurements since the onset under this oracle's hypothesis.
    log_likelihood: f64,
}

impl Mark {
    const NONE: Mark = Mark {
        sigma: f64::NAN,
        error: f64::NAN,
        output_sigma: f64::NAN,
        output_error: f64::NAN,
        log_likelihood: f64::NAN,
    };
}

type SeedResult = Vec<Mark>;

/// What the oracle is given.
#[derive(Clone, Copy, Default)]
struct Knowledge {
    nominal_model: bool,
    white_gusts: bool,
    /// Every actuator's healthy gamma and delta exactly (only the faulty one's pair, from the
    /// onset, is unknown): the bound on how well the fault's size can be read, not the health.
    known_healthy: bool,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("oracle_bound: {e:#}");
        std::process::exit(2);
    }
}

fn run() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let (mut scenario, mut seeds) = (None, 10u64);
    let mut knows = Knowledge::default();
    let mut against = None;
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seeds" => {
                let v = args.next().context("--seeds needs a number")?;
                seeds = v.parse().with_context(|| format!("--seeds {v}"))?;
            }
            "--nominal-model" => knows.nominal_model = true,
            "--white-gusts" => knows.white_gusts = true,
            "--known-healthy" => knows.known_healthy = true,
            "--against" => against = Some(args.next().context("--against needs an actuator")?),
            "-h" | "--help" => {
                println!(
                    "usage: oracle_bound SCENARIO [--seeds N] [--nominal-model] [--white-gusts] [--known-healthy] [--against ACTUATOR]"
                );
                return Ok(());
            }
            s if s.starts_with('-') => bail!("unknown option {s}"),
            _ => scenario = Some(a),
        }
    }
    let name = scenario.context("usage: oracle_bound SCENARIO [--seeds N]")?;
    let named = ahcmon::scenario::resolve(&name).map_err(|e| anyhow::anyhow!("{e}"))?;
    abrupt_fault(&named)?;
    let fault = abrupt_fault(&named)?;
    let results = (0..seeds)
        .map(|i| run_seed(&named, named.scenario.seed + i, knows, &fault.actuator))
        .collect::<Result<Vec<_>>>()?;
    println!("{name}, {seeds} seeds: the faulty actuator's gamma, oracle Kalman filter");
    println!(
        "after onset  sigma (mean)  actual RMS error  P(|error| <= {TOLERANCE})  output: sigma  actual RMS"
    );
    for (m, at) in MARKS_S.iter().enumerate() {
        let n = results.len() as f64;
        let mean = |f: &dyn Fn(&Mark) -> f64| results.iter().map(|r| f(&r[m])).sum::<f64>() / n;
        let sigma = mean(&|k| k.sigma);
        let rms = mean(&|k| k.error.powi(2)).sqrt();
        let within = mean(&|k| erf(TOLERANCE / (k.sigma * std::f64::consts::SQRT_2)));
        let output_sigma = mean(&|k| k.output_sigma);
        let output_rms = mean(&|k| k.output_error.powi(2)).sqrt();
        println!(
            "{at:>8.0} s   {sigma:>11.4}  {rms:>16.4}  {within:>19.2}  {output_sigma:>13.4}  {output_rms:>10.4}"
        );
    }
    if let Some(other) = against {
        // The same oracle restarting another actuator at the onset instead: how much better
        // the measurements fit the right one (twice the log-likelihood ratio, as the change
        // test's margins).
        let wrong = (0..seeds)
            .map(|i| run_seed(&named, named.scenario.seed + i, knows, &other))
            .collect::<Result<Vec<_>>>()?;
        println!(
            "{} against {other}: 2 ln LR of the data since the onset (min / median over seeds)",
            fault.actuator
        );
        for (m, at) in MARKS_S.iter().enumerate() {
            let mut lr: Vec<f64> = results
                .iter()
                .zip(&wrong)
                .map(|(r, w)| 2.0 * (r[m].log_likelihood - w[m].log_likelihood))
                .collect();
            lr.sort_by(f64::total_cmp);
            println!("{at:>8.0} s   {:>10.1} / {:>10.1}", lr[0], lr[lr.len() / 2]);
        }
    }
    Ok(())
}

/// One seed of the oracle, restarting `restart`'s gamma and delta at the fault's onset (the
/// faulty actuator, or another for `--against`).
fn run_seed(
    named: &ahcmon::scenario::NamedScenario,
    seed: u64,
    knows: Knowledge,
    restart: &str,
) -> Result<SeedResult> {
    let (cfg, monitor) = sim_config(named, seed).map_err(|e| anyhow::anyhow!("{e}"))?;
    let fault = abrupt_fault(named)?;
    // The simulator flies its own profile; the monitor's may differ (`profile = ...`).
    let vehicle = cfg.profile.clone();
    let truth = if knows.nominal_model {
        monitor.rate_params()
    } else {
        vehicle
            .rate_params()
            .scaled(cfg.mismatch.damping, cfg.mismatch.effectiveness)
    };
    let white = knows.white_gusts;
    let l = vehicle.actuators.len();
    let f = vehicle
        .actuator_index(restart)
        .with_context(|| format!("no actuator {restart}"))?;
    let rows = vehicle.measurements();
    let dt = cfg.dt;
    // Gust: g_k = a g_{k-1} + b sd n_k per axis (roll, pitch, yaw, vertical), as in the sim.
    let (tau, gust_sd) = match &cfg.gusts {
        Some(g) => (
            g.tau_s,
            [g.angular[0], g.angular[1], g.angular[2], g.vertical],
        ),
        None => (1.0, [0.0; 4]),
    };
    let a = (-dt / tau.max(dt)).exp();
    let b = (1.0 - a * a).sqrt();
    let (gyro_sd, az_sd) = (cfg.gyro_noise, cfg.az_noise);
    let mut sim = VehicleSim::new(cfg).map_err(|e| anyhow::anyhow!("{e}"))?;

    // z = [p q r | gust roll pitch yaw vertical | gamma_1..l | delta_1..l]
    let (gust0, gamma0, delta0) = (3, 7, 7 + l);
    let n = 7 + 2 * l;
    let mut z = DVector::<f64>::zeros(n);
    let mut p = DMatrix::<f64>::zeros(n, n);
    for i in 0..3 {
        p[(i, i)] = 1e-4;
    }
    for (i, sd) in gust_sd.iter().enumerate() {
        p[(gust0 + i, gust0 + i)] = sd * sd;
    }
    for j in 0..l {
        // Healthy: gamma 1 and delta 0 (the simulator's truth before any fault).
        z[gamma0 + j] = 1.0;
        if !knows.known_healthy {
            p[(gamma0 + j, gamma0 + j)] = FLAT_GAMMA_VAR;
            p[(delta0 + j, delta0 + j)] = FLAT_DELTA_VAR;
        }
    }
    let mut restarted = false;
    let mut out = vec![Mark::NONE; MARKS_S.len()];
    let mut log_likelihood = 0.0;
    for _ in 0..named.scenario.steps() {
        // The simulator applies the fault from the step that starts at its time on.
        let step_start = sim.time();
        let s = sim.step();
        if !restarted && step_start >= fault.t {
            restarted = true;
            for k in [gamma0 + f, delta0 + f] {
                for c in 0..n {
                    p[(k, c)] = 0.0;
                    p[(c, k)] = 0.0;
                }
            }
            p[(gamma0 + f, gamma0 + f)] = FLAT_GAMMA_VAR;
            p[(delta0 + f, delta0 + f)] = FLAT_DELTA_VAR;
        }
        // Predict: the gust is updated first and held over the step (zero-order hold of D).
        let mut fm = DMatrix::<f64>::identity(n, n);
        let mut drive = DVector::<f64>::zeros(n);
        let mut q = DMatrix::<f64>::zeros(n, n);
        for i in 0..3 {
            let d = truth.damping[i];
            let hold = if d * dt > 1e-12 {
                -(-d * dt).exp_m1() / d
            } else {
                dt
            };
            fm[(i, i)] = (-d * dt).exp();
            drive[i] = hold * truth.offset[i];
            for j in 0..l {
                fm[(i, gamma0 + j)] = hold * truth.effectiveness[j][i] * s.u[j];
                fm[(i, delta0 + j)] = hold * truth.effectiveness[j][i];
            }
            if white {
                // The gust's whole variance as this step's white noise; its states stay 0.
                q[(i, i)] = (hold * gust_sd[i]).powi(2);
            } else {
                let w = (b * gust_sd[i]).powi(2);
                fm[(i, gust0 + i)] = hold * a;
                q[(i, i)] = hold * hold * w;
                q[(i, gust0 + i)] = hold * w;
                q[(gust0 + i, i)] = hold * w;
                q[(gust0 + i, gust0 + i)] = w;
            }
        }
        for i in 0..4 {
            fm[(gust0 + i, gust0 + i)] = a;
        }
        if !white {
            q[(gust0 + 3, gust0 + 3)] = (b * gust_sd[3]).powi(2);
        }
        z = &fm * &z + drive;
        p = &fm * &p * fm.transpose() + q;
        // Update with the gyro rates and, where measured, a_z.
        let mut h = DMatrix::<f64>::zeros(rows, n);
        let mut y = DVector::<f64>::zeros(rows);
        let mut r = DMatrix::<f64>::zeros(rows, rows);
        for i in 0..3 {
            h[(i, i)] = 1.0;
            y[i] = s.y[i];
            r[(i, i)] = gyro_sd * gyro_sd;
        }
        if rows == 4 {
            if !white {
                h[(3, gust0 + 3)] = 1.0;
            }
            for j in 0..l {
                h[(3, gamma0 + j)] = truth.vertical[j] * s.u[j];
                h[(3, delta0 + j)] = truth.vertical[j];
            }
            y[3] = s.y[3] - truth.vertical_offset;
            r[(3, 3)] = az_sd * az_sd + if white { gust_sd[3].powi(2) } else { 0.0 };
        }
        let innovation = &y - &h * &z;
        let s_cov = &h * &p * h.transpose() + &r;
        let det = s_cov.determinant();
        let s_inv = s_cov
            .try_inverse()
            .context("innovation covariance singular")?;
        if restarted {
            log_likelihood -= 0.5
                * ((innovation.transpose() * &s_inv * &innovation)[0]
                    + det.ln()
                    + rows as f64 * (2.0 * std::f64::consts::PI).ln());
        }
        let k = &p * h.transpose() * s_inv;
        z += &k * innovation;
        // Joseph form: the flat prior spans ten orders of magnitude.
        let ikh = DMatrix::<f64>::identity(n, n) - &k * &h;
        p = &ikh * &p * ikh.transpose() + &k * &r * k.transpose();
        p = (&p + p.transpose()) * 0.5;
        for (m, at) in MARKS_S.iter().enumerate() {
            if out[m].sigma.is_nan() && s.t >= fault.t + at - 1e-9 {
                let (g, d, u) = (gamma0 + f, delta0 + f, s.u[f]);
                let output_var = u * u * p[(g, g)] + 2.0 * u * p[(g, d)] + p[(d, d)];
                let output_error = (z[g] - s.gamma[f]) * u + z[d] - s.delta[f];
                out[m] = Mark {
                    sigma: p[(g, g)].sqrt(),
                    error: z[g] - s.gamma[f],
                    output_sigma: output_var.max(0.0).sqrt(),
                    output_error,
                    log_likelihood,
                };
            }
        }
    }
    Ok(out)
}

/// The scenario's one fault, if its gamma and delta are constant from the onset on (what the
/// oracle assumes): not a ramp, a sine, a fault that ends, or one of several.
fn abrupt_fault(named: &ahcmon::scenario::NamedScenario) -> Result<ahcmon::sim::fault::Fault> {
    if named.scenario.is_paper() {
        bail!(
            "{} is one of the paper's scenarios; the oracle is for the vehicle simulators",
            named.name
        );
    }
    let faults = &named.scenario.faults;
    let Some(fault) = faults.first() else {
        bail!(
            "{} has no fault: the bound is about the faulty actuator",
            named.name
        );
    };
    if faults.len() > 1 || fault.until.is_some() || fault.ramp.is_some() || fault.sine.is_some() {
        bail!(
            "{}: the oracle takes one abrupt fault that lasts (no ramp, sine, until or second fault)",
            named.name
        );
    }
    let last_mark = MARKS_S[MARKS_S.len() - 1];
    if fault.t + last_mark > named.scenario.duration_s {
        bail!(
            "{}: the flight ends before onset + {last_mark} s, the last time reported",
            named.name
        );
    }
    Ok(fault.clone())
}

/// Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7), enough for a probability in a report.
fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    (1.0 - poly * (-x * x).exp()).copysign(x)
}
