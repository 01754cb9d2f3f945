//! The class of a fault (rules C1-C3), the data's alarm (D2) and the identification the
//! filters follow: the parts of the diagnosis that read the change test's fit and the MIT-UKF's
//! estimate (`docs/diagnosis.md`).

use super::*;

/// Why a fault has no class (C3).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum NoClass {
    /// The command does not move enough to tell a gain from an offset.
    NotSeparable,
    /// The MIT-UKF's bounds do not exclude either explanation.
    BoundsTellNothing,
}

impl Diagnoser {
    /// A motor's or throttle's gain-or-offset comparison on the whitened residual, for the
    /// reading's actuator.
    pub(super) fn whitened_kind(&self, j: usize) -> Option<KindFit> {
        self.whitened
            .filter(|_| self.reading.is_some_and(|r| r.actuator == j))
    }
    /// A reading's change is a fault: a gain under `1 - loe_tau` (a loss by the class's
    /// definition: near trim a surface's output moves little whatever its gain, so the gain's
    /// own size is the measure; a gain above one is no class, and is what a model calibrated in
    /// closed loop reads on a healthy actuator); a stuck output whose deviation from the
    /// commands, its root mean square over the changed stretch, is beyond `bias_tau` (stuck is
    /// a kind, told by the output no longer following the commands); an offset at least
    /// `threshold` and beyond `bias_tau` (an offset is a fault by its size alone, and the
    /// wind's and the model's slow part imitate one up to the deviation healthy flights show).
    pub(super) fn is_fault_size(&self, r: &Reading) -> bool {
        let p = &self.params;
        match r.kind {
            ChangeKind::Gain => 1.0 - r.value > p.loe_tau,
            ChangeKind::Offset => self.is_fault_size_offset(r.value),
            ChangeKind::Stuck => {
                let ms = r.command_rms * r.command_rms;
                let rms = (r.value * r.value - 2.0 * r.value * r.command_mean + ms).max(0.0);
                rms.sqrt() > p.bias_tau
            }
        }
    }
    /// Whether `r`'s gain change read as an offset of its actuator is of a fault's size: the
    /// offset that matches `(γ - 1) u` over the stretch in the least-squares sense is
    /// `(γ - 1)` times the command's mean there.
    pub(super) fn offset_reading_of_fault_size(&self, r: &Reading) -> bool {
        self.is_fault_size_offset((r.value - 1.0) * r.command_mean)
    }

    /// An offset of a fault's size: at least `threshold` and beyond `bias_tau`.
    fn is_fault_size_offset(&self, offset: f64) -> bool {
        let p = &self.params;
        offset.abs() >= p.threshold && offset.abs() > p.bias_tau
    }

    /// D2: the actuator the data alarm on: named clearly by the whitened search (its margin is
    /// honest about the wind's colour; the plain search's counts it only through the lag-one
    /// autocorrelation, and in 1.5 times the gusts read healthy surfaces clearly changed), on a
    /// change of at least `CLASS_MIN_S` that began with a second of the store before it, of a
    /// fault's size ([`Self::is_fault_size`]), that a gain and an offset of the same actuator
    /// changing together do not explain clearly better (by `DATA_MARGIN`): a fault of one kind
    /// leaves the pair's second unknown little to add, the wind's shape does not.
    pub(super) fn data_alarm(&self) -> Option<usize> {
        let r = self.naming_reading()?;
        let before = (1.0 / self.dt).round() as usize;
        let long = r.samples as f64 * self.dt >= CLASS_MIN_S;
        (self.reading_whitened
            && long
            && r.samples + before <= self.change.len()
            && self.is_fault_size(&r)
            && -r.margin_over(r.mixed_drop) < DATA_MARGIN)
            .then_some(r.actuator)
    }
    /// C1: the class the data give actuator `j`: the reading is its, the stretch at least
    /// `CLASS_MIN_S`, one kind beats the others by `DATA_MARGIN` and the pair of gain and
    /// offset is not significantly better (`PAIR_INSIGNIFICANT`); a motor's or throttle's gain
    /// against offset on the whitened residual. A ramp that beats the best step is a drift.
    pub(super) fn data_class(&self, j: usize) -> Option<FaultClass> {
        let r = self.reading.filter(|r| r.actuator == j)?;
        let p = &self.params;
        if r.samples as f64 * self.dt < CLASS_MIN_S {
            return None;
        }
        // A drift: the residual's ramp beats the best step clearly, fits as well as the pair
        // and moves the output away from the healthy model's (a ramp back toward it is a
        // fault's end or the wind's slow part). On a surface an offset growing; on a motor
        // also a gain weakening under a controller that holds the thrust, whose command then
        // rises along a ramp.
        let span = r.ramp_samples as f64 * self.dt;
        let deviation = match r.kind {
            ChangeKind::Gain => (r.value - 1.0) * r.command_mean,
            ChangeKind::Offset => r.value,
            ChangeKind::Stuck => r.value - r.command_mean,
        };
        if span >= CLASS_MIN_S
            && r.ramp_rate * deviation > 0.0
            && (r.ramp_rate * span).abs() > p.bias_tau
            && r.ramp_drop >= r.mixed_drop
            && -r.margin_over(r.ramp_drop) >= DATA_MARGIN
        {
            return Some(FaultClass::Drift);
        }
        let (kind, value, margin, mixed, pair_keeps) = match self.whitened_kind(j) {
            Some(f) => (
                f.kind,
                f.value,
                f.margin,
                f.mixed_margin,
                self.pair_keeps_kind(&f, f.kind),
            ),
            None => (
                r.kind,
                r.value,
                r.margin_over(r.next_kind_drop),
                -r.margin_over(r.mixed_drop),
                r.kind == ChangeKind::Stuck
                    && (self.change.whitened_gain_or_offset(j, r.samples))
                        .is_some_and(|f| self.pair_keeps_kind(&f, ChangeKind::Stuck)),
            ),
        };
        let whitened = self.whitened_kind(j).is_some();
        let needed = if whitened { KIND_MARGIN } else { DATA_MARGIN };
        if margin < needed || (mixed >= PAIR_INSIGNIFICANT && !pair_keeps) {
            return None;
        }
        match kind {
            ChangeKind::Gain if value < 1.0 - p.loe_tau => Some(FaultClass::LossOfEffectiveness),
            // Hovering, a motor's gain and offset differ only through its command's few per
            // cent of variation, which the plain fit weighs against the wind: only the
            // whitened comparison tells them.
            ChangeKind::Offset if value.abs() > p.bias_tau && (self.is_angle[j] || whitened) => {
                Some(FaultClass::Bias)
            }
            ChangeKind::Stuck => Some(FaultClass::Stuck),
            _ => None,
        }
    }
    /// Whether a gain and an offset fitted together (on the whitened residual) leave `kind` its
    /// class: the class definitions applied to the pair read the same class (an offset's pair
    /// gain within `loe_tau` of 1, a gain's pair offset within `bias_tau`, a stuck output's
    /// pair gain within `stuck_gamma` of 0: a stuck output is a pair, its gain zero). The pair
    /// then fits better only by what the tolerance is for: the calibrated model's own error on
    /// the command's swings.
    pub(super) fn pair_keeps_kind(&self, f: &KindFit, kind: ChangeKind) -> bool {
        let p = &self.params;
        match kind {
            ChangeKind::Gain => f.pair_delta.abs() <= p.bias_tau,
            ChangeKind::Offset => (f.pair_gamma - 1.0).abs() <= p.loe_tau,
            ChangeKind::Stuck => f.pair_gamma.abs() <= p.stuck_gamma,
        }
    }
    /// Whether the command separates gain and bias: its std over the window at least
    /// `excitation_min_std`, the MIT-UKF's gamma std at most `sigma_gamma_max` (a NaN spread is
    /// no evidence of excitation).
    pub(super) fn separable(&self, j: usize) -> bool {
        let st = &self.actuators[j];
        let p = &self.params;
        st.u.sd() >= p.excitation_min_std && self.sigma_gamma(j) <= p.sigma_gamma_max
    }

    fn sigma_gamma(&self, j: usize) -> f64 {
        let var_gamma = self.actuators[j].channels[0].last.block[0];
        if var_gamma.is_nan() {
            f64::NAN
        } else {
            var_gamma.max(0.0).sqrt()
        }
    }

    /// Why gain and bias are not separable, for a decision's detail.
    pub(super) fn not_separable(&self, j: usize) -> String {
        let p = &self.params;
        format!(
            "command std {:.4} over {} s, gamma std {:.3}: gain and bias not separable (the command must move by {} or more)",
            self.actuators[j].u.sd(),
            p.window_s,
            self.sigma_gamma(j),
            p.excitation_min_std
        )
    }

    /// A class's missing reason as text.
    pub(super) fn why_text(&self, j: usize, why: NoClass) -> String {
        match why {
            NoClass::NotSeparable => self.not_separable(j),
            NoClass::BoundsTellNothing => {
                "the MIT-UKF's bounds do not yet tell a gain from a bias: the class follows".into()
            }
        }
    }

    /// C2: the class from the MIT-UKF's estimate and its bounds, and whether it is only the
    /// mixed fallback. A kind is told when its coefficient is beyond its tolerance with bounds
    /// excluding the healthy value, and the other is not (its bounds reach within its
    /// tolerance); any other change (both beyond, or a gain above 1) is mixed: a loss only if
    /// one could make it (the output moved toward zero by no more than the command), else a
    /// bias (a range output's deviation toward zero is always a loss: it cannot go below zero).
    /// A gain bounded within `stuck_gamma` of zero with an offset beyond its tolerance is
    /// stuck. `None` while the bounds tell nothing.
    pub(super) fn filter_class(&self, j: usize) -> Option<(FaultClass, bool)> {
        let p = &self.params;
        let st = &self.actuators[j];
        let e = st.channels[0].last;
        let gain_off = (e.gamma - 1.0).abs() > p.loe_tau && (e.gamma_hi < 1.0 || e.gamma_lo > 1.0);
        let bias_off = e.delta.abs() > p.bias_tau && (e.delta_lo > 0.0 || e.delta_hi < 0.0);
        let gain_held = e.gamma_lo <= 1.0 + p.loe_tau && 1.0 - p.loe_tau <= e.gamma_hi;
        let bias_held = e.delta_lo <= p.bias_tau && -p.bias_tau <= e.delta_hi;
        if gain_off && !bias_off && e.gamma < 1.0 && bias_held {
            return Some((FaultClass::LossOfEffectiveness, false));
        }
        if bias_off && !gain_off && gain_held {
            return Some((FaultClass::Bias, false));
        }
        // A gain whose bounds lie within `stuck_gamma` of zero with an offset beyond its
        // tolerance: the output no longer follows the command (stuck, by the class
        // definitions). Not a gain passing through zero on its way: the command has moved
        // (`separable`) and the whole bounds are there. A range output's offset must be inside
        // its range: at or below zero it is a total loss.
        let near_zero = -p.stuck_gamma < e.gamma_lo && e.gamma_hi < p.stuck_gamma;
        let inside = self.is_angle[j] || e.delta_lo > p.bias_tau;
        if near_zero && bias_off && inside {
            return Some((FaultClass::Stuck, false));
        }
        if !(gain_off || bias_off) {
            return None;
        }
        // A motor's or throttle's output cannot go below zero: a deviation toward zero beyond
        // the command is a loss the estimate overstates, not an offset.
        let off = st.channels[0].e;
        let within = off.abs() <= st.u.mean.abs() || !self.is_angle[j];
        let loss = off * st.u.mean.signum() < 0.0 && within && e.gamma < 1.0;
        let class = if loss {
            FaultClass::LossOfEffectiveness
        } else {
            FaultClass::Bias
        };
        Some((class, true))
    }
    /// Whether the MIT-UKF's bounds keep actuator `j` outside what the classes call healthy:
    /// its gain's bounds beyond `loe_tau` of 1 or its offset's beyond `bias_tau` of 0 (bounds
    /// too wide to tell, or not finite, show nothing).
    pub(super) fn filter_shows_fault(&self, j: usize) -> bool {
        let p = &self.params;
        let e = self.actuators[j].channels[0].last;
        let gain_off = e.gamma_hi < 1.0 - p.loe_tau || e.gamma_lo > 1.0 + p.loe_tau;
        let bias_off = e.delta_hi < -p.bias_tau || e.delta_lo > p.bias_tau;
        gain_off || bias_off
    }
    /// C1, else C2 when separable, else C3: the class, its rule, whether it is the mixed
    /// fallback, and why there is none.
    pub(super) fn classify(&self, j: usize) -> (FaultClass, Rule, bool, Option<NoClass>) {
        if let Some(c) = self.data_class(j) {
            return (c, Rule::C1, false, None);
        }
        if !self.separable(j) {
            return (
                FaultClass::Unclassified,
                Rule::C3,
                false,
                Some(NoClass::NotSeparable),
            );
        }
        match self.filter_class(j) {
            Some((c, mixed)) => (c, Rule::C2, mixed, None),
            None => (
                FaultClass::Unclassified,
                Rule::C3,
                false,
                Some(NoClass::BoundsTellNothing),
            ),
        }
    }

    /// Actuator `j`'s fault in force as identified for the filters
    /// (`VehicleFilters::hold_class`), when it is alone: the data's fit of it
    /// ([`Self::data_identified`]), else a range output's offset by elimination
    /// ([`Self::offset_by_elimination`]).
    pub fn identified(&self, j: usize) -> Option<Identified> {
        let class = self.active(j)?;
        if (0..self.actuators.len()).any(|k| k != j && self.active(k).is_some()) {
            return None;
        }
        let data = if self.actuators[j].class_mixed {
            None
        } else {
            self.data_identified(j, class)
        };
        data.or_else(|| self.offset_by_elimination(j, class))
    }
    /// A motor's or throttle's bias the data do not fit clearly: at its operating point a gain
    /// above one and an offset up give the same output, and no fault class has a gain above
    /// one, so an output above the healthy model's there is the offset it reads (the class
    /// says bias, C2's mixed fallback). Identified as that offset, with the deviation's spread,
    /// the gain at one within the tolerance that tells the class; without it the MIT-UKF,
    /// whose prior on a range output's offset is narrow, shows the offset as a gain.
    fn offset_by_elimination(&self, j: usize, class: FaultClass) -> Option<Identified> {
        let p = &self.params;
        let st = &self.actuators[j];
        if class != FaultClass::Bias || self.is_angle[j] || st.class_from_data {
            return None;
        }
        // Not against the data: a gain they fit clearly better than an offset, or a gain and
        // an offset that together fit clearly better than one kind (the pair's other
        // coefficient beyond the class's tolerance), is no lone offset.
        if let Some(r) = self.reading.filter(|r| r.actuator == j) {
            let fit = self.change.whitened_gain_or_offset(j, r.samples);
            let (kind, margin, mixed) = fit.map_or(
                (
                    r.kind,
                    r.margin_over(r.next_kind_drop),
                    -r.margin_over(r.mixed_drop),
                ),
                |f| (f.kind, f.margin, f.mixed_margin),
            );
            let other_kind = kind != ChangeKind::Offset && margin >= DATA_MARGIN;
            let pair =
                mixed >= DATA_MARGIN && !fit.is_some_and(|f| self.pair_keeps_kind(&f, f.kind));
            if other_kind || pair {
                return None;
            }
        }
        let e = st.channels[0].last;
        let u = st.u.mean;
        let [gg, gd, dd] = e.block;
        let delta = (e.gamma - 1.0) * u + e.delta;
        let var = u * u * gg + 2.0 * u * gd + dd;
        if !(delta > p.bias_tau && var.is_finite() && var > 0.0) {
            return None;
        }
        Some(Identified {
            kind: IdentifiedKind::Offset,
            gamma: 1.0,
            gamma_std: p.loe_tau / 3.0,
            delta,
            delta_std: var.sqrt(),
            tolerance: p.bias_tau,
        })
    }
    /// The data's identification of actuator `j`'s fault (class `class`): when the class is
    /// a loss, a bias or a stuck output and the data fit that kind clearly, the changed
    /// coefficient from the fit and the other at its healthy value within the tolerance that
    /// tells the class (as 3σ).
    fn data_identified(&self, j: usize, class: FaultClass) -> Option<Identified> {
        let p = &self.params;
        let r = self.reading.filter(|r| r.actuator == j)?;
        let fit = self.change.whitened_gain_or_offset(j, r.samples);
        let whitened = fit.filter(|_| r.kind != ChangeKind::Stuck);
        let (kind, value, std) = match (r.kind, fit) {
            (ChangeKind::Stuck, Some(f)) => (r.kind, f.stuck_value, f.stuck_std),
            _ => whitened.map_or((r.kind, r.value, r.value_std), |f| {
                (f.kind, f.value, f.value_std)
            }),
        };
        let (margin, mixed_margin) = whitened.map_or(
            (
                r.margin_over(r.next_kind_drop),
                -r.margin_over(r.mixed_drop),
            ),
            |f| (f.margin, f.mixed_margin),
        );
        let long = r.samples as f64 * self.dt >= CLASS_MIN_S;
        let motor_offset_plain =
            whitened.is_none() && kind == ChangeKind::Offset && self.isolation.is_motor[j];
        let pair_keeps = fit.is_some_and(|f| self.pair_keeps_kind(&f, kind));
        let pair_better = mixed_margin >= DATA_MARGIN && !pair_keeps;
        let needed = if whitened.is_some() {
            KIND_MARGIN
        } else {
            DATA_MARGIN
        };
        if !long || margin < needed || pair_better || motor_offset_plain {
            return None;
        }
        if !(value.is_finite() && std.is_finite() && std > 0.0) {
            return None;
        }
        let kind = match (class, kind) {
            (FaultClass::LossOfEffectiveness, ChangeKind::Gain) => IdentifiedKind::Gain,
            (FaultClass::Bias, ChangeKind::Offset) => IdentifiedKind::Offset,
            (FaultClass::Stuck, ChangeKind::Stuck) => IdentifiedKind::Stuck,
            _ => return None,
        };
        let fitted = (value, std);
        let (gamma, delta) = match kind {
            IdentifiedKind::Gain => (fitted, (0.0, p.bias_tau / 3.0)),
            IdentifiedKind::Offset => ((1.0, p.loe_tau / 3.0), fitted),
            IdentifiedKind::Stuck => ((0.0, p.stuck_gamma / 3.0), fitted),
        };
        Some(Identified {
            kind,
            gamma: gamma.0,
            gamma_std: gamma.1,
            delta: delta.0,
            delta_std: delta.1,
            tolerance: match kind {
                IdentifiedKind::Gain => p.loe_tau,
                _ => p.bias_tau,
            },
        })
    }
    /// The change test's reading of this step, for `RUST_LOG=ahcmon::diagnose=trace`.
    pub(super) fn trace_reading(&self, t: f64) {
        if let Some(r) = self.reading {
            let kind = self.whitened_kind(r.actuator);
            tracing::trace!(
                t,
                actuator = r.actuator,
                kind = ?r.kind,
                value = r.value,
                since = r.since,
                margin = r.margin_over(r.next_kind_drop),
                naming = r.margin_over(r.next_actuator_drop),
                whitened_kind = ?kind.map(|f| f.kind),
                whitened_value = kind.map(|f| f.value),
                whitened_margin = kind.map(|f| f.margin),
                pair_margin = kind.map(|f| f.mixed_margin),
                pair_gamma = kind.map(|f| f.pair_gamma),
                pair_delta = kind.map(|f| f.pair_delta),
                "change test"
            );
        }
    }
    /// What the change test reads for actuator `j`, for a decision's detail.
    pub(super) fn data_note(&self, j: usize) -> Option<String> {
        let r = self.reading.filter(|r| r.actuator == j)?;
        let (kind, value) = self
            .whitened_kind(j)
            .map_or((r.kind, r.value), |f| (f.kind, f.value));
        let what = match kind {
            ChangeKind::Gain => format!("a gain of {value:.2}"),
            ChangeKind::Offset => format!("an offset of {value:+.3}"),
            ChangeKind::Stuck => format!("an output stuck at {value:.3}"),
        };
        let since = if r.samples >= self.change.len() {
            "since at least"
        } else {
            "since"
        };
        let how = if self.data_class(j).is_some() {
            "clearly"
        } else {
            "not clearly"
        };
        Some(format!(
            "{since} t={:.2} s the data fit {what} best, {how}",
            r.since
        ))
    }
}
