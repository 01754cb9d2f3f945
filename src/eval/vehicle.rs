//! `eval` on the vehicle scenarios: the vehicle simulator → MIT-UKF ‖ MIT-ESMF → diagnosis,
//! scored against the simulator's truth: isolation, class, false decisions, settling.

use super::{EvalError, FilterRun, Metrics, Run, Trace};
use crate::diagnose::vehicle::{Decision, Diagnoser, DiagnosisParams, Event};
use crate::estimate::vehicle::{FILTER_NAMES, build};
use crate::output::Sink;
use crate::pipeline::{Core, PipelineCounters, StepInput};
use crate::scenario::NamedScenario;
use crate::sim::fault::Fault;
use crate::sim::vehicle::{ModelMismatch, VehicleSim, VehicleSimConfig};
use crate::telemetry::Profile;
use std::time::Instant;

/// Isolation must happen within this long after onset (the matrix's `NAME_WITHIN_S`).
const ISOLATE_WITHIN_S: f64 = 5.0;
/// The class is judged on the decision in force this long after onset.
const CLASS_AT_S: f64 = 5.0;
/// The MIT-UKF's gamma should be within the tolerance of the truth from this long after onset.
const GAMMA_WITHIN_S: f64 = 5.0;
const TRACE_POINTS: usize = 2000;

/// True when `d` names an actuator that a scripted fault other than the scored one (`target`)
/// has made faulty at `d.t`: such a decision is right, not false.
fn later_fault_named(faults: &[Fault], target: Option<&str>, d: &Decision) -> bool {
    let Some(name) = d.actuator.as_deref() else {
        return false;
    };
    faults.iter().any(|f| {
        f.actuator == name
            && Some(name) != target
            && d.t >= f.t
            && f.until.is_none_or(|end| d.t <= end)
    })
}

/// A sink that keeps nothing.
pub struct NoSink;
impl Sink for NoSink {
    fn decision(&mut self, _: &Decision) {}
}

pub fn sim_config(
    named: &NamedScenario,
    seed: u64,
) -> Result<(VehicleSimConfig, Profile), EvalError> {
    let scn = &named.scenario;
    let err = |e: String| EvalError::Sim(named.name.clone(), e);
    let vehicle = Profile::resolve(&scn.vehicle).map_err(|e| err(e.to_string()))?;
    let monitor = match &scn.profile {
        Some(p) => Profile::resolve(p).map_err(|e| err(e.to_string()))?,
        None => vehicle.clone(),
    };
    let cfg = VehicleSimConfig {
        dt: scn.dt(),
        gyro_noise: scn.gyro_noise.unwrap_or(vehicle.noise.gyro),
        az_noise: scn.az_noise.unwrap_or(vehicle.noise.az),
        profile: vehicle,
        mismatch: scn.model_mismatch.unwrap_or(ModelMismatch {
            damping: 1.0,
            effectiveness: 1.0,
        }),
        gusts: scn.gusts.clone(),
        dither: scn.attitude_dither.clone(),
        manoeuvres: scn.manoeuvres.clone(),
        faults: scn.faults.clone(),
        bounded_noise: scn.bounded_noise,
        seed,
    };
    Ok((cfg, monitor))
}

/// Fly a vehicle scenario through the product's per-step core ([`Core::step`], as the
/// telemetry pipeline runs it) and score it against the simulator's truth. `threshold`
/// replaces the profile's decision threshold for both statistics (the threshold
/// calibration flies with an infinite one, so that no decision feeds back into the filters
/// it calibrates on).
pub fn run_vehicle_scenario(
    named: &NamedScenario,
    seed: u64,
    keep_traces: bool,
    threshold: Option<f64>,
    sink: &mut dyn Sink,
) -> Result<Run, EvalError> {
    let scn = &named.scenario;
    let err = |e: String| EvalError::Sim(named.name.clone(), e);
    let (cfg, mut profile) = sim_config(named, seed)?;
    if let Some(th) = threshold {
        profile.diagnosis.threshold = th;
        profile.diagnosis.gain_threshold = Some(th);
    }
    let dt = cfg.dt;
    let mut sim = VehicleSim::new(cfg).map_err(err)?;
    let filters = build(&profile, dt).map_err(|e| err(e.to_string()))?;
    let l = filters.actuators();
    if filters.inputs() != l {
        // An identified model takes delayed commands and measured increments, which only the
        // telemetry pipeline assembles; the simulator feeds commands and measurements.
        return Err(err(format!(
            "profile {} carries an identified model (model.arx); eval flies the profile's geometry model",
            profile.name
        )));
    }
    let m = filters.measurements();
    let names = profile.actuator_names();
    let diag = Diagnoser::new(DiagnosisParams::default(), 1, &profile, dt);
    let fault = scn.first_fault();
    let onset = fault.map(|f| f.t);
    let target = fault.and_then(|f| profile.actuator_index(&f.actuator));
    let moves_gamma = fault.is_none_or(|f| f.moves_gamma());
    let steps = scn.steps();
    let steady_from = scn.duration_s * (1.0 - scn.eval.steady_fraction);
    let decimate = steps.div_ceil(TRACE_POINTS).max(1);
    let mut core = Core::new(profile, filters, diag, 1);
    let mut counters = PipelineCounters::default();

    let mut decisions: Vec<Decision> = Vec::new();
    let mut nanos = 0u128;
    let mut errors = [0u64; 2];
    let mut last_violation: [Option<f64>; 2] = [None, None];
    let mut sq_g = [(0.0, 0usize); 2];
    let mut sq_d = [(0.0, 0usize); 2];
    let mut inside = [(0usize, 0usize); 2];
    // Steps from 5 s after onset, and how many of them had gamma off by more than the tolerance.
    let mut off_after = [(0usize, 0usize); 2];
    let mut traces = [Trace::default(), Trace::default()];
    let mut truth = Trace::default();
    let watch = target.unwrap_or(0);
    let mut rates_prev: Option<[f64; 3]> = None;
    for k in 0..steps {
        let s = sim.step();
        sink.truth(&s, &core.profile);
        // The simulator's commands act over the step that ends at its measurement; every
        // step but the first has the rates one period before, and no hole.
        let step = StepInput {
            t: s.t,
            input: &s.u[..l],
            y: &s.y[..m],
            acting: &s.u[..l],
            attitude: s.attitude,
            residual_from: rates_prev.as_ref(),
            // The geometry's model: a_z, where measured, is every filter's.
            set_az: None,
        };
        let t0 = Instant::now();
        let failed = core.step(&step, &mut counters, sink);
        nanos += t0.elapsed().as_nanos();
        rates_prev = Some([s.y[0], s.y[1], s.y[2]]);
        for (f, failed) in failed.iter().enumerate() {
            errors[f] += u64::from(*failed);
        }
        decisions.extend(core.decisions.iter().cloned());
        let est = core.est;
        // Scores on the watched actuator (the faulty one; actuator 0 in a healthy flight).
        let (g_true, d_true) = (s.gamma[watch], s.delta[watch]);
        for f in 0..2 {
            let e = est[f][watch];
            let ok = if moves_gamma {
                (e.gamma - g_true).abs() <= scn.eval.settle_tol_gamma
            } else {
                (e.delta - d_true).abs() <= scn.eval.settle_tol_delta
            };
            if !ok {
                last_violation[f] = Some(s.t);
            }
            if onset.is_some_and(|t0| s.t >= t0 + GAMMA_WITHIN_S) {
                off_after[f].0 += 1;
                off_after[f].1 += ((e.gamma - g_true).abs() > scn.eval.settle_tol_gamma) as usize;
            }
            if s.t >= steady_from {
                sq_g[f].0 += (e.gamma - g_true).powi(2);
                sq_g[f].1 += 1;
                sq_d[f].0 += (e.delta - d_true).powi(2);
                sq_d[f].1 += 1;
            }
            let within = e.gamma_lo <= g_true
                && g_true <= e.gamma_hi
                && e.delta_lo <= d_true
                && d_true <= e.delta_hi;
            inside[f].0 += within as usize;
            inside[f].1 += 1;
            if keep_traces && k % decimate == 0 {
                traces[f].push(
                    s.t,
                    e.gamma,
                    (e.gamma_lo, e.gamma_hi),
                    e.delta,
                    (e.delta_lo, e.delta_hi),
                );
            }
        }
        if keep_traces && k % decimate == 0 {
            truth.push(s.t, g_true, (g_true, g_true), d_true, (d_true, d_true));
        }
    }
    let us_per_step = nanos as f64 / 1000.0 / steps.max(1) as f64;
    let runs = (0..2)
        .map(|f| {
            let name = FILTER_NAMES[f];
            let mine: Vec<&Decision> = decisions
                .iter()
                .filter(|d| {
                    matches!(d.event, Event::Fault | Event::Changed) && d.filters.contains(&name)
                })
                .collect();
            let is_right = |d: &Decision| {
                target.is_some_and(|j| d.actuator.as_deref() == Some(names[j].as_str()))
            };
            // A scenario may script further faults after the first (the demo's tail bias): a
            // decision naming one of those actuators while it is faulty is not false either.
            let target_name = target.map(|j| names[j].as_str());
            let truly_faulted = |d: &Decision| later_fault_named(&scn.faults, target_name, d);
            let false_decisions = mine
                .iter()
                .filter(|d| d.event == Event::Fault || !is_right(d))
                .filter(|d| !is_right(d) || onset.is_none_or(|t0| d.t < t0))
                .filter(|d| !truly_faulted(d))
                .count() as u32;
            let first_right = mine
                .iter()
                .find(|d| is_right(d) && onset.is_some_and(|t0| d.t >= t0))
                .map(|d| d.t);
            let detection_delay_s = onset.zip(first_right).map(|(t0, t)| t - t0);
            let isolated_correct = onset.map(|_| {
                detection_delay_s.is_some_and(|d| d <= ISOLATE_WITHIN_S) && false_decisions == 0
            });
            let class = onset.and_then(|t0| {
                decisions
                    .iter()
                    .rfind(|d| {
                        is_right(d)
                            && d.t <= t0 + CLASS_AT_S
                            && d.class.is_some()
                            && matches!(d.event, Event::Fault | Event::Changed)
                    })
                    .and_then(|d| d.class)
                    .map(|c| c.as_str().to_string())
            });
            let settle_s = onset.and_then(|t0| match last_violation[f] {
                None => Some(0.0),
                Some(tv) if tv < scn.duration_s - 1.0 => Some((tv - t0).max(0.0)),
                _ => None,
            });
            let rmse = |(s, n): (f64, usize)| if n > 0 { (s / n as f64).sqrt() } else { 0.0 };
            FilterRun {
                filter: name,
                metrics: Metrics {
                    detection_delay_s,
                    settle_s,
                    gamma_rmse_3s: None,
                    gamma_rmse_steady: rmse(sq_g[f]),
                    delta_rmse_steady: rmse(sq_d[f]),
                    truth_in_bounds_pct: 100.0 * inside[f].0 as f64 / inside[f].1.max(1) as f64,
                    truth_in_bounds_after_1s_pct: f64::NAN,
                    false_decisions,
                    us_per_step,
                    step_errors: errors[f],
                    isolated_correct,
                    class,
                    excitation_low: decisions
                        .iter()
                        .filter(|d| d.event == Event::ExcitationLow)
                        .count() as u32,
                    gamma_off_after_5s_pct: (off_after[f].0 > 0)
                        .then(|| 100.0 * off_after[f].1 as f64 / off_after[f].0 as f64),
                },
                trace: std::mem::take(&mut traces[f]),
                decisions: mine.iter().map(|d| d.t).collect(),
            }
        })
        .collect();
    Ok(Run {
        scenario: named.name.clone(),
        vehicle: core.profile.name.clone(),
        seed,
        truth,
        filters: runs,
        final_speed: f64::NAN,
    })
}

/// The mean command of actuator `j` over the 2 s before `onset_s`, from the healthy flight
/// (a fault from then changes nothing before it): the trim a stuck output is put at.
pub fn mean_command_before(
    healthy: &NamedScenario,
    seed: u64,
    j: usize,
    onset_s: f64,
) -> Result<f64, EvalError> {
    let err = |e: String| EvalError::Sim(healthy.name.clone(), e);
    let (cfg, _) = sim_config(healthy, seed)?;
    let mut sim = VehicleSim::new(cfg).map_err(err)?;
    let (mut sum, mut n) = (0.0, 0u32);
    while sim.time() < onset_s {
        let t = sim.time();
        let s = sim.step();
        if t >= onset_s - 2.0 {
            sum += s.u[j];
            n += 1;
        }
    }
    Ok(sum / f64::from(n.max(1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(actuator: &str, t: f64, until: Option<f64>) -> Fault {
        let until = until.map(|e| format!("\nuntil = {e}")).unwrap_or_default();
        toml::from_str(&format!(
            "actuator = \"{actuator}\"\nt = {t}\ngamma = 0.5{until}"
        ))
        .expect("fault")
    }

    fn decision(t: f64, actuator: &str) -> Decision {
        let mut d = Decision::monitor(t, 1, Event::Fault, "");
        d.actuator = Some(actuator.to_string());
        d
    }

    #[test]
    fn a_decision_on_a_later_scripted_fault_is_not_false() {
        let faults = [fault("swash2", 32.0, None), fault("tail", 45.0, Some(50.0))];
        let target = Some("swash2");
        // The tail while it is faulty: right.
        assert!(later_fault_named(&faults, target, &decision(45.2, "tail")));
        // Before its onset, after its end, or another actuator: still false.
        assert!(!later_fault_named(&faults, target, &decision(44.0, "tail")));
        assert!(!later_fault_named(&faults, target, &decision(51.0, "tail")));
        assert!(!later_fault_named(
            &faults,
            target,
            &decision(46.0, "swash1")
        ));
        // The scored actuator itself is judged by the isolation rules, not here.
        assert!(!later_fault_named(
            &faults,
            target,
            &decision(40.0, "swash2")
        ));
    }
}
