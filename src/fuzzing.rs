//! Entry points for the fuzz targets (`fuzz/`, cargo-fuzz on nightly) and for the test that
//! replays their corpus on stable (`tests/fuzz_corpus.rs`). Each takes arbitrary bytes and
//! runs them through the code the binary runs, from the reader to the decisions. Any input
//! may be refused; none may panic or fail to return.

use crate::monitor::Monitor;
use crate::output::jsonl::Outputs;
use crate::pipeline::PipelineConfig;
use crate::protocol::Frame;
use crate::protocol::frame::StreamFramer;
use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};
use crate::telemetry::Profile;
use crate::telemetry::encode::SimTelemetry;

/// Simulated flight fed to the monitor for a profile or a scenario that loads: long enough
/// for take-off, the calibration and its fits (where the profile's numbers reach the maths).
const FLIGHT_STEPS: usize = 1500;

/// Outputs to nowhere (none is a file, so none can fail to open).
fn silent() -> Option<Outputs> {
    let mut sink = Outputs::new(None, None, 1).ok()?;
    sink.echo = false;
    Some(sink)
}

/// A tlog (stamped frames) into the monitor, arrival on the tlog's stamps, as `replay` does.
pub fn tlog(bytes: &[u8]) {
    let mut reader = crate::link::TlogReader::new(bytes);
    let mut monitor = Monitor::new(PipelineConfig::default());
    let Some(mut sink) = silent() else {
        return;
    };
    while let Ok(Some((ts, frame))) = reader.next_frame() {
        monitor.on_frame_at(&frame, Some(ts as f64 * 1e-6), &mut sink);
    }
    monitor.finish(&mut sink);
}

/// Datagrams as a live UDP link sees them: the first byte sets the datagram size (1-256),
/// the rest is cut into datagrams of that size, each arriving 2.5 ms after the last.
pub fn datagrams(bytes: &[u8]) {
    let Some((&size, rest)) = bytes.split_first() else {
        return;
    };
    let mut framer = StreamFramer::default();
    let mut monitor = Monitor::new(PipelineConfig::default());
    let Some(mut sink) = silent() else {
        return;
    };
    for (i, datagram) in rest.chunks(usize::from(size) + 1).enumerate() {
        framer.push(datagram);
        while let Some(frame) = framer.next_frame() {
            monitor.on_frame_at(&frame, Some(i as f64 * 0.0025), &mut sink);
        }
        framer.end_datagram();
    }
    monitor.finish(&mut sink);
}

/// A DataFlash log into the monitor as one vehicle's records.
pub fn dataflash(bytes: &[u8]) {
    let mut monitor = Monitor::new(PipelineConfig::default());
    let Some(mut sink) = silent() else {
        return;
    };
    let _ = crate::link::dataflash::read(
        bytes,
        &mut |r| monitor.on_record(1, r, &mut sink),
        &mut |_| {},
    );
    monitor.finish(&mut sink);
}

/// A ULog into the monitor. The ULog reader reads files, so the bytes go through one (in the
/// temporary directory, one per call).
pub fn ulog(bytes: &[u8]) {
    static CALLS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("ahcmon-fuzz-{}-{n}.ulg", std::process::id()));
    // Not the input's fault, and a silent return would fuzz nothing.
    if let Err(e) = std::fs::write(&path, bytes) {
        panic!("cannot write {}: {e}", path.display());
    }
    let mut monitor = Monitor::new(PipelineConfig::default());
    let Some(mut sink) = silent() else {
        return;
    };
    let _ = crate::link::ulog::read(&path, &mut |r| monitor.on_record(1, r, &mut sink));
    monitor.finish(&mut sink);
    let _ = std::fs::remove_file(&path);
}

/// A profile's TOML; one that loads flies the simulator in calm air and the monitor is given
/// the profile (its numbers reach the calibration's fits and the filters).
pub fn profile(bytes: &[u8]) {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    let Ok(profile) = Profile::from_toml(text, "fuzz.toml") else {
        return;
    };
    let cfg = VehicleSimConfig::calm(profile.clone(), 0.02, 1);
    fly(cfg, profile, FLIGHT_STEPS);
}

/// A scenario's TOML; one that loads and names a built-in profile is flown (its first
/// [`FLIGHT_STEPS`] steps) through the monitor, as `sim --out` and `monitor` would.
pub fn scenario(bytes: &[u8]) {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    let Ok(scenario) = crate::scenario::Scenario::from_toml(text, "fuzz.toml") else {
        return;
    };
    // A scenario may name a profile by path: only built-in names here, so that an input
    // never reads the machine's files.
    if scenario.is_paper()
        || scenario
            .profile
            .as_deref()
            .is_some_and(|p| p.contains('/') || p.contains('.'))
    {
        return;
    }
    let steps = scenario.steps().min(FLIGHT_STEPS);
    let named = crate::scenario::NamedScenario {
        name: "fuzz".into(),
        scenario,
    };
    let Ok((cfg, profile)) = crate::eval::vehicle::sim_config(&named, 1) else {
        return;
    };
    fly(cfg, profile, steps);
}

/// Fly `steps` of the simulator, encode its telemetry as ArduPilot does, and run the
/// monitor on the frames with `profile` given.
fn fly(cfg: VehicleSimConfig, profile: Profile, steps: usize) {
    let Ok(mut sim) = VehicleSim::new(cfg) else {
        return;
    };
    let mut enc = SimTelemetry::new(&profile);
    let l = profile.actuators.len();
    let mut monitor = Monitor::new(PipelineConfig {
        profile: Some(profile),
        ..PipelineConfig::default()
    });
    let Some(mut sink) = silent() else {
        return;
    };
    let mut msgs = Vec::new();
    let mut prev = sim.step();
    for seq in 1..steps {
        let next = sim.step();
        msgs.clear();
        enc.sample_messages(&prev, &next.u[..l], &mut msgs);
        for msg in msgs.drain(..) {
            let frame = Frame {
                version: mavlink_core::MavlinkVersion::V2,
                sysid: 1,
                compid: 1,
                seq: seq as u8,
                msg_id: mavlink_core::Message::message_id(&msg),
                msg,
            };
            monitor.on_frame_at(&frame, Some(prev.t), &mut sink);
        }
        prev = next;
    }
    monitor.finish(&mut sink);
}
