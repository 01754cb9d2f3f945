//! Which actuator changed, how and since when, read from the data rather than from the
//! filters' priors: a generalised likelihood ratio test with an unknown change time (Willsky &
//! Jones 1976) on the healthy model's one-step residual.
//!
//! The residual `r_k = y_k - ŷ_k(healthy)` (rows divided by the noise the filters assume, as in
//! [`crate::estimate::vehicle::weighted_effects`]) of a change of actuator `j` since step `τ` is
//! `b_j s_k` with `b_j` its weighted effect per unit of effective output and `s_k` the change of
//! that output, one unknown `θ` per hypothesis:
//! - gain: `s_k = (γ - 1) u_k` (`θ = γ - 1`): a loss of effectiveness;
//! - offset: `s_k = δ` (`θ = δ`): a bias;
//! - stuck: the output stays at `θ` whatever the command, `s_k = θ - u_k`.
//!
//! Each is linear in `θ`, so one backwards pass over the stored residuals gives, for every
//! change time at once, the least-squares `θ` and the drop of the residual sum of squares. The
//! hypothesis (actuator, kind, change time) with the largest drop is the reading. Unlike the
//! filters' gamma and delta, which a hover leaves free to trade along `γ u + δ` and which their
//! priors then settle (motors fail low), the three kinds differ in how the output follows the
//! command since the change, which the fit sees directly; and a motor stuck above what the
//! controller wants is not mistaken for the opposite motor losing thrust (they differ in the
//! command pattern and in a_z, which the fit weighs).
//!
//! The residual is coloured (wind, slow model error), which the plain search weighs like
//! independent samples. Once that colour is learned on healthy stretches (and learned on
//! during a fault, from the residual with the fault's identification taken out:
//! [`ChangeTest::push_identified`]),
//! [`ChangeTest::whitened_search`] runs the same search on the whitened residual (generalised
//! least squares), and [`ChangeTest::whitened_gain_or_offset`] compares one actuator's gain
//! with its offset there.

use crate::model::MAX_ACTUATORS;

/// How an actuator's effective output changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChangeKind {
    Gain,
    Offset,
    Stuck,
}

/// The best-fitting change and how much better it fits than the alternatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    pub actuator: usize,
    pub kind: ChangeKind,
    /// γ (gain), δ (offset) or the stuck output (stuck), normalised command units.
    pub value: f64,
    /// Its standard deviation from the fit.
    pub value_std: f64,
    /// Time of the first sample of the changed stretch.
    pub since: f64,
    /// Samples in the changed stretch.
    pub samples: usize,
    /// Drop of the weighted residual sum of squares that the change explains.
    pub drop: f64,
    /// Residual variance per row left in the changed stretch by the fit.
    pub noise_var: f64,
    /// Lag-one autocorrelation of the residual the fit leaves in the changed stretch.
    pub autocorrelation: f64,
    /// The actuator's mean command over the changed stretch (a stuck output's distance from
    /// it is the size of that change).
    pub command_mean: f64,
    /// The root mean square of that command: with the change, the size of a gain's or a
    /// stuck output's deviation over the stretch.
    pub command_rms: f64,
    /// The best drop of another kind of change of the same actuator.
    pub next_kind_drop: f64,
    /// The best drop of a gain and an offset of the same actuator changing together (two
    /// unknowns): well above `drop`, the change is not of one kind.
    pub mixed_drop: f64,
    /// The best drop of any change of another actuator.
    pub next_actuator_drop: f64,
    /// The best drop of an offset of the same actuator growing linearly from zero since its
    /// start, or over the whole store from a value already there (a drift), its rate
    /// (normalised command units per second) and stretch (samples).
    /// Kept out of the choice of actuator and kind, which the step changes make: it only tells
    /// a drift from the step it would otherwise be read as.
    pub ramp_drop: f64,
    pub ramp_rate: f64,
    pub ramp_samples: usize,
    /// Time of the ramp's first sample.
    pub ramp_since: f64,
}

/// The kinds of change in the order the searches index them.
const KINDS: [ChangeKind; 3] = [ChangeKind::Gain, ChangeKind::Offset, ChangeKind::Stuck];

/// One hypothesis' best fit over the change times: (drop, samples, θ, residual variance or
/// sum of squares, mean command, sum of squares of its regressor).
type Fit = (f64, usize, f64, f64, f64, f64);

/// The drops and values of a gain, an offset and a stuck output (in [`KINDS`] order), and of
/// a gain and an offset together, from `Σ g y`, `Σ g²`, `Σ o y`, `Σ o²`, `Σ g o` over a
/// changed stretch (`g` the gain regressor `b u`, `o` the offset regressor `b`, `y` the
/// residual); `None` where a regressor is zero or the pair is degenerate.
#[allow(clippy::type_complexity)]
fn kind_drops(
    gy: f64,
    gx: f64,
    oy: f64,
    ox: f64,
    go: f64,
) -> ([(Option<f64>, Option<f64>); 3], Option<f64>) {
    // Gain and offset together: the 2×2 normal equations.
    let det = gx * ox - go * go;
    let pair = (det > 1e-9 * gx * ox).then(|| {
        let (a, d) = ((gy * ox - go * oy) / det, (gx * oy - go * gy) / det);
        a * gy + d * oy
    });
    let mut fits = [(None, None); 3];
    if gx > 0.0 {
        fits[0] = (Some(gy * gy / gx), Some(1.0 + gy / gx));
    }
    if ox > 0.0 {
        fits[1] = (Some(oy * oy / ox), Some(oy / ox));
        // Stuck at θ: r = b (θ - u); the sum of squares left is Σ(r + b u)² - (Σ b(r + b u))²/Σb²,
        // and Σ(r + b u)² = Σ r² + 2 gy + gx.
        let sy = oy + go;
        fits[2] = (Some(sy * sy / ox - 2.0 * gy - gx), Some(sy / ox));
    }
    (fits, pair)
}

/// Keep in `row`, per kind, the best of this stretch's fits from `sums` (see [`kind_drops`]),
/// recorded as `fit(drop, θ, Σ regressor²)`, and in `pair_best` the best drop of the pair.
fn keep_best(
    row: &mut [Fit; 3],
    pair_best: &mut f64,
    sums: [f64; 5],
    fit: impl Fn(f64, f64, f64) -> Fit,
) {
    let [gy, gx, oy, ox, go] = sums;
    let (fits, pair) = kind_drops(gy, gx, oy, ox, go);
    if let Some(drop) = pair.filter(|d| d.is_finite() && *d > *pair_best) {
        *pair_best = drop;
    }
    // A stuck output's regressor is the offset's (see `kind_drops`).
    for ((slot, (drop, theta)), ss) in row.iter_mut().zip(fits).zip([gx, ox, ox]) {
        if let (Some(drop), Some(theta)) = (drop, theta)
            && drop.is_finite()
            && drop > slot.0
        {
            *slot = fit(drop, theta, ss);
        }
    }
}

/// The best hypothesis among `best` (per actuator and kind) and the best drops of the others.
struct Top {
    actuator: usize,
    kind: usize,
    next_kind_drop: f64,
    next_actuator_drop: f64,
}

fn top_hypothesis(best: &[[Fit; 3]]) -> Option<Top> {
    let mut top: Option<(usize, usize)> = None;
    for (j, row) in best.iter().enumerate() {
        for (k, h) in row.iter().enumerate() {
            if h.1 > 0 && top.is_none_or(|(tj, tk)| h.0 > best[tj][tk].0) {
                top = Some((j, k));
            }
        }
    }
    let (j, k) = top?;
    let next_kind_drop = (0..3)
        .filter(|&kk| kk != k)
        .map(|kk| best[j][kk].0)
        .fold(0.0, f64::max);
    let next_actuator_drop = (0..best.len())
        .filter(|&jj| jj != j)
        .flat_map(|jj| best[jj].iter().map(|x| x.0))
        .fold(0.0, f64::max);
    Some(Top {
        actuator: j,
        kind: k,
        next_kind_drop,
        next_actuator_drop,
    })
}

impl Reading {
    /// How much better this reading fits than an alternative whose drop is `other`, as a log
    /// likelihood ratio (×2) in the residual's own noise, counting only the independent
    /// samples: a residual with lag-one autocorrelation ρ holds about (1-ρ)/(1+ρ) of them
    /// (an AR(1) sequence's variance inflation). ρ below 0 counts as 0.
    pub fn margin_over(&self, other: f64) -> f64 {
        if self.noise_var.is_nan() || self.noise_var <= 0.0 {
            return 0.0;
        }
        let rho = self.autocorrelation.clamp(0.0, 0.999);
        let m = (self.drop - other) / self.noise_var * (1.0 - rho) / (1.0 + rho);
        if m.is_finite() { m } else { 0.0 }
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    t: f64,
    r: [f64; 4],
    u: [f64; MAX_ACTUATORS],
}

/// The stored residuals (a ring over the last `capacity` samples) and the test.
#[derive(Debug, Clone)]
pub struct ChangeTest {
    effects: Vec<[f64; 4]>,
    /// 1 / the noise standard deviation of each row (0 for a row not measured).
    weights: [f64; 4],
    rows: usize,
    buf: Vec<Entry>,
    head: usize,
    len: usize,
    /// Samples stored since the test was made (a clock for stretches that outlive the store).
    stored: u64,
    /// The shortest changed stretch considered (samples).
    min_samples: usize,
    /// The residual's colour, learned on healthy stretches and on identified faults (see [`Colour`]).
    colour: Colour,
    /// Per stored sample, the whitened series of [`ChangeTest::whitened_search`].
    scratch: Vec<SearchScratch>,
}

/// One sample's whitened residual, and per row the whitened commands and ones with the state
/// of their filters, for [`ChangeTest::whitened_search`].
#[derive(Debug, Clone, Copy, Default)]
struct SearchScratch {
    y: [f64; 4],
    f1: [f64; 4],
    h1: [f64; 4],
    fu: [[f64; 4]; MAX_ACTUATORS],
    hu: [[f64; 4]; MAX_ACTUATORS],
}

impl ChangeTest {
    /// `effects[j]`: actuator j's weighted effect per unit of effective output, `weights`: the
    /// inverse noise std of each measurement row (`rows` of them: 3, or 4 with a_z),
    /// `capacity`: samples kept (at most [`MAX_STORE`]), `min_samples`: the shortest stretch a
    /// change is fitted on, `colour_memory`: the healthy samples (or those with an identified
    /// fault taken out) the residual's colour is averaged over (it is used once a store's worth, `capacity`, has been learned).
    pub fn new(
        effects: Vec<[f64; 4]>,
        weights: [f64; 4],
        rows: usize,
        capacity: usize,
        min_samples: usize,
        colour_memory: usize,
    ) -> Self {
        let capacity = capacity.clamp(2, MAX_STORE);
        Self {
            effects,
            weights,
            rows: rows.min(4),
            buf: vec![
                Entry {
                    t: 0.0,
                    r: [0.0; 4],
                    u: [0.0; MAX_ACTUATORS],
                };
                capacity
            ],
            head: 0,
            len: 0,
            stored: 0,
            min_samples: min_samples.max(2),
            colour: Colour {
                memory: colour_memory.max(1),
                needed: capacity,
                ..Colour::default()
            },
            scratch: vec![SearchScratch::default(); capacity],
        }
    }

    /// Store one step's unweighted residual of the healthy model and the commands that acted;
    /// with `healthy` (nothing under way) the residual's colour learns from it too.
    /// A non-finite value breaks the record: what came before is dropped.
    pub fn push(&mut self, t: f64, residual: &[f64; 4], u: &[f64], healthy: bool) {
        let learn = if healthy { Learn::Raw } else { Learn::No };
        self.store(t, residual, u, learn);
    }

    /// [`Self::push`] during a fault identified from the data as actuator `j`'s gain `gamma`
    /// and offset `delta` (a stuck output: gain 0, offset its value): the colour learns from
    /// the residual with that fault taken out, which is the healthy residual if the
    /// identification is right.
    pub fn push_identified(
        &mut self,
        t: f64,
        residual: &[f64; 4],
        u: &[f64],
        j: usize,
        gamma: f64,
        delta: f64,
    ) {
        let learn =
            if j < self.effects.len() && j < u.len() && gamma.is_finite() && delta.is_finite() {
                Learn::Without {
                    actuator: j,
                    gain_change: gamma - 1.0,
                    offset: delta,
                }
            } else {
                Learn::No
            };
        self.store(t, residual, u, learn);
    }

    fn store(&mut self, t: f64, residual: &[f64; 4], u: &[f64], learn: Learn) {
        let l = self.effects.len().min(u.len());
        let finite = residual[..self.rows].iter().all(|v| v.is_finite())
            && u[..l].iter().all(|v| v.is_finite())
            && t.is_finite();
        if !finite {
            self.clear();
            return;
        }
        let mut e = Entry {
            t,
            r: [0.0; 4],
            u: [0.0; MAX_ACTUATORS],
        };
        for ((r, x), w) in
            e.r.iter_mut()
                .zip(residual)
                .zip(&self.weights)
                .take(self.rows)
        {
            *r = x * w;
        }
        e.u[..l].copy_from_slice(&u[..l]);
        match learn {
            Learn::Raw => self.colour.learn(&e.r, self.rows),
            Learn::Without {
                actuator,
                gain_change,
                offset,
            } => {
                let b = &self.effects[actuator];
                let s = gain_change * e.u[actuator] + offset;
                let mut r = e.r;
                for (ri, bi) in r.iter_mut().zip(b).take(self.rows) {
                    *ri -= bi * s;
                }
                self.colour.learn(&r, self.rows);
            }
            Learn::No => self.colour.break_history(),
        }
        let cap = self.buf.len();
        self.buf[self.head] = e;
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
        self.stored += 1;
    }

    /// Forget the stored residuals (a gap in the telemetry, a restart).
    pub fn clear(&mut self) {
        self.len = 0;
        self.colour.break_history();
    }

    /// Whether the residual's colour has been learned (the test whitens with it).
    pub fn colour_learned(&self) -> bool {
        self.colour.learned >= self.colour.needed
    }

    /// Samples stored so far (all of them, not only those kept).
    pub fn stored(&self) -> u64 {
        self.stored
    }

    /// The shortest stretch fitted.
    pub fn min_samples(&self) -> usize {
        self.min_samples
    }

    /// The most samples kept.
    pub fn capacity(&self) -> usize {
        self.buf.len()
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The root mean square of actuator `j`'s command over the newest `samples` stored.
    fn command_rms(&self, j: usize, samples: usize) -> f64 {
        let cap = self.buf.len();
        let n = samples.min(self.len).max(1);
        let ss: f64 = (1..=n)
            .map(|k| self.buf[(self.head + cap - k) % cap].u[j].powi(2))
            .sum();
        (ss / n as f64).sqrt()
    }

    /// The best change over the stored stretch, `None` with too few samples. No allocation.
    pub fn evaluate(&self) -> Option<Reading> {
        if self.len < self.min_samples {
            return None;
        }
        let cap = self.buf.len();
        let l = self.effects.len();
        // Per actuator and kind: see `Fit` (the residual variance in its fourth place).
        let mut best = [[(0.0f64, 0usize, 0.0f64, 0.0f64, 0.0f64, 0.0f64); 3]; MAX_ACTUATORS];
        let mut mixed = [0.0f64; MAX_ACTUATORS];
        // Per actuator: the best ramp (drop, samples, rate).
        let mut ramp = [(0.0f64, 0usize, 0.0f64); MAX_ACTUATORS];
        let t_newest = self.buf[(self.head + cap - 1) % cap].t;
        for (j, b) in self.effects.iter().enumerate() {
            // A ramp since τ, s_k = θ (t_k - t_τ): its sums from Σ q, Σ q t, Σ t, Σ t² (q the
            // sample's Σ b r; times from the newest sample, so they stay small).
            let bb: f64 = b.iter().take(self.rows).map(|x| x * x).sum();
            let (mut q0, mut q1, mut t1, mut t2) = (0.0, 0.0, 0.0, 0.0);
            // Sums over the changed stretch, extended one sample back per iteration.
            let (mut base, mut gy, mut gx, mut oy, mut ox, mut bbu) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            let mut su = 0.0;
            for n in 1..=self.len {
                let e = &self.buf[(self.head + cap - n) % cap];
                let u = e.u[j];
                su += u;
                for (&bi, &ri) in b.iter().zip(&e.r).take(self.rows) {
                    base += ri * ri;
                    gy += bi * u * ri;
                    gx += bi * bi * u * u;
                    oy += bi * ri;
                    ox += bi * bi;
                    bbu += bi * bi * u;
                }
                let tk = e.t - t_newest;
                let q: f64 = b
                    .iter()
                    .zip(&e.r)
                    .take(self.rows)
                    .map(|(bi, ri)| bi * ri)
                    .sum();
                q0 += q;
                q1 += q * tk;
                t1 += tk;
                t2 += tk * tk;
                if n < self.min_samples {
                    continue;
                }
                let num = q1 - tk * q0;
                let den = bb * (t2 - 2.0 * tk * t1 + n as f64 * tk * tk);
                if den > 0.0 {
                    let drop = num * num / den;
                    if drop.is_finite() && drop > ramp[j].0 {
                        ramp[j] = (drop, n, num / den);
                    }
                }
                let rows = (n * self.rows) as f64;
                let sums = [gy, gx, oy, ox, bbu];
                keep_best(&mut best[j], &mut mixed[j], sums, |drop, theta, ss| {
                    let var = ((base - drop) / rows).max(0.0);
                    (drop, n, theta, var, su / n as f64, ss)
                });
            }
            // Over the whole store, a drift that began before it: an offset already there and
            // growing (times centred on their mean, so the two are fitted independently). Its
            // drop includes the offset's, so only a clear slope makes it beat the offset.
            let n = self.len as f64;
            let stt = t2 - t1 * t1 / n;
            if self.len >= self.min_samples && bb > 0.0 && stt > 0.0 {
                let slope = q1 - q0 * t1 / n;
                let drop = q0 * q0 / (n * bb) + slope * slope / (bb * stt);
                if drop.is_finite() && drop > ramp[j].0 {
                    ramp[j] = (drop, self.len, slope / (bb * stt));
                }
            }
        }
        let (kinds, top) = (KINDS, top_hypothesis(&best[..l])?);
        let (j, k, h) = (top.actuator, top.kind, best[top.actuator][top.kind]);
        let first = &self.buf[(self.head + cap - h.1) % cap];
        // Lag-one autocorrelation of what the fit leaves, pooled over the rows: gusts and model
        // error make it coloured, and a coloured residual holds fewer independent samples.
        let b = &self.effects[j];
        let fitted = |e: &Entry, i: usize| -> f64 {
            let u = e.u[j];
            let s = match kinds[k] {
                ChangeKind::Gain => (h.2 - 1.0) * u,
                ChangeKind::Offset => h.2,
                ChangeKind::Stuck => h.2 - u,
            };
            e.r[i] - b[i] * s
        };
        // Walking back from the newest sample, each one's fit residual pairs with the one
        // after it (kept from the previous iteration).
        let (mut lag, mut sq) = (0.0, 0.0);
        let mut newer: Option<[f64; 4]> = None;
        for n in 1..=h.1 {
            let e = &self.buf[(self.head + cap - n) % cap];
            let mut x = [0.0; 4];
            for (i, xi) in x.iter_mut().enumerate().take(self.rows) {
                *xi = fitted(e, i);
                sq += *xi * *xi;
                if let Some(next) = newer {
                    lag += *xi * next[i];
                }
            }
            newer = Some(x);
        }
        let autocorrelation = if sq > 0.0 {
            (lag / sq).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // θ's spread, counting the independent samples as `margin_over` does.
        let rho = autocorrelation.clamp(0.0, 0.999);
        let value_std = (h.3 / h.5 * (1.0 + rho) / (1.0 - rho)).sqrt();
        Some(Reading {
            autocorrelation,
            value_std,
            command_mean: h.4,
            command_rms: self.command_rms(j, h.1),
            actuator: j,
            kind: kinds[k],
            value: h.2,
            since: first.t,
            samples: h.1,
            drop: h.0,
            noise_var: h.3,
            next_kind_drop: top.next_kind_drop,
            next_actuator_drop: top.next_actuator_drop,
            mixed_drop: mixed[j],
            ramp_drop: ramp[j].0,
            ramp_rate: ramp[j].2,
            ramp_samples: ramp[j].1,
            ramp_since: self.buf[(self.head + cap - ramp[j].1.max(1)) % cap].t,
        })
    }

    /// Actuator `j`'s gain and offset changes over the newest `samples` stored, compared with
    /// the residual whitened by its learned colour (generalised least squares; `None` until
    /// the colour is learned). Wind and slow model error carry over from one sample to the
    /// next, so the plain fit weighs what they share with a slowly moving command; whitened,
    /// the command's sample-to-sample moves, where a gain and an offset differ, weigh in full.
    /// No allocation.
    pub fn whitened_gain_or_offset(&self, j: usize, samples: usize) -> Option<KindFit> {
        self.whitened_gain_or_offset_within(j, samples, samples)
    }

    /// [`Self::whitened_gain_or_offset`] of a change `changed` samples old (at most the
    /// store), fitted on the newest `samples` of them only: the regressors start at the
    /// change, so that the fit on a later part of a change is not pulled towards healthy by
    /// the whitening (which, running from the store's start, has partly predicted the change
    /// away by then; tested), and fits on disjoint parts of one change pool (their sums are
    /// those of the fit on all of them, split).
    pub fn whitened_gain_or_offset_within(
        &self,
        j: usize,
        changed: usize,
        samples: usize,
    ) -> Option<KindFit> {
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
        // Oldest of the stretch first: the residual's filter runs over the whole store (its
        // state at the change is the healthy past's), each regressor's from zero at the
        // change (zero before it), all with the same gains; the sums over the stretch.
        let entry = |k: usize| &self.buf[(self.head + cap - self.len + k) % cap];
        let start = self.len - n;
        let change_start = self.len - changed.clamp(n, self.len);
        let (mut pr, mut pg, mut po) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        let mut pv = [0.0f64; 4];
        for (p, wi) in pv.iter_mut().zip(&w) {
            *p = wi.start();
        }
        let (mut gy, mut gx, mut oy, mut ox, mut base) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let (mut go, mut su) = (0.0, 0.0);
        for k in 0..self.len {
            let e = entry(k);
            let inside = k >= start;
            let u = e.u[j];
            if inside {
                su += u;
            }
            for (i, wi) in w.iter().enumerate().take(rows) {
                let (gain, scale, next) = wi.advance(pv[i]);
                pv[i] = next;
                let y = wi.apply(&mut pr[i], e.r[i], gain, scale);
                if k < change_start {
                    continue;
                }
                let g = wi.apply(&mut pg[i], b[i] * u, gain, scale);
                let o = wi.apply(&mut po[i], b[i], gain, scale);
                if !inside {
                    continue;
                }
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
        for k in 0..n {
            let e = &self.buf[(oldest + k) % cap];
            let x = &mut self.scratch[k];
            for (i, &(_, theta, c, alpha)) in filt.iter().enumerate().take(rows) {
                let wi = &w[i];
                let (gain, scale, next) = wi.advance(spread[i]);
                spread[i] = next;
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
            let e = &self.buf[(oldest + tau) % cap];
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

/// [`ChangeTest::whitened_gain_or_offset`]'s answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KindFit {
    /// Gain or offset, whichever fits the whitened residual better, and its value.
    pub kind: ChangeKind,
    pub value: f64,
    /// Its standard deviation from the whitened fit.
    pub value_std: f64,
    /// Twice the log likelihood ratio over the other kind, and of the pair (both together)
    /// over this one, in the whitened residual's noise.
    pub margin: f64,
    pub mixed_margin: f64,
    pub command_mean: f64,
    /// The output's value if it is stuck (gain 0), from the same whitened residual, and its
    /// standard deviation.
    pub stuck_value: f64,
    pub stuck_std: f64,
    /// The gain fitted together with the offset (the offset free), and its standard
    /// deviation, in the same whitened residual (NaN and infinite where the two regressors
    /// cannot be told apart).
    pub pair_gamma: f64,
    pub pair_gamma_std: f64,
    /// The pair's offset (NaN without a pair).
    pub pair_delta: f64,
}

/// What the residual's colour learns from a stored sample.
#[derive(Debug, Clone, Copy)]
enum Learn {
    /// Nothing (a change under way): the lags start again after it.
    No,
    /// The residual as it is (healthy).
    Raw,
    /// The residual less an identified change of one actuator's output,
    /// `gain_change · u + offset` (weighted effect per unit of output).
    Without {
        actuator: usize,
        gain_change: f64,
        offset: f64,
    },
}

/// The most samples a [`ChangeTest`] keeps.
pub const MAX_STORE: usize = 600;

/// Largest AR(1) coefficient the colour takes (a slower colour is read as 0.99).
const PHI_MAX: f64 = 0.99;

/// One row's noise model for its innovation filter: an AR(1) part (coefficient `phi`,
/// stationary variance `ar`, fresh variance per sample `fresh`) seen through white noise
/// (`white`). The filter starts from the AR part's stationary spread (the wind's level at the
/// store's first sample is unknown) and its gain settles as the samples come (time-varying
/// Kalman filter): prediction `h' = phi (h + k (x - h))`, output `(x - h) scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Whiten {
    phi: f64,
    ar: f64,
    fresh: f64,
    white: f64,
}

/// No colour: the residual as it is.
const IDENTITY: Whiten = Whiten {
    phi: 0.0,
    ar: 0.0,
    fresh: 0.0,
    white: 1.0,
};

impl Whiten {
    /// The filter at its steady state as `(φ, θ, c, α)`: the innovation of `x` is
    /// `c (1 - φ z⁻¹)/(1 - θ z⁻¹) x`, whose impulse response is `c` and then
    /// `α θ^(m-1)` (`θ = φ (1 - k)` with the steady gain `k`, `α = c (θ - φ)`).
    fn steady(&self) -> (f64, f64, f64, f64) {
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
    fn start(&self) -> f64 {
        self.ar
    }

    /// From the prediction variance `p`: this sample's gain, output scale and the next
    /// prediction variance.
    fn advance(&self, p: f64) -> (f64, f64, f64) {
        let s2 = p + self.white;
        let k = p / s2;
        (
            k,
            1.0 / s2.sqrt(),
            self.phi * self.phi * (1.0 - k) * p + self.fresh,
        )
    }

    /// One series' sample `x` through the filter with this sample's `gain` and `scale` (from
    /// [`Whiten::advance`]): its whitened value, and `predicted` carried to the next sample.
    fn apply(&self, predicted: &mut f64, x: f64, gain: f64, scale: f64) -> f64 {
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
struct Colour {
    mean: [f64; 4],
    /// Autocovariances at lags 0..=3 per row.
    cov: [[f64; 4]; 4],
    /// The previous three residuals (newest first) while consecutive and learned from.
    history: [[f64; 4]; 3],
    history_len: usize,
    /// Samples learned, the averaging memory, and how many make the colour usable.
    learned: usize,
    memory: usize,
    needed: usize,
}

impl Colour {
    fn learn(&mut self, r: &[f64; 4], rows: usize) {
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
    fn break_history(&mut self) {
        self.history_len = 0;
    }

    /// Each row's noise model for the innovation filter; the identity until learned or
    /// where the row's statistics are not usable.
    fn whitening(&self, rows: usize) -> [Whiten; 4] {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rng::Rng;

    /// Three actuators on three axes (one of them mixing two), unit weights.
    fn effects() -> Vec<[f64; 4]> {
        vec![
            [1.0, 0.0, 0.2, 0.0],
            [0.0, 1.0, -0.2, 0.0],
            [0.6, 0.6, 0.3, 0.0],
        ]
    }

    /// Residuals of a change of actuator `j` from step `onset` on, with white noise and
    /// commands varying about 0.5; returns the test after `steps`.
    fn run(j: usize, kind: ChangeKind, theta: f64, onset: usize, steps: usize) -> ChangeTest {
        let b = effects();
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 400, 10, 1);
        let mut rng = Rng::new(7);
        for k in 0..steps {
            let t = k as f64 * 0.02;
            let u: Vec<f64> = (0..3)
                .map(|i| 0.5 + 0.1 * (t * (1.3 + i as f64)).sin())
                .collect();
            let s = if k >= onset {
                match kind {
                    ChangeKind::Gain => (theta - 1.0) * u[j],
                    ChangeKind::Offset => theta,
                    ChangeKind::Stuck => theta - u[j],
                }
            } else {
                0.0
            };
            let mut r = [0.0; 4];
            for i in 0..3 {
                r[i] = b[j][i] * s + 0.05 * rng.normal();
            }
            test.push(t, &r, &u, false);
        }
        test
    }

    #[test]
    fn each_kind_of_change_is_read_with_its_actuator_size_and_onset() {
        for (j, kind, theta) in [
            (0, ChangeKind::Gain, 0.6),
            (1, ChangeKind::Offset, -0.1),
            (2, ChangeKind::Stuck, 0.45),
        ] {
            let test = run(j, kind, theta, 200, 350);
            let r = test.evaluate().expect("a reading");
            assert_eq!((r.actuator, r.kind), (j, kind), "{r:?}");
            assert!((r.value - theta).abs() < 0.02, "{r:?}");
            // Onset at step 200 = 4.0 s.
            assert!((r.since - 4.0).abs() <= 0.1, "{r:?}");
            assert!(r.drop > r.next_kind_drop && r.drop > r.next_actuator_drop);
            // The fit leaves the noise: variance 0.05² per row.
            assert!((r.noise_var / 0.0025 - 1.0).abs() < 0.3, "{r:?}");
        }
    }

    /// The reading after 7 s (350 steps) in which actuator 1's offset is `offset(t)`, with
    /// noise 0.02 a row and a store of `capacity` samples.
    fn offset_change(capacity: usize, seed: u64, offset: impl Fn(f64) -> f64) -> Reading {
        let b = effects();
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, capacity, 10, 1);
        let mut rng = Rng::new(seed);
        for k in 0..350 {
            let t = k as f64 * 0.02;
            let u: Vec<f64> = (0..3)
                .map(|i| 0.5 + 0.1 * (t * (1.3 + i as f64)).sin())
                .collect();
            let s = offset(t);
            let mut r = [0.0; 4];
            for i in 0..3 {
                r[i] = b[1][i] * s + 0.02 * rng.normal();
            }
            test.push(t, &r, &u, false);
        }
        test.evaluate().unwrap()
    }

    #[test]
    fn a_drift_fits_a_ramp_clearly_and_a_step_does_not() {
        // Actuator 1's offset grows 0.05 a second from 4 s: at 7 s the ramp fits clearly
        // better than any step, with its rate and start (noise 0.02 a row: the rate's standard
        // error over 3 s is about 0.002). An offset step of the size the ramp reaches (+0.15
        // from 4 s) fits the step best, the ramp clearly worse.
        let r = offset_change(400, 11, |t| if t >= 4.0 { 0.05 * (t - 4.0) } else { 0.0 });
        assert_eq!(r.actuator, 1, "{r:?}");
        assert!(-r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
        assert!((r.ramp_rate - 0.05).abs() < 0.005, "{r:?}");
        assert!((r.ramp_samples as f64 * 0.02 - 3.0).abs() < 0.2, "{r:?}");
        assert!((r.ramp_since - 4.0).abs() < 0.2, "{r:?}");
        assert!(r.ramp_drop >= r.mixed_drop, "{r:?}");
        let r = offset_change(400, 11, |t| if t >= 4.0 { 0.15 } else { 0.0 });
        assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
        assert!(r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
    }

    #[test]
    fn a_drift_older_than_the_store_still_fits_a_ramp_and_an_old_offset_does_not() {
        // Store of 150 samples (3 s). Actuator 1's offset has grown 0.05 a second since 1 s;
        // at 7 s the store holds only the ramp's last 3 s, which start at +0.15: the ramp over
        // the whole store (offset and slope) fits clearly better than any step. An offset of
        // +0.3 since 1 s fits no slope: not a drift.
        let r = offset_change(150, 5, |t| if t >= 1.0 { 0.05 * (t - 1.0) } else { 0.0 });
        assert_eq!(r.actuator, 1, "{r:?}");
        assert_eq!(r.ramp_samples, 150, "{r:?}");
        assert!((r.ramp_rate - 0.05).abs() < 0.01, "{r:?}");
        assert!(-r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
        let r = offset_change(150, 5, |t| if t >= 1.0 { 0.3 } else { 0.0 });
        assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
        assert!(-r.margin_over(r.ramp_drop) < 20.0, "{r:?}");
    }

    #[test]
    fn the_ring_keeps_the_latest_samples_and_a_change_older_than_it_starts_at_its_oldest() {
        // Capacity 400: after 600 steps with the change at 450 the onset is still found; with
        // the change at 100 the whole stored stretch is the changed one.
        let test = run(1, ChangeKind::Gain, 0.7, 450, 600);
        let r = test.evaluate().unwrap();
        assert_eq!((r.actuator, r.kind), (1, ChangeKind::Gain), "{r:?}");
        assert!((r.since - 9.0).abs() <= 0.1 && r.samples <= 160, "{r:?}");
        let test = run(1, ChangeKind::Gain, 0.7, 100, 600);
        let r = test.evaluate().unwrap();
        assert_eq!(test.len(), 400);
        assert_eq!(r.samples, 400, "{r:?}");
        assert!((r.since - 200.0 * 0.02).abs() < 1e-9, "{r:?}");
        assert!((r.value - 0.7).abs() < 0.02, "{r:?}");
    }

    #[test]
    fn white_noise_gives_no_decisive_margin() {
        // What the diagnosis acts on: the best reading's margin over any other actuator and
        // over the other kinds, in independent samples. Under no change both stay far below
        // the 20 the diagnosis asks for.
        for seed in 1..20 {
            let b = effects();
            let mut test = ChangeTest::new(b, [1.0; 4], 3, 300, 10, 1);
            let mut rng = Rng::new(seed);
            for k in 0..300 {
                let t = k as f64 * 0.02;
                let u = [
                    0.5 + 0.1 * (t * 1.3).sin(),
                    0.5 + 0.1 * (t * 2.3).sin(),
                    0.5,
                ];
                let r = [rng.normal(), rng.normal(), rng.normal(), 0.0];
                test.push(t, &r, &u, false);
            }
            let r = test.evaluate().unwrap();
            assert!(
                r.margin_over(r.next_actuator_drop) < 20.0
                    && r.margin_over(r.next_kind_drop) < 20.0,
                "seed {seed}: {r:?}"
            );
        }
    }

    #[test]
    fn coloured_residuals_count_fewer_independent_samples() {
        let r = Reading {
            actuator: 0,
            kind: ChangeKind::Gain,
            value: 0.5,
            value_std: 0.1,
            since: 0.0,
            samples: 100,
            drop: 120.0,
            noise_var: 1.0,
            autocorrelation: 0.0,
            command_mean: 0.5,
            command_rms: 0.5,
            next_kind_drop: 100.0,
            next_actuator_drop: 0.0,
            mixed_drop: 0.0,
            ramp_drop: 0.0,
            ramp_rate: 0.0,
            ramp_samples: 0,
            ramp_since: 0.0,
        };
        assert!((r.margin_over(r.next_kind_drop) - 20.0).abs() < 1e-9);
        let coloured = Reading {
            autocorrelation: 0.8,
            ..r
        };
        // (1 - 0.8) / (1 + 0.8) of the samples are independent.
        assert!((coloured.margin_over(coloured.next_kind_drop) - 20.0 / 9.0).abs() < 1e-9);
        let anti = Reading {
            autocorrelation: -0.5,
            ..r
        };
        assert!((anti.margin_over(anti.next_kind_drop) - 20.0).abs() < 1e-9);
    }

    #[test]
    fn the_residual_autocorrelation_is_measured_on_the_changed_stretch() {
        // A gain change with AR(1) noise of coefficient φ on every row: the reading's lag-one
        // autocorrelation is φ (0 for white noise), within sampling error.
        for phi in [0.0f64, 0.5, 0.9] {
            let b = effects();
            let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 2000, 10, 1);
            let mut rng = Rng::new(11);
            let mut w = [0.0; 3];
            for k in 0..2000 {
                let t = k as f64 * 0.02;
                let u = [0.5 + 0.1 * (t * 1.3).sin(), 0.5, 0.5];
                let s = if k >= 200 { -0.4 * u[0] } else { 0.0 };
                let mut r = [0.0; 4];
                for i in 0..3 {
                    w[i] = phi * w[i] + (1.0 - phi * phi).sqrt() * 0.05 * rng.normal();
                    r[i] = b[0][i] * s + w[i];
                }
                test.push(t, &r, &u, false);
            }
            let r = test.evaluate().unwrap();
            assert_eq!((r.actuator, r.kind), (0, ChangeKind::Gain), "{r:?}");
            assert!((r.autocorrelation - phi).abs() < 0.05, "phi {phi}: {r:?}");
        }
    }

    #[test]
    fn a_gain_and_an_offset_together_fit_as_mixed_and_one_kind_alone_does_not() {
        // A servo whose PWM is scaled about 1000 µs: about its trim, gain 0.75 and offset
        // -0.25 at once. The two-unknown fit leaves only the noise; the best single kind
        // leaves far more. A pure gain change gains nothing from the second unknown.
        let b = effects();
        let fit = |mixed: bool| {
            let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 400, 10, 1);
            let mut rng = Rng::new(4);
            for k in 0..400 {
                let t = k as f64 * 0.02;
                let u = [0.3 * (t * 1.9).sin(), 0.0, 0.0];
                let s = if k >= 100 {
                    -0.25 * u[0] - if mixed { 0.25 } else { 0.0 }
                } else {
                    0.0
                };
                let mut r = [0.0; 4];
                for i in 0..3 {
                    r[i] = b[0][i] * s + 0.05 * rng.normal();
                }
                test.push(t, &r, &u, false);
            }
            test.evaluate().unwrap()
        };
        let both = fit(true);
        assert_eq!(both.actuator, 0);
        assert!(-both.margin_over(both.mixed_drop) > 100.0, "{both:?}");
        let gain = fit(false);
        assert_eq!(
            (gain.actuator, gain.kind),
            (0, ChangeKind::Gain),
            "{gain:?}"
        );
        assert!(-gain.margin_over(gain.mixed_drop) < 20.0, "{gain:?}");
    }

    #[test]
    fn noise_alone_explains_little() {
        let test = run(0, ChangeKind::Offset, 0.0, 0, 400);
        let r = test.evaluate().expect("a reading");
        // Under no change the drop is a maximum of chi-square(1) variables in noise units.
        assert!(r.drop / r.noise_var < 30.0, "{r:?}");
    }

    #[test]
    fn a_non_finite_residual_drops_the_record_and_too_few_samples_read_nothing() {
        let mut test = run(0, ChangeKind::Gain, 0.5, 100, 300);
        assert!(test.evaluate().is_some());
        test.push(9.0, &[f64::NAN, 0.0, 0.0, 0.0], &[0.5; 3], false);
        assert!(test.is_empty());
        assert_eq!(test.evaluate(), None);
        for k in 0..5 {
            test.push(
                10.0 + k as f64 * 0.02,
                &[0.1, 0.0, 0.0, 0.0],
                &[0.5; 3],
                false,
            );
        }
        assert_eq!(test.evaluate(), None);
    }

    /// A residual of `steps` samples: an AR(1) part (coefficient `phi`, stationary std
    /// `ar_std`) plus white noise (`white_std`) on each of three rows.
    fn coloured(
        rng: &mut Rng,
        steps: usize,
        phi: f64,
        ar_std: f64,
        white_std: f64,
    ) -> Vec<[f64; 4]> {
        let fresh = ar_std * (1.0 - phi * phi).sqrt();
        let mut g = [0.0f64; 3];
        (0..steps)
            .map(|_| {
                let mut r = [0.0; 4];
                for i in 0..3 {
                    g[i] = phi * g[i] + fresh * rng.normal();
                    r[i] = g[i] + white_std * rng.normal();
                }
                r
            })
            .collect()
    }

    /// During an identified change the colour learns from the residual with the change taken
    /// out: with the right identification (a loss and an offset, or a stuck output), exactly
    /// what it would have learned from the noise alone, in the weighted residual's units; with
    /// a wrong one, something else; with none, nothing (the lags restart).
    #[test]
    fn the_colour_learns_on_through_an_identified_change() {
        let mut rng = Rng::new(11);
        let (healthy, steps) = (300, 1500);
        let weights = [2.0, 0.5, 4.0, 1.0];
        // The noise in weighted units; the residual pushed is unweighted.
        let noise = coloured(&mut rng, steps, 0.98, 0.1, 0.03);
        let unweighted = |r: &[f64; 4]| -> [f64; 4] { std::array::from_fn(|i| r[i] / weights[i]) };
        let u: Vec<[f64; 3]> = (0..steps)
            .map(|k| [0.5, 0.5 + 0.3 * (0.05 * k as f64).sin(), 0.5])
            .collect();
        // Actuator 1's output from `healthy` on: gamma u + delta.
        let fed = |(gamma, delta): (f64, f64), identified: Option<(f64, f64)>| {
            let mut test = ChangeTest::new(effects(), weights, 3, 300, 10, 3000);
            for (k, (n, u)) in noise.iter().zip(&u).enumerate() {
                let t = k as f64 * 0.02;
                if k < healthy {
                    test.push(t, &unweighted(n), u, true);
                    continue;
                }
                let s = (gamma - 1.0) * u[1] + delta;
                let b = effects()[1];
                let r = unweighted(&std::array::from_fn(|i| n[i] + b[i] * s));
                match identified {
                    Some((g, d)) => test.push_identified(t, &r, u, 1, g, d),
                    None => test.push(t, &r, u, false),
                }
            }
            test.colour
        };
        let mut reference = ChangeTest::new(effects(), weights, 3, 300, 10, 3000);
        for (k, (n, u)) in noise.iter().zip(&u).enumerate() {
            reference.push(k as f64 * 0.02, &unweighted(n), u, true);
        }
        let reference = reference.colour;
        // A loss with an offset, and an output stuck at 0.4 (gain 0, offset its value).
        for fault in [(0.6, 0.03), (0.0, 0.4)] {
            let right = fed(fault, Some(fault));
            assert_eq!(right.learned, reference.learned);
            for (a, b) in right
                .cov
                .iter()
                .flatten()
                .zip(reference.cov.iter().flatten())
            {
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1e-6),
                    "{fault:?}: {a} vs {b}"
                );
            }
        }
        let wrong = fed((0.6, 0.03), Some((0.8, 0.03)));
        assert!((wrong.cov[1][3] - reference.cov[1][3]).abs() > 0.1 * reference.cov[1][3].abs());
        let none = fed((0.6, 0.03), None);
        assert_eq!(none.learned, healthy - 3);
    }

    #[test]
    fn the_learned_colour_whitens_a_coloured_residual() {
        let mut rng = Rng::new(3);
        let mut test = ChangeTest::new(effects(), [1.0; 4], 3, 300, 10, 3000);
        // Wind-like: most of the variance in a slow AR(1) part.
        let (phi, ar, white) = (0.97, 1.0, 0.5);
        for (k, r) in coloured(&mut rng, 6000, phi, ar, white).iter().enumerate() {
            test.push(k as f64 * 0.02, r, &[0.5; 3], true);
        }
        assert!(test.colour_learned());
        let w = test.colour.whitening(3);
        // The filter applied to a fresh stretch of the same process: unit variance, no
        // lag-one correlation left (before: about phi·ar²/(ar² + white²) = 0.78).
        let fresh = coloured(&mut rng, 20000, phi, ar, white);
        for (i, wi) in w.iter().enumerate().take(3) {
            let (mut h, mut pv) = (0.0, wi.start());
            let out: Vec<f64> = fresh
                .iter()
                .map(|r| {
                    let (gain, scale, next) = wi.advance(pv);
                    pv = next;
                    wi.apply(&mut h, r[i], gain, scale)
                })
                .collect();
            let n = out.len() as f64;
            let var = out.iter().map(|e| e * e).sum::<f64>() / n;
            let lag1 = out.windows(2).map(|x| x[0] * x[1]).sum::<f64>() / n / var;
            assert!((var - 1.0).abs() < 0.1, "row {i}: variance {var}");
            assert!(lag1.abs() < 0.1, "row {i}: lag-one correlation {lag1}");
        }
    }

    /// A gain or an offset change of actuator 0, or its output stuck at `theta`, from step 1400
    /// of 1800 (the store keeps 100 samples from before it), under a wind-like residual (its
    /// slow part 10 times the sensor noise), with the command moving a few per cent about 0.5
    /// (a hovering motor's).
    fn hover_change(kind: ChangeKind, theta: f64, seed: u64) -> ChangeTest {
        let b = effects();
        let mut rng = Rng::new(seed);
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 500, 10, 3000);
        let residual = coloured(&mut rng, 1800, 0.97, 0.1, 0.01);
        for (k, r) in residual.iter().enumerate() {
            let t = k as f64 * 0.02;
            let u: Vec<f64> = (0..3)
                .map(|i| 0.5 + 0.04 * ((t * (7.0 + i as f64)).sin() + rng.normal()))
                .collect();
            let s = match (k >= 1400, kind) {
                (false, _) => 0.0,
                (true, ChangeKind::Gain) => (theta - 1.0) * u[0],
                (true, ChangeKind::Stuck) => theta - u[0],
                (true, _) => theta,
            };
            let mut r = *r;
            for i in 0..3 {
                r[i] += b[0][i] * s;
            }
            test.push(t, &r, &u, k < 1400);
        }
        test
    }

    /// A loss older than the store, fitted on the store's newest part: with the regressors from
    /// the change (the store's start) the fit is the loss (to the little noise in the store);
    /// with the regressors
    /// from the part's start, the whitening has partly predicted the loss away and the fit is
    /// pulled towards healthy.
    #[test]
    fn a_later_part_of_a_change_fits_it_with_the_regressors_from_the_change() {
        let mut rng = Rng::new(5);
        let mut test = ChangeTest::new(effects(), [1.0; 4], 3, 300, 10, 3000);
        let u = |k: usize| [0.5 + 0.2 * (0.07 * k as f64).sin(), 0.5, 0.5];
        for (k, r) in coloured(&mut rng, 1000, 0.98, 0.1, 0.02).iter().enumerate() {
            test.push(k as f64 * 0.02, r, &u(k), true);
        }
        assert!(test.colour_learned());
        let (gamma, b) = (0.5, effects()[0]);
        for k in 1000..1400 {
            let s = (gamma - 1.0) * u(k)[0];
            // (A little sensor noise: a residual the fit explains exactly has no spread.)
            let r: [f64; 4] = std::array::from_fn(|i| b[i] * s + 1e-5 * rng.normal());
            test.push(k as f64 * 0.02, &r, &u(k), false);
        }
        let len = test.len();
        for part in [30, 100, 150] {
            let within = test.whitened_gain_or_offset_within(0, len, part).unwrap();
            assert_eq!(within.kind, ChangeKind::Gain);
            assert!(
                (within.value - gamma).abs() < 1e-3,
                "{part}: {}",
                within.value
            );
            let from_part = test.whitened_gain_or_offset(0, part).unwrap();
            assert!(
                (from_part.value - gamma).abs() > 0.05,
                "{part}: {}",
                from_part.value
            );
        }
    }

    #[test]
    fn a_hovering_motors_gain_and_offset_are_told_apart_on_the_whitened_residual() {
        // An offset of -0.15 at a command of 0.5 moves the output as a gain of 0.7 does.
        for (kind, theta) in [(ChangeKind::Offset, -0.15), (ChangeKind::Gain, 0.7)] {
            let mut clear = 0;
            for seed in 1..=10 {
                let test = hover_change(kind, theta, seed);
                let fit = test
                    .whitened_gain_or_offset(0, 400)
                    .expect("colour learned");
                assert_eq!(fit.kind, kind, "seed {seed}: {fit:?}");
                // (The offset's level is what the slow wind hides most: 0.043 at worst here.)
                assert!((fit.value - theta).abs() < 0.06, "seed {seed}: {fit:?}");
                assert!(fit.margin >= 10.0, "seed {seed}: {fit:?}");
                assert!(fit.mixed_margin < 20.0, "seed {seed}: {fit:?}");
                clear += usize::from(fit.margin >= 20.0);
                // The plain fit cannot tell them apart here (it picks either).
                let plain = test.evaluate().expect("a reading");
                assert!(
                    plain.margin_over(plain.next_kind_drop) < 5.0,
                    "seed {seed}: {plain:?}"
                );
            }
            assert!(clear >= 9, "{kind:?}: clear on {clear} of 10");
        }
    }

    /// Root mean square of `(value - truth) / std` over readings.
    fn rms_z(z: &[f64]) -> f64 {
        (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt()
    }

    #[test]
    fn the_whitened_fits_spread_is_what_it_says() {
        // 30 seeds of each: with the spread right, the RMS of the standardised errors is 1
        // (0.75-1.25 holds 95 % of 30-sample draws); the colour is learned, not given, so a
        // little more is allowed, and well below or above is wrong.
        // A motor stuck a little above its hovering command too: its value from the same
        // whitened residual (the reading tells the kind).
        let cases = [
            (ChangeKind::Offset, -0.15),
            (ChangeKind::Gain, 0.7),
            (ChangeKind::Stuck, 0.545),
        ];
        // The gain fitted with the offset free too: the offset's gain is 1, a stuck one's 0.
        for (kind, theta) in cases {
            let gamma = match kind {
                ChangeKind::Offset => 1.0,
                ChangeKind::Gain => theta,
                _ => 0.0,
            };
            let (z, z_pair): (Vec<f64>, Vec<f64>) = (1..=30)
                .map(|seed| {
                    let fit = hover_change(kind, theta, seed)
                        .whitened_gain_or_offset(0, 400)
                        .expect("colour learned");
                    let z_pair = (fit.pair_gamma - gamma) / fit.pair_gamma_std;
                    match kind {
                        ChangeKind::Stuck => ((fit.stuck_value - theta) / fit.stuck_std, z_pair),
                        _ => ((fit.value - theta) / fit.value_std, z_pair),
                    }
                })
                .unzip();
            let (rms, rms_pair) = (rms_z(&z), rms_z(&z_pair));
            println!("{kind:?}: RMS z {rms:.2}, of the pair's gain {rms_pair:.2}");
            assert!((0.7..=1.5).contains(&rms), "{kind:?}: RMS z {rms:.2}");
            assert!(
                (0.7..=1.5).contains(&rms_pair),
                "{kind:?}: pair RMS z {rms_pair:.2}"
            );
        }
    }

    #[test]
    fn the_plain_fits_spread_is_what_it_says_on_white_noise() {
        // Offset +0.1 on actuator 1 from 4 s, white noise (see `offset_change`): the change
        // time is fitted too, so a little more than 1 is allowed.
        let z: Vec<f64> = (1..=30)
            .map(|seed| {
                let r = offset_change(400, seed, |t| if t >= 4.0 { 0.1 } else { 0.0 });
                assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
                (r.value - 0.1) / r.value_std
            })
            .collect();
        let rms = rms_z(&z);
        println!("RMS z {rms:.2}");
        assert!((0.7..=1.5).contains(&rms), "RMS z {rms:.2}");
    }

    /// A motor stuck a little above its hovering command (0.545 against 0.5) from step 1400 of
    /// 1800, actuator `stuck` of four where actuators 2 and 3 push the rates alike but for a
    /// weak third row (as a hexa's motor 5 pushing more and motor 6 giving less do, but for
    /// yaw), under a wind-like residual.
    fn small_stuck(stuck: usize, seed: u64, steps: usize) -> ChangeTest {
        let b = vec![
            [1.0, 0.0, 0.2, 0.0],
            [0.0, 1.0, -0.2, 0.0],
            [0.6, 0.6, 0.1, 0.0],
            [-0.6, -0.6, 0.1, 0.0],
        ];
        let mut rng = Rng::new(seed);
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 600, 10, 3000);
        let residual = coloured(&mut rng, steps, 0.97, 0.03, 0.01);
        for (k, r) in residual.iter().enumerate() {
            let t = k as f64 * 0.02;
            let u: Vec<f64> = (0..4)
                .map(|i| 0.5 + 0.02 * ((t * (3.0 + i as f64)).sin() + rng.normal()))
                .collect();
            let mut r = *r;
            if k >= 1400 {
                for i in 0..3 {
                    r[i] += b[stuck][i] * (0.545 - u[stuck]);
                }
            }
            test.push(t, &r, &u, k < 1400);
        }
        test
    }

    /// [`ChangeTest::whitened_search`] by brute force: every change time's regressors run
    /// through the steady-state filter from that time on (quadratic in the store).
    fn brute_force_search(test: &ChangeTest) -> (usize, ChangeKind, usize, f64, f64) {
        // (actuator, kind, samples, value, margin over any other actuator)
        let (rows, n, cap) = (test.rows, test.len, test.buf.len());
        let w = test.colour.whitening(rows);
        let filt: Vec<_> = w.iter().take(rows).map(|wi| wi.steady()).collect();
        let entries: Vec<Entry> = (0..n)
            .map(|k| test.buf[(test.head + cap - n + k) % cap])
            .collect();
        // Apply the steady filter to x (zero before its first sample).
        let whiten = |f: (f64, f64, f64, f64), x: &[f64]| -> Vec<f64> {
            let (_, theta, c, alpha) = f;
            let mut h = 0.0;
            x.iter()
                .map(|&v| {
                    let out = c * v + alpha * h;
                    h = theta * h + v;
                    out
                })
                .collect()
        };
        // The residual through the time-varying filter from the stationary spread.
        let y: Vec<Vec<f64>> = (0..rows)
            .map(|i| {
                let (mut h, mut p) = (0.0, w[i].start());
                entries
                    .iter()
                    .map(|e| {
                        let (gain, scale, next) = w[i].advance(p);
                        p = next;
                        w[i].apply(&mut h, e.r[i], gain, scale)
                    })
                    .collect()
            })
            .collect();
        let mut best = vec![[(0.0f64, 0usize, 0.0f64, 0.0f64); 3]; test.effects.len()];
        for tau in 0..=n - test.min_samples {
            let m = n - tau;
            for (j, b) in test.effects.iter().enumerate() {
                let (mut gy, mut gx, mut oy, mut ox, mut go, mut base) =
                    (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
                for i in 0..rows {
                    let g = whiten(
                        filt[i],
                        &entries[tau..]
                            .iter()
                            .map(|e| b[i] * e.u[j])
                            .collect::<Vec<_>>(),
                    );
                    let o = whiten(filt[i], &vec![b[i]; m]);
                    for (k, yk) in y[i][tau..].iter().enumerate() {
                        gy += g[k] * yk;
                        gx += g[k] * g[k];
                        oy += o[k] * yk;
                        ox += o[k] * o[k];
                        go += g[k] * o[k];
                        base += yk * yk;
                    }
                }
                let sy = oy + go;
                let drops = [
                    (gy * gy / gx, 1.0 + gy / gx),
                    (oy * oy / ox, oy / ox),
                    (sy * sy / ox - 2.0 * gy - gx, sy / ox),
                ];
                for (k, (drop, value)) in drops.into_iter().enumerate() {
                    if drop > best[j][k].0 {
                        best[j][k] = (drop, m, value, base);
                    }
                }
            }
        }
        let (mut tj, mut tk) = (0, 0);
        for j in 0..best.len() {
            for k in 0..3 {
                if best[j][k].0 > best[tj][tk].0 {
                    (tj, tk) = (j, k);
                }
            }
        }
        let h = best[tj][tk];
        let other = (0..best.len())
            .filter(|&j| j != tj)
            .flat_map(|j| best[j].iter().map(|x| x.0))
            .fold(0.0, f64::max);
        let noise_var = (h.3 - h.0) / (h.1 * rows) as f64;
        let kinds = [ChangeKind::Gain, ChangeKind::Offset, ChangeKind::Stuck];
        (tj, kinds[tk], h.1, h.2, (h.0 - other) / noise_var)
    }

    #[test]
    fn the_whitened_search_equals_its_brute_force() {
        for seed in [1, 2] {
            let mut test = small_stuck(2, seed, 1600);
            let (j, kind, samples, value, margin) = brute_force_search(&test);
            let r = test.whitened_search().expect("colour learned");
            assert_eq!((r.actuator, r.kind, r.samples), (j, kind, samples), "{r:?}");
            assert!((r.value - value).abs() < 1e-9, "{r:?} against {value}");
            let m = r.margin_over(r.next_actuator_drop);
            assert!(
                (m - margin).abs() < 1e-6 * margin.abs().max(1.0),
                "{m} against {margin}"
            );
        }
    }

    #[test]
    fn the_whitened_search_names_a_small_stuck_output_and_its_onset() {
        // 1.5 s after the onset: the right actuator, stuck where it is, since the onset, clearly
        // against the actuator that moves the rates alike (whose loss the plain fit, weighing
        // the wind's slow part like independent samples, can take it for).
        // (The plain fit named it clearly on none of these seeds, and another actuator on 8.)
        for seed in 1..=10 {
            let mut test = small_stuck(2, seed, 1475);
            let r = test.whitened_search().expect("colour learned");
            assert_eq!(
                (r.actuator, r.kind),
                (2, ChangeKind::Stuck),
                "seed {seed}: {r:?}"
            );
            assert!((r.since - 28.0).abs() <= 0.2, "seed {seed}: {r:?}");
            assert!(
                r.margin_over(r.next_actuator_drop) >= 20.0,
                "seed {seed}: {r:?}"
            );
            // Its level is what the wind's slow part hides most over 1.5 s (0.49-0.58 here).
            assert!((r.value - 0.545).abs() < 0.06, "seed {seed}: {r:?}");
            let plain = test.evaluate().expect("a reading");
            assert!(
                plain.actuator != 2 || plain.margin_over(plain.next_actuator_drop) < 20.0,
                "seed {seed}: {plain:?}"
            );
        }
        // And with no change, no clear reading (nor one over the whole store, which the
        // residual's filter started cold at the store's first sample used to give).
        for seed in 1..=10 {
            let mut rng = Rng::new(100 + seed);
            let mut test = ChangeTest::new(effects(), [1.0; 4], 3, 600, 10, 3000);
            for (k, r) in coloured(&mut rng, 1800, 0.97, 0.1, 0.01).iter().enumerate() {
                let t = k as f64 * 0.02;
                let u = [0.5 + 0.02 * (t * 3.0).sin(), 0.5, 0.5];
                test.push(t, r, &u, k < 1400);
            }
            let r = test.whitened_search().expect("colour learned");
            assert!(
                r.margin_over(r.next_actuator_drop) < 20.0,
                "seed {seed}: {r:?}"
            );
            assert!(r.samples < test.len(), "seed {seed}: {r:?}");
        }
    }

    #[test]
    fn without_a_learned_colour_there_is_no_whitened_reading() {
        // Everything pushed while under way: nothing learned.
        let test = run(0, ChangeKind::Gain, 0.6, 200, 350);
        assert!(!test.colour_learned());
        assert_eq!(test.whitened_gain_or_offset(0, 150), None);
    }
}
