//! Per-vehicle, per-actuator decisions: one state machine per actuator, driven by four
//! statistics, each rule with an ID (`docs/diagnosis.md` is the rule table).
//!
//! ```text
//!            S1 bounds / S2 alarm              F1 | F2 | F3
//!  healthy ─────────────────────▶ suspect ───────────────────▶ fault(class) ── R1 ──▶ healthy
//!     ▲                              │                           │  ▲
//!     └──── bounds back, no alarm ───┘               C1 | C2 | C3 └──┘ (a class held 1 s)
//! ```
//!
//! The statistics:
//! - **D1, the filters' alarm.** Per filter, the actuator's effective-output deviation at its
//!   operating point and in its command's excursions, `hypot((γ-1)ū + δ, (γ-1)σ_u)`, and for
//!   angle outputs how far the healthy gain lies outside the gamma bounds (at a reference
//!   deflection), attributed in the space the measurements see (`isolate`), over thresholds
//!   set on healthy Monte-Carlo flights (`ahcmon thresholds`); a CUSUM of that ratio minus one
//!   alarms at `cusum_h_s` and the alarm ends after `clear_s` under half the thresholds.
//! - **D2, the data's alarm.** The change test (`change`), on the residual whitened by its
//!   learned colour, names the actuator clearly (its likelihood ratio over every other
//!   actuator's best at least e^10), the change started inside the stored stretch with a
//!   second of it before, has lasted `CLASS_MIN_S`, and is as large as the thresholds call a
//!   fault.
//! - **S1, the bounds.** The MIT-UKF's bounds exclude the healthy point (gamma 1, delta 0).
//! - The change test's best fit, clear or not, and its kind.
//!
//! Decisions: a D1 alarm is a fault (F1) when the change test fits its actuator best (or an
//! actuator whose fault is already in force: the test fits one change), or
//! (F2) when the data have not named another actuator clearly within `DATA_WAIT_S`; meanwhile
//! the actuator is suspect (S2), and while the data clearly name another actuator its alarm is
//! that one's evidence (`also`). A D2 alarm is a fault by itself (F3). The class (C1-C3) comes
//! from the data when they tell the kind clearly, else from the MIT-UKF's gain and bias when
//! the command separates them, else none with the reason; the data's class outranks the
//! filters'. A fault clears (R1) when no filter alarms on it and the data do not name it.

pub use super::decision::{Decision, DiagnosisParams, Event, Evidence, FaultClass, Health, Rule};

use super::change::{ChangeKind, ChangeTest, KindFit, Reading};
use super::isolate::Isolation;
use crate::estimate::vehicle::{
    AhcEstimate, FILTER_NAMES, Identified, IdentifiedKind, VehicleFilters,
};
use crate::model::MAX_ACTUATORS;
use crate::telemetry::{Profile, Role};

/// Twice the log likelihood ratio that counts as clear (a ratio of e^10, about 2e4 to 1).
const DATA_MARGIN: f64 = 20.0;
/// Twice the log likelihood ratio at which the whitened comparison of one actuator's gain
/// against its offset tells the kind: the 99 % point of chi-squared with one degree of freedom.
/// The actuator and the change's start are given, so this is one comparison of two
/// one-parameter fits on a residual whitened by its learned colour, where `DATA_MARGIN` covers
/// the search over every actuator and start.
const KIND_MARGIN: f64 = 6.63;
/// A changed stretch this long is needed before the data give a class or alarm (s).
pub(crate) const CLASS_MIN_S: f64 = 1.0;
/// The change test's store (s, at most `change::MAX_STORE` samples) and its shortest fit.
const CHANGE_HORIZON_S: f64 = 6.0;
const CHANGE_MIN_S: f64 = 0.2;
/// Memory of the residual's learned colour (s).
const COLOUR_MEMORY_S: f64 = 60.0;
/// How long a filter alarm waits for the data before F2 decides it (s). The change test needs
/// `CHANGE_MIN_S` to fit and about a second to be clear; a filters' misreading at a fault's
/// onset ends within their alarm plus `clear_s`.
const DATA_WAIT_S: f64 = 3.0;
/// The flight envelope of rule X1: roll or pitch beyond twice the autopilots' default lean
/// limit (ArduCopter's `ANGLE_MAX` 30°, ArduPlane's `LIM_ROLL_CD` 45°), or a measured vertical
/// specific force under 0.3 g (free fall), for `ENVELOPE_S`. The rate model is identified about
/// controlled flight; beyond it a decision describes the crash, not an actuator.
const ENVELOPE_ROTORCRAFT_RAD: f64 = 60.0 * std::f64::consts::PI / 180.0;
const ENVELOPE_PLANE_RAD: f64 = 90.0 * std::f64::consts::PI / 180.0;
const FREE_FALL_G: f64 = 0.3;
const ENVELOPE_S: f64 = 0.2;

/// A new class must hold this long before a `changed` decision reports it (s).
pub(crate) const CLASS_HOLD_S: f64 = 1.0;
/// A single kind is the data's class only where a gain and an offset together do not fit
/// significantly better: twice their log likelihood ratio, one parameter more, under the 95 %
/// point of chi-squared with one degree of freedom.
const PAIR_INSIGNIFICANT: f64 = 3.84;

/// Exponential-window mean and variance of a command.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    mean: f64,
    var: f64,
    init: bool,
}

impl Moments {
    fn push(&mut self, x: f64, a: f64) {
        // A non-finite command (a corrupt sample) would spoil the window for good.
        if !x.is_finite() {
            return;
        }
        if !self.init {
            self.mean = x;
            self.init = true;
            return;
        }
        let d = x - self.mean;
        self.mean += a * d;
        self.var = (1.0 - a) * (self.var + a * d * d);
    }

    fn sd(&self) -> f64 {
        self.var.max(0.0).sqrt()
    }
}

/// D1 of one filter on one actuator.
#[derive(Debug, Clone, Copy, Default)]
struct Channel {
    cusum: f64,
    alarm: bool,
    alarm_since: f64,
    below: f64,
    last: AhcEstimate,
    /// The attributed deviation, excursion and gain statistic.
    e: f64,
    excursion: f64,
    gain_gap: f64,
    /// Until then the filter warms up after a reset: its alarm is held as it was and its
    /// CUSUM stays at zero (a fresh filter reads healthy, which says nothing either way).
    hold_until: f64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Actuator {
    u: Moments,
    channels: [Channel; 2],
    health: Health,
    /// Filters (bit f) that have alarmed on the fault in force, when and by which rule it was
    /// decided.
    decided_filters: u8,
    decided_at: f64,
    decided_by: Option<Rule>,
    /// When the data last named another actuator clearly during this actuator's alarm (F2's
    /// wait runs from then).
    contradicted_at: f64,
    /// When the data last named this actuator clearly (R1's hold of a fault they decided).
    data_named_at: f64,
    /// The class in force came from the data (C1), or from the filters' mixed fallback (a
    /// tie-break, not a kind: the filters are not held to it).
    class_from_data: bool,
    class_mixed: bool,
    /// A class other than the one in force, and since when it has been read.
    class_candidate: Option<(FaultClass, f64)>,
    /// Since when the class in force has been read by a stronger rule than the one it has.
    stronger_since: Option<f64>,
    /// Seconds the MIT-UKF's bounds have excluded (included) the healthy point.
    bounds_out: f64,
    bounds_in: f64,
    /// Seconds the excitation has been low, and whether that was said.
    low_for: f64,
    excitation_reported: bool,
}

impl Actuator {
    fn alarms(&self) -> u8 {
        (0..2)
            .filter(|&f| self.channels[f].alarm)
            .fold(0, |m, f| m | (1 << f))
    }

    fn first_alarm(&self) -> Option<f64> {
        (self.channels.iter())
            .filter(|c| c.alarm)
            .map(|c| c.alarm_since)
            .min_by(f64::total_cmp)
    }
}

/// Per-vehicle diagnosis over both filters.
pub struct Diagnoser {
    pub params: DiagnosisParams,
    sysid: u8,
    names: Vec<String>,
    channels: Vec<u8>,
    dt: f64,
    t0: Option<f64>,
    is_angle: Vec<bool>,
    isolation: Isolation,
    actuators: Vec<Actuator>,
    change: ChangeTest,
    /// The change test's reading this step, and its gain-or-offset comparison on the whitened
    /// residual (motors and throttle, once the colour is learned).
    reading: Option<Reading>,
    whitened: Option<KindFit>,
    /// The reading came from the whitened search.
    reading_whitened: bool,
    /// When the data are next read while nothing is under way, and whether the reading is such
    /// a scan's (of a stretch where nothing was under way: the data's alarm may use it, F1's
    /// "the data fit it best" takes a reading of what is under way).
    next_scan: f64,
    reading_scanned: bool,
    /// When the store may next be searched while a change is under way (`SEARCH_INTERVAL_S`),
    /// and the store's count of samples pushed when the reading was last brought up to date.
    next_search: f64,
    search_pushed: u64,
    /// Rule X1: the lean limit, since when the vehicle has been out of its envelope and why,
    /// and whether that has lasted `ENVELOPE_S` (a crash).
    envelope_rad: f64,
    outside: Option<(f64, String)>,
    crashing: bool,
    /// Since when the vehicle has been back inside the envelope.
    inside_since: Option<f64>,
}

impl Diagnoser {
    pub fn new(params: DiagnosisParams, sysid: u8, profile: &Profile, dt: f64) -> Self {
        let names = profile.actuator_names();
        let effects = crate::estimate::vehicle::weighted_effects(profile, dt);
        let is_motor: Vec<bool> = (profile.actuators.iter())
            .map(|a| a.role == Role::Motor)
            .collect();
        let mut motors: Vec<usize> = (0..is_motor.len()).filter(|&j| is_motor[j]).collect();
        if motors.len() < 3 {
            motors.clear();
        }
        let capacity =
            ((CHANGE_HORIZON_S / dt).round() as usize).clamp(16, super::change::MAX_STORE);
        let change = ChangeTest::new(
            effects.clone(),
            crate::estimate::vehicle::residual_weights(profile, dt),
            profile.measurements(),
            capacity,
            ((CHANGE_MIN_S / dt).round() as usize).max(5),
            (COLOUR_MEMORY_S / dt).round() as usize,
        );
        let params = DiagnosisParams {
            threshold: profile.diagnosis.threshold,
            gain_threshold: profile.diagnosis.gain_threshold.unwrap_or(f64::INFINITY),
            ..params
        };
        Self {
            sysid,
            actuators: vec![Actuator::default(); names.len()],
            channels: profile.actuators.iter().map(|a| a.channel).collect(),
            is_angle: (profile.actuators.iter())
                .map(|a| !a.role.is_range())
                .collect(),
            isolation: Isolation {
                effects,
                is_motor,
                motors,
                explain_min: params.explain_min,
            },
            names,
            params,
            dt,
            t0: None,
            change,
            reading: None,
            whitened: None,
            reading_whitened: false,
            next_scan: f64::NEG_INFINITY,
            next_search: f64::NEG_INFINITY,
            search_pushed: 0,
            reading_scanned: false,
            envelope_rad: if profile.vehicle == crate::telemetry::VehicleKind::Plane {
                ENVELOPE_PLANE_RAD
            } else {
                ENVELOPE_ROTORCRAFT_RAD
            },
            outside: None,
            crashing: false,
            inside_since: None,
        }
    }

    /// Rule X1, before each `update`: the attitude and, where measured, the vertical specific
    /// force (m/s², about -9.8 in level flight). Once out of the envelope for `ENVELOPE_S` the
    /// vehicle is in a crash until it has been back inside for `clear_s`: a tumbling vehicle
    /// passes through level attitudes on its way round.
    pub fn envelope(&mut self, t: f64, attitude: [f64; 3], az: Option<f64>) {
        let lean = attitude[0].abs().max(attitude[1].abs());
        let falling = az.is_some_and(|a| a.abs() < FREE_FALL_G * 9.80665);
        if lean <= self.envelope_rad && !falling {
            let back = *self.inside_since.get_or_insert(t);
            if !self.crashing || t - back >= self.params.clear_s {
                (self.outside, self.crashing) = (None, false);
            }
            return;
        }
        self.inside_since = None;
        if self.outside.is_none() {
            let why = if lean > self.envelope_rad {
                format!(
                    "roll {:.0}°, pitch {:.0}°",
                    attitude[0].to_degrees(),
                    attitude[1].to_degrees()
                )
            } else {
                format!("free fall (a_z {:+.1} m/s²)", az.unwrap_or(0.0))
            };
            self.outside = Some((t, why));
        }
        self.crashing |= self
            .outside
            .as_ref()
            .is_some_and(|(t0, _)| t - t0 >= ENVELOPE_S);
    }

    /// Feed the healthy model's residual of this step and the commands that acted, before
    /// `update`. The residual's colour learns while nothing is under way, and during a lone
    /// fault from the residual with that fault's identification taken out (learned only before
    /// a fault, a short stretch reads the wind's colour short).
    pub fn observe(&mut self, t: f64, residual: &[f64; 4], u: &[f64]) {
        if !self.under_way() {
            self.change.push(t, residual, u, true);
            return;
        }
        let mut in_force = (0..self.actuators.len())
            .filter(|&j| matches!(self.actuators[j].health, Health::Fault(_)));
        let alone = match (in_force.next(), in_force.next()) {
            (Some(j), None) if self.alarmed_elsewhere(j) == 0 => Some(j),
            _ => None,
        };
        let identified = alone
            .filter(|_| self.change.colour_learned())
            .and_then(|j| Some((j, self.identified(j)?)));
        match identified {
            Some((j, c)) => self
                .change
                .push_identified(t, residual, u, j, c.gamma, c.delta),
            None => self.change.push(t, residual, u, false),
        }
    }

    /// Actuators other than `j` with an alarm (bit k).
    fn alarmed_elsewhere(&self, j: usize) -> u16 {
        (0..self.actuators.len())
            .filter(|&k| k != j && self.actuators[k].alarms() != 0)
            .fold(0, |m, k| m | (1 << k))
    }

    /// A fault in force, a CUSUM above zero, or the data naming an actuator clearly: the
    /// change test reads the data on every step, and the residual's colour does not learn.
    fn under_way(&self) -> bool {
        self.naming_reading().is_some()
            || self.actuators.iter().any(|st| {
                matches!(st.health, Health::Fault(_))
                    || st.channels.iter().any(|c| c.cusum > 0.0 || c.alarm)
            })
    }

    /// A new flight, a restart or a long hole: the stored residuals do not chain with the next
    /// ones.
    pub fn residual_gap(&mut self) {
        self.change.clear();
    }

    /// The change test's last reading (`None` while nothing is under way).
    pub fn reading(&self) -> Option<Reading> {
        self.reading
    }

    pub fn deviation(&self, filter: usize, j: usize) -> f64 {
        self.actuators[j].channels[filter].e
    }

    pub fn excursion(&self, filter: usize, j: usize) -> f64 {
        self.actuators[j].channels[filter].excursion
    }

    pub fn gain_gap(&self, filter: usize, j: usize) -> f64 {
        self.actuators[j].channels[filter].gain_gap
    }

    /// Filter `f` was re-initialised at `t`: hold its alarms through a warm-up.
    pub fn filter_reset(&mut self, f: usize, t: f64) {
        let until = t + self.params.warmup_s;
        for st in &mut self.actuators {
            let ch = &mut st.channels[f];
            ch.hold_until = until;
            ch.cusum = 0.0;
            ch.below = 0.0;
        }
    }

    pub fn health(&self, j: usize) -> Health {
        self.actuators[j].health
    }

    /// The class of the fault in force on actuator `j`.
    pub fn active(&self, j: usize) -> Option<FaultClass> {
        match self.actuators[j].health {
            Health::Fault(c) => Some(c),
            _ => None,
        }
    }

    pub fn fault_in_force(&self) -> bool {
        (0..self.actuators.len()).any(|j| self.active(j).is_some())
    }

    /// The earliest evidence of the faults in force: their decisions, their filters' alarms
    /// and the data's estimate of when their change began (`None` with no fault in force).
    pub fn fault_evidence_since(&self) -> Option<f64> {
        let data = |j: usize| {
            (self.reading)
                .filter(|r| r.actuator == j)
                .map_or(f64::INFINITY, |r| r.since)
        };
        (0..self.actuators.len())
            .filter(|&j| self.active(j).is_some())
            .map(|j| {
                let a = &self.actuators[j];
                (a.decided_at)
                    .min(a.first_alarm().unwrap_or(f64::INFINITY))
                    .min(data(j))
            })
            .min_by(f64::total_cmp)
    }

    /// The reading when it names its actuator clearly against every other one.
    fn naming_reading(&self) -> Option<Reading> {
        self.reading
            .filter(|r| r.margin_over(r.next_actuator_drop) >= DATA_MARGIN)
    }

    /// What a step's decisions tell the filters: a decided fault makes both forget what they
    /// knew of that actuator, a cleared one sends the MIT-UKF's back to the healthy point; then
    /// the classes and whether a fault is in force, and the data's fit where it is awaited.
    pub fn steer_filters(
        &self,
        decisions: &[Decision],
        profile: &Profile,
        filters: &mut dyn VehicleFilters,
    ) {
        for d in decisions {
            let Some(j) = (d.actuator.as_deref()).and_then(|a| profile.actuator_index(a)) else {
                continue;
            };
            match d.event {
                Event::Fault => filters.forget(j),
                Event::Cleared => filters.recovered(j),
                _ => {}
            }
        }
        for j in 0..self.actuators.len() {
            filters.class_in_force(j, self.active(j).and_then(FaultClass::changed_kind));
        }
        filters.set_fault_in_force(self.fault_in_force());
        for j in 0..filters.actuators() {
            if filters.awaits_identification(j) {
                filters.hold_class(j, self.identified(j));
            }
        }
    }

    /// The statistics of this step: the change test's reading, the attributed deviations,
    /// and the CUSUMs (D1).
    fn statistics(&mut self, t: f64, u: &[f64], est: &[&[AhcEstimate]; 2], warm: bool) {
        let p = self.params;
        let a = (self.dt / p.window_s).min(1.0);
        let l = self.actuators.len();
        let mut raw = [[[0.0; MAX_ACTUATORS]; 2]; 3];
        let mut gain_seen = [false; MAX_ACTUATORS];
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        for j in 0..l {
            let st = &mut self.actuators[j];
            st.u.push(u[j], a);
            let sigma_u = st.u.sd();
            gain_seen[j] = self.is_angle[j] && sigma_u >= p.excitation_min_std;
            for f in 0..2 {
                let e = est[f][j];
                st.channels[f].last = e;
                raw[0][f][j] = finite((e.gamma - 1.0) * st.u.mean + e.delta);
                raw[1][f][j] = finite((e.gamma - 1.0) * sigma_u);
                let gap = if e.gamma_hi < 1.0 {
                    e.gamma_hi - 1.0
                } else if e.gamma_lo > 1.0 {
                    e.gamma_lo - 1.0
                } else {
                    0.0
                };
                raw[2][f][j] = if gain_seen[j] {
                    finite(gap * p.gain_ref)
                } else {
                    0.0
                };
            }
        }
        self.read_store(t, warm);
        let preferred = self.naming_reading().map(|r| r.actuator);
        let mut explained = [[[0.0; MAX_ACTUATORS]; 2]; 3];
        for (k, (xs, rs)) in explained.iter_mut().zip(&raw).enumerate() {
            for (x, r) in xs.iter_mut().zip(rs) {
                // Motors have no gain statistic, so no thrust mismatch to take out of it.
                let e = if k < 2 {
                    self.isolation.without_thrust_mismatch(r)
                } else {
                    *r
                };
                self.isolation.explain(&e[..l], &mut x[..l], preferred);
            }
        }
        for (j, st) in self.actuators.iter_mut().enumerate() {
            for (f, ch) in st.channels.iter_mut().enumerate() {
                ch.e = explained[0][f][j];
                ch.excursion = explained[1][f][j];
                ch.gain_gap = if gain_seen[j] {
                    explained[2][f][j]
                } else {
                    0.0
                };
                let ratio = (ch.e.hypot(ch.excursion) / p.threshold)
                    .max(ch.gain_gap.abs() / p.gain_threshold);
                ch.cusum = (ch.cusum + (ratio - 1.0) * self.dt).max(0.0);
                if !warm || t < ch.hold_until {
                    ch.cusum = 0.0;
                    continue;
                }
                if !ch.alarm && ch.cusum > p.cusum_h_s {
                    (ch.alarm, ch.alarm_since, ch.below) = (true, t, 0.0);
                } else if ch.alarm {
                    ch.below = if ratio < 0.5 { ch.below + self.dt } else { 0.0 };
                    if ch.below >= p.clear_s {
                        (ch.alarm, ch.cusum) = (false, 0.0);
                    }
                }
            }
        }
    }

    /// Feed one step: commands and both filters' estimates (`est[filter][j]`). Decisions are
    /// appended to `out`.
    pub fn update(
        &mut self,
        t: f64,
        u: &[f64],
        est: &[&[AhcEstimate]; 2],
        out: &mut Vec<Decision>,
    ) {
        let t0 = *self.t0.get_or_insert(t);
        let warm = t - t0 >= self.params.warmup_s;
        self.statistics(t, u, est, warm);
        if !warm {
            return;
        }
        self.trace_reading(t);
        let data_alarm = self.data_alarm();
        let named = self.naming_reading().map(|r| r.actuator);
        if let Some(k) = named {
            self.actuators[k].data_named_at = t;
        }
        let from = out.len();
        for j in 0..self.actuators.len() {
            if self.actuators[j].health == Health::CannotJudge {
                continue;
            }
            self.gate(t, j, out);
            self.track_bounds(j);
            match self.actuators[j].health {
                Health::Fault(class) => self.in_force(t, j, class, data_alarm, out),
                health => self.judge(t, j, health, data_alarm, named, out),
            }
        }
        if let Some((since, why)) = self.outside.as_ref().filter(|_| self.crashing) {
            let note = format!(
                "in a crash since t={since:.2} s ({why}): out of the flight envelope, the model does not hold (X1)"
            );
            for d in &mut out[from..] {
                d.in_crash = true;
                rules::append_detail(d, note.clone());
            }
        }
    }
}

#[path = "classify.rs"]
mod classify;
#[path = "gate.rs"]
pub mod gate;
#[path = "read_store.rs"]
mod read_store;
#[path = "rules.rs"]
mod rules;

#[cfg(test)]
#[path = "vehicle_tests.rs"]
mod tests;
