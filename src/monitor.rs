//! Frames of any number of vehicles → per-vehicle telemetry → per-vehicle pipelines. Pure:
//! the tlog replay, the live monitor and the tests feed it frames.

use crate::output::Sink;
use crate::pipeline::{PipelineConfig, VehiclePipeline};
use crate::protocol::Frame;
use crate::telemetry::{Assembler, AssemblerConfig};
use std::collections::BTreeMap;

pub struct Monitor {
    pub assembler: Assembler,
    samples: Vec<crate::telemetry::TelemetrySample>,
    pub pipelines: BTreeMap<u8, VehiclePipeline>,
    cfg: PipelineConfig,
    /// Per vehicle: the counts at the start of the current window of messages, and whether
    /// its stream was said to be mixed ([`MIXED_SHARE`]).
    mixing: BTreeMap<u8, ([u64; 2], bool)>,
}

/// A vehicle stream in which, over a window of [`MIXED_WINDOW`] rate instants (samples and
/// those dropped), at least this share were duplicates or went back in time is a mixed one
/// (two links of one vehicle, a link that replays, two vehicles with one id): said once as a
/// `contaminated` decision. A healthy link has none (a lost or reordered radio packet is
/// rarer than one in a hundred).
pub const MIXED_SHARE: f64 = 0.1;
pub const MIXED_WINDOW: u64 = 500;

impl Monitor {
    pub fn new(cfg: PipelineConfig) -> Self {
        Self {
            assembler: Assembler::new(AssemblerConfig::default()),
            samples: Vec::with_capacity(4),
            pipelines: BTreeMap::new(),
            cfg,
            mixing: BTreeMap::new(),
        }
    }

    /// Record that vehicle `sysid`'s stream was said to be mixed (by the link, which saw two
    /// senders); true the first time. One `contaminated` decision per vehicle.
    pub fn mark_mixed(&mut self, sysid: u8) -> bool {
        let (_, told) = self.mixing.entry(sysid).or_insert(([0; 2], false));
        !std::mem::replace(told, true)
    }

    pub fn on_frame(&mut self, frame: &Frame, sink: &mut dyn Sink) {
        self.on_frame_at(frame, None, sink);
    }

    /// [`Self::on_frame`] with the frame's arrival time (s, any origin: a live link's
    /// monotonic clock, a tlog's receive stamp), which the vehicle clock's jumps must agree
    /// with (`telemetry::assembler::REBOOT_ARRIVAL_S`).
    pub fn on_frame_at(&mut self, frame: &Frame, arrival: Option<f64>, sink: &mut dyn Sink) {
        self.samples.clear();
        self.assembler.on_frame_at(
            frame.sysid,
            frame.compid,
            &frame.msg,
            arrival,
            &mut self.samples,
        );
        self.assembler
            .on_sequence(frame.sysid, frame.compid, frame.seq);
        self.run(frame.sysid, sink);
    }

    /// One record of a vehicle's own log (DataFlash, ULog), as vehicle `sysid`.
    pub fn on_record(&mut self, sysid: u8, record: &crate::telemetry::Record, sink: &mut dyn Sink) {
        self.samples.clear();
        self.assembler.on_record(sysid, record, &mut self.samples);
        self.run(sysid, sink);
    }

    /// End of input: samples still waiting for their a_z are processed without it, and a
    /// reboot the new boot gave no sample after is still told (its warning, the summary's
    /// marks).
    pub fn finish(&mut self, sink: &mut dyn Sink) {
        let ids: Vec<u8> = self.assembler.vehicles.keys().copied().collect();
        for sysid in ids {
            if let Some(p) = self.pipelines.get_mut(&sysid) {
                p.settle(sink);
            }
            self.samples.clear();
            if let Some(v) = self.assembler.vehicles.get_mut(&sysid) {
                v.flush(&mut self.samples);
            }
            self.run(sysid, sink);
            // The last samples may have ended a calibration stretch.
            if let Some(p) = self.pipelines.get_mut(&sysid) {
                p.settle(sink);
            }
            if let (Some(v), Some(p)) = (
                self.assembler.vehicles.get_mut(&sysid),
                self.pipelines.get_mut(&sysid),
            ) && std::mem::take(&mut v.rebooted)
            {
                p.reset(v.clock().unwrap_or(0.0), sink);
            }
        }
    }

    /// Take back every calibration fit that has finished on its worker (a vehicle that went
    /// quiet during its fit sends no sample to do it).
    pub fn settle_finished_fits(&mut self, sink: &mut dyn Sink) {
        for p in self.pipelines.values_mut() {
            p.settle_if_done(sink);
        }
    }

    fn run(&mut self, sysid: u8, sink: &mut dyn Sink) {
        if self.samples.is_empty() {
            return;
        }
        let Some(vehicle) = self.assembler.vehicles.get_mut(&sysid) else {
            return;
        };
        let pipeline = self.pipelines.entry(sysid).or_insert_with(|| {
            tracing::debug!("sysid {sysid}: a new vehicle, with its own pipeline");
            VehiclePipeline::new(sysid, self.cfg.clone())
        });
        for sample in &self.samples {
            if std::mem::take(&mut vehicle.rebooted) {
                pipeline.reset(sample.t, sink);
            }
            pipeline.on_sample(sample, &vehicle.info, sink);
        }
        let c = &vehicle.counters;
        let bad = c.out_of_order + c.duplicates;
        let now = [c.samples + bad, bad];
        let (start, told) = self.mixing.entry(sysid).or_insert((now, false));
        let (seen, mixed) = (now[0] - start[0], now[1] - start[1]);
        if seen >= MIXED_WINDOW {
            if !*told && mixed as f64 >= MIXED_SHARE * seen as f64 {
                *told = true;
                let t = self.samples.last().map_or(0.0, |s| s.t);
                sink.decision(&crate::diagnose::vehicle::Decision::monitor(
                    t,
                    sysid,
                    crate::diagnose::vehicle::Event::Contaminated,
                    format!(
                        "{mixed} of the last {seen} rate instants were duplicates or went back in time: two streams of this vehicle mixed (two links, a link that replays, two vehicles with one id); its estimates may be wrong"
                    ),
                ));
            }
            *start = now;
        }
    }
}
