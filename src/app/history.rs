//! `ahcmon history`: `scan`'s rows grouped per airframe (its system id where no airframe is
//! named) × actuator, flights in start-time order, each series fitted and judged by the rule
//! in `ahcmon::history`.

use super::{InputFileError, UsageError, check_outputs, in_range};
use crate::cli::HistoryArgs;
use ahcmon::history::{HistoryRule, Point, first_alarm, fit};
use anyhow::Context;
use serde_json::{Value, json};
use std::collections::BTreeMap;

/// Flights by start time, those without one after them, then by file name.
fn order(flights: &mut [Flight]) {
    flights.sort_by(|a, b| {
        (a.start.is_none(), a.start, &a.file).cmp(&(b.start.is_none(), b.start, &b.file))
    });
}

/// One flight of a series, in the order it is sorted by.
struct Flight {
    start: Option<u64>,
    file: String,
    point: Point,
}

pub fn run(a: HistoryArgs) -> anyhow::Result<()> {
    let HistoryArgs {
        rows,
        loss_gamma,
        horizon,
        window,
        t_alarm,
        json: json_out,
    } = a;
    check_outputs(&[rows.as_path()], &[("--json", json_out.as_deref())])?;
    let rule = HistoryRule {
        loss_gamma: in_range("--loss-gamma", loss_gamma, 0.0, 2.0)?,
        horizon: in_range("--horizon", horizon, 0.0, 1e6)?,
        window: usize::from(window),
        t_alarm: in_range("--t-alarm", t_alarm, 0.0, 100.0)?,
    };
    let text = std::fs::read_to_string(&rows).map_err(|source| InputFileError {
        path: rows.display().to_string(),
        source,
    })?;
    let mut series: BTreeMap<(String, String), Vec<Flight>> = BTreeMap::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let row: Value = serde_json::from_str(line).map_err(|e| {
            UsageError(format!(
                "{}:{}: not a JSON row ({e})",
                rows.display(),
                n + 1
            ))
        })?;
        let (Some(actuator), Some(gamma)) =
            (row["actuator"].as_str(), row["mit_ukf"]["gamma"].as_f64())
        else {
            continue;
        };
        let airframe = row["airframe"]
            .as_str()
            .or(row["board_uid"].as_str())
            .map(str::to_string)
            .unwrap_or_else(|| format!("sysid {}", row["sysid"]));
        series
            .entry((airframe, actuator.to_string()))
            .or_default()
            .push(Flight {
                start: row["start_unix_us"].as_u64(),
                file: row["file"].as_str().unwrap_or_default().to_string(),
                point: Point {
                    gamma,
                    lo: row["mit_ukf"]["gamma_lo"].as_f64().unwrap_or(f64::NAN),
                    hi: row["mit_ukf"]["gamma_hi"].as_f64().unwrap_or(f64::NAN),
                },
            });
    }
    if series.is_empty() {
        return Err(UsageError(format!(
            "{}: no row with an actuator's MIT-UKF gamma (ahcmon scan's rows?)",
            rows.display()
        ))
        .into());
    }
    outln!(
        "{:<12} {:<9} {:>7} {:>7} {:>16} {:>9}  alarm (rule: slope < -{} se and gamma {} within {} flights, over the last {})",
        "airframe",
        "actuator",
        "flights",
        "gamma",
        "slope/flight",
        "reaches",
        rule.t_alarm,
        rule.loss_gamma,
        rule.horizon,
        rule.window
    );
    let mut doc = Vec::new();
    let mut alarms = 0;
    for ((airframe, actuator), mut flights) in series {
        order(&mut flights);
        if flights.iter().any(|f| f.start.is_none()) && flights.iter().any(|f| f.start.is_some()) {
            tracing::warn!(
                "history: {airframe} {actuator}: some flights have no start time (a DataFlash or ULog log): they are put after those that have, by file name"
            );
        }
        let points: Vec<Point> = flights.iter().map(|f| f.point).collect();
        let last = points.len() - 1;
        let trend = fit(
            &points,
            (last + 1).saturating_sub(rule.window),
            last,
            rule.loss_gamma,
        );
        let alarm = first_alarm(&points, &rule);
        alarms += usize::from(alarm.is_some());
        outln!(
            "{airframe:<12} {actuator:<9} {:>7} {:>7.3} {:>16} {:>9}  {}",
            points.len(),
            points[last].gamma,
            trend.map_or("-".into(), |t| format!(
                "{:+.4} ± {:.4}",
                t.slope, t.slope_se
            )),
            trend
                .and_then(|t| t.crossing)
                .filter(|c| c.is_finite())
                .map_or("-".into(), |c| format!(
                    "flight {:.0}",
                    (c + 1.0).ceil().max(1.0)
                )),
            alarm.map_or(String::new(), |(k, _)| format!(
                "ALARM from flight {} ({})",
                k + 1,
                flights[k].file
            )),
        );
        doc.push(json!({
            "airframe": airframe,
            "actuator": actuator,
            "flights": flights.iter().map(|f| json!({
                "file": f.file, "start_unix_us": f.start,
                "gamma": f.point.gamma, "gamma_lo": f.point.lo, "gamma_hi": f.point.hi,
            })).collect::<Vec<_>>(),
            "trend": trend.map(|t| json!({
                "slope": t.slope, "slope_se": t.slope_se, "intercept": t.intercept,
                "reaches_loss_at_flight": t.crossing.filter(|c| c.is_finite()).map(|c| c + 1.0),
            })),
            "alarm_from_flight": alarm.map(|(k, _)| k + 1),
        }));
    }
    outln!("{alarms} alarms");
    if let Some(p) = json_out {
        let text = serde_json::to_string_pretty(&json!({ "series": doc }))? + "\n";
        ahcmon::output::file::write_whole(&p, text.as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flights_go_by_start_time_then_those_without_by_name() {
        let f = |start: Option<u64>, file: &str| Flight {
            start,
            file: file.into(),
            point: Point {
                gamma: 1.0,
                lo: 0.9,
                hi: 1.1,
            },
        };
        let mut flights = vec![
            f(None, "a.bin"),
            f(Some(30), "b.tlog"),
            f(Some(10), "z.tlog"),
            f(None, "0.ulg"),
        ];
        order(&mut flights);
        let names: Vec<&str> = flights.iter().map(|f| f.file.as_str()).collect();
        assert_eq!(names, ["z.tlog", "b.tlog", "0.ulg", "a.bin"]);
    }
}
