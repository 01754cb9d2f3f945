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

/// A ring index `i < 2 cap` brought into `0..cap` (the store's loops index it once a sample,
/// and a subtraction is a fraction of the cost of `%`).
#[inline]
pub(super) fn wrap(i: usize, cap: usize) -> usize {
    debug_assert!(i < 2 * cap);
    if i >= cap { i - cap } else { i }
}

/// The kinds of change in the order the searches index them.
const KINDS: [ChangeKind; 3] = [ChangeKind::Gain, ChangeKind::Offset, ChangeKind::Stuck];

/// One hypothesis' best fit over the change times: (drop, samples, θ, residual variance or
/// sum of squares, mean command, sum of squares of its regressor).
type Fit = (f64, usize, f64, f64, f64, f64);

/// The drops of a gain, an offset and a stuck output (in [`KINDS`] order), and of a gain and
/// an offset together, from `Σ g y`, `Σ g²`, `Σ o y`, `Σ o²`, `Σ g o` over a changed stretch
/// (`g` the gain regressor `b u`, `o` the offset regressor `b`, `y` the residual); `None`
/// where a regressor is zero or the pair is degenerate. Their values: [`kind_value`].
fn kind_drops(gy: f64, gx: f64, oy: f64, ox: f64, go: f64) -> ([Option<f64>; 3], Option<f64>) {
    // Gain and offset together: the 2×2 normal equations.
    let det = gx * ox - go * go;
    let pair = (det > 1e-9 * gx * ox).then(|| {
        let (a, d) = ((gy * ox - go * oy) / det, (gx * oy - go * gy) / det);
        a * gy + d * oy
    });
    let mut drops = [None; 3];
    if gx > 0.0 {
        drops[0] = Some(gy * gy / gx);
    }
    if ox > 0.0 {
        drops[1] = Some(oy * oy / ox);
        // Stuck at θ: r = b (θ - u); the sum of squares left is Σ(r + b u)² - (Σ b(r + b u))²/Σb²,
        // and Σ(r + b u)² = Σ r² + 2 gy + gx.
        let sy = oy + go;
        drops[2] = Some(sy * sy / ox - 2.0 * gy - gx);
    }
    (drops, pair)
}

/// The fitted value θ of kind `k` (in [`KINDS`] order) whose drop [`kind_drops`] gave: the
/// gain, the offset, the stuck output. Computed only for a fit that is kept (the search
/// compares drops over every stretch, and most are not).
fn kind_value(k: usize, gy: f64, gx: f64, oy: f64, ox: f64, go: f64) -> f64 {
    match k {
        0 => 1.0 + gy / gx,
        1 => oy / ox,
        _ => (oy + go) / ox,
    }
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
    let (drops, pair) = kind_drops(gy, gx, oy, ox, go);
    if let Some(drop) = pair.filter(|d| d.is_finite() && *d > *pair_best) {
        *pair_best = drop;
    }
    // A stuck output's regressor is the offset's (see `kind_drops`).
    for (k, ((slot, drop), ss)) in row.iter_mut().zip(drops).zip([gx, ox, ox]).enumerate() {
        if let Some(drop) = drop
            && drop.is_finite()
            && drop > slot.0
        {
            *slot = fit(drop, kind_value(k, gy, gx, oy, ox, go), ss);
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
    /// Samples pushed since the start (a reading's stretch grows by the ones pushed after it).
    pushed: u64,
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
            pushed: 0,
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
        self.pushed += 1;
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

    pub fn len(&self) -> usize {
        self.len
    }

    /// Samples pushed since the start.
    pub fn pushed(&self) -> u64 {
        self.pushed
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The root mean square of actuator `j`'s command over the newest `samples` stored.
    fn command_rms(&self, j: usize, samples: usize) -> f64 {
        let cap = self.buf.len();
        let n = samples.min(self.len).max(1);
        let ss: f64 = (1..=n)
            .map(|k| self.buf[wrap(self.head + cap - k, cap)].u[j].powi(2))
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
                let e = &self.buf[wrap(self.head + cap - n, cap)];
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
            let e = &self.buf[wrap(self.head + cap - n, cap)];
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

#[path = "whiten.rs"]
mod whiten;
use whiten::Colour;

#[cfg(test)]
#[path = "change_tests.rs"]
mod tests;
#[cfg(test)]
#[path = "change_tests_more.rs"]
mod tests_more;
