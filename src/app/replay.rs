//! `ahcmon replay`: a telemetry log through the pipeline, as fast as the CPU goes or paced,
//! with the dashboard or headless, and the summary at the end.

use super::{InputFileError, Progress, SPEED_RANGE, UsageError, in_range};
use crate::cli::{ReplayArgs, RunArgs};
use ahcmon::link::{LogError, LogFormat, TlogReader};
use ahcmon::monitor::Monitor;
use ahcmon::output::summary;
use anyhow::Context;
use std::io::IsTerminal;

pub fn run(a: ReplayArgs) -> anyhow::Result<()> {
    let ReplayArgs {
        file,
        run,
        speed,
        fast: _,
        headless,
        plot,
    } = a;
    // On a rayon worker, so each vehicle's two filters step on two cores.
    rayon::scope(|_| replay(&file, &run, speed, plot.as_deref(), headless))
}

/// Longest a paced replay waits for the next record; a longer wait is a hole in the log (or
/// a timestamp off by hours), skipped.
const MAX_PACE_WAIT: std::time::Duration = std::time::Duration::from_secs(2);

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
    let format = std::fs::File::open(file)
        .and_then(ahcmon::link::sniff)
        .map_err(input_error)?;
    if format != LogFormat::Tlog {
        return replay_own_log(file, format, size, args, plot);
    }
    let mut reader = TlogReader::open(file).map_err(input_error)?;
    reader.signing = args.signing()?;
    let mut monitor = Monitor::new(args.pipeline_config()?);
    let mut files = args.files(&[file], &[("--plot", plot)])?;
    if let Some(p) = plot {
        // Fail now rather than after a long replay.
        ahcmon::output::jsonl::OutputFile::open(p)
            .with_context(|| format!("cannot write {}", p.display()))?;
        files.plot = Some(ahcmon::output::plot::PlotRecorder::default());
    }
    // The dashboard at a replay speed a person can follow; --fast (the default) is headless.
    let dashboard =
        !headless && std::io::stdout().is_terminal() && !ahcmon::output::file::stdout_taken();
    // Declared before the dashboard: dropped after it, once the terminal is restored.
    let held = dashboard.then(super::log::hold);
    let mut ui = if dashboard {
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
    let progress = Progress::new(ui.is_none(), "replay", size);
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
        // The tlog's stamp is the ground station's receive time.
        monitor.on_frame_at(&frame, Some(ts as f64 * 1e-6), &mut files);
        // Every estimate into the chart: at 10 redraws a second, a replay as fast as the CPU
        // goes charted only the last second of the log.
        if let Some(ui) = ui.as_mut() {
            ui.history.live.sample(&monitor);
        }
        // Redrawn per thousandth of the log, not per record.
        if let Some(permille) = (reader.position() * 1000).checked_div(size)
            && permille != shown
        {
            shown = permille;
            progress.set(reader.position());
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
    drop(held);
    progress.clear();
    // Not a telemetry log at all: no frame of a message it knows, whose checksum held (a
    // frame of an unknown id has no checksum to check; random bytes make some). Its output
    // files stay as they were.
    let refused = reader.counters.unsigned + reader.counters.bad_signature;
    let not_a_log = reader.counters.frames == 0;
    if !not_a_log {
        files.finish();
    }
    // Reported after the plot and the summary, which do not depend on the files.
    let write_error = files
        .error
        .take()
        .map(|e| anyhow::Error::new(e).context("writing JSON lines"));
    if !not_a_log {
        write_plot(plot, &files, file)?;
    }
    out!(
        "{}",
        summary::render(&monitor, &reader.counters, &files.seen)
    );
    // Not for an input that is not a log: its outputs stay as they were.
    let summary_written = if not_a_log {
        Ok(())
    } else {
        args.write_summary(&monitor, &reader.counters, &files.seen)
    };
    outln!(
        "replayed {} in {:.2} s",
        file.display(),
        replay_time.as_secs_f64()
    );
    write_error.map_or(Ok(()), Err)?;
    summary_written?;
    // An input error, so a script can tell.
    if not_a_log && refused > 0 {
        return Err(UsageError(format!(
            "{}: none of its {refused} frames passed the signature check (not signed, or signed with another key than --signing-key-file's); the output files are left as they were",
            file.display()
        ))
        .into());
    }
    if not_a_log {
        let read = if reader.gave_up {
            format!(
                "first {} MiB",
                ahcmon::link::tlog::MAX_BYTES_BEFORE_FIRST_FRAME >> 20
            )
        } else {
            format!("{size} bytes")
        };
        return Err(UsageError(format!(
            "{}: no MAVLink frame of a known message in its {read}; is it a telemetry log (.tlog)? (the output files are left as they were)",
            file.display()
        ))
        .into());
    }
    estimation_failed(&monitor)
}

/// A vehicle's own log (DataFlash, ULog), headless: one vehicle, its records on its own
/// clock through the same monitor.
fn replay_own_log(
    file: &std::path::Path,
    format: LogFormat,
    size: u64,
    args: &RunArgs,
    plot: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    let mut monitor = Monitor::new(args.pipeline_config()?);
    if args.signing_key_file.is_some() {
        return Err(UsageError(format!(
            "--signing-key-file: {} is a {}, which is not MAVLink and has no signatures",
            file.display(),
            format.name()
        ))
        .into());
    }
    let mut files = args.files(&[file], &[("--plot", plot)])?;
    if let Some(p) = plot {
        ahcmon::output::jsonl::OutputFile::open(p)
            .with_context(|| format!("cannot write {}", p.display()))?;
        files.plot = Some(ahcmon::output::plot::PlotRecorder::default());
    }
    tracing::info!("{}: {}", file.display(), format.name());
    let progress = Progress::new(true, "replay", size);
    let started = std::time::Instant::now();
    let mut shown = 0;
    let mut emit = |r: &ahcmon::telemetry::Record| monitor.on_record(1, r, &mut files);
    let read = match format {
        LogFormat::DataFlash => {
            let input = std::fs::File::open(file).map_err(|source| InputFileError {
                path: file.display().to_string(),
                source,
            })?;
            ahcmon::link::dataflash::read(std::io::BufReader::new(input), &mut emit, &mut |at| {
                if let Some(permille) = (at * 1000).checked_div(size)
                    && permille != shown
                {
                    shown = permille;
                    progress.set(at);
                }
            })
        }
        _ => ahcmon::link::ulog::read(file, &mut emit),
    };
    progress.clear();
    let report = match read {
        Ok(r) => r,
        Err(LogError::Io(source)) => {
            return Err(InputFileError {
                path: file.display().to_string(),
                source,
            }
            .into());
        }
        Err(e) => {
            return Err(UsageError(format!("{}: {} ({e})", file.display(), format.name())).into());
        }
    };
    monitor.finish(&mut files);
    let replay_time = started.elapsed();
    files.finish();
    let write_error = files
        .error
        .take()
        .map(|e| anyhow::Error::new(e).context("writing JSON lines"));
    write_plot(plot, &files, file)?;
    out!(
        "{}",
        summary::render(&monitor, &report.counters, &files.seen)
    );
    let summary_written = args.write_summary(&monitor, &report.counters, &files.seen);
    for note in &report.notes {
        outln!("log: {note}");
    }
    if report.dropouts > 0 {
        outln!(
            "log: the on-board logger dropped data {} times ({} ms in all)",
            report.dropouts,
            report.dropout_ms
        );
    }
    outln!(
        "replayed {} ({}, {:.1} MB) in {:.2} s",
        file.display(),
        format.name(),
        report.bytes as f64 / 1e6,
        replay_time.as_secs_f64()
    );
    write_error.map_or(Ok(()), Err)?;
    summary_written?;
    estimation_failed(&monitor)
}

/// The plot of a replay, once its log is through.
fn write_plot(
    plot: Option<&std::path::Path>,
    files: &ahcmon::output::jsonl::Outputs,
    file: &std::path::Path,
) -> anyhow::Result<()> {
    if let (Some(p), Some(rec)) = (plot, files.plot.as_ref()) {
        let title = format!("ahcmon replay {}", file.display());
        let svg = rec.render(&title);
        let bytes = if ahcmon::output::png::is_png(p) {
            ahcmon::output::png::from_svg(&svg)
                .with_context(|| format!("cannot draw {}", p.display()))?
        } else {
            svg.into_bytes()
        };
        ahcmon::output::file::write_whole(p, &bytes)
            .with_context(|| format!("cannot write {}", p.display()))?;
        tracing::info!("plot written to {}", p.display());
    }
    Ok(())
}

/// An estimation that failed (said when it happened and in the summary) is no success: a
/// script must not take the log as checked. (A log with no flight in it is: the summary says
/// why nothing was estimated.)
fn estimation_failed(monitor: &Monitor) -> anyhow::Result<()> {
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
