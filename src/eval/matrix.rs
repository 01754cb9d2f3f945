//! `ahcmon eval --matrix`: every built-in vehicle × every actuator × fault kinds × flights ×
//! weather × seeds, plus long healthy flights, each flown through the pipeline `replay` runs
//! (the simulator's telemetry as MAVLink messages, the vehicle detected from its heartbeat and
//! parameters, calibrated on the flight's healthy start), and scored against the simulator's
//! truth and the oracle's detectability ([`super::oracle`]).
//!
//! A fault case flies [`FAULT_FLIGHT_S`] with the fault from [`ONSET_S`] on (sim time; the
//! vehicle's clock is [`BOOT_OFFSET_S`] ahead): take-off at 0, the 3 s settle and the 20 s
//! calibration stretch end at 23 s, the diagnosis' 5 s warm-up at 28 s. Pure: no I/O; the
//! caller runs the cases (in parallel) and prints.

use super::EvalError;
use super::oracle::{
    Alternative, DETECTABLE_LAMBDA, IsolationOracle, KindOracle, Oracle, OracleNoise,
};
use super::vehicle::{mean_command_before, sim_config};
use crate::diagnose::vehicle::{Decision, Event};
use crate::estimate::vehicle::AhcEstimate;
use crate::monitor::Monitor;
use crate::output::Sink;
use crate::pipeline::PipelineConfig;
use crate::protocol::Frame;
use crate::scenario::{NamedScenario, Scenario};
use crate::sim::vehicle::VehicleSim;
use crate::telemetry::Profile;
use crate::telemetry::encode::{BOOT_OFFSET_S, SimTelemetry};
use serde::Serialize;

/// The built-in vehicles the matrix flies.
pub const VEHICLES: [&str; 5] = ["quad-x", "quad-plus", "hexa-x", "heli-h3-120", "plane"];

/// Fault onset (s of sim time) and the length of a fault flight.
pub const ONSET_S: f64 = 35.0;
pub const FAULT_FLIGHT_S: f64 = 55.0;
/// A fault is to be named within this long of its onset, and judged (class, estimates) this
/// long after its decision.
pub const NAME_WITHIN_S: f64 = 5.0;
pub const JUDGE_AFTER_S: f64 = 5.0;
/// How long the gain ramp runs.
const RAMP_S: f64 = 8.0;
/// MIT-UKF gamma and delta within this of the truth count as right.
pub const ESTIMATE_TOLERANCE: f64 = 0.1;
/// The soonest the diagnosis can report a new class after the fault changes kind: a class
/// needs `CLASS_MIN_S` of changed data and holds `CLASS_HOLD_S` before a `changed` decision.
pub const CLASS_LATENCY_S: f64 =
    crate::diagnose::vehicle::CLASS_MIN_S + crate::diagnose::vehicle::CLASS_HOLD_S;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    Loss050,
    Loss075,
    BiasUp,
    BiasDown,
    StuckNearTrim,
    RampTo060,
}

impl FaultKind {
    pub const ALL: [FaultKind; 6] = [
        Self::Loss050,
        Self::Loss075,
        Self::BiasUp,
        Self::BiasDown,
        Self::StuckNearTrim,
        Self::RampTo060,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Loss050 => "loss 0.5",
            Self::Loss075 => "loss 0.75",
            Self::BiasUp => "bias +0.15",
            Self::BiasDown => "bias -0.15",
            Self::StuckNearTrim => "stuck at trim",
            Self::RampTo060 => "ramp to 0.6/8 s",
        }
    }

    /// Whether `class` is right for this fault when its truth is `(gamma, delta)` at the
    /// judging time: the class definitions applied to the truth (`docs/diagnosis.md`), so a
    /// surface stuck at a trim near 0 (gain 0, no offset) is stuck or a loss, a gain ramp a
    /// drift while it moves (and for [`CLASS_LATENCY_S`] after: no class change can be
    /// reported sooner) and a loss either way.
    pub fn right_class(self, class: &str, gamma: f64, delta: f64, t_sim: f64) -> bool {
        let p = crate::diagnose::vehicle::DiagnosisParams::default();
        let loss = gamma < 1.0 - p.loe_tau && delta.abs() <= p.bias_tau;
        let bias = delta.abs() > p.bias_tau && (gamma - 1.0).abs() <= p.loe_tau;
        match class {
            "loss_of_effectiveness" => loss,
            "bias" => bias,
            "stuck" => self == Self::StuckNearTrim,
            "drift" => self == Self::RampTo060 && t_sim < ONSET_S + RAMP_S + CLASS_LATENCY_S,
            _ => false,
        }
    }

    /// The kinds of change whose classes [`Self::right_class`] rejects for this fault, which a
    /// classifier must tell it from: a loss (or a gain ramp) an offset, an offset a gain
    /// change, a stuck output either (a gain change only at a trim beyond the bias tolerance:
    /// stuck near 0 is gain 0, a loss too).
    fn alternatives(self, trim: f64) -> &'static [Alternative] {
        let bias_tau = crate::diagnose::vehicle::DiagnosisParams::default().bias_tau;
        match self {
            Self::Loss050 | Self::Loss075 | Self::RampTo060 => &[Alternative::Offset],
            Self::BiasUp | Self::BiasDown => &[Alternative::Gain],
            Self::StuckNearTrim if trim.abs() <= bias_tau => &[Alternative::Offset],
            Self::StuckNearTrim => &[Alternative::Gain, Alternative::Offset],
        }
    }

    /// The fault's TOML lines (`trim`: the actuator's mean command before the onset).
    fn toml(self, actuator: &str, trim: f64) -> String {
        let what = match self {
            Self::Loss050 => "gamma = 0.5".to_string(),
            Self::Loss075 => "gamma = 0.75".to_string(),
            Self::BiasUp => "delta = 0.15".to_string(),
            Self::BiasDown => "delta = -0.15".to_string(),
            Self::StuckNearTrim => format!("stuck = {trim:.6}"),
            Self::RampTo060 => format!("ramp = {{ duration_s = {RAMP_S:.1}, gamma = 0.6 }}"),
        };
        format!("\n[[fault]]\nactuator = \"{actuator}\"\nt = {ONSET_S:.1}\n{what}\n")
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Flight {
    /// Hover or cruise with the built-in attitude dither.
    Steady,
    /// The dither and a roll, a pitch and a yaw manoeuvre every 12 s.
    Manoeuvres,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Weather {
    /// The built-in scenarios' gusts and 10 % damping mismatch.
    Builtin,
    /// 1.5 times the gusts, damping 15 % over and effectiveness 15 % under the profile.
    Rough,
}

/// One flight of the matrix.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Case {
    pub vehicle: &'static str,
    /// The faulty actuator and the fault; `None` for a healthy flight.
    pub fault: Option<(String, FaultKind)>,
    pub flight: Flight,
    pub weather: Weather,
    pub seed: u64,
    pub duration_s: f64,
}

/// Which cases: all, or the fast subset CI runs (one seed, losses of 0.5 and biases of +0.15
/// in steady flight with the built-in weather, two healthy minutes per vehicle).
#[derive(Debug, Clone)]
pub struct MatrixSpec {
    pub seeds: u64,
    /// The first seed (seeds run `first_seed..first_seed + seeds`).
    pub first_seed: u64,
    pub healthy_s: f64,
    pub fast: bool,
    /// Only these vehicles ([`VEHICLES`]' names); empty: all.
    pub vehicles: Vec<String>,
}

/// The cases of `spec`, in a fixed order.
pub fn cases(spec: &MatrixSpec) -> Result<Vec<Case>, EvalError> {
    let (kinds, flights, weathers): (&[FaultKind], &[Flight], &[Weather]) = if spec.fast {
        (
            &[FaultKind::Loss050, FaultKind::BiasUp],
            &[Flight::Steady],
            &[Weather::Builtin],
        )
    } else {
        (
            &FaultKind::ALL,
            &[Flight::Steady, Flight::Manoeuvres],
            &[Weather::Builtin, Weather::Rough],
        )
    };
    if let Some(v) = (spec.vehicles.iter()).find(|v| !VEHICLES.contains(&v.as_str())) {
        return Err(EvalError::Sim(
            v.clone(),
            format!("not a matrix vehicle (one of {})", VEHICLES.join(", ")),
        ));
    }
    let mut out = vec![];
    for vehicle in VEHICLES {
        if !spec.vehicles.is_empty() && !spec.vehicles.iter().any(|v| v == vehicle) {
            continue;
        }
        let profile = Profile::resolve(vehicle)
            .map_err(|e| EvalError::Sim(vehicle.to_string(), e.to_string()))?;
        for seed in spec.first_seed..spec.first_seed + spec.seeds {
            for &flight in flights {
                for &weather in weathers {
                    let case = |fault, duration_s| Case {
                        vehicle,
                        fault,
                        flight,
                        weather,
                        seed,
                        duration_s,
                    };
                    for name in profile.actuator_names() {
                        for &kind in kinds {
                            out.push(case(Some((name.clone(), kind)), FAULT_FLIGHT_S));
                        }
                    }
                    out.push(case(None, spec.healthy_s));
                }
            }
        }
    }
    Ok(out)
}

impl Case {
    pub fn label(&self) -> String {
        let fault = match &self.fault {
            Some((a, k)) => format!("{a} {}", k.as_str()),
            None => "healthy".into(),
        };
        format!(
            "{} {fault}, {:?}, {:?} weather, seed {}",
            self.vehicle, self.flight, self.weather, self.seed
        )
        .to_lowercase()
    }

    /// The case as a scenario file's text, with the fault's trim given (`ahcmon sim` flies it
    /// again). Every case starts from the built-in scenarios' weather and dither.
    pub fn scenario_toml(&self, trim: f64) -> String {
        let (gust, mismatch) = match self.weather {
            Weather::Builtin => (1.0, "{ damping = 1.1 }"),
            Weather::Rough => (1.5, "{ damping = 1.15, effectiveness = 0.85 }"),
        };
        let mut s = format!(
            "description = \"matrix: {}\"\nvehicle = \"{}\"\nduration_s = {:.1}\nrate_hz = 50.0\nseed = {}\nmodel_mismatch = {mismatch}\ngusts = {{ angular = [{:.3}, {:.3}, {:.3}], vertical = {:.3}, tau_s = 1.0 }}\n\n[attitude_dither]\namplitude = [0.05, 0.05, 0.1]\nfreqs_hz = [0.3, 0.7, 1.1]\n",
            self.label(),
            self.vehicle,
            self.duration_s,
            self.seed,
            0.5 * gust,
            0.5 * gust,
            0.15 * gust,
            0.3 * gust,
        );
        if self.flight == Flight::Manoeuvres {
            let mut t = 2.0;
            let mut sign = 1.0;
            while t < self.duration_s {
                s += &format!(
                    "\n[[manoeuvre]]\nt = {t:.1}\nduration_s = 2.0\nroll_deg = {:.1}\n\n[[manoeuvre]]\nt = {:.1}\nduration_s = 2.0\npitch_deg = {:.1}\n\n[[manoeuvre]]\nt = {:.1}\nduration_s = 2.0\nyaw_rate_dps = {:.1}\n",
                    15.0 * sign,
                    t + 4.0,
                    -10.0 * sign,
                    t + 7.0,
                    30.0 * sign
                );
                t += 12.0;
                sign = -sign;
            }
        }
        if let Some((actuator, kind)) = &self.fault {
            s += &kind.toml(actuator, trim);
        }
        s
    }

    fn named(&self, trim: f64) -> Result<NamedScenario, EvalError> {
        let text = self.scenario_toml(trim);
        let scenario = Scenario::from_toml(&text, "matrix case")
            .map_err(|e| EvalError::Sim(self.label(), e.to_string()))?;
        Ok(NamedScenario {
            name: self.label(),
            scenario,
        })
    }
}

/// How one case went.
#[derive(Debug, Clone, Serialize)]
pub struct CaseResult {
    pub case: Case,
    /// The oracle's non-centrality 5 s after the onset, and whether that makes the fault
    /// detectable ([`DETECTABLE_LAMBDA`]).
    pub oracle_lambda: Option<f64>,
    pub detectable: Option<bool>,
    /// The isolation oracle's non-centrality at the same time ([`IsolationOracle`], the fault
    /// against the closest change of another actuator), and whether that names the actuator.
    pub isolation_lambda: Option<f64>,
    pub isolable: Option<bool>,
    /// Fault decisions before the onset (any actuator; all of a healthy flight's), and each
    /// one's actuator and rule.
    pub false_before_onset: u32,
    pub false_decisions: Vec<(String, String)>,
    /// After the onset: the first fault decision's actuator and delay (s).
    pub first: Option<(String, f64)>,
    /// Delay of the first fault decision on the faulty actuator (s).
    pub named_after_s: Option<f64>,
    /// Fault decisions on other actuators after the onset.
    pub wrong_actuator: u32,
    /// The class in force on the faulty actuator `JUDGE_AFTER_S` after its decision.
    pub class: Option<String>,
    pub class_right: Option<bool>,
    /// The class oracle's non-centrality ([`KindOracle`], the fault against the closest
    /// alternative of another kind) at the same time, and whether that separates the class.
    pub class_lambda: Option<f64>,
    pub class_separable: Option<bool>,
    /// MIT-UKF gamma and delta minus the truth `JUDGE_AFTER_S` after the decision.
    pub gamma_error: Option<f64>,
    pub delta_error: Option<f64>,
    /// The vehicle got a `cannot_estimate` decision; an actuator a `cannot_judge` one.
    pub cannot_estimate: bool,
    pub cannot_judge: bool,
    /// Estimating time (h) of the flight.
    pub estimating_h: f64,
}

/// What a case's run keeps: the decisions and the faulty actuator's MIT-UKF estimates.
struct Collect {
    target: Option<usize>,
    decisions: Vec<Decision>,
    estimates: Vec<(f64, AhcEstimate)>,
    first_estimate: Option<f64>,
    last_estimate: f64,
}

impl Sink for Collect {
    fn decision(&mut self, d: &Decision) {
        self.decisions.push(d.clone());
    }

    fn estimates(&mut self, t: f64, _sysid: u8, est: &[&[AhcEstimate]; 3], _p: &Profile) {
        self.first_estimate.get_or_insert(t);
        self.last_estimate = t;
        if let Some(e) = self.target.and_then(|j| est[0].get(j)) {
            self.estimates.push((t, *e));
        }
    }
}

/// Fly one case through the pipeline and score it.
pub fn run_case(case: &Case) -> Result<CaseResult, EvalError> {
    let vehicle =
        Profile::resolve(case.vehicle).map_err(|e| EvalError::Sim(case.label(), e.to_string()))?;
    let target = case
        .fault
        .as_ref()
        .and_then(|(a, _)| vehicle.actuator_index(a));
    let trim = match (&case.fault, target) {
        (Some((_, FaultKind::StuckNearTrim)), Some(j)) => {
            let healthy = Case {
                fault: None,
                ..case.clone()
            };
            mean_command_before(&healthy.named(0.0)?, case.seed, j, ONSET_S)?
        }
        _ => 0.0,
    };
    let named = case.named(trim)?;
    let (cfg, _) = sim_config(&named, case.seed)?;
    let truth = cfg
        .profile
        .rate_params()
        .scaled(cfg.mismatch.damping, cfg.mismatch.effectiveness);
    let gusts = cfg.gusts.clone().unwrap_or(crate::sim::vehicle::Gusts {
        angular: [0.0; 3],
        vertical: 0.0,
        tau_s: 1.0,
    });
    let noise = OracleNoise {
        dt: cfg.dt,
        gust_tau_s: gusts.tau_s,
        gust_sd: [
            gusts.angular[0],
            gusts.angular[1],
            gusts.angular[2],
            gusts.vertical,
        ],
        gyro_sd: cfg.gyro_noise,
        az_sd: vehicle.model.measure_az.then_some(cfg.az_noise),
    };
    let mut oracle = Oracle::new(truth.clone(), noise);
    let l = vehicle.actuators.len();
    let mut kind_oracle = target.map(|j| KindOracle::new(truth.clone(), noise, j, l));
    let mut isolation_oracle = target.map(|j| IsolationOracle::new(truth.clone(), noise, j, l));
    let mut isolation_at_mark = None;
    let alternatives = case
        .fault
        .as_ref()
        .map_or(&[][..], |(_, k)| k.alternatives(trim));
    let mut sink = Collect {
        target,
        decisions: vec![],
        estimates: vec![],
        first_estimate: None,
        last_estimate: 0.0,
    };
    let mut lambda_at_mark = None;
    let mut deviation = [0.0; crate::model::MAX_ACTUATORS];
    let mut truth_at: Vec<(f64, f64, f64)> = vec![];
    let mut class_lambda_at: Vec<f64> = vec![];
    let _ = fly(
        &named,
        case.seed,
        PipelineConfig::default(),
        &mut sink,
        |prev| {
            for (j, dev) in deviation.iter_mut().enumerate().take(l) {
                *dev = (prev.gamma[j] - 1.0) * prev.u[j] + prev.delta[j];
            }
            oracle.step(&deviation[..l]);
            if let (Some(j), Some(o)) = (target, isolation_oracle.as_mut()) {
                o.step(deviation[j], &prev.u[..l], prev.t >= ONSET_S);
            }
            if lambda_at_mark.is_none() && prev.t >= ONSET_S + NAME_WITHIN_S {
                lambda_at_mark = Some(oracle.lambda());
                isolation_at_mark = isolation_oracle.as_ref().map(IsolationOracle::lambda);
            }
            if let (Some(j), Some(k)) = (target, kind_oracle.as_mut()) {
                truth_at.push((prev.t + BOOT_OFFSET_S, prev.gamma[j], prev.delta[j]));
                k.step(deviation[j], prev.u[j], prev.t >= ONSET_S);
                let sep = (alternatives.iter())
                    .map(|&a| k.lambda_from(a))
                    .fold(f64::INFINITY, f64::min);
                class_lambda_at.push(sep);
            }
        },
    )?;
    let mut result = score(
        case,
        target.is_some(),
        lambda_at_mark,
        &sink,
        &truth_at,
        &class_lambda_at,
    );
    result.isolation_lambda = isolation_at_mark;
    result.isolable = isolation_at_mark.map(|l| l >= DETECTABLE_LAMBDA);
    Ok(result)
}

/// Fly `named` with `seed` through the pipeline `replay` runs: the simulator's telemetry as
/// the MAVLink messages an autopilot sends, into a [`Monitor`] with `config`. `on_sample` sees
/// each sample (with its truth) before its messages are sent.
pub(super) fn fly(
    named: &NamedScenario,
    seed: u64,
    config: PipelineConfig,
    sink: &mut dyn Sink,
    mut on_sample: impl FnMut(&crate::sim::vehicle::VehicleSample),
) -> Result<Monitor, EvalError> {
    let err = |e: String| EvalError::Sim(named.name.clone(), e);
    let (cfg, _) = sim_config(named, seed)?;
    let vehicle = cfg.profile.clone();
    let l = vehicle.actuators.len();
    let mut sim = VehicleSim::new(cfg).map_err(err)?;
    let mut enc = SimTelemetry::new(&vehicle);
    let mut monitor = Monitor::new(config);
    let mut msgs = Vec::with_capacity(16);
    let mut seq = 0u8;
    let mut prev = sim.step();
    for _ in 1..named.scenario.steps() {
        let next = sim.step();
        on_sample(&prev);
        msgs.clear();
        enc.sample_messages(&prev, &next.u[..l], &mut msgs);
        for m in msgs.drain(..) {
            let frame = Frame {
                version: mavlink_core::MavlinkVersion::V2,
                sysid: 1,
                compid: 1,
                seq,
                msg_id: mavlink_core::Message::message_id(&m),
                msg: m,
            };
            seq = seq.wrapping_add(1);
            monitor.on_frame(&frame, sink);
        }
        prev = next;
    }
    monitor.finish(sink);
    Ok(monitor)
}

fn score(
    case: &Case,
    faulty: bool,
    lambda: Option<f64>,
    sink: &Collect,
    truth_at: &[(f64, f64, f64)],
    class_lambda_at: &[f64],
) -> CaseResult {
    let onset = ONSET_S + BOOT_OFFSET_S;
    let target = case.fault.as_ref().map(|(a, _)| a.as_str());
    let faults: Vec<&Decision> = (sink.decisions.iter())
        .filter(|d| d.event == Event::Fault)
        .collect();
    let before = |d: &&&Decision| !faulty || d.t < onset;
    let false_before_onset = faults.iter().filter(before).count() as u32;
    let false_decisions = (faults.iter().filter(before))
        .map(|d| {
            let rule = d.rule.map_or(String::new(), |r| format!("{r:?}"));
            (d.actuator.clone().unwrap_or_default(), rule)
        })
        .collect();
    let after: Vec<&Decision> = if faulty {
        faults.iter().copied().filter(|d| d.t >= onset).collect()
    } else {
        vec![]
    };
    let first = after
        .first()
        .map(|d| (d.actuator.clone().unwrap_or_default(), d.t - onset));
    let on_target = after.iter().find(|d| d.actuator.as_deref() == target);
    let wrong_actuator = after
        .iter()
        .filter(|d| d.actuator.as_deref() != target)
        .count() as u32;
    let mut class = None;
    let (mut gamma_error, mut delta_error) = (None, None);
    if let Some(d) = on_target {
        let at = d.t + JUDGE_AFTER_S;
        for e in &sink.decisions {
            if e.t > at || e.actuator.as_deref() != target {
                continue;
            }
            match e.event {
                Event::Fault | Event::Changed if e.t >= d.t => class = e.class,
                Event::Cleared if e.t >= d.t => class = None,
                _ => {}
            }
        }
        let est = sink.estimates.iter().find(|(t, _)| *t >= at);
        let tru = truth_at.iter().find(|(t, _, _)| *t >= at - 1e-9);
        if let (Some((_, e)), Some((_, g, dl))) = (est, tru) {
            gamma_error = Some(e.gamma - g);
            delta_error = Some(e.delta - dl);
        }
    }
    let class = class.map(|c| c.as_str().to_string());
    let judged_at = on_target.and_then(|d| {
        let at = d.t + JUDGE_AFTER_S;
        truth_at.iter().position(|(t, _, _)| *t >= at - 1e-9)
    });
    let judged = judged_at.map(|i| &truth_at[i]);
    let class_lambda = judged_at.and_then(|i| class_lambda_at.get(i).copied());
    let class_right = match (&case.fault, judged) {
        (Some((_, kind)), Some(&(t, g, dl))) => {
            let t_sim = t - BOOT_OFFSET_S;
            Some(
                class
                    .as_deref()
                    .is_some_and(|c| kind.right_class(c, g, dl, t_sim)),
            )
        }
        _ => None,
    };
    let estimating_h = sink
        .first_estimate
        .map_or(0.0, |t0| (sink.last_estimate - t0) / 3600.0);
    CaseResult {
        case: case.clone(),
        oracle_lambda: lambda.filter(|_| faulty),
        detectable: lambda.filter(|_| faulty).map(|l| l >= DETECTABLE_LAMBDA),
        isolation_lambda: None,
        isolable: None,
        false_before_onset,
        false_decisions,
        first,
        named_after_s: on_target.map(|d| d.t - onset),
        wrong_actuator,
        class,
        class_right,
        class_lambda,
        class_separable: class_lambda.map(|l| l >= DETECTABLE_LAMBDA),
        gamma_error,
        delta_error,
        cannot_estimate: (sink.decisions.iter()).any(|d| d.event == Event::CannotEstimate),
        cannot_judge: (sink.decisions.iter()).any(|d| d.event == Event::CannotJudge),
        estimating_h,
    }
}

pub use super::matrix_report::{ReportRow, report};

#[cfg(test)]
#[path = "matrix_tests.rs"]
mod tests;
