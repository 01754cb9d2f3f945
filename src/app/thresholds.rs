//! `ahcmon thresholds`: each vehicle's decision threshold calibrated on healthy Monte-Carlo
//! flights.

use crate::cli::ThresholdsArgs;
use ahcmon::scenario::{self, NamedScenario};

pub fn run(a: ThresholdsArgs) -> anyhow::Result<()> {
    let ThresholdsArgs {
        scenarios,
        seeds,
        json,
    } = a;
    rayon::scope(|_| thresholds(scenarios, seeds, json))
}

fn thresholds(names: Vec<String>, seeds: u64, json: bool) -> anyhow::Result<()> {
    use ahcmon::eval::thresholds::{CALIBRATION_FIRST_SEED, calibrate_threshold};
    let list: Vec<NamedScenario> = if names.is_empty() {
        scenario::all_builtin()?
            .into_iter()
            .filter(|n| n.name.ends_with("-healthy-gusts"))
            .collect()
    } else {
        names
            .iter()
            .map(|n| scenario::resolve(n))
            .collect::<Result<_, _>>()?
    };
    let seed_list: Vec<u64> = (0..seeds).map(|i| CALIBRATION_FIRST_SEED + i).collect();
    let progress = super::Progress::new(true, "thresholds", list.len() as u64);
    let mut out = vec![];
    for named in &list {
        progress.step(&format!("{} ({} flights)", named.name, seeds));
        out.push(calibrate_threshold(named, &seed_list)?);
    }
    progress.clear();
    if json {
        outln!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    outln!(
        "{:<24} {:<12} {:>7} {:<9} {:>14} {:>14} {:>10} {:>10} {:>11} {:>9}",
        "scenario",
        "vehicle",
        "flights",
        "statistic",
        "alarm-free ukf",
        "alarm-free set",
        "max ukf",
        "max set",
        "recommended",
        "profile"
    );
    for c in &out {
        let profile = ahcmon::telemetry::Profile::resolve(&c.vehicle).ok();
        let rows = [
            (
                "deviation",
                c.alarm_free,
                c.max_abs_deviation,
                c.recommended,
                profile.as_ref().map(|p| p.diagnosis.threshold),
            ),
            (
                "gain",
                c.gain_alarm_free,
                c.max_abs_gain_gap,
                c.gain_recommended,
                profile.as_ref().and_then(|p| p.diagnosis.gain_threshold),
            ),
        ];
        for (stat, free, max, rec, current) in rows {
            // A statistic that stayed 0 (for one filter, or both: no angle outputs, for the
            // gain) has nothing to calibrate: the bisection's floor would read as a threshold.
            let num = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.4}"));
            outln!(
                "{:<24} {:<12} {:>7} {:<9} {:>14} {:>14} {:>10.4} {:>10.4} {:>11} {:>9}",
                c.scenario,
                c.vehicle,
                c.seeds.len(),
                stat,
                num(free[0]),
                num(free[1]),
                max[0],
                max[1],
                rec.map_or("-".into(), |r| format!("{r:.3}")),
                current.map_or("-".into(), |t| format!("{t:.3}"))
            );
        }
        // The reference of rule T1: the gusts these flights' calibrations measured, the axes' means
        // at the strongest flight's level.
        let axes: Vec<String> = c
            .gusts
            .iter()
            .map(|g| g.map_or("-".into(), |g| format!("{g:.3}")))
            .collect();
        let current = profile
            .as_ref()
            .and_then(|p| p.diagnosis.gusts)
            .map_or("-".into(), |g| {
                format!("[{:.3}, {:.3}, {:.3}]", g[0], g[1], g[2])
            });
        outln!(
            "{:<24} {:<12} gusts (rule T1; rad/s², roll pitch yaw): [{}], profile {current}",
            c.scenario,
            c.vehicle,
            axes.join(", ")
        );
    }
    Ok(())
}
