//! The `eval` table for people and its JSON twin for programs.

use crate::eval::Row;
use std::fmt::Write;

fn opt(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => "-".into(),
    }
}

pub fn render(rows: &[Row]) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<24} {:<9} {:>9} {:>9} {:>9} {:>10} {:>10} {:>9} {:>10} {:>9} {:>6} {:>8} {:>4} {:<22}",
        "scenario",
        "filter",
        "detect_s",
        "settle_s",
        "g_rmse3s",
        "g_rmse_ss",
        "d_rmse_ss",
        "in_bnd%",
        "in_bnd>1s%",
        "g_off>5s%",
        "false",
        "us/step",
        "iso",
        "class"
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{:<24} {:<9} {:>9} {:>9} {:>9} {:>10.4} {:>10.5} {:>9.2} {:>10} {:>9} {:>6} {:>8.2} {:>4} {:<22}",
            r.scenario,
            r.filter,
            opt(r.detection_delay_s, 2),
            opt(r.settle_s, 2),
            opt(r.gamma_rmse_3s, 3),
            r.gamma_rmse_steady,
            r.delta_rmse_steady,
            r.truth_in_bounds_pct,
            opt(Some(r.truth_in_bounds_after_1s_min_pct), 2),
            opt(r.gamma_off_after_5s_pct, 1),
            r.false_decisions,
            r.us_per_step,
            match r.isolated_correct {
                Some(true) => "yes",
                Some(false) => "no",
                None => "-",
            },
            r.class.as_deref().unwrap_or("-"),
        );
    }
    out
}

pub fn to_json(rows: &[Row]) -> String {
    // Non-finite numbers become null (serde_json writes NaN as null too; keep it explicit).
    let value = serde_json::to_value(rows).unwrap_or(serde_json::Value::Null);
    serde_json::to_string_pretty(&value).unwrap_or_else(|_| "[]".into())
}
