//! The live monitor loop on tokio: a reader task turns the link's bytes into frames and
//! hands them over a bounded channel to the estimating side, which never blocks the reader.
//! Link loss per vehicle becomes a `link_lost` decision, its end `link_restored`.

use super::conn::Link;
use crate::protocol::frame::{Frame, FrameCounters};
use crate::diagnose::vehicle::{Decision, Event};
use crate::monitor::Monitor;
use crate::pipeline::PipelineSink;
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

/// What the reader saw, for the summary.
#[derive(Debug, Clone, Default)]
pub struct LiveCounters {
    pub link: FrameCounters,
    /// Frames dropped because the estimating side fell behind (channel full).
    pub backpressure_drops: u64,
    /// The connection's notes (see [`super::conn::Received::Note`]) that the dashboard kept
    /// from being said: the caller says them once the terminal is restored. The first and the
    /// last `KEPT_NOTES` only (a flapping peer says two a second for as long as it runs).
    pub unsaid_notes: Vec<String>,
    unsaid_last: std::collections::VecDeque<String>,
    unsaid_skipped: u64,
    /// Our own alert frames (component `ALERT_COMPID`) that came back in, ignored: a forwarder
    /// such as MAVProxy sends what one link gives it to its other links.
    pub own_echo: u64,
}

/// How many of the first and of the last unsaid notes are kept.
const KEPT_NOTES: usize = 20;

impl LiveCounters {
    fn keep_note(&mut self, note: String) {
        if self.unsaid_notes.len() < KEPT_NOTES {
            self.unsaid_notes.push(note);
            return;
        }
        self.unsaid_last.push_back(note);
        if self.unsaid_last.len() > KEPT_NOTES {
            self.unsaid_last.pop_front();
            self.unsaid_skipped += 1;
        }
    }

    /// The notes to say after the dashboard: the first, how many were left out, the last.
    pub fn notes_to_say(&self) -> Vec<String> {
        let mut out = self.unsaid_notes.clone();
        if self.unsaid_skipped > 0 {
            out.push(format!(
                "({} more notes like these, not repeated)",
                self.unsaid_skipped
            ));
        }
        out.extend(self.unsaid_last.iter().cloned());
        out
    }
}

/// Run until ctrl-c, the idle timeout or a fatal link error. Returns the counters. With
/// `alerts`, the frames the sink's alert component queues are sent on that link.
pub async fn run(
    mut link: Link,
    monitor: &mut Monitor,
    sink: &mut crate::output::jsonl::MonitorFiles,
    mut alerts: Option<Link>,
    mut ui: Option<&mut crate::output::dashboard::TerminalUi>,
    opts: LiveOptions,
) -> Result<LiveCounters, super::ConnError> {
    let clock = Instant::now();
    // The reader's drop counters, for the dashboard's footer while running and for the
    // summary if the reader does not hand back its final ones in time.
    let live_counters = std::sync::Arc::new(std::sync::Mutex::new(LiveCounters::default()));
    let reader_counters = live_counters.clone();
    let (tx, mut rx) = mpsc::channel::<Frame>(opts.channel_capacity);
    let (done_tx, done_rx) =
        tokio::sync::oneshot::channel::<Result<LiveCounters, super::ConnError>>();
    // Frames for the vehicle link (only SET_MESSAGE_INTERVAL, only with --request-rates).
    let (vehicle_tx, mut vehicle_rx) = mpsc::channel::<Vec<u8>>(16);
    // Headless, the connection's state changes are said (the dashboard's footer shows the link).
    let say_notes = ui.is_none();
    let spec = link.spec.to_string();
    let reader = tokio::spawn(async move {
        let mut drops = 0u64;
        let result = loop {
            tokio::select! {
                Some(out) = vehicle_rx.recv() => {
                    if let Err(e) = link.send(&out).await {
                        break Err(e);
                    }
                }
                r = link.recv_or_note() => match r {
                    Ok(super::conn::Received::Note(note)) => {
                        let note = format!("{spec}: {note}");
                        if say_notes {
                            eprintln!("monitor: {note}");
                        } else if let Ok(mut c) = reader_counters.lock() {
                            c.keep_note(note);
                        }
                    }
                    Ok(super::conn::Received::Frame(frame)) => {
                        if let Err(mpsc::error::TrySendError::Full(_)) = tx.try_send(frame) {
                            drops += 1;
                        }
                        if let Ok(mut c) = reader_counters.lock() {
                            c.link = link.counters();
                            c.backpressure_drops = drops;
                        }
                    }
                    Err(e) => break Err(e),
                },
                () = tx.closed() => break Ok(()),
            }
        };
        let _ = done_tx.send(result.map(|()| {
            let mut c = reader_counters
                .lock()
                .map(|c| c.clone())
                .unwrap_or_default();
            c.link = link.counters();
            c.backpressure_drops = drops;
            c
        }));
    });
    let mut last_seen: BTreeMap<u8, Instant> = BTreeMap::new();
    let mut lost: BTreeMap<u8, bool> = BTreeMap::new();
    let mut any_frame: Option<Instant> = None;
    let mut own_echo = 0u64;
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
                let Some(frame) = frame else { break };
                // Our own alerts, echoed back in under the vehicle's system id, would keep a
                // vehicle that has gone silent "alive" (no link_lost, no --exit-idle).
                if sink.alerts.is_some() && frame.compid == crate::output::alerts::ALERT_COMPID {
                    own_echo += 1;
                    continue;
                }
                let now = Instant::now();
                any_frame = Some(now);
                if frame.sysid != 255 && frame.sysid != 0 {
                    last_seen.insert(frame.sysid, now);
                    if lost.insert(frame.sysid, false) == Some(true) {
                        sink.link_event(&link_event(monitor, frame.sysid, Event::LinkRestored, "frames arrive again".into()));
                    }
                }
                if let Some(hz) = opts.request_rates {
                    for out in rates.on_frame(&frame, monitor, hz, sink) {
                        let _ = vehicle_tx.send(out).await;
                    }
                }
                monitor.on_frame(&frame, sink);
                // The alerts speak as a vehicle's system id from when the vehicle is known.
                if let Some(a) = sink.alerts.as_mut()
                    && monitor.assembler.vehicles.contains_key(&frame.sysid)
                {
                    a.see(frame.sysid);
                }
                send_alerts(sink, alerts.as_mut(), clock).await;
            }
            _ = tick.tick() => {
                send_alerts(sink, alerts.as_mut(), clock).await;
                let now = Instant::now();
                let over = opts
                    .stream_over
                    .as_ref()
                    .is_some_and(|o| o.load(std::sync::atomic::Ordering::Relaxed));
                for (sysid, seen) in &last_seen {
                    // Only vehicles the monitor knows (not every stray system id).
                    if !monitor.assembler.vehicles.contains_key(sysid) {
                        continue;
                    }
                    let gone = now.duration_since(*seen) > opts.link_timeout;
                    if gone && !over && lost.get(sysid) != Some(&true) {
                        lost.insert(*sysid, true);
                        // Shortest form that shows the value (0.03 s, 2 s, 2.5 s).
                        let detail = format!("no frame for {} s", opts.link_timeout.as_secs_f64());
                        sink.link_event(&link_event(monitor, *sysid, Event::LinkLost, detail));
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
                    eprintln!(
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
                    if let crate::output::dashboard::KeyAction::Quit = ui.keys(monitor) {
                        break;
                    }
                    let counters = live_counters.lock().map(|c| c.link).unwrap_or_default();
                    let age = any_frame.map(|t| now.duration_since(t).as_secs_f64());
                    // (Vehicles only: not a second ground station or a gimbal's own system.)
                    let vehicles: crate::output::dashboard::VehicleLinks = last_seen
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
    // Closing the channel ends the reader, which hands back its counters.
    drop(rx);
    monitor.finish(sink);
    let result = tokio::time::timeout(Duration::from_secs(1), done_rx).await;
    reader.abort();
    let result = match result {
        Ok(Ok(r)) => r,
        // The reader is stuck (e.g. a tcpin send waiting for a client): its counters as of
        // its last frame, not zeros.
        _ => Ok(live_counters.lock().map(|c| c.clone()).unwrap_or_default()),
    };
    result.map(|mut c| {
        c.own_echo = own_echo;
        c
    })
}

/// The messages the estimators need, by id: ATTITUDE, SERVO_OUTPUT_RAW and the a_z source the
/// assembler reads from this autopilot: RAW_IMU is in mG only on ArduPilot, so others (PX4)
/// are asked for HIGHRES_IMU.
fn needed(autopilot: crate::protocol::dialects::ahcmon::MavAutopilot) -> [(u32, &'static str); 3] {
    use crate::protocol::dialects::ahcmon::MavAutopilot;
    let imu = if autopilot == MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA {
        (27, "RAW_IMU")
    } else {
        (105, "HIGHRES_IMU")
    };
    [
        (30, "ATTITUDE"),
        (SERVO_OUTPUT_RAW_ID, "SERVO_OUTPUT_RAW"),
        imu,
    ]
}
/// How long the achieved rates are counted after the request.
const RATE_WINDOW: Duration = Duration::from_secs(5);

/// `--request-rates`: one SET_MESSAGE_INTERVAL per needed message to each vehicle's autopilot
/// after its first heartbeat; then its COMMAND_ACKs and the rates achieved are reported.
#[derive(Default)]
struct RateRequests {
    asked: BTreeMap<u8, Asked>,
    seq: u8,
}

/// What was asked of one vehicle and what came of it.
struct Asked {
    since: Instant,
    acks: u32,
    /// The results of acknowledgements other than ACCEPTED.
    refused: Vec<String>,
    /// Frames of each needed message since the request.
    counts: [u64; 3],
    reported: bool,
    messages: [(u32, &'static str); 3],
    /// Vehicle time (s) of the first and the latest ATTITUDE since the request, and the frames
    /// of each needed message after that first ATTITUDE: the rates are per vehicle second, so
    /// a simulator sent at `--speed` is not reported at its wall rate.
    vehicle_span: Option<(f64, f64)>,
    vehicle_counts: [u64; 3],
    /// ACTUATOR_OUTPUT_STATUS frames (as `counts` and `vehicle_counts`): PX4 may stream its
    /// outputs so, and the assembler takes either; the faster of the two is the outputs' rate.
    status_counts: [u64; 2],
}

const SERVO_OUTPUT_RAW_ID: u32 = 36;
const ACTUATOR_OUTPUT_STATUS_ID: u32 = 375;

impl Asked {
    /// The achieved rates' report, and what to say about missing acknowledgements.
    fn report(&self, hz: f64) -> String {
        let wall = self.since.elapsed().as_secs_f64();
        let (span, clock, counts, status) = match self.vehicle_span {
            Some((a, b)) if b > a => (
                b - a,
                "vehicle",
                &self.vehicle_counts,
                self.status_counts[1],
            ),
            _ => (wall, "wall-clock", &self.counts, self.status_counts[0]),
        };
        // The outputs' rate is the faster of their two messages, under its name.
        let rated: Vec<(&str, u64)> = self
            .messages
            .iter()
            .zip(counts.iter())
            .map(|((id, name), n)| {
                if *id == SERVO_OUTPUT_RAW_ID && status > *n {
                    ("ACTUATOR_OUTPUT_STATUS", status)
                } else {
                    (*name, *n)
                }
            })
            .collect();
        let achieved: Vec<String> = rated
            .iter()
            .map(|(name, n)| format!("{name} {:.1} Hz", *n as f64 / span))
            .collect();
        let mut text = format!(
            "rates achieved (requested {hz} Hz, over {span:.1} s of {clock} time): {}",
            achieved.join(", ")
        );
        // Under 80 % of the rate asked for (ArduPilot caps streams by its SRn_ parameters
        // and by the link's bandwidth).
        let slow: Vec<&str> = rated
            .iter()
            .filter(|(_, n)| (*n as f64 / span) < 0.8 * hz)
            .map(|(name, _)| *name)
            .collect();
        if !slow.is_empty() {
            text.push_str(&format!(
                "; warning: {} under 80 % of the {hz} Hz asked for (the autopilot's stream limits or the link's bandwidth)",
                slow.join(", ")
            ));
        }
        if !self.refused.is_empty() {
            text.push_str(&format!(
                "; warning: {} of {} requests refused ({})",
                self.refused.len(),
                self.messages.len(),
                self.refused.join(", ")
            ));
        }
        let asked = self.messages.len() as u32;
        if self.acks < asked {
            text.push_str(&format!(
                "; warning: {} of {asked} requests got no COMMAND_ACK in {wall:.0} s (the link may be one-way, or the autopilot ignores SET_MESSAGE_INTERVAL)",
                asked - self.acks
            ));
        }
        text
    }
}

impl RateRequests {
    fn on_frame(
        &mut self,
        frame: &Frame,
        monitor: &Monitor,
        hz: f64,
        sink: &mut dyn PipelineSink,
    ) -> Vec<Vec<u8>> {
        use crate::protocol::dialects::ahcmon::{
            COMMAND_LONG_DATA, MavAutopilot, MavCmd, MavMessage, MavResult, MavType,
        };
        let mut out = vec![];
        let sysid = frame.sysid;
        if let Some(a) = self.asked.get_mut(&sysid) {
            match &frame.msg {
                MavMessage::COMMAND_ACK(ack)
                    if ack.command == MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL =>
                {
                    a.acks += 1;
                    if ack.result != MavResult::MAV_RESULT_ACCEPTED {
                        a.refused
                            .push(format!("{:?}", ack.result).replace("MAV_RESULT_", ""));
                    }
                    sink.message(
                        sysid,
                        &format!(
                            "COMMAND_ACK SET_MESSAGE_INTERVAL {}/3: {:?}",
                            a.acks, ack.result
                        ),
                    );
                }
                MavMessage::ATTITUDE(att) => {
                    let t = f64::from(att.time_boot_ms) * 1e-3;
                    let first = a.vehicle_span.map_or(t, |(first, _)| first);
                    a.vehicle_span = Some((first, t));
                }
                _ => {}
            }
            let slot = a.messages.iter().position(|(id, _)| *id == frame.msg_id);
            let status = frame.msg_id == ACTUATOR_OUTPUT_STATUS_ID;
            if slot.is_some() || status {
                // The first ATTITUDE opens the span; what comes after it falls within.
                let opened = a.vehicle_span.is_some_and(|(first, last)| {
                    !matches!(frame.msg, MavMessage::ATTITUDE(_)) || last > first
                });
                let (wall, vehicle) = match slot {
                    Some(k) => (&mut a.counts[k], &mut a.vehicle_counts[k]),
                    None => {
                        let [wall, vehicle] = &mut a.status_counts;
                        (wall, vehicle)
                    }
                };
                *wall += 1;
                *vehicle += u64::from(opened);
            }
            if !a.reported && a.since.elapsed() >= RATE_WINDOW {
                a.reported = true;
                sink.message(sysid, &a.report(hz));
            }
            return out;
        }
        let MavMessage::HEARTBEAT(hb) = &frame.msg else {
            return out;
        };
        if hb.autopilot == MavAutopilot::MAV_AUTOPILOT_INVALID
            || matches!(
                hb.mavtype,
                MavType::MAV_TYPE_GCS | MavType::MAV_TYPE_ONBOARD_CONTROLLER
            )
            || !monitor.assembler.vehicles.contains_key(&sysid)
        {
            return out;
        }
        // The autopilot as the assembler knows it (not a gimbal's or companion's heartbeat).
        let Some(info) = monitor.assembler.vehicles.get(&sysid).map(|v| &v.info) else {
            return out;
        };
        let (Some(autopilot), Some(compid)) = (info.autopilot, info.compid) else {
            return out;
        };
        if compid != frame.compid {
            return out;
        }
        let asked = needed(autopilot);
        for (id, _) in asked {
            let msg = MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
                param1: id as f32,
                param2: (1e6 / hz) as f32,
                command: MavCmd::MAV_CMD_SET_MESSAGE_INTERVAL,
                target_system: sysid,
                target_component: frame.compid,
                ..Default::default()
            });
            let mut bytes = Vec::with_capacity(64);
            // As a component of the vehicle's own system (never as a GCS, sysid 255).
            crate::protocol::frame::encode_v2(
                sysid,
                crate::output::alerts::ALERT_COMPID,
                self.seq,
                &msg,
                &mut bytes,
            );
            self.seq = self.seq.wrapping_add(1);
            out.push(bytes);
        }
        let names: Vec<&str> = asked.iter().map(|(_, n)| *n).collect();
        sink.message(
            sysid,
            &format!(
                "requested {} at {hz} Hz (SET_MESSAGE_INTERVAL)",
                names.join(", ")
            ),
        );
        self.asked.insert(
            sysid,
            Asked {
                since: Instant::now(),
                acks: 0,
                refused: vec![],
                counts: [0; 3],
                reported: false,
                messages: asked,
                vehicle_span: None,
                vehicle_counts: [0; 3],
                status_counts: [0; 2],
            },
        );
        out
    }
}

/// Drain the alert component's queue onto the alert link (a failed send is not fatal: the
/// planner may not be up yet).
async fn send_alerts(
    sink: &mut crate::output::jsonl::MonitorFiles,
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
    use crate::protocol::dialects::ahcmon::{
        ATTITUDE_DATA, HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
    };
    use crate::output::jsonl::MonitorFiles;
    use crate::pipeline::PipelineConfig;

    fn frame(msg: MavMessage) -> Frame {
        Frame {
            version: mavlink_core::MavlinkVersion::V2,
            sysid: 3,
            compid: 1,
            seq: 0,
            msg_id: mavlink_core::Message::message_id(&msg),
            msg,
        }
    }

    /// Under the dashboard a flapping peer's notes are kept first and last, the rest counted.
    #[test]
    fn unsaid_notes_keep_the_first_and_the_last() {
        let mut c = LiveCounters::default();
        for k in 0..1000 {
            c.keep_note(format!("note {k}"));
        }
        let said = c.notes_to_say();
        assert_eq!(said.len(), 2 * KEPT_NOTES + 1, "{said:?}");
        assert_eq!(said[0], "note 0");
        assert_eq!(
            said[KEPT_NOTES],
            "(960 more notes like these, not repeated)"
        );
        assert_eq!(said.last().map(String::as_str), Some("note 999"));
        let mut few = LiveCounters::default();
        few.keep_note("only".into());
        assert_eq!(few.notes_to_say(), vec!["only".to_string()]);
    }

    /// The rates report after 5 s of a PX4 at 50 Hz that sends, at step k (20 ms apart),
    /// ATTITUDE, HIGHRES_IMU and what `outputs(k, ms)` gives.
    fn px4_rates_report(outputs: impl Fn(u32, u32) -> Vec<MavMessage>) -> String {
        use crate::protocol::dialects::ahcmon::HIGHRES_IMU_DATA;
        let mut m = Monitor::new(PipelineConfig::default());
        let mut sink = MonitorFiles::new(None, None, 1).unwrap();
        sink.echo = false;
        let mut rates = RateRequests::default();
        let heartbeat = frame(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            mavtype: MavType::MAV_TYPE_QUADROTOR,
            autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
            ..Default::default()
        }));
        m.on_frame(&heartbeat, &mut sink);
        assert_eq!(rates.on_frame(&heartbeat, &m, 50.0, &mut sink).len(), 3);
        for k in 0..250u32 {
            let ms = 1000 + 20 * k;
            let mut msgs = vec![
                MavMessage::ATTITUDE(ATTITUDE_DATA {
                    time_boot_ms: ms,
                    ..Default::default()
                }),
                MavMessage::HIGHRES_IMU(HIGHRES_IMU_DATA {
                    time_usec: u64::from(ms) * 1000,
                    ..Default::default()
                }),
            ];
            msgs.extend(outputs(k, ms));
            for msg in msgs {
                let f = frame(msg);
                m.on_frame(&f, &mut sink);
                rates.on_frame(&f, &m, 50.0, &mut sink);
            }
        }
        rates.asked[&3].report(50.0)
    }

    /// A PX4 that streams its outputs as ACTUATOR_OUTPUT_STATUS has them counted as the
    /// outputs, under that name (it was told its SERVO_OUTPUT_RAW was starved at 0.0 Hz); with
    /// both, the faster one is the outputs' rate, not their sum.
    #[test]
    fn outputs_as_actuator_output_status_count_for_the_rate_asked() {
        use crate::protocol::dialects::ahcmon::{ACTUATOR_OUTPUT_STATUS_DATA, SERVO_OUTPUT_RAW_DATA};
        let status = |ms: u32| {
            MavMessage::ACTUATOR_OUTPUT_STATUS(ACTUATOR_OUTPUT_STATUS_DATA {
                time_usec: u64::from(ms) * 1000,
                active: 4,
                ..Default::default()
            })
        };
        let report = px4_rates_report(|_, ms| vec![status(ms)]);
        assert!(
            report.contains("ACTUATOR_OUTPUT_STATUS 50.") && !report.contains("under 80 %"),
            "{report}"
        );
        // SERVO_OUTPUT_RAW at 10 Hz and ACTUATOR_OUTPUT_STATUS at 25 Hz: 25 Hz is too slow.
        let report = px4_rates_report(|k, ms| {
            let mut v = vec![];
            if k % 5 == 0 {
                v.push(MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
                    time_usec: ms * 1000,
                    ..Default::default()
                }));
            }
            if k % 2 == 0 {
                v.push(status(ms));
            }
            v
        });
        assert!(
            report.contains("ACTUATOR_OUTPUT_STATUS 25.")
                && report.contains("warning: ACTUATOR_OUTPUT_STATUS under 80 %"),
            "{report}"
        );
    }

    #[test]
    fn a_link_event_is_on_the_vehicles_clock_or_says_it_has_none() {
        let mut m = Monitor::new(PipelineConfig::default());
        let mut sink = MonitorFiles::new(None, None, 1).unwrap();
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
