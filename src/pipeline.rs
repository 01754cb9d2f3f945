//! One vehicle's processing, from telemetry samples to estimates and decisions. Pure: no I/O,
//! no clocks; replay, the live monitor and tests drive it the same way.
//!
//! Stages: on the ground nothing is estimated (ground contact is not in the model). Once the
//! vehicle is airborne and has settled, a healthy stretch (`calibrate_s`, or up to
//! `--calibrate-until`) identifies the vehicle's magnitudes against the profile's geometry
//! ([`calibrate_scaled`]); then both filters and the diagnosis run on every sample.

use crate::diagnose::vehicle::{Decision, Diagnoser, DiagnosisParams, Event};
use crate::estimate::vehicle::{AhcEstimate, VehicleFilters, build};
use crate::model::MAX_ACTUATORS;
use crate::model::calibrate::{CalibrationSample, ScaledFit, calibrate_arx, calibrate_scaled};
use crate::telemetry::detect::{Detection, detect};
use crate::telemetry::profile::Dynamics;
use crate::telemetry::{Profile, TelemetrySample, VehicleInfo};

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
        }
    }
}

/// Where a pipeline's results go.
pub trait PipelineSink {
    fn decision(&mut self, d: &Decision, profile: &Profile);
    /// Every filter step: both filters' estimates per actuator.
    fn estimates(&mut self, _t: f64, _sysid: u8, _est: &[&[AhcEstimate]; 2], _profile: &Profile) {}
    /// Progress and warnings, one line each.
    fn message(&mut self, sysid: u8, text: &str);
    /// A decision about the link rather than an actuator (`link_lost` / `link_restored`).
    fn link_event(&mut self, d: &Decision);
}

#[derive(Clone, Copy)]
struct StoredSample {
    t: f64,
    rates: [f64; 3],
    u: [f64; MAX_ACTUATORS],
    az: Option<f64>,
}

/// Commands kept for an identified model's delay (samples).
const U_HISTORY: usize = crate::telemetry::profile::MAX_ARX_DELAY + 1;
/// Longest hole in the samples the filters coast over, predicting each lost period with the last
/// outputs held (at 50 Hz: up to 5 lost samples). After a longer one the outputs over it are
/// too far from the held ones, and the filters' rates are re-measured instead (`reseat`). On the
/// simulated healthy plane with a hole every 2 s, coasting gave 0 false decisions over 0.12 s
/// holes but 2 over 0.16 s and 7 over 0.2 s ones, re-seating 0 for all; re-seating every hole
/// instead slows detection on a randomly lossy link (20 % of frames lost: the plane's elevator
/// fault found after 4.2 s, median, against 2.2 s). The diagnosis' change test has its own
/// limit, 1 s, to keep its residuals across a hole.
const MAX_COAST_S: f64 = 0.13;
/// Longest command delay the identification considers (s).
const MAX_DELAY_S: f64 = 0.12;
/// Longest interval between two calibration samples, in median sample periods, that still
/// counts as one step: a dropped sample doubles it, and the change over it is not one step's.
const CALIBRATION_MAX_INTERVAL: f64 = 1.5;

struct Running {
    profile: Profile,
    filters: Box<dyn VehicleFilters>,
    diag: Diagnoser,
    dt: f64,
    l: usize,
    m: usize,
    prev_u: Option<[f64; MAX_ACTUATORS]>,
    /// The commands of the last periods (ring) and how many were pushed since take-off or the
    /// last hole too long to coast over (coasts push the held outputs): an identified model
    /// takes them `delay` periods late.
    u_history: [[f64; MAX_ACTUATORS]; U_HISTORY],
    u_pushed: usize,
    delay: usize,
    /// Steps since the last gap (the change test waits until the inputs are measured ones).
    since_gap: usize,
    /// The last two measured rates (identified models take their increment).
    rates_prev: [[f64; 3]; 2],
    exogenous: bool,
    last_t: f64,
    est: [[AhcEstimate; MAX_ACTUATORS]; 2],
    decisions: Vec<Decision>,
    /// Per filter: when its last reset was reported, and resets since (a filter failing step
    /// after step is reported once a second, with the count).
    reset_reported: [(f64, u64); 2],
}

impl Running {
    /// Push the outputs that act over the coming period into the command history; the
    /// filters' input for it: the commands that act now (`delay` periods late; until the
    /// history covers the delay the oldest stands in), then for an identified model the last
    /// rate increment.
    fn push_command(&mut self, u: [f64; MAX_ACTUATORS]) -> [f64; crate::model::MAX_INPUTS] {
        self.u_history[self.u_pushed % U_HISTORY] = u;
        self.u_pushed += 1;
        let back = self.delay.min(self.u_pushed - 1);
        let acting = self.u_history[(self.u_pushed - 1 - back) % U_HISTORY];
        let mut input = [0.0; crate::model::MAX_INPUTS];
        input[..self.l].copy_from_slice(&acting[..self.l]);
        if self.exogenous {
            for i in 0..3 {
                input[self.l + i] = self.rates_prev[1][i] - self.rates_prev[0][i];
            }
        }
        input
    }

    fn n_in(&self) -> usize {
        self.l + if self.exogenous { 3 } else { 0 }
    }
}

enum Stage {
    Grounded,
    Calibrating {
        profile: Box<Profile>,
        samples: Vec<StoredSample>,
    },
    Running(Box<Running>),
    /// The profile could not be chosen or the filters not built; said once.
    Failed,
}

/// What the take-off test saw, to say why a run never started estimating.
#[derive(Debug, Clone, Copy, Default)]
pub struct FlightGate {
    /// Complete samples seen, and those with the vehicle armed.
    pub samples: u64,
    pub armed_samples: u64,
    /// Longest armed stretch (s) and the highest relative altitude while armed (m).
    pub longest_armed_s: f64,
    pub max_rel_alt_armed: Option<f64>,
    /// Longest stretch taken as airborne: its first and last sample times (vehicle clock, s).
    pub longest_airborne: Option<(f64, f64)>,
    /// Samples taken as airborne.
    pub airborne_samples: u64,
}

impl FlightGate {
    /// How long the longest airborne stretch lasted (s); 0 if never airborne.
    pub fn longest_airborne_s(&self) -> f64 {
        self.longest_airborne.map_or(0.0, |(from, to)| to - from)
    }
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
    /// Samples without a_z when the model measures it: skipped while estimating, left out of
    /// the a_z fit (not the rates') while calibrating.
    pub missing_az: u64,
    /// Samples dropped because an actuator's output channel carried no PWM (0 or absent) or
    /// not a pulse width (over `MAX_PWM_US`).
    pub missing_output: u64,
    pub decisions: u64,
}

/// Vehicle seconds since boot after which a first sample already airborne means the monitor
/// joined a flight under way (a real vehicle spends longer than this on the ground between
/// boot and take-off; a simulator starts airborne at boot).
const JOINED_IN_FLIGHT_S: f64 = 30.0;
/// The PWM (µs) on actuator `a`'s output channel in sample `s`; 0 when the sample has none.
fn pwm_of(a: &crate::telemetry::profile::ActuatorSpec, s: &TelemetrySample) -> u16 {
    usize::from(a.channel)
        .checked_sub(1)
        .and_then(|c| s.pwm.get(c))
        .copied()
        .unwrap_or(0)
}

/// Longest output pulse taken as a command (µs): servo and ESC pulses stay within 500-2500;
/// 65535 marks an unused channel.
pub const MAX_PWM_US: f64 = 3000.0;

/// A calibration stretch shorter than this (s) is warned about.
const SHORT_CALIBRATION_S: f64 = 10.0;
/// A sample period (s) over which the stream is said to be too slow: the SITL manoeuvres
/// decimated to 10 Hz are decided as at 50 Hz, at 4 Hz a motor's recovery read as stuck.
const SLOW_PERIOD_S: f64 = 0.105;

/// Rate spread (standard deviation, rad/s) above which a calibration stretch manoeuvred: a
/// steady SITL hover spreads 0.0014, the SITL manoeuvres 0.14-0.26.
const MOVED_RATE_STD: f64 = 0.05;

/// The standard deviation of one rate axis over a calibration stretch.
fn rate_spread(samples: &[CalibrationSample], axis: usize) -> f64 {
    let n = samples.len().max(1) as f64;
    let mean = samples.iter().map(|s| s.rates[axis]).sum::<f64>() / n;
    (samples
        .iter()
        .map(|s| (s.rates[axis] - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}
/// With a profile whose model `ahcmon calibrate` identified, the samples collected after the
/// settle before estimating (s): enough to measure the sample period and seed the command
/// history, nothing is fitted.
const AS_IS_SEED_S: f64 = 1.0;
const JOINED_WARNING: &str = "no take-off seen";

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
    pub last: Option<(f64, [[AhcEstimate; MAX_ACTUATORS]; 2])>,
    /// Vehicle time of the last sample seen (any stage).
    pub last_sample_t: Option<f64>,
    /// A sample on the ground (or disarmed) has been seen: the take-off was watched.
    seen_grounded: bool,
    /// Actuators with a fault in force, by index.
    pub active: [Option<crate::diagnose::vehicle::FaultClass>; MAX_ACTUATORS],
    /// Said once that an output channel carries no PWM.
    warned_missing_output: bool,
    /// Said once that the samples come too slowly.
    warned_slow: bool,
    /// The take-off last announced: a calibration retried in the same flight says so instead
    /// (a slow stream's failed fits repeated "airborne at t=49.43 s" five times).
    announced_takeoff: Option<f64>,
    /// Why the run failed (said when it happened; repeated in the summary).
    failure: Option<String>,
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

/// The calibrated profile's rate and noise levels: the process noise from what the model could
/// not explain on the healthy stretch (rates, then a_z), but never below the profile's: a calm
/// stretch (a still hover) would otherwise make the filters trust the model more than any
/// manoeuvre or fault transient deserves.
fn set_noise_from_fit(calibrated: &mut Profile, residual_std: &[f64], dt: f64) {
    calibrated.rate_hz = (1e3 / dt).round() / 1e3;
    let rates = &residual_std[..3.min(residual_std.len())];
    let rate_sd = (rates.iter().map(|x| x * x).sum::<f64>() / rates.len().max(1) as f64).sqrt();
    calibrated.noise.rate_process = rate_sd.max(calibrated.noise.rate_process);
    if calibrated.model.measure_az
        && let Some(sd) = residual_std.get(3)
    {
        calibrated.noise.az = sd.max(calibrated.noise.az);
    }
}

/// The sample period: the median interval among those near the shortest common one (within
/// half of the lower quartile's either way). A plain median reads a period twice as long when
/// every third sample is lost (intervals 20, 40, 20, 40 ms: the filters then ran 20 ms steps as
/// 40 ms ones); the quartile stands while fewer than three intervals in four span a hole.
fn sample_period(ts: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = ts.collect();
    let mut d: Vec<f64> = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return 0.02;
    }
    d.sort_by(f64::total_cmp);
    let quartile = d[d.len() / 4];
    let near: Vec<f64> = d
        .iter()
        .copied()
        .filter(|x| (0.5 * quartile..=1.5 * quartile).contains(x))
        .collect();
    near[near.len() / 2]
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
            warned_missing_output: false,
            warned_slow: false,
            announced_takeoff: None,
            failure: None,
            before_reboot: None,
        }
    }

    /// The profile in use, once chosen.
    pub fn profile(&self) -> Option<&Profile> {
        match &self.stage {
            Stage::Calibrating { profile, .. } => Some(profile),
            Stage::Running(r) => Some(&r.profile),
            _ => self.detection.as_ref().map(|d| &d.profile),
        }
    }

    /// While calibrating: seconds of healthy flight collected, and how many are wanted
    /// (`None` for the target when it ends at `--calibrate-until`).
    pub fn calibration_progress(&self) -> Option<(f64, Option<f64>)> {
        match &self.stage {
            Stage::Calibrating { samples, profile } => {
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
        if let Stage::Calibrating { samples, profile } = &self.stage {
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
                    "the data end {:.1} s into the {} s calibration stretch",
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
                format!(
                    "airborne for at most {:.1} s, and no calibration completed (it starts {} s after take-off; a landing, a reboot or a failed fit, said above, start it over)",
                    g.longest_airborne_s(),
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
    fn fail(&mut self, why: String, sink: &mut dyn PipelineSink) {
        sink.message(self.sysid, &format!("error: {why}"));
        self.failure = Some(why);
        self.stage = Stage::Failed;
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
            Stage::Failed => Some(self.failure.as_deref().unwrap_or("failed")),
            _ => None,
        }
    }

    pub fn stage_name(&self) -> &'static str {
        match self.stage {
            Stage::Grounded => "waiting for flight",
            Stage::Calibrating { .. } => "calibrating",
            Stage::Running(_) => "estimating",
            Stage::Failed => "failed",
        }
    }

    /// The vehicle rebooted: start over.
    pub fn reset(&mut self, t: f64, sink: &mut dyn PipelineSink) {
        if let Stage::Running(r) = &self.stage {
            let d = Decision::monitor(t, self.sysid, Event::FilterReset, "vehicle rebooted");
            sink.decision(&d, &r.profile);
            self.counters.decisions += 1;
            // A fault in force is not cleared by a reboot: say so, since the new boot's
            // calibration may take it for the vehicle's normal.
            let faulty: Vec<String> = r
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
        self.stage = Stage::Grounded;
        self.armed_since = None;
        self.airborne_since = None;
        self.announced_takeoff = None;
        self.active = [None; MAX_ACTUATORS];
        // The new boot's take-off is watched or not afresh.
        self.seen_grounded = false;
        self.warned.remove(JOINED_WARNING);
    }

    fn airborne(&mut self, s: &TelemetrySample) -> bool {
        self.gate.samples += 1;
        if !s.armed {
            self.armed_since = None;
            return false;
        }
        let since = *self.armed_since.get_or_insert(s.t);
        let g = &mut self.gate;
        g.armed_samples += 1;
        g.longest_armed_s = g.longest_armed_s.max(s.t - since);
        if let Some(h) = s.rel_alt {
            g.max_rel_alt_armed = Some(g.max_rel_alt_armed.map_or(h, |m: f64| m.max(h)));
        }
        let airborne = match s.rel_alt {
            Some(h) => h > self.cfg.airborne_alt_m,
            None => s.t - since >= self.cfg.armed_airborne_s,
        };
        g.airborne_samples += u64::from(airborne);
        airborne
    }

    /// The profile's actuators' commands, normalised; Err(index of the first actuator whose
    /// channel carried no PWM, or not a pulse width).
    fn normalise(profile: &Profile, s: &TelemetrySample) -> Result<[f64; MAX_ACTUATORS], usize> {
        let mut u = [0.0; MAX_ACTUATORS];
        for (j, a) in profile.actuators.iter().enumerate() {
            let pwm = pwm_of(a, s);
            // 0: the channel is unused; 65535 (UINT16_MAX) marks it unused too, and no servo
            // or ESC pulse is longer than MAX_PWM_US.
            if pwm == 0 || f64::from(pwm) > MAX_PWM_US {
                return Err(j);
            }
            u[j] = profile.normalise(j, f64::from(pwm));
        }
        Ok(u)
    }

    /// `normalise`, counting a sample it cannot use and saying so once per run.
    fn commands(
        counters: &mut PipelineCounters,
        warned: &mut bool,
        sysid: u8,
        profile: &Profile,
        s: &TelemetrySample,
        sink: &mut dyn PipelineSink,
    ) -> Option<[f64; MAX_ACTUATORS]> {
        match Self::normalise(profile, s) {
            Ok(u) => Some(u),
            Err(j) => {
                counters.missing_output += 1;
                if !std::mem::replace(warned, true) {
                    let a = &profile.actuators[j];
                    let pwm = pwm_of(a, s);
                    let what = if pwm == 0 {
                        format!("no PWM on output channel {} ({})", a.channel, a.name)
                    } else {
                        format!(
                            "output channel {} ({}) reads {pwm} µs, not a pulse width (over {MAX_PWM_US} µs; 65535 marks an unused channel)",
                            a.channel, a.name
                        )
                    };
                    sink.message(
                        sysid,
                        &format!(
                            "warning: {what}: samples without a pulse width are dropped and counted"
                        ),
                    );
                }
                None
            }
        }
    }

    pub fn on_sample(
        &mut self,
        s: &TelemetrySample,
        info: &VehicleInfo,
        sink: &mut dyn PipelineSink,
    ) {
        self.last_sample_t = Some(s.t);
        let airborne = self.airborne(s);
        if !airborne {
            // Known to be on the ground: disarmed by its heartbeat, or armed at a known low
            // height (not merely not armed long enough, or before the first heartbeat).
            let low = s.rel_alt.is_some_and(|h| h <= self.cfg.airborne_alt_m);
            self.seen_grounded |= info.mav_type.is_some() && (!s.armed || low);
            self.announced_takeoff = None;
            // Where a flight ended, to choose a stretch by (`--calibrate-until`, `calibrate
            // --until`): the take-off was said, the landing was not.
            let flew = self
                .airborne_since
                .take()
                .filter(|since| s.t - since >= self.cfg.settle_s);
            match &mut self.stage {
                Stage::Calibrating { .. } => {
                    sink.message(
                        self.sysid,
                        &format!(
                            "landed at t={:.2} s during calibration; starting over at the next take-off",
                            s.t
                        ),
                    );
                    self.stage = Stage::Grounded;
                }
                Stage::Running(r) => {
                    if let Some(since) = flew {
                        sink.message(
                            self.sysid,
                            &format!("landed at t={:.2} s (airborne from t={since:.2} s)", s.t),
                        );
                    }
                    r.prev_u = None;
                    r.u_pushed = 0;
                    r.since_gap = 0;
                }
                _ => {}
            }
            return;
        }
        let since = *self.airborne_since.get_or_insert(s.t);
        if s.t - since >= self.gate.longest_airborne_s() {
            self.gate.longest_airborne = Some((since, s.t));
        }
        match &mut self.stage {
            Stage::Failed => {}
            Stage::Grounded => {
                if s.t - since < self.cfg.settle_s {
                    return;
                }
                let detection = match &self.cfg.profile {
                    Some(p) => Ok(Detection {
                        profile: p.clone(),
                        warnings: crate::telemetry::detect::given_profile_warnings(p, info),
                        source: format!("{} (--profile)", p.name),
                    }),
                    None => detect(info),
                };
                match detection {
                    Ok(d) => {
                        // Once a run: detection runs again at every take-off until calibrated.
                        for w in &d.warnings {
                            if self.warned.insert(w.clone()) {
                                // The message is prefixed with the sysid already.
                                let prefix = format!("sysid {}: ", self.sysid);
                                let w = w.strip_prefix(&prefix).unwrap_or(w);
                                sink.message(self.sysid, &format!("warning: {w}"));
                            }
                        }
                        let as_is = Self::as_is(&self.cfg, &d.profile);
                        let next = if as_is {
                            "its identified model as it is (no calibration in flight)"
                        } else {
                            "calibrating"
                        };
                        if self.announced_takeoff.replace(since) == Some(since) {
                            sink.message(
                                self.sysid,
                                &format!(
                                    "{next} again from t={:.2} s (in the flight since t={since:.2} s)",
                                    s.t
                                ),
                            );
                        } else {
                            sink.message(
                                self.sysid,
                                &format!(
                                    "airborne at t={since:.2} s; profile {}; {next}",
                                    d.source
                                ),
                            );
                        }
                        // Joined a flight under way (a vehicle up for a while, and no sample
                        // on the ground): whatever it flies with now is taken as healthy. A
                        // simulator's flight starts airborne at boot, and is not warned about.
                        if !self.seen_grounded
                            && !as_is
                            && since >= JOINED_IN_FLIGHT_S
                            && self.warned.insert(JOINED_WARNING.into())
                        {
                            // Without a height, armed long enough counts as airborne: the
                            // vehicle may still be on the ground.
                            let began = self.armed_since.unwrap_or(since);
                            let how = if s.rel_alt.is_some() {
                                "already airborne"
                            } else {
                                "already armed, with no height to tell the ground from the air"
                            };
                            sink.message(
                                self.sysid,
                                &format!(
                                    "warning: {JOINED_WARNING}: the vehicle was {how} when its data began ({began:.0} s after boot). The calibration takes the next stretch as healthy, so a fault already present is calibrated in and not seen; start the monitor before take-off to watch the whole flight"
                                ),
                            );
                        }
                        self.stage = Stage::Calibrating {
                            profile: Box::new(d.profile.clone()),
                            samples: Vec::with_capacity(2048),
                        };
                        self.detection = Some(d);
                    }
                    Err(e) => self.fail(e.to_string(), sink),
                }
            }
            Stage::Calibrating { profile, samples } => {
                let warned = &mut self.warned_missing_output;
                let Some(u) =
                    Self::commands(&mut self.counters, warned, self.sysid, profile, s, sink)
                else {
                    return;
                };
                samples.push(StoredSample {
                    t: s.t,
                    rates: s.rates,
                    u,
                    az: s.az,
                });
                let start = samples[0].t;
                if let Some(until) = self.cfg.calibrate_until
                    && until <= start
                {
                    self.fail(
                        format!(
                            "the calibration stretch was chosen to end at t={until} s, before it can start (airborne and settled at t={start:.2} s): give a later end"
                        ),
                        sink,
                    );
                    return;
                }
                let done = match self.cfg.calibrate_until {
                    Some(until) => s.t >= until,
                    None => {
                        s.t - start >= Self::stretch_s(&self.cfg, profile).unwrap_or(f64::INFINITY)
                    }
                };
                if done {
                    let profile = (**profile).clone();
                    let samples = std::mem::take(samples);
                    self.start_running(profile, &samples, sink);
                }
            }
            Stage::Running(r) => {
                let warned = &mut self.warned_missing_output;
                let Some(u) =
                    Self::commands(&mut self.counters, warned, self.sysid, &r.profile, s, sink)
                else {
                    return;
                };
                let mut y = [0.0; 4];
                y[..3].copy_from_slice(&s.rates);
                if r.m == 4 {
                    match s.az {
                        Some(a) => y[3] = a,
                        None => {
                            // Skipped, before its outputs replace the previous ones: the next
                            // sample follows a gap (last_t stays), and the filters coast over
                            // this period with the outputs that acted in it.
                            self.counters.missing_az += 1;
                            return;
                        }
                    }
                }
                let Some(prev_u) = r.prev_u.replace(u) else {
                    // A new take-off (or the first sample): no residual spans what came before.
                    r.diag.residual_gap();
                    r.last_t = s.t;
                    r.u_pushed = 0;
                    r.since_gap = 0;
                    r.rates_prev = [s.rates; 2];
                    return;
                };
                // The same limit as the calibration's: a lost sample is a gap.
                let span = s.t - r.last_t;
                let gap = span > 1.5 * r.dt;
                // After a hole the filters coast over: the mean rate increment over it, which
                // stands in for the unknown increment of the period ending at the next sample.
                let mut increment_after_hole = None;
                if gap {
                    self.counters.gaps += 1;
                    r.diag.samples_lost(span);
                    r.since_gap = 0;
                    if span <= MAX_COAST_S {
                        // The filters predict over the lost periods, with the last outputs
                        // held, so this measurement meets the state at its own time (stepping
                        // across the hole as one period left its rate change to the gains).
                        let lost = ((span / r.dt).round() as usize).saturating_sub(1);
                        self.counters.coasted += lost as u64;
                        // An identified model's input is the last period's rate increment.
                        // The first lost period's is the last one measured; the rest, and the
                        // two periods that end at this sample and the next, are unknown: each
                        // takes the mean increment over the hole, so that together they add
                        // up to the measured change. (Before: zero over the hole, then the
                        // whole change as one period's increment; on 480 lossy replays of
                        // the two TradHeli SITL logs, 136 had a false decision, now 81.)
                        let last = r.rates_prev[1];
                        let mean: [f64; 3] =
                            std::array::from_fn(|i| (s.rates[i] - last[i]) / (lost + 1) as f64);
                        let after_first = [last, std::array::from_fn(|i| last[i] + mean[i])];
                        for c in 0..lost {
                            let input = r.push_command(prev_u);
                            let res = r.filters.coast(&input[..r.n_in()]);
                            Self::reset_failed(&mut self.counters, self.sysid, r, s.t, &res, sink);
                            if c == 0 {
                                r.rates_prev = after_first;
                            }
                        }
                        increment_after_hole = Some(mean);
                    } else {
                        // A long outage: the outputs over it are unknown, so the rates are
                        // re-measured rather than predicted (stepped across as one period, the
                        // rate change over the hole read as an actuator fault), and the command
                        // history starts over. This sample only re-seats the filters.
                        r.filters.reseat(&s.rates, (span / r.dt).round());
                        self.counters.reseats += 1;
                        r.last_t = s.t;
                        r.u_pushed = 0;
                        r.rates_prev = [s.rates; 2];
                        return;
                    }
                }
                r.last_t = s.t;
                // The outputs sent at the previous instant act until this one.
                let input = r.push_command(prev_u);
                let n_in = r.n_in();
                let rates_before = r.rates_prev[1];
                r.rates_prev = match increment_after_hole {
                    // The next increment is the hole's mean too (see above).
                    Some(mean) => [std::array::from_fn(|i| s.rates[i] - mean[i]), s.rates],
                    None => [r.rates_prev[1], s.rates],
                };
                let back = r.delay.min(r.u_pushed - 1);
                let prev_u = r.u_history[(r.u_pushed - 1 - back) % U_HISTORY];
                let res = r.filters.step(&input[..n_in], &y[..r.m]);
                r.since_gap += 1;
                // Only once the commands that acted and the increment are measured ones, one
                // period apart (after a gap or take-off the delayed commands are held outputs or
                // stand-ins for `delay` steps, and an identified model's increment spans the gap
                // for one more).
                let own_inputs = r.since_gap > (r.delay + 1).max(if r.exogenous { 2 } else { 0 });
                if !gap && own_inputs {
                    let residual =
                        r.filters
                            .healthy_residual(&rates_before, &input[..n_in], &y[..r.m]);
                    r.diag.observe(s.t, &residual, &prev_u[..r.l]);
                }
                self.counters.steps += 1;
                Self::reset_failed(&mut self.counters, self.sysid, r, s.t, &res, sink);
                for f in 0..2 {
                    for j in 0..r.l {
                        r.est[f][j] = r.filters.ahc(f, j);
                    }
                }
                let views = [&r.est[0][..r.l], &r.est[1][..r.l]];
                r.decisions.clear();
                r.diag.update(s.t, &prev_u[..r.l], &views, &mut r.decisions);
                for f in 0..2 {
                    for j in 0..r.l {
                        r.est[f][j].deviation = r.diag.deviation(f, j);
                        r.est[f][j].excursion = r.diag.excursion(f, j);
                        r.est[f][j].gain_gap = r.diag.gain_gap(f, j);
                    }
                }
                let views = [&r.est[0][..r.l], &r.est[1][..r.l]];
                sink.estimates(s.t, self.sysid, &views, &r.profile);
                for d in &r.decisions {
                    sink.decision(d, &r.profile);
                    self.counters.decisions += 1;
                }
                r.diag
                    .steer_filters(&r.decisions, &r.profile, r.filters.as_mut());
                for j in 0..r.l {
                    self.active[j] = r.diag.active(j);
                }
                self.last = Some((s.t, r.est));
                if let Some(b) = &mut self.before_reboot {
                    b.estimated_since = true;
                }
            }
        }
    }

    /// A filter whose step (or coast) failed is re-initialised; said once a second, with the
    /// count since the last report.
    fn reset_failed(
        counters: &mut PipelineCounters,
        sysid: u8,
        r: &mut Running,
        t: f64,
        res: &[Result<(), crate::estimate::EstimatorError>; 2],
        sink: &mut dyn PipelineSink,
    ) {
        for (f, out) in res.iter().enumerate() {
            if out.is_ok() {
                continue;
            }
            counters.filter_errors += 1;
            r.filters.reset(f);
            // The fresh filter reads healthy at once: the diagnosis holds that filter's alarms
            // through a warm-up instead of clearing on it.
            r.diag.filter_reset(f, t);
            let (last, since) = &mut r.reset_reported[f];
            *since += 1;
            if t - *last >= 1.0 {
                let name = crate::estimate::vehicle::FILTER_NAMES[f];
                let detail = if *since > 1 {
                    format!("{name} update failed; reset ({since} resets since the last report)")
                } else {
                    format!("{name} update failed; reset")
                };
                let d = Decision::monitor(t, sysid, Event::FilterReset, detail);
                sink.decision(&d, &r.profile);
                counters.decisions += 1;
                (*last, *since) = (t, 0);
            }
        }
    }

    /// The calibration stretch was unusable (too short, too many holes): not the vehicle, so
    /// the next stretch may do; a stretch the user chose is not retried.
    fn calibration_failed(&mut self, why: String, sink: &mut dyn PipelineSink) {
        if self.cfg.calibrate_until.is_some() {
            self.fail(format!("calibration failed: {why}"), sink);
        } else {
            sink.message(
                self.sysid,
                &format!("calibration failed: {why}; trying again on the next stretch"),
            );
            self.stage = Stage::Grounded;
        }
    }

    fn start_running(
        &mut self,
        profile: Profile,
        samples: &[StoredSample],
        sink: &mut dyn PipelineSink,
    ) {
        let dt = sample_period(samples.iter().map(|s| s.t));
        if dt > SLOW_PERIOD_S && !std::mem::replace(&mut self.warned_slow, true) {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the samples come at {:.1} Hz (ATTITUDE with outputs every {:.0} ms): under 10 Hz the filters follow an actuator loosely and a class may be wrong; raise the stream rates (the ground station's, ArduPilot's SRn_/MAVn_ parameters, or --request-rates)",
                    1.0 / dt,
                    dt * 1e3
                ),
            );
        }
        let l = profile.actuators.len();
        let mut profile = profile;
        // a_z is measured if the vehicle sends an IMU with most samples; those without it are
        // left out and counted (a link that lost one RAW_IMU in ten or more used to switch the whole
        // run to rates only, leaving a multirotor's thrust direction unobserved).
        let with_az = samples.iter().filter(|s| s.az.is_some()).count();
        if profile.model.measure_az && with_az * 2 < samples.len() {
            let why = if with_az == 0 {
                "no IMU acceleration with the rates (HIGHRES_IMU / SCALED_IMU / RAW_IMU)"
                    .to_string()
            } else {
                format!(
                    "IMU acceleration with only {with_az} of {} calibration samples",
                    samples.len()
                )
            };
            sink.message(self.sysid, &format!("{why}; estimating from rates only"));
            profile.model.measure_az = false;
        }
        // An identified model predicts the rates only: a static a_z row cannot follow a
        // helicopter's vertical manoeuvres (R² below 0.2 on the TradHeli SITL even with the
        // vertical speed) and its errors, slow and correlated with the manoeuvre, pulled the
        // swash servos' estimates off by up to 0.5 (measured). Isolation works in the observable
        // space instead, where what rates cannot see is never blamed on one actuator.
        if profile.model.dynamics == Dynamics::Arx && profile.model.measure_az {
            profile.model.measure_az = false;
        }
        if Self::as_is(&self.cfg, &profile) {
            self.run_identified(profile, samples, dt, sink);
            return;
        }
        // The outputs of sample k act until sample k+1: pair each rate with the previous outputs.
        // A pair whose interval is not one period (a dropped or late sample, a link gap) is left
        // out; the next pair then starts a new run, so no fit row spans the hole. A sample
        // without a_z still serves the rate axes (left out of the rates' runs, one IMU message
        // lost in ten halved the rows the wind-robust fit could use and biased a gusty quad's
        // roll factor from 1.04 to 0.75) and is only left out of the a_z fit.
        let measure_az = profile.model.measure_az;
        let mut shifted: Vec<CalibrationSample> = Vec::with_capacity(samples.len());
        let (mut kept_previous, mut gaps) = (false, 0u64);
        // Each kept sample's position in periods: one after a kept predecessor, else as many as
        // passed (rounded, at least one).
        let mut last_kept: Option<(f64, u64)> = None;
        for w in samples.windows(2) {
            let interval = w[1].t - w[0].t;
            let regular = interval > 0.0 && interval <= CALIBRATION_MAX_INTERVAL * dt;
            gaps += u64::from(!regular);
            let az = if measure_az { w[1].az } else { None };
            let keep = regular;
            self.counters.missing_az += u64::from(regular && measure_az && az.is_none());
            if keep {
                let step = match last_kept {
                    None => 0,
                    Some((_, step)) if kept_previous => step + 1,
                    Some((t, step)) => step + (((w[1].t - t) / dt).round() as u64).max(1),
                };
                last_kept = Some((w[1].t, step));
                shifted.push(CalibrationSample {
                    rates: w[1].rates,
                    u: &w[0].u[..l],
                    az,
                    follows_previous: kept_previous,
                    step,
                });
            }
            kept_previous = keep;
        }
        if gaps > 0 {
            self.counters.calibration_gaps += gaps;
            sink.message(
                self.sysid,
                &format!(
                    "calibration: {gaps} gaps in the telemetry (intervals over {CALIBRATION_MAX_INTERVAL} sample periods, or not increasing); the fit leaves out the steps across them"
                ),
            );
        }
        let base = profile.rate_params();
        // Too few usable samples where the stretch had many: the holes left too few runs.
        let holes_note = |e: &crate::model::calibrate::CalibrationError| match e {
            crate::model::calibrate::CalibrationError::TooFew { .. } if gaps > 0 => format!(
                "; the stretch had {} samples, but a fit row spans consecutive ones and its {gaps} gaps leave too few unbroken runs (the link loses too many)",
                samples.len()
            ),
            // In flight time, which a stretch is chosen by.
            crate::model::calibrate::CalibrationError::TooFew { need, .. } => format!(
                " (at a sample every {:.0} ms: {:.1} s of flight after the {} s settle)",
                dt * 1e3,
                *need as f64 * dt,
                self.cfg.settle_s
            ),
            _ => String::new(),
        };
        let identified = if profile.model.dynamics == Dynamics::Arx {
            // Above ~58 Hz the history, not MAX_DELAY_S, bounds the delay searched.
            let max_delay = ((MAX_DELAY_S / dt).round() as usize).min(U_HISTORY - 1);
            match calibrate_arx(&shifted, dt, max_delay, &base) {
                Ok(f) => Some(f),
                // On a stretch with many holes (over one interval in twenty) the scaled
                // geometry, fitted on the same holes, is no fallback (TradHeli SITL logs with
                // one ATTITUDE in five lost, or one in five at random: roll x0.17, R² -2.1, and
                // up to 25 false decisions before the onset). The next stretch may do better.
                Err(e) if gaps * 20 > samples.len() as u64 => {
                    let why = match holes_note(&e) {
                        note if !note.is_empty() => format!("the identified model needs {e}{note}"),
                        _ => format!(
                            "the identified model failed ({e}) on a stretch with {gaps} gaps in {} samples (the link loses too many)",
                            samples.len()
                        ),
                    };
                    self.calibration_failed(why, sink);
                    return;
                }
                Err(e) => {
                    sink.message(
                        self.sysid,
                        &format!(
                            "warning: the identified model failed ({e}{}); using the profile's geometry, scaled per axis",
                            holes_note(&e)
                        ),
                    );
                    None
                }
            }
        } else {
            None
        };
        // Rate axes the model fits worse than a constant would: a profile that is not this
        // vehicle's, or a stretch that was not healthy flight (an offset-only axis, which a
        // steady hover does not excite, has little to explain and passes down to R² = -1).
        let mut poor: Vec<String> = Vec::new();
        let mut unexplained: Vec<(&str, f64)> = Vec::new();
        let (calibrated, fit, summary) = if let Some(arx) = identified {
            let mut calibrated = profile.clone();
            set_noise_from_fit(&mut calibrated, &arx.quality.residual_std, dt);
            let axes = ["roll", "pitch", "yaw", "a_z"];
            let mut parts: Vec<String> = arx.quality.r_squared[..3]
                .iter()
                .enumerate()
                .map(|(i, r2)| format!("{} increment R²={r2:.2}", axes[i]))
                .collect();
            if let Some(r2) = arx.quality.r_squared.get(3) {
                let how = if arx.vertical_scaled {
                    "scaled"
                } else {
                    "offset only"
                };
                parts.push(format!("a_z {how} R²={r2:.2}"));
            }
            for (i, r2) in arx.quality.r_squared[..3].iter().enumerate() {
                if *r2 < 0.0 {
                    poor.push(format!("{} R²={r2:.2}", axes[i]));
                }
            }
            let summary = format!(
                "identified model, command delay {} ms: {}",
                (arx.params.delay as f64 * dt * 1e3).round(),
                parts.join(", ")
            );
            calibrated.model.arx = Some(arx.params.clone());
            self.arx = Some(arx);
            (calibrated, None, summary)
        } else {
            let fit = match calibrate_scaled(&shifted, dt, &base) {
                Ok(f) => f,
                Err(e) => {
                    self.calibration_failed(format!("{e}{}", holes_note(&e)), sink);
                    return;
                }
            };
            let mut calibrated = profile.with_rate_params(&fit.params);
            set_noise_from_fit(&mut calibrated, &fit.quality.residual_std, dt);
            let axes = ["roll", "pitch", "yaw", "a_z"];
            for (i, (axis, (r2, scaled))) in axes
                .iter()
                .zip(fit.quality.r_squared.iter().zip(&fit.scaled))
                .take(3)
                .enumerate()
            {
                if *r2 < if *scaled { 0.0 } else { -1.0 } {
                    poor.push(format!("{axis} R²={r2:.2}"));
                }
                // Left offset-only though the vehicle manoeuvred: the commands did not explain
                // its motion on this geometry (a fault in the stretch, or another frame).
                let spread = rate_spread(&shifted, i);
                if !scaled && spread >= MOVED_RATE_STD {
                    unexplained.push((axis, spread));
                }
            }
            let summary: Vec<String> = fit
                .scaled
                .iter()
                .enumerate()
                .map(|(i, sc)| {
                    format!(
                        "{} {} R²={:.2}",
                        axes[i],
                        if *sc {
                            format!("x{:.2}", fit.scale[i])
                        } else {
                            "offset only".into()
                        },
                        fit.quality.r_squared[i]
                    )
                })
                .collect();
            (calibrated, Some(fit), summary.join(", "))
        };
        let span = samples.last().map_or(0.0, |s| s.t) - samples[0].t;
        sink.message(
            self.sysid,
            &format!(
                "calibrated on {span:.1} s ({} samples, dt {:.1} ms): {}",
                samples.len(),
                dt * 1e3,
                summary
            ),
        );
        if !poor.is_empty() {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the model fits {} worse than a constant: the profile ({}) may not be this vehicle's, or the stretch was not healthy flight; its estimates and decisions are not to be trusted",
                    poor.join(", "),
                    calibrated.name
                ),
            );
        }
        if !unexplained.is_empty() {
            sink.message(
                self.sysid,
                &format!(
                    "warning: {} moved (rate spread {} rad/s) but the commands do not explain that motion on the geometry of {}: the calibration stretch may hold a fault, or the profile may not be this vehicle's; its estimates and decisions are not to be trusted",
                    unexplained
                        .iter()
                        .map(|(a, _)| *a)
                        .collect::<Vec<_>>()
                        .join(" and "),
                    unexplained
                        .iter()
                        .map(|(_, s)| format!("{s:.2}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    calibrated.name
                ),
            );
        }
        // A stretch cut short (by --calibrate-until / --calibrate-s) still fits, but loosely.
        if span < SHORT_CALIBRATION_S {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the calibration stretch is only {span:.1} s (the default is 20 s from {} s after take-off): a short stretch leaves the model loose, and healthy actuators may read off",
                    self.cfg.settle_s
                ),
            );
        }
        self.run_with(calibrated, fit, samples, dt, sink);
    }

    /// A profile `ahcmon calibrate` wrote: its model is this vehicle's, identified on a healthy
    /// stretch, and is used as it is (a fault present from the take-off is then seen, where a
    /// calibration in flight would take it as the vehicle's normal).
    fn run_identified(
        &mut self,
        profile: Profile,
        samples: &[StoredSample],
        dt: f64,
        sink: &mut dyn PipelineSink,
    ) {
        // A helicopter's discrete model holds only at the rate it was identified at (the filters
        // refuse one more than 5 % off): calibrate in flight instead, on the samples so far.
        if let Some(arx) = &profile.model.arx
            && (arx.dt - dt).abs() > crate::model::ARX_DT_TOLERANCE * dt
        {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the telemetry comes every {:.1} ms, the profile's identified model is for {:.1} ms: calibrating in flight instead ({} s)",
                    dt * 1e3,
                    arx.dt * 1e3,
                    self.cfg.calibrate_s
                ),
            );
            let mut profile = profile;
            profile.identified = false;
            self.stage = Stage::Calibrating {
                profile: Box::new(profile),
                samples: samples.to_vec(),
            };
            return;
        }
        let expected = 1.0 / profile.rate_hz;
        if ((dt - expected) / expected).abs() > 0.1 {
            sink.message(
                self.sysid,
                &format!(
                    "warning: the telemetry comes every {:.1} ms, the profile's model was identified at {:.1} ms: its noise levels (and a helicopter's discrete model) are for another rate; calibrate at this rate (ahcmon calibrate, or --calibrate-until)",
                    dt * 1e3,
                    expected * 1e3
                ),
            );
        }
        sink.message(
            self.sysid,
            &format!(
                "estimating with the profile's identified model ({}), not calibrated in flight",
                profile.name
            ),
        );
        self.run_with(profile, None, samples, dt, sink);
    }

    /// Build the filters and the diagnosis on `calibrated` and start estimating, seeded with
    /// the end of the stored stretch.
    fn run_with(
        &mut self,
        calibrated: Profile,
        fit: Option<ScaledFit>,
        samples: &[StoredSample],
        dt: f64,
        sink: &mut dyn PipelineSink,
    ) {
        let l = calibrated.actuators.len();
        let filters = match build(&calibrated, dt) {
            Ok(f) => f,
            Err(e) => {
                self.fail(e.to_string(), sink);
                return;
            }
        };
        let m = filters.measurements();
        let exogenous = filters.inputs() > l;
        let delay = calibrated.model.arx.as_ref().map_or(0, |a| a.delay);
        let diag = Diagnoser::new(self.cfg.diagnosis, self.sysid, &calibrated, dt);
        self.fit = fit;
        let last = samples.last().map(|s| (s.t, s.u));
        // Seed the command history and the last rates with the end of the healthy stretch.
        let mut u_history = [[0.0; MAX_ACTUATORS]; U_HISTORY];
        let tail = &samples[samples.len().saturating_sub(U_HISTORY)..];
        // The newest stored command becomes `prev_u`; the ones before it are history.
        let older = &tail[..tail.len().saturating_sub(1)];
        for (k, s) in older.iter().enumerate() {
            u_history[k] = s.u;
        }
        let n = samples.len();
        let rates_prev = if n >= 2 {
            [samples[n - 2].rates, samples[n - 1].rates]
        } else {
            [[0.0; 3]; 2]
        };
        self.stage = Stage::Running(Box::new(Running {
            profile: calibrated,
            filters,
            diag,
            dt,
            l,
            m,
            prev_u: last.map(|l| l.1),
            u_history,
            u_pushed: older.len(),
            since_gap: older.len(),
            delay,
            rates_prev,
            exogenous,
            last_t: last.map_or(0.0, |l| l.0),
            reset_reported: [(f64::NEG_INFINITY, 0); 2],
            est: [[AhcEstimate::default(); MAX_ACTUATORS]; 2],
            decisions: Vec::with_capacity(8),
        }));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One sample in three lost: intervals 20, 40, 20, 40 ms, whose median could be 40.
    #[test]
    fn the_sample_period_is_the_short_interval_when_every_third_sample_is_lost() {
        let t: Vec<f64> = (0..300)
            .filter(|k| k % 3 != 2)
            .map(|k| k as f64 * 0.02)
            .collect();
        assert!((sample_period(t.iter().copied()) - 0.02).abs() < 1e-12);
        // With jitter and no loss, the median interval.
        let t: Vec<f64> = (0..300)
            .map(|k| k as f64 * 0.02 + if k % 2 == 0 { 0.001 } else { 0.0 })
            .collect();
        let p = sample_period(t.iter().copied());
        assert!((p - 0.021).abs() < 1e-9 || (p - 0.019).abs() < 1e-9, "{p}");
    }
    use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};

    #[derive(Debug, Default)]
    struct Messages(Vec<String>);
    impl PipelineSink for Messages {
        fn decision(&mut self, _: &Decision, _: &Profile) {}
        fn message(&mut self, _: u8, text: &str) {
            self.0.push(text.to_owned());
        }
        fn link_event(&mut self, _: &Decision) {}
    }

    /// What happens to one sample on its way.
    #[derive(Debug, Clone, Copy, PartialEq)]
    enum Damage {
        Intact,
        Lost,
        NoAz,
        NoPwm,
        /// The channel reads 65535, the unused marker (it had been taken as a command of 10.7).
        UnusedMarker,
    }

    /// Flies the simulated quad through the pipeline, `damage(k, estimating)` deciding what
    /// happens to sample k. Returns the pipeline, its messages and the samples lost while
    /// calibrating.
    fn fly_quad_with(damage: impl Fn(usize, bool) -> Damage) -> (VehiclePipeline, Messages, u64) {
        fly_quad_for(2000, |k, stage| {
            damage(k, matches!(stage, Stage::Running(_)))
        })
    }

    /// `fly_quad_with` for `steps` samples, `damage` seeing the stage.
    fn fly_quad_for(
        steps: usize,
        damage: impl Fn(usize, &Stage) -> Damage,
    ) -> (VehiclePipeline, Messages, u64) {
        let profile = Profile::resolve("quad-x").unwrap();
        let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, 3)).unwrap();
        let cfg = PipelineConfig {
            profile: Some(profile.clone()),
            ..PipelineConfig::default()
        };
        let mut pipeline = VehiclePipeline::new(1, cfg);
        let mut sink = Messages::default();
        let info = VehicleInfo::default();
        let mut lost_in_stretch = 0;
        for k in 0..steps {
            let s = sim.step();
            let d = damage(k, &pipeline.stage);
            if d == Damage::Lost {
                let calibrating = matches!(pipeline.stage, Stage::Calibrating { .. });
                lost_in_stretch += u64::from(calibrating);
                continue;
            }
            let mut pwm = [0u16; 16];
            for (j, a) in profile.actuators.iter().enumerate() {
                pwm[usize::from(a.channel) - 1] = profile.to_pwm(j, s.u[j]).round() as u16;
            }
            match d {
                Damage::NoPwm => pwm[2] = 0,
                Damage::UnusedMarker => pwm[2] = u16::MAX,
                _ => {}
            }
            let sample = TelemetrySample {
                t: s.t,
                rates: [s.y[0], s.y[1], s.y[2]],
                attitude: s.attitude,
                az: (profile.model.measure_az && d != Damage::NoAz).then_some(s.y[3]),
                pwm,
                armed: true,
                rel_alt: Some(10.0),
            };
            pipeline.on_sample(&sample, &info, &mut sink);
        }
        (pipeline, sink, lost_in_stretch)
    }

    /// With `lossy`, one sample in ten never arrives.
    fn fly_quad(lossy: bool) -> (VehiclePipeline, Messages, u64) {
        fly_quad_with(|k, _| {
            if lossy && k % 10 == 9 {
                Damage::Lost
            } else {
                Damage::Intact
            }
        })
    }

    /// While estimating: every lost sample and every sample without a_z leaves a counted gap
    /// (the next step does not pretend to follow the previous one); a sample whose actuator
    /// channel carries no PWM (or the unused marker) is counted and said once.
    #[test]
    fn estimating_counts_lost_samples_missing_az_and_missing_outputs() {
        let damage = |k: usize, estimating: bool| match k % 50 {
            _ if !estimating => Damage::Intact,
            7 => Damage::Lost,
            21 => Damage::NoAz,
            33 => Damage::NoPwm,
            41 => Damage::UnusedMarker,
            _ => Damage::Intact,
        };
        let (clean, _, _) = fly_quad(false);
        let (p, said, _) = fly_quad_with(damage);
        assert!(matches!(p.stage, Stage::Running(_)), "{:?}", said.0);
        assert_eq!(clean.counters.gaps, 0);
        let c = p.counters;
        let each = c.missing_az;
        assert!(each >= 5, "{c:?}");
        assert_eq!(c.missing_output, 2 * each, "{c:?}");
        // One gap after each lost sample, each sample without a_z and each without outputs.
        assert_eq!(c.gaps, 4 * each, "{c:?}");
        // And no filter step for any of them: the filters coast over each period.
        assert_eq!(clean.counters.steps - c.steps, 4 * each, "{c:?}");
        assert_eq!(c.coasted, 4 * each, "{c:?}");
        assert_eq!(clean.counters.coasted, 0);
        assert_eq!(c.filter_errors, 0, "{c:?}");
        let warnings: Vec<_> = said.0.iter().filter(|m| m.contains("no PWM")).collect();
        assert_eq!(warnings.len(), 1, "{:?}", said.0);
        assert!(warnings[0].contains("channel 3"), "{}", warnings[0]);
    }

    /// The filters coast over each period of a short hole (5 samples, 0.12 s between the
    /// samples either side), and not over a long one (25 samples, 0.52 s): after that one their
    /// rates are re-measured, as the held outputs are too far from what the autopilot sent.
    #[test]
    fn short_holes_are_coasted_over_and_long_ones_reseat_the_rates() {
        let lost = std::cell::RefCell::new(vec![]);
        let (p, said, _) = fly_quad_with(|k, estimating| match k % 200 {
            _ if !estimating => Damage::Intact,
            100..125 | 150..155 => {
                lost.borrow_mut().push(k);
                Damage::Lost
            }
            _ => Damage::Intact,
        });
        assert!(matches!(p.stage, Stage::Running(_)), "{:?}", said.0);
        // The holes while estimating (the first may have begun before), by length.
        let mut holes: Vec<usize> = vec![];
        for (i, k) in lost.borrow().iter().enumerate() {
            if i > 0 && lost.borrow()[i - 1] + 1 == *k {
                *holes.last_mut().unwrap() += 1;
            } else {
                holes.push(1);
            }
        }
        // Coasted: a hole of n lost samples spans (n + 1) periods; up to 0.13 s, n <= 5.
        let short = holes.iter().filter(|n| **n <= 5).count();
        assert!(
            short >= 3 && holes.iter().filter(|n| **n == 25).count() >= 3,
            "{holes:?}"
        );
        let c = p.counters;
        assert_eq!(c.gaps, holes.len() as u64, "{c:?} {holes:?}");
        let coasted: usize = holes.iter().filter(|n| **n <= 5).sum();
        assert_eq!(c.coasted, coasted as u64, "{c:?} {holes:?}");
        assert_eq!(c.reseats, (holes.len() - short) as u64, "{c:?} {holes:?}");
        assert_eq!(c.filter_errors, 0, "{c:?}");
    }

    /// Records the inputs the pipeline gives the filters (`true` for a coast) and passes the
    /// commands on.
    use crate::estimate::EstimatorError;
    use crate::estimate::vehicle::{Identified, IdentifiedKind};

    /// Each input the filters were given, and whether it was a coast's.
    type InputLog = std::sync::Arc<std::sync::Mutex<Vec<(bool, Vec<f64>)>>>;

    struct Recorder {
        inner: Box<dyn VehicleFilters>,
        inputs: InputLog,
    }
    impl VehicleFilters for Recorder {
        fn actuators(&self) -> usize {
            self.inner.actuators()
        }
        fn inputs(&self) -> usize {
            self.inner.inputs() + 3
        }
        fn measurements(&self) -> usize {
            self.inner.measurements()
        }
        fn step(&mut self, u: &[f64], y: &[f64]) -> [Result<(), EstimatorError>; 2] {
            self.inputs.lock().unwrap().push((false, u.to_vec()));
            self.inner.step(&u[..self.inner.inputs()], y)
        }
        fn coast(&mut self, u: &[f64]) -> [Result<(), EstimatorError>; 2] {
            self.inputs.lock().unwrap().push((true, u.to_vec()));
            self.inner.coast(&u[..self.inner.inputs()])
        }
        fn reseat(&mut self, rates: &[f64; 3], periods: f64) {
            self.inner.reseat(rates, periods)
        }
        fn ahc(&self, filter: usize, j: usize) -> AhcEstimate {
            self.inner.ahc(filter, j)
        }
        fn healthy_residual(&self, rates_prev: &[f64; 3], u: &[f64], y: &[f64]) -> [f64; 4] {
            self.inner
                .healthy_residual(rates_prev, &u[..self.inner.inputs()], y)
        }
        fn nis(&self, filter: usize) -> f64 {
            self.inner.nis(filter)
        }
        fn reset(&mut self, filter: usize) {
            self.inner.reset(filter)
        }
        fn forget(&mut self, j: usize) {
            self.inner.forget(j)
        }
        fn set_fault_in_force(&mut self, in_force: bool) {
            self.inner.set_fault_in_force(in_force)
        }
        fn hold_class(&mut self, j: usize, identified: Option<Identified>) {
            self.inner.hold_class(j, identified)
        }
        fn awaits_identification(&self, j: usize) -> bool {
            self.inner.awaits_identification(j)
        }
        fn recovered(&mut self, j: usize) {
            self.inner.recovered(j)
        }
        fn class_in_force(&mut self, j: usize, kind: Option<IdentifiedKind>) {
            self.inner.class_in_force(j, kind)
        }
    }

    /// An identified model's rate-increment input over a hole of two lost samples: the first
    /// lost period takes the last increment measured; the second, and the periods ending at the
    /// next two samples, each take the mean increment over the hole, so the four add up to the
    /// measured change; then measured increments again.
    #[test]
    fn an_identified_model_takes_the_mean_rate_increment_over_a_hole() {
        let (mut p, said, _) = fly_quad_for(1500, |_, _| Damage::Intact);
        let Stage::Running(r) = &mut p.stage else {
            panic!("{:?}", said.0);
        };
        let inputs = InputLog::default();
        let inner = std::mem::replace(
            &mut r.filters,
            crate::estimate::vehicle::build(&r.profile, r.dt).unwrap(),
        );
        r.filters = Box::new(Recorder {
            inner,
            inputs: inputs.clone(),
        });
        // The quad's model takes no increment; this one does, so the increments are fed.
        r.exogenous = true;
        let l = r.l;
        let profile = r.profile.clone();
        let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, 4)).unwrap();
        let mut sink = Messages::default();
        let mut rates = vec![];
        for k in 0..12 {
            let s = sim.step();
            // Shifted past the flight so far, so that time runs on.
            let t = s.t + 40.0;
            rates.push([s.y[0], s.y[1], s.y[2]]);
            if k == 5 || k == 6 {
                continue;
            }
            let mut pwm = [0u16; 16];
            for (j, a) in profile.actuators.iter().enumerate() {
                pwm[usize::from(a.channel) - 1] = profile.to_pwm(j, s.u[j]).round() as u16;
            }
            let sample = TelemetrySample {
                t,
                rates: rates[k],
                attitude: s.attitude,
                az: Some(s.y[3]),
                pwm,
                armed: true,
                rel_alt: Some(10.0),
            };
            p.on_sample(&sample, &VehicleInfo::default(), &mut sink);
        }
        let got = inputs.lock().unwrap().clone();
        let inc =
            |a: usize, b: usize| -> [f64; 3] { std::array::from_fn(|i| rates[a][i] - rates[b][i]) };
        let mean: [f64; 3] = std::array::from_fn(|i| (rates[7][i] - rates[4][i]) / 3.0);
        // The hole's mean differs from the increments measured around it (gyro noise).
        assert!((0..3).all(
            |i| (mean[i] - inc(4, 3)[i]).abs() > 1e-6 && (mean[i] - inc(9, 8)[i]).abs() > 1e-6
        ));
        // Sample 0 starts over after the jump in time (a reseat, no input); then steps at 1..=4,
        // coasts for 5 and 6, steps at 7..=11.
        let kinds: Vec<bool> = got.iter().map(|(c, _)| *c).collect();
        assert_eq!(
            kinds,
            [
                false, false, false, false, true, true, false, false, false, false, false
            ],
            "{got:?}"
        );
        let want: Vec<[f64; 3]> = vec![
            [0.0; 3],
            inc(1, 0),
            inc(2, 1),
            inc(3, 2),
            inc(4, 3),
            mean,
            mean,
            mean,
            inc(8, 7),
            inc(9, 8),
            inc(10, 9),
        ];
        for (k, ((_, u), w)) in got.iter().zip(&want).enumerate() {
            for i in 0..3 {
                assert!(
                    (u[l + i] - w[i]).abs() < 1e-12,
                    "input {k}: {u:?}, want {w:?}"
                );
            }
        }
    }

    /// A calibration stretch too holed to fit: said, and the next stretch calibrates.
    #[test]
    fn a_failed_calibration_is_tried_again_on_the_next_stretch() {
        let (p, said, _) = fly_quad_for(3000, |k, stage| {
            if matches!(stage, Stage::Calibrating { .. }) && k < 1300 && k % 25 != 0 {
                Damage::Lost
            } else {
                Damage::Intact
            }
        });
        let failed = said
            .0
            .iter()
            .filter(|m| m.contains("calibration failed"))
            .count();
        assert_eq!(failed, 1, "{:?}", said.0);
        assert!(matches!(p.stage, Stage::Running(_)), "{:?}", said.0);
        assert!(p.counters.steps > 100, "{:?}", p.counters);
    }

    /// One sample in ten lost during the calibration stretch: every hole is counted and said
    /// once, and the fit on what is left scales the axes as the fit on the whole stretch does.
    #[test]
    fn calibration_counts_the_holes_and_fits_around_them() {
        let (whole, said_whole, _) = fly_quad(false);
        let (lossy, said, lost) = fly_quad(true);
        for p in [&whole, &lossy] {
            assert!(matches!(p.stage, Stage::Running(_)), "{said:?}");
        }
        assert_eq!(whole.counters.calibration_gaps, 0);
        assert!(!said_whole.0.iter().any(|m| m.contains("gaps")));
        // Holes at the very start or end of the stretch may fall outside what it kept.
        let counted = lossy.counters.calibration_gaps;
        assert!(
            counted <= lost && counted + 2 >= lost && counted >= 90,
            "{counted} of {lost}"
        );
        let gaps: Vec<_> = said.0.iter().filter(|m| m.contains("gaps")).collect();
        assert_eq!(gaps.len(), 1, "{:?}", said.0);
        assert!(gaps[0].contains(&format!("{counted} gaps")), "{}", gaps[0]);
        let (a, b) = (whole.fit.unwrap().scale, lossy.fit.unwrap().scale);
        for axis in 0..3 {
            assert!((a[axis] - b[axis]).abs() < 0.02, "scales {a:?} and {b:?}");
        }
    }
}
