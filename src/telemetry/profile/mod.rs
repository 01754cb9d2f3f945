//! Vehicle profiles (TOML, `replay/profiles/`): which outputs are actuators, how their PWM is
//! normalised, and the rate-effectiveness model (`D`, `G`, `c`) with its noise levels.
//!
//! `G` comes either from geometry (multirotor arm angle and spin, swashplate servo angle, plane
//! surface) times the vehicle's axis gains, or from an explicit `effectiveness` column.

use crate::model::{MAX_ACTUATORS, RateParams};
use crate::toml_file::{self, TomlFileError};
use serde::{Deserialize, Serialize};

/// What an actuator is; decides the normalisation and the geometry of its `G` column.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    Motor,
    Throttle,
    Swash,
    Tail,
    Aileron,
    Elevator,
    Rudder,
    /// Any other output; needs an explicit `effectiveness` column.
    Custom,
}

impl Role {
    /// Range outputs (motors, throttle) are normalised from PWM min to [0, 1]; angle outputs
    /// about their trim to [-1, 1].
    pub fn is_range(self) -> bool {
        matches!(self, Role::Motor | Role::Throttle)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Spin {
    Cw,
    Ccw,
}

/// One actuator as written in the profile file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorSpec {
    pub name: String,
    /// 1-based output number as in SERVO_OUTPUT_RAW / `SERVOn_*`.
    pub channel: u8,
    pub role: Role,
    #[serde(default = "pwm_min")]
    pub pwm_min: f64,
    #[serde(default = "pwm_trim")]
    pub pwm_trim: f64,
    #[serde(default = "pwm_max")]
    pub pwm_max: f64,
    #[serde(default)]
    pub reversed: bool,
    /// Motor: arm angle from the nose, clockwise seen from above (deg). Swash: servo position.
    #[serde(default)]
    pub angle_deg: Option<f64>,
    /// Motor spin direction seen from above.
    #[serde(default)]
    pub spin: Option<Spin>,
    /// Explicit `G` column `[roll, pitch, yaw]` (rad/s² per unit), overriding the geometry.
    #[serde(default)]
    pub effectiveness: Option<[f64; 3]>,
    /// Explicit vertical specific force per unit (m/s²), overriding the geometry.
    #[serde(default)]
    pub vertical: Option<f64>,
}

fn pwm_min() -> f64 {
    1000.0
}
fn pwm_trim() -> f64 {
    1500.0
}
fn pwm_max() -> f64 {
    2000.0
}

/// The model part of a profile.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// Diagonal damping `D` of p, q, r (1/s).
    pub damping: [f64; 3],
    /// Trim offset `c` of the rate rows (rad/s²).
    #[serde(default)]
    pub offset: [f64; 3],
    /// Trim offset of the vertical specific force (m/s²).
    #[serde(default)]
    pub vertical_offset: f64,
    /// Axis gains the geometry is scaled by (rad/s² per unit of command).
    #[serde(default)]
    pub roll_gain: f64,
    #[serde(default)]
    pub pitch_gain: f64,
    #[serde(default)]
    pub yaw_gain: f64,
    /// Motors: vertical specific force per unit per motor; swash: for all three servos together.
    #[serde(default)]
    pub thrust_gain: f64,
    /// Swash: yaw acceleration per unit of collective (main-rotor torque), all servos together.
    #[serde(default)]
    pub collective_yaw: f64,
    /// Measure vertical specific force `a_z` as a fourth output.
    #[serde(default)]
    pub measure_az: bool,
    /// What the calibration identifies on the healthy stretch of a log or live flight:
    /// `first_order` (default) scales the geometry per axis; `arx` identifies a discrete model
    /// with cross-axis coupling, full effectiveness, the previous angular acceleration and a
    /// command delay (for rotors that flap and servos that lag; see `calibrate_arx`).
    #[serde(default)]
    pub dynamics: Dynamics,
    /// The identified discrete model (written by calibration; used instead of `D`/`G`/`c`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub arx: Option<crate::model::ArxParams>,
}

/// Longest command delay an identified model may have (samples; the pipeline keeps this many
/// past commands).
pub const MAX_ARX_DELAY: usize = 7;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Dynamics {
    #[default]
    FirstOrder,
    Arx,
}

/// Noise levels the filters are set up with (standard deviations).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Gyro noise (rad/s).
    pub gyro: f64,
    /// Vertical specific force noise (m/s²).
    #[serde(default = "az_noise")]
    pub az: f64,
    /// Rate process noise per step at the profile's rate (rad/s): gusts and model error.
    pub rate_process: f64,
    /// Random-walk noise per step of gamma and delta.
    pub gamma_process: f64,
    pub delta_process: f64,
}

fn az_noise() -> f64 {
    0.3
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiagnosisSpec {
    /// Effective output deviation (units of normalised command) that counts as a fault.
    pub threshold: f64,
    /// The same for the gain statistic of angle outputs: the healthy gain's distance outside
    /// the gamma bounds, times the reference deflection (see `diagnose::vehicle`). Absent:
    /// that statistic decides nothing (it has to be calibrated for the vehicle first, with
    /// `ahcmon thresholds`: healthy values differ by a factor of three between vehicles).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain_threshold: Option<f64>,
    /// The gusts of the healthy flights `threshold` was set on, per rate axis (roll, pitch,
    /// yaw; the wind's standard deviation as an angular acceleration, rad/s², as the in-flight
    /// calibration measures it; the axes' means at the strongest flight's level): the
    /// threshold's false-alarm rate holds up to these
    /// (rule T1, [`DiagnosisSpec::gust_factor`]). Absent: the threshold is not raised.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gusts: Option<[f64; 3]>,
}

impl Default for DiagnosisSpec {
    fn default() -> Self {
        Self {
            threshold: 0.08,
            gain_threshold: None,
            gusts: None,
        }
    }
}

/// A vehicle profile file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// `helicopter` | `multirotor` | `plane`.
    pub vehicle: VehicleKind,
    /// Telemetry rate the noise levels refer to (Hz).
    pub rate_hz: f64,
    /// Written by `ahcmon calibrate`: the model was identified on a healthy stretch of this
    /// vehicle's telemetry, and a monitor given this profile uses it as it is, from the
    /// take-off on, instead of calibrating in flight (`--calibrate-until` calibrates anew).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub identified: bool,
    pub model: ModelSpec,
    pub noise: NoiseSpec,
    /// Decision settings calibrated for this vehicle on healthy Monte-Carlo flights.
    #[serde(default)]
    pub diagnosis: DiagnosisSpec,
    #[serde(rename = "actuator")]
    pub actuators: Vec<ActuatorSpec>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VehicleKind {
    Helicopter,
    Multirotor,
    Plane,
}

/// A profile file that cannot be found, read, parsed or validated.
pub type ProfileError = TomlFileError;

/// The profiles shipped in `replay/profiles/`.
pub const BUILTIN: &[(&str, &str)] = &[
    (
        "paper-heli",
        include_str!("../../../replay/profiles/paper-heli.toml"),
    ),
    (
        "heli-h3-120",
        include_str!("../../../replay/profiles/heli-h3-120.toml"),
    ),
    (
        "quad-plus",
        include_str!("../../../replay/profiles/quad-plus.toml"),
    ),
    (
        "quad-x",
        include_str!("../../../replay/profiles/quad-x.toml"),
    ),
    (
        "hexa-x",
        include_str!("../../../replay/profiles/hexa-x.toml"),
    ),
    ("plane", include_str!("../../../replay/profiles/plane.toml")),
];

impl Profile {
    /// Parse and validate TOML text; `path` names the source in errors.
    pub fn from_toml(text: &str, path: &str) -> Result<Self, ProfileError> {
        toml_file::parse(text, path, Profile::validate)
    }

    /// A built-in profile by name, or a profile file by path.
    pub fn resolve(name_or_path: &str) -> Result<Self, ProfileError> {
        let source = toml_file::find(name_or_path, BUILTIN, "replay/profiles", "profile")?;
        Self::from_toml(&source.text, &source.label)
    }

    pub fn actuator_names(&self) -> Vec<String> {
        self.actuators.iter().map(|a| a.name.clone()).collect()
    }

    pub fn actuator_index(&self, name: &str) -> Option<usize> {
        self.actuators.iter().position(|a| a.name == name)
    }

    /// Number of measurements (3 gyro rates, plus `a_z`).
    pub fn measurements(&self) -> usize {
        if self.model.measure_az { 4 } else { 3 }
    }

    /// The `G` column and vertical effectiveness of actuator `j` (geometry or explicit).
    pub fn column(&self, j: usize) -> ([f64; 3], f64) {
        let a = &self.actuators[j];
        let m = &self.model;
        let swash = self
            .actuators
            .iter()
            .filter(|a| a.role == Role::Swash)
            .count()
            .max(1) as f64;
        let (ang_s, ang_c) = a.angle_deg.unwrap_or(0.0).to_radians().sin_cos();
        // Geometry. FRD body axes: a motor (or raised swash side) on the right rolls the
        // vehicle left (negative p), one in front pitches it nose up; a CCW propeller's
        // reaction torque yaws the body clockwise (ArduPilot yaw factor +1).
        let (col, vertical) = match a.role {
            Role::Motor => {
                let yaw = match a.spin {
                    Some(Spin::Ccw) => m.yaw_gain,
                    _ => -m.yaw_gain,
                };
                (
                    [-ang_s * m.roll_gain, ang_c * m.pitch_gain, yaw],
                    -m.thrust_gain,
                )
            }
            Role::Swash => (
                [
                    -ang_s * m.roll_gain,
                    ang_c * m.pitch_gain,
                    m.collective_yaw / swash,
                ],
                -m.thrust_gain / swash,
            ),
            Role::Tail | Role::Rudder => ([0.0, 0.0, m.yaw_gain], 0.0),
            Role::Aileron => ([m.roll_gain, 0.0, 0.0], 0.0),
            Role::Elevator => ([0.0, m.pitch_gain, 0.0], 0.0),
            Role::Throttle | Role::Custom => ([0.0; 3], 0.0),
        };
        (
            a.effectiveness.unwrap_or(col),
            a.vertical.unwrap_or(vertical),
        )
    }

    /// The continuous rate-effectiveness parameters.
    pub fn rate_params(&self) -> RateParams {
        let cols: Vec<_> = (0..self.actuators.len()).map(|j| self.column(j)).collect();
        RateParams {
            damping: self.model.damping,
            effectiveness: cols.iter().map(|c| c.0).collect(),
            vertical: cols.iter().map(|c| c.1).collect(),
            offset: self.model.offset,
            vertical_offset: self.model.vertical_offset,
        }
    }

    /// Replace `D`, `G` (as explicit columns) and `c` by identified values.
    pub fn with_rate_params(&self, p: &RateParams) -> Self {
        let mut out = self.clone();
        // An identified discrete model would take precedence over the parameters given here.
        out.model.arx = None;
        out.model.damping = p.damping;
        out.model.offset = p.offset;
        out.model.vertical_offset = p.vertical_offset;
        for (j, a) in out.actuators.iter_mut().enumerate() {
            a.effectiveness = Some(p.effectiveness[j]);
            if let Some(v) = p.vertical.get(j) {
                a.vertical = Some(*v);
            }
        }
        out
    }

    /// Normalised command of actuator `j` from its PWM (µs).
    pub fn normalise(&self, j: usize, pwm: f64) -> f64 {
        normalise(&self.actuators[j], pwm)
    }

    /// PWM (µs) of actuator `j` for a normalised command (the simulators' inverse).
    pub fn to_pwm(&self, j: usize, u: f64) -> f64 {
        let a = &self.actuators[j];
        let u = if a.reversed && !a.role.is_range() {
            -u
        } else if a.reversed {
            1.0 - u
        } else {
            u
        };
        if a.role.is_range() {
            a.pwm_min + u * (a.pwm_max - a.pwm_min)
        } else if u >= 0.0 {
            a.pwm_trim + u * (a.pwm_max - a.pwm_trim)
        } else {
            a.pwm_trim + u * (a.pwm_trim - a.pwm_min)
        }
    }

    /// Command range of actuator `j` in normalised units.
    pub fn command_range(&self, j: usize) -> (f64, f64) {
        if self.actuators[j].role.is_range() {
            (0.0, 1.0)
        } else {
            (-1.0, 1.0)
        }
    }
}

/// Range outputs: `(pwm - min) / (max - min)`; angle outputs: about trim, each side scaled to
/// its own half-range. Never about the flight trim: a gain fault must stay a gain.
pub fn normalise(a: &ActuatorSpec, pwm: f64) -> f64 {
    let u = if a.role.is_range() {
        (pwm - a.pwm_min) / (a.pwm_max - a.pwm_min)
    } else if pwm >= a.pwm_trim {
        (pwm - a.pwm_trim) / (a.pwm_max - a.pwm_trim)
    } else {
        (pwm - a.pwm_trim) / (a.pwm_trim - a.pwm_min)
    };
    match (a.reversed, a.role.is_range()) {
        (false, _) => u,
        (true, false) => -u,
        (true, true) => 1.0 - u,
    }
}

mod gusts;
mod validate;
pub use gusts::MAX_GUST_FACTOR;

#[cfg(test)]
mod tests;
