//! One vehicle's processing, from telemetry samples to estimates and decisions. Pure: no I/O,
//! no clocks; replay, the live monitor and tests drive it the same way.
//!
//! Stages, one file each: on the ground nothing is estimated (ground contact is not in the
//! model; `gate.rs` tells take-off and landing). Once the vehicle is airborne and has
//! settled, a healthy stretch (`calibrate_s`, or up to `--calibrate-until`) identifies the
//! vehicle's magnitudes against the profile's geometry (`calibrating.rs`); then both
//! filters and the diagnosis run on every sample (`running.rs`), through the per-step core
//! (`step.rs`) that `eval` runs too.

mod calibrating;
mod commands;
mod fitting;
mod gate;
mod gusts;
mod holes;
mod running;
mod set_bounds;
pub mod step;
#[cfg(test)]
mod tests;

pub use commands::MAX_PWM_US;
pub use gate::FlightGate;
pub use step::{Core, StepInput};

use crate::diagnose::vehicle::gate::AxisFailure;
use crate::diagnose::vehicle::{Decision, DiagnosisParams, Event, Health};
use crate::estimate::vehicle::AhcEstimate;
use crate::model::MAX_ACTUATORS;
use crate::model::calibrate::ScaledFit;
use crate::output::Sink;
use crate::telemetry::detect::Detection;
use crate::telemetry::{Profile, TelemetrySample, VehicleInfo};
use calibrating::StoredSample;
use running::Running;

#[derive(Debug, Clone)]
pub struct PipelineConfig {
    /// `--profile`: used as given, no detection.
    pub profile: Option<Profile>,
    pub diagnosis: DiagnosisParams,
    /// Height above home (m) that counts as airborne, when the vehicle reports it.
    pub airborne_alt_m: f64,
    /// Without a height: armed this long counts as airborne.
    pub armed_airborne_s: f64,
    /// Time after take-off before the healthy stretch starts (the climb-out transient).
    pub settle_s: f64,
    /// Length of the healthy stretch used for calibration.
    pub calibrate_s: f64,
    /// End the healthy stretch at this vehicle time instead (s since boot).
    pub calibrate_until: Option<f64>,
    /// Fit the calibration on a worker thread while the samples that arrive meanwhile wait
    /// (the live monitor: `fitting.rs`); otherwise in place (replay, tests: deterministic).
    pub fit_in_background: bool,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            profile: None,
            diagnosis: DiagnosisParams::default(),
            airborne_alt_m: 1.0,
            armed_airborne_s: 5.0,
            settle_s: 3.0,
            calibrate_s: 20.0,
            calibrate_until: None,
            fit_in_background: false,
        }
    }
}

enum Stage {
    Grounded,
    Calibrating {
        profile: Box<Profile>,
        samples: Vec<StoredSample>,
        /// The same samples as received: the filters run over them once the model is fitted.
        raw: Vec<TelemetrySample>,
    },
    Running(Box<Running>),
    /// The calibration's fit on a worker thread (`fitting.rs`).
    Fitting(Box<fitting::Fitting>),
    /// The profile could not be chosen or the filters not built; said once.
    Failed,
}

/// Counters of the pipeline itself.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct PipelineCounters {
    /// Filter steps (predict and update; coasts are counted in `coasted`).
    pub steps: u64,
    /// Steps and coasts whose filter update failed (the filter was reset).
    pub filter_errors: u64,
    /// Intervals of more than 1.5 sample periods between samples while estimating (lost
    /// samples; a missing a_z leaves one too). The filters coast over the lost periods of a
    /// hole of up to 0.13 s (prediction only, the last outputs held); after a longer one their
    /// rates are re-measured (`reseats`) and the command history restarts.
    pub gaps: u64,
    /// Lost periods the filters coasted over (prediction only, inside the gaps above).
    pub coasted: u64,
    /// Gaps too long to coast over, after which the filters' rates were re-measured.
    pub reseats: u64,
    /// Intervals of more than 1.5 sample periods in the calibration stretch (the steps across
    /// them are left out of the fit).
    pub calibration_gaps: u64,
    /// Samples filled into short holes of a calibration stretch (history for the fit only).
    pub calibration_filled: u64,
    /// Samples without a_z when the model measures it: skipped while estimating, left out of
    /// the a_z fit (not the rates') while calibrating.
    pub missing_az: u64,
    /// Samples dropped because an actuator's output channel carried no PWM (0 or absent) or
    /// not a pulse width (over `MAX_PWM_US`).
    pub missing_output: u64,
    pub decisions: u64,
}

/// With a profile whose model `ahcmon calibrate` identified, the samples collected after the
/// settle before estimating (s): enough to measure the sample period and seed the command
/// history, nothing is fitted.
const AS_IS_SEED_S: f64 = 1.0;

pub struct VehiclePipeline {
    pub sysid: u8,
    cfg: PipelineConfig,
    stage: Stage,
    armed_since: Option<f64>,
    airborne_since: Option<f64>,
    pub detection: Option<Detection>,
    pub fit: Option<ScaledFit>,
    /// The identified discrete model, for `dynamics = "arx"` profiles.
    pub arx: Option<crate::model::calibrate::ArxFit>,
    pub counters: PipelineCounters,
    pub gate: FlightGate,
    /// Detection warnings already said.
    warned: std::collections::BTreeSet<String>,
    /// Last estimates (vehicle time, per filter and actuator), for summaries and dashboards.
    pub last: Option<(f64, [[AhcEstimate; MAX_ACTUATORS]; 3])>,
    /// Vehicle time of the last sample seen (any stage).
    pub last_sample_t: Option<f64>,
    /// A sample on the ground (or disarmed) has been seen: the take-off was watched.
    seen_grounded: bool,
    /// Actuators with a fault in force, by index.
    pub active: [Option<crate::diagnose::vehicle::FaultClass>; MAX_ACTUATORS],
    /// Each actuator's state in the diagnosis' state machine (suspect by S1, S2; cannot
    /// judge by G2; a fault's class is also in `active`).
    pub health: [Health; MAX_ACTUATORS],
    /// Rate axes the calibrated model does not explain (rule G2), from the last calibration;
    /// said once per calibration.
    failing_axes: Vec<AxisFailure>,
    failing_said: bool,
    /// Said once that an output channel carries no PWM.
    warned_missing_output: bool,
    /// The last calibration stretch's data could not support an estimate (`cannot_estimate`,
    /// said; `failure` says why): no failure of the run, the summary says why, as for a log
    /// without a flight.
    unsupported: bool,
    /// The take-off last announced: a calibration retried in the same flight says so instead
    /// (a slow stream's failed fits repeated "airborne at t=49.43 s" five times).
    announced_takeoff: Option<f64>,
    /// Why the run failed (said when it happened; repeated in the summary).
    failure: Option<String>,
    /// The calibration stretch as received, while its model is fitted: the filters start by
    /// running over it (`running::catch_up`).
    stretch: Vec<TelemetrySample>,
    /// What the monitor knew when the vehicle last rebooted (for the summary: `last` and
    /// the faults then in force belong to the boot before).
    pub before_reboot: Option<BeforeReboot>,
}

/// The faults in force when the vehicle last rebooted after estimating.
#[derive(Debug, Clone, Copy)]
pub struct BeforeReboot {
    pub active: [Option<crate::diagnose::vehicle::FaultClass>; MAX_ACTUATORS],
    /// The filters have run since (`last` is the new boot's).
    pub estimated_since: bool,
}

impl VehiclePipeline {
    pub fn new(sysid: u8, cfg: PipelineConfig) -> Self {
        Self {
            sysid,
            cfg,
            stage: Stage::Grounded,
            armed_since: None,
            airborne_since: None,
            detection: None,
            fit: None,
            arx: None,
            counters: PipelineCounters::default(),
            gate: FlightGate::default(),
            warned: std::collections::BTreeSet::new(),
            last: None,
            last_sample_t: None,
            seen_grounded: false,
            active: [None; MAX_ACTUATORS],
            health: [Health::Healthy; MAX_ACTUATORS],
            failing_axes: Vec::new(),
            failing_said: false,
            warned_missing_output: false,
            unsupported: false,
            announced_takeoff: None,
            failure: None,
            stretch: Vec::new(),
            before_reboot: None,
        }
    }

    /// The profile in use, once chosen.
    pub fn profile(&self) -> Option<&Profile> {
        match &self.stage {
            Stage::Calibrating { profile, .. } => Some(profile),
            Stage::Running(r) => Some(&r.core.profile),
            _ => self.detection.as_ref().map(|d| &d.profile),
        }
    }

    /// While calibrating: seconds of healthy flight collected, and how many are wanted
    /// (`None` for the target when it ends at `--calibrate-until`).
    pub fn calibration_progress(&self) -> Option<(f64, Option<f64>)> {
        match &self.stage {
            Stage::Calibrating {
                samples, profile, ..
            } => {
                let done = match (samples.first(), samples.last()) {
                    (Some(a), Some(b)) => b.t - a.t,
                    _ => 0.0,
                };
                Some((done, Self::stretch_s(&self.cfg, profile)))
            }
            _ => None,
        }
    }

    /// Why the run has not estimated anything yet, when it has not (`None` once it has).
    /// `heartbeat`: an autopilot HEARTBEAT was seen (without one the armed flag is unknown).
    pub fn why_not_estimating(&self, heartbeat: bool) -> Option<String> {
        if self.counters.steps > 0 {
            return None;
        }
        if self.unsupported {
            return self.failure.clone();
        }
        // Samples were there but unusable: said first, or the landing (or the end of the
        // data) reads as the cause.
        let airborne = self.gate.longest_airborne_s().max(
            self.airborne_since
                .zip(self.last_sample_t)
                .map_or(0.0, |(a, b)| b - a),
        );
        let unusable = match &self.stage {
            Stage::Calibrating { samples, .. } => samples.is_empty(),
            Stage::Grounded => airborne > 0.0,
            _ => false,
        };
        // Most of them (one glitch in a flight is not the cause).
        if unusable && 2 * self.counters.missing_output >= self.gate.airborne_samples.max(1) {
            return Some(format!(
                "airborne for {airborne:.1} s, but {} samples were dropped for an output channel without a pulse width (said above): the profile has outputs this vehicle does not drive",
                self.counters.missing_output
            ));
        }
        // Still calibrating when the data ended.
        if let Stage::Calibrating {
            samples, profile, ..
        } = &self.stage
        {
            let (first, last) = (samples.first()?.t, samples.last()?.t);
            return Some(match self.cfg.calibrate_until {
                Some(until) => format!(
                    "the calibration stretch was chosen to end at t={until} s, but the data end at t={last:.2} s (it began at t={first:.2} s)"
                ),
                None if profile.identified => format!(
                    "the data end {:.1} s into the {AS_IS_SEED_S} s that measure the sample period before the profile's identified model is used",
                    last - first
                ),
                None => format!(
                    "the data end {:.1} s into the {} s calibration stretch (a shorter one: --calibrate-s)",
                    last - first,
                    self.cfg.calibrate_s
                ),
            });
        }
        if matches!(self.stage, Stage::Failed) {
            return Some(self.failure.clone().unwrap_or_else(|| "failed".into()));
        }
        if !matches!(self.stage, Stage::Grounded) {
            return None;
        }
        let g = &self.gate;
        Some(
            if let (Some((from, to)), Some(until)) = (g.longest_airborne, self.cfg.calibrate_until)
            {
                format!(
                    "airborne for at most {:.1} s (from t={from:.2} s to t={to:.2} s), but the calibration stretch was chosen to end at t={until} s: the vehicle had landed (or the data ended) before then, and a stretch must end in flight",
                    g.longest_airborne_s()
                )
            } else if g.longest_airborne_s() > 0.0 {
                let air = g.longest_airborne_s();
                let shorter = if air < self.cfg.settle_s + self.cfg.calibrate_s {
                    format!(
                        "; a flight this short needs a shorter stretch than {} s: --calibrate-s",
                        self.cfg.calibrate_s
                    )
                } else {
                    String::new()
                };
                format!(
                    "airborne for at most {air:.1} s, and no calibration completed (it starts {} s after take-off; a landing, a reboot or a failed fit, said above, start it over){shorter}",
                    self.cfg.settle_s
                )
            } else if !heartbeat {
                format!(
                    "no autopilot HEARTBEAT in these {} samples, so the vehicle was never known to be armed",
                    g.samples
                )
            } else if g.armed_samples == 0 {
                format!(
                    "the vehicle never armed in these {} samples (HEARTBEAT base_mode); the monitor estimates in flight only",
                    g.samples
                )
            } else if let Some(h) = g.max_rel_alt_armed {
                format!(
                    "armed for up to {:.1} s, but never above {} m relative altitude (highest {h:.1} m), so never taken as airborne",
                    g.longest_armed_s, self.cfg.airborne_alt_m
                )
            } else {
                format!(
                    "armed for up to {:.1} s without a relative altitude; {} s armed counts as airborne",
                    g.longest_armed_s, self.cfg.armed_airborne_s
                )
            },
        )
    }

    /// Stop this vehicle's run: said now, and kept for the summary.
    fn fail(&mut self, why: String, sink: &mut dyn Sink) {
        sink.message(self.sysid, &format!("error: {why}"));
        self.set_stage(Stage::Failed, &why);
        self.failure = Some(why);
    }

    /// The data of a calibration stretch cannot support an estimate: a `cannot_estimate`
    /// decision at `t`, said once (again only after an estimate in between), kept for the
    /// summary; no fault is decided. The next stretch is tried, silently (a live link's rates
    /// may be raised); a stretch the user chose is not.
    fn cannot_estimate(&mut self, t: f64, why: String, sink: &mut dyn Sink) {
        if !std::mem::replace(&mut self.unsupported, true) {
            let d = Decision::monitor(t, self.sysid, Event::CannotEstimate, why.clone());
            sink.decision(&d);
        }
        let why = format!("cannot estimate: {why}");
        if self.cfg.calibrate_until.is_some() {
            self.set_stage(Stage::Failed, &why);
        } else {
            self.set_stage(Stage::Grounded, &why);
        }
        self.failure = Some(why);
    }

    /// Move to another stage, said at debug level with the reason.
    fn set_stage(&mut self, stage: Stage, why: &str) {
        let from = self.stage_name();
        self.stage = stage;
        tracing::debug!(
            "sysid {}: stage {from} -> {} ({why})",
            self.sysid,
            self.stage_name()
        );
    }

    /// How long the stretch stored after the settle lasts (s), when not to `--calibrate-until`:
    /// the calibration's, or with a profile `ahcmon calibrate` identified, only the seconds
    /// that measure the sample period.
    /// Whether `profile`'s identified model is used as it is (see [`Profile::identified`]):
    /// unless `--calibrate-until` asks for a calibration.
    fn as_is(cfg: &PipelineConfig, profile: &Profile) -> bool {
        profile.identified && cfg.calibrate_until.is_none()
    }

    fn stretch_s(cfg: &PipelineConfig, profile: &Profile) -> Option<f64> {
        match cfg.calibrate_until {
            Some(_) => None,
            None if profile.identified => Some(AS_IS_SEED_S),
            None => Some(cfg.calibrate_s),
        }
    }

    /// Why the run failed, once it has (the estimation stopped for good).
    pub fn failed(&self) -> Option<&str> {
        match self.stage {
            Stage::Failed if self.unsupported => None,
            Stage::Failed => Some(self.failure.as_deref().unwrap_or("failed")),
            _ => None,
        }
    }

    pub fn stage_name(&self) -> &'static str {
        match self.stage {
            Stage::Running(_) => "estimating",
            Stage::Grounded | Stage::Calibrating { .. } | Stage::Failed if self.unsupported => {
                "cannot estimate"
            }
            Stage::Grounded => "waiting for flight",
            Stage::Calibrating { .. } | Stage::Fitting(_) => "calibrating",
            Stage::Failed => "failed",
        }
    }

    /// The vehicle rebooted: start over.
    pub fn reset(&mut self, t: f64, sink: &mut dyn Sink) {
        self.settle(sink);
        if let Stage::Running(r) = &self.stage {
            let d = Decision::monitor(t, self.sysid, Event::FilterReset, "vehicle rebooted");
            sink.decision(&d);
            self.counters.decisions += 1;
            // A fault in force is not cleared by a reboot: say so, since the new boot's
            // calibration may take it for the vehicle's normal.
            let faulty: Vec<String> = r
                .core
                .profile
                .actuators
                .iter()
                .zip(&self.active)
                .filter_map(|(a, c)| c.map(|c| format!("{} ({})", a.name, c.as_str())))
                .collect();
            if !faulty.is_empty() {
                sink.message(
                    self.sysid,
                    &format!(
                        "warning: the vehicle rebooted with faults in force: {}; they are not cleared, and the new boot's calibration may take them for normal",
                        faulty.join(", ")
                    ),
                );
            }
        }
        // (A boot that never estimated leaves the one before it as it was.)
        if matches!(self.stage, Stage::Running(_)) {
            self.before_reboot = Some(BeforeReboot {
                active: self.active,
                estimated_since: false,
            });
        }
        self.set_stage(
            Stage::Grounded,
            &format!("the vehicle rebooted at t={t:.2} s"),
        );
        self.armed_since = None;
        self.airborne_since = None;
        self.announced_takeoff = None;
        self.active = [None; MAX_ACTUATORS];
        self.health = [Health::Healthy; MAX_ACTUATORS];
        // The new boot's take-off is watched or not afresh.
        self.seen_grounded = false;
        self.warned.remove(gate::JOINED_WARNING);
    }

    pub fn on_sample(&mut self, s: &TelemetrySample, info: &VehicleInfo, sink: &mut dyn Sink) {
        if let Stage::Fitting(_) = self.stage {
            self.hold(s, info, sink);
            return;
        }
        self.last_sample_t = Some(s.t);
        if !self.airborne(s) {
            self.on_ground(s, info, sink);
            return;
        }
        let since = *self.airborne_since.get_or_insert(s.t);
        if s.t - since >= self.gate.longest_airborne_s() {
            self.gate.longest_airborne = Some((since, s.t));
        }
        match self.stage {
            Stage::Failed => {}
            Stage::Grounded => self.take_off(s, info, since, sink),
            Stage::Calibrating { .. } => self.calibrating(s, sink),
            Stage::Running(_) => self.running(s, sink),
            Stage::Fitting(_) => {}
        }
    }
}
