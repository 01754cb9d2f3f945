//! `ahcmon history`: `scan`'s rows grouped per airframe (else board id, else system id) ×
//! actuator, flights in start-time order, each series fitted and judged by the rule in
//! `ahcmon::history` (`series`); the table, `--json` and `--plot`.

use super::{InputFileError, UsageError, check_outputs, in_range};
use crate::cli::HistoryArgs;
use ahcmon::history::{HistoryRule, series};
use anyhow::Context;
use serde_json::{Value, json};

pub fn run(a: HistoryArgs) -> anyhow::Result<()> {
    let HistoryArgs {
        rows,
        loss_gamma,
        horizon,
        window,
        false_alarm,
        json: json_out,
        plot,
    } = a;
    check_outputs(
        &[rows.as_path()],
        &[("--json", json_out.as_deref()), ("--plot", plot.as_deref())],
    )?;
    let rule = HistoryRule {
        loss_gamma: in_range("--loss-gamma", loss_gamma, 0.0, 2.0)?,
        horizon: in_range("--horizon", horizon, 0.0, 1e6)?,
        window: usize::from(window),
        false_alarm: in_range("--false-alarm", false_alarm, 1e-9, 0.5)?,
    };
    let text = std::fs::read_to_string(&rows).map_err(|source| InputFileError {
        path: rows.display().to_string(),
        source,
    })?;
    let mut parsed = Vec::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        parsed.push(serde_json::from_str::<Value>(line).map_err(|e| {
            UsageError(format!(
                "{}:{}: not a JSON row ({e})",
                rows.display(),
                n + 1
            ))
        })?);
    }
    let series = series(&parsed, &rule);
    if series.is_empty() {
        return Err(UsageError(format!(
            "{}: no row with an actuator's MIT-UKF gamma (ahcmon scan's rows?)",
            rows.display()
        ))
        .into());
    }
    outln!(
        "{:<12} {:<9} {:>7} {:>7} {:>16} {:>9}  alarm (rule: slope below Student's t at p {} and gamma {} within {} flights, over the last {})",
        "airframe",
        "actuator",
        "flights",
        "gamma",
        "slope/flight",
        "reaches",
        rule.false_alarm,
        rule.loss_gamma,
        rule.horizon,
        rule.window
    );
    let mut doc = Vec::new();
    let mut alarms = 0;
    for s in &series {
        let (airframe, actuator, flights) = (&s.airframe, &s.actuator, &s.flights);
        if s.mixed_start_times {
            tracing::warn!(
                "history: {airframe} {actuator}: some flights have no start time (a DataFlash or ULog log): they are put after those that have, by file name"
            );
        }
        let last = flights.len() - 1;
        let trend = s.trend;
        alarms += usize::from(s.alarm.is_some());
        outln!(
            "{airframe:<12} {actuator:<9} {:>7} {:>7.3} {:>16} {:>9}  {}",
            flights.len(),
            flights[last].point.gamma,
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
            s.alarm.map_or(String::new(), |k| format!(
                "ALARM from flight {} ({})",
                k + 1,
                flights[k].file
            )),
        );
        doc.push(s.json());
    }
    outln!("{alarms} alarms");
    if let Some(p) = plot {
        let svg = ahcmon::output::history_plot::render(
            &series,
            &rule,
            &format!("ahcmon history {}", rows.display()),
        );
        let bytes = if ahcmon::output::png::is_png(&p) {
            ahcmon::output::png::from_svg(&svg)
                .with_context(|| format!("cannot draw {}", p.display()))?
        } else {
            svg.into_bytes()
        };
        ahcmon::output::file::write_whole(&p, &bytes)
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    if let Some(p) = json_out {
        let text = serde_json::to_string_pretty(&json!({ "series": doc }))? + "\n";
        ahcmon::output::file::write_whole(&p, text.as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))?;
    }
    Ok(())
}
