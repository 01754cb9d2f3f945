//! Parts shared by the MIT-rule and KF-based adaptive filters: the windowed innovation
//! covariance, the recursive sensitivity of the predicted covariance to each process-noise
//! entry, and the step-size schedule with restart and floor.

use super::linalg::{
    SMALL_N, SparseRows, identity_tail_start, sandwich_gain, sandwich_gain_in_place, sandwich_walk,
    sandwich_walk_in_place,
};
use nalgebra::{SMatrix, SVector};

/// Largest window the ring buffer holds (the window length itself is a runtime parameter).
pub const MAX_WINDOW: usize = 256;

/// Tuning of the adaptive process noise, shared by MIT-UKF, KF-UKF and MIT-ESMF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdaptationParams {
    /// Innovation window N (steps). The relative std of a windowed variance is √(2/N).
    pub window: usize,
    /// Forgetting factor of the recursive sensitivity (keeps it bounded when an actuator is unexcited).
    pub forgetting: f64,
    /// Step size: eta_k = max(eta_min, eta0 / (1 + j/j0)^decay), j = steps since the last restart.
    pub eta0: f64,
    pub j0: f64,
    pub decay: f64,
    pub eta_min: f64,
    /// Projection box for each q_i, as factors of its initial value.
    pub q_min_factor: f64,
    pub q_max_factor: f64,
    /// Largest change of ln q_i in one step.
    pub max_log_step: f64,
    /// CUSUM on the normalised innovation squared that restarts the schedule: drift and threshold.
    pub nis_drift: f64,
    pub nis_threshold: f64,
}

impl Default for AdaptationParams {
    fn default() -> Self {
        Self {
            window: 25,
            forgetting: 1.0 - 1.0 / 25.0,
            eta0: 0.2,
            j0: 100.0,
            decay: 0.75,
            eta_min: 0.02,
            q_min_factor: 1e-3,
            q_max_factor: 1e3,
            max_log_step: std::f64::consts::LN_2,
            nis_drift: 1.0,
            nis_threshold: 25.0,
        }
    }
}

/// Ring buffer of the last `window` innovations and their sample covariance `Ĉ_k`.
#[derive(Debug, Clone)]
pub struct InnovationWindow<const M: usize> {
    buf: [SVector<f64, M>; MAX_WINDOW],
    window: usize,
    head: usize,
    count: usize,
    sum: SMatrix<f64, M, M>,
    sum_e: SVector<f64, M>,
}

impl<const M: usize> InnovationWindow<M> {
    pub fn new(window: usize) -> Self {
        Self {
            buf: [SVector::zeros(); MAX_WINDOW],
            window: window.clamp(1, MAX_WINDOW),
            head: 0,
            count: 0,
            sum: SMatrix::zeros(),
            sum_e: SVector::zeros(),
        }
    }

    pub fn push(&mut self, e: &SVector<f64, M>) {
        if self.count == self.window {
            let old = self.buf[self.head];
            self.sum -= old * old.transpose();
            self.sum_e -= old;
        } else {
            self.count += 1;
        }
        self.buf[self.head] = *e;
        self.sum += e * e.transpose();
        self.sum_e += e;
        self.head = (self.head + 1) % self.window;
    }

    /// `Ĉ_k`: the mean of e eᵀ over the window (over the samples so far before it is full).
    pub fn covariance(&self) -> SMatrix<f64, M, M> {
        if self.count == 0 {
            SMatrix::zeros()
        } else {
            self.sum / self.count as f64
        }
    }

    /// The windowed innovation mean.
    pub fn mean(&self) -> SVector<f64, M> {
        if self.count == 0 {
            SVector::zeros()
        } else {
            self.sum_e / self.count as f64
        }
    }

    /// `Ĉ_k - μ μᵀ`: the spread of the innovations about their windowed mean.
    pub fn centered_covariance(&self) -> SMatrix<f64, M, M> {
        let mu = self.mean();
        self.covariance() - mu * mu.transpose()
    }

    pub fn is_full(&self) -> bool {
        self.count == self.window
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

/// A linear map `X ↦ A X Aᵀ` on symmetric matrices (the sensitivity recursion's transition).
pub trait Sandwich<const N: usize> {
    fn sandwich(&self, x: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N>;
    /// `x ← A x Aᵀ`, the same numbers as [`Sandwich::sandwich`].
    fn sandwich_in_place(&self, x: &mut SMatrix<f64, N, N>) {
        *x = self.sandwich(x);
    }
}

impl<const N: usize> Sandwich<N> for SMatrix<f64, N, N> {
    fn sandwich(&self, x: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
        self * x * self.transpose()
    }
}

/// `A = F (I - K H)` kept in its factors: `F` is the identity below its rate rows and `H` is
/// sparse, so `A X Aᵀ = F (G X Gᵀ) Fᵀ` costs about 60 % of the dense product at n = 11.
#[derive(Debug, Clone, Copy)]
pub struct GainTransition<const N: usize, const M: usize> {
    f: SMatrix<f64, N, N>,
    walk_from: usize,
    k: SMatrix<f64, N, M>,
    h: SparseRows<M, N>,
    /// `A` itself for small N, where nalgebra's unrolled dense product is faster.
    dense: Option<SMatrix<f64, N, N>>,
}

impl<const N: usize, const M: usize> GainTransition<N, M> {
    pub fn new(f: &SMatrix<f64, N, N>, k: &SMatrix<f64, N, M>, h: &SMatrix<f64, M, N>) -> Self {
        let dense = (N <= SMALL_N).then(|| f * (SMatrix::<f64, N, N>::identity() - k * h));
        Self {
            f: *f,
            walk_from: identity_tail_start(f),
            k: *k,
            h: SparseRows::new(h),
            dense,
        }
    }

    /// `A` as a dense matrix.
    pub fn matrix(&self) -> SMatrix<f64, N, N> {
        let h = self.h.left(&SMatrix::<f64, N, N>::identity());
        self.f * (SMatrix::<f64, N, N>::identity() - self.k * h)
    }
}

impl<const N: usize, const M: usize> Sandwich<N> for GainTransition<N, M> {
    fn sandwich(&self, x: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N> {
        match &self.dense {
            Some(a) => a * x * a.transpose(),
            None => sandwich_walk(&self.f, &sandwich_gain(x, &self.k, &self.h), self.walk_from),
        }
    }
    fn sandwich_in_place(&self, x: &mut SMatrix<f64, N, N>) {
        match &self.dense {
            Some(a) => *x = a * *x * a.transpose(),
            None => {
                sandwich_gain_in_place(x, &self.k, &self.h);
                sandwich_walk_in_place(&self.f, x, self.walk_from);
            }
        }
    }
}

/// `M_i,k = ∂P⁻_k/∂q_i`, propagated as `M_i,k = λ A_k M_i,k-1 A_kᵀ + E_ii` with
/// `A_k = F_k (I - K_{k-1} H)` (gains held fixed: first-order exact at the optimal gain).
/// The one-step version (`M_i = E_ii`) has a zero gradient for every AHC entry, because the
/// measurement sees no AHC directly; the recursion carries the AHC noise into the rates.
#[derive(Debug, Clone)]
pub struct Sensitivity<const N: usize> {
    pub m: [SMatrix<f64, N, N>; N],
}

impl<const N: usize> Default for Sensitivity<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Sensitivity<N> {
    /// Start at `M_i,0 = 0` (no history yet).
    pub fn new() -> Self {
        Self {
            m: [SMatrix::zeros(); N],
        }
    }

    pub fn propagate(&mut self, a: &impl Sandwich<N>, forgetting: f64) {
        self.propagate_masked(a, forgetting, &[false; N]);
    }

    /// [`Sensitivity::propagate`] for the entries not in `skip` (theirs stay as they are).
    pub fn propagate_masked(&mut self, a: &impl Sandwich<N>, forgetting: f64, skip: &[bool; N]) {
        for (i, m) in self.m.iter_mut().enumerate().filter(|(i, _)| !skip[*i]) {
            a.sandwich_in_place(m);
            *m *= forgetting;
            m[(i, i)] += 1.0;
        }
    }

    /// `∂J/∂q_i = -2 tr[D H M_i Hᵀ]` for `J = tr[(Ĉ - S)²]`, `D = Ĉ - S`, together with the
    /// Gauss–Newton curvature `2 ‖H M_i Hᵀ‖²_F` of J along q_i. Entries `i < ahc_start` (rates)
    /// use `d_rates`, the AHC entries `d_ahc` (see [`MitUkf`](super::MitUkf) for why they differ).
    pub fn gradient<const M: usize>(
        &self,
        h: &SMatrix<f64, M, N>,
        d_rates: &SMatrix<f64, M, M>,
        d_ahc: &SMatrix<f64, M, M>,
        ahc_start: usize,
    ) -> (SVector<f64, N>, SVector<f64, N>) {
        let none = [false; N];
        gradient_from(&self.projected(h, &none), d_rates, d_ahc, ahc_start, &none)
    }

    /// `H M_i Hᵀ` for every entry not in `skip` (zero for those).
    pub fn projected<const M: usize>(
        &self,
        h: &SMatrix<f64, M, N>,
        skip: &[bool; N],
    ) -> [SMatrix<f64, M, M>; N] {
        self.projected_with(h, &SparseRows::new(h), skip)
    }

    /// [`Sensitivity::projected`] with `H`'s nonzeros already gathered.
    pub fn projected_with<const M: usize>(
        &self,
        h: &SMatrix<f64, M, N>,
        sh: &SparseRows<M, N>,
        skip: &[bool; N],
    ) -> [SMatrix<f64, M, M>; N] {
        let mut out = [SMatrix::<f64, M, M>::zeros(); N];
        for (i, o) in out.iter_mut().enumerate().filter(|(i, _)| !skip[*i]) {
            *o = h_x_ht(h, sh, &self.m[i]);
        }
        out
    }
}

/// `H X Hᵀ`: sparse, except for small models, where nalgebra's unrolled dense product is faster.
pub fn h_x_ht<const M: usize, const N: usize>(
    h: &SMatrix<f64, M, N>,
    sh: &SparseRows<M, N>,
    x: &SMatrix<f64, N, N>,
) -> SMatrix<f64, M, M> {
    if let Some(block) = sh.picked(x) {
        block
    } else if N <= SMALL_N {
        h * x * h.transpose()
    } else {
        sh.left(&sh.right_t(x))
    }
}

/// [`Sensitivity::gradient`] from the projected sensitivities `H M_i Hᵀ` (0 for `skip`).
pub fn gradient_from<const N: usize, const M: usize>(
    hmh: &[SMatrix<f64, M, M>; N],
    d_rates: &SMatrix<f64, M, M>,
    d_ahc: &SMatrix<f64, M, M>,
    ahc_start: usize,
    skip: &[bool; N],
) -> (SVector<f64, N>, SVector<f64, N>) {
    let mut g = SVector::<f64, N>::zeros();
    let mut curv = SVector::<f64, N>::zeros();
    for i in (0..N).filter(|&i| !skip[i]) {
        let d = if i < ahc_start { d_rates } else { d_ahc };
        g[i] = -2.0 * d.dot(&hmh[i]);
        curv[i] = 2.0 * hmh[i].norm_squared();
    }
    (g, curv)
}

/// Robbins–Monro step size with restart on a detected change and a floor for tracking.
/// The floor deliberately breaks Σ η² < ∞: a step size that decays to 0 cannot follow a
/// process noise that changes (paper: fault at 10 s, noise step at 20 s).
#[derive(Debug, Clone)]
pub struct StepSchedule {
    pub since_restart: u64,
    cusum: f64,
    pub restarts: u64,
}

impl Default for StepSchedule {
    fn default() -> Self {
        Self::new()
    }
}

impl StepSchedule {
    pub fn new() -> Self {
        Self {
            since_restart: 0,
            cusum: 0.0,
            restarts: 0,
        }
    }

    pub fn eta(&self, p: &AdaptationParams) -> f64 {
        let j = self.since_restart as f64;
        (p.eta0 / (1.0 + j / p.j0).powf(p.decay)).max(p.eta_min)
    }

    /// Feed the NIS of this step (`m` measurements); restarts the schedule on a CUSUM alarm.
    pub fn observe(&mut self, nis: f64, m: usize, p: &AdaptationParams) {
        self.since_restart += 1;
        if nis.is_finite() {
            self.cusum = (self.cusum + nis - m as f64 - p.nis_drift).max(0.0);
        }
        if self.cusum > p.nis_threshold {
            self.restart();
        }
    }

    pub fn restart(&mut self) {
        self.since_restart = 0;
        self.cusum = 0.0;
        self.restarts += 1;
    }
}

/// Projected diagonal Gauss–Newton descent step on one q_i: `q ← q - η g / curvature`, the
/// change of q_i that alone would remove the part of the mismatch it can explain, scaled by η.
/// Scale-free per entry (q_rates ~ 1e-4 and q_delta ~ 1e-9 move alike); the change of ln q is
/// capped per step and q is projected onto [q_min, q_max] (positivity).
pub fn gn_step(q: f64, grad: f64, curvature: f64, eta: f64, q0: f64, p: &AdaptationParams) -> f64 {
    if !(grad.is_finite() && curvature.is_finite() && curvature > 0.0) {
        return q;
    }
    let target = q - eta * grad / curvature;
    let (lo, hi) = (q * (-p.max_log_step).exp(), q * p.max_log_step.exp());
    target
        .clamp(lo, hi)
        .clamp(q0 * p.q_min_factor, q0 * p.q_max_factor)
}

/// Projected multiplicative step `q ← clamp(q·exp(-η ∂ln J/∂ln q))` with `∂ln J/∂ln q = q g / J`:
/// the elasticity of the loss, scale-free; used by the MIT-ESMF, whose loss has no
/// least-squares structure.
pub fn log_step(q: f64, grad: f64, eta: f64, loss: f64, q0: f64, p: &AdaptationParams) -> f64 {
    if !(grad.is_finite() && loss.is_finite() && loss > 0.0) {
        return q;
    }
    let step = (-eta * q * grad / loss).clamp(-p.max_log_step, p.max_log_step);
    (q * step.exp()).clamp(q0 * p.q_min_factor, q0 * p.q_max_factor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factored_transition_matches_the_dense_product() {
        // F: identity below three mixing rows; H: three unit rows and one on the AHCs.
        let mut f = SMatrix::<f64, 11, 11>::identity();
        let mut h = SMatrix::<f64, 4, 11>::zeros();
        for c in 0..11 {
            for r in 0..3 {
                f[(r, c)] = ((r * 5 + c * 3) as f64 * 0.37).sin();
            }
            if c >= 3 {
                h[(3, c)] = (c as f64 * 0.7).cos();
            }
        }
        for r in 0..3 {
            h[(r, r)] = 1.0;
        }
        let k = SMatrix::<f64, 11, 4>::from_fn(|i, j| ((i + 2 * j) as f64 * 0.41).sin() * 0.3);
        let b = SMatrix::<f64, 11, 11>::from_fn(|i, j| ((i * 7 + j) as f64 * 0.23).cos());
        let x = b * b.transpose();
        let t = GainTransition::new(&f, &k, &h);
        let a = f * (SMatrix::<f64, 11, 11>::identity() - k * h);
        assert!((t.matrix() - a).amax() < 1e-12);
        let dense = a * x * a.transpose();
        assert!((t.sandwich(&x) - dense).amax() < 1e-10 * dense.amax());
        // In place: the same numbers, bit for bit (the recursions' outputs must not move).
        let mut y = x;
        t.sandwich_in_place(&mut y);
        assert_eq!(y, t.sandwich(&x));
    }

    #[test]
    fn window_covariance_matches_direct_mean() {
        let mut w = InnovationWindow::<2>::new(3);
        let es = [[1.0, 2.0], [0.5, -1.0], [2.0, 0.0], [-1.0, 1.0], [0.3, 0.3]];
        for (k, e) in es.iter().enumerate() {
            w.push(&SVector::<f64, 2>::new(e[0], e[1]));
            let lo = k.saturating_sub(2);
            let mut c = SMatrix::<f64, 2, 2>::zeros();
            for e in &es[lo..=k] {
                let v = SVector::<f64, 2>::new(e[0], e[1]);
                c += v * v.transpose();
            }
            c /= (k - lo + 1) as f64;
            assert!((w.covariance() - c).amax() < 1e-12);
        }
    }

    #[test]
    fn schedule_decays_floors_and_restarts() {
        let p = AdaptationParams::default();
        let mut s = StepSchedule::new();
        let e0 = s.eta(&p);
        for _ in 0..100_000 {
            s.observe(3.0, 3, &p);
        }
        assert!(s.eta(&p) < e0 && (s.eta(&p) - p.eta_min).abs() < 1e-12);
        for _ in 0..20 {
            s.observe(50.0, 3, &p);
        }
        // A sustained NIS excess keeps restarting the schedule: the step size stays at eta0.
        assert!(s.restarts >= 1);
        assert!((s.eta(&p) - e0).abs() < 1e-12);
    }
}
