//! The calibration's fit off the caller's thread (`PipelineConfig::fit_in_background`, the
//! live monitor): the fit of a 20 s stretch takes 40 ms at 50 Hz and 300-400 ms at 400 Hz,
//! and on the live loop's thread it held back every vehicle's frames, decisions and alerts
//! that long. The pipeline as it stands at the end of its stretch moves to a worker thread,
//! which fits and starts estimating exactly as the caller's thread would; a stand-in keeps
//! what the dashboard shows and holds the samples that arrive meanwhile. When the worker is
//! done, the pipeline comes back, what it said is passed on in order, and the held samples
//! run through it. The decisions and estimates are those of a fit in place; only the moment
//! they are written moves.

use super::{Stage, VehiclePipeline};
use crate::diagnose::vehicle::Decision;
use crate::estimate::vehicle::AhcEstimate;
use crate::output::Sink;
use crate::telemetry::{Profile, TelemetrySample, VehicleInfo};

/// What the worker's pipeline said, in order.
#[derive(Default)]
pub(super) struct Said(Vec<Saying>);

enum Saying {
    Decision(Decision),
    Estimates(f64, u8, [Vec<AhcEstimate>; 3], Box<Profile>),
    Message(u8, String),
}

impl Sink for Said {
    fn decision(&mut self, d: &Decision) {
        self.0.push(Saying::Decision(d.clone()));
    }
    fn estimates(&mut self, t: f64, sysid: u8, est: &[&[AhcEstimate]; 3], profile: &Profile) {
        let est = est.map(<[AhcEstimate]>::to_vec);
        self.0
            .push(Saying::Estimates(t, sysid, est, Box::new(profile.clone())));
    }
    fn message(&mut self, sysid: u8, text: &str) {
        self.0.push(Saying::Message(sysid, text.to_owned()));
    }
}

impl Said {
    fn pass_on(self, sink: &mut dyn Sink) {
        for s in self.0 {
            match s {
                Saying::Decision(d) => sink.decision(&d),
                Saying::Estimates(t, sysid, est, profile) => {
                    sink.estimates(t, sysid, &[&est[0], &est[1], &est[2]], &profile);
                }
                Saying::Message(sysid, text) => sink.message(sysid, &text),
            }
        }
    }
}

pub(super) struct Fitting {
    worker: Option<std::thread::JoinHandle<Option<(VehiclePipeline, Said)>>>,
    /// Samples that arrived while the worker fitted, with what was known of the vehicle.
    held: Vec<(TelemetrySample, VehicleInfo)>,
}

impl VehiclePipeline {
    /// Hand this pipeline, at the end of its calibration stretch, to a worker thread that
    /// runs `finish` on it; this one becomes its stand-in until [`Self::settle`]. Without a
    /// thread to be had, `finish` runs here.
    pub(super) fn fit_in_background(
        &mut self,
        finish: fn(&mut VehiclePipeline, &mut dyn Sink),
        sink: &mut dyn Sink,
    ) {
        // The thread first, the pipeline sent to it after: a failed start keeps it here.
        let (tx, rx) = std::sync::mpsc::channel::<VehiclePipeline>();
        let started = std::thread::Builder::new()
            .name(format!("fit sysid {}", self.sysid))
            .spawn(move || {
                let mut pipeline = rx.recv().ok()?;
                let mut said = Said::default();
                finish(&mut pipeline, &mut said);
                Some((pipeline, said))
            });
        let Ok(worker) = started else {
            finish(self, sink);
            return;
        };
        let mut stand_in = VehiclePipeline::new(self.sysid, self.cfg.clone());
        stand_in.detection = self.detection.clone();
        stand_in.last = self.last;
        stand_in.last_sample_t = self.last_sample_t;
        stand_in.active = self.active;
        stand_in.health = self.health;
        stand_in.counters = self.counters;
        stand_in.gate = self.gate;
        stand_in.airborne_since = self.airborne_since;
        stand_in.armed_since = self.armed_since;
        stand_in.before_reboot = self.before_reboot;
        let pipeline = std::mem::replace(self, stand_in);
        if let Err(std::sync::mpsc::SendError(pipeline)) = tx.send(pipeline) {
            // The worker is gone already: fit here.
            *self = pipeline;
            finish(self, sink);
            return;
        }
        self.stage = Stage::Fitting(Box::new(Fitting {
            worker: Some(worker),
            held: Vec::new(),
        }));
    }

    /// While the worker fits: hold the sample; take the pipeline back once it is done.
    pub(super) fn hold(&mut self, s: &TelemetrySample, info: &VehicleInfo, sink: &mut dyn Sink) {
        let Stage::Fitting(f) = &mut self.stage else {
            return;
        };
        f.held.push((*s, info.clone()));
        self.settle_if_done(sink);
    }

    /// [`Self::settle`] if the worker is done; nothing otherwise (no wait).
    pub fn settle_if_done(&mut self, sink: &mut dyn Sink) {
        if let Stage::Fitting(f) = &self.stage
            && f.worker.as_ref().is_some_and(|w| w.is_finished())
        {
            self.settle(sink);
        }
    }

    /// Wait for a fit under way, take the pipeline back, pass on what it said and run the
    /// samples held meanwhile through it, until no fit is under way (the held samples may end
    /// another stretch). Nothing to do when none is. Called on the caller's thread: a reboot
    /// or the end of the input during a fit waits for it (up to the fit's time).
    pub fn settle(&mut self, sink: &mut dyn Sink) {
        while let Stage::Fitting(f) = &mut self.stage {
            let held = std::mem::take(&mut f.held);
            let Some(worker) = f.worker.take() else {
                return;
            };
            match worker.join() {
                Ok(Some((pipeline, said))) => {
                    *self = pipeline;
                    said.pass_on(sink);
                    for (s, info) in &held {
                        self.on_sample(s, info, sink);
                    }
                }
                _ => {
                    self.fail(
                        "the calibration's fit stopped on an internal error".into(),
                        sink,
                    );
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::PipelineConfig;
    use super::*;

    /// Everything a pipeline says, as text, in order.
    #[derive(Default)]
    struct Trace(Vec<String>);
    impl Sink for Trace {
        fn decision(&mut self, d: &Decision) {
            self.0.push(format!("{d:?}"));
        }
        fn estimates(&mut self, t: f64, sysid: u8, est: &[&[AhcEstimate]; 3], _: &Profile) {
            self.0.push(format!("{t} {sysid} {est:?}"));
        }
        fn message(&mut self, sysid: u8, text: &str) {
            self.0.push(format!("{sysid} {text}"));
        }
    }

    /// A quad in gusts whose motor 2 loses half its gain at 40 s, through a pipeline that fits
    /// in place and one that fits on a worker: the same decisions, estimates and messages in
    /// the same order, and the worker was used.
    #[test]
    fn a_fit_on_a_worker_says_what_a_fit_in_place_says() {
        let (profile, samples) = super::super::tests::gusty_quad(
            3500,
            vec![super::super::tests::motor2_loss_from(40.0)],
        );
        let pipeline = |background| {
            VehiclePipeline::new(
                1,
                PipelineConfig {
                    profile: Some(profile.clone()),
                    fit_in_background: background,
                    ..PipelineConfig::default()
                },
            )
        };
        let (mut in_place, mut worker) = (pipeline(false), pipeline(true));
        let (mut said_in_place, mut said_worker) = (Trace::default(), Trace::default());
        let info = VehicleInfo::default();
        let mut fitted_apart = false;
        for sample in &samples {
            in_place.on_sample(sample, &info, &mut said_in_place);
            worker.on_sample(sample, &info, &mut said_worker);
            fitted_apart |= matches!(worker.stage, Stage::Fitting(_));
        }
        worker.settle(&mut said_worker);
        assert!(fitted_apart, "the fit never ran on a worker");
        assert!(matches!(worker.stage, Stage::Running(_)));
        assert!(
            said_in_place.0.iter().any(|s| s.contains("Fault")),
            "the loss was not decided"
        );
        assert_eq!(said_in_place.0.len(), said_worker.0.len());
        for (a, b) in said_in_place.0.iter().zip(&said_worker.0) {
            assert_eq!(a, b);
        }
    }
}
