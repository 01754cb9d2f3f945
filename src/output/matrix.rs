//! The scenario matrix's report as a table (`ahcmon eval --matrix`).

use crate::eval::matrix::ReportRow;
use std::fmt::Write;

fn pct(k: usize, n: usize) -> String {
    if n == 0 {
        "-".into()
    } else {
        format!("{:.0}", 100.0 * k as f64 / n as f64)
    }
}

fn secs(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.2}"))
}

/// One line per row: detection among the oracle-detectable cases (named right within 5 s; `iso%`
/// among those the isolation oracle can also name), its delays, class and estimates of those named right (`sep%`: the class right among those
/// whose class the class oracle separates from the other kinds), wrong-actuator decisions on cases the
/// oracle cannot detect, false decisions before the onsets and in healthy flights (and per
/// healthy hour), and the flights the data could not support: `c_est` with a `cannot_estimate`,
/// `c_judge` with an actuator `cannot_judge` (rule G2).
pub fn render(rows: &[ReportRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<12} {:<16} {:>5} {:>5} {:>7} {:>5} {:>6} {:>6} {:>7} {:>6} {:>6} {:>7} {:>6} {:>7} {:>7} {:>5} {:>7}",
        "vehicle",
        "fault",
        "cases",
        "detec",
        "named%",
        "iso%",
        "p50_s",
        "p90_s",
        "class%",
        "sep%",
        "est%",
        "undet_w",
        "pre_on",
        "healthy",
        "false/h",
        "c_est",
        "c_judge"
    );
    for r in rows {
        let per_h = if r.healthy_h > 0.0 {
            format!("{:.1}", f64::from(r.false_healthy) / r.healthy_h)
        } else {
            "-".into()
        };
        let _ = writeln!(
            s,
            "{:<12} {:<16} {:>5} {:>5} {:>7} {:>5} {:>6} {:>6} {:>7} {:>6} {:>6} {:>7} {:>6} {:>7} {:>7} {:>5} {:>7}",
            r.vehicle,
            r.kind,
            r.cases,
            r.detectable,
            pct(r.named_right, r.detectable),
            pct(r.named_right_isolable, r.isolable),
            secs(r.delay_p50_s),
            secs(r.delay_p90_s),
            pct(r.class_right, r.named_right),
            pct(r.class_right_separable, r.class_separable),
            pct(r.estimate_right, r.named_right),
            r.undetectable_wrong,
            r.false_before_onset,
            r.false_healthy,
            per_h,
            r.cannot_estimate,
            r.cannot_judge
        );
    }
    s
}
