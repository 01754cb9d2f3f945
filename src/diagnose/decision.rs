//! The diagnosis' vocabulary: its settings, the classes, events and rules, and the decision
//! record written to the decisions JSONL (`replay/schemas/decisions.schema.json`).

use crate::estimate::vehicle::IdentifiedKind;
use serde::Serialize;

/// Detection, gating and classification settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiagnosisParams {
    /// No decisions before this (s).
    pub warmup_s: f64,
    /// Window of the operating point and excitation statistics (s).
    pub window_s: f64,
    /// Effective output deviation (units of normalised command) that counts as a fault.
    pub threshold: f64,
    /// The gain statistic's threshold (same units; see `update`); infinite: it decides nothing.
    pub gain_threshold: f64,
    /// Reference deflection of an angle output (fraction of its half-range) at which a gain
    /// known to be off is judged: what the fault would cost the operator in a manoeuvre.
    pub gain_ref: f64,
    /// CUSUM alarm level (s of the statistic at twice the threshold ≈ this × 1).
    pub cusum_h_s: f64,
    /// Below half the threshold for this long clears a fault (s).
    pub clear_s: f64,
    /// Command standard deviation over the window below which gamma and delta are not separable.
    pub excitation_min_std: f64,
    /// The MIT-UKF's gamma standard deviation above which gamma is not identified.
    pub sigma_gamma_max: f64,
    /// Classification tolerances: gamma below `1 - loe_tau` is a loss of effectiveness; |delta|
    /// above `bias_tau` is a bias; |gamma| below `stuck_gamma` with a bias is stuck.
    pub loe_tau: f64,
    pub bias_tau: f64,
    pub stuck_gamma: f64,
    /// Both filters alarming on the same actuator within this time (s) give a decision
    /// confidence 0.9; further apart 0.75; one filter 0.6.
    pub agree_s: f64,
    /// An actuator joins the explanation of the deviations only if its own share of what is
    /// still unexplained is at least this (normalised command); see `isolate`. Fixed rather
    /// than tied to the threshold, so that the threshold calibration does not chase itself.
    pub explain_min: f64,
    /// The persistence window of rule S1: the MIT-UKF's bounds excluding the healthy point
    /// this long make the actuator suspect (s).
    pub suspect_s: f64,
}

impl Default for DiagnosisParams {
    fn default() -> Self {
        Self {
            warmup_s: 5.0,
            window_s: 2.0,
            // Calibrated on the healthy flights with gusts and 10 % mismatch (see README).
            threshold: 0.08,
            gain_threshold: f64::INFINITY,
            gain_ref: 0.25,
            cusum_h_s: 0.25,
            clear_s: 2.0,
            excitation_min_std: 0.01,
            sigma_gamma_max: 0.15,
            loe_tau: 0.15,
            bias_tau: 0.04,
            stuck_gamma: 0.25,
            agree_s: 0.5,
            explain_min: 0.04,
            suspect_s: 2.0,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultClass {
    LossOfEffectiveness,
    Stuck,
    Bias,
    Drift,
    /// The effective output is off, but the flight has not moved the command enough to tell
    /// a gain from a bias (steady hover): detected and isolated, class open.
    Unclassified,
}

impl FaultClass {
    /// What the class changes: a loss the gain, a bias or a drift the offset (a drift is an
    /// offset that moves: it leaves the gain as a bias does), a stuck output both; `None`
    /// for a class still open.
    pub fn changed_kind(self) -> Option<IdentifiedKind> {
        match self {
            Self::LossOfEffectiveness => Some(IdentifiedKind::Gain),
            Self::Bias | Self::Drift => Some(IdentifiedKind::Offset),
            Self::Stuck => Some(IdentifiedKind::Stuck),
            Self::Unclassified => None,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            FaultClass::LossOfEffectiveness => "loss_of_effectiveness",
            FaultClass::Stuck => "stuck",
            FaultClass::Bias => "bias",
            FaultClass::Drift => "drift",
            FaultClass::Unclassified => "unclassified",
        }
    }
}

/// Where an actuator stands: the state machine of `docs/diagnosis.md`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Health {
    #[default]
    Healthy,
    /// Evidence of a fault that does not make one (yet): the bounds exclude the healthy point
    /// (S1), or an alarm waits for the data (S2).
    Suspect,
    Fault(FaultClass),
    /// The calibrated model does not explain the axes this actuator mostly acts on (G2): no
    /// rule decides on it.
    CannotJudge,
}

impl Health {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Healthy => "healthy",
            Self::Suspect => "suspect",
            Self::Fault(c) => c.as_str(),
            Self::CannotJudge => "cannot judge",
        }
    }
}

/// The rules, by their ID in `docs/diagnosis.md`'s rule table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Rule {
    /// Suspect: the MIT-UKF's bounds exclude the healthy point for the persistence window.
    S1,
    /// Suspect: a filter alarm (D1) the data do not yet confirm.
    S2,
    /// Suspect → healthy: no alarm, and the bounds hold the healthy point again.
    S3,
    /// Fault: a filter alarm whose actuator the change test fits best.
    F1,
    /// Fault: a filter alarm the data have not contradicted within `DATA_WAIT_S`.
    F2,
    /// Fault: the change test names the actuator clearly with a change beyond the thresholds
    /// (D2).
    F3,
    /// Class from the data (the change test's kind).
    C1,
    /// Class from the MIT-UKF's gain and bias.
    C2,
    /// No class: the excitation cannot separate gain and bias.
    C3,
    /// A fault in force changed: a class held `CLASS_HOLD_S` on evidence of the fault as it
    /// is now, or another filter alarming on it.
    K1,
    /// Cleared: no alarm for `clear_s` and the data do not name it.
    R1,
    /// Not judged: gain and bias not separable (a statement, `excitation_low`).
    G1,
    /// Not judged: the calibrated model does not explain the axes the actuator mostly acts on
    /// (a statement, `cannot_judge`).
    G2,
    /// Out of the flight envelope: a decision made then is marked `in_crash`.
    X1,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Event {
    Fault,
    Changed,
    Cleared,
    LinkLost,
    LinkRestored,
    ExcitationLow,
    FilterReset,
    /// The data cannot support an estimate (too slow a stream, a model that does not fit):
    /// said once, and no fault is decided for the vehicle.
    CannotEstimate,
    /// An actuator is suspect: evidence of a fault that does not (yet) make one (rules S1, S2).
    Suspect,
    /// A suspect actuator is healthy again.
    SuspectCleared,
    /// An actuator the calibrated model cannot judge (rule G2): said once, and no fault is
    /// decided on it.
    CannotJudge,
    /// The vehicle's stream is mixed with another (its system id from two senders at once):
    /// its estimates may be wrong. Said once per vehicle.
    Contaminated,
}

impl Event {
    /// What the monitor says about an actuator without a fault: no alert, and the table's
    /// state column carries it.
    pub fn is_statement(self) -> bool {
        matches!(
            self,
            Self::ExcitationLow | Self::Suspect | Self::SuspectCleared | Self::CannotJudge
        )
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Self::Fault => "fault",
            Self::Changed => "changed",
            Self::Cleared => "cleared",
            Self::LinkLost => "link_lost",
            Self::LinkRestored => "link_restored",
            Self::ExcitationLow => "excitation_low",
            Self::FilterReset => "filter_reset",
            Self::CannotEstimate => "cannot_estimate",
            Self::Suspect => "suspect",
            Self::SuspectCleared => "suspect_cleared",
            Self::CannotJudge => "cannot_judge",
            Self::Contaminated => "contaminated",
        }
    }
}

/// A filter's D1 statistic against its threshold: `deviation` (the attributed deviation and
/// excursion, `hypot`) or `gain_gap` (an angle output's gain statistic).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Evidence {
    pub filter: &'static str,
    pub statistic: &'static str,
    pub value: f64,
    pub threshold: f64,
}

/// One decision, as written to the decisions JSONL (`replay/schemas/decisions.schema.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Decision {
    #[serde(serialize_with = "super::serialize_time")]
    pub t: f64,
    pub sysid: u8,
    pub event: Event,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub actuator: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub channel: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub class: Option<FaultClass>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gamma: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delta: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gamma_bounds: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delta_bounds: Option<[f64; 2]>,
    /// How far the actuator's effective output (`gamma u + delta`) is off at the operating
    /// point, as the measurements attribute it (the MIT-UKF's; the estimates' `deviation`):
    /// the size of a bias, whatever the filter's split of it into gain and offset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deviation: Option<f64>,
    /// Which filters agree.
    pub filters: Vec<&'static str>,
    /// The numbers behind the filters' alarm: of the filters alarming at this step, the D1
    /// statistic standing highest against its threshold (this step's value: the alarm is a
    /// CUSUM, so it may stand under the threshold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evidence: Option<Evidence>,
    pub confidence: f64,
    /// Other actuators that also alarmed (a `multiple` isolation), by name.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub also: Vec<String>,
    /// The rule that made the decision (`docs/diagnosis.md`, the rule table).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rule: Option<Rule>,
    /// Made while the vehicle was out of its flight envelope (rule X1): the model does not hold
    /// there, and the decision describes the crash rather than an actuator.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub in_crash: bool,
    /// Free text: the evidence, and what the data cannot tell.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
}

impl Decision {
    pub fn monitor(t: f64, sysid: u8, event: Event, detail: impl Into<String>) -> Self {
        Self {
            t,
            sysid,
            event,
            actuator: None,
            channel: None,
            class: None,
            gamma: None,
            delta: None,
            gamma_bounds: None,
            delta_bounds: None,
            deviation: None,
            filters: vec![],
            confidence: 0.0,
            also: vec![],
            rule: None,
            in_crash: false,
            evidence: None,
            detail: Some(detail.into()),
        }
    }
}
