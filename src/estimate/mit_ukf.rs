//! MIT-UKF: the UKF with diag(Q) adapted by gradient *descent* on
//! `J_k = tr[(Ĉ_k - S_k)²]` (paper eq. 21-22; the printed sign ascends), using the recursive
//! sensitivity so that the AHC entries of Q adapt too.
//!
//! One refinement of ours ([DERIVED], documented in the README): the MIT rule holds Ĉ fixed, so
//! it cannot see that a larger AHC noise would make the filter *follow* a fault and shrink the
//! innovations; the cheapest explanation of a fault's large innovations is then always a larger
//! rate noise. Rate process noise is white and cannot produce an innovation *mean*, while a
//! lagging AHC estimate shows up as one. So S is split to first order into the AHC part
//! `S_ahc = Σ_{i ∈ AHC} q_i H M_i Hᵀ` and the rest: the AHC entries descend `tr[(μμᵀ - S_ahc)²]`
//! (μ: the windowed innovation mean) and the rate entries `tr[(Ĉ - μμᵀ - (S - S_ahc))²]`.
//! A noise step moves the spread, a fault the mean. Each gradient is still `-2 tr[D H M_i Hᵀ]`.

use super::linalg::SparseRows;
use super::mit::{
    AdaptationParams, GainTransition, InnovationWindow, Sandwich, Sensitivity, StepSchedule,
    gn_step, gradient_from, h_x_ht,
};
use super::{EstimatorError, Ukf, UkfParams, check_commands, check_inputs};
use crate::model::Model;
use nalgebra::{SMatrix, SVector};

#[derive(Debug, Clone)]
pub struct MitUkf<Mo, const N: usize, const M: usize, const S: usize> {
    pub ukf: Ukf<Mo, N, M, S>,
    pub adapt: AdaptationParams,
    pub window: InnovationWindow<M>,
    pub sensitivity: Sensitivity<N>,
    pub schedule: StepSchedule,
    /// Initial process noise: the reference for the projection box.
    pub q0: SVector<f64, N>,
    /// Entries the adaptation leaves at q0 (a fault mode the prior rules out, e.g. a motor's
    /// offset: letting a transient inflate it moves the estimate along the direction the
    /// data cannot see).
    pub fixed: [bool; N],
    /// Last gradient ∂J/∂q (for inspection and tests).
    pub gradient: SVector<f64, N>,
    /// `Σ q_i M_i` over the fixed entries. Their q_i never change, so the sum obeys the
    /// sensitivity recursion itself (`λ A S Aᵀ + Σ q_i E_ii`): one propagation instead of one
    /// per fixed entry. The fixed AHC entries still count in `S_ahc` through it.
    fixed_sum: SMatrix<f64, N, N>,
    steps: u64,
    /// Identification while a fault is in force (see [`MitUkf::set_fault_in_force`]); `None`
    /// (the default) adapts as in detection throughout.
    pub identify: Option<IdentifyParams>,
    /// Measured steps with a fault in force since the hold's delay last started (at the fault
    /// coming in force, a release or a new decision).
    in_force_steps: u64,
    /// The AHC entries of Q are being held at most at q0.
    identifying: bool,
    /// How many times identification was given up because the innovations' mean left what the
    /// noise can explain (a further change: the fault grew, or went away).
    pub releases: u64,
    /// AHC entries held at most at q0 even while not identifying: those of an actuator
    /// identified before a further decision (see `FilterPair::forget`).
    pub keep_capped: [bool; N],
}

/// When the MIT-UKF stops raising its gains' and biases' noise once a fault is decided.
///
/// The MIT rule raises an AHC's process noise so that the estimate follows a change quickly:
/// what detection needs. Once the diagnosis has decided the fault, the change is modelled by the
/// jump it adds to that actuator's covariance (`forget`), and what is left is estimating a
/// constant again: a noise still raised then makes every gain and bias follow the gusts (on the
/// simulated hexa's motor 3 loss, gamma beyond 0.05 of the truth on 46 % of the steps after
/// onset + 5 s, against 5 % held). So the AHC entries are capped at q0 (the MIT rule may still
/// lower them) from `after_steps` after the decision, until no fault is in force, a further
/// fault is decided, or the innovations show a further change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifyParams {
    /// Measured steps (lost samples do not count) from the fault decision to the hold: the
    /// onset's transient (the autopilot's answer to the change, the estimate's re-convergence
    /// after the jump) is over first, so that the hold does not weigh it for the rest of the
    /// fault.
    pub after_steps: u64,
    /// The hold ends (and its delay restarts) when `μᵀ S⁻¹ μ` of the window's innovation mean μ
    /// exceeds this, a chi-square quantile (the vehicles' filters take 99.99 %): with the
    /// filter's S right, noise of any colour does that on at most 0.01 % of windows (fully
    /// correlated over the window, μ is one draw of N(0, S); white, its spread is n times
    /// smaller).
    pub release_chi2: f64,
}

impl<Mo: Model<N, M>, const N: usize, const M: usize, const S: usize> MitUkf<Mo, N, M, S> {
    pub fn new(
        model: Mo,
        params: UkfParams,
        adapt: AdaptationParams,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        q0: SVector<f64, N>,
        r: SMatrix<f64, M, M>,
    ) -> Self {
        Self {
            ukf: Ukf::new(model, params, x0, p0, q0, r),
            window: InnovationWindow::new(adapt.window),
            adapt,
            sensitivity: Sensitivity::new(),
            schedule: StepSchedule::new(),
            q0,
            fixed: [false; N],
            gradient: SVector::zeros(),
            fixed_sum: SMatrix::zeros(),
            steps: 0,
            identify: None,
            in_force_steps: 0,
            identifying: false,
            releases: 0,
            keep_capped: [false; N],
        }
    }

    /// `A_k = F_k (I - K_{k-1} H)` with F at the previous estimate.
    pub(crate) fn sensitivity_transition(
        ukf: &Ukf<Mo, N, M, S>,
        u: &[f64],
    ) -> GainTransition<N, M> {
        GainTransition::new(&ukf.model.jacobian(&ukf.x, u), &ukf.gain, &ukf.h)
    }

    pub fn try_step(&mut self, u: &[f64], y: &SVector<f64, M>) -> Result<(), EstimatorError> {
        check_inputs(self.ukf.model.input_dim(), u, y)?;
        let a = Self::sensitivity_transition(&self.ukf, u);
        self.ukf.try_step(u, y)?;
        self.steps += 1;
        self.window.push(&self.ukf.innovation);
        let propagate_fixed_sum = self.propagate_sensitivities(&a);
        let ahc = self.ukf.model.ahc_start();
        self.schedule.observe(self.ukf.nis, M, &self.adapt);
        // The part of S the AHC noise accounts for (first order, from the sensitivities).
        let (h, sh) = (&self.ukf.h, SparseRows::new(&self.ukf.h));
        let hmh = self.sensitivity.projected_with(h, &sh, &self.fixed);
        let mut s_ahc = if propagate_fixed_sum {
            h_x_ht(h, &sh, &self.fixed_sum)
        } else {
            SMatrix::zeros()
        };
        for i in (ahc..N).filter(|&i| !self.fixed[i]) {
            s_ahc += hmh[i] * self.ukf.process_noise[i];
        }
        let mu = self.window.mean();
        if self.identifying {
            self.release_on_change(&mu);
        }
        let d_ahc = mu * mu.transpose() - s_ahc;
        let d_rates = self.window.centered_covariance() - (self.ukf.s - s_ahc);
        let (grad, curv) = gradient_from(&hmh, &d_rates, &d_ahc, ahc, &self.fixed);
        self.gradient = grad;
        // Warm-up: no adaptation until the window is full.
        if self.window.is_full() {
            let eta = self.schedule.eta(&self.adapt);
            for i in (0..N).filter(|&i| !self.fixed[i]) {
                let q = self.ukf.process_noise[i];
                let next = gn_step(q, grad[i], curv[i], eta, self.q0[i], &self.adapt);
                self.ukf.process_noise[i] = if (self.identifying || self.keep_capped[i]) && i >= ahc
                {
                    next.min(self.q0[i])
                } else {
                    next
                };
            }
        }
        Ok(())
    }

    /// Propagate the sensitivities (and the fixed entries' sum) over one prediction with
    /// transition `a`. Returns whether the fixed sum is in use: while no AHC entry is fixed and
    /// the sum is zero (never fixed, or `fixed` changed back) it stays zero and is skipped.
    fn propagate_sensitivities(&mut self, a: &GainTransition<N, M>) -> bool {
        self.sensitivity
            .propagate_masked(a, self.adapt.forgetting, &self.fixed);
        let ahc = self.ukf.model.ahc_start();
        let propagate_fixed_sum =
            (ahc..N).any(|i| self.fixed[i]) || self.fixed_sum.iter().any(|v| *v != 0.0);
        if propagate_fixed_sum {
            a.sandwich_in_place(&mut self.fixed_sum);
            self.fixed_sum *= self.adapt.forgetting;
            for i in (ahc..N).filter(|&i| self.fixed[i]) {
                self.fixed_sum[(i, i)] += self.ukf.process_noise[i];
            }
        }
        propagate_fixed_sum
    }

    /// A period without a measurement (lost on the link): the UKF's prediction, and the
    /// sensitivities carried through it (`dP⁻/dq` of two predictions in a row, with no update
    /// between). Nothing is observed, so the innovation window, the step-size schedule and the
    /// process noise stay as they are.
    pub fn coast(&mut self, u: &[f64]) -> Result<(), EstimatorError> {
        check_commands(self.ukf.model.input_dim(), u)?;
        let a = Self::sensitivity_transition(&self.ukf, u);
        self.ukf.coast(u)?;
        self.propagate_sensitivities(&a);
        Ok(())
    }

    /// [`Ukf::reseat`], with the sensitivities of what it sets: the re-measured rates no longer
    /// depend on q (their rows and columns are cleared), the rest carry `periods` more steps of
    /// their own entry.
    pub fn reseat(&mut self, rates: &[f64], var: &[f64], periods: f64) {
        self.carry_through_last_update();
        self.ukf.reseat(rates, var, periods);
        let k = rates.len().min(var.len()).min(N);
        self.clear_sensitivities_of(0..k);
        for (i, m) in self.sensitivity.m.iter_mut().enumerate() {
            if i >= k && !self.fixed[i] {
                m[(i, i)] += periods;
            }
        }
        for i in (k..N).filter(|&i| self.fixed[i]) {
            self.fixed_sum[(i, i)] += periods * self.ukf.process_noise[i];
        }
    }

    /// [`Ukf::reseat_entries`], with the sensitivities of what it sets cleared (they no longer
    /// depend on q), after carrying them through the last step's update as [`Self::reseat`]
    /// does.
    pub fn reseat_entries(&mut self, entries: &[(usize, f64, f64)]) {
        self.carry_through_last_update();
        let set = entries.iter().filter(|e| super::ukf::reseatable::<N>(e));
        self.clear_sensitivities_of(set.map(|e| e.0));
        self.ukf.reseat_entries(entries);
    }

    /// The sensitivities are of the last prediction (dP⁻/dq); a reseat starts from the
    /// updated covariance, so they are carried through that update first: (I - K H) M (I - K H)ᵀ
    /// (the identity after a coast or a reseat, whose gain is zero).
    fn carry_through_last_update(&mut self) {
        let update = GainTransition::new(&SMatrix::identity(), &self.ukf.gain, &self.ukf.h);
        for (i, m) in self.sensitivity.m.iter_mut().enumerate() {
            if !self.fixed[i] {
                update.sandwich_in_place(m);
            }
        }
        update.sandwich_in_place(&mut self.fixed_sum);
    }

    /// Coordinates set from outside no longer depend on q: their rows and columns of every
    /// sensitivity are cleared.
    fn clear_sensitivities_of(&mut self, coordinates: impl Iterator<Item = usize> + Clone) {
        for m in self.sensitivity.m.iter_mut().chain([&mut self.fixed_sum]) {
            for i in coordinates.clone() {
                for j in 0..N {
                    m[(i, j)] = 0.0;
                    m[(j, i)] = 0.0;
                }
            }
        }
    }

    /// Tell the filter, after each step's decisions, whether a fault is in force (see
    /// [`IdentifyParams`]). Does nothing unless `identify` is set.
    pub fn set_fault_in_force(&mut self, in_force: bool) {
        let Some(p) = self.identify else {
            return;
        };
        if !in_force {
            self.in_force_steps = 0;
            self.identifying = false;
            self.keep_capped = [false; N];
            return;
        }
        self.in_force_steps += 1;
        if !self.identifying && self.in_force_steps > p.after_steps {
            self.identifying = true;
            let ahc = self.ukf.model.ahc_start();
            for i in (ahc..N).filter(|&i| !self.fixed[i]) {
                self.ukf.process_noise[i] = self.ukf.process_noise[i].min(self.q0[i]);
            }
        }
    }

    /// A fault was decided (again): the change must be followed first, so the hold ends and its
    /// delay restarts.
    pub fn restart_identification(&mut self) {
        self.identifying = false;
        self.in_force_steps = 0;
    }

    /// Whether the AHC noise is being held (identification).
    pub fn identifying(&self) -> bool {
        self.identifying
    }

    /// End the hold when the windowed innovation mean `mu` is beyond what noise can explain.
    fn release_on_change(&mut self, mu: &SVector<f64, M>) {
        let Some(p) = self.identify else {
            return;
        };
        let Some(chol) = self.ukf.s.cholesky() else {
            return;
        };
        if chol.solve(mu).dot(mu) > p.release_chi2 {
            self.identifying = false;
            self.in_force_steps = 0;
            self.releases += 1;
        }
    }

    /// Restart the step-size schedule (called by diagnosis when a fault decision fires).
    pub fn restart_adaptation(&mut self) {
        self.schedule.restart();
    }
}

impl_estimator!(MitUkf<S>, "mit-ukf", [ukf], three_sigma);
