//! `ahcmon sim`: a vehicle scenario flown in the simulator, with the monitor's filters and
//! diagnosis on it (JSONL files), or spoken as MAVLink to a connection and/or a tlog.

use super::eval::run_with_files;
use super::{
    SPEED_RANGE, UsageError, check_outputs, file_input, in_range, now_us, runtime,
    warn_fault_in_calibration,
};
use crate::cli::{AutopilotArg, SimArgs};
use ahcmon::eval::vehicle::sim_config;
use ahcmon::link::{ConnSpec, Link, TlogWriter};
use ahcmon::output::jsonl::Outputs;
use ahcmon::scenario::{self, NamedScenario};
use anyhow::Context;
use std::path::PathBuf;

pub fn run(a: SimArgs) -> anyhow::Result<()> {
    let SimArgs {
        scenario: name,
        truth,
        output,
        seed,
        out,
        tlog,
        speed,
        sysid,
        autopilot,
    } = a;
    let named = scenario::resolve(&name)?;
    let [decisions, estimates] = output.flags();
    check_outputs(
        file_input(&name, scenario::BUILTIN).as_slice(),
        &[
            ("--truth", truth.as_deref()),
            decisions,
            estimates,
            ("--tlog", tlog.as_deref()),
        ],
    )?;
    if out.is_some() || tlog.is_some() {
        if output.any() {
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
    let mut files = Outputs::new(
        output.decisions.as_deref(),
        output.estimates.as_deref(),
        output.decimate,
    )
    .context("cannot create output file")?;
    files.explain = output.explain;
    if let Some(path) = &truth {
        files = files
            .with_truth(path, cfg.gyro_noise, cfg.az_noise)
            .context("cannot create output file")?;
    }
    run_with_files(&named, seed.unwrap_or(named.scenario.seed), files, true).map(|_| ())
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

/// The simulated vehicle as a MAVLink autopilot: to a live connection and/or a tlog.
fn sim_mavlink(named: &NamedScenario, o: SimOutput) -> anyhow::Result<()> {
    use super::fly::{FlyOptions, fly};
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
                tracing::info!("sim: {s}: {w}; frames are not sent until then");
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
    if let Some(t) = truth.as_mut() {
        t.finish().context("writing the truth")?;
    }
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
