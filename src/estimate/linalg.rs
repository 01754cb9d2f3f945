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
const SMALL_N: usize = 6;
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

/// `A X Aᵀ` when rows `k..N` of `A` are rows of the identity (the AHCs are random walks, so
/// only the first `k` rows of the Jacobian mix): `2 k N²` products instead of `2 N³`.
pub fn sandwich_walk<const N: usize>(
    a: &SMatrix<f64, N, N>,
    x: &SMatrix<f64, N, N>,
    k: usize,
) -> SMatrix<f64, N, N> {
    if N <= SMALL_N || k > WALK_MAX_ROWS {
        return a * x * a.transpose();
    }
    // The mixing rows of A, as columns (contiguous for the dot products).
    let mut rows = [SVector::<f64, N>::zeros(); WALK_MAX_ROWS];
    for (r, row) in rows.iter_mut().enumerate().take(k) {
        *row = a.row(r).transpose();
    }
    // T = A X: rows from k on are X's own.
    let mut y = *x;
    for c in 0..N {
        let xc = x.column(c);
        for (r, row) in rows.iter().enumerate().take(k) {
            y[(r, c)] = row.dot(&xc);
        }
    }
    // Y = T Aᵀ: columns from k on are T's own; the first k from T before they change.
    let mut cols = [SVector::<f64, N>::zeros(); WALK_MAX_ROWS];
    for (col, row) in cols.iter_mut().zip(rows.iter()).take(k) {
        *col = y * row;
    }
    for (c, col) in cols.iter().enumerate().take(k) {
        y.set_column(c, col);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

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
