//! The paper's decision rule, which `eval` scores the paper's figures with: a fault is
//! declared when the healthy point (gamma = 1, delta = 0) has been outside the filter's bounds
//! for a persistence time, and cleared after it has been back inside for a hold-off time
//! (hysteresis). A set filter adds its explicit indication (the paper's conclusion): a step
//! whose data no state in its set can explain is a fault at once. The vehicles' decisions are
//! `diagnose`'s.

/// A decision event of the bounds rule.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoundsEvent {
    Fault,
    Cleared,
}

#[derive(Debug, Clone)]
pub struct BoundsDetector {
    persistence_steps: u32,
    clear_steps: u32,
    warmup_steps: u64,
    outside: u32,
    inside: u32,
    steps: u64,
    pub active: bool,
}

impl BoundsDetector {
    /// `persistence_s` outside before a fault; `clear_s` inside before it clears; nothing during `warmup_s`.
    pub fn new(dt: f64, persistence_s: f64, clear_s: f64, warmup_s: f64) -> Self {
        let steps = |s: f64| ((s / dt).round() as u32).max(1);
        Self {
            persistence_steps: steps(persistence_s),
            clear_steps: steps(clear_s),
            warmup_steps: (warmup_s / dt).round() as u64,
            outside: 0,
            inside: 0,
            steps: 0,
            active: false,
        }
    }

    /// Feed one step's bounds of gamma and delta, and whether the step's data contradicted
    /// the filter's set (set filters only; always false for the Kalman filters).
    pub fn update(
        &mut self,
        gamma_bounds: (f64, f64),
        delta_bounds: (f64, f64),
        contradicted: bool,
    ) -> Option<BoundsEvent> {
        self.steps += 1;
        if contradicted && self.steps > self.warmup_steps {
            self.inside = 0;
            if !self.active {
                self.active = true;
                return Some(BoundsEvent::Fault);
            }
            return None;
        }
        let healthy_inside = gamma_bounds.0 <= 1.0
            && 1.0 <= gamma_bounds.1
            && delta_bounds.0 <= 0.0
            && 0.0 <= delta_bounds.1;
        if self.steps <= self.warmup_steps {
            return None;
        }
        if healthy_inside {
            self.outside = 0;
            self.inside = self.inside.saturating_add(1);
            if self.active && self.inside >= self.clear_steps {
                self.active = false;
                return Some(BoundsEvent::Cleared);
            }
        } else {
            self.inside = 0;
            self.outside = self.outside.saturating_add(1);
            if !self.active && self.outside >= self.persistence_steps {
                self.active = true;
                return Some(BoundsEvent::Fault);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn persistence_and_hysteresis() {
        let mut d = BoundsDetector::new(0.02, 0.1, 0.2, 0.0);
        let ok = ((0.9, 1.1), (-0.1, 0.1));
        let bad = ((0.4, 0.6), (-0.1, 0.1));
        for _ in 0..4 {
            assert_eq!(d.update(bad.0, bad.1, false), None);
        }
        assert_eq!(d.update(bad.0, bad.1, false), Some(BoundsEvent::Fault));
        for _ in 0..9 {
            assert_eq!(d.update(ok.0, ok.1, false), None);
        }
        assert_eq!(d.update(ok.0, ok.1, false), Some(BoundsEvent::Cleared));
        // A short excursion does not fire.
        for _ in 0..3 {
            d.update(bad.0, bad.1, false);
        }
        assert_eq!(d.update(ok.0, ok.1, false), None);
        // A contradiction fires at once, even with the healthy point inside the bounds.
        let mut d = BoundsDetector::new(0.02, 0.1, 0.2, 0.0);
        assert_eq!(d.update(ok.0, ok.1, true), Some(BoundsEvent::Fault));
        assert_eq!(d.update(ok.0, ok.1, true), None);
    }
}
