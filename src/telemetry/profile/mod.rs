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

    fn validate(&self) -> Result<(), String> {
        let l = self.actuators.len();
        if l == 0 || l > MAX_ACTUATORS {
            return Err(format!(
                "{l} actuators; between 1 and {MAX_ACTUATORS} are supported"
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0) {
            return Err(format!("rate_hz must be positive (got {})", self.rate_hz));
        }
        // Names key the decisions, the estimates and the planner's values.
        for (j, a) in self.actuators.iter().enumerate() {
            if a.name.trim().is_empty() || a.name.chars().any(char::is_control) {
                return Err(format!(
                    "actuator {}: a name must be non-empty printable text",
                    j + 1
                ));
            }
            if self.actuators[..j].iter().any(|b| b.name == a.name) {
                return Err(format!("actuator name `{}` is used twice", a.name));
            }
        }
        let m = &self.model;
        check_ranges(&self.numbers())?;
        if !(self.diagnosis.threshold.is_finite() && self.diagnosis.threshold > 0.0) {
            return Err("diagnosis.threshold must be positive".into());
        }
        if let Some(g) = self.diagnosis.gain_threshold
            && !(g.is_finite() && g > 0.0)
        {
            return Err("diagnosis.gain_threshold must be positive".into());
        }
        if let Some(g) = self.diagnosis.gusts
            && !g.iter().all(|v| v.is_finite() && *v > 0.0)
        {
            return Err("diagnosis.gusts must be positive".into());
        }
        // A geometry column scaled by a gain left out (0) cannot move: its gamma would read
        // healthy whatever the actuator does.
        if m.arx.is_none() {
            for a in &self.actuators {
                let mut needs: Vec<(&str, f64)> = match (a.role, a.effectiveness) {
                    (_, Some(_)) => vec![],
                    (Role::Motor, None) => vec![
                        ("roll_gain", m.roll_gain),
                        ("pitch_gain", m.pitch_gain),
                        ("yaw_gain", m.yaw_gain),
                    ],
                    (Role::Swash, None) => {
                        vec![("roll_gain", m.roll_gain), ("pitch_gain", m.pitch_gain)]
                    }
                    (Role::Tail | Role::Rudder, None) => vec![("yaw_gain", m.yaw_gain)],
                    (Role::Aileron, None) => vec![("roll_gain", m.roll_gain)],
                    (Role::Elevator, None) => vec![("pitch_gain", m.pitch_gain)],
                    (Role::Throttle | Role::Custom, None) => vec![],
                };
                if m.measure_az
                    && matches!(a.role, Role::Motor | Role::Swash)
                    && a.vertical.is_none()
                {
                    needs.push(("thrust_gain", m.thrust_gain));
                }
                if let Some((gain, _)) = needs.iter().find(|(_, v)| *v == 0.0) {
                    return Err(format!(
                        "model.{gain} is 0 or missing, but actuator `{}` needs it (its column of G is the geometry scaled by it)",
                        a.name
                    ));
                }
            }
        }
        // An identified ARX profile without its model would be flown on the bare geometry and
        // trusted as identified (false alarms from the first second).
        if self.identified && m.dynamics == Dynamics::Arx && m.arx.is_none() {
            return Err(
                "identified = true with dynamics = \"arx\" needs its [model.arx] section (as `ahcmon calibrate` writes it); without it, set identified = false to calibrate in flight"
                    .into(),
            );
        }
        if let Some(a) = &m.arx {
            if a.input.len() != l || (!a.vertical.is_empty() && a.vertical.len() != l) {
                return Err(format!(
                    "model.arx: {} input columns and {} vertical entries for {l} actuators",
                    a.input.len(),
                    a.vertical.len()
                ));
            }
            if !(a.dt.is_finite() && a.dt > 0.0) || a.delay > MAX_ARX_DELAY {
                return Err(format!(
                    "model.arx: dt must be positive and delay at most {MAX_ARX_DELAY} samples (got dt {}, delay {})",
                    a.dt, a.delay
                ));
            }
        }
        let n = &self.noise;
        for (k, v) in [
            ("gyro", n.gyro),
            ("az", n.az),
            ("rate_process", n.rate_process),
            ("gamma_process", n.gamma_process),
            ("delta_process", n.delta_process),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("noise.{k} must be positive (got {v})"));
            }
        }
        let mut seen = std::collections::HashSet::new();
        for a in &self.actuators {
            if !seen.insert(a.channel) {
                return Err(format!(
                    "actuator `{}`: channel {} used twice",
                    a.name, a.channel
                ));
            }
            if a.channel == 0 || a.channel > 32 {
                return Err(format!("actuator `{}`: channel must be 1..32", a.name));
            }
            let ordered = a.pwm_min < a.pwm_max && a.pwm_min.is_finite() && a.pwm_max.is_finite();
            if !ordered {
                return Err(format!(
                    "actuator `{}`: pwm_min must be below pwm_max",
                    a.name
                ));
            }
            let trim_inside = a.pwm_min < a.pwm_trim && a.pwm_trim < a.pwm_max;
            if !a.role.is_range() && !trim_inside {
                return Err(format!(
                    "actuator `{}`: pwm_trim must lie between pwm_min and pwm_max",
                    a.name
                ));
            }
            if a.effectiveness.is_none() {
                match a.role {
                    Role::Motor if a.angle_deg.is_none() || a.spin.is_none() => {
                        return Err(format!(
                            "motor `{}` needs angle_deg and spin (or an explicit effectiveness)",
                            a.name
                        ));
                    }
                    Role::Swash if a.angle_deg.is_none() => {
                        return Err(format!(
                            "swash servo `{}` needs angle_deg (or an explicit effectiveness)",
                            a.name
                        ));
                    }
                    Role::Custom | Role::Throttle => {
                        return Err(format!(
                            "actuator `{}` ({:?}) needs an explicit effectiveness",
                            a.name, a.role
                        ));
                    }
                    _ => {}
                }
            }
        }
        if self
            .actuators
            .iter()
            .filter(|a| a.role == Role::Swash)
            .count()
            == 1
        {
            return Err("a swashplate needs at least two servos".into());
        }
        Ok(())
    }

    /// Every number of the profile with its key and the range it must lie in (finite, and
    /// far from what overflows the models' products: the calibration's least squares square
    /// them, an SVD of a non-finite matrix panics or never returns).
    fn numbers(&self) -> Vec<(String, f64, f64, f64)> {
        const GAIN: f64 = 1e5; // rad/s² or m/s² per unit of command
        let m = &self.model;
        let mut out: Vec<(String, f64, f64, f64)> =
            vec![("rate_hz".into(), self.rate_hz, 0.0, 1e4)];
        for (i, axis) in ["p", "q", "r"].iter().enumerate() {
            out.push((format!("model.damping ({axis})"), m.damping[i], 0.0, 1e3));
            out.push((format!("model.offset ({axis})"), m.offset[i], -1e4, 1e4));
        }
        for (key, v) in [
            ("model.vertical_offset", m.vertical_offset),
            ("model.roll_gain", m.roll_gain),
            ("model.pitch_gain", m.pitch_gain),
            ("model.yaw_gain", m.yaw_gain),
            ("model.thrust_gain", m.thrust_gain),
            ("model.collective_yaw", m.collective_yaw),
        ] {
            out.push((key.into(), v, -GAIN, GAIN));
        }
        if let Some(a) = &m.arx {
            out.push(("model.arx.dt".into(), a.dt, 0.0, 10.0));
            let rows = a.phi.iter().chain(&a.previous_increment).chain(&a.input);
            for v in rows.flatten().chain(&a.offset).chain(&a.vertical) {
                out.push(("model.arx".into(), *v, -GAIN, GAIN));
            }
            out.push((
                "model.arx.vertical_offset".into(),
                a.vertical_offset,
                -GAIN,
                GAIN,
            ));
        }
        let n = &self.noise;
        for (key, v, hi) in [
            ("noise.gyro", n.gyro, 10.0),
            ("noise.az", n.az, 100.0),
            ("noise.rate_process", n.rate_process, 100.0),
            ("noise.gamma_process", n.gamma_process, 10.0),
            ("noise.delta_process", n.delta_process, 10.0),
        ] {
            out.push((key.into(), v, 0.0, hi));
        }
        let d = &self.diagnosis;
        out.push(("diagnosis.threshold".into(), d.threshold, 0.0, 10.0));
        if let Some(g) = d.gain_threshold {
            out.push(("diagnosis.gain_threshold".into(), g, 0.0, 10.0));
        }
        for g in d.gusts.iter().flatten() {
            out.push(("diagnosis.gusts".into(), *g, 0.0, 1e4));
        }
        for a in &self.actuators {
            let key = |k: &str| format!("actuator `{}`: {k}", a.name);
            for (k, v) in [
                ("pwm_min", a.pwm_min),
                ("pwm_trim", a.pwm_trim),
                ("pwm_max", a.pwm_max),
            ] {
                out.push((key(k), v, 0.0, 65535.0));
            }
            if let Some(v) = a.angle_deg {
                out.push((key("angle_deg"), v, -360.0, 360.0));
            }
            for v in a.effectiveness.iter().flatten() {
                out.push((key("effectiveness"), *v, -GAIN, GAIN));
            }
            if let Some(v) = a.vertical {
                out.push((key("vertical"), v, -GAIN, GAIN));
            }
        }
        out
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

/// Each `(key, value, lo, hi)` within `lo..=hi` (NaN never is).
fn check_ranges(numbers: &[(String, f64, f64, f64)]) -> Result<(), String> {
    match numbers
        .iter()
        .find(|(_, v, lo, hi)| !(lo..=hi).contains(&v))
    {
        Some((key, v, lo, hi)) => {
            let show = |x: f64| {
                if x.is_finite() && x.abs() >= 1e5 {
                    format!("{x:e}")
                } else {
                    format!("{x}")
                }
            };
            Err(format!(
                "{key} must be within {}..{} (got {})",
                show(*lo),
                show(*hi),
                show(*v)
            ))
        }
        None => Ok(()),
    }
}

mod gusts;
pub use gusts::MAX_GUST_FACTOR;

#[cfg(test)]
mod tests;
