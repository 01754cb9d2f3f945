//! The actuator fault module: what each actuator really delivers, `gamma * u + delta`.

use serde::{Deserialize, Serialize};

/// One fault on one actuator, from `t` (and until `until`, if given).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// Actuator name as the vehicle knows it (paper heli: `collective`, `lat`, `lon`, `tail`).
    pub actuator: String,
    /// Onset (s).
    pub t: f64,
    /// End (s); the actuator is healthy again afterwards.
    #[serde(default)]
    pub until: Option<f64>,
    /// Abrupt gain.
    #[serde(default)]
    pub gamma: Option<f64>,
    /// Abrupt bias (in input units).
    #[serde(default)]
    pub delta: Option<f64>,
    /// Sinusoidal bias `amplitude * sin(omega (t - onset))`.
    #[serde(default)]
    pub sine: Option<SineBias>,
    /// Linear ramp from healthy to the target gain/bias over `duration_s`.
    #[serde(default)]
    pub ramp: Option<Ramp>,
    /// Stuck at this position (input units): gamma = 0, delta = position.
    #[serde(default)]
    pub stuck: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SineBias {
    pub amplitude: f64,
    pub omega_rad_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ramp {
    pub duration_s: f64,
    #[serde(default = "one")]
    pub gamma: f64,
    #[serde(default)]
    pub delta: f64,
}

fn one() -> f64 {
    1.0
}

impl Fault {
    /// (gamma, delta) this fault imposes at time t, or None when it is not active.
    pub fn health_at(&self, t: f64) -> Option<(f64, f64)> {
        if t < self.t || self.until.is_some_and(|u| t >= u) {
            return None;
        }
        if let Some(pos) = self.stuck {
            return Some((0.0, pos));
        }
        let mut gamma = self.gamma.unwrap_or(1.0);
        let mut delta = self.delta.unwrap_or(0.0);
        if let Some(s) = self.sine {
            delta += s.amplitude * (s.omega_rad_s * (t - self.t)).sin();
        }
        if let Some(r) = self.ramp {
            let frac = if r.duration_s > 0.0 {
                ((t - self.t) / r.duration_s).clamp(0.0, 1.0)
            } else {
                1.0
            };
            gamma *= 1.0 + frac * (r.gamma - 1.0);
            delta += frac * r.delta;
        }
        Some((gamma, delta))
    }

    /// What the fault does, in a few words: `swash2 gain 0.6`, `tail bias +0.15`,
    /// `motor5 stuck at 0.55`, `lon sine bias 0.02`, `lon ramp over 5 s to gain 0.5`.
    pub fn describe(&self) -> String {
        // Three decimals at most: values come from TOML and products or sums of them.
        let num = |v: f64| {
            let s = format!("{v:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        };
        let signed = |v: f64| {
            if v >= 0.0 {
                format!("+{}", num(v))
            } else {
                num(v)
            }
        };
        let mut what = Vec::new();
        if let Some(p) = self.stuck {
            what.push(format!("stuck at {}", num(p)));
        } else {
            let (g, d) = (self.gamma.unwrap_or(1.0), self.delta.unwrap_or(0.0));
            if self.gamma.is_some() {
                what.push(format!("gain {}", num(g)));
            }
            if self.delta.is_some() {
                what.push(format!("bias {}", signed(d)));
            }
            if let Some(s) = self.sine {
                what.push(format!("sine bias {}", num(s.amplitude)));
            }
            if let Some(r) = self.ramp {
                // `health_at` multiplies the gain and adds the bias: say where it ends.
                let mut to = Vec::new();
                if r.gamma != 1.0 {
                    to.push(format!("gain {}", num(g * r.gamma)));
                }
                if r.delta != 0.0 {
                    to.push(format!("bias {}", signed(d + r.delta)));
                }
                what.push(if to.is_empty() {
                    format!("ramp over {} s (no change)", num(r.duration_s))
                } else {
                    format!("ramp over {} s to {}", num(r.duration_s), to.join(" and "))
                });
            }
        }
        format!("{} {}", self.actuator, what.join(", "))
    }

    /// Which coefficient the fault moves: used to pick the settling criterion.
    pub fn moves_gamma(&self) -> bool {
        self.stuck.is_some() || self.gamma.is_some() || self.ramp.is_some_and(|r| r.gamma != 1.0)
    }

    pub fn validate(&self) -> Result<(), String> {
        let kinds = [
            self.gamma.is_some() || self.delta.is_some(),
            self.sine.is_some(),
            self.ramp.is_some(),
            self.stuck.is_some(),
        ];
        if kinds.iter().filter(|k| **k).count() == 0 {
            return Err(format!(
                "fault on `{}` at t = {} sets none of gamma, delta, sine, ramp, stuck",
                self.actuator, self.t
            ));
        }
        // A stuck output overrides the rest: anything set beside it would be silently dropped.
        if self.stuck.is_some() && kinds[..3].iter().any(|k| *k) {
            return Err(format!(
                "fault on `{}` at t = {}: stuck sets the output alone; gamma, delta, sine and ramp cannot go with it (give them as another fault)",
                self.actuator, self.t
            ));
        }
        if let Some(r) = self.ramp
            && (r.duration_s.is_nan() || r.duration_s <= 0.0)
        {
            return Err(format!(
                "fault on `{}`: ramp.duration_s must be positive (got {}; a step is gamma or delta alone)",
                self.actuator, r.duration_s
            ));
        }
        let mut nums = vec![("t", self.t)];
        nums.extend(self.until.map(|v| ("until", v)));
        nums.extend(self.gamma.map(|v| ("gamma", v)));
        nums.extend(self.delta.map(|v| ("delta", v)));
        nums.extend(self.stuck.map(|v| ("stuck", v)));
        if let Some(s) = self.sine {
            nums.extend([
                ("sine.amplitude", s.amplitude),
                ("sine.omega_rad_s", s.omega_rad_s),
            ]);
        }
        if let Some(r) = self.ramp {
            nums.extend([
                ("ramp.duration_s", r.duration_s),
                ("ramp.gamma", r.gamma),
                ("ramp.delta", r.delta),
            ]);
        }
        for (name, v) in nums {
            if !v.is_finite() {
                return Err(format!(
                    "fault on `{}`: {name} is not a finite number ({v})",
                    self.actuator
                ));
            }
        }
        Ok(())
    }
}

/// (gamma, delta) of actuator `name` at time t: healthy unless a fault says otherwise
/// (later faults in the list override earlier ones).
pub fn health_of(faults: &[Fault], name: &str, t: f64) -> (f64, f64) {
    faults
        .iter()
        .filter(|f| f.actuator == name)
        .filter_map(|f| f.health_at(t))
        .next_back()
        .unwrap_or((1.0, 0.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(toml: &str) -> Fault {
        toml::from_str(toml).unwrap()
    }

    #[test]
    fn describe_says_what_the_fault_does() {
        let cases = [
            ("actuator='swash2'\nt=32.0\ngamma=0.6", "swash2 gain 0.6"),
            ("actuator='tail'\nt=45.0\ndelta=0.15", "tail bias +0.15"),
            (
                "actuator='motor5'\nt=15.0\nstuck=0.55",
                "motor5 stuck at 0.55",
            ),
            (
                "actuator='lon'\nt=1.0\nramp={duration_s=5.0, gamma=0.5}",
                "lon ramp over 5 s to gain 0.5",
            ),
            (
                "actuator='lon'\nt=1.0\ngamma=0.8\ndelta=-0.02",
                "lon gain 0.8, bias -0.02",
            ),
            (
                "actuator='lon'\nt=1.0\ngamma=0.8\nramp={duration_s=5.0, gamma=0.5}",
                "lon gain 0.8, ramp over 5 s to gain 0.4",
            ),
            (
                "actuator='lon'\nt=1.0\nramp={duration_s=5.0, gamma=1.0}",
                "lon ramp over 5 s (no change)",
            ),
        ];
        for (toml, want) in cases {
            assert_eq!(fault(toml).describe(), want, "{toml}");
        }
    }

    #[test]
    fn kinds_give_the_right_coefficients() {
        let g = fault("actuator='lon'\nt=10.0\ngamma=0.5\nuntil=30.0");
        assert_eq!(g.health_at(9.99), None);
        assert_eq!(g.health_at(10.0), Some((0.5, 0.0)));
        assert_eq!(g.health_at(30.0), None);
        let s = fault("actuator='lon'\nt=10.0\nsine={amplitude=0.02, omega_rad_s=1.0}");
        let (_, d) = s.health_at(10.0 + std::f64::consts::FRAC_PI_2).unwrap();
        assert!((d - 0.02).abs() < 1e-12);
        let r = fault("actuator='lon'\nt=0.0\nramp={duration_s=10.0, gamma=0.5}");
        assert!((r.health_at(5.0).unwrap().0 - 0.75).abs() < 1e-12);
        let st = fault("actuator='lon'\nt=0.0\nstuck=0.05");
        assert_eq!(st.health_at(1.0), Some((0.0, 0.05)));
        assert_eq!(health_of(&[g], "lat", 20.0), (1.0, 0.0));
    }

    #[test]
    fn faults_that_would_drop_part_of_themselves_are_refused() {
        let refused = [
            (
                "actuator='lon'\nt=1.0\ngamma=0.7\nstuck=0.5",
                "stuck sets the output alone",
            ),
            (
                "actuator='lon'\nt=1.0\nstuck=0.5\nsine={amplitude=0.02, omega_rad_s=1.0}",
                "stuck sets the output alone",
            ),
            (
                "actuator='lon'\nt=1.0\nramp={duration_s=-3.0, gamma=0.5}",
                "ramp.duration_s must be positive (got -3",
            ),
            (
                "actuator='lon'\nt=1.0\nramp={duration_s=0.0, gamma=0.5}",
                "ramp.duration_s must be positive (got 0",
            ),
        ];
        for (toml, want) in refused {
            let e = fault(toml).validate().unwrap_err();
            assert!(e.contains(want), "{toml}: {e}");
        }
        // Gain, bias, sine and ramp compose (see describe), so they may go together.
        let composed = "actuator='lon'\nt=1.0\ngamma=0.8\ndelta=0.1\nramp={duration_s=5.0}";
        assert_eq!(fault(composed).validate(), Ok(()));
    }
}
