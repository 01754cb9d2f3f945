//! A convex polygon in the plane with at most `V` vertices (counter-clockwise), for the exact
//! feasible set of one actuator's `(γ, δ)`: cut by half-planes (Sutherland-Hodgman, one edge:
//! exact), grown by a box (the exact Minkowski sum), and, when it has too many vertices, grown
//! to fewer by dropping the edge whose removal adds the least area (an outer bound). No
//! operation ever loses a point of the set it bounds.

/// A convex polygon; vertices `v[..n]` counter-clockwise. `n = 0` is never stored: a cut that
/// would empty it is refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Polygon<const V: usize> {
    v: [[f64; 2]; V],
    n: usize,
}

/// The vertex after `k` and the one before it, of `n` (`%` costs a division each).
#[inline]
fn next(k: usize, n: usize) -> usize {
    if k + 1 >= n { 0 } else { k + 1 }
}

#[inline]
fn prev(k: usize, n: usize) -> usize {
    if k == 0 { n - 1 } else { k - 1 }
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Where the lines through `p0, p1` and `q0, q1` meet (`None` when parallel).
fn meet(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> Option<[f64; 2]> {
    let d = [p1[0] - p0[0], p1[1] - p0[1]];
    let e = [q1[0] - q0[0], q1[1] - q0[1]];
    let den = d[0] * e[1] - d[1] * e[0];
    if den.abs() < 1e-300 {
        return None;
    }
    let t = ((q0[0] - p0[0]) * e[1] - (q0[1] - p0[1]) * e[0]) / den;
    Some([p0[0] + t * d[0], p0[1] + t * d[1]])
}

/// The box corner whose normal cone holds the outward normal `n`: `(sign n_x · rx, sign n_y · ry)`
/// (quadrants counted counter-clockwise from `+,+`).
fn quadrant(n: [f64; 2]) -> usize {
    match (n[0] >= 0.0, n[1] >= 0.0) {
        (true, true) => 0,
        (false, true) => 1,
        (false, false) => 2,
        (true, false) => 3,
    }
}

const CORNERS: [[f64; 2]; 4] = [[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]];

impl<const V: usize> Polygon<V> {
    /// The box `[lo[0], hi[0]] × [lo[1], hi[1]]`.
    pub fn from_box(lo: [f64; 2], hi: [f64; 2]) -> Self {
        let mut v = [[0.0; 2]; V];
        v[0] = [lo[0], lo[1]];
        v[1] = [hi[0], lo[1]];
        v[2] = [hi[0], hi[1]];
        v[3] = [lo[0], hi[1]];
        Self { v, n: 4 }
    }

    pub fn vertices(&self) -> &[[f64; 2]] {
        &self.v[..self.n]
    }

    /// `(min, max)` of `a·x + b·y` over the polygon.
    pub fn range(&self, a: f64, b: f64) -> (f64, f64) {
        self.vertices()
            .iter()
            .map(|p| a * p[0] + b * p[1])
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
                (lo.min(s), hi.max(s))
            })
    }

    /// Cut by `{ p : a·p ≤ b }`. Returns false, leaving the polygon as it was, when nothing of
    /// it is inside.
    pub fn clip(&mut self, a: [f64; 2], b: f64) -> bool {
        let side = |p: &[f64; 2]| a[0] * p[0] + a[1] * p[1] - b;
        let (lo, hi) = self.range(a[0], a[1]);
        if lo > b {
            return false;
        }
        if hi <= b {
            return true;
        }
        if self.n + 1 > V {
            self.simplify(V - 1);
        }
        let mut out = [[0.0; 2]; V];
        let mut m = 0;
        for k in 0..self.n {
            let (p, q) = (self.v[k], self.v[next(k, self.n)]);
            let (sp, sq) = (side(&p), side(&q));
            if sp <= 0.0 {
                out[m] = p;
                m += 1;
            }
            if (sp < 0.0 && sq > 0.0) || (sp > 0.0 && sq < 0.0) {
                let t = sp / (sp - sq);
                out[m] = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])];
                m += 1;
            }
        }
        self.v = out;
        self.n = m;
        self.dedup();
        true
    }

    /// `P ⊕ [-rx, rx] × [-ry, ry]`, exact: each vertex is moved by the box corners whose normal
    /// cones meet its own (the corners between its two edges' outward normals).
    pub fn grow(&mut self, rx: f64, ry: f64) {
        if rx <= 0.0 && ry <= 0.0 {
            return;
        }
        if self.n + 4 > V {
            self.simplify(V - 4);
        }
        let n = self.n;
        let normal = |a: [f64; 2], b: [f64; 2]| [b[1] - a[1], a[0] - b[0]];
        let mut out = [[0.0; 2]; V];
        let mut m = 0;
        for k in 0..n {
            let prev = self.v[prev(k, n)];
            let (p, next) = (self.v[k], self.v[next(k, n)]);
            let (from, to) = (quadrant(normal(prev, p)), quadrant(normal(p, next)));
            // Corners from the incoming edge's quadrant to the outgoing one's, turning
            // counter-clockwise (a convex polygon's normals turn that way).
            let mut q = from;
            loop {
                if m < V {
                    out[m] = [p[0] + CORNERS[q][0] * rx, p[1] + CORNERS[q][1] * ry];
                    m += 1;
                }
                if q == to {
                    break;
                }
                q = (q + 1) % 4;
            }
        }
        self.v = out;
        self.n = m;
        self.dedup();
    }

    /// Drop repeated vertices (closer than a relative 1e-12) and collinear ones.
    fn dedup(&mut self) {
        let scale = self
            .vertices()
            .iter()
            .fold(1.0f64, |s, p| s.max(p[0].abs()).max(p[1].abs()));
        let eps = 1e-12 * scale;
        let mut k = 0;
        while self.n > 3 && k < self.n {
            let n = self.n;
            let (a, b, c) = (self.v[prev(k, n)], self.v[k], self.v[next(k, n)]);
            let close = (a[0] - b[0]).abs() < eps && (a[1] - b[1]).abs() < eps;
            if close || cross(a, b, c).abs() < eps * eps {
                self.v.copy_within(k + 1..n, k);
                self.n -= 1;
            } else {
                k += 1;
            }
        }
    }

    /// Grow to at most `max` vertices: each removed edge is replaced by the meeting point of its
    /// neighbours' lines, the one whose triangle adds the least area first.
    pub fn simplify(&mut self, max: usize) {
        let max = max.max(3);
        while self.n > max {
            let n = self.n;
            let mut best: Option<(f64, usize, [f64; 2])> = None;
            for k in 0..n {
                let (a, b) = (self.v[prev(k, n)], self.v[k]);
                let (c, d) = (self.v[next(k, n)], self.v[next(next(k, n), n)]);
                // The neighbours' lines must meet beyond the edge b-c (their turns sum below π).
                let Some(w) = meet(a, b, c, d) else { continue };
                let beyond_b = (w[0] - b[0]) * (b[0] - a[0]) + (w[1] - b[1]) * (b[1] - a[1]);
                let beyond_c = (w[0] - c[0]) * (c[0] - d[0]) + (w[1] - c[1]) * (c[1] - d[1]);
                if cross(b, c, w) > 0.0 || beyond_b < 0.0 || beyond_c < 0.0 {
                    continue;
                }
                let added = 0.5 * cross(b, w, c).abs();
                if best.is_none_or(|(x, _, _)| added < x) {
                    best = Some((added, k, w));
                }
            }
            let Some((_, k, w)) = best else { return };
            // Replace b (k) and c (k + 1) by w.
            let c = next(k, n);
            self.v[k] = w;
            if c == 0 {
                self.v.copy_within(1..n, 0);
            } else {
                self.v.copy_within(c + 1..n, c);
            }
            self.n -= 1;
        }
    }

    /// The area centroid (the vertices' mean when the area vanishes).
    pub fn centroid(&self) -> [f64; 2] {
        let n = self.n;
        let o = self.v[0];
        let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for k in 1..n.saturating_sub(1) {
            let (p, q) = (self.v[k], self.v[k + 1]);
            let w = cross(o, p, q);
            a += w;
            cx += w * (o[0] + p[0] + q[0]);
            cy += w * (o[1] + p[1] + q[1]);
        }
        if a.abs() > 1e-300 {
            [cx / (3.0 * a), cy / (3.0 * a)]
        } else {
            let k = n.max(1) as f64;
            let s = self
                .vertices()
                .iter()
                .fold([0.0; 2], |s, p| [s[0] + p[0], s[1] + p[1]]);
            [s[0] / k, s[1] / k]
        }
    }

    pub fn is_finite(&self) -> bool {
        self.vertices()
            .iter()
            .all(|p| p[0].is_finite() && p[1].is_finite())
    }
}

#[cfg(test)]
#[path = "polygon_tests.rs"]
mod tests;
