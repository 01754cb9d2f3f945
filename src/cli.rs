//! The command line: one clap struct per command, shared option groups flattened.

use clap::{Parser, Subcommand};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "ahcmon",
    version,
    about = "Actuator health monitor: estimates each actuator's gain (gamma) and bias (delta) with MIT-UKF and MIT-ESMF"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// More diagnostics on stderr: -v the pipeline's stages, -vv every detail (RUST_LOG
    /// also sets them, e.g. RUST_LOG=ahcmon::pipeline=debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count, conflicts_with = "quiet", display_order = 900)]
    pub verbose: u8,
    /// Only results: no progress, notes or warnings on stderr (errors still are).
    #[arg(short, long, global = true, display_order = 900)]
    pub quiet: bool,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run scenarios through the simulator and all five filters (UKF, KF-UKF, MIT-UKF, ESMF,
    /// MIT-ESMF) and score them against the truth: detection delay, settling time, RMSE,
    /// truth-in-bounds, false decisions, µs per step. With --decisions / --estimates (one
    /// vehicle scenario), also the JSON lines of its first seed.
    Eval(EvalArgs),
    /// Calibrate each vehicle's decision threshold on healthy Monte-Carlo flights: the smallest
    /// threshold at which no healthy flight would raise a fault, times a margin. Flown with
    /// seeds from 1001 on, which the tests and `eval` do not use.
    ///
    /// Two rows per scenario, one per statistic: `deviation` (the effective output's deviation
    /// attributed to an actuator) and `gain` (angle outputs' gain statistic). Columns:
    /// `alarm-free ukf` / `alarm-free set`, the smallest threshold at which the MIT-UKF's / the
    /// MIT-ESMF's statistic raised no alarm on any flight; `max ukf` / `max set`, the largest
    /// value of that statistic seen after the warm-up; `recommended`, 1.25 × the larger
    /// alarm-free threshold; `profile`, the built-in profile's threshold now ("-": none). A
    /// third row gives the gusts the in-flight calibration measured on the same flights (roll,
    /// pitch, yaw in rad/s², the axes' means at the strongest flight's level): the profile's
    /// `diagnosis.gusts`, against which a flight in stronger gusts has its threshold raised
    /// (rule T1).
    Thresholds(ThresholdsArgs),
    /// Fly a vehicle scenario in the simulator (with the monitor's filters and diagnosis
    /// running on it), print its decisions as they are made, and write its ground truth,
    /// decisions and estimates as JSON lines.
    Sim(SimArgs),
    /// Watch live vehicles on a MAVLink connection (e.g. udpin:0.0.0.0:14550 beside a ground
    /// station): both filters and the diagnosis per vehicle, decisions as they happen, a summary
    /// on exit (ctrl-c).
    Monitor(MonitorArgs),
    /// The built-in demonstration: a simulated H3-120 helicopter flies in this process over
    /// loopback UDP to the monitor; 32 s into the flight swash servo 2 loses 40 % effectiveness,
    /// at 45 s the tail servo gets a bias; headless it ends by itself after 58 s (the dashboard
    /// stays until q). The monitor shows the autopilot's clock, which reads 10 s when the
    /// flight starts: the faults come at t=42 s and t=55 s.
    Demo(DemoArgs),
    /// Identify a vehicle's model (D, G, c and the noise levels) from a healthy stretch of a
    /// telemetry log and write it as a profile (usable with --profile FILE).
    Calibrate(CalibrateArgs),
    /// Replay a log (a ground station's .tlog, an ArduPilot DataFlash .bin, a PX4 .ulg) through both filters and the
    /// diagnosis: decisions as they happen, a summary at the end (final estimates with bounds,
    /// decisions, and counts of everything dropped).
    Replay(ReplayArgs),
    /// Replay many logs (files, directories searched for .tlog, .bin and .ulg, glob patterns)
    /// on all cores, one log per task, and write one JSON line per flight × vehicle ×
    /// actuator: its gamma and delta (both filters' medians over the flight, with bounds), its
    /// faults and the data's quality. A log that cannot be read is named with its reason and
    /// the others go on. Exit 0: every log read; 1: some logs or directories could not be
    /// read, or some paths named nothing (their rows are missing, the others' written); 2: no
    /// log at all, or the command line.
    Scan(ScanArgs),
    /// Health over flights, from `scan`'s rows: per airframe (else board id, else system id) ×
    /// actuator, the MIT-UKF's median gamma flight by flight, its weighted trend over the last
    /// flights, and an alarm when it falls faster than chance explains at --false-alarm and
    /// is predicted to reach --loss-gamma within --horizon flights (docs/fleet.md). Exit 0
    /// with or without alarms.
    History(HistoryArgs),
    /// Replay labelled logs and score the fault decisions against their truth: per log the
    /// first fault decision at or after the onset (actuator, delay, class), the fault decisions
    /// before it, and per dataset the totals (healthy flights' fault decisions per flight hour,
    /// per-flight precision and recall, a published figure beside ours where the truth file
    /// quotes one). The truth format and the scoring rules: docs/results.md, "Dataset
    /// benchmark".
    Benchmark(BenchmarkArgs),
    /// Print a shell's completion script for ahcmon (bash, zsh, fish, elvish, powershell).
    /// bash: `ahcmon completions bash > ~/.local/share/bash-completion/completions/ahcmon`;
    /// zsh: into a directory of your $fpath as `_ahcmon`; fish:
    /// `ahcmon completions fish > ~/.config/fish/completions/ahcmon.fish`.
    Completions(CompletionsArgs),
    /// Print the manual page (roff): `ahcmon man > ahcmon.1; man -l ahcmon.1`, or with --dir
    /// one page per command (ahcmon.1, ahcmon-replay.1, ...) for a MANPATH.
    Man(ManArgs),
}

#[derive(clap::Args)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: clap_complete::Shell,
}

#[derive(clap::Args)]
pub struct ManArgs {
    /// Write every command's page into this directory instead of the main page to stdout.
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
}

/// `eval --json`, whose report is printed on standard output, among [`Command::stdout_flags`].
pub const PRINTED_JSON: &str = "--json (the report)";

impl Command {
    /// The output flags given as `-` (standard output), and `eval --json`'s report.
    pub fn stdout_flags(&self) -> Vec<&'static str> {
        fn common(o: &OutputArgs) -> Vec<(&'static str, Option<&std::path::Path>)> {
            o.flags().to_vec()
        }
        let flags: Vec<(&'static str, Option<&std::path::Path>)> = match self {
            Command::Eval(a) => {
                let mut f = common(&a.output);
                // The report printed as JSON is standard output's: no output file goes there too.
                if a.json {
                    f.push((PRINTED_JSON, Some(std::path::Path::new("-"))));
                }
                f
            }
            Command::Sim(a) => {
                let mut f = common(&a.output);
                f.extend([
                    ("--truth", a.truth.as_deref()),
                    ("--tlog", a.tlog.as_deref()),
                ]);
                f
            }
            Command::Monitor(a) => {
                let mut f = common(&a.run.output);
                f.push(("--summary", a.run.summary.as_deref()));
                f
            }
            Command::Demo(a) => common(&a.output),
            Command::Replay(a) => {
                let mut f = common(&a.run.output);
                f.extend([
                    ("--plot", a.plot.as_deref()),
                    ("--summary", a.run.summary.as_deref()),
                ]);
                f
            }
            Command::Calibrate(a) => vec![("--output", Some(a.output.as_path()))],
            Command::Benchmark(a) => vec![("--json", a.json.as_deref())],
            Command::Scan(a) => vec![
                ("--rows", a.rows_path()),
                ("--parquet", a.parquet.as_deref()),
            ],
            Command::History(a) => {
                vec![("--json", a.json.as_deref()), ("--plot", a.plot.as_deref())]
            }
            Command::Thresholds(_) | Command::Completions(_) | Command::Man(_) => vec![],
        };
        flags
            .into_iter()
            .filter(|(_, p)| p.is_some_and(ahcmon::output::file::is_stdout))
            .map(|(flag, _)| flag)
            .collect()
    }
}

#[derive(clap::Args)]
pub struct ScanArgs {
    /// Logs: files (any name: the format is told by content), directories (searched
    /// recursively for .tlog, .bin and .ulg), or glob patterns in quotes ('logs/**/*.tlog').
    #[arg(required = true, value_name = "PATH")]
    pub paths: Vec<PathBuf>,
    /// Write the rows as JSON lines here (`-`: standard output, the default unless
    /// --parquet is given).
    #[arg(long, value_name = "FILE.jsonl")]
    pub rows: Option<PathBuf>,
    /// Write the rows as a Parquet table here too (columns flattened: `mit_ukf_gamma`, ...;
    /// the schema is in docs/fleet.md). `-`: standard output.
    #[arg(long, value_name = "FILE.parquet")]
    pub parquet: Option<PathBuf>,
    /// Logs replayed at once (default: one per core).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..=1024))]
    pub jobs: Option<u16>,
    /// Vehicle profile for every log: built-in name or TOML file. One that `ahcmon calibrate`
    /// wrote (identified on a healthy flight of the airframe) is used from the take-off on,
    /// so a weakness present from the start is measured against the airframe's healthy model
    /// rather than learnt as its normal by the in-flight calibration. Default: chosen per log
    /// from its HEARTBEAT and parameters, calibrated in flight.
    #[arg(long, value_name = "NAME|FILE")]
    pub profile: Option<String>,
    /// Which airframe each log belongs to: a TOML file of `[[airframe]]` entries, each a
    /// `name` and the `logs` (glob patterns of paths) or `boards` (board ids) that are it.
    /// Without one, `history` groups the flights by board id where the log carries it, else
    /// by system id.
    #[arg(long, value_name = "FILE.toml")]
    pub airframes: Option<PathBuf>,
}

impl ScanArgs {
    /// Where the JSON lines go: `--rows`, or standard output when no output is named.
    pub fn rows_path(&self) -> Option<&std::path::Path> {
        match (&self.rows, &self.parquet) {
            (Some(r), _) => Some(r),
            (None, None) => Some(std::path::Path::new("-")),
            (None, Some(_)) => None,
        }
    }
}

#[derive(clap::Args)]
pub struct HistoryArgs {
    /// `ahcmon scan`'s rows (JSON lines).
    #[arg(value_name = "ROWS.jsonl")]
    pub rows: PathBuf,
    /// The gain counted as lost.
    #[arg(long, default_value_t = 0.8, value_name = "GAMMA")]
    pub loss_gamma: f64,
    /// Alarm when the loss is predicted within this many flights.
    #[arg(long, default_value_t = 10.0, value_name = "FLIGHTS")]
    pub horizon: f64,
    /// Flights fitted, the last ones up to the flight judged (fewer at a series' start, from
    /// 4 on).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u16).range(4..=1000))]
    pub window: u16,
    /// Probability, per flight judged, that a healthy series' slope passes the alarm's test by
    /// chance (its threshold is Student's t quantile at the fit's degrees of freedom).
    #[arg(long, default_value_t = 0.001, value_name = "P")]
    pub false_alarm: f64,
    /// Also write every series with its points, trend and alarm as one JSON document (`-`:
    /// standard output, the table then on standard error).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Draw the series (SVG, or PNG for a .png name): per airframe × actuator its flights'
    /// gamma with bounds, the fitted line, the loss gain and the alarm; alarms first, at most
    /// 48 panels.
    #[arg(long, value_name = "FILE.svg|png")]
    pub plot: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct BenchmarkArgs {
    /// Truth files (TOML), one per dataset, e.g. tests/datasets/*.toml.
    #[arg(required = true, value_name = "TRUTH.toml")]
    pub truth: Vec<PathBuf>,
    /// The folder the truth files' `file` paths are under.
    #[arg(long, value_name = "DIR")]
    pub data: PathBuf,
    /// Also write the results as one JSON document (`-`: standard output, the table then on
    /// standard error).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Scenario files or built-in names (default: all built-in scenarios, the paper's figures
    /// and ten minutes of healthy flight).
    pub scenarios: Vec<String>,
    /// Print a JSON array (one object per scenario × filter) instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write one SVG per scenario (truth, estimates, bounds) into this directory.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
    /// Run each scenario with this many seeds (the scenario's seed, +1, +2, ...); with
    /// --matrix, each case this many times, numbered from one.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub seeds: u64,
    /// Instead of scenarios: the scenario matrix. Every built-in vehicle x every actuator x
    /// {loss 0.5, loss 0.75, bias +-0.15, stuck at trim, ramp to gain 0.6 over 8 s} x {steady,
    /// manoeuvres} x {built-in, rough weather} x seeds, plus healthy flights, each flown
    /// through the pipeline replay runs (calibration included) and scored against the truth
    /// and an oracle's detectability (docs/results.md says how).
    #[arg(long, conflicts_with_all = ["scenarios", "plot"])]
    pub matrix: bool,
    /// With --matrix: the fast subset (losses of 0.5 and biases of +0.15, steady flight,
    /// built-in weather).
    #[arg(long, requires = "matrix")]
    pub fast: bool,
    /// With --matrix: minutes of each healthy flight (one per vehicle, flight, weather and seed).
    #[arg(long, requires = "matrix", value_name = "MIN", default_value_t = 10.0)]
    pub healthy_minutes: f64,
    /// With --matrix: only this vehicle (repeat for several): quad-x, quad-plus, hexa-x,
    /// heli-h3-120, plane.
    #[arg(long = "vehicle", requires = "matrix", value_name = "NAME")]
    pub vehicles: Vec<String>,
    /// With --matrix: number the seeds from this one (a set beyond those the figures in
    /// docs/results.md were tuned on measures them on flights new to the rules).
    #[arg(long, requires = "matrix", value_name = "N", default_value_t = 1,
          value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub first_seed: u64,
    // --decisions / --estimates: of the first seed, one vehicle scenario only.
    #[command(flatten)]
    pub output: OutputArgs,
}

#[derive(clap::Args)]
pub struct ThresholdsArgs {
    /// Healthy vehicle scenarios (default: the built-in *-healthy-gusts flights).
    pub scenarios: Vec<String>,
    /// Flights per scenario.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub seeds: u64,
    /// Print JSON instead of the table.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct SimArgs {
    /// Scenario file or built-in name (a vehicle scenario, e.g. quad-x-motor2-loe).
    #[arg(long)]
    pub scenario: String,
    /// Truth JSONL: per step, every actuator's true gamma and delta and the noise in force
    /// (`-`: standard output).
    #[arg(long, value_name = "FILE")]
    pub truth: Option<PathBuf>,
    // The JSON lines of the monitor's filters and diagnosis running on the flight.
    #[command(flatten)]
    pub output: OutputArgs,
    /// Seed (default: the scenario's).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Speak MAVLink like an autopilot on this connection (e.g. udpout:127.0.0.1:14550):
    /// HEARTBEAT, ATTITUDE, SERVO_OUTPUT_RAW, RAW_IMU, SYS_STATUS, GLOBAL_POSITION_INT and
    /// the frame parameters. Paced at --speed (default real time).
    #[arg(long, value_name = "CONN")]
    pub out: Option<String>,
    /// Write the same MAVLink stream as a .tlog (`-`: standard output).
    #[arg(long, value_name = "FILE")]
    pub tlog: Option<PathBuf>,
    /// Multiple of real time for --out (default 1); without --out the tlog is written as
    /// fast as possible.
    #[arg(long, value_name = "X", allow_negative_numbers = true)]
    pub speed: Option<f64>,
    /// MAVLink system id of the simulated vehicle.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=254))]
    pub sysid: u8,
    /// Which autopilot the stream sounds like: ardupilot (SERVO_OUTPUT_RAW, RAW_IMU and the
    /// frame parameters) or px4 (ACTUATOR_OUTPUT_STATUS and HIGHRES_IMU, no ArduPilot
    /// parameters).
    #[arg(long, value_enum, default_value_t = AutopilotArg::Ardupilot)]
    pub autopilot: AutopilotArg,
}

#[derive(clap::Args)]
pub struct MonitorArgs {
    /// udpin:HOST:PORT, tcpin:HOST:PORT, tcpout:HOST:PORT, serial:DEVICE:BAUD, or a serial
    /// device as MAVProxy's --master takes it: /dev/ttyUSB0,57600 or /dev/ttyUSB0 alone (57600
    /// baud). udp: and tcp: are udpin: and tcpout:, as in MAVProxy. Not udpout or udpbcast: the
    /// monitor sends nothing to the vehicle, so a UDP peer would never learn where to send.
    /// Several connections go into one monitor. For one stream by two paths (a port split to
    /// two radios, a forward beside its radio) a frame one link has delivered is dropped when
    /// another delivers it too. Two ports of one autopilot are no two paths: each numbers its
    /// own frames (docs/telemetry.md).
    #[arg(value_name = "CONN", required = true, num_args = 1..)]
    pub conns: Vec<String>,
    #[command(flatten)]
    pub run: RunArgs,
    /// No dashboard: decisions are printed as they happen (automatic when stdout is not a
    /// terminal or an output flag is `-`).
    #[arg(long)]
    pub headless: bool,
    /// A vehicle silent this long (s) gets a link_lost decision.
    #[arg(
        long,
        default_value_t = 2.0,
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub link_timeout: f64,
    /// Exit after this long (s) without any frame, once frames have arrived (e.g. at the
    /// end of a simulated flight).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub exit_idle: Option<f64>,
    /// Send alerts to a mission planner on this connection (usually
    /// udpout:127.0.0.1:14551 into a MAVProxy master): HEARTBEAT, STATUSTEXT per decision,
    /// NAMED_VALUE_FLOAT g_/d_<actuator> at 2 Hz and AHC_ESTIMATE.
    #[arg(long, value_name = "CONN")]
    pub alerts: Option<String>,
    /// Ask each vehicle for ATTITUDE, SERVO_OUTPUT_RAW and RAW_IMU at this rate
    /// (SET_MESSAGE_INTERVAL; reports COMMAND_ACK and the rates achieved). Off by
    /// default: without it nothing is ever sent to the vehicle.
    #[arg(long, value_name = "HZ", allow_negative_numbers = true)]
    pub request_rates: Option<f64>,
}

#[derive(clap::Args)]
pub struct DemoArgs {
    /// Print the decisions instead of showing the dashboard (automatic when stdout is not a
    /// terminal or an output flag is `-`).
    #[arg(long)]
    pub headless: bool,
    /// Another vehicle scenario instead of the built-in one (heli-demo).
    #[arg(long, value_name = "FILE|NAME")]
    pub scenario: Option<String>,
    #[command(flatten)]
    pub output: OutputArgs,
    /// Also send the alerts to a planner (see `monitor --alerts`).
    #[arg(long, value_name = "CONN")]
    pub alerts: Option<String>,
    /// Multiple of real time (e.g. 4 for a quick look).
    #[arg(
        long,
        default_value_t = 1.0,
        value_name = "X",
        allow_negative_numbers = true
    )]
    pub speed: f64,
}

#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// The log: a .tlog, an ArduPilot DataFlash .bin or a PX4 .ulg (told by content).
    pub file: PathBuf,
    /// End of the healthy stretch (vehicle time, s since boot, as in the decisions' `t`);
    /// it starts when the vehicle is airborne and settled.
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    pub until: f64,
    /// The profile file to write (`-`: standard output).
    #[arg(short = 'o', long = "output", value_name = "PROFILE.toml")]
    pub output: PathBuf,
    /// Start from this profile's geometry instead of the detected one.
    #[arg(long, value_name = "NAME|FILE")]
    pub profile: Option<String>,
    /// Calibrate this vehicle (MAVLink system id) of a log that holds several (default:
    /// the first whose stretch completes; the others are named).
    #[arg(long, value_name = "ID")]
    pub sysid: Option<u8>,
}

#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The log: a ground station's .tlog, an ArduPilot DataFlash .bin or a PX4 .ulg (told by
    /// content, not by the name).
    pub file: PathBuf,
    #[command(flatten)]
    pub run: RunArgs,
    /// Replay at this multiple of real time instead of as fast as possible.
    #[arg(
        long,
        value_name = "X",
        conflicts_with = "fast",
        allow_negative_numbers = true
    )]
    pub speed: Option<f64>,
    /// As fast as the CPU goes (the default).
    #[arg(long)]
    pub fast: bool,
    /// No dashboard (automatic when stdout is not a terminal or an output flag is `-`).
    #[arg(long)]
    pub headless: bool,
    /// Draw every actuator's gamma, delta and output at its recent command ((γ-1)ū+δ) with
    /// both filters' bounds and the decisions into this file: SVG, or PNG when its name ends
    /// in .png (`-`: SVG on standard output).
    #[arg(long, value_name = "FILE.svg|FILE.png")]
    pub plot: Option<PathBuf>,
}

/// Options shared by `replay` and `monitor`.
#[derive(clap::Args, Debug)]
pub struct RunArgs {
    /// Vehicle profile, built-in name (paper-heli, heli-h3-120, quad-plus, quad-x, hexa-x,
    /// plane) or TOML file. Default: chosen from the vehicle's HEARTBEAT and parameters.
    #[arg(long, value_name = "NAME|FILE")]
    pub profile: Option<String>,
    #[command(flatten)]
    pub output: OutputArgs,
    /// End the healthy calibration stretch at this vehicle time (s since boot, as in the
    /// decisions' `t`); default: 20 s from when the vehicle is airborne and settled (3 s
    /// after take-off).
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    pub calibrate_until: Option<f64>,
    /// Length of the healthy calibration stretch (s of flight from 3 s after take-off). A
    /// shorter one starts the monitoring sooner (a flight too short for the default never
    /// calibrates) but fits the model more loosely: under 10 s is warned about.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 20.0,
        allow_negative_numbers = true,
        conflicts_with = "calibrate_until"
    )]
    pub calibrate_s: f64,
    /// Verify MAVLink 2 signatures with the secret key in FILE (32 raw bytes, 64 hexadecimal
    /// digits, or a one-line passphrase hashed as MAVProxy's `signing setup` does): frames
    /// not signed with it, or replayed, are dropped and counted. Without it signed frames are
    /// read unchecked. A file, so that the key is never on a command line.
    #[arg(long, value_name = "FILE")]
    pub signing_key_file: Option<PathBuf>,
    /// Also write the end-of-run summary as one JSON document (`-`: standard output): the
    /// link's and each vehicle's counters, and per actuator its fault count, state and each
    /// filter's final gamma and delta with bounds.
    #[arg(long, value_name = "FILE")]
    pub summary: Option<PathBuf>,
}

/// The JSON-lines files of a run (`replay`, `monitor`, `demo`, `sim`, `eval`).
#[derive(clap::Args, Debug, Default)]
pub struct OutputArgs {
    /// Decisions JSONL (one object a line, flushed per line); `-` streams them to standard
    /// output, and the lines for a person go to standard error.
    #[arg(long, value_name = "FILE")]
    pub decisions: Option<PathBuf>,
    /// Estimates JSONL (both filters, every actuator; every step, or see --decimate); `-` for
    /// standard output.
    #[arg(long, value_name = "FILE")]
    pub estimates: Option<PathBuf>,
    /// Write every k-th step's estimates.
    #[arg(long, default_value_t = 1, value_name = "K", value_parser = clap::value_parser!(u64).range(1..))]
    pub decimate: u64,
    /// Print each decision with its reasons on a second line (the rule's words and numbers;
    /// the decisions JSON always carries them as `detail`).
    #[arg(long)]
    pub explain: bool,
}

/// `sim --autopilot`.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum AutopilotArg {
    Ardupilot,
    Px4,
}
