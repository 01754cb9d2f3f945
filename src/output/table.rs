//! The `eval` table for people and its JSON twin for programs.

use crate::eval::Row;
use std::fmt::Write;

fn opt(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) => num(x, prec),
        None => "-".into(),
    }
}

/// A figure in a column: fixed-point, or in exponent form from 1e5 on (a diverged filter's
/// RMSE printed 100 digits and broke the table), "-" when not finite.
fn num(x: f64, prec: usize) -> String {
    if !x.is_finite() {
        "-".into()
    } else if x.abs() >= 1e5 {
        format!("{x:.2e}")
    } else {
        format!("{x:.prec$}")
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
            "{:<24} {:<9} {:>9} {:>9} {:>9} {:>10} {:>10} {:>9} {:>10} {:>9} {:>6} {:>8} {:>4} {:<22}",
            r.scenario,
            r.filter,
            opt(r.detection_delay_s, 2),
            opt(r.settle_s, 2),
            opt(r.gamma_rmse_3s, 3),
            num(r.gamma_rmse_steady, 4),
            num(r.delta_rmse_steady, 5),
            num(r.truth_in_bounds_pct, 2),
            opt(Some(r.truth_in_bounds_after_1s_min_pct), 2),
            opt(r.gamma_off_after_5s_pct, 1),
            r.false_decisions,
            num(r.us_per_step, 2),
            match r.isolated_correct {
                Some(true) => "yes",
                Some(false) => "no",
                None => "-",
            },
            r.class.as_deref().unwrap_or("-"),
        );
    }
    // A filter that refused steps kept its state through them: its figures describe a filter
    // that stood still, not one that tracked (a diverging run read "settled, 100 % in bounds").
    for r in rows.iter().filter(|r| r.step_errors > 0) {
        let _ = writeln!(
            out,
            "warning: {} {}: {} steps failed over {} seed(s) (the filter kept its state or was reset through them): its figures are not to be trusted",
            r.scenario, r.filter, r.step_errors, r.seeds
        );
    }
    out
}

pub fn to_json(rows: &[Row]) -> String {
    // Non-finite numbers become null (serde_json writes NaN as null too; keep it explicit).
    let value = serde_json::to_value(rows).unwrap_or(serde_json::Value::Null);
    serde_json::to_string_pretty(&value).unwrap_or_else(|_| "[]".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_diverged_row_stays_in_its_columns_and_is_flagged() {
        let good = Row {
            scenario: "s".into(),
            filter: "ukf".into(),
            gamma_rmse_steady: 0.01,
            seeds: 1,
            ..Row::default()
        };
        let bad = Row {
            filter: "esmf".into(),
            gamma_rmse_steady: 3.2e104,
            delta_rmse_steady: f64::NAN,
            step_errors: 1491,
            ..good.clone()
        };
        let table = render(&[good, bad]);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 4, "{table}");
        // Every row as wide as the header.
        assert_eq!(lines[1].len(), lines[0].len(), "{table}");
        assert_eq!(lines[2].len(), lines[0].len(), "{table}");
        assert!(lines[2].contains("3.20e104"), "{table}");
        assert!(
            lines[3].starts_with("warning: s esmf: 1491 steps failed"),
            "{table}"
        );
    }
}
