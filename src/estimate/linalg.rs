//! Small fixed-size linear algebra the filters need, allocation-free.

use super::EstimatorError;
use nalgebra::{Cholesky, Const, SMatrix, SVector};

/// Make `p` exactly symmetric: `(P + Pᵀ)/2`.
pub fn symmetrize<const N: usize>(p: &mut SMatrix<f64, N, N>) {
    for i in 0..N {
        for j in (i + 1)..N {
            let v = 0.5 * (p[(i, j)] + p[(j, i)]);
            p[(i, j)] = v;
            p[(j, i)] = v;
        }
    }
}

/// Copy the upper triangle onto the lower one.
pub fn mirror_upper<const N: usize>(p: &mut SMatrix<f64, N, N>) {
    for c in 0..N {
        for r in (c + 1)..N {
            p[(r, c)] = p[(c, r)];
        }
    }
}

/// Cholesky factorisation; on failure retry with `P + eps * max(diag P) * I` for
/// eps = 1e-12, 1e-10, 1e-8, then give up with a typed error.
pub fn cholesky_jitter<const N: usize>(
    p: &SMatrix<f64, N, N>,
    stage: &'static str,
) -> Result<Cholesky<f64, Const<N>>, EstimatorError> {
    if let Some(c) = p.cholesky() {
        return Ok(c);
    }
    let scale = (0..N)
        .map(|i| p[(i, i)].abs())
        .fold(0.0_f64, f64::max)
        .max(f64::MIN_POSITIVE);
    for eps in [1e-12, 1e-10, 1e-8] {
        let mut q = *p;
        symmetrize(&mut q);
        for i in 0..N {
            q[(i, i)] += eps * scale;
        }
        if let Some(c) = q.cholesky() {
            return Ok(c);
        }
    }
    Err(EstimatorError::NotPositiveDefinite { stage })
}

/// Largest eigenvalue and its unit eigenvector of a symmetric matrix (cyclic Jacobi; M is 3 or 4
/// here, so a few sweeps reach machine precision and nothing is allocated).
pub fn sym_top_eigen<const M: usize>(a: &SMatrix<f64, M, M>) -> (f64, SVector<f64, M>) {
    let mut a = *a;
    let mut v = SMatrix::<f64, M, M>::identity();
    for _sweep in 0..30 {
        let mut off = 0.0;
        for i in 0..M {
            for j in (i + 1)..M {
                off += a[(i, j)] * a[(i, j)];
            }
        }
        let diag: f64 = (0..M).map(|i| a[(i, i)] * a[(i, i)]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..M {
            for q in (p + 1)..M {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..M {
                    let akp = a[(k, p)];
                    let akq = a[(k, q)];
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..M {
                    let apk = a[(p, k)];
                    let aqk = a[(q, k)];
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
                for k in 0..M {
                    let vkp = v[(k, p)];
                    let vkq = v[(k, q)];
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut best = 0;
    for i in 1..M {
        if a[(i, i)] > a[(best, best)] {
            best = i;
        }
    }
    (a[(best, best)], v.column(best).into_owned())
}

/// Up to this size nalgebra's unrolled dense products beat the structured loops below
/// (measured: the paper model, n = 5).
pub const SMALL_N: usize = 6;
/// [`sandwich_walk`] handles up to this many mixing rows (the rates: 3) on the stack.
const WALK_MAX_ROWS: usize = 4;

/// The first row from which `A` is the identity (`N` when the last row is not): the rows of
/// random-walk states.
pub fn identity_tail_start<const N: usize>(a: &SMatrix<f64, N, N>) -> usize {
    let mut k = N;
    while k > 0 && (0..N).all(|c| a[(k - 1, c)] == if c == k - 1 { 1.0 } else { 0.0 }) {
        k -= 1;
    }
    k
}

/// `A X Aᵀ` for a symmetric `X` when rows `k..N` of `A` are rows of the identity (the AHCs
/// are random walks, so only the first `k` rows of the Jacobian mix). With `A = [A₁; 0 I]`
/// the result is `X` outside its first `k` rows and columns, `A₁ X` in those rows (mirrored),
/// and `A₁ X A₁ᵀ` in the corner: about `k N²` products instead of `2 N³`. Every caller passes
/// a symmetric matrix (a shape, a covariance or a derivative of one); the result is exactly
/// symmetric.
pub fn sandwich_walk<const N: usize>(
    a: &SMatrix<f64, N, N>,
    x: &SMatrix<f64, N, N>,
    k: usize,
) -> SMatrix<f64, N, N> {
    let mut out = *x;
    sandwich_walk_in_place(a, &mut out, k);
    out
}

/// [`sandwich_walk`] overwriting `x` (no copies of the N×N matrix).
#[allow(clippy::needless_range_loop)] // index loops mirror the block formulas
pub fn sandwich_walk_in_place<const N: usize>(
    a: &SMatrix<f64, N, N>,
    x: &mut SMatrix<f64, N, N>,
    k: usize,
) {
    if N <= SMALL_N || k > WALK_MAX_ROWS {
        *x = a * *x * a.transpose();
        return;
    }
    // The mixing rows of A, as columns (contiguous for the dot products).
    let mut rows = [SVector::<f64, N>::zeros(); WALK_MAX_ROWS];
    for (r, row) in rows.iter_mut().enumerate().take(k) {
        *row = a.row(r).transpose();
    }
    // T = A₁ X, row r of it as column r of `t`: (A₁ X)ᵀ = X A₁ᵀ (X symmetric), a sum of X's
    // columns (contiguous axpys, no horizontal sums).
    let mut t = [SVector::<f64, N>::zeros(); WALK_MAX_ROWS];
    for (c, xc) in x.as_slice().chunks_exact(N).enumerate() {
        for r in 0..k {
            let coeff = rows[r][c];
            for (tj, xj) in t[r].iter_mut().zip(xc) {
                *tj += coeff * xj;
            }
        }
    }
    for r in 0..k {
        for c in k..N {
            x[(r, c)] = t[r][c];
            x[(c, r)] = t[r][c];
        }
        for s in 0..=r {
            let v = t[r].dot(&rows[s]);
            x[(r, s)] = v;
            x[(s, r)] = v;
        }
    }
}

/// A measurement matrix by its nonzero entries per row. The gyro rows are unit rows and the
/// `a_z` row touches only the AHCs, so a product with `H` costs a quarter of a dense one.
#[derive(Debug, Clone, Copy)]
pub struct SparseRows<const M: usize, const N: usize> {
    index: [[usize; N]; M],
    value: [[f64; N]; M],
    len: [usize; M],
    /// Every row is a single 1: `H` only picks coordinates (the rates-only models).
    selector: bool,
}

impl<const M: usize, const N: usize> SparseRows<M, N> {
    pub fn new(h: &SMatrix<f64, M, N>) -> Self {
        let mut s = Self {
            index: [[0; N]; M],
            value: [[0.0; N]; M],
            len: [0; M],
            selector: false,
        };
        for m in 0..M {
            for c in 0..N {
                let v = h[(m, c)];
                if v != 0.0 {
                    s.index[m][s.len[m]] = c;
                    s.value[m][s.len[m]] = v;
                    s.len[m] += 1;
                }
            }
        }
        s.selector = (0..M).all(|m| s.len[m] == 1 && s.value[m][0] == 1.0);
        s
    }

    /// `H X Hᵀ` when `H` only picks coordinates: the picked block of `X`, no arithmetic.
    pub fn picked(&self, x: &SMatrix<f64, N, N>) -> Option<SMatrix<f64, M, M>> {
        self.selector
            .then(|| SMatrix::from_fn(|a, b| x[(self.index[a][0], self.index[b][0])]))
    }

    fn row(&self, m: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        (0..self.len[m]).map(move |t| (self.index[m][t], self.value[m][t]))
    }

    /// `X Hᵀ`: column m is a combination of X's columns (contiguous).
    pub fn right_t<const R: usize>(&self, x: &SMatrix<f64, R, N>) -> SMatrix<f64, R, M> {
        let mut out = SMatrix::<f64, R, M>::zeros();
        for m in 0..M {
            let mut col = SVector::<f64, R>::zeros();
            for (c, v) in self.row(m) {
                col.axpy(v, &x.column(c), 1.0);
            }
            out.set_column(m, &col);
        }
        out
    }

    /// `H X`.
    pub fn left<const C: usize>(&self, x: &SMatrix<f64, N, C>) -> SMatrix<f64, M, C> {
        let mut out = SMatrix::<f64, M, C>::zeros();
        for m in 0..M {
            let (index, value) = (&self.index[m][..self.len[m]], &self.value[m][..self.len[m]]);
            for (j, col) in x.as_slice().chunks_exact(N).enumerate() {
                // -0.0: the neutral element `Iterator::sum` starts from.
                let mut acc = -0.0;
                for (&c, &v) in index.iter().zip(value) {
                    acc += v * col[c];
                }
                out[(m, j)] = acc;
            }
        }
        out
    }

    /// `H x`.
    pub fn apply(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        SVector::from_fn(|m, _| self.row(m).map(|(c, v)| v * x[c]).sum())
    }
}

/// `G X Gᵀ` with `G = I - K H` and `X` symmetric, from `X Hᵀ` (sparse `H`) and two rank-M
/// products: about half the work of the dense `(I - KH) X (I - KH)ᵀ`. Exactly symmetric.
pub fn sandwich_gain<const N: usize, const M: usize>(
    x: &SMatrix<f64, N, N>,
    k: &SMatrix<f64, N, M>,
    h: &SparseRows<M, N>,
) -> SMatrix<f64, N, N> {
    let mut out = *x;
    sandwich_gain_in_place(&mut out, k, h);
    out
}

/// [`sandwich_gain`] overwriting `x` (the same arithmetic, no copies of the N×N matrix: the
/// sensitivity recursions run it for every adapted entry, every step).
pub fn sandwich_gain_in_place<const N: usize, const M: usize>(
    x: &mut SMatrix<f64, N, N>,
    k: &SMatrix<f64, N, M>,
    h: &SparseRows<M, N>,
) {
    // Y = G X = X - K (X Hᵀ)ᵀ; then G X Gᵀ = Y - (Y Hᵀ) Kᵀ, built on the upper triangle.
    let xh = h.right_t(x);
    *x -= k * xh.transpose();
    let yh = h.right_t(x);
    x.gemm(-1.0, &yh, &k.transpose(), 1.0);
    symmetrize(x);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sparse_products_and_gain_sandwich_match_dense() {
        let mut h = test_matrix::<4, 11>(0.53);
        for r in 0..3 {
            for c in 0..11 {
                h[(r, c)] = if r == c { 1.0 } else { 0.0 };
            }
        }
        for c in 0..3 {
            h[(3, c)] = 0.0;
        }
        let sh = SparseRows::new(&h);
        let b = test_matrix::<11, 11>(0.29);
        let x = b * b.transpose();
        let k = test_matrix::<11, 4>(0.71);
        let v = test_matrix::<11, 1>(0.17);
        assert!((sh.right_t(&x) - x * h.transpose()).amax() < 1e-12);
        assert!((sh.left(&x) - h * x).amax() < 1e-12);
        assert!((sh.apply(&v) - h * v).amax() < 1e-12);
        let g = SMatrix::<f64, 11, 11>::identity() - k * h;
        let dense = g * x * g.transpose();
        assert!((sandwich_gain(&x, &k, &sh) - dense).amax() < 1e-10 * dense.amax());
        // In place: bit for bit the formula as it was written before, with its copies.
        let y = x - k * sh.right_t(&x).transpose();
        let mut before = y;
        before.gemm(-1.0, &sh.right_t(&y), &k.transpose(), 1.0);
        symmetrize(&mut before);
        let mut in_place = x;
        sandwich_gain_in_place(&mut in_place, &k, &sh);
        assert_eq!(in_place, before);
    }

    #[test]
    fn a_picking_h_gives_the_block_and_others_no_shortcut() {
        let b = test_matrix::<5, 5>(0.43);
        let x = b * b.transpose();
        let mut h = SMatrix::<f64, 3, 5>::zeros();
        for r in 0..3 {
            h[(r, r)] = 1.0;
        }
        let block = SparseRows::new(&h).picked(&x).expect("H picks the rates");
        assert_eq!(block, h * x * h.transpose());
        // A scaled or mixed row is a product, not a pick.
        h[(2, 2)] = 0.5;
        assert!(SparseRows::new(&h).picked(&x).is_none());
        h[(2, 2)] = 1.0;
        h[(2, 4)] = 0.3;
        assert!(SparseRows::new(&h).picked(&x).is_none());
    }

    #[test]
    fn top_eigen_of_known_matrix() {
        let a = SMatrix::<f64, 3, 3>::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 1.0);
        let (l, v) = sym_top_eigen(&a);
        let r = a * v - v * l;
        assert!(r.amax() < 1e-12, "residual {r}");
        assert!((v.norm() - 1.0).abs() < 1e-12);
        // Compare with nalgebra's general symmetric eigensolver (off the hot path).
        let e = a.symmetric_eigen();
        let lmax = e.eigenvalues.iter().cloned().fold(f64::MIN, f64::max);
        assert!((l - lmax).abs() < 1e-12);
    }

    fn test_matrix<const R: usize, const C: usize>(seed: f64) -> SMatrix<f64, R, C> {
        SMatrix::from_fn(|i, j| ((i * 7 + j * 3) as f64 * seed).sin())
    }

    #[test]
    fn structured_sandwich_matches_the_plain_product() {
        let mut a = test_matrix::<7, 7>(0.37);
        for r in 3..7 {
            for c in 0..7 {
                a[(r, c)] = if r == c { 1.0 } else { 0.0 };
            }
        }
        let b = test_matrix::<7, 7>(0.91);
        let x = b * b.transpose();
        let plain = a * x * a.transpose();
        assert_eq!(identity_tail_start(&a), 3);
        assert_eq!(identity_tail_start(&SMatrix::<f64, 7, 7>::identity()), 0);
        assert_eq!(identity_tail_start(&x), 7);
        assert!((sandwich_walk(&a, &x, 3) - plain).amax() < 1e-12);
    }

    #[test]
    fn cholesky_jitter_recovers_semidefinite_and_rejects_indefinite() {
        // Rank-deficient PSD: plain Cholesky fails, jitter succeeds.
        let v = SVector::<f64, 3>::new(1.0, 2.0, 3.0);
        let p = v * v.transpose();
        assert!(cholesky_jitter(&p, "test").is_ok());
        let bad = SMatrix::<f64, 2, 2>::new(1.0, 0.0, 0.0, -1.0);
        assert!(matches!(
            cholesky_jitter(&bad, "test"),
            Err(EstimatorError::NotPositiveDefinite { .. })
        ));
    }
}
