//! `ahcmon calibrate`: a vehicle's model identified from a healthy stretch of a log (a tlog,
//! a DataFlash or a ULog log), written as a profile.

use super::{InputFileError, UsageError, check_outputs, file_input, positive};
use crate::cli::{CalibrateArgs, RunArgs};
use ahcmon::link::{LogError, LogItem, read_log};
use ahcmon::monitor::Monitor;
use ahcmon::output::jsonl::Outputs;
use anyhow::Context;

pub fn run(a: CalibrateArgs) -> anyhow::Result<()> {
    let CalibrateArgs {
        file,
        until,
        output,
        profile,
        sysid,
    } = a;
    calibrate(&file, until, &output, profile.as_deref(), sysid)
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
    let args = RunArgs {
        profile: profile.map(str::to_string),
        output: Default::default(),
        calibrate_until: Some(until),
        calibrate_s: ahcmon::pipeline::PipelineConfig::default().calibrate_s,
        signing_key_file: None,
        summary: None,
    };
    let mut monitor = Monitor::new(args.pipeline_config()?);
    // Echoed: the pipeline's progress and warnings (a short stretch, a poor fit, a profile of
    // another kind, outputs without PWM) concern the profile written. Its vehicle makes no
    // decision before its calibration, where this stops; with several vehicles, another one
    // may have (--sysid runs only the one).
    let mut files = Outputs::new(None, None, 1)?;
    let mut found = None;
    // Systems whose attitude the log holds: the vehicles a --sysid could name.
    let mut vehicles = std::collections::BTreeSet::new();
    // Any format, told by content; a vehicle's own log is one vehicle, sysid 1. Once a
    // stretch is fitted the rest is only read (a tlog's other vehicles are named below).
    let read = read_log(
        file,
        &mut |item| {
            let sysid = match item {
                LogItem::Frame(frame) => {
                    if matches!(frame.msg, ahcmon::protocol::MavMessage::ATTITUDE(_)) {
                        vehicles.insert(frame.sysid);
                    }
                    frame.sysid
                }
                LogItem::Record(_) => {
                    vehicles.insert(1);
                    1
                }
            };
            // Another vehicle's frames would run its whole pipeline, decisions and all.
            if found.is_some() || only.is_some_and(|s| s != sysid) {
                return;
            }
            match item {
                LogItem::Frame(frame) => monitor.on_frame(frame, &mut files),
                LogItem::Record(r) => monitor.on_record(1, r, &mut files),
            }
            if let Some((sysid, p)) = monitor.pipelines.iter().find(|(id, p)| {
                only.is_none_or(|s| s == **id) && (p.fit.is_some() || p.arx.is_some())
            }) {
                found = Some((*sysid, p.profile().cloned(), p.fit.clone(), p.arx.clone()));
            }
        },
        &mut |_| {},
    );
    match read {
        Ok((_, report)) => {
            for note in &report.notes {
                tracing::warn!("log: {note}");
            }
        }
        // Past the stretch the log was only read on to name its other vehicles.
        Err(e) if found.is_some() => {
            tracing::warn!(
                "warning: {}: {e}, after the calibration stretch",
                file.display()
            );
        }
        Err(LogError::Io(source)) => return Err(input_error(source).into()),
        Err(e) => return Err(UsageError(format!("{}: {e}", file.display())).into()),
    }
    if let Some((chosen, ..)) = &found
        && only.is_none()
    {
        let others: Vec<String> = vehicles
            .iter()
            .filter(|id| *id != chosen)
            .map(|id| id.to_string())
            .collect();
        if !others.is_empty() {
            tracing::warn!(
                "warning: the log also holds sysid {}: calibrating sysid {chosen}, the first to complete its stretch (--sysid chooses)",
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
    ahcmon::output::file::write_whole(
        output,
        format!("# written by `ahcmon calibrate`\n{text}").as_bytes(),
    )
    .with_context(|| format!("cannot write {}", output.display()))?;
    outln!("{}", calibrated.description);
    outln!("profile written to {}", output.display());
    Ok(())
}
