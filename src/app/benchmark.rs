//! `ahcmon benchmark`: labelled logs (any format `replay` reads) through the monitor, their
//! fault decisions scored against the truth files (`ahcmon::eval::datasets`), one table on
//! stdout and, with `--json`, the same as one JSON document.

use super::{InputFileError, Progress, UsageError, check_outputs};
use crate::cli::BenchmarkArgs;
use ahcmon::diagnose::vehicle::Decision;
use ahcmon::eval::datasets::{
    CaseScore, DatasetTruth, Outcome, Published, Totals, score_case, totals,
};
use ahcmon::link::{LogItem, read_log};
use ahcmon::monitor::Monitor;
use ahcmon::output::Sink;
use ahcmon::pipeline::PipelineConfig;
use ahcmon::telemetry::Profile;
use anyhow::Context;
use serde::Serialize;
use std::path::Path;

#[derive(Default)]
struct Collect(Vec<Decision>);

impl Sink for Collect {
    fn decision(&mut self, d: &Decision) {
        self.0.push(d.clone());
    }
}

#[derive(Serialize)]
struct CaseRun {
    #[serde(flatten)]
    score: CaseScore,
    format: &'static str,
    bytes: u64,
    seconds: f64,
    /// Samples the pipeline was given (paired outputs and rates).
    samples: u64,
    /// Why nothing was estimated, when nothing was and no `cannot_estimate` said why.
    #[serde(skip_serializing_if = "Option::is_none")]
    not_estimated: Option<String>,
    /// A log the reader stopped on: the rest of it was not replayed.
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

#[derive(Serialize)]
struct DatasetRun {
    dataset: String,
    description: String,
    totals: Totals,
    #[serde(skip_serializing_if = "Option::is_none")]
    published: Option<Published>,
    cases: Vec<CaseRun>,
}

pub fn run(a: BenchmarkArgs) -> anyhow::Result<()> {
    // Every truth file parsed and every log found before anything is replayed or written.
    let mut sets = Vec::new();
    for path in &a.truth {
        let text = ahcmon::toml_file::read_at_most(
            path,
            ahcmon::toml_file::MAX_TOML_BYTES,
            "a truth file",
        )
        .and_then(|b| {
            String::from_utf8(b)
                .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()))
        })
        .map_err(|source| InputFileError {
            path: path.display().to_string(),
            source,
        })?;
        let truth = DatasetTruth::from_toml(&text, &path.display().to_string())
            .map_err(|e| UsageError(e.to_string()))?;
        for c in &truth.cases {
            let file = a.data.join(&c.file);
            if !file.is_file() {
                return Err(UsageError(format!(
                    "{}: case {}: no such file under --data {} ({})",
                    path.display(),
                    c.file,
                    a.data.display(),
                    file.display()
                ))
                .into());
            }
            if let Some(p) = &c.profile {
                Profile::resolve(p)
                    .with_context(|| format!("{}: case {}", path.display(), c.file))?;
            }
        }
        sets.push(truth);
    }
    // The JSON names no log or truth file (it is created before the replays, to fail early).
    let logs: Vec<std::path::PathBuf> = sets
        .iter()
        .flat_map(|t| t.cases.iter().map(|c| a.data.join(&c.file)))
        .collect();
    let inputs: Vec<&Path> = a
        .truth
        .iter()
        .map(|p| p.as_path())
        .chain(logs.iter().map(|p| p.as_path()))
        .collect();
    check_outputs(&inputs, &[("--json", a.json.as_deref())])?;
    if let Some(json) = &a.json {
        // Fail now rather than after the replays; the file is replaced only at the end.
        ahcmon::output::file::OutputFile::open(json)
            .with_context(|| format!("cannot write {}", json.display()))?;
    }
    let n: usize = sets.iter().map(|s| s.cases.len()).sum();
    let progress = Progress::new(true, "benchmark", n as u64);
    let mut done = 0;
    let mut runs = Vec::new();
    for truth in sets {
        let mut cases = Vec::new();
        for c in &truth.cases {
            done += 1;
            progress.message(&format!("[{done}/{n}] {}", c.file));
            let profile = c.profile.as_deref().map(Profile::resolve).transpose()?;
            cases.push(rayon::scope(|_| {
                replay_case(&a.data.join(&c.file), c, profile, truth.calibrate_s)
            }));
            progress.set(done as u64);
        }
        let scores: Vec<CaseScore> = cases.iter().map(|c| c.score.clone()).collect();
        runs.push(DatasetRun {
            totals: totals(&scores),
            dataset: truth.dataset,
            description: truth.description,
            published: truth.published,
            cases,
        });
    }
    progress.clear();
    out!("{}", render(&runs));
    if let Some(json) = &a.json {
        let text = serde_json::to_string_pretty(&runs)?;
        ahcmon::output::file::write_whole(json, (text + "\n").as_bytes())
            .with_context(|| format!("cannot write {}", json.display()))?;
    }
    let errors: Vec<&CaseRun> = runs
        .iter()
        .flat_map(|r| &r.cases)
        .filter(|c| c.error.is_some())
        .collect();
    if !errors.is_empty() {
        anyhow::bail!(
            "{} of {n} logs could not be read to the end (see the table)",
            errors.len()
        );
    }
    Ok(())
}

fn replay_case(
    path: &Path,
    case: &ahcmon::eval::datasets::Case,
    profile: Option<Profile>,
    calibrate_s: Option<f64>,
) -> CaseRun {
    let defaults = PipelineConfig::default();
    let mut monitor = Monitor::new(PipelineConfig {
        profile,
        calibrate_s: calibrate_s.unwrap_or(defaults.calibrate_s),
        ..defaults
    });
    let mut sink = Collect::default();
    let started = std::time::Instant::now();
    let read = read_log(
        path,
        &mut |item| match item {
            LogItem::Frame(f) => monitor.on_frame(f, &mut sink),
            LogItem::Record(r) => monitor.on_record(1, r, &mut sink),
        },
        &mut |_| {},
    );
    monitor.finish(&mut sink);
    let seconds = started.elapsed().as_secs_f64();
    let airborne_s = monitor.pipelines.values().map(|p| p.gate.airborne_s).sum();
    let samples = monitor.pipelines.values().map(|p| p.gate.samples).sum();
    let heartbeat = |sysid: &u8| {
        monitor
            .assembler
            .vehicles
            .get(sysid)
            .is_some_and(|v| v.info.mav_type.is_some())
    };
    let not_estimated = monitor
        .pipelines
        .iter()
        .find_map(|(sysid, p)| p.why_not_estimating(heartbeat(sysid)));
    let (format, bytes, error) = match read {
        Ok((format, report)) => (format.name(), report.bytes, None),
        Err(e) => (
            "?",
            std::fs::metadata(path).map_or(0, |m| m.len()),
            Some(e.to_string()),
        ),
    };
    let score = score_case(case, &sink.0, airborne_s);
    CaseRun {
        not_estimated: not_estimated.filter(|_| score.cannot_estimate.is_none()),
        score,
        format,
        bytes,
        seconds,
        samples,
        error,
    }
}

fn render(runs: &[DatasetRun]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let opt = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |v| format!("{v:.2}{unit}"));
    for r in runs {
        let _ = writeln!(s, "== {} — {}", r.dataset, r.description);
        let _ = writeln!(
            s,
            "{:<52} {:<30} {:<11} {:<28} {:>8} {:>6} {:>6} {:>7}  note",
            "case",
            "truth",
            "outcome",
            "first fault after onset",
            "delay",
            "before",
            "faults",
            "air min"
        );
        for c in &r.cases {
            let first = c
                .score
                .first_after_onset
                .as_ref()
                .map_or("-".to_string(), |f| {
                    format!(
                        "{} ch{} {}",
                        f.actuator.as_deref().unwrap_or("?"),
                        f.channel.map_or("?".to_string(), |c| c.to_string()),
                        f.class.as_deref().unwrap_or("?")
                    )
                });
            let note = c
                .error
                .as_deref()
                .map(|e| format!("read error: {e}"))
                .or_else(|| {
                    c.score
                        .cannot_estimate
                        .as_deref()
                        .map(|t| format!("cannot estimate: {t}"))
                })
                .or_else(|| {
                    c.not_estimated
                        .as_deref()
                        .map(|t| format!("no estimate: {t}"))
                })
                .unwrap_or_default();
            let _ = writeln!(
                s,
                "{:<52} {:<30} {:<11} {:<28} {:>8} {:>6} {:>6} {:>7.1}  {note}",
                short(c.score.file.rsplit('/').next().unwrap_or_default(), 52),
                head(&c.score.truth, 30),
                outcome_name(c.score.outcome),
                head(&first, 28),
                opt(
                    c.score.first_after_onset.as_ref().and_then(|f| f.delay_s),
                    " s"
                ),
                c.score.faults_before_onset,
                c.score.faults,
                c.score.airborne_s / 60.0,
            );
        }
        let t = &r.totals;
        let _ = writeln!(
            s,
            "totals: {} fault flights: {} detected, {} misdecided, {} missed (median delay {}; {} decisions before onset); \
             {} healthy flights: {} with a fault, {} decisions in {:.2} h airborne ({}/h); \
             cannot estimate {} of {}; per flight precision {} recall {}",
            t.fault_flights,
            t.detected,
            t.misdecided,
            t.missed,
            opt(t.median_delay_s, " s"),
            t.faults_before_onset,
            t.healthy_flights,
            t.false_alarm_flights,
            t.healthy_faults,
            t.healthy_airborne_h,
            opt(t.healthy_faults_per_h, ""),
            t.cannot_estimate,
            t.cases,
            opt(t.precision_pct, " %"),
            opt(t.recall_pct, " %"),
        );
        if let Some(p) = &r.published {
            let _ = writeln!(
                s,
                "published ({}; {}, as quoted): precision {} recall {} detection {}",
                p.source,
                p.method,
                opt(p.precision_pct, " %"),
                opt(p.recall_pct, " %"),
                opt(p.detection_s, " s"),
            );
        }
        let _ = writeln!(s);
    }
    s
}

fn outcome_name(o: Outcome) -> &'static str {
    match o {
        Outcome::Detected => "detected",
        Outcome::Misdecided => "misdecided",
        Outcome::Missed => "missed",
        Outcome::Clean => "clean",
        Outcome::FalseAlarm => "false alarm",
    }
}

/// The start of a long text.
fn head(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return text.to_string();
    }
    let start: String = text.chars().take(width - 1).collect();
    format!("{start}…")
}

/// The end of a long name, which is where logs differ.
fn short(text: &str, width: usize) -> String {
    let n = text.chars().count();
    if n <= width {
        return text.to_string();
    }
    let tail: String = text.chars().skip(n - (width - 1)).collect();
    format!("…{tail}")
}
