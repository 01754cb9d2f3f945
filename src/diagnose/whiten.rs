//! The change test on the residual whitened by its learned colour: the colour (an AR(1)
//! part seen through white noise, per row), its innovation filter, and the generalised
//! likelihood ratio search of [`ChangeTest::evaluate`] run on the whitened residual, and one
//! actuator's gain against its offset there.

use super::*;

impl ChangeTest {
    /// The generalised likelihood ratio search of [`ChangeTest::evaluate`] (every actuator,
    /// kind and change time) on the residual whitened by its learned colour. The residual
    /// goes through each row's time-varying filter from the wind's stationary spread, the
    /// regressors (zero before their change) through its steady state, to which it settles
    /// within the first samples: an ARMA(1,1) filter `(1 - φ z⁻¹)/(1 - θ z⁻¹)`, so that a
    /// regressor started at `τ` comes out as the whole store's filtered regressor less a
    /// geometric tail `α H_τ θ^(k-τ)`, and the sums for every `τ` come from backward
    /// recursions in one pass. `None` until the colour is learned.
    ///
    /// The answer is a [`Reading`] in the whitened residual's terms: drops and noise variance
    /// of the whitened residual (its autocorrelation 0), no ramp (a drift is read on angle
    /// outputs, with [`ChangeTest::evaluate`]). No allocation.
    pub fn whitened_search(&mut self) -> Option<Reading> {
        if !self.colour_learned() || self.len < self.min_samples {
            return None;
        }
        let (cap, rows, l) = (self.buf.len(), self.rows, self.effects.len());
        let n = self.len;
        let w = self.colour.whitening(rows);
        let mut filt = [(0.0f64, 0.0f64, 1.0f64, 0.0f64); 4];
        for (f, wi) in filt.iter_mut().zip(&w).take(rows) {
            *f = wi.steady();
        }
        let oldest = self.head + cap - n;
        // Forward pass: whitened residual y, and per row and actuator the filtered command
        // (F^u, H^u), per row the filtered ones (F^1, H^1): kept for the backward pass. The
        // residual's filter is the time-varying one, started from the wind's stationary spread:
        // the wind's level at the store's first sample is unknown, and the steady filter
        // started cold would weigh the first samples several times over (a healthy store then
        // fits a change over its whole length). Its gain settles within a few samples to the
        // steady one the regressors (zero before their change) are filtered with.
        let mut predicted = [0.0f64; 4];
        let mut spread = [0.0f64; 4];
        for (p, wi) in spread.iter_mut().zip(&w) {
            *p = wi.start();
        }
        let mut hu_run = [[0.0f64; 4]; MAX_ACTUATORS];
        let mut h1_run = [0.0f64; 4];
        let mut settled = [None; 4];
        for k in 0..n {
            let e = &self.buf[wrap(oldest + k, cap)];
            let x = &mut self.scratch[k];
            for (i, &(_, theta, c, alpha)) in filt.iter().enumerate().take(rows) {
                let wi = &w[i];
                let (gain, scale) = wi.advance_settling(&mut spread[i], &mut settled[i]);
                x.y[i] = wi.apply(&mut predicted[i], e.r[i], gain, scale);
                x.f1[i] = c + alpha * h1_run[i];
                x.h1[i] = h1_run[i];
                h1_run[i] = theta * h1_run[i] + 1.0;
                for (j, run) in hu_run.iter_mut().enumerate().take(l) {
                    let u = e.u[j];
                    x.fu[j][i] = c * u + alpha * run[i];
                    x.hu[j][i] = run[i];
                    run[i] = theta * run[i] + u;
                }
            }
        }
        // Backward pass over τ: per row, E_y, C; per row and actuator the u and 1 sums.
        #[derive(Clone, Copy, Default)]
        struct Acc {
            d_u: f64,  // Σ F^u y
            d_1: f64,  // Σ F^1 y
            a_uu: f64, // Σ F^u F^u
            a_11: f64,
            a_u1: f64,
            b_u: f64, // Σ θ^(k-τ) F^u
            b_1: f64,
        }
        let mut acc = [[Acc::default(); 4]; MAX_ACTUATORS];
        let (mut e_y, mut c_sum, mut base) = ([0.0f64; 4], [0.0f64; 4], 0.0);
        // Per actuator and kind: see `Fit` (Σ y² over the stretch in its fourth place).
        let mut best = [[(0.0f64, 0usize, 0.0f64, 0.0f64, 0.0f64, 0.0f64); 3]; MAX_ACTUATORS];
        let mut mixed = [0.0f64; MAX_ACTUATORS];
        let mut su = [0.0f64; MAX_ACTUATORS];
        for tau in (0..n).rev() {
            let m = n - tau;
            let x = &self.scratch[tau];
            let e = &self.buf[wrap(oldest + tau, cap)];
            for (sj, uj) in su.iter_mut().zip(&e.u).take(l) {
                *sj += uj;
            }
            for (i, &(_, theta, _, _)) in filt.iter().enumerate().take(rows) {
                let yk = x.y[i];
                base += yk * yk;
                e_y[i] = yk + theta * e_y[i];
                c_sum[i] = 1.0 + theta * theta * c_sum[i];
                for (j, per_row) in acc.iter_mut().enumerate().take(l) {
                    let a = &mut per_row[i];
                    let (fuk, f1k) = (x.fu[j][i], x.f1[i]);
                    a.d_u += fuk * yk;
                    a.d_1 += f1k * yk;
                    a.a_uu += fuk * fuk;
                    a.a_11 += f1k * f1k;
                    a.a_u1 += fuk * f1k;
                    a.b_u = fuk + theta * a.b_u;
                    a.b_1 = f1k + theta * a.b_1;
                }
            }
            if m < self.min_samples {
                continue;
            }
            for (j, b) in self.effects.iter().enumerate() {
                let (mut gy, mut gx, mut oy, mut ox, mut go) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for (i, &(_, _, _, alpha)) in filt.iter().enumerate().take(rows) {
                    let a = &acc[j][i];
                    let (hu_t, h1_t) = (x.hu[j][i], x.h1[i]);
                    let bi = b[i];
                    let sy_u = a.d_u - alpha * hu_t * e_y[i];
                    let sy_1 = a.d_1 - alpha * h1_t * e_y[i];
                    let sxx_u = a.a_uu - 2.0 * alpha * hu_t * a.b_u
                        + alpha * alpha * hu_t * hu_t * c_sum[i];
                    let sxx_1 = a.a_11 - 2.0 * alpha * h1_t * a.b_1
                        + alpha * alpha * h1_t * h1_t * c_sum[i];
                    let sx_u1 = a.a_u1 - alpha * h1_t * a.b_u - alpha * hu_t * a.b_1
                        + alpha * alpha * hu_t * h1_t * c_sum[i];
                    gy += bi * sy_u;
                    gx += bi * bi * sxx_u;
                    oy += bi * sy_1;
                    ox += bi * bi * sxx_1;
                    go += bi * bi * sx_u1;
                }
                let mean_u = su[j] / m as f64;
                let sums = [gy, gx, oy, ox, go];
                keep_best(&mut best[j], &mut mixed[j], sums, |drop, theta, ss| {
                    (drop, m, theta, base, mean_u, ss)
                });
            }
        }
        let (kinds, top) = (KINDS, top_hypothesis(&best[..l])?);
        let (j, k, h) = (top.actuator, top.kind, best[top.actuator][top.kind]);
        // In the whitened residual's own noise (about 1 where the colour is right).
        let noise_var = (h.3 - h.0) / (h.1 * rows) as f64;
        if !(noise_var > 0.0 && noise_var.is_finite()) {
            return None;
        }
        let since = self.buf[(oldest + n - h.1) % cap].t;
        Some(Reading {
            actuator: j,
            kind: kinds[k],
            value: h.2,
            value_std: (noise_var / h.5).sqrt(),
            since,
            samples: h.1,
            drop: h.0,
            noise_var,
            autocorrelation: 0.0,
            command_mean: h.4,
            command_rms: self.command_rms(j, h.1),
            next_kind_drop: top.next_kind_drop,
            mixed_drop: mixed[j],
            next_actuator_drop: top.next_actuator_drop,
            ramp_drop: 0.0,
            ramp_rate: 0.0,
            ramp_samples: 0,
            ramp_since: since,
        })
    }
}

/// Largest AR(1) coefficient the colour takes (a slower colour is read as 0.99).
pub(super) const PHI_MAX: f64 = 0.99;

/// One row's noise model for its innovation filter: an AR(1) part (coefficient `phi`,
/// stationary variance `ar`, fresh variance per sample `fresh`) seen through white noise
/// (`white`). The filter starts from the AR part's stationary spread (the wind's level at the
/// store's first sample is unknown) and its gain settles as the samples come (time-varying
/// Kalman filter): prediction `h' = phi (h + k (x - h))`, output `(x - h) scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Whiten {
    pub(super) phi: f64,
    pub(super) ar: f64,
    pub(super) fresh: f64,
    pub(super) white: f64,
}

/// No colour: the residual as it is.
pub(super) const IDENTITY: Whiten = Whiten {
    phi: 0.0,
    ar: 0.0,
    fresh: 0.0,
    white: 1.0,
};

impl Whiten {
    /// The filter at its steady state as `(φ, θ, c, α)`: the innovation of `x` is
    /// `c (1 - φ z⁻¹)/(1 - θ z⁻¹) x`, whose impulse response is `c` and then
    /// `α θ^(m-1)` (`θ = φ (1 - k)` with the steady gain `k`, `α = c (θ - φ)`).
    pub(super) fn steady(&self) -> (f64, f64, f64, f64) {
        let mut p = self.ar;
        // The Riccati recursion contracts by at least φ² < 1 per sample.
        for _ in 0..200 {
            let k = p / (p + self.white);
            p = self.phi * self.phi * (1.0 - k) * p + self.fresh;
        }
        let s2 = p + self.white;
        if !(s2 > 0.0 && s2.is_finite()) {
            return (0.0, 0.0, 1.0, 0.0);
        }
        let theta = self.phi * (1.0 - p / s2);
        let c = 1.0 / s2.sqrt();
        (self.phi, theta, c, c * (theta - self.phi))
    }

    /// The prediction variance before the first sample.
    pub(super) fn start(&self) -> f64 {
        self.ar
    }

    /// From the prediction variance `p`: this sample's gain, output scale and the next
    /// prediction variance.
    pub(super) fn advance(&self, p: f64) -> (f64, f64, f64) {
        let s2 = p + self.white;
        let k = p / s2;
        (
            k,
            1.0 / s2.sqrt(),
            self.phi * self.phi * (1.0 - k) * p + self.fresh,
        )
    }

    /// [`Whiten::advance`] from the prediction variance `p`, which it moves on, until the
    /// recursion reaches its fixed point (the next variance equal to this one, bit for bit):
    /// from then on every sample's gain and scale are the same, kept in `settled` and not
    /// computed again (the same numbers, without a square root and two divisions a sample).
    pub(super) fn advance_settling(
        &self,
        p: &mut f64,
        settled: &mut Option<(f64, f64)>,
    ) -> (f64, f64) {
        if let Some(gain_scale) = *settled {
            return gain_scale;
        }
        let (gain, scale, next) = self.advance(*p);
        if next.to_bits() == p.to_bits() {
            *settled = Some((gain, scale));
        }
        *p = next;
        (gain, scale)
    }

    /// One series' sample `x` through the filter with this sample's `gain` and `scale` (from
    /// [`Whiten::advance`]): its whitened value, and `predicted` carried to the next sample.
    pub(super) fn apply(&self, predicted: &mut f64, x: f64, gain: f64, scale: f64) -> f64 {
        let y = (x - *predicted) * scale;
        *predicted = self.phi * (*predicted + gain * (x - *predicted));
        y
    }
}

/// The healthy residual's colour per row, as an AR(1) part (wind and slow model error: it
/// carries over from one sample to the next) plus a white part (sensor noise), from
/// exponentially weighted autocovariances at lags 0-3. The AR coefficient is the lag-3 over
/// lag-2 ratio: the gyro's noise enters the one-step residual twice (now and through the
/// previous rate), which correlates lags 0 and 1 only (as `calibrate` reads the wind).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Colour {
    pub(super) mean: [f64; 4],
    /// Autocovariances at lags 0..=3 per row.
    pub(super) cov: [[f64; 4]; 4],
    /// The previous three residuals (newest first) while consecutive and learned from.
    pub(super) history: [[f64; 4]; 3],
    pub(super) history_len: usize,
    /// Samples learned, the averaging memory, and how many make the colour usable.
    pub(super) learned: usize,
    pub(super) memory: usize,
    pub(super) needed: usize,
}

impl Colour {
    pub(super) fn learn(&mut self, r: &[f64; 4], rows: usize) {
        // (A weighted residual that overflowed would poison the averages for good.)
        if !r[..rows].iter().all(|x| x.is_finite()) {
            self.break_history();
            return;
        }
        if self.history_len == 3 {
            let a = 1.0 / (self.learned + 1).min(self.memory) as f64;
            for (i, ri) in r.iter().enumerate().take(rows) {
                let mean = &mut self.mean[i];
                *mean += a * (ri - *mean);
                let x = ri - *mean;
                // Lags 1-3 from the history, about the same mean.
                let lagged = [
                    x,
                    self.history[0][i] - *mean,
                    self.history[1][i] - *mean,
                    self.history[2][i] - *mean,
                ];
                for (cov, past) in self.cov[i].iter_mut().zip(lagged) {
                    *cov += a * (x * past - *cov);
                }
            }
            self.learned += 1;
        }
        self.history = [*r, self.history[0], self.history[1]];
        self.history_len = (self.history_len + 1).min(3);
    }

    /// A gap, a restart or a stretch under way: the lags start again.
    pub(super) fn break_history(&mut self) {
        self.history_len = 0;
    }

    /// Each row's noise model for the innovation filter; the identity until learned or
    /// where the row's statistics are not usable.
    pub(super) fn whitening(&self, rows: usize) -> [Whiten; 4] {
        let mut w = [IDENTITY; 4];
        if self.learned < self.needed {
            return w;
        }
        for (wi, c) in w.iter_mut().zip(&self.cov).take(rows) {
            let [g0, _, g2, g3] = *c;
            if !(g0 > 0.0 && g0.is_finite() && g2.is_finite() && g3.is_finite()) {
                continue;
            }
            let phi = if g2 > 0.0 && g3 > 0.0 {
                (g3 / g2).min(PHI_MAX)
            } else {
                0.0
            };
            // The AR part's variance, at most 99 % of the whole.
            let ar = if phi > 0.0 {
                (g2 / (phi * phi)).min(0.99 * g0)
            } else {
                0.0
            };
            *wi = Whiten {
                phi,
                ar,
                fresh: ar * (1.0 - phi * phi),
                white: g0 - ar,
            };
        }
        w
    }
}

impl ChangeTest {
    /// Actuator `j`'s gain and offset changes over the newest `samples` stored, compared with
    /// the residual whitened by its learned colour (generalised least squares; `None` until
    /// the colour is learned). Wind and slow model error carry over from one sample to the
    /// next, so the plain fit weighs what they share with a slowly moving command; whitened,
    /// the command's sample-to-sample moves, where a gain and an offset differ, weigh in full.
    /// No allocation.
    pub fn whitened_gain_or_offset(&self, j: usize, samples: usize) -> Option<KindFit> {
        if !self.colour_learned() || j >= self.effects.len() {
            return None;
        }
        let (cap, rows) = (self.buf.len(), self.rows);
        let n = samples.min(self.len);
        if n < self.min_samples {
            return None;
        }
        let w = self.colour.whitening(rows);
        let b = &self.effects[j];
        // Oldest first: the residual's filter runs over the whole store (its state at the
        // stretch's start is the healthy past's), each regressor's from zero at the stretch's
        // start (zero before it), all with the same gains; the sums over the stretch.
        let entry = |k: usize| &self.buf[wrap(self.head + cap - self.len + k, cap)];
        let start = self.len - n;
        let (mut pr, mut pg, mut po) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        let mut pv = [0.0f64; 4];
        for (p, wi) in pv.iter_mut().zip(&w) {
            *p = wi.start();
        }
        let (mut gy, mut gx, mut oy, mut ox, mut base) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut go, mut su) = (0.0, 0.0);
        let mut settled = [None; 4];
        for k in 0..self.len {
            let e = entry(k);
            let inside = k >= start;
            let u = e.u[j];
            if inside {
                su += u;
            }
            for (i, wi) in w.iter().enumerate().take(rows) {
                let (gain, scale) = wi.advance_settling(&mut pv[i], &mut settled[i]);
                let y = wi.apply(&mut pr[i], e.r[i], gain, scale);
                if !inside {
                    continue;
                }
                let g = wi.apply(&mut pg[i], b[i] * u, gain, scale);
                let o = wi.apply(&mut po[i], b[i], gain, scale);
                gy += g * y;
                gx += g * g;
                oy += o * y;
                ox += o * o;
                go += g * o;
                base += y * y;
            }
        }
        if !(gx > 0.0 && ox > 0.0) {
            return None;
        }
        let (gain_drop, offset_drop) = (gy * gy / gx, oy * oy / ox);
        let det = gx * ox - go * go;
        let pair =
            (det > 1e-9 * gx * ox).then(|| ((gy * ox - go * oy) / det, (gx * oy - go * gy) / det));
        let mixed_drop = pair.map_or(gain_drop.max(offset_drop), |(a, d)| a * gy + d * oy);
        let (kind, value, drop, other, ss) = if offset_drop > gain_drop {
            (ChangeKind::Offset, oy / ox, offset_drop, gain_drop, ox)
        } else {
            (ChangeKind::Gain, 1.0 + gy / gx, gain_drop, offset_drop, gx)
        };
        let noise_var = ((base - drop) / (n * rows) as f64).max(0.0);
        if !(noise_var > 0.0 && drop.is_finite() && mixed_drop.is_finite()) {
            return None;
        }
        // Stuck at s: the output is s whatever the command, so the residual is s b - b u,
        // and the whitened y + g is s times the whitened offset regressor.
        let stuck_value = (oy + go) / ox;
        let stuck_var =
            ((base + 2.0 * gy + gx - stuck_value * (oy + go)) / (n * rows) as f64).max(0.0);
        // The gain fitted with the offset free, in the pair's own residual noise.
        let pair_var = ((base - mixed_drop) / (n * rows) as f64).max(0.0);
        let (pair_gamma, pair_gamma_std) = pair.map_or((f64::NAN, f64::INFINITY), |(a, _)| {
            (1.0 + a, (pair_var * ox / det).sqrt())
        });
        Some(KindFit {
            kind,
            value,
            value_std: (noise_var / ss).sqrt(),
            margin: (drop - other) / noise_var,
            mixed_margin: (mixed_drop - drop) / noise_var,
            command_mean: su / n as f64,
            stuck_value,
            stuck_std: (stuck_var / ox).sqrt(),
            pair_gamma,
            pair_gamma_std,
            pair_delta: pair.map_or(f64::NAN, |(_, d)| d),
        })
    }
}
