//! `ahcmon monitor` (live vehicles on a connection) and `ahcmon demo` (a simulated vehicle
//! flown in this process over loopback UDP to the same monitor).

use super::{
    SPEED_RANGE, TIMEOUT_RANGE_S, UsageError, check_outputs, file_input, in_range, now_us, runtime,
    warn_fault_in_calibration,
};
use crate::cli::{DemoArgs, MonitorArgs, RunArgs};
use ahcmon::link::{ConnSpec, Link};
use ahcmon::monitor::Monitor;
use ahcmon::output::summary;
use ahcmon::scenario::{self, NamedScenario};
use anyhow::Context;
use std::io::IsTerminal;

pub fn run(a: MonitorArgs) -> anyhow::Result<()> {
    let MonitorArgs {
        conns,
        run,
        link_timeout,
        exit_idle,
        alerts,
        headless,
        request_rates,
    } = a;
    monitor(
        &conns,
        &run,
        MonitorOptions {
            link_timeout,
            exit_idle,
            alerts,
            request_rates,
            headless,
        },
        None,
    )
}

pub fn demo(a: DemoArgs) -> anyhow::Result<()> {
    let DemoArgs {
        headless,
        scenario: name,
        output,
        alerts,
        speed,
    } = a;
    let named = scenario::resolve(name.as_deref().unwrap_or("heli-demo"))?;
    check_outputs(
        name.as_deref()
            .and_then(|n| file_input(n, scenario::BUILTIN))
            .as_slice(),
        &output.flags(),
    )?;
    if named.scenario.is_paper() {
        return Err(UsageError(format!(
            "{} is a paper scenario; the demo needs a vehicle scenario",
            named.name
        ))
        .into());
    }
    let speed = in_range("--speed", speed, SPEED_RANGE.0, SPEED_RANGE.1)?;
    // One clock: the autopilot's, which the monitor shows (the scenario's description counts
    // from the start of the flight).
    tracing::info!(
        "demo: {}, on the autopilot's clock as the monitor shows it: {}",
        named.name,
        ahcmon::scenario::script_on_vehicle_clock(&named.scenario)
    );
    warn_fault_in_calibration("demo", &named);
    let args = RunArgs {
        profile: None,
        output,
        calibrate_until: None,
        calibrate_s: ahcmon::pipeline::PipelineConfig::default().calibrate_s,
        signing_key_file: None,
        summary: None,
    };
    // Headless, the monitor stops once the simulated flight has ended; with the
    // dashboard the operator looks on until q.
    let dashboard =
        !headless && std::io::stdout().is_terminal() && !ahcmon::output::file::stdout_taken();
    let idle = (!dashboard).then_some((1.5 / speed).max(0.5));
    monitor(
        &["udpin:127.0.0.1:0".to_string()],
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
    conns: &[String],
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
    let specs = conns
        .iter()
        .map(|c| c.parse::<ConnSpec>())
        .collect::<Result<Vec<_>, _>>()?;
    for (k, spec) in specs.iter().enumerate() {
        // A UDP peer sends to addresses it has heard from, and the monitor says nothing on the
        // vehicle link: from udpout or udpbcast it would wait forever.
        if let ConnSpec::UdpOut(a) | ConnSpec::UdpBcast(a) = spec {
            let port = a.port();
            return Err(UsageError(format!(
                "monitor {spec}: the monitor sends nothing to the vehicle, so a UDP peer would never learn where to send; have the autopilot or router send to this machine and listen with udpin:0.0.0.0:{port} (MAVProxy: --out=udp:THIS_HOST:{port})"
            ))
            .into());
        }
        if specs[..k].contains(spec) {
            return Err(UsageError(format!("monitor: {spec} is given twice")).into());
        }
    }
    // The dashboard unless asked not to, or when stdout is not a terminal (CI, pipes).
    let dashboard =
        !headless && std::io::stdout().is_terminal() && !ahcmon::output::file::stdout_taken();
    let alerts: Option<ConnSpec> = alerts.map(str::parse).transpose()?;
    let mut opts = super::live::LiveOptions {
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
    // Live, a calibration's fit must not hold back the other vehicles' frames.
    let mut monitor = Monitor::new(ahcmon::pipeline::PipelineConfig {
        fit_in_background: true,
        ..args.pipeline_config()?
    });
    let signing = args.signing()?;
    let mut files = args.files(&[], &[])?;
    if alerts.is_some() {
        files.alerts = Some(ahcmon::output::alerts::Alerts::default());
    }
    let rt = runtime()?;
    let result = rt.block_on(async {
        let mut links = Vec::with_capacity(specs.len());
        for spec in &specs {
            let mut link = Link::open(spec.clone()).await?;
            if let Some(s) = &signing {
                link.set_signing(s.clone());
            }
            let verb = match spec {
                ConnSpec::UdpIn(_) | ConnSpec::TcpIn(_) => "listening on",
                ConnSpec::UdpOut(_) | ConnSpec::UdpBcast(_) => "sending to",
                ConnSpec::TcpOut(_) => "connected to",
                ConnSpec::Serial(..) => "reading",
            };
            match link.not_connected() {
                Some(why) => tracing::warn!("monitor: {spec}: {why}; retrying every second"),
                None => tracing::info!(
                    "monitor: {verb} {spec}{}",
                    link.local_addr()
                        .map_or(String::new(), |a| format!(" (local {a})"))
                ),
            }
            links.push(link);
        }
        // The first link's address: the demo's vehicle sends to it.
        let local = links.first().and_then(Link::local_addr);
        let alert_link = match &alerts {
            Some(a) => {
                tracing::info!("monitor: alerts to {a} (sysid of the vehicle, component 191)");
                Some(Link::open(a.clone()).await?)
            }
            None => None,
        };
        let script = demo
            .as_ref()
            .map(|d| ahcmon::scenario::script_on_vehicle_clock(&d.named.scenario));
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
                    let opts = super::fly::FlyOptions {
                        sysid: 1,
                        seed: d.named.scenario.seed,
                        flavour: Default::default(),
                        speed: Some(d.speed),
                        epoch_us: now_us(),
                    };
                    let flown = super::fly::fly(&d.named, &opts, Some(&mut out), None, None).await;
                    // A flight that failed is no planned end: its silence is a lost link.
                    if flown.is_ok() {
                        over.store(true, std::sync::atomic::Ordering::Relaxed);
                    }
                    flown
                }))
            }
            _ => None,
        };
        // Declared before the dashboard: dropped after it, once the terminal is restored.
        let held = dashboard.then(super::log::hold);
        let mut ui = if dashboard {
            files.echo = false;
            // The addresses actually bound (the demo's udpin:127.0.0.1:0 showed port 0).
            let shown: Vec<String> = specs
                .iter()
                .zip(&links)
                .map(|(spec, link)| match (spec, link.local_addr()) {
                    (ConnSpec::UdpIn(_), Some(a)) => format!("udpin:{a}"),
                    (ConnSpec::TcpIn(_), Some(a)) => format!("tcpin:{a}"),
                    _ => spec.to_string(),
                })
                .collect();
            let shown = shown.join(" + ");
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
        let counters = super::live::run(
            links,
            &mut monitor,
            &mut files,
            alert_link,
            ui.as_mut(),
            opts,
        )
        .await;
        // Restore the terminal before anything is printed, then say what was held.
        drop(ui);
        drop(held);
        let counters = counters?;
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
    if result.is_ok() {
        files.finish();
    }
    // A write error is reported whatever else happened, after the summary when there is one.
    let write_error = files
        .error
        .take()
        .map(|e| anyhow::Error::new(e).context("writing JSON lines"));
    let counters = match result {
        Ok(c) => c,
        Err(e) => {
            if let Some(w) = &write_error {
                tracing::error!("ahcmon: error: {w:#}");
            }
            return Err(e);
        }
    };
    out!("{}", summary::render(&monitor, &counters.link, &files.seen));
    // Several links: each one's counters (`link` adds them up, copies included) and what the
    // merge dropped.
    let links = (counters.per_link.len() > 1).then(|| {
        let each: Vec<serde_json::Value> = specs
            .iter()
            .zip(&counters.per_link)
            .map(|(spec, c)| serde_json::json!({"conn": spec.to_string(), "counters": c}))
            .collect();
        serde_json::json!({
            "each": each,
            "copies": counters.copies,
            "late": counters.late,
            "merge_evicted": counters.merge_evicted,
            "failed": counters.failed_links,
        })
    });
    let summary_written = args.write_summary_with(&monitor, &counters.link, &files.seen, links);
    if counters.per_link.len() > 1 {
        for (spec, c) in specs.iter().zip(&counters.per_link) {
            outln!("  {spec}: {c}");
        }
        outln!(
            "{} frames dropped as copies of another link's, {} as late (behind a newer frame of their sender that another link delivered: the filters step forward in time)",
            counters.copies,
            counters.late
        );
        if counters.merge_evicted > 0 {
            outln!(
                "{} remembered frames forgotten before their 0.5 s (over the merge's cap): their copies may have passed",
                counters.merge_evicted
            );
        }
    }
    for failed in &counters.failed_links {
        outln!("link failed, the others went on: {failed}");
    }
    if counters.backpressure_drops > 0 {
        outln!(
            "{} frames dropped: the estimators fell behind",
            counters.backpressure_drops
        );
    }
    if counters.processed.count() > 0 {
        outln!(
            "latency from a frame's receive to its estimates and decisions written: {}",
            counters.processed.describe("frames")
        );
    }
    if counters.decided.count() > 0 {
        outln!(
            "latency from receive to a decision written: {}",
            counters.decided.describe("frames that decided")
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
    write_error.map_or(Ok(()), Err)?;
    summary_written
}
