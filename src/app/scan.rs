//! `ahcmon scan`: many logs at once on a pool of threads, one log per task. Each log has its
//! own monitor, alive only while the log is read, so memory stays flat per log. The rows
//! (`output::flights`) are written as JSON lines in the order the logs were named, a
//! directory's in name order. A log that cannot be read is named with its reason; the
//! others go on.

use super::{Progress, UsageError, check_outputs};
use crate::cli::ScanArgs;
use ahcmon::link::{LogFormat, LogItem, TlogReader, read_log, sniff};
use ahcmon::monitor::Monitor;
use ahcmon::output::flights::{FlightSink, LogInfo, rows};
use anyhow::Context;
use rayon::prelude::*;
use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Extensions a directory is searched for (in any case); named files may have any name.
const LOG_EXTENSIONS: [&str; 3] = ["tlog", "bin", "ulg"];

pub fn run(a: ScanArgs) -> anyhow::Result<()> {
    let ScanArgs {
        paths,
        rows: out,
        jobs,
        profile,
    } = a;
    let config = ahcmon::pipeline::PipelineConfig {
        profile: profile
            .as_deref()
            .map(ahcmon::telemetry::Profile::resolve)
            .transpose()?,
        ..ahcmon::pipeline::PipelineConfig::default()
    };
    let inputs: Vec<&Path> = paths.iter().map(PathBuf::as_path).collect();
    check_outputs(&inputs, &[("--rows", Some(&out))])?;
    let (logs, missing) = expand(&paths)?;
    if logs.is_empty() && missing.is_empty() {
        return Err(UsageError(format!(
            "no log in {} (directories are searched for .{})",
            paths
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
            LOG_EXTENSIONS.join(", .")
        ))
        .into());
    }
    // Open (not empty) the output before the long work, so a path that cannot be written
    // fails at once.
    let mut file = std::io::BufWriter::new(
        ahcmon::output::file::OutputFile::open(&out)
            .with_context(|| format!("cannot write {}", out.display()))?,
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(jobs.map_or(0, usize::from))
        .stack_size(8 << 20)
        .build()
        .context("cannot start the worker threads")?;
    let started = std::time::Instant::now();
    let progress = Progress::new(true, "scan", logs.len() as u64);
    let results: Vec<Result<Vec<Value>, String>> = pool.install(|| {
        logs.par_iter()
            .map(|path| {
                let r = scan_log(path, &config);
                progress.step(&path.display().to_string());
                r
            })
            .collect()
    });
    progress.clear();
    let named = logs.len() + missing.len();
    let mut failed: Vec<(String, String)> = missing
        .into_iter()
        .map(|p| {
            (
                p.display().to_string(),
                "no such file or directory".to_string(),
            )
        })
        .collect();
    let (mut written, mut flightless) = (0usize, 0usize);
    for (path, result) in logs.iter().zip(results) {
        match result {
            Ok(rows) => {
                flightless += usize::from(rows.is_empty());
                for row in rows {
                    serde_json::to_writer(&mut file, &row)?;
                    file.write_all(b"\n")?;
                    written += 1;
                }
            }
            Err(why) => failed.push((path.display().to_string(), why)),
        }
    }
    file.flush()
        .with_context(|| format!("cannot write {}", out.display()))?;
    for (path, why) in &failed {
        tracing::warn!("scan: {path}: {why}");
    }
    outln!(
        "scanned {} logs in {:.1} s on {} threads: {written} rows; {flightless} logs without a vehicle's samples; {} could not be read",
        logs.len(),
        started.elapsed().as_secs_f64(),
        pool.current_num_threads(),
        failed.len()
    );
    if !failed.is_empty() {
        anyhow::bail!(
            "{} of {} logs could not be read (named above); the others' rows are written",
            failed.len(),
            named
        );
    }
    Ok(())
}

/// The logs the paths name, each once, in order (a directory's files sorted by path), and the
/// paths that name nothing.
fn expand(paths: &[PathBuf]) -> anyhow::Result<(Vec<PathBuf>, Vec<PathBuf>)> {
    let (mut logs, mut missing) = (Vec::new(), Vec::new());
    for p in paths {
        if p.is_dir() {
            walk(p, &mut logs)?;
        } else if p.exists() {
            logs.push(p.clone());
        } else if let Some(pattern) = p.to_str().filter(|s| s.contains(['*', '?', '['])) {
            let matched = glob::glob(pattern)
                .map_err(|e| UsageError(format!("{pattern}: not a glob pattern ({e})")))?;
            let mut any = false;
            for m in matched.flatten() {
                any = true;
                if m.is_dir() {
                    walk(&m, &mut logs)?;
                } else {
                    logs.push(m);
                }
            }
            if !any {
                missing.push(p.clone());
            }
        } else {
            missing.push(p.clone());
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    logs.retain(|p| seen.insert(std::fs::canonicalize(p).unwrap_or_else(|_| p.clone())));
    Ok((logs, missing))
}

/// A directory's logs, recursively, sorted by path; symbolic links to directories are not
/// followed (no cycles).
fn walk(dir: &Path, out: &mut Vec<PathBuf>) -> anyhow::Result<()> {
    let mut entries: Vec<std::fs::DirEntry> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read directory {}", dir.display()))?
        .collect::<Result<_, _>>()
        .with_context(|| format!("cannot read directory {}", dir.display()))?;
    entries.sort_by_key(std::fs::DirEntry::path);
    for e in entries {
        let kind = e.file_type()?;
        let path = e.path();
        if kind.is_dir() {
            walk(&path, out)?;
        } else if path.extension().and_then(|x| x.to_str()).is_some_and(|x| {
            LOG_EXTENSIONS
                .iter()
                .any(|known| x.eq_ignore_ascii_case(known))
        }) {
            out.push(path);
        }
    }
    Ok(())
}

/// One log through its own monitor: its rows, or why it could not be read.
fn scan_log(path: &Path, config: &ahcmon::pipeline::PipelineConfig) -> Result<Vec<Value>, String> {
    let mut monitor = Monitor::new(config.clone());
    let mut sink = FlightSink::default();
    let format = std::fs::File::open(path)
        .and_then(sniff)
        .map_err(|e| e.to_string())?;
    let mut info = LogInfo {
        file: path.display().to_string(),
        format: format.name(),
        ..LogInfo::default()
    };
    if format == LogFormat::Tlog {
        let mut reader = TlogReader::open(path).map_err(|e| e.to_string())?;
        while let Some((ts, frame)) = reader.next_frame().map_err(|e| e.to_string())? {
            info.start_unix_us.get_or_insert(ts);
            monitor.on_frame(&frame, &mut sink);
        }
        if reader.counters.frames == 0 {
            return Err("no MAVLink frame of a known message: not a telemetry log".into());
        }
        info.dropped = reader.counters.dropped();
    } else {
        let (_, report) = read_log(
            path,
            &mut |item| match item {
                LogItem::Frame(f) => monitor.on_frame(f, &mut sink),
                LogItem::Record(r) => monitor.on_record(1, r, &mut sink),
            },
            &mut |_| {},
        )
        .map_err(|e| format!("{}: {e}", format.name()))?;
        info.dropped = report.counters.dropped();
    }
    monitor.finish(&mut sink);
    Ok(rows(&monitor, &sink, &info))
}
