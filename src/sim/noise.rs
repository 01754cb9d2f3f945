//! Noise as a schedule: Gaussian (level = variance) or uniform (level = half-width), with the
//! level changing at given times.

use super::rng::Rng;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseKind {
    /// Zero-mean Gaussian; `level` is the variance.
    Gaussian,
    /// Uniform on [-level, level]; `level` is the half-width.
    Uniform,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseStep {
    /// Time (s) from which this level holds.
    pub t: f64,
    pub level: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSchedule {
    pub kind: NoiseKind,
    pub schedule: Vec<NoiseStep>,
}

impl NoiseSchedule {
    pub fn constant(kind: NoiseKind, level: f64) -> Self {
        Self {
            kind,
            schedule: vec![NoiseStep { t: 0.0, level }],
        }
    }

    /// The level in force at time t (the first step's level before it starts).
    pub fn level_at(&self, t: f64) -> f64 {
        let mut level = self.schedule.first().map_or(0.0, |s| s.level);
        for s in &self.schedule {
            if s.t <= t {
                level = s.level;
            }
        }
        level
    }

    /// The level at t = 0: what a filter is told.
    pub fn nominal(&self) -> f64 {
        self.level_at(0.0)
    }

    /// The variance of one sample at level `level`.
    pub fn variance(&self, level: f64) -> f64 {
        match self.kind {
            NoiseKind::Gaussian => level,
            NoiseKind::Uniform => level * level / 3.0,
        }
    }

    /// The half-width of a box that bounds one sample: the half-width itself for uniform noise,
    /// 3σ for Gaussian noise (not a guaranteed bound: Gaussian noise has none).
    pub fn bound(&self, level: f64) -> f64 {
        match self.kind {
            NoiseKind::Gaussian => 3.0 * level.sqrt(),
            NoiseKind::Uniform => level,
        }
    }

    pub fn sample(&self, rng: &mut Rng, t: f64) -> f64 {
        let level = self.level_at(t);
        match self.kind {
            NoiseKind::Gaussian => level.sqrt() * rng.normal(),
            NoiseKind::Uniform => rng.uniform(level),
        }
    }

    /// Check the schedule: non-empty, finite, non-negative levels, increasing times.
    pub fn validate(&self) -> Result<(), String> {
        if self.schedule.is_empty() {
            return Err("noise schedule is empty".into());
        }
        let mut last = f64::NEG_INFINITY;
        for s in &self.schedule {
            if !s.t.is_finite() || !s.level.is_finite() {
                return Err(format!(
                    "noise step at t = {} has a non-finite time or level ({})",
                    s.t, s.level
                ));
            }
            if s.level < 0.0 {
                return Err(format!(
                    "noise level {} at t = {} is negative",
                    s.level, s.t
                ));
            }
            if s.t <= last {
                return Err("noise schedule times must increase".into());
            }
            last = s.t;
        }
        Ok(())
    }
}
