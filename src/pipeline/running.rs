//! The estimating stage: each sample's commands and rates become one step of both filters
//! and the diagnosis ([`Core::step`]). Lost samples are coasted over (short holes) or the
//! rates re-measured (long ones); an identified model's delayed commands and rate increments
//! are assembled here.

use super::calibrating::StoredSample;
use super::gusts::GustWatch;
use super::step::{Core, StepInput};
use super::{Stage, VehiclePipeline};
use crate::diagnose::decision::Decision;
use crate::diagnose::vehicle::{Diagnoser, Health};
use crate::estimate::vehicle::build;
use crate::model::MAX_ACTUATORS;
use crate::model::calibrate::ScaledFit;
use crate::output::Sink;
use crate::telemetry::{Profile, TelemetrySample};

/// Commands kept for an identified model's delay (samples).
pub(super) const U_HISTORY: usize = crate::telemetry::profile::MAX_ARX_DELAY + 1;
/// Longest hole in the samples the filters coast over, predicting each lost period with the last
/// outputs held (at 50 Hz: up to 5 lost samples). After a longer one the outputs over it are
/// too far from the held ones, and the filters' rates are re-measured instead (`reseat`). On the
/// simulated healthy plane with a hole every 2 s, coasting gave 0 false decisions over 0.12 s
/// holes but 2 over 0.16 s and 7 over 0.2 s ones, re-seating 0 for all; re-seating every hole
/// instead slows detection on a randomly lossy link (20 % of frames lost: the plane's elevator
/// fault found after 4.2 s, median, against 2.2 s). The diagnosis' change test keeps its
/// residuals across a hole coasted over or one lost sample, and starts over after a longer one.
const MAX_COAST_S: f64 = 0.13;

pub(super) struct Running {
    /// Both filters and the diagnosis, stepped as `eval` steps them.
    pub(super) core: Core,
    pub(super) dt: f64,
    pub(super) l: usize,
    pub(super) m: usize,
    pub(super) prev_u: Option<[f64; MAX_ACTUATORS]>,
    /// The commands of the last periods (ring) and how many were pushed since take-off or the
    /// last hole too long to coast over (coasts push the held outputs): an identified model
    /// takes them `delay` periods late.
    pub(super) u_history: [[f64; MAX_ACTUATORS]; U_HISTORY],
    pub(super) u_pushed: usize,
    pub(super) delay: usize,
    /// Steps since the last gap (the change test waits until the inputs are measured ones).
    pub(super) since_gap: usize,
    /// The last two measured rates (identified models take their increment).
    pub(super) rates_prev: [[f64; 3]; 2],
    pub(super) exogenous: bool,
    pub(super) last_t: f64,
    /// Rule T1 over the flight (where it applies): the gusts measured on every further stretch.
    pub(super) gusts: Option<GustWatch>,
}

impl Running {
    /// Push the outputs that act over the coming period into the command history; the
    /// filters' input for it: the commands that act now (`delay` periods late; until the
    /// history covers the delay the oldest stands in), then for an identified model the last
    /// rate increment.
    fn push_command(&mut self, u: [f64; MAX_ACTUATORS]) -> [f64; crate::model::MAX_INPUTS] {
        self.u_history[self.u_pushed % U_HISTORY] = u;
        self.u_pushed += 1;
        let back = self.delay.min(self.u_pushed - 1);
        let acting = self.u_history[(self.u_pushed - 1 - back) % U_HISTORY];
        let mut input = [0.0; crate::model::MAX_INPUTS];
        input[..self.l].copy_from_slice(&acting[..self.l]);
        if self.exogenous {
            for i in 0..3 {
                input[self.l + i] = self.rates_prev[1][i] - self.rates_prev[0][i];
            }
        }
        input
    }

    fn n_in(&self) -> usize {
        self.l + if self.exogenous { 3 } else { 0 }
    }
}

impl VehiclePipeline {
    /// A sample while estimating: one step of both filters and the diagnosis.
    pub(super) fn running(&mut self, s: &TelemetrySample, sink: &mut dyn Sink) {
        let Stage::Running(r) = &mut self.stage else {
            return;
        };
        let warned = &mut self.warned_missing_output;
        let Some(u) = Self::commands(
            &mut self.counters,
            warned,
            self.sysid,
            &r.core.profile,
            s,
            sink,
        ) else {
            return;
        };
        let mut y = [0.0; 4];
        y[..3].copy_from_slice(&s.rates);
        if r.m == 4 {
            match s.az {
                Some(a) => y[3] = a,
                None => {
                    // Skipped, before its outputs replace the previous ones: the next
                    // sample follows a gap (last_t stays), and the filters coast over
                    // this period with the outputs that acted in it.
                    self.counters.missing_az += 1;
                    return;
                }
            }
        }
        let Some(prev_u) = r.prev_u.replace(u) else {
            // A new take-off (or the first sample): no residual spans what came before.
            r.core.diag.residual_gap();
            r.last_t = s.t;
            r.u_pushed = 0;
            r.since_gap = 0;
            r.rates_prev = [s.rates; 2];
            return;
        };
        // The same limit as the calibration's: a lost sample is a gap.
        let span = s.t - r.last_t;
        let gap = span > 1.5 * r.dt;
        // After a hole the filters coast over: the mean rate increment over it, which
        // stands in for the unknown increment of the period ending at the next sample.
        let mut increment_after_hole = None;
        if gap {
            self.counters.gaps += 1;
            // The change test's residuals chain across a hole the filters coast over or one
            // lost sample (what a 10 Hz stream loses now and then); over a longer hole the wind
            // moves unseen, and its level after it would read as a change at the seam.
            if span.is_nan() || span > MAX_COAST_S.max(2.5 * r.dt) {
                r.core.diag.residual_gap();
            }
            r.since_gap = 0;
            if span <= MAX_COAST_S {
                // The filters predict over the lost periods, with the last outputs
                // held, so this measurement meets the state at its own time (stepping
                // across the hole as one period left its rate change to the gains).
                let lost = ((span / r.dt).round() as usize).saturating_sub(1);
                self.counters.coasted += lost as u64;
                tracing::trace!(
                    "sysid {}: {span:.3} s without a sample at t={:.2} s: {lost} periods coasted over",
                    self.sysid,
                    s.t
                );
                // An identified model's input is the last period's rate increment.
                // The first lost period's is the last one measured; the rest, and the
                // two periods that end at this sample and the next, are unknown: each
                // takes the mean increment over the hole, so that together they add
                // up to the measured change (the whole change as one period's
                // increment would read as a jump the actuators made).
                let last = r.rates_prev[1];
                let mean: [f64; 3] =
                    std::array::from_fn(|i| (s.rates[i] - last[i]) / (lost + 1) as f64);
                let after_first = [last, std::array::from_fn(|i| last[i] + mean[i])];
                for c in 0..lost {
                    let input = r.push_command(prev_u);
                    let n_in = r.n_in();
                    r.core.coast(s.t, &input[..n_in], &mut self.counters, sink);
                    if c == 0 {
                        r.rates_prev = after_first;
                    }
                }
                increment_after_hole = Some(mean);
            } else {
                // A long outage: the outputs over it are unknown, so the rates are
                // re-measured rather than predicted (stepped across as one period, the
                // rate change over the hole read as an actuator fault), and the command
                // history starts over. This sample only re-seats the filters.
                r.core.filters.reseat(&s.rates, (span / r.dt).round());
                self.counters.reseats += 1;
                tracing::debug!(
                    "sysid {}: {span:.3} s without a sample at t={:.2} s: the rates are re-measured",
                    self.sysid,
                    s.t
                );
                r.last_t = s.t;
                r.u_pushed = 0;
                r.rates_prev = [s.rates; 2];
                return;
            }
        }
        r.last_t = s.t;
        // The outputs sent at the previous instant act until this one.
        let input = r.push_command(prev_u);
        let n_in = r.n_in();
        let rates_before = r.rates_prev[1];
        r.rates_prev = match increment_after_hole {
            // The next increment is the hole's mean too (see above).
            Some(mean) => [std::array::from_fn(|i| s.rates[i] - mean[i]), s.rates],
            None => [r.rates_prev[1], s.rates],
        };
        let back = r.delay.min(r.u_pushed - 1);
        let prev_u = r.u_history[(r.u_pushed - 1 - back) % U_HISTORY];
        r.since_gap += 1;
        // Only once the commands that acted and the increment are measured ones, one
        // period apart (after a gap or take-off the delayed commands are held outputs or
        // stand-ins for `delay` steps, and an identified model's increment spans the gap
        // for one more).
        let own_inputs = r.since_gap > (r.delay + 1).max(if r.exogenous { 2 } else { 0 });
        let step = StepInput {
            t: s.t,
            input: &input[..n_in],
            y: &y[..r.m],
            acting: &prev_u[..r.l],
            attitude: s.attitude,
            residual_from: (!gap && own_inputs).then_some(&rates_before),
            set_az: s.az.filter(|_| r.m == 3),
        };
        r.core.step(&step, &mut self.counters, sink);
        if let Some(g) = &mut r.gusts {
            // Only measured samples after the calibration stretch (a catch-up runs over it).
            if s.t > g.from_t
                && let Some(factor) = g.push(s.t, s.rates, u, r.core.diag.fault_evidence_since())
            {
                r.core.diag.params.threshold = g.base_threshold * factor;
                if g.worth_saying(factor) {
                    sink.message(
                        self.sysid,
                        &format!(
                            "gusts measured again in flight ({:.0} s in {} stretches, the calibration's included): x{factor:.2} those the thresholds were set on; the deviation threshold is now {:.3} (rule T1)",
                            g.measured_s(),
                            g.stretches(),
                            r.core.diag.params.threshold
                        ),
                    );
                }
            }
        }
        for j in 0..r.l {
            self.active[j] = r.core.diag.active(j);
            self.health[j] = r.core.diag.health(j);
        }
        self.last = Some((s.t, r.core.est));
        if let Some(b) = &mut self.before_reboot {
            b.estimated_since = true;
        }
    }

    /// Build the filters and the diagnosis on `calibrated` and start estimating: first over the
    /// calibration stretch the model was fitted on, as far as it was kept (`catch_up`), else
    /// seeded with the stretch's end.
    pub(super) fn run_with(
        &mut self,
        calibrated: Profile,
        fit: Option<ScaledFit>,
        samples: &[StoredSample],
        dt: f64,
        sink: &mut dyn Sink,
    ) {
        let stretch = std::mem::take(&mut self.stretch);
        self.unsupported = false;
        self.fit = fit;
        if !self.start_stage(&calibrated, samples, dt, sink) {
            return;
        }
        if stretch.len() > 1 && !self.catch_up(&stretch, sink) {
            self.start_stage(&calibrated, samples, dt, sink);
        }
    }

    /// The filters and the diagnosis on the stretch they were fitted on, its decisions held back:
    /// they then start estimating at its end with what it taught them (the residuals' colour,
    /// the change test's store, the adapted noise, the bounds' persistence) instead of cold, so
    /// that a fault soon after the stretch is judged as one later is (a short flight's fault
    /// came before the diagnosis had learned anything). The stretch is healthy by the
    /// calibration's premise: when the diagnosis decides a fault or a suspect on it, its own
    /// model does not explain it, that is said, and the filters start cold at its end instead
    /// (false). Statements (low excitation, suspect: `Event::is_statement`) are passed on with
    /// their times; the counters stay those of the samples after the stretch.
    fn catch_up(&mut self, stretch: &[TelemetrySample], sink: &mut dyn Sink) -> bool {
        #[derive(Default)]
        struct Held(Vec<Decision>);
        impl Sink for Held {
            fn decision(&mut self, d: &Decision) {
                self.0.push(d.clone());
            }
        }
        let counters = self.counters;
        if let Stage::Running(r) = &mut self.stage {
            r.prev_u = None;
        }
        let mut held = Held::default();
        for s in stretch {
            self.running(s, &mut held);
        }
        self.counters = counters;
        let judged: Vec<&Decision> = held.0.iter().filter(|d| !d.event.is_statement()).collect();
        if let Some(first) = judged.first() {
            sink.message(
                self.sysid,
                &format!(
                    "warning: run over their own calibration stretch, the filters made {} decisions on it, the first {} on {} at t={:.2} s: the model explains the stretch loosely; estimating from its end without it",
                    judged.len(),
                    first.event.as_str(),
                    first.actuator.as_deref().unwrap_or("the vehicle"),
                    first.t
                ),
            );
            self.active = [None; MAX_ACTUATORS];
            self.health = [Health::Healthy; MAX_ACTUATORS];
            self.last = None;
            return false;
        }
        for d in &held.0 {
            self.counters.decisions += 1;
            sink.decision(d);
        }
        true
    }

    /// The estimating stage on `calibrated`, seeded with the end of the stored stretch: false
    /// (said) when the filters cannot be built.
    fn start_stage(
        &mut self,
        calibrated: &Profile,
        samples: &[StoredSample],
        dt: f64,
        sink: &mut dyn Sink,
    ) -> bool {
        let l = calibrated.actuators.len();
        let mut filters = match build(calibrated, dt) {
            Ok(f) => f,
            Err(e) => {
                self.fail(e.to_string(), sink);
                return false;
            }
        };
        let m = filters.measurements();
        let exogenous = filters.inputs() > l;
        let delay = calibrated.model.arx.as_ref().map_or(0, |a| a.delay);
        // An identified model's detectors take the rates only (`calibrating`: a static a_z row
        // cannot follow a helicopter's vertical response and would pull its estimates); the set
        // filter, whose bound of that row's error is measured on the stretch like the others',
        // takes a_z through it: without it a helicopter's three swash servos, which the rate
        // rows see only in combination, are not separable.
        if let Some(arx) = calibrated.model.arx.as_ref().filter(|_| m == 3)
            && let Some((gain, offset)) =
                super::set_bounds::vertical_row(&arx.vertical, samples, delay)
        {
            filters.set_vertical(Some((&gain, offset)));
        }
        // The set filter's bounds from this flight's healthy stretch (else the profile's
        // stated noise). A vertical row needs a_z on a run as long as the rates': without
        // one (a_z slower than the rates) the rates' bounds are measured without the row.
        let mut measured =
            super::set_bounds::measure(filters.as_ref(), samples, dt, delay, exogenous);
        if measured.is_none() && filters.set_rows() > filters.measurements() {
            filters.set_vertical(None);
            measured = super::set_bounds::measure(filters.as_ref(), samples, dt, delay, exogenous);
        }
        match measured {
            Some((bounds, command_ref)) => {
                tracing::debug!(sysid = self.sysid, ?bounds, "set filter: residual bounds per lag");
                filters.set_residual_bounds(bounds, command_ref)
            }
            None => sink.message(
                self.sysid,
                "the calibration stretch has no unbroken run of a second: the set filter's bounds are the profile's stated noise",
            ),
        }
        let mut diag = Diagnoser::new(self.cfg.diagnosis, self.sysid, calibrated, dt);
        let last = samples.last().map(|s| (s.t, s.u));
        // Rule T1: the deviation threshold raised by the gusts this flight's calibration
        // measured (said at the calibration), then by those measured again over the flight; a
        // profile used as identified has no fit, and none.
        let gusts = self.fit.as_ref().and_then(|f| {
            GustWatch::new(
                &calibrated.diagnosis,
                calibrated.rate_params(),
                &f.gusts,
                diag.params.threshold,
                samples.len(),
                dt,
                last.map_or(f64::NEG_INFINITY, |l| l.0),
            )
        });
        if let Some(g) = &gusts {
            diag.params.threshold *= g.factor;
        }
        if !self.failing_axes.is_empty() {
            let t = last.map_or(0.0, |l| l.0);
            let mut said = vec![];
            // The axes, why each fails, and what that leaves to do.
            let axes = ["roll", "pitch", "yaw"];
            let failing = format!(
                "the calibrated model does not explain {} on the calibration stretch ({:.1} Hz)",
                (self.failing_axes.iter())
                    .map(|f| format!("{} ({})", axes[f.axis], f.why))
                    .collect::<Vec<_>>()
                    .join(", "),
                1.0 / dt
            );
            let remedy = format!(
                "the profile ({}) may not be this vehicle's, the stream too slow for it, or the stretch not healthy flight; give the vehicle's profile (--profile, ahcmon calibrate)",
                calibrated.name
            );
            if diag.cannot_judge(t, &self.failing_axes, &mut said) == 0 {
                let why =
                    format!("{failing}, and every actuator acts mostly there (rule G2): {remedy}");
                // Nothing of this fit is to be kept (`ahcmon calibrate` writes none).
                (self.fit, self.arx) = (None, None);
                self.cannot_estimate(t, why, sink);
                return false;
            }
            if !std::mem::replace(&mut self.failing_said, true) {
                sink.message(
                    self.sysid,
                    &format!(
                        "warning: {failing}: the actuators acting mostly there are not judged (cannot_judge, rule G2); {remedy}"
                    ),
                );
                for d in &said {
                    self.counters.decisions += 1;
                    sink.decision(d);
                }
            }
        }
        // Seed the command history and the last rates with the end of the healthy stretch.
        let mut u_history = [[0.0; MAX_ACTUATORS]; U_HISTORY];
        let tail = &samples[samples.len().saturating_sub(U_HISTORY)..];
        // The newest stored command becomes `prev_u`; the ones before it are history.
        let older = &tail[..tail.len().saturating_sub(1)];
        for (k, s) in older.iter().enumerate() {
            u_history[k] = s.u;
        }
        let n = samples.len();
        let rates_prev = if n >= 2 {
            [samples[n - 2].rates, samples[n - 1].rates]
        } else {
            [[0.0; 3]; 2]
        };
        let why = format!(
            "{l} actuators, {m} measurements, a sample every {:.1} ms, command delay {delay}",
            dt * 1e3
        );
        let stage = Stage::Running(Box::new(Running {
            core: Core::new(calibrated.clone(), filters, diag, self.sysid),
            dt,
            l,
            m,
            prev_u: last.map(|l| l.1),
            u_history,
            u_pushed: older.len(),
            since_gap: older.len(),
            delay,
            rates_prev,
            exogenous,
            last_t: last.map_or(0.0, |l| l.0),
            gusts,
        }));
        self.set_stage(stage, &why);
        true
    }
}
