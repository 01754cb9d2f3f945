//! What each filter tells of one actuator ([`AhcEstimate`]), read from the filters' states.

use super::*;

/// One actuator's health estimate from one filter.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AhcEstimate {
    pub gamma: f64,
    pub gamma_lo: f64,
    pub gamma_hi: f64,
    pub delta: f64,
    pub delta_lo: f64,
    pub delta_hi: f64,
    /// The 2×2 block of the covariance (UKF) or shape (ESMF) of (gamma, delta):
    /// `[gg, gd, dd]`.
    pub block: [f64; 3],
    /// Adapted process noise of gamma and delta.
    pub q_gamma: f64,
    pub q_delta: f64,
    /// The effective output deviation at the operating point that the measurements attribute
    /// to this actuator (filled in by the diagnosis; see `diagnose::vehicle`). Unlike
    /// `(gamma - 1) u + delta` it does not wander along what the measurements cannot see.
    pub deviation: f64,
    /// The same for the command's excursions about the operating point, `(gamma - 1) σ_u`:
    /// the deviation statistic is `hypot(deviation, excursion)`.
    pub excursion: f64,
    /// How far the healthy gain lies outside the filter's gamma bounds, at the reference
    /// deflection (`DiagnosisParams::gain_ref`), attributed like `deviation`: the gain
    /// statistic of angle outputs (see `diagnose::vehicle`).
    pub gain_gap: f64,
    /// Set-membership estimates: whether the gamma, the delta bounds are still (nearly) the a
    /// priori box's (the data have not excited them).
    pub unexcited: [bool; 2],
    /// Set-membership estimates: the bounds of the effective output less the healthy one at
    /// the actuator's recent command `command_ref`, `(γ - 1) ū + δ` (healthy: 0), which the
    /// data bound before they split it into a gain and a bias ([`AhcSet::output_range`]);
    /// `None` where they have not (still the a priori box's extent), or for another filter.
    pub output_bounds: Option<[f64; 2]>,
    pub command_ref: f64,
}

impl AhcEstimate {
    /// `(a - h)ᵀ B⁻¹ (a - h)` of the estimate against the healthy point h = (1, 0).
    pub fn distance2(&self) -> f64 {
        let (dg, dd) = (self.gamma - 1.0, self.delta);
        let [a, b, c] = self.block;
        let det = a * c - b * b;
        if det.is_nan() || det <= 0.0 {
            return 0.0;
        }
        (c * dg * dg - 2.0 * b * dg * dd + a * dd * dd) / det
    }

    /// The estimate's output less the healthy one at command `u`, `(γ - 1) u + δ`.
    pub fn output_at(&self, u: f64) -> f64 {
        (self.gamma - 1.0) * u + self.delta
    }

    /// A Kalman filter's estimate of the output's departure from the healthy one at command
    /// `u`, `(γ - 1) u + δ`, and its probable bounds (±3σ of its (γ, δ) covariance block):
    /// `[estimate, lo, hi]`, to set beside the set filter's guaranteed `output_bounds`.
    pub fn output_probable(&self, u: f64) -> [f64; 3] {
        let [gg, gd, dd] = self.block;
        let centre = self.output_at(u);
        let var = u * u * gg + 2.0 * u * gd + dd;
        // A NaN block stays NaN (`f64::max` would take the 0).
        let sd = if var.is_nan() {
            var
        } else {
            var.max(0.0).sqrt()
        };
        [centre, centre - 3.0 * sd, centre + 3.0 * sd]
    }
}

pub(super) fn estimate<const N: usize, const M: usize, E: Estimator<N, M>>(
    f: &E,
    p: &SMatrix<f64, N, N>,
    l: usize,
    j: usize,
) -> AhcEstimate {
    let (gi, di) = (3 + j, 3 + l + j);
    let x = f.state();
    let (gamma_lo, gamma_hi) = f.bounds(gi);
    let (delta_lo, delta_hi) = f.bounds(di);
    let q = f.process_noise();
    // The MIT-ESMF's outer ellipsoid can have its centre outside the a priori box its bounds
    // are clipped to: the estimate is the set's point nearest it (the truth is in the box).
    let inside = |v: f64, lo: f64, hi: f64| if lo <= hi { v.clamp(lo, hi) } else { v };
    AhcEstimate {
        gamma: inside(x[gi], gamma_lo, gamma_hi),
        gamma_lo,
        gamma_hi,
        delta: inside(x[di], delta_lo, delta_hi),
        delta_lo,
        delta_hi,
        block: [p[(gi, gi)], p[(gi, di)], p[(di, di)]],
        q_gamma: q[gi],
        q_delta: q[di],
        deviation: 0.0,
        excursion: 0.0,
        gain_gap: 0.0,
        unexcited: [false; 2],
        output_bounds: None,
        command_ref: 0.0,
    }
}

/// Actuator `j`'s estimate from the set: the polygon's centroid and ranges; its "block" the
/// squared half-widths, its "process noise" the drift per step.
pub(super) fn set_estimate<const N: usize, const M: usize>(
    set: &AhcSet<N, M>,
    j: usize,
) -> AhcEstimate {
    let [gamma, delta] = set.centre(j);
    let (gamma_lo, gamma_hi) = set.bounds(j, 0);
    let (delta_lo, delta_hi) = set.bounds(j, 1);
    let half2 = |lo: f64, hi: f64| 0.25 * (hi - lo) * (hi - lo);
    let output = set.output_range(j);
    AhcEstimate {
        gamma,
        gamma_lo,
        gamma_hi,
        delta,
        delta_lo,
        delta_hi,
        block: [half2(gamma_lo, gamma_hi), 0.0, half2(delta_lo, delta_hi)],
        q_gamma: set.params.drift_gamma,
        q_delta: set.params.drift_delta,
        unexcited: [set.unexcited(j, 0), set.unexcited(j, 1)],
        output_bounds: (!set.output_unexcited(j, output)).then_some([output.1, output.2]),
        command_ref: output.0,
        ..AhcEstimate::default()
    }
}
