//! `ahcmon eval` and the JSONL files of one vehicle run (`eval --decisions`, `sim`).

use super::{Progress, UsageError, file_input, in_range};
use crate::cli::EvalArgs;
use ahcmon::eval::vehicle::run_vehicle_scenario;
use ahcmon::eval::{Run, aggregate, run_scenario};
use ahcmon::output::jsonl::Outputs;
use ahcmon::output::{svg, table};
use ahcmon::scenario::{self, NamedScenario};
use anyhow::Context;
use std::path::PathBuf;

pub fn run(a: EvalArgs) -> anyhow::Result<()> {
    if a.output.explain {
        return Err(UsageError(
            "--explain: eval prints no decision lines (its decisions file carries each one's `detail`)".into(),
        )
        .into());
    }
    let EvalArgs {
        scenarios,
        json,
        plot,
        seeds,
        output,
        matrix,
        fast,
        healthy_minutes,
        vehicles,
        first_seed,
    } = a;
    if matrix {
        if output.any() {
            return Err(UsageError(
                "--decisions / --estimates take one scenario; --matrix flies hundreds".into(),
            )
            .into());
        }
        let minutes = in_range("--healthy-minutes", healthy_minutes, 0.5, 600.0)?;
        let spec = ahcmon::eval::matrix::MatrixSpec {
            seeds,
            first_seed,
            healthy_s: minutes * 60.0,
            fast,
            vehicles,
        };
        return super::matrix::run(spec, json);
    }
    if output.any() {
        let [one] = scenarios.as_slice() else {
            return Err(
                UsageError("--decisions / --estimates take exactly one scenario".into()).into(),
            );
        };
        let named = scenario::resolve(one)?;
        let input = file_input(one, scenario::BUILTIN);
        let files = output.create(input.as_slice(), &[])?;
        // The files come from the first seed; the table (all seeds) follows as usual.
        let written = run_with_files(&named, named.scenario.seed, files, false)?;
        rayon::scope(|_| eval(scenarios, json, plot, seeds))?;
        if !json {
            outln!("seed {}{written}", named.scenario.seed);
        }
        return Ok(());
    }
    // On a rayon worker, so each vehicle's two filters step on two cores.
    rayon::scope(|_| eval(scenarios, json, plot, seeds))
}

/// One vehicle run with its JSONL files; with `print`, the decisions as they are made and
/// then what was written.
pub(crate) fn run_with_files(
    named: &NamedScenario,
    seed: u64,
    mut files: Outputs,
    print: bool,
) -> anyhow::Result<String> {
    if named.scenario.is_paper() {
        return Err(UsageError(format!(
            "{} is a paper scenario; decision and truth files come from vehicle scenarios",
            named.name
        ))
        .into());
    }
    files.echo = print;
    let run = run_vehicle_scenario(named, seed, false, None, &mut files)?;
    files.finish();
    if let Some(e) = files.error.take() {
        return Err(anyhow::Error::new(e).context("writing JSON lines"));
    }
    // Only the files asked for are named.
    let mut parts = vec![];
    let lines = |w: &Option<ahcmon::output::jsonl::JsonlWriter<_>>| w.as_ref().map(|w| w.lines);
    if let Some(n) = lines(&files.decisions) {
        parts.push(format!("{n} decision lines"));
    }
    if let Some(n) = lines(&files.estimates) {
        parts.push(format!("{n} estimate lines"));
    }
    if let Some((w, _, _)) = &files.truth {
        parts.push(format!("{} truth lines", w.lines));
    }
    let written = if parts.is_empty() {
        String::new()
    } else {
        format!("; written: {}", parts.join(", "))
    };
    if print {
        outln!(
            "{}: {} s of {} (seed {}), {} decisions{written}",
            named.name,
            named.scenario.duration_s,
            run.vehicle,
            seed,
            files.seen.len(),
        );
    }
    Ok(written)
}

fn eval(names: Vec<String>, json: bool, plot: Option<PathBuf>, seeds: u64) -> anyhow::Result<()> {
    let list: Vec<NamedScenario> = if names.is_empty() {
        scenario::all_builtin()?
    } else {
        names
            .iter()
            .map(|n| scenario::resolve(n))
            .collect::<Result<_, _>>()?
    };
    if let Some(dir) = &plot {
        if dir.exists() && !dir.is_dir() {
            return Err(UsageError(format!(
                "--plot {}: a file, not a directory (one SVG per scenario is written into it)",
                dir.display()
            ))
            .into());
        }
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create plot directory {}", dir.display()))?;
    }
    let progress = Progress::new(true, "eval", list.len() as u64 * seeds);
    let mut rows = vec![];
    for named in &list {
        let mut runs: Vec<Run> = vec![];
        for i in 0..seeds {
            progress.step(&format!("{} seed {}/{}", named.name, i + 1, seeds));
            let keep = plot.is_some() && i == 0;
            runs.push(run_scenario(named, named.scenario.seed + i, keep)?);
        }
        if let (Some(dir), Some(first)) = (&plot, runs.first()) {
            let path = dir.join(format!("{}.svg", named.name));
            std::fs::write(&path, svg::render(first))
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        rows.extend(aggregate(&runs));
    }
    progress.clear();
    if json {
        outln!("{}", table::to_json(&rows));
    } else {
        out!("{}", table::render(&rows));
        if let Some(dir) = &plot {
            outln!("plots written to {}", dir.display());
        }
    }
    Ok(())
}
