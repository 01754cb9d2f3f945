//! ahcmon command line: parses arguments and wires the pipeline; the work is in the library.

use ahcmon::eval::vehicle::{run_vehicle_scenario, sim_config};
use ahcmon::eval::{EvalError, Run, aggregate, run_scenario};
use ahcmon::link::TlogReader;
use ahcmon::monitor::Monitor;
use ahcmon::output::jsonl::{MonitorFiles, RunFiles};
use ahcmon::output::{summary, svg, table};
use ahcmon::pipeline::PipelineConfig;
use ahcmon::telemetry::{Profile, ProfileError};
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
    /// Replay a telemetry log (.tlog from any ground station) through both filters and the
    /// diagnosis: decisions as they happen, a summary at the end (final estimates with bounds,
    /// decisions, and counts of everything dropped).
    Replay {
        /// The .tlog file.
        file: PathBuf,
        #[command(flatten)]
        run: RunArgs,
        /// Replay at this multiple of real time instead of as fast as possible.
        #[arg(long, value_name = "X", conflicts_with = "fast")]
        speed: Option<f64>,
        /// As fast as the CPU goes (the default).
        #[arg(long)]
        fast: bool,
        /// No dashboard (the dashboard is not built yet: replay is always headless for now).
        #[arg(long)]
        headless: bool,
    },
}

/// Options shared by `replay` and `monitor`.
#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Vehicle profile, built-in name (paper-heli, heli-h3-120, quad-plus, quad-x, hexa-x,
    /// plane) or TOML file. Default: chosen from the vehicle's HEARTBEAT and parameters.
    #[arg(long, value_name = "NAME|FILE")]
    profile: Option<String>,
    /// Decisions JSONL (one object a line).
    #[arg(long, value_name = "FILE")]
    decisions: Option<PathBuf>,
    /// Estimates JSONL (both filters, every actuator, every step).
    #[arg(long, value_name = "FILE")]
    estimates: Option<PathBuf>,
    /// Write every k-th step's estimates.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    decimate: u64,
    /// End the healthy calibration stretch at this vehicle time (s since boot, as in the
    /// decisions' `t`); default: the first 20 s after take-off.
    #[arg(long, value_name = "T")]
    calibrate_until: Option<f64>,
}

impl RunArgs {
    fn pipeline_config(&self) -> anyhow::Result<PipelineConfig> {
        let profile = self
            .profile
            .as_deref()
            .map(Profile::resolve)
            .transpose()?;
        if let Some(t) = self.calibrate_until
            && !(t.is_finite() && t > 0.0)
        {
            return Err(UsageError(format!("--calibrate-until {t}: must be a positive time in s")).into());
        }
        Ok(PipelineConfig {
            profile,
            calibrate_until: self.calibrate_until,
            ..PipelineConfig::default()
        })
    }

    fn files(&self) -> anyhow::Result<MonitorFiles> {
        MonitorFiles::new(self.decisions.as_deref(), self.estimates.as_deref(), self.decimate)
            .context("cannot create output file")
    }
}

/// Errors that are the user's input (exit code 2) rather than ours (exit code 1).
fn is_input_error(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<ScenarioError>()
            || c.is::<UsageError>()
            || c.is::<EvalError>()
            || c.is::<ProfileError>()
            || c.is::<InputFileError>()
    })
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
        Command::Replay {
            file,
            run,
            speed,
            fast: _,
            headless: _,
        } => replay(&file, &run, speed),
    }
}

/// An input file that cannot be read (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
struct InputFileError {
    path: String,
    source: std::io::Error,
}

fn replay(file: &std::path::Path, args: &RunArgs, speed: Option<f64>) -> anyhow::Result<()> {
    if let Some(x) = speed
        && !(x.is_finite() && x > 0.0)
    {
        return Err(UsageError(format!("--speed {x}: must be a positive multiple of real time")).into());
    }
    let input_error = |source| InputFileError {
        path: file.display().to_string(),
        source,
    };
    let size = std::fs::metadata(file).map_err(input_error)?.len();
    let mut reader = TlogReader::open(file).map_err(input_error)?;
    let mut monitor = Monitor::new(args.pipeline_config()?);
    let mut files = args.files()?;
    let progress = std::io::stderr().is_terminal();
    let started = std::time::Instant::now();
    let mut first_ts = None;
    let mut shown = 0;
    while let Some((ts, frame)) = reader.next_frame().map_err(input_error)? {
        if let Some(x) = speed {
            let t0 = *first_ts.get_or_insert(ts);
            let due = std::time::Duration::from_secs_f64(ts.saturating_sub(t0) as f64 * 1e-6 / x);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        monitor.on_frame(&frame, &mut files);
        if progress && size > 0 {
            let pct = (reader.position() * 100 / size) as usize;
            if pct != shown {
                shown = pct;
                eprint!("\rreplay: {pct:3}% [{:<40}]", "#".repeat(pct * 40 / 100));
            }
        }
    }
    monitor.finish(&mut files);
    if progress {
        eprint!("\r{:60}\r", "");
    }
    if let Some(e) = files.error.take() {
        return Err(anyhow::Error::new(e).context("writing JSON lines"));
    }
    print!("{}", summary::render(&monitor, &reader.counters, &files.seen));
    println!("replayed {} in {:.2} s", file.display(), started.elapsed().as_secs_f64());
    Ok(())
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
