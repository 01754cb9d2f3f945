//! The live monitor loop on tokio: a reader task turns the link's bytes into frames and
//! hands them over a bounded channel to the estimating side, which never blocks the reader.
//! Link loss per vehicle becomes a `link_lost` decision, its end `link_restored`.

use super::rates::RateRequests;
use ahcmon::diagnose::vehicle::{Decision, Event};
use ahcmon::link::{ConnError, Link, Received};
use ahcmon::monitor::Monitor;
use ahcmon::output::Sink;
use ahcmon::protocol::{Frame, FrameCounters};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use tokio::sync::mpsc;

/// How long a link may stay silent from the start before the headless monitor says so.
const NO_DATA_HINT: Duration = Duration::from_secs(5);

#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// No frame from a vehicle for this long: `link_lost`.
    pub link_timeout: Duration,
    /// Stop after this long without any frame, once frames have arrived (end of a sim).
    pub exit_idle: Option<Duration>,
    /// Frames buffered between the reader and the estimators.
    pub channel_capacity: usize,
    /// `--request-rates HZ`: ask each vehicle for ATTITUDE, SERVO_OUTPUT_RAW and RAW_IMU
    /// (HIGHRES_IMU from a non-ArduPilot autopilot) at this rate (SET_MESSAGE_INTERVAL), the only thing ever sent on the vehicle link.
    pub request_rates: Option<f64>,
    /// Set when the stream has ended as planned (the demo's flight): the silence after it is
    /// not told as a lost link (the footer says END OF FLIGHT).
    pub stream_over: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl Default for LiveOptions {
    fn default() -> Self {
        Self {
            link_timeout: Duration::from_secs(2),
            exit_idle: None,
            channel_capacity: 4096,
            request_rates: None,
            stream_over: None,
        }
    }
}

/// What the readers saw, for the summary.
#[derive(Debug, Clone, Default)]
pub struct LiveCounters {
    /// Every link's counters added up.
    pub link: FrameCounters,
    /// Each link's own, in the order given.
    pub per_link: Vec<FrameCounters>,
    /// Frames dropped because the estimating side fell behind (channel full).
    pub backpressure_drops: u64,
    /// Our own alert frames (component `ALERT_COMPID`) that came back in, ignored: a forwarder
    /// such as MAVProxy sends what one link gives it to its other links.
    pub own_echo: u64,
    /// System ids heard from two senders at once, not yet made decisions.
    pub two_sources: Vec<(u8, String)>,
    /// Several links: frames another link had delivered already, frames behind a newer one
    /// another link delivered (`protocol::merge`), both dropped; remembered frames forgotten
    /// early (over the merge's cap).
    pub copies: u64,
    pub late: u64,
    pub merge_evicted: u64,
    /// Links that failed while others went on: what each said.
    pub failed_links: Vec<String>,
    /// From a frame's receive to the end of its processing (estimates, decisions written).
    pub processed: super::latency::Latency,
    /// The same, for the frames that wrote a decision.
    pub decided: super::latency::Latency,
}

impl LiveCounters {
    fn add_up(&mut self) {
        self.link = FrameCounters::default();
        for c in &self.per_link {
            self.link.add(c);
        }
    }
}

/// Run until ctrl-c, the idle timeout, or every link failed. Returns the counters. Several
/// links are merged (`protocol::merge`): a frame another link delivered already is dropped.
/// With `alerts`, the frames the sink's alert component queues are sent on that link.
pub async fn run(
    links: Vec<Link>,
    monitor: &mut Monitor,
    sink: &mut ahcmon::output::jsonl::Outputs,
    mut alerts: Option<Link>,
    mut ui: Option<&mut ahcmon::output::dashboard::TerminalUi>,
    opts: LiveOptions,
) -> Result<LiveCounters, ConnError> {
    let clock = Instant::now();
    let count = links.len();
    // The readers' drop counters, for the dashboard's footer while running and for the
    // summary if a reader does not hand back its final ones in time.
    let live_counters = std::sync::Arc::new(std::sync::Mutex::new(LiveCounters {
        per_link: vec![FrameCounters::default(); count],
        ..LiveCounters::default()
    }));
    let (tx, mut rx) = mpsc::channel::<(Frame, Instant, usize)>(opts.channel_capacity);
    // Frames for each vehicle link (only SET_MESSAGE_INTERVAL, only with --request-rates).
    let mut vehicle_txs = Vec::with_capacity(count);
    let mut done = Vec::with_capacity(count);
    let mut readers = Vec::with_capacity(count);
    let names: Vec<String> = links.iter().map(|l| l.spec.to_string()).collect();
    let alive = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(count));
    for (index, link) in links.into_iter().enumerate() {
        let (vehicle_tx, vehicle_rx) = mpsc::channel::<Vec<u8>>(16);
        let (done_tx, done_rx) = tokio::sync::oneshot::channel::<Result<(), ConnError>>();
        vehicle_txs.push(vehicle_tx);
        done.push(done_rx);
        let reader = Reader {
            link,
            index,
            alive: alive.clone(),
            tx: tx.clone(),
            vehicle_rx,
            counters: live_counters.clone(),
        };
        readers.push(tokio::spawn(async move {
            let _ = done_tx.send(reader.run().await);
        }));
    }
    // The channel ends when every reader has.
    drop(tx);
    let mut merger = ahcmon::protocol::merge::Merger::new(names);
    let mut last_seen: BTreeMap<u8, Instant> = BTreeMap::new();
    let mut lost: BTreeMap<u8, bool> = BTreeMap::new();
    let mut any_frame: Option<Instant> = None;
    let mut own_echo = 0u64;
    let mut processed = super::latency::Latency::default();
    let mut decided = super::latency::Latency::default();
    let mut silence_told = false;
    let mut rates = RateRequests::default();
    // 10 Hz: link-loss checks, alerts and the dashboard's redraw.
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let ctrl_c = tokio::signal::ctrl_c();
    tokio::pin!(ctrl_c);
    // SIGTERM and SIGHUP (the terminal closed) end the loop like ctrl-c, so the terminal is
    // restored and the summary printed. Not SIGHUP when it was ignored at the start: that is
    // `nohup`, whose monitor must outlive the terminal.
    #[cfg(unix)]
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()).ok();
    #[cfg(unix)]
    let mut hangup = if hangup_ignored() {
        None
    } else {
        tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup()).ok()
    };
    #[cfg(not(unix))]
    let (mut term, mut hangup): (Signal, Signal) = (None, None);
    loop {
        tokio::select! {
            frame = rx.recv() => {
                let Some((frame, received, index)) = frame else { break };
                // Our own alerts, echoed back in under the vehicle's system id, would keep a
                // vehicle that has gone silent "alive" (no link_lost, no --exit-idle).
                if sink.alerts.is_some() && frame.compid == ahcmon::output::alerts::ALERT_COMPID {
                    own_echo += 1;
                    continue;
                }
                if count > 1
                    && merger.accept(&frame, index, received.duration_since(clock).as_secs_f64())
                        != ahcmon::protocol::merge::Verdict::New
                {
                    continue;
                }
                let now = Instant::now();
                any_frame = Some(now);
                if frame.sysid != 255 && frame.sysid != 0 {
                    last_seen.insert(frame.sysid, now);
                    if lost.insert(frame.sysid, false) == Some(true) {
                        sink.decision(&link_event(monitor, frame.sysid, Event::LinkRestored, "frames arrive again".into()));
                    }
                }
                if let Some(hz) = opts.request_rates {
                    // Never waiting: a link stuck sending must not hold the others' frames.
                    // A request that finds its link's queue full is lost, and the report
                    // of COMMAND_ACKs shows it missing.
                    for out in rates.on_frame(&frame, monitor, hz, sink) {
                        let _ = vehicle_txs[index].try_send(out);
                    }
                }
                let decisions = sink.seen.len();
                monitor.on_frame_at(&frame, Some(now.duration_since(clock).as_secs_f64()), sink);
                let latency = received.elapsed();
                processed.record(latency);
                if sink.seen.len() > decisions {
                    decided.record(latency);
                }
                // The alerts speak as a vehicle's system id from when the vehicle is known.
                if let Some(a) = sink.alerts.as_mut()
                    && monitor.assembler.vehicles.contains_key(&frame.sysid)
                {
                    a.see(frame.sysid);
                }
                send_alerts(sink, alerts.as_mut(), clock).await;
            }
            _ = tick.tick() => {
                monitor.settle_finished_fits(sink);
                send_alerts(sink, alerts.as_mut(), clock).await;
                let now = Instant::now();
                let over = opts
                    .stream_over
                    .as_ref()
                    .is_some_and(|o| o.load(std::sync::atomic::Ordering::Relaxed));
                let mut mixed = live_counters
                    .lock()
                    .map(|mut c| std::mem::take(&mut c.two_sources))
                    .unwrap_or_default();
                for (sysid, detail) in merger.take_two_sources() {
                    tracing::warn!("monitor: {detail}");
                    mixed.push((sysid, detail));
                }
                for (sysid, detail) in mixed {
                    if monitor.mark_mixed(sysid) {
                        sink.decision(&link_event(monitor, sysid, Event::Contaminated, detail));
                    }
                }
                for (sysid, seen) in &last_seen {
                    // Only vehicles that sent a sample: a stray system id's heartbeat (one
                    // from each of 252 made 252 link_lost decisions) is no vehicle to lose.
                    if monitor
                        .assembler
                        .vehicles
                        .get(sysid)
                        .is_none_or(|v| v.counters.samples == 0)
                    {
                        continue;
                    }
                    let gone = now.duration_since(*seen) > opts.link_timeout;
                    if gone && !over && lost.get(sysid) != Some(&true) {
                        lost.insert(*sysid, true);
                        // Shortest form that shows the value (0.03 s, 2 s, 2.5 s).
                        let detail = format!("no frame for {} s", opts.link_timeout.as_secs_f64());
                        sink.decision(&link_event(monitor, *sysid, Event::LinkLost, detail));
                    }
                }
                // Headless, say once that nothing arrives (the dashboard's footer says it).
                if any_frame.is_none()
                    && ui.is_none()
                    && !silence_told
                    && clock.elapsed() > NO_DATA_HINT
                {
                    silence_told = true;
                    // Only decoded frames reach here: bytes that never make a frame (a wrong
                    // baud rate) look the same, and the summary counts them.
                    tracing::warn!(
                        "monitor: no MAVLink frame in {} s; check that the vehicle or ground station sends to this address (e.g. MAVProxy --out udp:HOST:PORT for udpin:0.0.0.0:PORT), and a serial link's baud rate",
                        NO_DATA_HINT.as_secs()
                    );
                }
                if let (Some(idle), Some(last)) = (opts.exit_idle, any_frame)
                    && now.duration_since(last) > idle
                {
                    break;
                }
                if let Some(ui) = ui.as_deref_mut() {
                    if let ahcmon::output::dashboard::KeyAction::Quit = ui.keys(monitor) {
                        break;
                    }
                    let counters = live_counters
                        .lock()
                        .map(|mut c| {
                            c.add_up();
                            c.link
                        })
                        .unwrap_or_default();
                    let age = any_frame.map(|t| now.duration_since(t).as_secs_f64());
                    // (Vehicles only: not a second ground station or a gimbal's own system.)
                    let vehicles: ahcmon::output::dashboard::VehicleLinks = last_seen
                        .iter()
                        .filter(|(s, _)| monitor.assembler.vehicles.contains_key(s))
                        .map(|(s, seen)| {
                            let age = now.duration_since(*seen).as_secs_f64();
                            (*s, (age, lost.get(s) == Some(&true)))
                        })
                        .collect();
                    let _ = ui.draw(monitor, &sink.seen, counters, age, &vehicles);
                }
            }
            _ = &mut ctrl_c => break,
            Some(()) = next_signal(&mut term) => break,
            Some(()) = next_signal(&mut hangup) => break,
        }
    }
    // Closing the channel ends the readers, which hand back their counters.
    drop(rx);
    monitor.finish(sink);
    let mut errors = Vec::new();
    let deadline = tokio::time::Instant::now() + Duration::from_secs(1);
    for d in done {
        // A reader stuck (e.g. a tcpin send waiting for a client) keeps its counters as of
        // its last frame.
        if let Ok(Ok(Err(e))) = tokio::time::timeout_at(deadline, d).await {
            errors.push(e);
        }
    }
    for r in readers {
        r.abort();
    }
    // Every link failed: the monitor failed.
    if errors.len() == count
        && let Some(e) = errors.into_iter().next()
    {
        return Err(e);
    }
    let mut c = live_counters.lock().map(|c| c.clone()).unwrap_or_default();
    c.add_up();
    c.own_echo = own_echo;
    c.copies = merger.copies_total();
    c.late = merger.late;
    c.merge_evicted = merger.evicted;
    c.processed = processed;
    c.decided = decided;
    Ok(c)
}

/// One link's reader: frames into the shared channel (never blocking: a full channel drops,
/// counted), the vehicle's outgoing frames onto the link.
struct Reader {
    link: Link,
    index: usize,
    /// Links whose readers still run: while one does, this one failing is said and the
    /// monitor goes on.
    alive: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    tx: mpsc::Sender<(Frame, Instant, usize)>,
    vehicle_rx: mpsc::Receiver<Vec<u8>>,
    counters: std::sync::Arc<std::sync::Mutex<LiveCounters>>,
}

impl Reader {
    async fn run(mut self) -> Result<(), ConnError> {
        let spec = self.link.spec.to_string();
        let result = loop {
            tokio::select! {
                Some(out) = self.vehicle_rx.recv() => {
                    if let Err(e) = self.link.send(&out).await {
                        break Err(e);
                    }
                }
                r = self.link.recv_or_note() => match r {
                    // (Under the dashboard, held until the terminal is restored.)
                    Ok(Received::Note(note)) => tracing::info!("monitor: {spec}: {note}"),
                    Ok(Received::TwoSources { sysid, detail }) => {
                        tracing::warn!("monitor: {spec}: {detail}");
                        if let Ok(mut c) = self.counters.lock() {
                            c.two_sources.push((sysid, detail));
                        }
                    }
                    Ok(Received::Frame(frame)) => {
                        let full = matches!(
                            self.tx.try_send((frame, Instant::now(), self.index)),
                            Err(mpsc::error::TrySendError::Full(_))
                        );
                        if let Ok(mut c) = self.counters.lock() {
                            c.per_link[self.index] = self.link.counters();
                            c.backpressure_drops += u64::from(full);
                        }
                    }
                    Err(e) => break Err(e),
                },
                () = self.tx.closed() => break Ok(()),
            }
        };
        let others = self
            .alive
            .fetch_sub(1, std::sync::atomic::Ordering::SeqCst)
            .saturating_sub(1);
        if let Ok(mut c) = self.counters.lock() {
            c.per_link[self.index] = self.link.counters();
            if let Err(e) = &result
                && others > 0
            {
                c.failed_links.push(format!("{spec}: {e}"));
            }
        }
        if let Err(e) = &result
            && others > 0
        {
            tracing::warn!("monitor: {spec} failed ({e}); the other links go on");
        }
        result
    }
}

/// Drain the alert component's queue onto the alert link (a failed send is not fatal: the
/// planner may not be up yet).
async fn send_alerts(
    sink: &mut ahcmon::output::jsonl::Outputs,
    link: Option<&mut Link>,
    clock: Instant,
) {
    let (Some(a), Some(link)) = (sink.alerts.as_mut(), link) else {
        return;
    };
    a.tick(clock.elapsed().as_secs_f64());
    for frame in std::mem::take(&mut a.outbox) {
        if !matches!(link.send(&frame).await, Ok(true)) {
            a.frames_unsent += 1;
        }
    }
}

#[cfg(unix)]
type Signal = Option<tokio::signal::unix::Signal>;
#[cfg(not(unix))]
type Signal = Option<()>;

/// The next delivery of a signal we listen to; never, when we do not.
#[allow(unused_variables)]
async fn next_signal(signal: &mut Signal) -> Option<()> {
    #[cfg(unix)]
    if let Some(s) = signal.as_mut() {
        return s.recv().await;
    }
    std::future::pending::<Option<()>>().await
}

#[cfg(unix)]
/// SIGHUP was ignored when the process started (`nohup`): Linux's /proc says so (SigIgn, bit
/// 0). Elsewhere, or unreadable, taken as ignored: the hangup then keeps its default.
fn hangup_ignored() -> bool {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return true;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigIgn:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_none_or(|mask| mask & 1 != 0)
}

/// The vehicle's time (s) for a link event: its clock (the newest stamp of the boot it is
/// on), else its last sample's; `None` when it has sent no time stamp (a HEARTBEAT-only
/// system).
fn vehicle_time(monitor: &Monitor, sysid: u8) -> Option<f64> {
    monitor
        .assembler
        .vehicles
        .get(&sysid)
        .and_then(|v| v.clock())
        .or_else(|| monitor.pipelines.get(&sysid)?.last_sample_t)
}

/// A link event at the vehicle's time; without one, at 0 and said so.
fn link_event(monitor: &Monitor, sysid: u8, event: Event, detail: String) -> Decision {
    match vehicle_time(monitor, sysid) {
        Some(t) => Decision::monitor(t, sysid, event, detail),
        None => Decision::monitor(
            0.0,
            sysid,
            event,
            format!("{detail}; t is 0: the vehicle has sent no time stamp"),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ahcmon::output::jsonl::Outputs;
    use ahcmon::pipeline::PipelineConfig;
    use ahcmon::protocol::dialects::ahcmon::{
        ATTITUDE_DATA, HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
    };

    use super::super::test_frame as frame;

    #[test]
    fn a_link_event_is_on_the_vehicles_clock_or_says_it_has_none() {
        let mut m = Monitor::new(PipelineConfig::default());
        let mut sink = Outputs::new(None, None, 1).unwrap();
        sink.echo = false;
        m.on_frame(
            &frame(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 0,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                base_mode: MavModeFlag::empty(),
                system_status: MavState::MAV_STATE_STANDBY,
                mavlink_version: 3,
            })),
            &mut sink,
        );
        // A HEARTBEAT carries no time: t 0, and the detail says why (it read t=0.00 bare).
        let d = link_event(&m, 3, Event::LinkLost, "no frame for 2 s".into());
        assert_eq!(d.t, 0.0);
        assert!(
            d.detail
                .as_deref()
                .is_some_and(|s| s.contains("no time stamp"))
        );
        // An ATTITUDE alone (no outputs, so no sample): its stamp.
        m.on_frame(
            &frame(MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: 12_340,
                ..Default::default()
            })),
            &mut sink,
        );
        let d = link_event(&m, 3, Event::LinkLost, "no frame for 2 s".into());
        assert_eq!(d.t, 12.34);
        assert_eq!(d.detail.as_deref(), Some("no frame for 2 s"));
    }
}
