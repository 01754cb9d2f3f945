//! The commands, one file each; they wire sources, the pipeline and sinks. Shared here: how
//! results reach stdout, the checks on outputs before anything is created, and the errors
//! that are the user's input (exit code 2) rather than ours (exit code 1).

use crate::cli::{OutputArgs, RunArgs};
use ahcmon::eval::EvalError;
use ahcmon::link::ConnError;
use ahcmon::output::jsonl::Outputs;
use ahcmon::pipeline::PipelineConfig;
use ahcmon::scenario::{NamedScenario, ScenarioError};
use ahcmon::telemetry::{Profile, ProfileError};
use anyhow::Context;
use std::path::{Path, PathBuf};

/// `print!` that ends the program quietly when stdout is closed (`ahcmon eval | head`)
/// instead of panicking; other write errors are reported on stderr once and output stops.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let text = format!($($arg)*);
        let mut out = ahcmon::output::file::for_people();
        if let Err(e) = out.write_all(ahcmon::output::printable(&text).as_bytes()) {
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

pub mod benchmark;
pub mod calibrate;
pub mod eval;
mod fly;
pub mod history;
mod latency;
mod live;
pub mod log;
mod matrix;
pub mod monitor;
mod rates;
pub mod replay;
pub mod scan;
pub mod shell;
pub mod sim;
pub mod thresholds;

impl RunArgs {
    pub fn pipeline_config(&self) -> anyhow::Result<PipelineConfig> {
        let profile = self.profile.as_deref().map(Profile::resolve).transpose()?;
        if let Some(t) = self.calibrate_until
            && !(t.is_finite() && t > 0.0)
        {
            return Err(UsageError(format!(
                "--calibrate-until {t}: must be a positive time in s"
            ))
            .into());
        }
        if !(self.calibrate_s.is_finite() && (1.0..=3600.0).contains(&self.calibrate_s)) {
            return Err(UsageError(format!(
                "--calibrate-s {}: must be between 1 and 3600 s",
                self.calibrate_s
            ))
            .into());
        }
        Ok(PipelineConfig {
            profile,
            calibrate_until: self.calibrate_until,
            calibrate_s: self.calibrate_s,
            ..PipelineConfig::default()
        })
    }

    /// The signature check `--signing-key-file` asks for.
    pub fn signing(&self) -> anyhow::Result<Option<ahcmon::protocol::signing::Signing>> {
        let Some(path) = &self.signing_key_file else {
            return Ok(None);
        };
        // A key file is 32 bytes, or 64 hex digits with a line end.
        let bytes =
            ahcmon::toml_file::read_at_most(path, 1024, "a key file").map_err(|source| {
                InputFileError {
                    path: path.display().to_string(),
                    source,
                }
            })?;
        let key = ahcmon::protocol::signing::Signing::key_from_file_contents(&bytes)
            .map_err(|e| UsageError(format!("--signing-key-file {}: {e}", path.display())))?;
        Ok(Some(ahcmon::protocol::signing::Signing::new(key)))
    }

    /// The JSON-lines files, created only once no output names an input or another output.
    pub fn files(
        &self,
        inputs: &[&Path],
        more: &[(&str, Option<&Path>)],
    ) -> anyhow::Result<Outputs> {
        let mut inputs = inputs.to_vec();
        inputs.extend(
            self.profile
                .as_deref()
                .and_then(|p| file_input(p, ahcmon::telemetry::profile::BUILTIN)),
        );
        let mut more = more.to_vec();
        more.push(("--summary", self.summary.as_deref()));
        if let Some(p) = &self.summary {
            // Fail now rather than after a long run; the file is replaced only at the end.
            ahcmon::output::file::OutputFile::open(p)
                .with_context(|| format!("cannot write {}", p.display()))?;
        }
        self.output.create(&inputs, &more)
    }

    /// `--summary`: the end-of-run summary as JSON.
    pub fn write_summary(
        &self,
        monitor: &ahcmon::monitor::Monitor,
        frames: &ahcmon::protocol::FrameCounters,
        decisions: &[ahcmon::diagnose::vehicle::Decision],
    ) -> anyhow::Result<()> {
        self.write_summary_with(monitor, frames, decisions, None)
    }

    /// The summary, with `links` (several links' own counters and their merge) beside `link`.
    pub fn write_summary_with(
        &self,
        monitor: &ahcmon::monitor::Monitor,
        frames: &ahcmon::protocol::FrameCounters,
        decisions: &[ahcmon::diagnose::vehicle::Decision],
        links: Option<serde_json::Value>,
    ) -> anyhow::Result<()> {
        let Some(p) = &self.summary else {
            return Ok(());
        };
        let mut doc = ahcmon::output::summary_json::summary_json(monitor, frames, decisions);
        if let Some(links) = links {
            doc["links"] = links;
        }
        let text = serde_json::to_string_pretty(&doc)? + "\n";
        ahcmon::output::file::write_whole(p, text.as_bytes())
            .with_context(|| format!("cannot write {}", p.display()))
    }
}

impl OutputArgs {
    /// The flags and the files they name, for [`check_outputs`].
    pub fn flags(&self) -> [(&'static str, Option<&Path>); 2] {
        [
            ("--decisions", self.decisions.as_deref()),
            ("--estimates", self.estimates.as_deref()),
        ]
    }

    pub fn any(&self) -> bool {
        self.decisions.is_some() || self.estimates.is_some()
    }

    /// The files, created only once no output (these and `more`) names one of `inputs` or
    /// another output.
    pub fn create(
        &self,
        inputs: &[&Path],
        more: &[(&str, Option<&Path>)],
    ) -> anyhow::Result<Outputs> {
        let mut outputs = self.flags().to_vec();
        outputs.extend_from_slice(more);
        check_outputs(inputs, &outputs)?;
        let mut outputs = Outputs::new(
            self.decisions.as_deref(),
            self.estimates.as_deref(),
            self.decimate,
        )
        .context("cannot create output file")?;
        outputs.explain = self.explain;
        Ok(outputs)
    }
}

/// The file a scenario or profile argument reads, unless the name is a built-in one (which
/// takes priority over a file of the same name).
pub(crate) fn file_input<'a>(name: &'a str, builtin: &[(&str, &str)]) -> Option<&'a Path> {
    (!builtin.iter().any(|(stem, _)| *stem == name)).then(|| Path::new(name))
}

/// Whether two paths name the same regular file: two existing ones by device and inode (hard
/// links too), a new one by its directory's canonical path and its name. Devices
/// (`/dev/null`) never clash.
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
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
pub(crate) fn check_outputs(
    inputs: &[&Path],
    outputs: &[(&str, Option<&Path>)],
) -> Result<(), UsageError> {
    // `-` is standard output, no file (`claim_stdout` allows one).
    let outputs: Vec<(&str, &Path)> = outputs
        .iter()
        .filter_map(|(flag, p)| p.map(|p| (*flag, p)))
        .filter(|(_, p)| !ahcmon::output::file::is_stdout(p))
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

/// Output flags given as `-`: at most one may take standard output, and the text for a person
/// then goes to standard error.
pub(crate) fn claim_stdout(flags: &[&str]) -> Result<(), UsageError> {
    match flags {
        [] => Ok(()),
        // The report itself is what standard output carries.
        [only] if *only == crate::cli::PRINTED_JSON => Ok(()),
        [_] => {
            ahcmon::output::file::take_stdout();
            Ok(())
        }
        [first, rest @ ..] => Err(UsageError(format!(
            "{first} and {} {} name standard output (-): only one output can go there",
            rest.join(" and "),
            if rest.len() == 1 { "both" } else { "all" }
        ))),
    }
}

/// Errors that are the user's input (exit code 2) rather than ours (exit code 1).
pub(crate) fn is_input_error(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.is::<ScenarioError>()
            || c.is::<UsageError>()
            || c.is::<EvalError>()
            || c.is::<ProfileError>()
            || c.is::<InputFileError>()
            || matches!(c.downcast_ref::<ConnError>(), Some(ConnError::Syntax(..)))
    })
}

pub(crate) fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

pub(crate) fn positive(name: &str, v: f64) -> anyhow::Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(UsageError(format!("{name} {v:?}: must be a positive number")).into())
    }
}

/// A speed-up factor or a duration (s) that becomes a `Duration` or divides one: bounded, so
/// that no conversion overflows (`--speed 1e-300` would ask to wait 10^300 s).
pub(crate) fn in_range(name: &str, v: f64, lo: f64, hi: f64) -> anyhow::Result<f64> {
    if v.is_finite() && (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(UsageError(format!("{name} {v:?}: must be between {lo} and {hi}")).into())
    }
}

/// Bounds of `--speed` (multiple of real time) and of the monitor's timeouts (s).
pub(crate) const SPEED_RANGE: (f64, f64) = (1e-3, 1e6);

pub(crate) const TIMEOUT_RANGE_S: (f64, f64) = (1e-3, 1e6);

/// A monitor with default settings takes the first settle + calibration seconds of the
/// flight as healthy: a scenario's fault in them becomes the vehicle's normal. Said by `sim`
/// and `demo` (`demo --scenario quad-x-motor2-loe` decided only a wrong motor, silently).
pub(crate) fn warn_fault_in_calibration(who: &str, named: &NamedScenario) {
    let defaults = PipelineConfig::default();
    let learned_until = defaults.settle_s + defaults.calibrate_s;
    if let Some(f) = named.scenario.first_fault()
        && f.t < learned_until
    {
        tracing::warn!(
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

pub(crate) fn now_us() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// An input file that cannot be read (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{path}: {source}")]
pub(crate) struct InputFileError {
    pub path: String,
    pub source: std::io::Error,
}

/// A mistake in how the command line combines things (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub(crate) struct UsageError(pub String);

/// A progress bar on stderr with the time left (`indicatif`): only on a terminal, and not
/// with `-q`. `total` counts what the work goes through (a log's bytes, flights, cases).
pub(crate) struct Progress {
    bar: indicatif::ProgressBar,
}

impl Progress {
    /// `wanted`: the caller shows no other progress (a dashboard).
    pub(crate) fn new(wanted: bool, what: &str, total: u64) -> Self {
        use std::io::IsTerminal;
        // (Not when an output took stdout: the lines for a person are on stderr then.)
        let on = wanted
            && std::io::stderr().is_terminal()
            && log::progress_enabled()
            && !ahcmon::output::file::stdout_taken();
        let bar = if on {
            indicatif::ProgressBar::new(total)
        } else {
            indicatif::ProgressBar::hidden()
        };
        let style = indicatif::ProgressStyle::with_template(
            "{prefix}: {percent:>3}% [{bar:30}] {elapsed} elapsed, about {eta} left  {msg}",
        )
        .map(|s| s.progress_chars("#>-"));
        if let Ok(style) = style {
            bar.set_style(style);
        }
        bar.set_prefix(what.to_string());
        Self { bar }
    }

    /// Where the work is, of `total`.
    pub(crate) fn set(&self, done: u64) {
        self.bar.set_position(done);
    }

    /// One more of `total` done, and what is under way.
    pub(crate) fn step(&self, now: &str) {
        self.bar.inc(1);
        self.bar.set_message(now.to_string());
    }

    /// What is under way.
    pub(crate) fn message(&self, now: &str) {
        self.bar.set_message(now.to_string());
    }

    /// Wipe the line, before results or other lines are written.
    pub(crate) fn clear(&self) {
        self.bar.finish_and_clear();
    }
}

/// A frame from system 3's autopilot, for the commands' tests.
#[cfg(test)]
fn test_frame(msg: ahcmon::protocol::MavMessage) -> ahcmon::protocol::Frame {
    ahcmon::protocol::Frame {
        version: mavlink_core::MavlinkVersion::V2,
        sysid: 3,
        compid: 1,
        seq: 0,
        msg_id: mavlink_core::Message::message_id(&msg),
        msg,
    }
}
