//! A profile's checks before any maths runs: every number finite and in a stated range, names,
//! channels, PWM and the geometry each role needs.

use super::*;

impl Profile {
    pub(super) fn validate(&self) -> Result<(), String> {
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
