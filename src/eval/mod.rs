//! `ahcmon eval`: scenarios through the simulator and all five filters (fed the same samples),
//! scored against the simulator's truth. Pure: printing and plotting live in `output/`.

pub mod bank;
pub mod bounds;
pub mod datasets;
pub mod matrix;
pub mod matrix_report;
pub mod oracle;
pub mod thresholds;
pub mod vehicle;

use crate::scenario::{NamedScenario, Scenario};
use crate::sim::paper::{ESTIMATED, PaperSim};
use bank::{BankNoise, FILTERS, paper_bank};
use bounds::{BoundsDetector, BoundsEvent};
use serde::Serialize;
use std::time::Instant;

/// Bounds-decision hold-off before a fault clears.
const CLEAR_S: f64 = 2.0;
/// At most this many points per trace are kept for plots.
const TRACE_POINTS: usize = 2000;

#[derive(Debug, Clone, Default, Serialize)]
pub struct Trace {
    pub t: Vec<f64>,
    pub gamma: Vec<f64>,
    pub gamma_lo: Vec<f64>,
    pub gamma_hi: Vec<f64>,
    pub delta: Vec<f64>,
    pub delta_lo: Vec<f64>,
    pub delta_hi: Vec<f64>,
}

impl Trace {
    pub fn push(&mut self, t: f64, g: f64, gb: (f64, f64), d: f64, db: (f64, f64)) {
        self.t.push(t);
        self.gamma.push(g);
        self.gamma_lo.push(gb.0);
        self.gamma_hi.push(gb.1);
        self.delta.push(d);
        self.delta_lo.push(db.0);
        self.delta_hi.push(db.1);
    }
}

/// Scores of one filter on one run.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Metrics {
    pub detection_delay_s: Option<f64>,
    pub settle_s: Option<f64>,
    pub gamma_rmse_3s: Option<f64>,
    pub gamma_rmse_steady: f64,
    pub delta_rmse_steady: f64,
    pub truth_in_bounds_pct: f64,
    /// The same, leaving out the first second after the fault onset.
    pub truth_in_bounds_after_1s_pct: f64,
    pub false_decisions: u32,
    pub us_per_step: f64,
    /// Steps the filter rejected with an error (state kept).
    pub step_errors: u64,
    /// Fault scenarios: the right actuator isolated within 2 s of onset and no wrong fault
    /// decision; None for a healthy flight.
    pub isolated_correct: Option<bool>,
    /// Class of the decision in force 5 s after onset (vehicle scenarios).
    pub class: Option<String>,
    /// `excitation_low` decisions.
    pub excitation_low: u32,
    /// Vehicle fault scenarios: % of the steps from 5 s after onset on with the gamma estimate
    /// more than `settle_tol_gamma` from the truth (issue 4: "within 0.05 of truth within
    /// 5 s" holds at 0).
    pub gamma_off_after_5s_pct: Option<f64>,
}

#[derive(Debug, Clone)]
pub struct FilterRun {
    pub filter: &'static str,
    pub metrics: Metrics,
    pub trace: Trace,
    /// Fault decision times of the bounds rule.
    pub decisions: Vec<f64>,
}

#[derive(Debug, Clone)]
pub struct Run {
    pub scenario: String,
    pub vehicle: String,
    pub seed: u64,
    pub truth: Trace,
    pub filters: Vec<FilterRun>,
    pub final_speed: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("scenario {0}: {1}")]
    Sim(String, String),
}

struct Accum {
    detector: BoundsDetector,
    decisions: Vec<f64>,
    false_decisions: u32,
    first_detection: Option<f64>,
    sq_3s: (f64, usize),
    sq_steady_g: (f64, usize),
    sq_steady_d: (f64, usize),
    inside: (usize, usize),
    inside_after: (usize, usize),
    last_violation: Option<f64>,
    nanos: u128,
    steps: u64,
    errors: u64,
    trace: Trace,
}

/// Run one scenario with one seed through the sim and the whole filter bank.
pub fn run_scenario(named: &NamedScenario, seed: u64, keep_traces: bool) -> Result<Run, EvalError> {
    let scn: &Scenario = &named.scenario;
    if !scn.is_paper() {
        return vehicle::run_vehicle_scenario(named, seed, keep_traces, None, &mut vehicle::NoSink);
    }
    let settings = scn.eval;
    let dt = scn.dt();
    let mut sim = PaperSim::new(scn.paper_sim_config(seed))
        .map_err(|e| EvalError::Sim(named.name.clone(), e))?;
    let noise = BankNoise::nominal(&scn.process_noise, &scn.measurement_noise);
    let mut bank = paper_bank(&sim.model, &noise);
    let steps = scn.steps();
    let fault = scn.first_fault();
    let onset = fault.map(|f| f.t);
    let moves_gamma = fault.is_none_or(|f| f.moves_gamma());
    let steady_from = scn.duration_s * (1.0 - settings.steady_fraction);
    let decimate = steps.div_ceil(TRACE_POINTS).max(1);
    let mut acc: Vec<Accum> = bank
        .iter()
        .map(|_| Accum {
            detector: BoundsDetector::new(
                dt,
                settings.detect_persistence_s,
                CLEAR_S,
                settings.warmup_s,
            ),
            decisions: vec![],
            false_decisions: 0,
            first_detection: None,
            sq_3s: (0.0, 0),
            sq_steady_g: (0.0, 0),
            sq_steady_d: (0.0, 0),
            inside: (0, 0),
            inside_after: (0, 0),
            last_violation: None,
            nanos: 0,
            steps: 0,
            errors: 0,
            trace: Trace::default(),
        })
        .collect();
    let mut truth = Trace::default();
    let mut final_speed = scn.forward_speed_mps;
    for k in 0..steps {
        let s = sim.step();
        final_speed = s.speed;
        let (g_true, d_true) = s.truth[ESTIMATED];
        let keep = keep_traces && k % decimate == 0;
        if keep {
            truth.push(s.t, g_true, (g_true, g_true), d_true, (d_true, d_true));
        }
        // Time of the step the truth applies to (the measurement closes it).
        let t_step = s.t - dt;
        for (f, a) in bank.iter_mut().zip(acc.iter_mut()) {
            let start = Instant::now();
            let r = f.step(&s.u, &s.y);
            a.nanos += start.elapsed().as_nanos();
            a.steps += 1;
            if r.is_err() {
                a.errors += 1;
            }
            let x = f.state();
            let (g, d) = (x[3], x[4]);
            let (gb, db) = (f.bounds(3), f.bounds(4));
            if keep {
                a.trace.push(s.t, g, gb, d, db);
            }
            let healthy_stretch = onset.is_none_or(|t0| t_step < t0);
            if let Some(BoundsEvent::Fault) = a.detector.update(gb, db, f.contradicted()) {
                a.decisions.push(s.t);
                if healthy_stretch {
                    a.false_decisions += 1;
                } else if a.first_detection.is_none() {
                    a.first_detection = Some(s.t);
                }
            }
            let inside = gb.0 <= g_true && g_true <= gb.1 && db.0 <= d_true && d_true <= db.1;
            a.inside.1 += 1;
            a.inside.0 += inside as usize;
            if onset.is_none_or(|t0| t_step < t0 || t_step >= t0 + 1.0) {
                a.inside_after.1 += 1;
                a.inside_after.0 += inside as usize;
            }
            if s.t >= steady_from {
                a.sq_steady_g.0 += (g - g_true).powi(2);
                a.sq_steady_g.1 += 1;
                a.sq_steady_d.0 += (d - d_true).powi(2);
                a.sq_steady_d.1 += 1;
            }
            if let Some(t0) = onset {
                if t_step >= t0 && t_step < t0 + 3.0 {
                    a.sq_3s.0 += (g - g_true).powi(2);
                    a.sq_3s.1 += 1;
                }
                let err = if moves_gamma {
                    (g - g_true).abs() > settings.settle_tol_gamma
                } else {
                    (d - d_true).abs() > settings.settle_tol_delta
                };
                if t_step >= t0 && err {
                    a.last_violation = Some(s.t);
                }
            }
        }
    }
    let rms = |(s, n): (f64, usize)| {
        if n == 0 {
            f64::NAN
        } else {
            (s / n as f64).sqrt()
        }
    };
    let pct = |(i, n): (usize, usize)| {
        if n == 0 {
            f64::NAN
        } else {
            100.0 * i as f64 / n as f64
        }
    };
    let filters = acc
        .into_iter()
        .zip(FILTERS)
        .map(|(a, name)| {
            let ended_violating = a
                .last_violation
                .is_some_and(|t| t >= steps as f64 * dt - 0.5 * dt);
            let settle_s = onset.and_then(|t0| {
                if ended_violating {
                    None
                } else {
                    Some(a.last_violation.map_or(0.0, |t| t - t0))
                }
            });
            FilterRun {
                filter: name,
                metrics: Metrics {
                    detection_delay_s: onset.and_then(|t0| a.first_detection.map(|t| t - t0)),
                    settle_s,
                    gamma_rmse_3s: onset.map(|_| rms(a.sq_3s)),
                    gamma_rmse_steady: rms(a.sq_steady_g),
                    delta_rmse_steady: rms(a.sq_steady_d),
                    truth_in_bounds_pct: pct(a.inside),
                    truth_in_bounds_after_1s_pct: pct(a.inside_after),
                    false_decisions: a.false_decisions,
                    us_per_step: a.nanos as f64 / 1e3 / a.steps.max(1) as f64,
                    step_errors: a.errors,
                    isolated_correct: onset.map(|_| a.first_detection.is_some()),
                    class: None,
                    excitation_low: 0,
                    // The paper's figures are judged on settling (`settle_s`).
                    gamma_off_after_5s_pct: None,
                },
                trace: a.trace,
                decisions: a.decisions,
            }
        })
        .collect();
    Ok(Run {
        scenario: named.name.clone(),
        vehicle: scn.vehicle.clone(),
        seed,
        truth,
        filters,
        final_speed,
    })
}

/// One row of the eval table: one scenario × filter, aggregated over seeds.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Row {
    pub scenario: String,
    pub vehicle: String,
    pub filter: String,
    /// True when every seed isolated the right actuator (null for a healthy flight).
    pub isolated_correct: Option<bool>,
    /// The class every seed reported, or the classes joined by `|` when seeds differ.
    pub class: Option<String>,
    pub excitation_low: u32,
    /// Worst over seeds; null when some seed never detected the fault (or there is none).
    pub detection_delay_s: Option<f64>,
    /// Worst over seeds; null when some seed never settled.
    pub settle_s: Option<f64>,
    /// Means over seeds.
    pub gamma_rmse_3s: Option<f64>,
    pub gamma_rmse_steady: f64,
    pub delta_rmse_steady: f64,
    pub truth_in_bounds_pct: f64,
    /// Lowest over seeds, leaving out the first second after onset.
    pub truth_in_bounds_after_1s_min_pct: f64,
    /// Worst over seeds (vehicle fault scenarios; null otherwise).
    pub gamma_off_after_5s_pct: Option<f64>,
    /// Sum over seeds.
    pub false_decisions: u32,
    pub us_per_step: f64,
    pub step_errors: u64,
    pub seeds: usize,
}

pub fn aggregate(runs: &[Run]) -> Vec<Row> {
    let Some(first) = runs.first() else {
        return vec![];
    };
    let n = runs.len() as f64;
    (0..first.filters.len())
        .map(|i| {
            let ms: Vec<&Metrics> = runs.iter().map(|r| &r.filters[i].metrics).collect();
            let worst = |f: &dyn Fn(&Metrics) -> Option<f64>| -> Option<f64> {
                ms.iter()
                    .map(|m| f(m))
                    .collect::<Option<Vec<f64>>>()
                    .map(|v| v.into_iter().fold(f64::MIN, f64::max))
            };
            let mean = |f: &dyn Fn(&Metrics) -> f64| ms.iter().map(|m| f(m)).sum::<f64>() / n;
            Row {
                scenario: first.scenario.clone(),
                vehicle: first.vehicle.clone(),
                filter: first.filters[i].filter.to_string(),
                isolated_correct: ms
                    .iter()
                    .map(|m| m.isolated_correct)
                    .collect::<Option<Vec<bool>>>()
                    .map(|v| v.iter().all(|b| *b)),
                class: {
                    let mut classes: Vec<String> = Vec::new();
                    for m in &ms {
                        let c = m.class.clone().unwrap_or_else(|| "none".into());
                        if !classes.contains(&c) {
                            classes.push(c);
                        }
                    }
                    if classes == ["none"] {
                        None
                    } else {
                        Some(classes.join("|"))
                    }
                },
                excitation_low: ms.iter().map(|m| m.excitation_low).sum(),
                detection_delay_s: worst(&|m| m.detection_delay_s).map(crate::diagnose::whole_us),
                settle_s: worst(&|m| m.settle_s).map(crate::diagnose::whole_us),
                gamma_rmse_3s: ms
                    .iter()
                    .map(|m| m.gamma_rmse_3s)
                    .collect::<Option<Vec<f64>>>()
                    .map(|v| v.iter().sum::<f64>() / n),
                gamma_rmse_steady: mean(&|m| m.gamma_rmse_steady),
                delta_rmse_steady: mean(&|m| m.delta_rmse_steady),
                truth_in_bounds_pct: mean(&|m| m.truth_in_bounds_pct),
                // NaN (vehicle scenarios do not measure it) stays NaN and prints as "-".
                truth_in_bounds_after_1s_min_pct: ms
                    .iter()
                    .map(|m| m.truth_in_bounds_after_1s_pct)
                    .filter(|v| v.is_finite())
                    .reduce(f64::min)
                    .unwrap_or(f64::NAN),
                gamma_off_after_5s_pct: worst(&|m| m.gamma_off_after_5s_pct),
                false_decisions: ms.iter().map(|m| m.false_decisions).sum(),
                us_per_step: mean(&|m| m.us_per_step),
                step_errors: ms.iter().map(|m| m.step_errors).sum(),
                seeds: runs.len(),
            }
        })
        .collect()
}
