//! The scenario matrix's report: its cases' results summed by vehicle and fault kind
//! (`ahcmon eval --matrix`).

use super::matrix::{CaseResult, ESTIMATE_TOLERANCE, NAME_WITHIN_S};
use serde::Serialize;

/// One row of the report: a vehicle and fault kind (or all), or a vehicle's healthy flights.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ReportRow {
    pub vehicle: String,
    pub kind: String,
    pub cases: usize,
    pub detectable: usize,
    /// Detectable cases whose first decision after the onset names the faulty actuator within
    /// `NAME_WITHIN_S`.
    pub named_right: usize,
    /// Of the detectable cases: those whose actuator the isolation oracle tells from every
    /// other's change, and of them the named right.
    pub isolable: usize,
    pub named_right_isolable: usize,
    pub delay_p50_s: Option<f64>,
    pub delay_p90_s: Option<f64>,
    /// Of the named-right cases: the class right, and gamma and delta both within 0.1.
    pub class_right: usize,
    pub estimate_right: usize,
    /// Of the named-right cases: those whose class the class oracle separates from the other
    /// kinds at the judging time, and of them the class right.
    pub class_separable: usize,
    pub class_right_separable: usize,
    /// Not-detectable cases with a fault decision on another actuator.
    pub undetectable_wrong: usize,
    /// Fault decisions before the onsets of fault flights.
    pub false_before_onset: u32,
    /// Fault decisions in healthy flights, and those flights' estimating hours.
    pub false_healthy: u32,
    pub healthy_h: f64,
    pub cannot_estimate: usize,
    /// Flights with an actuator `cannot_judge` (rule G2).
    pub cannot_judge: usize,
}

fn percentile(v: &mut [f64], p: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let i = ((v.len() - 1) as f64 * p).round() as usize;
    Some(v[i])
}

/// The rows over `results`: per vehicle and kind, per vehicle, per kind and overall.
pub fn report(results: &[CaseResult]) -> Vec<ReportRow> {
    let mut keys: Vec<(String, String)> = vec![];
    let kind_of = |r: &CaseResult| {
        r.case
            .fault
            .as_ref()
            .map_or("healthy".to_string(), |(_, k)| k.as_str().to_string())
    };
    for r in results {
        for k in [
            (r.case.vehicle.to_string(), kind_of(r)),
            (r.case.vehicle.to_string(), "all".into()),
            ("all".into(), kind_of(r)),
            ("all".into(), "all".into()),
        ] {
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
    }
    keys.sort_by_key(|(v, k)| (v == "all", v.clone(), k == "all", k == "healthy", k.clone()));
    keys.iter()
        .map(|(v, k)| {
            let rows: Vec<&CaseResult> = (results.iter())
                .filter(|r| (v == "all" || r.case.vehicle == v) && (k == "all" || kind_of(r) == *k))
                .collect();
            row(v, k, &rows)
        })
        .collect()
}

fn row(vehicle: &str, kind: &str, rows: &[&CaseResult]) -> ReportRow {
    let mut out = ReportRow {
        vehicle: vehicle.into(),
        kind: kind.into(),
        cases: rows.len(),
        ..Default::default()
    };
    let mut delays = vec![];
    for r in rows {
        out.cannot_estimate += usize::from(r.cannot_estimate);
        out.cannot_judge += usize::from(r.cannot_judge);
        if r.case.fault.is_none() {
            out.false_healthy += r.false_before_onset;
            out.healthy_h += r.estimating_h;
            continue;
        }
        out.false_before_onset += r.false_before_onset;
        let target = r.case.fault.as_ref().map(|(a, _)| a.as_str());
        if r.detectable != Some(true) {
            out.undetectable_wrong += usize::from(r.wrong_actuator > 0);
            continue;
        }
        out.detectable += 1;
        let isolable = r.isolable == Some(true);
        out.isolable += usize::from(isolable);
        let right = r
            .first
            .as_ref()
            .is_some_and(|(a, t)| Some(a.as_str()) == target && *t <= NAME_WITHIN_S);
        if !right {
            continue;
        }
        out.named_right += 1;
        out.named_right_isolable += usize::from(isolable);
        delays.extend(r.named_after_s);
        out.class_right += usize::from(r.class_right == Some(true));
        if r.class_separable == Some(true) {
            out.class_separable += 1;
            out.class_right_separable += usize::from(r.class_right == Some(true));
        }
        let within = |e: Option<f64>| e.is_some_and(|e| e.abs() <= ESTIMATE_TOLERANCE);
        out.estimate_right += usize::from(within(r.gamma_error) && within(r.delta_error));
    }
    out.delay_p50_s = percentile(&mut delays, 0.5);
    out.delay_p90_s = percentile(&mut delays, 0.9);
    out
}
