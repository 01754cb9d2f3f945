//! ahcmon command line: parses arguments and wires the pipeline; the work is in the library.

use ahcmon::eval::vehicle::{run_vehicle_scenario, sim_config};
use ahcmon::eval::{EvalError, Run, aggregate, run_scenario};
use ahcmon::link::{ConnError, ConnSpec, Link, TlogReader, TlogWriter};
use ahcmon::monitor::Monitor;
use ahcmon::output::jsonl::{MonitorFiles, RunFiles};
use ahcmon::output::{summary, svg, table};
use ahcmon::pipeline::PipelineConfig;
use ahcmon::scenario::{self, NamedScenario, ScenarioError};
use ahcmon::telemetry::{Profile, ProfileError};
use anyhow::Context;
use clap::{Parser, Subcommand};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// `print!` that ends the program quietly when stdout is closed (`ahcmon eval | head`)
/// instead of panicking; other write errors are reported on stderr once and output stops.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = write!(std::io::stdout(), $($arg)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            eprintln!("ahcmon: cannot write to stdout: {e}");
            std::process::exit(1);
        }
    }};
}

/// `println!` with the same handling as `out!`.
macro_rules! outln {
    ($($arg:tt)*) => {
        out!("{}\n", format_args!($($arg)*))
    };
}

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
    /// Calibrate each vehicle's decision threshold on healthy Monte-Carlo flights: the smallest
    /// threshold at which no healthy flight would raise a fault, times a margin. Flown with
    /// seeds from 1001 on, which the tests and `eval` do not use.
    ///
    /// Two rows per scenario, one per statistic: `deviation` (the effective output's deviation
    /// attributed to an actuator) and `gain` (angle outputs' gain statistic). Columns:
    /// `alarm-free ukf` / `alarm-free set`, the smallest threshold at which the MIT-UKF's / the
    /// MIT-ESMF's statistic raised no alarm on any flight; `max ukf` / `max set`, the largest
    /// value of that statistic seen after the warm-up; `recommended`, 1.25 × the larger
    /// alarm-free threshold; `profile`, the built-in profile's threshold now ("-": none).
    Thresholds {
        /// Healthy vehicle scenarios (default: the built-in *-healthy-gusts flights).
        scenarios: Vec<String>,
        /// Flights per scenario.
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=1000))]
        seeds: u64,
        /// Print JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Fly a vehicle scenario in the simulator (with the monitor's filters and diagnosis
    /// running on it), print its decisions as they are made, and write its ground truth,
    /// decisions and estimates as JSON lines.
    Sim {
        /// Scenario file or built-in name (a vehicle scenario, e.g. quad-x-motor2-loe).
        #[arg(long)]
        scenario: String,
        /// Truth JSONL: per step, every actuator's true gamma and delta and the noise in force.
        #[arg(long, value_name = "FILE")]
        truth: Option<PathBuf>,
        /// Decisions JSONL of the monitor running on the flight (one object a line).
        #[arg(long, value_name = "FILE")]
        decisions: Option<PathBuf>,
        /// Estimates JSONL (both filters, every actuator, every step).
        #[arg(long, value_name = "FILE")]
        estimates: Option<PathBuf>,
        /// Seed (default: the scenario's).
        #[arg(long)]
        seed: Option<u64>,
        /// Speak MAVLink like an autopilot on this connection (e.g. udpout:127.0.0.1:14550):
        /// HEARTBEAT, ATTITUDE, SERVO_OUTPUT_RAW, RAW_IMU, SYS_STATUS, GLOBAL_POSITION_INT and
        /// the frame parameters. Paced at --speed (default real time).
        #[arg(long, value_name = "CONN")]
        out: Option<String>,
        /// Write the same MAVLink stream as a .tlog.
        #[arg(long, value_name = "FILE")]
        tlog: Option<PathBuf>,
        /// Multiple of real time for --out (default 1); without --out the tlog is written as
        /// fast as possible.
        #[arg(long, value_name = "X", allow_negative_numbers = true)]
        speed: Option<f64>,
        /// MAVLink system id of the simulated vehicle.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=254))]
        sysid: u8,
        /// Which autopilot the stream sounds like: ardupilot (SERVO_OUTPUT_RAW, RAW_IMU and the
        /// frame parameters) or px4 (ACTUATOR_OUTPUT_STATUS and HIGHRES_IMU, no ArduPilot
        /// parameters).
        #[arg(long, value_enum, default_value_t = AutopilotArg::Ardupilot)]
        autopilot: AutopilotArg,
    },
    /// Watch live vehicles on a MAVLink connection (e.g. udpin:0.0.0.0:14550 beside a ground
    /// station): both filters and the diagnosis per vehicle, decisions as they happen, a summary
    /// on exit (ctrl-c).
    Monitor {
        /// udpin:HOST:PORT, tcpin:HOST:PORT, tcpout:HOST:PORT or serial:DEVICE:BAUD (udp: and
        /// tcp: are udpin: and tcpout:, as in MAVProxy). Not udpout or udpbcast: the monitor
        /// sends nothing to the vehicle, so a UDP peer would never learn where to send.
        conn: String,
        #[command(flatten)]
        run: RunArgs,
        /// No dashboard: decisions are printed as they happen (automatic when stdout is not a
        /// terminal).
        #[arg(long)]
        headless: bool,
        /// A vehicle silent this long (s) gets a link_lost decision.
        #[arg(
            long,
            default_value_t = 2.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        link_timeout: f64,
        /// Exit after this long (s) without any frame, once frames have arrived (e.g. at the
        /// end of a simulated flight).
        #[arg(long, value_name = "S", allow_negative_numbers = true)]
        exit_idle: Option<f64>,
        /// Send alerts to a mission planner on this connection (usually
        /// udpout:127.0.0.1:14551 into a MAVProxy master): HEARTBEAT, STATUSTEXT per decision,
        /// NAMED_VALUE_FLOAT g_/d_<actuator> at 2 Hz and AHC_ESTIMATE.
        #[arg(long, value_name = "CONN")]
        alerts: Option<String>,
        /// Ask each vehicle for ATTITUDE, SERVO_OUTPUT_RAW and RAW_IMU at this rate
        /// (SET_MESSAGE_INTERVAL; reports COMMAND_ACK and the rates achieved). Off by
        /// default: without it nothing is ever sent to the vehicle.
        #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
        request_rates: Option<f64>,
    },
    /// The built-in demonstration: a simulated H3-120 helicopter flies in this process over
    /// loopback UDP to the monitor; 32 s into the flight swash servo 2 loses 40 % effectiveness,
    /// at 45 s the tail servo gets a bias; headless it ends by itself after 58 s (the dashboard
    /// stays until q). The monitor shows the autopilot's clock, which reads 10 s when the
    /// flight starts: the faults come at t=42 s and t=55 s.
    Demo {
        /// Print the decisions instead of showing the dashboard (automatic when stdout is not a
        /// terminal).
        #[arg(long)]
        headless: bool,
        /// Another vehicle scenario instead of the built-in one (heli-demo).
        #[arg(long, value_name = "FILE|NAME")]
        scenario: Option<String>,
        /// Decisions JSONL (one object a line).
        #[arg(long, value_name = "FILE")]
        decisions: Option<PathBuf>,
        /// Estimates JSONL (both filters, every actuator, every step).
        #[arg(long, value_name = "FILE")]
        estimates: Option<PathBuf>,
        /// Also send the alerts to a planner (see `monitor --alerts`).
        #[arg(long, value_name = "CONN")]
        alerts: Option<String>,
        /// Multiple of real time (e.g. 4 for a quick look).
        #[arg(
            long,
            default_value_t = 1.0,
            value_name = "X",
            allow_negative_numbers = true
        )]
        speed: f64,
    },
    /// Identify a vehicle's model (D, G, c and the noise levels) from a healthy stretch of a
    /// telemetry log and write it as a profile (usable with --profile FILE).
    Calibrate {
        /// The .tlog file.
        file: PathBuf,
        /// End of the healthy stretch (vehicle time, s since boot, as in the decisions' `t`);
        /// it starts when the vehicle is airborne and settled.
        #[arg(long, value_name = "T", allow_negative_numbers = true)]
        until: f64,
        /// The profile file to write.
        #[arg(short = 'o', long = "output", value_name = "PROFILE.toml")]
        output: PathBuf,
        /// Start from this profile's geometry instead of the detected one.
        #[arg(long, value_name = "NAME|FILE")]
        profile: Option<String>,
        /// Calibrate this vehicle (MAVLink system id) of a log that holds several (default:
        /// the first whose stretch completes; the others are named).
        #[arg(long, value_name = "ID")]
        sysid: Option<u8>,
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
        #[arg(
            long,
            value_name = "X",
            conflicts_with = "fast",
            allow_negative_numbers = true
        )]
        speed: Option<f64>,
        /// As fast as the CPU goes (the default).
        #[arg(long)]
        fast: bool,
        /// No dashboard (automatic when stdout is not a terminal).
        #[arg(long)]
        headless: bool,
        /// Draw every actuator's gamma and delta with both filters' bounds and the decisions
        /// into this SVG file.
        #[arg(long, value_name = "FILE.svg")]
        plot: Option<PathBuf>,
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
    /// decisions' `t`); default: 20 s from when the vehicle is airborne and settled (3 s
    /// after take-off).
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    calibrate_until: Option<f64>,
}

impl RunArgs {
    fn pipeline_config(&self) -> anyhow::Result<PipelineConfig> {
        let profile = self.profile.as_deref().map(Profile::resolve).transpose()?;
        if let Some(t) = self.calibrate_until
            && !(t.is_finite() && t > 0.0)
        {
            return Err(UsageError(format!(
                "--calibrate-until {t}: must be a positive time in s"
            ))
            .into());
        }
        Ok(PipelineConfig {
            profile,
            calibrate_until: self.calibrate_until,
            ..PipelineConfig::default()
        })
    }

    /// The JSON-lines files, created only once no output names an input or another output.
    fn files(
        &self,
        inputs: &[&Path],
        more: &[(&str, Option<&Path>)],
    ) -> anyhow::Result<MonitorFiles> {
        let mut outputs = vec![
            ("--decisions", self.decisions.as_deref()),
            ("--estimates", self.estimates.as_deref()),
        ];
        outputs.extend_from_slice(more);
        let mut inputs = inputs.to_vec();
        inputs.extend(
            self.profile
                .as_deref()
                .and_then(|p| file_input(p, ahcmon::telemetry::profile::BUILTIN)),
        );
        check_outputs(&inputs, &outputs)?;
        MonitorFiles::new(
            self.decisions.as_deref(),
            self.estimates.as_deref(),
            self.decimate,
        )
        .context("cannot create output file")
    }
}

/// The file a scenario or profile argument reads, unless the name is a built-in one (which
/// takes priority over a file of the same name).
fn file_input<'a>(name: &'a str, builtin: &[(&str, &str)]) -> Option<&'a Path> {
    (!builtin.iter().any(|(stem, _)| *stem == name)).then(|| Path::new(name))
}

/// Whether two paths name the same regular file: two existing ones by device and inode (hard
/// links too), a new one by its directory's canonical path and its name. Devices
/// (`/dev/null`) never clash.
fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    if let (Ok(x), Ok(y)) = (std::fs::metadata(a), std::fs::metadata(b)) {
        use std::os::unix::fs::MetadataExt;
        return x.is_file() && y.is_file() && (x.dev(), x.ino()) == (y.dev(), y.ino());
    }
    fn canonical(p: &Path) -> Option<PathBuf> {
        match std::fs::metadata(p) {
            Ok(m) if !m.is_file() => None,
            Ok(_) => std::fs::canonicalize(p).ok(),
            Err(_) => {
                let dir = p.parent().filter(|d| !d.as_os_str().is_empty());
                Some(
                    std::fs::canonicalize(dir.unwrap_or(Path::new(".")))
                        .ok()?
                        .join(p.file_name()?),
                )
            }
        }
    }
    matches!((canonical(a), canonical(b)), (Some(x), Some(y)) if x == y)
}

/// Refuse, before anything is created, an output that would overwrite an input (a replayed
/// log) or another output.
fn check_outputs(inputs: &[&Path], outputs: &[(&str, Option<&Path>)]) -> Result<(), UsageError> {
    let outputs: Vec<(&str, &Path)> = outputs
        .iter()
        .filter_map(|(flag, p)| p.map(|p| (*flag, p)))
        .collect();
    for (k, (flag, out)) in outputs.iter().enumerate() {
        // Only an existing input can be overwritten (a built-in scenario name is no file).
        if let Some(input) = inputs.iter().find(|i| i.is_file() && same_file(out, i)) {
            return Err(UsageError(format!(
                "{flag} {}: that is the input file {}, which it would overwrite",
                out.display(),
                input.display()
            )));
        }
        if let Some((other, _)) = outputs[k + 1..].iter().find(|(_, o)| same_file(out, o)) {
            return Err(UsageError(format!(
                "{flag} and {other} name the same file ({})",
                out.display()
            )));
        }
    }
    Ok(())
}

/// Errors that are the user's input (exit code 2) rather than ours (exit code 1).
fn is_input_error(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<ScenarioError>()
            || c.is::<UsageError>()
            || c.is::<EvalError>()
            || c.is::<ProfileError>()
            || c.is::<InputFileError>()
            || matches!(c.downcast_ref::<ConnError>(), Some(ConnError::Syntax(..)))
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // replay and eval run on this pool (two filters of a vehicle on two cores): give its
    // workers the main thread's stack size, the filter structs are moved by value.
    let _ = rayon::ThreadPoolBuilder::new()
        .stack_size(8 << 20)
        .build_global();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // The chain, each link once: an error that already says its source (`{path}:
            // {source}`) is not followed by the source again.
            let mut msg = String::new();
            for link in e.chain().map(|c| c.to_string()) {
                if msg.ends_with(&link) {
                    continue;
                }
                if !msg.is_empty() {
                    msg.push_str(": ");
                }
                msg.push_str(&link);
            }
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
                let input = file_input(one, scenario::BUILTIN);
                check_outputs(
                    input.as_slice(),
                    &[
                        ("--decisions", decisions.as_deref()),
                        ("--estimates", estimates.as_deref()),
                    ],
                )?;
                let files = RunFiles::new(decisions.as_deref(), estimates.as_deref(), decimate)
                    .context("cannot create output file")?;
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
        Command::Thresholds {
            scenarios,
            seeds,
            json,
        } => rayon::scope(|_| thresholds(scenarios, seeds, json)),
        Command::Sim {
            scenario: name,
            truth,
            decisions,
            estimates,
            seed,
            out,
            tlog,
            speed,
            sysid,
            autopilot,
        } => {
            let named = scenario::resolve(&name)?;
            check_outputs(
                file_input(&name, scenario::BUILTIN).as_slice(),
                &[
                    ("--truth", truth.as_deref()),
                    ("--decisions", decisions.as_deref()),
                    ("--estimates", estimates.as_deref()),
                    ("--tlog", tlog.as_deref()),
                ],
            )?;
            if out.is_some() || tlog.is_some() {
                if decisions.is_some() || estimates.is_some() {
                    return Err(UsageError(
                        "--decisions / --estimates come from the in-process filters; with --out / --tlog run `ahcmon monitor` or `ahcmon replay` on the stream instead".into(),
                    )
                    .into());
                }
                let opts = SimOutput {
                    out,
                    tlog,
                    truth,
                    speed,
                    sysid,
                    seed: seed.unwrap_or(named.scenario.seed),
                    flavour: match autopilot {
                        AutopilotArg::Ardupilot => ahcmon::telemetry::encode::Flavour::ArduPilot,
                        AutopilotArg::Px4 => ahcmon::telemetry::encode::Flavour::Px4,
                    },
                };
                return sim_mavlink(&named, opts);
            }
            let (cfg, _) = sim_config(&named, 0)?;
            let mut files = RunFiles::new(decisions.as_deref(), estimates.as_deref(), 1)
                .context("cannot create output file")?;
            if let Some(path) = &truth {
                files = files
                    .with_truth(path, cfg.gyro_noise, cfg.az_noise)
                    .context("cannot create output file")?;
            }
            run_with_files(&named, seed.unwrap_or(named.scenario.seed), files, true).map(|_| ())
        }
        Command::Monitor {
            conn,
            run,
            link_timeout,
            exit_idle,
            alerts,
            headless,
            request_rates,
        } => monitor(
            &conn,
            &run,
            MonitorOptions {
                link_timeout,
                exit_idle,
                alerts,
                request_rates,
                headless,
            },
            None,
        ),
        Command::Demo {
            headless,
            scenario: name,
            decisions,
            estimates,
            alerts,
            speed,
        } => {
            let named = scenario::resolve(name.as_deref().unwrap_or("heli-demo"))?;
            check_outputs(
                name.as_deref()
                    .and_then(|n| file_input(n, scenario::BUILTIN))
                    .as_slice(),
                &[
                    ("--decisions", decisions.as_deref()),
                    ("--estimates", estimates.as_deref()),
                ],
            )?;
            if named.scenario.is_paper() {
                return Err(UsageError(format!(
                    "{} is a paper scenario; the demo needs a vehicle scenario",
                    named.name
                ))
                .into());
            }
            let speed = in_range("--speed", speed, SPEED_RANGE.0, SPEED_RANGE.1)?;
            eprintln!("demo: {}", named.scenario.description);
            eprintln!(
                "demo: on the autopilot's clock, which the monitor shows: {}",
                ahcmon::link::simulate::script_on_vehicle_clock(&named.scenario)
            );
            warn_fault_in_calibration("demo", &named);
            let args = RunArgs {
                profile: None,
                decisions,
                estimates,
                decimate: 1,
                calibrate_until: None,
            };
            // Headless, the monitor stops once the simulated flight has ended; with the
            // dashboard the operator looks on until q.
            let dashboard = !headless && std::io::stdout().is_terminal();
            let idle = (!dashboard).then_some((1.5 / speed).max(0.5));
            monitor(
                "udpin:127.0.0.1:0",
                &args,
                MonitorOptions {
                    link_timeout: 2.0,
                    exit_idle: idle,
                    alerts,
                    request_rates: None,
                    headless,
                },
                Some(DemoVehicle { named, speed }),
            )
        }
        Command::Calibrate {
            file,
            until,
            output,
            profile,
            sysid,
        } => calibrate(&file, until, &output, profile.as_deref(), sysid),
        Command::Replay {
            file,
            run,
            speed,
            fast: _,
            headless,
            plot,
        } => {
            // On a rayon worker, so each vehicle's two filters step on two cores.
            rayon::scope(|_| replay(&file, &run, speed, plot.as_deref(), headless))
        }
    }
}

struct SimOutput {
    out: Option<String>,
    tlog: Option<PathBuf>,
    truth: Option<PathBuf>,
    speed: Option<f64>,
    sysid: u8,
    seed: u64,
    flavour: ahcmon::telemetry::encode::Flavour,
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn positive(name: &str, v: f64) -> anyhow::Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(UsageError(format!("{name} {v:?}: must be a positive number")).into())
    }
}

/// A speed-up factor or a duration (s) that becomes a `Duration` or divides one: bounded, so
/// that no conversion overflows (`--speed 1e-300` would ask to wait 10^300 s).
fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> anyhow::Result<f64> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(UsageError(format!("{name} {v:?}: must be between {lo} and {hi}")).into())
    }
}

/// Longest a paced replay waits for the next record; a longer wait is a hole in the log (or
/// a timestamp off by hours), skipped.
const MAX_PACE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

/// Bounds of `--speed` (multiple of real time) and of the monitor's timeouts (s).
const SPEED_RANGE: (f64, f64) = (1e-3, 1e6);
const TIMEOUT_RANGE_S: (f64, f64) = (1e-3, 1e6);

/// A monitor with default settings takes the first settle + calibration seconds of the
/// flight as healthy: a scenario's fault in them becomes the vehicle's normal. Said by `sim`
/// and `demo` (`demo --scenario quad-x-motor2-loe` decided only a wrong motor, silently).
fn warn_fault_in_calibration(who: &str, named: &NamedScenario) {
    let defaults = PipelineConfig::default();
    let learned_until = defaults.settle_s + defaults.calibrate_s;
    if let Some(f) = named.scenario.first_fault()
        && f.t < learned_until
    {
        eprintln!(
            "{who}: warning: the fault on {} at {} s into the flight falls in the first {learned_until} s, which a monitor with default settings calibrates on as healthy: it would learn the fault as the vehicle's normal (the `-live` scenarios start their faults later{})",
            f.actuator,
            f.t,
            if who == "sim" {
                "; or give the monitor --calibrate-until, or a profile ahcmon calibrate identified"
            } else {
                ""
            }
        );
    }
}

/// The simulated vehicle as a MAVLink autopilot: to a live connection and/or a tlog.
fn sim_mavlink(named: &NamedScenario, o: SimOutput) -> anyhow::Result<()> {
    use ahcmon::link::simulate::{FlyOptions, fly};
    use ahcmon::output::jsonl::JsonlWriter;
    if named.scenario.is_paper() {
        return Err(UsageError(format!(
            "{} is a paper scenario; MAVLink output needs a vehicle scenario",
            named.name
        ))
        .into());
    }
    let speed = o
        .speed
        .map(|x| in_range("--speed", x, SPEED_RANGE.0, SPEED_RANGE.1))
        .transpose()?;
    let spec: Option<ConnSpec> = o.out.as_deref().map(str::parse).transpose()?;
    warn_fault_in_calibration("sim", named);
    let mut tlog = o
        .tlog
        .as_deref()
        .map(|p| TlogWriter::create(p).with_context(|| format!("cannot create {}", p.display())))
        .transpose()?;
    let mut truth = o
        .truth
        .as_deref()
        .map(|p| JsonlWriter::create(p).context("cannot create output file"))
        .transpose()?;
    // tlog time: now when live, a fixed epoch otherwise (reproducible files).
    let live = spec.is_some();
    let opts = FlyOptions {
        sysid: o.sysid,
        seed: o.seed,
        flavour: o.flavour,
        speed: if live {
            Some(speed.unwrap_or(1.0))
        } else {
            speed
        },
        epoch_us: if live {
            now_us()
        } else {
            1_767_225_600_000_000
        },
    };
    let rt = runtime()?;
    let report = rt.block_on(async {
        let mut link = match &spec {
            Some(s) => Some(Link::open(s.clone()).await?),
            None => None,
        };
        // Where frames go before a peer is there (they are counted as not sent).
        if let (Some(s), Some(l)) = (&spec, &link) {
            let waiting = match (s, l.not_connected()) {
                (_, Some(why)) => Some(format!("{why}; retrying every second")),
                (ConnSpec::UdpIn(_), _) => Some("no peer until a datagram arrives".into()),
                (ConnSpec::TcpIn(_), _) => Some("no client connected yet".into()),
                _ => None,
            };
            if let Some(w) = waiting {
                eprintln!("sim: {s}: {w}; frames are not sent until then");
            }
        }
        let flight = fly(named, &opts, link.as_mut(), tlog.as_mut(), truth.as_mut());
        // ctrl-c ends the flight with the files whole (the default would kill the process with
        // the tlog's last records still buffered).
        tokio::select! {
            r = flight => anyhow::Ok(Some(r?)),
            _ = tokio::signal::ctrl_c() => anyhow::Ok(None),
        }
    })?;
    let Some(report) = report else {
        if let Some(w) = tlog.as_mut() {
            w.flush().context("writing the tlog")?;
        }
        outln!(
            "{}: interrupted; the files hold the flight up to now",
            named.name
        );
        return Ok(());
    };
    let list: Vec<String> = report
        .counts
        .iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect();
    outln!(
        "{}: {} s of {} as sysid {} (seed {}): {}",
        named.name,
        named.scenario.duration_s,
        report.vehicle,
        o.sysid,
        o.seed,
        list.join(", ")
    );
    if let Some(s) = &spec {
        outln!(
            "sent {} frames to {s}{}",
            report.sent,
            if report.unsent > 0 {
                format!(", {} not sent (no peer yet)", report.unsent)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

fn now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// What runs beside the monitor in the same process: `demo`'s simulated vehicle.
struct DemoVehicle {
    named: NamedScenario,
    speed: f64,
}

struct MonitorOptions {
    link_timeout: f64,
    exit_idle: Option<f64>,
    alerts: Option<String>,
    request_rates: Option<f64>,
    headless: bool,
}

fn monitor(
    conn: &str,
    args: &RunArgs,
    o: MonitorOptions,
    demo: Option<DemoVehicle>,
) -> anyhow::Result<()> {
    let MonitorOptions {
        link_timeout,
        exit_idle,
        alerts,
        request_rates,
        headless,
    } = o;
    let alerts = alerts.as_deref();
    let spec: ConnSpec = conn.parse()?;
    // A UDP peer sends to addresses it has heard from, and the monitor says nothing on the
    // vehicle link: from udpout or udpbcast it would wait forever.
    if let ConnSpec::UdpOut(a) | ConnSpec::UdpBcast(a) = &spec {
        let port = a.port();
        return Err(UsageError(format!(
            "monitor {spec}: the monitor sends nothing to the vehicle, so a UDP peer would never learn where to send; have the autopilot or router send to this machine and listen with udpin:0.0.0.0:{port} (MAVProxy: --out=udp:THIS_HOST:{port})"
        ))
        .into());
    }
    // The dashboard unless asked not to, or when stdout is not a terminal (CI, pipes).
    let dashboard = !headless && std::io::stdout().is_terminal();
    let alerts: Option<ConnSpec> = alerts.map(str::parse).transpose()?;
    let mut opts = ahcmon::link::live::LiveOptions {
        link_timeout: std::time::Duration::from_secs_f64(in_range(
            "--link-timeout",
            link_timeout,
            TIMEOUT_RANGE_S.0,
            TIMEOUT_RANGE_S.1,
        )?),
        exit_idle: exit_idle
            .map(|s| {
                in_range("--exit-idle", s, TIMEOUT_RANGE_S.0, TIMEOUT_RANGE_S.1)
                    .map(std::time::Duration::from_secs_f64)
            })
            .transpose()?,
        request_rates: request_rates
            .map(|hz| in_range("--request-rates", hz, 0.1, 1000.0))
            .transpose()?,
        ..Default::default()
    };
    let mut monitor = Monitor::new(args.pipeline_config()?);
    let mut files = args.files(&[], &[])?;
    if alerts.is_some() {
        files.alerts = Some(ahcmon::output::alerts::Alerts::default());
    }
    let rt = runtime()?;
    let result = rt.block_on(async {
        let link = Link::open(spec.clone()).await?;
        let local = link.local_addr();
        let verb = match spec {
            ConnSpec::UdpIn(_) | ConnSpec::TcpIn(_) => "listening on",
            ConnSpec::UdpOut(_) | ConnSpec::UdpBcast(_) => "sending to",
            ConnSpec::TcpOut(_) => "connected to",
            ConnSpec::Serial(..) => "reading",
        };
        match link.not_connected() {
            Some(why) => eprintln!("monitor: {spec}: {why}; retrying every second"),
            None => eprintln!(
                "monitor: {verb} {spec}{}",
                local.map_or(String::new(), |a| format!(" (local {a})"))
            ),
        }
        let alert_link = match &alerts {
            Some(a) => {
                eprintln!("monitor: alerts to {a} (sysid of the vehicle, component 191)");
                Some(Link::open(a.clone()).await?)
            }
            None => None,
        };
        let script = demo
            .as_ref()
            .map(|d| ahcmon::link::simulate::script_on_vehicle_clock(&d.named.scenario));
        // demo: the simulated vehicle flies in this process, over loopback UDP to the monitor.
        let flight_over = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        if demo.is_some() {
            opts.stream_over = Some(flight_over.clone());
        }
        let sim = match (demo, local) {
            (Some(d), Some(addr)) => {
                let target: ConnSpec = format!("udpout:127.0.0.1:{}", addr.port()).parse()?;
                let mut out = Link::open(target).await?;
                let over = flight_over.clone();
                Some(tokio::spawn(async move {
                    let opts = ahcmon::link::simulate::FlyOptions {
                        sysid: 1,
                        seed: d.named.scenario.seed,
                        flavour: Default::default(),
                        speed: Some(d.speed),
                        epoch_us: now_us(),
                    };
                    let flown =
                        ahcmon::link::simulate::fly(&d.named, &opts, Some(&mut out), None, None)
                            .await;
                    // A flight that failed is no planned end: its silence is a lost link.
                    if flown.is_ok() {
                        over.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                    flown
                }))
            }
            _ => None,
        };
        let mut ui = if dashboard {
            files.echo = false;
            // The address actually bound (the demo's udpin:127.0.0.1:0 showed port 0).
            let shown = match (&spec, local) {
                (ConnSpec::UdpIn(_), Some(a)) => format!("udpin:{a}"),
                (ConnSpec::TcpIn(_), Some(a)) => format!("tcpin:{a}"),
                _ => spec.to_string(),
            };
            let mut ui = ahcmon::output::dashboard::TerminalUi::start(&shown)
                .context("cannot start the dashboard (try --headless)")?;
            if let Some(script) = script {
                ui.set_note(format!("script: {script}"));
                ui.end_when(flight_over.clone(), "END OF FLIGHT");
            }
            Some(ui)
        } else {
            None
        };
        let counters = ahcmon::link::live::run(
            link,
            &mut monitor,
            &mut files,
            alert_link,
            ui.as_mut(),
            opts,
        )
        .await;
        // Restore the terminal before anything is printed.
        drop(ui);
        let counters = counters?;
        for note in &counters.notes_to_say() {
            eprintln!("monitor: {note}");
        }
        if let Some(h) = sim {
            // Quit before the script ended: stop the vehicle; else report how it ended.
            if h.is_finished() {
                h.await.context("the simulated vehicle stopped")??;
            } else {
                h.abort();
            }
        }
        anyhow::Ok(counters)
    });
    // A write error is reported whatever else happened, after the summary when there is one.
    let write_error = files
        .error
        .take()
        .map(|e| anyhow::Error::new(e).context("writing JSON lines"));
    let counters = match result {
        Ok(c) => c,
        Err(e) => {
            if let Some(w) = &write_error {
                eprintln!("ahcmon: error: {w:#}");
            }
            return Err(e);
        }
    };
    out!("{}", summary::render(&monitor, &counters.link, &files.seen));
    if counters.backpressure_drops > 0 {
        outln!(
            "{} frames dropped: the estimators fell behind",
            counters.backpressure_drops
        );
    }
    if counters.own_echo > 0 {
        outln!(
            "{} of our own alert frames (component {}) came back in on the vehicle link and were ignored: the forwarder sends our alerts back to us (harmless)",
            counters.own_echo,
            ahcmon::output::alerts::ALERT_COMPID
        );
    }
    if let Some(a) = &files.alerts {
        outln!(
            "alerts: {} STATUSTEXT queued for sending ({} of them a loss told again at its new size), {} dropped by the rate limit, {} not repeated (the planner's last text on that actuator already said it); {} frames found no planner to send to (none connected yet, or the link failed; a udpout target that is not listening cannot be told apart from one that is)",
            a.texts_sent,
            a.texts_resized,
            a.texts_dropped,
            a.texts_repeated,
            a.frames_unsent
        );
    }
    write_error.map_or(Ok(()), Err)
}

fn calibrate(
    file: &std::path::Path,
    until: f64,
    output: &std::path::Path,
    profile: Option<&str>,
    only: Option<u8>,
) -> anyhow::Result<()> {
    let until = positive("--until", until)?;
    let mut inputs = vec![file];
    inputs.extend(profile.and_then(|p| file_input(p, ahcmon::telemetry::profile::BUILTIN)));
    check_outputs(&inputs, &[("--output", Some(output))])?;
    let input_error = |source| InputFileError {
        path: file.display().to_string(),
        source,
    };
    let mut reader = TlogReader::open(file).map_err(input_error)?;
    let args = RunArgs {
        profile: profile.map(str::to_string),
        decisions: None,
        estimates: None,
        decimate: 1,
        calibrate_until: Some(until),
    };
    let mut monitor = Monitor::new(args.pipeline_config()?);
    // Echoed: the pipeline's progress and warnings (a short stretch, a poor fit, a profile of
    // another kind, outputs without PWM) concern the profile written. Its vehicle makes no
    // decision before its calibration, where this stops; with several vehicles, another one
    // may have (--sysid runs only the one).
    let mut files = MonitorFiles::new(None, None, 1)?;
    let mut found = None;
    // Systems whose attitude the log holds: the vehicles a --sysid could name.
    let mut vehicles = std::collections::BTreeSet::new();
    let mut note_vehicle = |frame: &ahcmon::protocol::Frame| {
        if matches!(frame.msg, ahcmon::protocol::MavMessage::ATTITUDE(_)) {
            vehicles.insert(frame.sysid);
        }
    };
    while let Some((_, frame)) = reader.next_frame().map_err(input_error)? {
        note_vehicle(&frame);
        // Another vehicle's frames would run its whole pipeline, decisions and all.
        if only.is_some_and(|s| s != frame.sysid) {
            continue;
        }
        monitor.on_frame(&frame, &mut files);
        if let Some((sysid, p)) = monitor
            .pipelines
            .iter()
            .find(|(id, p)| only.is_none_or(|s| s == **id) && (p.fit.is_some() || p.arx.is_some()))
        {
            found = Some((*sysid, p.profile().cloned(), p.fit.clone(), p.arx.clone()));
            break;
        }
    }
    if let Some((chosen, ..)) = &found
        && only.is_none()
    {
        // Read on, decoding only, to learn which other vehicles the log holds.
        while let Ok(Some((_, frame))) = reader.next_frame() {
            note_vehicle(&frame);
        }
        let others: Vec<String> = vehicles
            .iter()
            .filter(|id| *id != chosen)
            .map(|id| id.to_string())
            .collect();
        if !others.is_empty() {
            eprintln!(
                "the log also holds sysid {}: calibrating sysid {chosen}, the first to complete its stretch (--sysid chooses)",
                others.join(", ")
            );
        }
    }
    let Some((sysid, Some(mut calibrated), fit, arx)) = found else {
        // Why, per vehicle, as the replay summary says it.
        let reasons: Vec<String> = monitor
            .pipelines
            .iter()
            .filter(|(id, _)| only.is_none_or(|s| s == **id))
            .map(|(sysid, p)| {
                let heartbeat = monitor
                    .assembler
                    .vehicles
                    .get(sysid)
                    .is_some_and(|v| v.info.mav_type.is_some());
                let why = p
                    .why_not_estimating(heartbeat)
                    .unwrap_or_else(|| format!("stopped {}", p.stage_name()));
                format!("sysid {sysid}: {why}")
            })
            .collect();
        let why = if let (true, Some(id)) = (reasons.is_empty(), only) {
            let ids: Vec<String> = vehicles.iter().map(|i| i.to_string()).collect();
            format!(
                "no vehicle with sysid {id} (systems sending ATTITUDE: {})",
                if ids.is_empty() {
                    "none".into()
                } else {
                    ids.join(", ")
                }
            )
        } else if reasons.is_empty() {
            "no vehicle with rates and outputs in it".to_string()
        } else {
            reasons.join("; ")
        };
        return Err(UsageError(format!(
            "{}: no healthy stretch ending at t = {until} s (vehicle time) to calibrate on: {why}",
            file.display()
        ))
        .into());
    };
    let base = calibrated.name.clone();
    calibrated.name = format!("{base}-calibrated");
    calibrated.identified = true;
    let axes = ["roll", "pitch", "yaw", "a_z"];
    let (samples, quality): (usize, Vec<String>) = match (&fit, &arx) {
        (Some(fit), _) => (
            fit.quality.samples,
            fit.quality
                .r_squared
                .iter()
                .zip(&fit.scaled)
                .enumerate()
                .map(|(i, (r2, scaled))| {
                    format!(
                        "{} {} R2 {:.2}",
                        axes[i],
                        if *scaled { "fitted" } else { "offset only" },
                        r2
                    )
                })
                .collect(),
        ),
        (None, Some(arx)) => (
            arx.quality.samples,
            arx.quality
                .r_squared
                .iter()
                .enumerate()
                .map(|(i, r2)| format!("{} increment R2 {:.2}", axes[i], r2))
                .chain(std::iter::once(format!(
                    "command delay {} samples",
                    arx.params.delay
                )))
                .collect(),
        ),
        (None, None) => unreachable!("found only with a fit"),
    };
    calibrated.description = format!(
        "{base} identified from {} (sysid {sysid}), healthy stretch of {} samples ending at t = {until} s: {}",
        file.display(),
        samples,
        quality.join(", ")
    );
    let text = toml::to_string(&calibrated).context("cannot serialise the profile")?;
    std::fs::write(output, format!("# written by `ahcmon calibrate`\n{text}"))
        .with_context(|| format!("cannot write {}", output.display()))?;
    outln!("{}", calibrated.description);
    outln!("profile written to {}", output.display());
    Ok(())
}

/// An input file that cannot be read (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
struct InputFileError {
    path: String,
    source: std::io::Error,
}

fn replay(
    file: &std::path::Path,
    args: &RunArgs,
    speed: Option<f64>,
    plot: Option<&std::path::Path>,
    headless: bool,
) -> anyhow::Result<()> {
    if let Some(x) = speed {
        in_range("--speed", x, SPEED_RANGE.0, SPEED_RANGE.1)?;
    }
    let input_error = |source| InputFileError {
        path: file.display().to_string(),
        source,
    };
    let size = std::fs::metadata(file).map_err(input_error)?.len();
    let mut reader = TlogReader::open(file).map_err(input_error)?;
    let mut monitor = Monitor::new(args.pipeline_config()?);
    let mut files = args.files(&[file], &[("--plot", plot)])?;
    if let Some(p) = plot {
        // Fail now rather than after a long replay.
        std::fs::write(p, "").with_context(|| format!("cannot write {}", p.display()))?;
        files.plot = Some(ahcmon::output::svg::PlotRecorder::default());
    }
    // The dashboard at a replay speed a person can follow; --fast (the default) is headless.
    let mut ui = if !headless && std::io::stdout().is_terminal() {
        files.echo = false;
        Some(
            // The file's name: its whole path left no room for the counters.
            ahcmon::output::dashboard::TerminalUi::start(&format!(
                "replay {}",
                file.file_name().map_or(file.display().to_string(), |n| n
                    .to_string_lossy()
                    .into_owned())
            ))
            .context("cannot start the dashboard (try --headless)")?,
        )
    } else {
        None
    };
    let progress = ui.is_none() && std::io::stderr().is_terminal();
    let started = std::time::Instant::now();
    // Pacing for --speed: a log timestamp and the moment it was replayed.
    let mut pace: Option<(u64, std::time::Instant)> = None;
    let mut shown = 0;
    let mut last_draw = std::time::Instant::now();
    let mut quit = false;
    while let Some((ts, frame)) = reader.next_frame().map_err(input_error)? {
        if let Some(ui) = ui.as_mut()
            && last_draw.elapsed() >= std::time::Duration::from_millis(100)
        {
            last_draw = std::time::Instant::now();
            if let ahcmon::output::dashboard::KeyAction::Quit = ui.keys(&monitor) {
                quit = true;
                break;
            }
            let _ = ui.draw(
                &monitor,
                &files.seen,
                reader.counters,
                Some(0.0),
                &Default::default(),
            );
        }
        if let Some(x) = speed {
            let (t0, at) = *pace.get_or_insert((ts, std::time::Instant::now()));
            let due =
                std::time::Duration::try_from_secs_f64(ts.saturating_sub(t0) as f64 * 1e-6 / x)
                    .unwrap_or(std::time::Duration::MAX);
            match due.checked_sub(at.elapsed()) {
                // A hole in the log, or a clock that jumps: go on from here, not sleep through.
                Some(wait) if wait > MAX_PACE_WAIT => {
                    pace = Some((ts, std::time::Instant::now()));
                }
                Some(wait) => std::thread::sleep(wait),
                None => {}
            }
        }
        monitor.on_frame(&frame, &mut files);
        // Every estimate into the chart: at 10 redraws a second, a replay as fast as the CPU
        // goes charted only the last second of the log.
        if let Some(ui) = ui.as_mut() {
            ui.history.live.sample(&monitor);
        }
        if progress && size > 0 {
            let pct = (reader.position() * 100 / size) as usize;
            if pct != shown {
                shown = pct;
                eprint!("\rreplay: {pct:3}% [{:<40}]", "#".repeat(pct * 40 / 100));
            }
        }
    }
    monitor.finish(&mut files);
    let replay_time = started.elapsed();
    // End of the log: the dashboard stays until q.
    if let Some(ui) = ui.as_mut()
        && !quit
    {
        ui.mark_ended("END OF LOG");
        loop {
            if let ahcmon::output::dashboard::KeyAction::Quit = ui.keys(&monitor) {
                break;
            }
            let _ = ui.draw(
                &monitor,
                &files.seen,
                reader.counters,
                None,
                &Default::default(),
            );
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
    }
    drop(ui);
    if progress {
        eprint!("\r{:60}\r", "");
    }
    // Reported after the plot and the summary, which do not depend on the files.
    let write_error = files
        .error
        .take()
        .map(|e| anyhow::Error::new(e).context("writing JSON lines"));
    if let (Some(p), Some(rec)) = (plot, files.plot.as_ref()) {
        let title = format!("ahcmon replay {}", file.display());
        std::fs::write(p, rec.render(&title))
            .with_context(|| format!("cannot write {}", p.display()))?;
        eprintln!("plot written to {}", p.display());
    }
    out!(
        "{}",
        summary::render(&monitor, &reader.counters, &files.seen)
    );
    outln!(
        "replayed {} in {:.2} s",
        file.display(),
        replay_time.as_secs_f64()
    );
    write_error.map_or(Ok(()), Err)?;
    // Not a telemetry log at all: say so with an input error, so a script can tell.
    let c = &reader.counters;
    if c.frames == 0 && c.unknown_id == 0 {
        return Err(UsageError(format!(
            "{}: no MAVLink frame in its {size} bytes; is it a telemetry log (.tlog)?",
            file.display()
        ))
        .into());
    }
    // An estimation that failed (said when it happened and in the summary) is no success: a
    // script must not take the log as checked. (A log with no flight in it is: the summary
    // says why nothing was estimated.)
    let failed: Vec<String> = monitor
        .pipelines
        .iter()
        .filter_map(|(sysid, p)| p.failed().map(|why| format!("sysid {sysid}: {why}")))
        .collect();
    if !failed.is_empty() {
        anyhow::bail!("the estimation failed ({})", failed.join("; "));
    }
    Ok(())
}

/// `sim --autopilot`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum AutopilotArg {
    Ardupilot,
    Px4,
}

/// A mistake in how the command line combines things (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct UsageError(String);

/// One vehicle run with its JSONL files; with `print`, the decisions as they are made and
/// then what was written.
fn run_with_files(
    named: &NamedScenario,
    seed: u64,
    mut files: RunFiles,
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
    let run = run_vehicle_scenario(named, seed, false, &mut files)?;
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
            files.decisions_made,
        );
    }
    Ok(written)
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
    let progress = std::io::stderr().is_terminal();
    let mut out = vec![];
    for named in &list {
        if progress {
            eprint!("\rthresholds: {} ({} flights)   ", named.name, seeds);
        }
        out.push(calibrate_threshold(named, &seed_list)?);
    }
    if progress {
        eprint!("\r{:60}\r", "");
    }
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
        outln!("{}", table::to_json(&rows));
    } else {
        out!("{}", table::render(&rows));
        if let Some(dir) = &plot {
            outln!("plots written to {}", dir.display());
        }
    }
    Ok(())
}
