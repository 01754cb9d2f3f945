//! Scenario files (TOML, `replay/scenarios/`): vehicle, duration, rate, seed, noise schedules,
//! excitation and faults. Unknown keys are errors naming the key, the file and the line.

use crate::sim::fault::Fault;
use crate::sim::noise::NoiseSchedule;
use crate::sim::paper::{ACTUATORS, Dither, PaperSimConfig};
use crate::sim::vehicle::{AttitudeDither, Gusts, Manoeuvre, ModelMismatch};
use crate::telemetry::Profile;
use crate::toml_file::{self, TomlFileError};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    #[serde(default)]
    pub description: String,
    /// `paper-heli` (the paper's simulation) or a vehicle profile (built-in name or file) that
    /// the vehicle simulator flies.
    pub vehicle: String,
    /// The monitor's profile when it differs from the simulated vehicle's (default: the same).
    #[serde(default)]
    pub profile: Option<String>,
    pub duration_s: f64,
    pub rate_hz: f64,
    #[serde(default = "default_seed")]
    pub seed: u64,
    #[serde(default = "default_speed")]
    pub forward_speed_mps: f64,
    /// Paper scenarios: rate process and gyro noise schedules (required there).
    #[serde(default = "quiet")]
    pub process_noise: NoiseSchedule,
    #[serde(default = "quiet")]
    pub measurement_noise: NoiseSchedule,
    /// Vehicle scenarios: gyro (rad/s) and a_z (m/s²) noise std; default: the profile's.
    #[serde(default)]
    pub gyro_noise: Option<f64>,
    #[serde(default)]
    pub az_noise: Option<f64>,
    /// Vehicle scenarios: the gusts' driving noise and the sensor noise uniform (bounded at
    /// `√3` times the stated standard deviation) instead of Gaussian.
    #[serde(default)]
    pub bounded_noise: bool,
    #[serde(default)]
    pub gusts: Option<Gusts>,
    #[serde(default)]
    pub model_mismatch: Option<ModelMismatch>,
    #[serde(default)]
    pub attitude_dither: Option<AttitudeDither>,
    #[serde(default, rename = "manoeuvre")]
    pub manoeuvres: Vec<Manoeuvre>,
    #[serde(default)]
    pub dither: Option<Dither>,
    #[serde(default, rename = "fault")]
    pub faults: Vec<Fault>,
    #[serde(default)]
    pub eval: EvalSettings,
}

/// How `eval` judges this scenario.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalSettings {
    /// Settling tolerance on gamma (for faults that move gamma).
    pub settle_tol_gamma: f64,
    /// Settling tolerance on delta (for faults that move only delta), in input units (rad).
    pub settle_tol_delta: f64,
    /// The simple detection rule: healthy point outside the bounds for this long.
    pub detect_persistence_s: f64,
    /// No decisions before this time (filters warming up).
    pub warmup_s: f64,
    /// Steady state = the last fraction of the run.
    pub steady_fraction: f64,
}

impl Default for EvalSettings {
    fn default() -> Self {
        Self {
            settle_tol_gamma: 0.05,
            settle_tol_delta: 0.005,
            detect_persistence_s: 0.25,
            warmup_s: 2.0,
            steady_fraction: 0.25,
        }
    }
}

fn quiet() -> NoiseSchedule {
    NoiseSchedule::constant(crate::sim::noise::NoiseKind::Gaussian, 0.0)
}

fn default_seed() -> u64 {
    1
}

fn default_speed() -> f64 {
    10.0
}

/// A scenario file that cannot be found, read, parsed or validated.
pub type ScenarioError = TomlFileError;

/// The scenarios shipped in `replay/scenarios/`, built into the binary so `eval` runs anywhere.
pub const BUILTIN: &[(&str, &str)] = &[
    (
        "paper-fig5-gaussian",
        include_str!("../replay/scenarios/paper-fig5-gaussian.toml"),
    ),
    (
        "paper-fig5-uniform",
        include_str!("../replay/scenarios/paper-fig5-uniform.toml"),
    ),
    (
        "paper-fig7-sine-delta",
        include_str!("../replay/scenarios/paper-fig7-sine-delta.toml"),
    ),
    (
        "paper-fig8-noise-step",
        include_str!("../replay/scenarios/paper-fig8-noise-step.toml"),
    ),
    (
        "paper-fig9-uniform-step",
        include_str!("../replay/scenarios/paper-fig9-uniform-step.toml"),
    ),
    (
        "paper-fig10-delta-step",
        include_str!("../replay/scenarios/paper-fig10-delta-step.toml"),
    ),
    (
        "healthy-10min",
        include_str!("../replay/scenarios/healthy-10min.toml"),
    ),
    (
        "quad-x-motor2-loe",
        include_str!("../replay/scenarios/quad-x-motor2-loe.toml"),
    ),
    (
        "quad-x-motor2-loe-live",
        include_str!("../replay/scenarios/quad-x-motor2-loe-live.toml"),
    ),
    (
        "quad-x-motor4-bias",
        include_str!("../replay/scenarios/quad-x-motor4-bias.toml"),
    ),
    (
        "quad-x-healthy-gusts",
        include_str!("../replay/scenarios/quad-x-healthy-gusts.toml"),
    ),
    (
        "quad-x-hover-still",
        include_str!("../replay/scenarios/quad-x-hover-still.toml"),
    ),
    (
        "hexa-x-motor3-loe",
        include_str!("../replay/scenarios/hexa-x-motor3-loe.toml"),
    ),
    (
        "hexa-x-motor5-stuck",
        include_str!("../replay/scenarios/hexa-x-motor5-stuck.toml"),
    ),
    (
        "hexa-x-healthy-gusts",
        include_str!("../replay/scenarios/hexa-x-healthy-gusts.toml"),
    ),
    (
        "heli-swash2-loe",
        include_str!("../replay/scenarios/heli-swash2-loe.toml"),
    ),
    (
        "heli-swash2-loe-live",
        include_str!("../replay/scenarios/heli-swash2-loe-live.toml"),
    ),
    (
        "heli-demo",
        include_str!("../replay/scenarios/heli-demo.toml"),
    ),
    (
        "heli-tail-bias",
        include_str!("../replay/scenarios/heli-tail-bias.toml"),
    ),
    (
        "heli-healthy-gusts",
        include_str!("../replay/scenarios/heli-healthy-gusts.toml"),
    ),
    (
        "plane-elevator-loe",
        include_str!("../replay/scenarios/plane-elevator-loe.toml"),
    ),
    (
        "plane-aileron-bias",
        include_str!("../replay/scenarios/plane-aileron-bias.toml"),
    ),
    (
        "plane-healthy-gusts",
        include_str!("../replay/scenarios/plane-healthy-gusts.toml"),
    ),
];

/// A scenario with the name it is reported under (the file stem).
#[derive(Debug, Clone)]
pub struct NamedScenario {
    pub name: String,
    pub scenario: Scenario,
}

impl Scenario {
    /// Parse and validate TOML text; `path` only names the source in errors.
    pub fn from_toml(text: &str, path: &str) -> Result<Self, ScenarioError> {
        toml_file::parse(text, path, Scenario::validate)
    }

    /// The paper's simulation rather than a vehicle profile.
    pub fn is_paper(&self) -> bool {
        self.vehicle == "paper-heli"
    }

    pub fn dt(&self) -> f64 {
        1.0 / self.rate_hz
    }

    /// The paper simulation of this scenario with `seed` (meaningful when [`Self::is_paper`]).
    pub fn paper_sim_config(&self, seed: u64) -> PaperSimConfig {
        PaperSimConfig {
            dt: self.dt(),
            forward_speed: self.forward_speed_mps,
            process_noise: self.process_noise.clone(),
            measurement_noise: self.measurement_noise.clone(),
            faults: self.faults.clone(),
            dither: self.dither.clone(),
            seed,
        }
    }

    pub fn steps(&self) -> usize {
        (self.duration_s * self.rate_hz).round() as usize
    }

    /// Time of the first fault onset, if any.
    pub fn first_fault(&self) -> Option<&Fault> {
        self.faults.iter().min_by(|a, b| a.t.total_cmp(&b.t))
    }

    fn validate(&self) -> Result<(), String> {
        let actuators: Vec<String> = if self.is_paper() {
            ACTUATORS.iter().map(|s| s.to_string()).collect()
        } else {
            let p = Profile::resolve(&self.vehicle).map_err(|e| format!("vehicle: {e}"))?;
            if let Some(name) = &self.profile {
                let m = Profile::resolve(name).map_err(|e| format!("profile: {e}"))?;
                if m.actuator_names() != p.actuator_names() {
                    return Err("profile: its actuators differ from the vehicle's".into());
                }
            }
            p.actuator_names()
        };
        for (name, v) in [("gyro_noise", self.gyro_noise), ("az_noise", self.az_noise)] {
            if v.is_some_and(|v| !v.is_finite() || v < 0.0) {
                return Err(format!("{name} must be a finite non-negative number"));
            }
        }
        if let Some(g) = &self.gusts
            && (!g.tau_s.is_finite()
                || g.tau_s <= 0.0
                || !g.vertical.is_finite()
                || g.vertical < 0.0
                || g.angular.iter().any(|v| !v.is_finite() || *v < 0.0))
        {
            return Err("gusts: finite non-negative levels and a positive tau_s".into());
        }
        if let Some(m) = &self.model_mismatch
            && !(m.damping.is_finite()
                && m.damping > 0.0
                && m.effectiveness.is_finite()
                && m.effectiveness > 0.0)
        {
            return Err("model_mismatch: scales must be positive".into());
        }
        for (name, v) in [
            ("duration_s", self.duration_s),
            ("rate_hz", self.rate_hz),
            ("forward_speed_mps", self.forward_speed_mps),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(format!(
                    "{name} must be a finite non-negative number (got {v})"
                ));
            }
        }
        if self.duration_s <= 0.0 || self.rate_hz <= 0.0 {
            return Err("duration_s and rate_hz must be positive".into());
        }
        if self.steps() == 0 {
            return Err(format!(
                "duration_s = {} at rate_hz = {} is not one step",
                self.duration_s, self.rate_hz
            ));
        }
        if self.steps() > 50_000_000 {
            return Err(format!(
                "{} steps is more than this tool will simulate",
                self.steps()
            ));
        }
        self.process_noise
            .validate()
            .map_err(|e| format!("process_noise: {e}"))?;
        self.measurement_noise
            .validate()
            .map_err(|e| format!("measurement_noise: {e}"))?;
        if let Some(d) = &self.dither
            && (!d.amplitude_rad.is_finite() || d.freqs_hz.iter().any(|f| !f.is_finite()))
        {
            return Err("dither: amplitude and frequencies must be finite".into());
        }
        if let Some(d) = &self.attitude_dither
            && (d.amplitude.iter().any(|v| !v.is_finite())
                || d.freqs_hz.iter().any(|f| !f.is_finite() || *f < 0.0))
        {
            return Err(
                "attitude_dither: amplitudes must be finite and frequencies finite and non-negative"
                    .into(),
            );
        }
        for m in &self.manoeuvres {
            for (name, v) in [
                ("t", m.t),
                ("duration_s", m.duration_s),
                ("roll_deg", m.roll_deg),
                ("pitch_deg", m.pitch_deg),
                ("yaw_rate_dps", m.yaw_rate_dps),
            ] {
                if !v.is_finite() {
                    return Err(format!(
                        "manoeuvre at t = {}: {name} is not a finite number ({v})",
                        m.t
                    ));
                }
            }
            if m.duration_s < 0.0 {
                return Err(format!(
                    "manoeuvre at t = {}: duration_s must not be negative",
                    m.t
                ));
            }
        }
        for f in &self.faults {
            if !actuators.contains(&f.actuator) {
                return Err(format!(
                    "fault actuator `{}` is not one of {}",
                    f.actuator,
                    actuators.join(", ")
                ));
            }
            f.validate()?;
            // A fault outside the flight would be scored as a healthy flight.
            if !(0.0..self.duration_s).contains(&f.t) {
                return Err(format!(
                    "fault on `{}` at t = {} s is outside the flight (0 to duration_s = {} s)",
                    f.actuator, f.t, self.duration_s
                ));
            }
            if f.until.is_some_and(|u| u <= f.t) {
                return Err(format!(
                    "fault on `{}`: until must come after t = {} s",
                    f.actuator, f.t
                ));
            }
        }
        let e = &self.eval;
        for (name, v) in [
            ("eval.settle_tol_gamma", e.settle_tol_gamma),
            ("eval.settle_tol_delta", e.settle_tol_delta),
            ("eval.detect_persistence_s", e.detect_persistence_s),
            ("eval.warmup_s", e.warmup_s),
            ("eval.steady_fraction", e.steady_fraction),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(format!(
                    "{name} must be a finite non-negative number (got {v})"
                ));
            }
        }
        Ok(())
    }
}

/// Load a scenario from the built-in set by stem, or from a file path.
pub fn resolve(name_or_path: &str) -> Result<NamedScenario, ScenarioError> {
    let source = toml_file::find(name_or_path, BUILTIN, "replay/scenarios", "scenario")?;
    Ok(NamedScenario {
        scenario: Scenario::from_toml(&source.text, &source.label)?,
        name: source.stem,
    })
}

/// Every built-in scenario, parsed.
pub fn all_builtin() -> Result<Vec<NamedScenario>, ScenarioError> {
    BUILTIN.iter().map(|(stem, _)| resolve(stem)).collect()
}

/// The scenario's faults and end as the monitor will show them: on the simulated autopilot's
/// clock, which reads `BOOT_OFFSET_S` at the scenario's start (a vehicle is not connected to at
/// boot). E.g. `swash2 gain 0.6 at t=42 s, tail bias +0.15 at t=55 s; ends at t=68 s`.
pub fn script_on_vehicle_clock(scenario: &Scenario) -> String {
    // Two decimals at most (1.12 + 10 is 11.120000000000001 in floating point).
    let clock = |t: f64| {
        let v = format!("{:.2}", t + crate::telemetry::encode::BOOT_OFFSET_S);
        format!("t={} s", v.trim_end_matches('0').trim_end_matches('.'))
    };
    let faults: Vec<String> = scenario
        .faults
        .iter()
        .map(|f| {
            let until = f
                .until
                .map_or(String::new(), |u| format!(" until {}", clock(u)));
            format!("{} at {}{until}", f.describe(), clock(f.t))
        })
        .collect();
    let faults = if faults.is_empty() {
        "no faults".to_string()
    } else {
        faults.join(", ")
    };
    format!("{faults}; ends at {}", clock(scenario.duration_s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_scenarios_parse() {
        let all = all_builtin().unwrap();
        assert_eq!(all.len(), BUILTIN.len());
    }

    #[test]
    fn unknown_key_names_key_file_and_line() {
        let text = "vehicle = 'paper-heli'\nduration_s = 1.0\nrate_hz = 50.0\nbogus_key = 3\n";
        let err = Scenario::from_toml(text, "x.toml").unwrap_err().to_string();
        assert!(
            err.contains("x.toml:4") && err.contains("bogus_key"),
            "{err}"
        );
        assert!(!err.contains('\n'));
    }

    #[test]
    fn nan_noise_level_is_rejected() {
        let text = "vehicle = 'paper-heli'\nduration_s = 1.0\nrate_hz = 50.0\n\
            process_noise = { kind = 'gaussian', schedule = [{ t = 0.0, level = nan }] }\n\
            measurement_noise = { kind = 'gaussian', schedule = [{ t = 0.0, level = 1e-6 }] }\n";
        let err = Scenario::from_toml(text, "n.toml").unwrap_err().to_string();
        assert!(
            err.contains("process_noise") && err.contains("NaN"),
            "{err}"
        );
    }
    #[test]
    fn the_demo_script_is_told_on_the_clock_the_monitor_shows() {
        let named = resolve("heli-demo").unwrap();
        assert_eq!(
            script_on_vehicle_clock(&named.scenario),
            "swash2 gain 0.6 at t=42 s, tail bias +0.15 at t=55 s; ends at t=68 s"
        );
    }
}
