//! The per-step core: both filters, the diagnosis on their estimates, and the steering of
//! the filters by its decisions. It is the product's work per sample, and the one code that
//! runs it: the telemetry pipeline (`replay`, `monitor`) steps it on each sample it
//! assembles, `eval` on each simulator sample, so what `eval` scores is what the product
//! does. The callers differ only in what they pass: the inputs they assembled and whether
//! this step's residual may feed the change test (`residual_from`).
//!
//! One step, in this order (the order is behaviour: the diagnosis reads the filters' state
//! after their update, the filters are steered by the decisions of this step):
//! 1. both filters predict and update on `input` and `y`;
//! 2. the healthy model's residual of the step feeds the change test, when allowed;
//! 3. a filter whose update failed is re-initialised and the diagnosis told (said once a
//!    second as a `filter_reset` decision);
//! 4. the estimates are read, the diagnosis updated on them, its statistics copied back
//!    into the estimates;
//! 5. the sink gets the estimates, then the step's decisions;
//! 6. the decisions steer the filters (forget, hold a class).

use crate::diagnose::vehicle::{Decision, Diagnoser, Event};
use crate::estimate::EstimatorError;
use crate::estimate::vehicle::{AhcEstimate, FILTER_NAMES, VehicleFilters};
use crate::model::MAX_ACTUATORS;
use crate::output::Sink;
use crate::pipeline::PipelineCounters;
use crate::telemetry::Profile;

/// Both filters of one vehicle and the diagnosis on them.
pub struct Core {
    pub profile: Profile,
    pub filters: Box<dyn VehicleFilters>,
    pub diag: Diagnoser,
    sysid: u8,
    l: usize,
    /// The last step's estimates, per filter and actuator (the first `l` are the vehicle's):
    /// the two detectors', then the set filter's (`FILTER_NAMES`).
    pub est: [[AhcEstimate; MAX_ACTUATORS]; 3],
    /// The last step's decisions.
    pub decisions: Vec<Decision>,
    /// Per filter: when its last reset was reported, and resets since (a filter failing step
    /// after step is reported once a second, with the count).
    reset_reported: [(f64, u64); 2],
}

/// What one step estimates on.
pub struct StepInput<'a> {
    /// Vehicle time of the measurement (s).
    pub t: f64,
    /// The filters' inputs ([`VehicleFilters::inputs`] long): the commands acting over the
    /// period, then for an identified model the previous rate increment.
    pub input: &'a [f64],
    /// The measurement `[p, q, r(, a_z)]` at `t` ([`VehicleFilters::measurements`] long).
    pub y: &'a [f64],
    /// The actuators' commands acting over the period (one per actuator), as the diagnosis
    /// weighs them.
    pub acting: &'a [f64],
    /// The vehicle's attitude [roll, pitch, yaw] (rad) at `t`: whether it is still in its flight
    /// envelope (a crash's decisions are marked as such).
    pub attitude: [f64; 3],
    /// The measured rates one period before `y`, when this step's residual may feed the
    /// change test: the period was not a hole and its inputs are measured ones. `None` skips
    /// the change test for this step.
    pub residual_from: Option<&'a [f64; 3]>,
    /// a_z when the detectors take the rates only: the set filter's, where it has a vertical
    /// row ([`VehicleFilters::set_vertical`]).
    pub set_az: Option<f64>,
}

impl Core {
    pub fn new(
        profile: Profile,
        filters: Box<dyn VehicleFilters>,
        diag: Diagnoser,
        sysid: u8,
    ) -> Self {
        let l = filters.actuators();
        Self {
            profile,
            filters,
            diag,
            sysid,
            l,
            est: [[AhcEstimate::default(); MAX_ACTUATORS]; 3],
            decisions: Vec::with_capacity(8),
            reset_reported: [(f64::NEG_INFINITY, 0); 2],
        }
    }

    /// The last step's estimates of every filter, one per actuator.
    pub fn estimates(&self) -> [&[AhcEstimate]; 3] {
        let l = self.l;
        [&self.est[0][..l], &self.est[1][..l], &self.est[2][..l]]
    }

    /// One step (see the module's documentation). Returns, per filter, whether its update
    /// failed (it has been reset).
    pub fn step(
        &mut self,
        s: &StepInput,
        counters: &mut PipelineCounters,
        sink: &mut dyn Sink,
    ) -> [bool; 2] {
        let l = self.l;
        let mut with_az = [0.0; 4];
        let y = match s.set_az {
            Some(a) if s.y.len() == 3 && self.filters.set_rows() == 4 => {
                with_az[..3].copy_from_slice(s.y);
                with_az[3] = a;
                &with_az[..]
            }
            _ => s.y,
        };
        let res = self.filters.step(s.input, y);
        if let Some(rates_before) = s.residual_from {
            let residual = self.filters.healthy_residual(rates_before, s.input, s.y);
            self.diag.observe(s.t, &residual, s.acting);
        }
        counters.steps += 1;
        self.reset_failed(counters, s.t, &res, sink);
        for f in 0..2 {
            for j in 0..l {
                self.est[f][j] = self.filters.ahc(f, j);
            }
        }
        for j in 0..l {
            self.est[2][j] = self.filters.guaranteed(j);
        }
        let views = [&self.est[0][..l], &self.est[1][..l]];
        self.decisions.clear();
        let az = (s.y.len() > 3).then(|| s.y[3]);
        self.diag.envelope(s.t, s.attitude, az);
        self.diag.update(s.t, s.acting, &views, &mut self.decisions);
        for f in 0..2 {
            for j in 0..l {
                self.est[f][j].deviation = self.diag.deviation(f, j);
                self.est[f][j].excursion = self.diag.excursion(f, j);
                self.est[f][j].gain_gap = self.diag.gain_gap(f, j);
            }
        }
        let views = [&self.est[0][..l], &self.est[1][..l], &self.est[2][..l]];
        sink.estimates(s.t, self.sysid, &views, &self.profile);
        for d in &self.decisions {
            sink.decision(d);
            counters.decisions += 1;
        }
        self.diag
            .steer_filters(&self.decisions, &self.profile, self.filters.as_mut());
        [res[0].is_err(), res[1].is_err()]
    }

    /// Both filters over a lost period (prediction only, `input` as for [`Self::step`]); a
    /// filter that fails is reset as in a step. `t` is the sample that ends the hole.
    pub fn coast(
        &mut self,
        t: f64,
        input: &[f64],
        counters: &mut PipelineCounters,
        sink: &mut dyn Sink,
    ) {
        let res = self.filters.coast(input);
        self.reset_failed(counters, t, &res, sink);
    }

    /// A filter whose step (or coast) failed is re-initialised; said once a second, with the
    /// count since the last report.
    fn reset_failed(
        &mut self,
        counters: &mut PipelineCounters,
        t: f64,
        res: &[Result<(), EstimatorError>; 2],
        sink: &mut dyn Sink,
    ) {
        for (f, out) in res.iter().enumerate() {
            if out.is_ok() {
                continue;
            }
            counters.filter_errors += 1;
            self.filters.reset(f);
            // The fresh filter reads healthy at once: the diagnosis holds that filter's alarms
            // through a warm-up instead of clearing on it.
            self.diag.filter_reset(f, t);
            let (last, since) = &mut self.reset_reported[f];
            *since += 1;
            if t - *last >= 1.0 {
                let name = FILTER_NAMES[f];
                let detail = if *since > 1 {
                    format!("{name} update failed; reset ({since} resets since the last report)")
                } else {
                    format!("{name} update failed; reset")
                };
                let d = Decision::monitor(t, self.sysid, Event::FilterReset, detail);
                sink.decision(&d);
                counters.decisions += 1;
                (*last, *since) = (t, 0);
            }
        }
    }
}
