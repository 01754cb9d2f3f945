//! A zonotope `Z = <p, H> = { p + H ξ : ‖ξ‖∞ ≤ 1 }` in `R^P` with at most `G` generators, and
//! the three operations a bounded-error parameter estimator needs, each an outer bound that
//! never loses a point of the exact set:
//!
//! - **strip intersection** (Alamo, Bravo, Camacho, "Guaranteed state estimation by
//!   zonotopes", Automatica 41, 2005; Bravo, Alamo, Camacho, "Bounded error identification of
//!   systems with time-varying parameters", IEEE TAC 51, 2006): for the strip
//!   `S = { θ : |y - cᵀθ| ≤ σ }` and any `λ ∈ R^P`,
//!
//!   ```text
//!   Z ∩ S ⊆ < p + λ (y - cᵀp), [ (I - λcᵀ) H , σ λ ] >
//!   ```
//!
//!   (write `θ = p + Hξ` with `cᵀθ = y - σ s`, `|s| ≤ 1`; then
//!   `θ = p + λ(y - cᵀp) + (I - λcᵀ)Hξ - σλs`). We take the `λ` that minimises the squared
//!   Frobenius norm of the new generator matrix, `λ = H Hᵀ c / (cᵀ H Hᵀ c + σ²)`. The strip is
//!   disjoint from `Z` exactly when `|y - cᵀp| > σ + ‖Hᵀc‖₁` (`cᵀZ` is that interval);
//! - **Minkowski sum with a box** (a bounded change per step): exact, the box's half-widths
//!   added as generators;
//! - **order reduction** (Girard, "Reachability of uncertain linear systems using zonotopes",
//!   HSCC 2005): the generators with the smallest `‖h‖₁ - ‖h‖∞` (those a box encloses with the
//!   least excess) are replaced by the box `diag(Σ|h|)` that contains their sum.
//!
//! A coordinate's interval is `p_i ± Σ_g |H_ig|`: the exact projection of `Z`.

use nalgebra::{SMatrix, SVector};

/// A zonotope with at most `G` generators in `R^P`. Columns `used..G` of `h` are zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Zonotope<const P: usize, const G: usize> {
    pub centre: SVector<f64, P>,
    h: SMatrix<f64, P, G>,
    used: usize,
    /// How the strip gain `λ` is chosen.
    pub gain: StripGain,
}

/// The choice of `λ` in a strip intersection (every choice is an outer bound).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StripGain {
    /// Minimise the squared Frobenius norm of the generators (Alamo et al. 2005). It can widen
    /// a coordinate's interval.
    Frobenius,
    /// Minimise each coordinate's interval: `r_i(λ_i) = Σ_g |H_ig - λ_i v_g| + σ|λ_i|` with
    /// `v = Hᵀc` depends on `λ_i` alone and is convex and piecewise linear, so its minimum is
    /// the weighted median of the points `H_ig / v_g` (weights `|v_g|`) and `0` (weight `σ`).
    /// `λ_i = 0` is among the candidates: no interval ever widens.
    Hull,
}

/// What intersecting with a strip did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StripOutcome {
    /// The zonotope lay inside the strip: unchanged.
    Inside,
    /// Cut by the strip.
    Cut,
    /// Disjoint: no point of the zonotope explains the measurement; the zonotope is unchanged.
    /// `excess` is by how much `|y - cᵀp|` exceeds `σ + ‖Hᵀc‖₁`.
    Disjoint { excess: f64 },
}

impl<const P: usize, const G: usize> Zonotope<P, G> {
    /// The box `centre ± half` (a non-positive half-width gives no generator).
    pub fn from_box(centre: &SVector<f64, P>, half: &SVector<f64, P>) -> Self {
        let mut z = Self {
            centre: *centre,
            h: SMatrix::zeros(),
            used: 0,
            gain: StripGain::Hull,
        };
        z.add_box(half);
        z
    }

    pub fn generators(&self) -> usize {
        self.used
    }

    /// Half-width of the projection on coordinate `i`.
    pub fn radius(&self, i: usize) -> f64 {
        (0..self.used).map(|g| self.h[(i, g)].abs()).sum()
    }

    /// The projection on coordinate `i`: `(lo, hi)`.
    pub fn interval(&self, i: usize) -> (f64, f64) {
        let r = self.radius(i);
        (self.centre[i] - r, self.centre[i] + r)
    }

    /// `Σ_g h_ig h_jg` for coordinates `i, j`: the shape `H Hᵀ` (a second moment of the set's
    /// generators, not a covariance).
    pub fn shape(&self, i: usize, j: usize) -> f64 {
        (0..self.used)
            .map(|g| self.h[(i, g)] * self.h[(j, g)])
            .sum()
    }

    /// `Z ⊕ box(0, half)`: the half-widths join the generators (reduced first if there is no
    /// room). Exact.
    pub fn add_box(&mut self, half: &SVector<f64, P>) {
        let needed = half.iter().filter(|v| **v > 0.0).count();
        if self.used + needed > G {
            self.reduce(G.saturating_sub(needed));
        }
        for i in 0..P {
            if half[i] > 0.0 && self.used < G {
                self.h.column_mut(self.used).fill(0.0);
                self.h[(i, self.used)] = half[i];
                self.used += 1;
            }
        }
    }

    /// Outer bound of `Z ∩ { θ : |y - cᵀθ| ≤ sigma }` (see the module note).
    pub fn intersect_strip(&mut self, c: &SVector<f64, P>, y: f64, sigma: f64) -> StripOutcome {
        let mut v = SVector::<f64, G>::zeros();
        let mut reach = 0.0;
        for g in 0..self.used {
            let d = self.h.column(g).dot(c);
            v[g] = d;
            reach += d.abs();
        }
        let miss = y - c.dot(&self.centre);
        if miss.abs() > sigma + reach {
            return StripOutcome::Disjoint {
                excess: miss.abs() - sigma - reach,
            };
        }
        if miss.abs() + reach <= sigma {
            return StripOutcome::Inside;
        }
        let lambda = match self.gain {
            StripGain::Frobenius => {
                let denom = v.norm_squared() + sigma * sigma;
                if denom <= 0.0 || !denom.is_finite() {
                    return StripOutcome::Inside;
                }
                (self.h * v) / denom
            }
            StripGain::Hull => self.hull_gain(&v, sigma),
        };
        self.centre += lambda * miss;
        // H ← H - λ vᵀ: columns beyond `used` have v = 0 and stay zero.
        self.h -= lambda * v.transpose();
        if sigma > 0.0 {
            if self.used == G {
                self.reduce(G - 1);
            }
            self.h.set_column(self.used, &(lambda * sigma));
            self.used += 1;
        }
        StripOutcome::Cut
    }

    /// `λ` of [`StripGain::Hull`].
    fn hull_gain(&self, v: &SVector<f64, G>, sigma: f64) -> SVector<f64, P> {
        let mut lambda = SVector::<f64, P>::zeros();
        // (point, weight) pairs: one per generator that the strip sees, and the origin.
        let mut points = [(0.0f64, 0.0f64); G];
        for i in 0..P {
            let mut n = 0;
            let mut total = sigma;
            for g in 0..self.used {
                if v[g] != 0.0 {
                    points[n] = (self.h[(i, g)] / v[g], v[g].abs());
                    total += v[g].abs();
                    n += 1;
                }
            }
            if n == 0 {
                continue;
            }
            points[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            // The weighted median of the points and the origin (weight sigma).
            let half = 0.5 * total;
            let mut acc = 0.0;
            let mut origin_counted = false;
            let mut median = 0.0;
            for &(a, w) in &points[..n] {
                if !origin_counted && a > 0.0 {
                    acc += sigma;
                    origin_counted = true;
                    if acc >= half {
                        median = 0.0;
                        break;
                    }
                }
                acc += w;
                if acc >= half {
                    median = a;
                    break;
                }
            }
            lambda[i] = median;
        }
        lambda
    }

    /// Outer bound of `Z ∩ box(lo, hi)`: each coordinate whose interval leaves its range is
    /// intersected with that coordinate's strip.
    pub fn intersect_box(&mut self, lo: &SVector<f64, P>, hi: &SVector<f64, P>) {
        for i in 0..P {
            let (zl, zh) = self.interval(i);
            if zl < lo[i] || zh > hi[i] {
                let c = SVector::<f64, P>::from_fn(|k, _| if k == i { 1.0 } else { 0.0 });
                let outcome =
                    self.intersect_strip(&c, 0.5 * (lo[i] + hi[i]), 0.5 * (hi[i] - lo[i]));
                if let StripOutcome::Disjoint { .. } = outcome {
                    // Nothing of the set is in the range: the range is all that is known.
                    self.centre[i] = 0.5 * (lo[i] + hi[i]);
                }
            }
        }
    }

    /// Girard's reduction to at most `target` generators (`target ≥ P`): all but the
    /// `target - P` generators a box encloses worst are replaced by their bounding box.
    pub fn reduce(&mut self, target: usize) {
        let target = target.max(P).min(G);
        if self.used <= target {
            return;
        }
        let keep = target - P;
        // Generator indices sorted by the box's excess over them, largest first (kept).
        let mut order = [(0.0f64, 0usize); G];
        for g in 0..self.used {
            let col = self.h.column(g);
            let l1: f64 = col.iter().map(|v| v.abs()).sum();
            let linf = col.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            order[g] = (l1 - linf, g);
        }
        order[..self.used].sort_unstable_by(|a, b| b.0.total_cmp(&a.0));
        let mut boxed = SVector::<f64, P>::zeros();
        for &(_, g) in &order[keep..self.used] {
            for i in 0..P {
                boxed[i] += self.h[(i, g)].abs();
            }
        }
        let mut out = SMatrix::<f64, P, G>::zeros();
        for (k, &(_, g)) in order[..keep].iter().enumerate() {
            out.set_column(k, &self.h.column(g));
        }
        let mut used = keep;
        for i in 0..P {
            if boxed[i] > 0.0 {
                out[(i, used)] = boxed[i];
                used += 1;
            }
        }
        self.h = out;
        self.used = used;
    }

    /// Whether every entry is finite.
    pub fn is_finite(&self) -> bool {
        self.centre.iter().all(|v| v.is_finite()) && self.h.iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
#[path = "zonotope_tests.rs"]
mod tests;
