//! `ahcmon scan`: many logs at once on a pool of threads, one log per task. Each log has its
//! own monitor, alive only while the log is read, so memory stays flat per log. The rows
//! (`output::flights`) are written as JSON lines in the order the logs were named, a
//! directory's in name order. A log that cannot be read is named with its reason; the
//! others go on.

use super::{Progress, UsageError, check_outputs};
use crate::cli::ScanArgs;
use ahcmon::output::flights::log_rows;
use anyhow::Context;
use rayon::prelude::*;
use serde_json::Value;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Extensions a directory is searched for (in any case); named files may have any name.
const LOG_EXTENSIONS: [&str; 3] = ["tlog", "bin", "ulg"];

pub fn run(a: ScanArgs) -> anyhow::Result<()> {
    let rows_out = a.rows_path().map(Path::to_path_buf);
    let ScanArgs {
        paths,
        parquet,
        jobs,
        profile,
        airframes,
        ..
    } = a;
    let airframes = airframes
        .as_deref()
        .map(ahcmon::airframes::Airframes::load)
        .transpose()?;
    let config = ahcmon::pipeline::PipelineConfig {
        profile: profile
            .as_deref()
            .map(ahcmon::telemetry::Profile::resolve)
            .transpose()?,
        ..ahcmon::pipeline::PipelineConfig::default()
    };
    let Expanded {
        logs,
        unreadable,
        nothing,
    } = expand(&paths);
    if logs.is_empty() {
        let mut why = vec![format!(
            "no log in {} (directories are searched for .{})",
            shown(&paths),
            LOG_EXTENSIONS.join(", .")
        )];
        why.extend(
            nothing
                .iter()
                .map(|p| format!("{}: no such file or directory", p.display())),
        );
        why.extend(
            unreadable
                .iter()
                .map(|(p, e)| format!("{}: {e}", p.display())),
        );
        return Err(UsageError(why.join("; ")).into());
    }
    // Against every log found, not only the paths named (a glob may match the rows file).
    let inputs: Vec<&Path> = logs.iter().map(PathBuf::as_path).collect();
    check_outputs(
        &inputs,
        &[
            ("--rows", rows_out.as_deref()),
            ("--parquet", parquet.as_deref()),
        ],
    )?;
    // Open (not empty) the outputs before the long work, so a path that cannot be written
    // fails at once.
    let open = |p: &Path| {
        ahcmon::output::file::OutputFile::open(p)
            .with_context(|| format!("cannot write {}", p.display()))
    };
    let mut file = rows_out
        .as_deref()
        .map(open)
        .transpose()?
        .map(std::io::BufWriter::new);
    let mut parquet_file = parquet.as_deref().map(open).transpose()?;
    let want_table = parquet.is_some();
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
                // A panic in one log's replay is that log's failure, not the scan's.
                let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    log_rows(path, &config, airframes.as_ref())
                }))
                .unwrap_or_else(|_| {
                    Err("internal error while replaying it (a bug: please report the log)".into())
                })
                // A row the table cannot hold (a garbled start time past i64) is this log's
                // failure, found here so that the other logs' rows are still written.
                .and_then(|rows| {
                    if want_table {
                        ahcmon::output::parquet::to_parquet(&rows)
                            .map(|_| rows)
                            .map_err(|e| format!("its rows do not fit the Parquet table: {e}"))
                    } else {
                        Ok(rows)
                    }
                });
                progress.step(&path.display().to_string());
                r
            })
            .collect()
    });
    progress.clear();
    let mut failed: Vec<(String, String)> = Vec::new();
    let mut flightless = 0usize;
    let mut all_rows: Vec<Value> = Vec::new();
    for (path, result) in logs.iter().zip(results) {
        match result {
            Ok(rows) => {
                flightless += usize::from(rows.is_empty());
                all_rows.extend(rows);
            }
            Err(why) => failed.push((path.display().to_string(), why)),
        }
    }
    let written = all_rows.len();
    if airframes.is_some() && written > 0 && all_rows.iter().all(|r| r["airframe"].is_null()) {
        tracing::warn!(
            "scan: the airframes file names none of the logs scanned (its patterns match the paths as scan names them: as given, or the directory given joined with the names under it)"
        );
    }
    // The table is made (and every row checked against its schema) before either file is
    // written, so a row that does not fit leaves both files as they were.
    let table = parquet_file
        .is_some()
        .then(|| ahcmon::output::parquet::to_parquet(&all_rows))
        .transpose()
        .context("--parquet")?;
    if let Some(file) = &mut file {
        for row in &all_rows {
            serde_json::to_writer(&mut *file, row)?;
            file.write_all(b"\n")?;
        }
    }
    // The table replaces the file atomically (`write_whole`): the handle opened at the start
    // only proved the path writable, and is closed first (a file it created and left empty
    // goes with it).
    drop(parquet_file.take());
    if let (Some(out), Some(table)) = (&parquet, &table) {
        ahcmon::output::file::write_whole(out, table)
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    failed.extend(
        unreadable
            .iter()
            .map(|(p, e)| (p.display().to_string(), e.clone())),
    );
    if let (Some(file), Some(out)) = (&mut file, &rows_out) {
        // A scan that wrote no row leaves no earlier run's rows behind.
        if written == 0 {
            file.get_mut()
                .empty()
                .with_context(|| format!("cannot write {}", out.display()))?;
        }
        file.flush()
            .with_context(|| format!("cannot write {}", out.display()))?;
    }
    for (path, why) in &failed {
        tracing::warn!("scan: {path}: {why}");
    }
    for p in &nothing {
        tracing::warn!("scan: {}: no such file or directory", p.display());
    }
    outln!(
        "scanned {} logs in {:.1} s on {} threads: {written} rows; {flightless} logs without a vehicle's samples; {} could not be read; {} paths named nothing",
        logs.len(),
        started.elapsed().as_secs_f64(),
        pool.current_num_threads(),
        failed.len(),
        nothing.len()
    );
    if !failed.is_empty() || !nothing.is_empty() {
        anyhow::bail!(
            "{} logs or directories could not be read and {} paths named nothing (said above); every other log's rows are written",
            failed.len(),
            nothing.len()
        );
    }
    Ok(())
}

fn shown(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// What the paths name: the logs, each once, in order (a directory's sorted by path); the
/// directories or glob matches that could not be read, with why; the paths that name nothing.
struct Expanded {
    logs: Vec<PathBuf>,
    unreadable: Vec<(PathBuf, String)>,
    nothing: Vec<PathBuf>,
}

fn expand(paths: &[PathBuf]) -> Expanded {
    let mut x = Expanded {
        logs: Vec::new(),
        unreadable: Vec::new(),
        nothing: Vec::new(),
    };
    for p in paths {
        if p.is_dir() {
            walk(p, &mut x);
        } else if p.exists() {
            x.logs.push(p.clone());
        } else if let Some(pattern) = p.to_str().filter(|s| s.contains(['*', '?', '['])) {
            let matched = match glob::glob(pattern) {
                Ok(m) => m,
                Err(e) => {
                    x.unreadable
                        .push((p.clone(), format!("not a glob pattern ({e})")));
                    continue;
                }
            };
            let mut any = false;
            for m in matched {
                any = true;
                match m {
                    Ok(m) if m.is_dir() => walk(&m, &mut x),
                    Ok(m) => x.logs.push(m),
                    Err(e) => x
                        .unreadable
                        .push((e.path().to_path_buf(), e.error().to_string())),
                }
            }
            if !any {
                x.nothing.push(p.clone());
            }
        } else {
            x.nothing.push(p.clone());
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    x.logs
        .retain(|p| seen.insert(std::fs::canonicalize(p).unwrap_or_else(|_| p.clone())));
    x
}

/// A directory's logs, recursively, sorted by path; symbolic links to directories are not
/// followed (no cycles). A directory that cannot be read is noted and the rest go on.
fn walk(dir: &Path, x: &mut Expanded) {
    let entries = std::fs::read_dir(dir).and_then(|d| d.collect::<Result<Vec<_>, _>>());
    let mut entries = match entries {
        Ok(e) => e,
        Err(e) => {
            x.unreadable.push((dir.to_path_buf(), e.to_string()));
            return;
        }
    };
    entries.sort_by_key(std::fs::DirEntry::path);
    for e in entries {
        let path = e.path();
        match e.file_type() {
            Ok(kind) if kind.is_dir() => walk(&path, x),
            Ok(_) => {
                if path
                    .extension()
                    .and_then(|x| x.to_str())
                    .is_some_and(|ext| {
                        LOG_EXTENSIONS
                            .iter()
                            .any(|known| ext.eq_ignore_ascii_case(known))
                    })
                {
                    x.logs.push(path);
                }
            }
            Err(e) => x.unreadable.push((path, e.to_string())),
        }
    }
}
