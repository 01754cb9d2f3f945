//! The dataset benchmark's scoring: public logs with their truth (`tests/datasets/*.toml`, one
//! file per dataset, naming each log relative to a data root), and each case's fault decisions
//! scored against it. Pure: reading the logs and printing live in `ahcmon benchmark`
//! (`src/app/benchmark.rs`).
//!
//! Per case, from the `fault` decisions only (monitor events are not decisions about an
//! actuator):
//! - the first fault decision at or after the onset: which actuator, the delay, the class, and
//!   whether its channel is one the truth names (unknown when the truth names none);
//! - fault decisions before the onset (a fault known for the whole flight has no "before");
//! - for a healthy flight, every fault decision is a false one; per flight hour over the time
//!   airborne the pipeline saw.
//!
//! Per flight, as the published ALFA figures count (Keipour et al., a detection per flight):
//! a true positive is a fault flight whose first fault decision comes at or after the onset,
//! on a named channel (or any, if none is named), with none before; a fault flight otherwise
//! decided is a false positive and a false negative, one never decided a false negative; a
//! healthy flight with any fault decision a false positive.

use crate::diagnose::vehicle::{Decision, Event};
use serde::{Deserialize, Serialize};

/// One dataset's truth.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetTruth {
    pub dataset: String,
    pub description: String,
    #[serde(default)]
    pub published: Option<Published>,
    /// The calibration stretch's length (s) for this dataset's flights, as `--calibrate-s`
    /// (default 20 s): for flights too short for the default, stated with the reason.
    #[serde(default)]
    pub calibrate_s: Option<f64>,
    #[serde(rename = "case")]
    pub cases: Vec<Case>,
}

/// A figure someone else published on the same data, quoted with its source.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Published {
    pub source: String,
    pub method: String,
    pub precision_pct: Option<f64>,
    pub recall_pct: Option<f64>,
    pub detection_s: Option<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Case {
    /// Relative to the data root.
    pub file: String,
    /// `--profile`, where the log cannot say the frame.
    #[serde(default)]
    pub profile: Option<String>,
    /// None: a healthy flight.
    #[serde(default)]
    pub fault: Option<TruthFault>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthFault {
    pub what: String,
    /// Output channels (1-based) the fault is on; empty when the data do not say which.
    #[serde(default)]
    pub channels: Vec<u8>,
    /// On the log's vehicle clock (s); None: present for the whole flight.
    #[serde(default)]
    pub onset_s: Option<f64>,
}

#[derive(Debug, Clone, thiserror::Error)]
pub enum TruthError {
    #[error("{path}: {message}")]
    Parse { path: String, message: String },
    #[error("{path}: case {file}: {message}")]
    Invalid {
        path: String,
        file: String,
        message: String,
    },
}

impl DatasetTruth {
    pub fn from_toml(text: &str, path: &str) -> Result<Self, TruthError> {
        let truth: Self = toml::from_str(text).map_err(|e| TruthError::Parse {
            path: path.to_string(),
            message: e.to_string(),
        })?;
        if let Some(t) = truth.calibrate_s
            && !(t.is_finite() && (1.0..=3600.0).contains(&t))
        {
            return Err(TruthError::Parse {
                path: path.to_string(),
                message: format!("calibrate_s = {t}: must be between 1 and 3600 s"),
            });
        }
        for c in &truth.cases {
            let invalid = |message: &str| TruthError::Invalid {
                path: path.to_string(),
                file: c.file.clone(),
                message: message.to_string(),
            };
            if c.file.is_empty() || c.file.starts_with('/') || c.file.contains("..") {
                return Err(invalid("file must be a path inside the data root"));
            }
            if let Some(f) = &c.fault {
                if f.onset_s.is_some_and(|t| !(t.is_finite() && t >= 0.0)) {
                    return Err(invalid("onset_s must be a time ≥ 0 s"));
                }
                if f.channels.contains(&0) {
                    return Err(invalid("channels are 1-based"));
                }
            }
        }
        Ok(truth)
    }
}

/// The first fault decision at or after the onset.
#[derive(Debug, Clone, Serialize)]
pub struct FirstFault {
    pub t: f64,
    pub actuator: Option<String>,
    pub channel: Option<u8>,
    pub class: Option<String>,
    /// From the onset; None for a fault present the whole flight.
    pub delay_s: Option<f64>,
    /// The channel is one the truth names; None when it names none.
    pub right: Option<bool>,
}

/// How a flight came out, per the rules in the module docs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Fault flight: decided right, after the onset.
    Detected,
    /// Fault flight: a fault decided before the onset or on a channel the truth does not name.
    Misdecided,
    /// Fault flight: no fault decided.
    Missed,
    /// Healthy flight: no fault decided.
    Clean,
    /// Healthy flight: a fault decided.
    FalseAlarm,
}

/// One case's score.
#[derive(Debug, Clone, Serialize)]
pub struct CaseScore {
    pub file: String,
    pub truth: String,
    pub outcome: Outcome,
    pub first_after_onset: Option<FirstFault>,
    pub faults_before_onset: u32,
    pub faults: u32,
    /// The pipeline's `cannot_estimate` text, when it said one.
    pub cannot_estimate: Option<String>,
    /// Time airborne the pipeline saw (s).
    pub airborne_s: f64,
}

/// Scores one case from every decision of its replay.
pub fn score_case(case: &Case, decisions: &[Decision], airborne_s: f64) -> CaseScore {
    let faults: Vec<&Decision> = decisions
        .iter()
        .filter(|d| d.event == Event::Fault)
        .collect();
    let cannot_estimate = decisions
        .iter()
        .find(|d| d.event == Event::CannotEstimate)
        .map(|d| d.detail.clone().unwrap_or_default());
    let onset = case.fault.as_ref().and_then(|f| f.onset_s);
    let before = faults
        .iter()
        .filter(|d| case.fault.is_some() && onset.is_some_and(|o| d.t < o))
        .count() as u32;
    let first_after_onset = case.fault.as_ref().and_then(|f| {
        faults
            .iter()
            .find(|d| onset.is_none_or(|o| d.t >= o))
            .map(|d| FirstFault {
                t: d.t,
                actuator: d.actuator.clone(),
                channel: d.channel,
                class: d.class.map(|c| {
                    serde_json::to_value(c)
                        .ok()
                        .and_then(|v| v.as_str().map(str::to_string))
                        .unwrap_or_default()
                }),
                delay_s: onset.map(|o| d.t - o),
                right: (!f.channels.is_empty())
                    .then(|| d.channel.is_some_and(|ch| f.channels.contains(&ch))),
            })
    });
    let outcome = match &case.fault {
        None if faults.is_empty() => Outcome::Clean,
        None => Outcome::FalseAlarm,
        Some(_) if faults.is_empty() => Outcome::Missed,
        Some(_) => match &first_after_onset {
            Some(first) if before == 0 && first.right != Some(false) => Outcome::Detected,
            _ => Outcome::Misdecided,
        },
    };
    CaseScore {
        file: case.file.clone(),
        truth: case
            .fault
            .as_ref()
            .map_or_else(|| "healthy".to_string(), |f| f.what.clone()),
        outcome,
        first_after_onset,
        faults_before_onset: before,
        faults: faults.len() as u32,
        cannot_estimate,
        airborne_s,
    }
}

/// A dataset's totals.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Totals {
    pub cases: u32,
    pub fault_flights: u32,
    pub detected: u32,
    pub misdecided: u32,
    pub missed: u32,
    pub healthy_flights: u32,
    pub false_alarm_flights: u32,
    pub cannot_estimate: u32,
    pub faults_before_onset: u32,
    /// Median delay of the detected flights with a known onset (s).
    pub median_delay_s: Option<f64>,
    pub healthy_airborne_h: f64,
    pub healthy_faults: u32,
    /// Fault decisions per flight hour on the healthy flights; None with no time airborne.
    pub healthy_faults_per_h: Option<f64>,
    /// Per flight (module docs); None where nothing was decided or nothing was to find.
    pub precision_pct: Option<f64>,
    pub recall_pct: Option<f64>,
}

pub fn totals(scores: &[CaseScore]) -> Totals {
    let mut t = Totals {
        cases: scores.len() as u32,
        ..Totals::default()
    };
    let mut delays = Vec::new();
    let mut healthy_s = 0.0;
    for s in scores {
        t.cannot_estimate += u32::from(s.cannot_estimate.is_some());
        t.faults_before_onset += s.faults_before_onset;
        match s.outcome {
            Outcome::Detected => {
                t.detected += 1;
                delays.extend(s.first_after_onset.as_ref().and_then(|f| f.delay_s));
            }
            Outcome::Misdecided => t.misdecided += 1,
            Outcome::Missed => t.missed += 1,
            Outcome::Clean => {}
            Outcome::FalseAlarm => t.false_alarm_flights += 1,
        }
        if matches!(s.outcome, Outcome::Clean | Outcome::FalseAlarm) {
            t.healthy_flights += 1;
            t.healthy_faults += s.faults;
            healthy_s += s.airborne_s;
        } else {
            t.fault_flights += 1;
        }
    }
    t.median_delay_s = median(&mut delays);
    t.healthy_airborne_h = healthy_s / 3600.0;
    t.healthy_faults_per_h =
        (healthy_s > 0.0).then(|| f64::from(t.healthy_faults) / t.healthy_airborne_h);
    let tp = f64::from(t.detected);
    let fp = f64::from(t.misdecided + t.false_alarm_flights);
    let fn_ = f64::from(t.misdecided + t.missed);
    t.precision_pct = (tp + fp > 0.0).then(|| 100.0 * tp / (tp + fp));
    t.recall_pct = (tp + fn_ > 0.0).then(|| 100.0 * tp / (tp + fn_));
    t
}

fn median(v: &mut [f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(t: f64, ch: u8) -> Decision {
        Decision {
            actuator: Some(format!("m{ch}")),
            channel: Some(ch),
            ..Decision::monitor(t, 1, Event::Fault, "")
        }
    }

    fn case(fault: Option<TruthFault>) -> Case {
        Case {
            file: "a.tlog".into(),
            profile: None,
            fault,
        }
    }

    fn on(ch: u8, onset: Option<f64>) -> Option<TruthFault> {
        Some(TruthFault {
            what: "motor".into(),
            channels: vec![ch],
            onset_s: onset,
        })
    }

    #[test]
    fn each_outcome_follows_its_rule() {
        let cannot = Decision::monitor(1.0, 1, Event::CannotEstimate, "slow");
        let s = score_case(
            &case(on(2, Some(10.0))),
            &[fault(11.5, 2), fault(12.0, 3)],
            60.0,
        );
        assert_eq!(s.outcome, Outcome::Detected);
        let first = s.first_after_onset.as_ref().map(|f| (f.delay_s, f.right));
        assert_eq!(first, Some((Some(1.5), Some(true))));
        assert_eq!((s.faults, s.faults_before_onset), (2, 0));
        let early = score_case(
            &case(on(2, Some(10.0))),
            &[fault(9.0, 2), fault(11.0, 2)],
            0.0,
        );
        assert_eq!(
            (early.outcome, early.faults_before_onset),
            (Outcome::Misdecided, 1)
        );
        let wrong = score_case(&case(on(2, Some(10.0))), &[fault(11.0, 1)], 0.0);
        assert_eq!(wrong.outcome, Outcome::Misdecided);
        let missed = score_case(&case(on(2, Some(10.0))), std::slice::from_ref(&cannot), 0.0);
        assert_eq!(missed.outcome, Outcome::Missed);
        assert_eq!(missed.cannot_estimate.as_deref(), Some("slow"));
        let whole = score_case(&case(on(2, None)), &[fault(3.0, 2)], 0.0);
        assert_eq!(whole.outcome, Outcome::Detected);
        assert_eq!(whole.first_after_onset.and_then(|f| f.delay_s), None);
        let unknown_channel = Some(TruthFault {
            what: "a propeller".into(),
            channels: vec![],
            onset_s: None,
        });
        assert_eq!(
            score_case(&case(unknown_channel), &[fault(3.0, 4)], 0.0).outcome,
            Outcome::Detected
        );
        assert_eq!(
            score_case(&case(None), &[cannot], 7200.0).outcome,
            Outcome::Clean
        );
        assert_eq!(
            score_case(&case(None), &[fault(3.0, 4)], 0.0).outcome,
            Outcome::FalseAlarm
        );
    }

    #[test]
    fn totals_count_flights_as_the_rules_say() {
        let scores = [
            score_case(&case(on(2, Some(10.0))), &[fault(11.0, 2)], 60.0),
            score_case(&case(on(2, Some(10.0))), &[fault(13.0, 2)], 60.0),
            score_case(&case(on(2, Some(10.0))), &[fault(9.0, 2)], 60.0),
            score_case(&case(on(2, Some(10.0))), &[], 60.0),
            score_case(&case(None), &[fault(5.0, 1), fault(6.0, 1)], 1800.0),
            score_case(&case(None), &[], 1800.0),
        ];
        let t = totals(&scores);
        assert_eq!((t.detected, t.misdecided, t.missed), (2, 1, 1));
        assert_eq!(
            (t.healthy_flights, t.false_alarm_flights, t.healthy_faults),
            (2, 1, 2)
        );
        assert_eq!(t.median_delay_s, Some(2.0));
        assert_eq!(t.healthy_faults_per_h, Some(2.0));
        // TP 2, FP 1 (misdecided) + 1 (false alarm), FN 1 (misdecided) + 1 (missed)
        assert_eq!(t.precision_pct, Some(50.0));
        assert_eq!(t.recall_pct, Some(50.0));
    }

    #[test]
    fn truth_files_are_checked() {
        let ok = "dataset = \"d\"\ndescription = \"x\"\n[[case]]\nfile = \"a/b.tlog\"\n";
        assert!(DatasetTruth::from_toml(ok, "t.toml").is_ok());
        let unknown = format!("{ok}colour = 1\n");
        assert!(DatasetTruth::from_toml(&unknown, "t.toml").is_err());
        let outside = ok.replace("a/b.tlog", "../b.tlog");
        assert!(DatasetTruth::from_toml(&outside, "t.toml").is_err());
        let negative = format!("{ok}fault = {{ what = \"m\", onset_s = -1.0 }}\n");
        assert!(DatasetTruth::from_toml(&negative, "t.toml").is_err());
    }
}
