//! Fly a vehicle scenario as a MAVLink autopilot: the simulator's samples encoded like
//! ArduPilot sends them, paced in real time (or a multiple), to a live connection and/or a
//! tlog, with the ground truth as JSON lines. Used by `ahcmon sim` and `ahcmon demo`.

use ahcmon::eval::vehicle::sim_config;
use ahcmon::link::{ConnError, Link, TlogWriter};
use ahcmon::output::jsonl::{JsonlFile, NoiseInForce, TruthRecord};
use ahcmon::protocol::frame::encode_v2;
use ahcmon::scenario::NamedScenario;
use ahcmon::sim::vehicle::VehicleSim;
use ahcmon::telemetry::encode::{BOOT_OFFSET_S, SimTelemetry};
use std::collections::BTreeMap;
use std::io::BufWriter;

pub struct FlyOptions {
    pub sysid: u8,
    /// Which autopilot the stream sounds like.
    pub flavour: ahcmon::telemetry::encode::Flavour,
    pub seed: u64,
    /// Multiple of real time; None = as fast as possible.
    pub speed: Option<f64>,
    /// tlog record time of the first sample (µs since the Unix epoch).
    pub epoch_us: u64,
}

#[derive(Debug, Default)]
pub struct FlyReport {
    pub vehicle: String,
    /// Messages per type.
    pub counts: BTreeMap<&'static str, u64>,
    pub sent: u64,
    /// Frames that had nowhere to go (udpin before a peer, TCP down).
    pub unsent: u64,
}

#[derive(Debug, thiserror::Error)]
pub enum FlyError {
    #[error(transparent)]
    Setup(#[from] ahcmon::eval::EvalError),
    #[error("{0}")]
    Sim(String),
    #[error(transparent)]
    Link(#[from] ConnError),
    #[error("writing: {0}")]
    Io(#[from] std::io::Error),
}

pub async fn fly(
    named: &NamedScenario,
    opts: &FlyOptions,
    mut link: Option<&mut Link>,
    mut tlog: Option<&mut TlogWriter<BufWriter<ahcmon::output::file::OutputFile>>>,
    mut truth: Option<&mut JsonlFile>,
) -> Result<FlyReport, FlyError> {
    let (cfg, _) = sim_config(named, opts.seed)?;
    let vehicle = cfg.profile.clone();
    let (gyro, az_noise) = (cfg.gyro_noise, cfg.az_noise);
    let mut sim = VehicleSim::new(cfg).map_err(FlyError::Sim)?;
    let mut enc = SimTelemetry::with_flavour(&vehicle, opts.flavour);
    let l = vehicle.actuators.len();
    let mut report = FlyReport {
        vehicle: vehicle.name.clone(),
        ..Default::default()
    };
    let started = tokio::time::Instant::now();
    let mut msgs = Vec::with_capacity(64);
    let mut frame = Vec::with_capacity(300);
    let mut seq = 0u8;
    let mut prev = sim.step();
    for _ in 1..named.scenario.steps() {
        let next = sim.step();
        msgs.clear();
        // The rates of this instant with the outputs commanded now (they act until the next).
        enc.sample_messages(&prev, &next.u[..l], &mut msgs);
        if let Some(x) = opts.speed {
            tokio::time::sleep_until(started + std::time::Duration::from_secs_f64(prev.t / x))
                .await;
        }
        let ts = opts.epoch_us + (prev.t * 1e6) as u64;
        for m in &msgs {
            encode_v2(opts.sysid, 1, seq, m, &mut frame);
            seq = seq.wrapping_add(1);
            *report
                .counts
                .entry(mavlink_core::Message::message_name(m))
                .or_insert(0) += 1;
            if let Some(w) = tlog.as_deref_mut() {
                w.write_raw(ts, &frame)?;
            }
            if let Some(l) = link.as_deref_mut() {
                if l.send(&frame).await? {
                    report.sent += 1;
                } else {
                    report.unsent += 1;
                }
            }
        }
        if let Some(w) = truth.as_deref_mut() {
            let noise = NoiseInForce { gyro, az: az_noise };
            let mut rec = TruthRecord::new(&prev, &vehicle, noise);
            // On the vehicle's clock, like the decisions.
            rec.t = prev.t + BOOT_OFFSET_S;
            w.write(&rec)?;
        }
        prev = next;
    }
    if let Some(w) = tlog {
        w.flush()?;
    }
    Ok(report)
}
