//! The two monitoring filters (MIT-UKF and MIT-ESMF, the detectors the diagnosis reads) and the
//! set-membership filter (the guaranteed bounds: `ahc_set`) on a vehicle's rate-effectiveness
//! model, behind one object-safe face so the rest of ahcmon does not care how many actuators a vehicle
//! has. Sizes are fixed at compile time (allocation-free steps); [`build`] picks the size that
//! fits the profile.

use super::ahc_set::{AhcSet, LAGS};
use super::{
    AdaptationParams, EsmfParams, Estimator, EstimatorError, IdentifyParams, MitEsmf, MitUkf,
    UkfParams,
};
use crate::model::{MAX_ACTUATORS, Model, RateModel, RateModelError};
use crate::telemetry::Profile;
use nalgebra::{SMatrix, SVector};
use thiserror::Error;

/// Filter names in the order of [`VehicleFilters`]' filter index: the two detectors, then the
/// set-membership filter ([`VehicleFilters::guaranteed`]).
pub const FILTER_NAMES: [&str; 3] = ["mit-ukf", "mit-esmf", "set"];

/// Initial 1σ uncertainty of the rates (rad/s), gamma and delta (normalised command).
pub const INITIAL_STD: [f64; 3] = [0.1, 0.1, 0.05];

#[derive(Debug, Error)]
pub enum BuildError {
    #[error(
        "{l} actuators with {m} measurements: this build has filters for 2, 3, 4, 6 or 8 actuators"
    )]
    Size { l: usize, m: usize },
    #[error(transparent)]
    Model(#[from] RateModelError),
}

/// Both monitoring filters of one vehicle.
pub trait VehicleFilters: Send {
    fn actuators(&self) -> usize;
    /// Inputs `step` takes: the actuators' commands, then (identified discrete models) the
    /// previous step's measured rate increment.
    fn inputs(&self) -> usize;
    fn measurements(&self) -> usize;
    /// One step of the filters. `u.len()` = [`VehicleFilters::inputs`] (the commands, then for
    /// an identified model the previous measured rate increment), `y` = [p, q, r(, a_z)]: with
    /// three measurements a fourth, a_z, goes to the set filter's vertical row alone.
    fn step(&mut self, u: &[f64], y: &[f64]) -> [Result<(), EstimatorError>; 2];
    /// Both filters over a period whose sample was lost: the prediction only, with the inputs
    /// that acted then (`u` as for `step`). Then the next `step` compares its measurement
    /// with the state at its own time instead of stepping one period across the hole.
    fn coast(&mut self, u: &[f64]) -> [Result<(), EstimatorError>; 2];
    /// Both filters after an outage too long to coast over: the rates are re-measured
    /// (`rates`, within the measurement noise) instead of predicted over outputs nobody saw,
    /// and the gains and biases keep their estimates, `periods` steps more uncertain.
    fn reseat(&mut self, rates: &[f64; 3], periods: f64);
    fn ahc(&self, filter: usize, j: usize) -> AhcEstimate;
    /// What the healthy model (gamma = 1, delta = 0) fails to predict of `y` from the previous
    /// measured rates and this step's inputs (same `u` as `step`): `[p, q, r(, a_z)]`, unweighted.
    fn healthy_residual(&self, rates_prev: &[f64; 3], u: &[f64], y: &[f64]) -> [f64; 4];
    /// The set filter's bounds of the healthy residual (lag 0) and of its changes over
    /// [`LAGS`], and each actuator's mean command, as a calibration stretch measured them; the
    /// set filter starts again from its a priori box.
    fn set_residual_bounds(
        &mut self,
        bounds: [[f64; 4]; LAGS.len()],
        command_ref: [f64; MAX_ACTUATORS],
    );
    /// Actuator `j`'s guaranteed estimate: the set-membership filter's.
    fn guaranteed(&self, j: usize) -> AhcEstimate;
    /// A static a_z row for the set filter when the detectors take the rates only (`g_z` per
    /// actuator, the trim; `None` takes it away): `step` then takes a fourth measurement, a_z,
    /// for the set alone, and `healthy_residual` its residual. It bounds once
    /// `set_residual_bounds` states its bound.
    fn set_vertical(&mut self, row: Option<(&[f64], f64)>);
    /// The rows of the set filter's residual: `measurements()`, or 4 with a vertical row.
    fn set_rows(&self) -> usize;
    /// The normalised innovation square (UKF) or `M (1 - consistency)` (ESMF) of the last step.
    fn nis(&self, filter: usize) -> f64;
    /// Re-initialise one filter (after repeated numerical failure).
    fn reset(&mut self, filter: usize);
    /// Forget what both filters knew about actuator `j`'s gain and bias (its prior uncertainty
    /// is added back) and restart the step-size schedules: called when a fault is decided on
    /// it, so the estimates re-converge from the data since the change instead of fading
    /// slowly from the healthy values. Another actuator whose identification was followed
    /// until then (or until a release at most 2 s before) goes back to its last fit, its noise
    /// capped at q0 while a fault is in force.
    fn forget(&mut self, j: usize);
    /// Whether a fault is in force, after every step's decisions: the MIT-UKF then moves from
    /// detection to identification ([`IdentifyParams`]).
    fn set_fault_in_force(&mut self, in_force: bool);
    /// Actuator `j`'s fault in force as the diagnosis identifies it from the data (`None`:
    /// not, or not yet), after a step's [`Self::set_fault_in_force`], when
    /// [`Self::awaits_identification`]. Hovering, a gain and an offset trade along `γ u + δ`,
    /// and the MIT-UKF, which takes the gusts for white noise, lets them pick its split and
    /// then wander with them (the gusts move the commands the controller makes against them);
    /// the change test reads the split from how the output follows the command, weighing the
    /// gusts' colour, over the samples since the change (at most its store's:
    /// `Diagnoser::identified`). So during the
    /// identification that follows a fault decision, each step the data clearly fit the kind
    /// of the class in force, the actuator's gamma and delta are reseated from that fit, of
    /// the kind first taken only: a later change of class is the diagnosis' to make, partly
    /// from these estimates, and following it would confirm it (a fit of another kind is
    /// ignored). After a clearing or a further decision the data's fit spans that change too,
    /// and it is not followed (a further decision puts an actuator followed until then back at
    /// its last fit: [`Self::forget`]). After a release (the innovations say a further change: the
    /// fault grew or went away, or a strong gust) the fit is followed again, once the
    /// identification resumes, only when it names the kind followed with the changed
    /// coefficient within the class's tolerance of the last fit (or 3σ of the two fits'
    /// spreads, if wider): a gust leaves the fit about where it was, a fault's end moves it.
    fn hold_class(&mut self, j: usize, identified: Option<Identified>);
    /// Whether [`Self::hold_class`] is asked for actuator `j` now (the MIT-UKF identifies after
    /// a decision on it, and no clearing or further decision has ended that since, nor a
    /// release before its fit was first followed; a fit of another kind than the one followed,
    /// or after a release one away from the last, is then still ignored): the diagnosis' fit
    /// is computed only then.
    fn awaits_identification(&self, j: usize) -> bool;
    /// Actuator `j`'s fault was cleared: the MIT-UKF's gamma and delta go back to the healthy
    /// point with their prior spread. The clearing says the effective output is healthy again
    /// at the operating point; in a still hover the data cannot move the fault's split of it
    /// back (gamma and delta stay traded along `γ u + δ`, bounds excluding the healthy point),
    /// and what is known of the split is what was known before the fault. The MIT-ESMF's set
    /// is left as it is.
    fn recovered(&mut self, j: usize);
    /// The kind of actuator `j`'s class in force (a loss a gain, a bias or a drift an offset,
    /// a stuck output; `None` for no fault or a class still open), before each step's
    /// [`Self::set_fault_in_force`]: after a release, the coefficient that class leaves
    /// unchanged stays at the last fit while the class stands.
    fn class_in_force(&mut self, j: usize, kind: Option<IdentifiedKind>);
}

/// A fault's coefficients as the diagnosis identifies them (see
/// [`VehicleFilters::hold_class`]), each with its standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identified {
    pub kind: IdentifiedKind,
    pub gamma: f64,
    pub gamma_std: f64,
    pub delta: f64,
    pub delta_std: f64,
    /// How far the changed coefficient may move and still read as this fault: the class's
    /// tolerance (what tells it from a healthy actuator). After a release the fit is followed
    /// again only within it of the last fit ([`VehicleFilters::hold_class`]).
    pub tolerance: f64,
}

/// What changed, as the diagnosis identifies it: the gain (a loss), the offset (a bias) or both
/// (a stuck output).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IdentifiedKind {
    Gain,
    Offset,
    Stuck,
}

/// Where an actuator's identification stands (see [`VehicleFilters::hold_class`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Following {
    /// No decision to identify (none, or its identification ended).
    Idle,
    /// Decided; no clear identification yet.
    Awaiting,
    /// Reseated from an identification of this kind, and held there while it stays clear.
    Kind(IdentifiedKind),
    /// Followed until a release: resumed once the data's fit again names this kind with the
    /// changed coefficient where the last fit had it.
    Released(IdentifiedKind),
}

/// Seconds from a fault decision to the MIT-UKF's identification (see [`IdentifyParams`]): the
/// change test's store must hold samples from after the onset's transient, whose split between
/// gain and offset is the controller's reaction, not the fault's (the figures:
/// docs/tuning-log.md).
const IDENTIFY_AFTER_S: f64 = 3.0;

/// Seconds from a release of the identification to a decision on another actuator within which
/// an actuator followed until that release keeps its last fit (`FilterPair::forget`), counted
/// in steps with a fault in force (lost samples do not count).
const RELEASE_TO_DECISION_S: f64 = 2.0;

#[path = "vehicle_estimate.rs"]
mod ahc_estimate;
pub use ahc_estimate::AhcEstimate;
use ahc_estimate::{estimate, set_estimate};

#[path = "vehicle_follow.rs"]
mod follow;
use follow::fit_entries;

#[path = "vehicle_setup.rs"]
mod setup;
pub use setup::{FilterSetup, SET_DRIFT_PER_S, build, residual_weights, weighted_effects};

/// MIT-UKF, MIT-ESMF and the set-membership filter of one size.
pub struct FilterPair<const N: usize, const M: usize, const S: usize> {
    pub ukf: MitUkf<RateModel<N, M>, N, M, S>,
    pub esmf: MitEsmf<RateModel<N, M>, N, M>,
    pub set: AhcSet<N, M>,
    setup: FilterSetup<N, M>,
    /// Per actuator, whether its identification is awaited or followed (see
    /// [`VehicleFilters::hold_class`]).
    following: [Following; MAX_ACTUATORS],
    /// Steps with a fault in force (`set_fault_in_force` calls), and per actuator that count
    /// when its followed identification was released.
    steps: u64,
    released_at: [u64; MAX_ACTUATORS],
    /// The last identification each followed actuator was reseated from.
    last_fit: [Option<Identified>; MAX_ACTUATORS],
    /// The kind of each actuator's class in force (`VehicleFilters::class_in_force`).
    class_kind: [Option<IdentifiedKind>; MAX_ACTUATORS],
    /// Whether the MIT-UKF identified after the last step's decisions.
    was_identifying: bool,
    /// A fault was decided in this step (cleared by `set_fault_in_force`, after the step's
    /// decisions).
    decided_this_step: bool,
}

impl<const N: usize, const M: usize, const S: usize> FilterPair<N, M, S> {
    pub fn new(setup: FilterSetup<N, M>) -> Self {
        let adapt = AdaptationParams::default();
        Self {
            ukf: Self::new_ukf(&setup, adapt),
            esmf: Self::new_esmf(&setup, adapt),
            set: Self::new_set(&setup),
            setup,
            following: [Following::Idle; MAX_ACTUATORS],
            steps: 0,
            released_at: [0; MAX_ACTUATORS],
            last_fit: [None; MAX_ACTUATORS],
            class_kind: [None; MAX_ACTUATORS],
            was_identifying: false,
            decided_this_step: false,
        }
    }

    fn new_ukf(s: &FilterSetup<N, M>, adapt: AdaptationParams) -> MitUkf<RateModel<N, M>, N, M, S> {
        // chi-square 99.9 % quantile with M degrees of freedom (3 or 4 measurements).
        let clip = if M == 4 { 18.47 } else { 16.27 };
        let mut f = MitUkf::new(
            s.model,
            UkfParams {
                innovation_clip_nis: clip,
                ..UkfParams::default()
            },
            adapt,
            s.x0,
            s.kalman_p0,
            s.kalman_q,
            s.kalman_r,
        );
        f.fixed = s.fixed;
        f.identify = Some(IdentifyParams {
            after_steps: (IDENTIFY_AFTER_S / Model::dt(&s.model)).round() as u64,
            // The chi-square 99.99 % quantile: held at the fit (`hold_class`), the filter no
            // longer takes the gusts into the held gain and bias, so their colour reaches the
            // window's mean; at 99.99 % coloured noise releases the hold on at most 0.01 % of
            // windows (see `IdentifyParams`), while a fault's end still releases it. The
            // measurements behind the choice are in docs/tuning-log.md.
            release_chi2: if M == 4 { 23.51 } else { 21.11 },
        });
        f
    }

    fn new_set(s: &FilterSetup<N, M>) -> AhcSet<N, M> {
        let l = (N - 3) / 2;
        let mut lo = [[0.0; 2]; MAX_ACTUATORS];
        let mut hi = [[0.0; 2]; MAX_ACTUATORS];
        for j in 0..l {
            for (c, i) in [3 + j, 3 + l + j].into_iter().enumerate() {
                lo[j][c] = s.box_centre[i] - s.box_half[i];
                hi[j][c] = s.box_centre[i] + s.box_half[i];
            }
        }
        let set = AhcSet::new(s.model, s.set_params, &lo[..l], &hi[..l]);
        match &s.set_vertical {
            Some((gain, offset)) => set.with_vertical(&gain[..l], *offset),
            None => set,
        }
    }

    fn new_esmf(s: &FilterSetup<N, M>, adapt: AdaptationParams) -> MitEsmf<RateModel<N, M>, N, M> {
        let mut f = MitEsmf::new(
            s.model,
            // The jump threshold was calibrated on the paper simulations' healthy runs; the
            // consistency of a vehicle's set on real telemetry (model mismatch) has its own
            // distribution, not calibrated yet, so vehicles keep the inflation-only policy.
            EsmfParams {
                jump_below: f64::NEG_INFINITY,
                ..EsmfParams::default()
            },
            adapt,
            s.x0,
            s.set_p0,
            s.set_q,
            s.set_r,
        );
        // Unlike the paper bank, the rate entries adapt here too (within the projection box):
        // on real vehicles they absorb unmodelled dynamics, which held at q0 (the default, see
        // the MIT-ESMF module note) would be blamed on healthy actuators.
        f.fixed = s.fixed;
        f.esmf.box_centre = s.box_centre;
        f.esmf.box_half = s.box_half;
        f
    }
}

impl<const N: usize, const M: usize, const S: usize> VehicleFilters for FilterPair<N, M, S> {
    fn actuators(&self) -> usize {
        (N - 3) / 2
    }
    fn measurements(&self) -> usize {
        M
    }
    fn inputs(&self) -> usize {
        use crate::model::Model;
        self.setup.model.input_dim()
    }
    fn step(&mut self, u: &[f64], y: &[f64]) -> [Result<(), EstimatorError>; 2] {
        // An a_z beyond the detectors' rows is the set filter's alone.
        let az = (M == 3 && y.len() == 4).then(|| y[3]);
        if y.len() != M && az.is_none() {
            let e = EstimatorError::InputDimension {
                expected: M,
                got: y.len(),
            };
            return [Err(e.clone()), Err(e)];
        }
        let y = SVector::<f64, M>::from_column_slice(&y[..M]);
        let (ukf, esmf) = (&mut self.ukf, &mut self.esmf);
        // The two filters are independent: inside a rayon pool (replay, eval) they run on two
        // cores; the calling thread takes the (heavier) set filter, so the other core has the
        // time it needs to pick up the UKF. Outside one (the live monitor at 50 Hz) handing
        // the work to the pool would cost more than it saves, so they run in turn.
        let out = if rayon::current_thread_index().is_some() {
            let (b, a) = rayon::join(|| esmf.try_step(u, &y).map(|_| ()), || ukf.try_step(u, &y));
            [a, b]
        } else {
            [ukf.try_step(u, &y), esmf.try_step(u, &y).map(|_| ())]
        };
        // The set filter's own failure (non-finite arithmetic) restarts it from its box.
        let _ = self.set.try_step_az(u, &y, az);
        out
    }
    fn coast(&mut self, u: &[f64]) -> [Result<(), EstimatorError>; 2] {
        let _ = self.set.coast(u);
        [self.ukf.coast(u), self.esmf.coast(u)]
    }
    fn reseat(&mut self, rates: &[f64; 3], periods: f64) {
        let (r, sr) = (&self.setup.kalman_r, &self.setup.set_r);
        self.ukf
            .reseat(rates, &[r[(0, 0)], r[(1, 1)], r[(2, 2)]], periods);
        self.esmf
            .reseat(rates, &[sr[(0, 0)], sr[(1, 1)], sr[(2, 2)]], periods);
        self.set.reseat(rates, periods);
    }
    fn healthy_residual(&self, rates_prev: &[f64; 3], u: &[f64], y: &[f64]) -> [f64; 4] {
        use crate::model::Model;
        let model = &self.setup.model;
        let mut out = [f64::NAN; 4];
        let vertical = self.setup.set_vertical.filter(|_| M == 3 && y.len() == 4);
        if (y.len() != M && vertical.is_none()) || u.len() != model.input_dim() {
            return out;
        }
        let predicted = model.f(&model.healthy_state(*rates_prev), u);
        for i in 0..3 {
            out[i] = y[i] - predicted[i];
        }
        if let Some((gain, offset)) = vertical {
            let l = self.actuators();
            out[3] = y[3] - offset - (0..l).map(|j| gain[j] * u[j]).sum::<f64>();
            return out;
        }
        if M == 4 {
            let now = model.healthy_state([y[0], y[1], y[2]]);
            let h = model.h_matrix(u) * now + model.h_offset(u);
            out[3] = y[3] - h[3];
        } else {
            out[3] = 0.0;
        }
        out
    }
    fn set_residual_bounds(
        &mut self,
        bounds: [[f64; 4]; LAGS.len()],
        command_ref: [f64; MAX_ACTUATORS],
    ) {
        self.setup.set_params.residual_bound = bounds;
        self.setup.set_params.command_ref = command_ref;
        self.set = Self::new_set(&self.setup);
    }
    fn guaranteed(&self, j: usize) -> AhcEstimate {
        set_estimate(&self.set, j)
    }
    fn set_vertical(&mut self, row: Option<(&[f64], f64)>) {
        let l = self.actuators();
        self.setup.set_vertical = row.filter(|_| M == 3).map(|(gain, offset)| {
            let mut g = [0.0; MAX_ACTUATORS];
            let n = l.min(gain.len());
            g[..n].copy_from_slice(&gain[..n]);
            (g, offset)
        });
        self.set = Self::new_set(&self.setup);
    }
    fn set_rows(&self) -> usize {
        self.set
            .rows()
            .max(self.setup.set_vertical.map_or(M, |_| 4))
    }
    fn ahc(&self, filter: usize, j: usize) -> AhcEstimate {
        let l = self.actuators();
        if filter == 0 {
            estimate(&self.ukf, &self.ukf.ukf.p, l, j)
        } else {
            estimate(&self.esmf, &self.esmf.esmf.p, l, j)
        }
    }
    fn nis(&self, filter: usize) -> f64 {
        if filter == 0 {
            self.ukf.ukf.nis
        } else {
            M as f64 * (1.0 - self.esmf.esmf.last.consistency)
        }
    }
    fn forget(&mut self, j: usize) {
        let l = self.actuators();
        let (gi, di) = (3 + j, 3 + l + j);
        let p = &mut self.ukf.ukf.p;
        p[(gi, gi)] += self.setup.kalman_p0[(gi, gi)];
        p[(di, di)] += self.setup.kalman_p0[(di, di)];
        // A further change ends the identification of an actuator decided earlier, awaited or
        // followed: its fit would span this change too (as after a release). Several decided
        // in one step all wait. One followed until this change or the release before it (the
        // innovations see a change some steps before it is decided) was not what changed: it
        // goes back to its last fit, and its noise stays capped at q0 while the fault is in
        // force: released alone, the MIT rule raised it with the rest, and the filter put part
        // of the new change into it. Kept at any release, it would hold the gain of a fault
        // that had gone away.
        if !self.decided_this_step {
            // A release longer ago than this was not this change's (the innovations see a change
            // at most about a second before it is decided): it may be the followed fault's end.
            let recent = (RELEASE_TO_DECISION_S / Model::dt(&self.setup.model)) as u64;
            for k in (0..l).filter(|&k| k != j) {
                let kept = match self.following[k] {
                    Following::Kind(_) => true,
                    Following::Released(_) => self.steps - self.released_at[k] <= recent,
                    _ => false,
                };
                let Some(c) = self.last_fit[k].filter(|_| kept) else {
                    continue;
                };
                for i in [3 + k, 3 + l + k] {
                    self.ukf.keep_capped[i] = true;
                    let q = &mut self.ukf.ukf.process_noise[i];
                    *q = q.min(self.ukf.q0[i]);
                }
                self.ukf.reseat_entries(&fit_entries(k, l, &c));
            }
            self.following = [Following::Idle; MAX_ACTUATORS];
        }
        self.ukf.keep_capped[gi] = false;
        self.ukf.keep_capped[di] = false;
        self.decided_this_step = true;
        self.ukf.restart_adaptation();
        self.ukf.restart_identification();
        if let Some(a) = self.following.get_mut(j) {
            *a = Following::Awaiting;
        }
        // Ended here for the decision, not by a change or the fault's end.
        self.was_identifying = false;
        super::esmf::add_jump_set_on(&mut self.esmf.esmf.p, &self.setup.set_p0, &[gi, di]);
        self.esmf.esmf.intersect_box();
        self.esmf.schedule.restart();
        self.set.forget(j);
    }
    fn set_fault_in_force(&mut self, in_force: bool) {
        self.ukf.ukf.consider = [false; N];
        self.ukf.set_fault_in_force(in_force);
        self.decided_this_step = false;
        // A release (a further change, the fault gone, or a gust) ends the following until the
        // data's fit agrees with the last one again (`hold_class`): the fit then spans the
        // change too, and followed regardless it would hold a loss's gain after the fault went
        // away. Resumed once the fit agrees again, a gust's release does not leave the estimate
        // off for the rest of the fault.
        let now = self.ukf.identifying();
        if in_force {
            self.steps += 1;
        }
        if self.was_identifying && !now {
            for (f, at) in self.following.iter_mut().zip(&mut self.released_at) {
                *f = match *f {
                    Following::Kind(k) => {
                        *at = self.steps;
                        Following::Released(k)
                    }
                    Following::Released(k) => Following::Released(k),
                    _ => Following::Idle,
                };
            }
        }
        if !in_force {
            self.following = [Following::Idle; MAX_ACTUATORS];
        }
        // While followed, the updates leave a decided actuator's gain and bias at the last
        // clear fit too (`hold_class`): on a hovering motor the data tell a gain from an offset
        // only now and then, and between those fits the filter's updates moved the gain of
        // a motor's offset away from 1, its bounds excluding 1.
        let l = (N - 3) / 2;
        for k in 0..l {
            match self.following[k] {
                Following::Kind(_) if now => self.consider_last_fit(k),
                Following::Released(kind) if self.class_kind[k] == Some(kind) => {
                    self.hold_unchanged(k, kind)
                }
                _ => {}
            }
        }
        self.was_identifying = now;
    }
    fn hold_class(&mut self, j: usize, identified: Option<Identified>) {
        let l = self.actuators();
        let Some(c) = identified.filter(|_| self.awaits_identification(j)) else {
            return;
        };
        // Another kind than the one followed is the diagnosis' to decide, partly from these
        // estimates: following it would confirm it.
        if matches!(self.following[j], Following::Kind(k) if k != c.kind) {
            return;
        }
        if let Following::Released(k) = self.following[j] {
            let consistent = self.last_fit[j].is_some_and(|last| {
                // A mild fault's end moves its fit within the class tolerance: at most half way
                // to the healthy value (gamma 1, delta 0) counts.
                let (now, then, healthy) = match k {
                    IdentifiedKind::Gain => {
                        ((c.gamma, c.gamma_std), (last.gamma, last.gamma_std), 1.0)
                    }
                    _ => ((c.delta, c.delta_std), (last.delta, last.delta_std), 0.0),
                };
                let within = last.tolerance.min(0.5 * (then.0 - healthy).abs());
                (now.0 - then.0).abs() <= (3.0 * now.1.hypot(then.1)).max(within)
            });
            if k != c.kind || !consistent {
                return;
            }
        }
        self.following[j] = Following::Kind(c.kind);
        self.last_fit[j] = Some(c);
        self.consider_last_fit(j);
        // The updates leave them at the identification (consider states; on every step while
        // followed: `set_fault_in_force`): the filter, taking the gusts for white noise, weighs
        // each sample as if it were independent of those the fit has already weighed with
        // their colour, and would move a gain reseated at the fit by the gusts' whole colour in
        // the step after a reseat (the figures are in docs/tuning-log.md).
        self.ukf.reseat_entries(&fit_entries(j, l, &c));
    }
    fn recovered(&mut self, j: usize) {
        let l = self.actuators();
        if j >= l {
            return;
        }
        let (gi, di) = (3 + j, 3 + l + j);
        self.following[j] = Following::Idle;
        self.ukf.keep_capped[gi] = false;
        self.ukf.keep_capped[di] = false;
        let (x0, p0) = (&self.setup.x0, &self.setup.kalman_p0);
        self.ukf
            .reseat_entries(&[(gi, x0[gi], p0[(gi, gi)]), (di, x0[di], p0[(di, di)])]);
    }
    fn class_in_force(&mut self, j: usize, kind: Option<IdentifiedKind>) {
        if let Some(k) = self.class_kind.get_mut(j) {
            *k = kind;
        }
    }
    fn awaits_identification(&self, j: usize) -> bool {
        self.ukf.identifying() && self.following.get(j).is_some_and(|f| *f != Following::Idle)
    }
    fn reset(&mut self, filter: usize) {
        let adapt = AdaptationParams::default();
        if filter == 0 {
            self.ukf = Self::new_ukf(&self.setup, adapt);
            // A fresh MIT-UKF identifies nothing until the next decision.
            self.following = [Following::Idle; MAX_ACTUATORS];
            self.was_identifying = false;
        } else {
            self.esmf = Self::new_esmf(&self.setup, adapt);
            self.set.restart();
        }
    }
}

#[cfg(test)]
#[path = "vehicle_tests.rs"]
mod tests;
