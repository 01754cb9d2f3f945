//! ahcmon command line: parses arguments and wires the pipeline; the work is in the library.

use ahcmon::eval::{Run, aggregate, run_scenario};
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
    },
}

/// Errors that are the user's input (exit code 2) rather than ours (exit code 1).
fn is_input_error(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<ScenarioError>())
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
        } => eval(scenarios, json, plot, seeds),
    }
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
