//! ahcmon command line: parses arguments and wires the pipeline; the work is in the library.

use ahcmon::eval::vehicle::{run_vehicle_scenario, sim_config};
use ahcmon::eval::{EvalError, Run, aggregate, run_scenario};
use ahcmon::output::jsonl::RunFiles;
use ahcmon::output::{svg, table};
use ahcmon::scenario::{self, NamedScenario, ScenarioError};
use anyhow::Context;
use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "ahcmon",
    version,
    about = "Actuator health monitor: estimates each actuator's gain (gamma) and bias (delta) with MIT-UKF and MIT-ESMF"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run scenarios through the simulator and all five filters (UKF, KF-UKF, MIT-UKF, ESMF,
    /// MIT-ESMF) and score them against the truth: detection delay, settling time, RMSE,
    /// truth-in-bounds, false decisions, µs per step.
    Eval {
        /// Scenario files or built-in names (default: all built-in scenarios, the paper's figures
        /// and ten minutes of healthy flight).
        scenarios: Vec<String>,
        /// Print a JSON array (one object per scenario × filter) instead of the table.
        #[arg(long)]
        json: bool,
        /// Write one SVG per scenario (truth, estimates, bounds) into this directory.
        #[arg(long, value_name = "DIR")]
        plot: Option<PathBuf>,
        /// Run each scenario with this many seeds (the scenario's seed, +1, +2, ...).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
        seeds: u64,
        /// Write the decisions JSONL of the first seed (one vehicle scenario only).
        #[arg(long, value_name = "FILE")]
        decisions: Option<PathBuf>,
        /// Write the estimates JSONL of the first seed (one vehicle scenario only).
        #[arg(long, value_name = "FILE")]
        estimates: Option<PathBuf>,
        /// Write every k-th step's estimates.
        #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
        decimate: u64,
    },
    /// Fly a vehicle scenario in the simulator (with the monitor's filters and diagnosis
    /// running on it) and write its ground truth, decisions and estimates as JSON lines.
    Sim {
        /// Scenario file or built-in name (a vehicle scenario, e.g. quad-x-motor2-loe).
        #[arg(long)]
        scenario: String,
        /// Truth JSONL: per step, every actuator's true gamma and delta and the noise in force.
        #[arg(long, value_name = "FILE")]
        truth: Option<PathBuf>,
        #[arg(long, value_name = "FILE")]
        decisions: Option<PathBuf>,
        #[arg(long, value_name = "FILE")]
        estimates: Option<PathBuf>,
        /// Seed (default: the scenario's).
        #[arg(long)]
        seed: Option<u64>,
    },
}

/// Errors that are the user's input (exit code 2) rather than ours (exit code 1).
fn is_input_error(e: &anyhow::Error) -> bool {
    e.chain()
        .any(|c| c.is::<ScenarioError>() || c.is::<UsageError>() || c.is::<EvalError>())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let msg = e
                .chain()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(": ");
            eprintln!("ahcmon: error: {}", msg.replace('\n', " "));
            ExitCode::from(if is_input_error(&e) { 2 } else { 1 })
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Eval {
            scenarios,
            json,
            plot,
            seeds,
            decisions,
            estimates,
            decimate,
        } => {
            if decisions.is_some() || estimates.is_some() {
                let [one] = scenarios.as_slice() else {
                    return Err(UsageError(
                        "--decisions / --estimates take exactly one scenario".into(),
                    )
                    .into());
                };
                let named = scenario::resolve(one)?;
                let files = RunFiles::new(decisions.as_deref(), estimates.as_deref(), decimate)
                    .context("cannot create output file")?;
                return run_with_files(&named, named.scenario.seed, files, false);
            }
            eval(scenarios, json, plot, seeds)
        }
        Command::Sim {
            scenario: name,
            truth,
            decisions,
            estimates,
            seed,
        } => {
            let named = scenario::resolve(&name)?;
            let (cfg, _) = sim_config(&named, 0)?;
            let mut files = RunFiles::new(decisions.as_deref(), estimates.as_deref(), 1)
                .context("cannot create output file")?;
            if let Some(path) = &truth {
                files = files
                    .with_truth(path, cfg.gyro_noise, cfg.az_noise)
                    .with_context(|| format!("cannot create {}", path.display()))?;
            }
            run_with_files(&named, seed.unwrap_or(named.scenario.seed), files, true)
        }
    }
}

/// A mistake in how the command line combines things (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct UsageError(String);

/// One vehicle run with its JSONL files; prints what was written and the decisions.
fn run_with_files(
    named: &NamedScenario,
    seed: u64,
    mut files: RunFiles,
    print: bool,
) -> anyhow::Result<()> {
    if named.scenario.is_paper() {
        return Err(UsageError(format!(
            "{} is a paper scenario; decision and truth files come from vehicle scenarios",
            named.name
        ))
        .into());
    }
    let run = run_vehicle_scenario(named, seed, false, &mut files)?;
    if let Some(e) = files.error.take() {
        return Err(anyhow::Error::new(e).context("writing JSON lines"));
    }
    let count =
        |w: &Option<ahcmon::output::jsonl::JsonlWriter<_>>| w.as_ref().map_or(0, |w| w.lines);
    let truth_lines = files.truth.as_ref().map_or(0, |(w, _, _)| w.lines);
    if print {
        println!(
            "{}: {} s of {} (seed {}): {} decision lines, {} estimate lines, {} truth lines",
            named.name,
            named.scenario.duration_s,
            run.vehicle,
            seed,
            count(&files.decisions),
            count(&files.estimates),
            truth_lines
        );
    }
    Ok(())
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
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create plot directory {}", dir.display()))?;
    }
    let progress = std::io::stderr().is_terminal();
    let mut rows = vec![];
    for named in &list {
        let mut runs: Vec<Run> = vec![];
        for i in 0..seeds {
            if progress {
                eprint!("\reval: {} seed {}/{}   ", named.name, i + 1, seeds);
            }
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
    if progress {
        eprint!("\r{:60}\r", "");
    }
    if json {
        println!("{}", table::to_json(&rows));
    } else {
        print!("{}", table::render(&rows));
        if let Some(dir) = &plot {
            println!("plots written to {}", dir.display());
        }
    }
    Ok(())
}
