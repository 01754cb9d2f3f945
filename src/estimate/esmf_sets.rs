//! Operations on the ESMF's shape matrices outside a step: a block's inflation and the
//! Minkowski sum with a jump set (a change the set must be able to follow).

use nalgebra::{SMatrix, SVector};

/// Scale rows and columns `from..N` of `p` by `s` (inflates that block by s²).
pub fn scale_block<const N: usize>(p: &mut SMatrix<f64, N, N>, from: usize, s: f64) {
    for i in 0..N {
        for j in 0..N {
            let f = (if i >= from { s } else { 1.0 }) * (if j >= from { s } else { 1.0 });
            p[(i, j)] *= f;
        }
    }
}

/// `P ← P/(1-β) + J/β`, the trace-optimal outer ellipsoid of `E(0,P) ⊕ E(0,J)`, where `J` is
/// the diagonal of `p0` on the coordinates `from..N` (zero elsewhere).
pub fn add_jump_set<const N: usize>(
    p: &mut SMatrix<f64, N, N>,
    p0: &SMatrix<f64, N, N>,
    from: usize,
) {
    let d = SVector::<f64, N>::from_fn(|i, _| if i >= from { p0[(i, i)].max(0.0) } else { 0.0 });
    minkowski_add_diagonal(p, &d, from..N);
}

/// [`add_jump_set`] on the listed coordinates only (one actuator's gain and bias).
pub fn add_jump_set_on<const N: usize>(
    p: &mut SMatrix<f64, N, N>,
    p0: &SMatrix<f64, N, N>,
    coords: &[usize],
) {
    let mut d = SVector::<f64, N>::zeros();
    for &i in coords {
        d[i] = p0[(i, i)].max(0.0);
    }
    minkowski_add_diagonal(p, &d, coords.iter().copied());
}

/// `p ← E(p) ⊕ E(diag d)` over `coords` (the trace-optimal outer ellipsoid of the Minkowski sum:
/// `p/(1-β) + diag(d)/β`); a point set `p` becomes `diag(d)`, and a zero `d` leaves `p` as it is.
pub(super) fn minkowski_add_diagonal<const N: usize>(
    p: &mut SMatrix<f64, N, N>,
    d: &SVector<f64, N>,
    coords: impl Iterator<Item = usize> + Clone,
) {
    let tr_j: f64 = coords.clone().map(|i| d[i]).sum();
    let tr_p = p.trace().max(0.0);
    if tr_j <= 0.0 {
        return;
    }
    if tr_p <= 0.0 {
        *p = SMatrix::zeros();
        for i in coords {
            p[(i, i)] = d[i];
        }
        return;
    }
    let beta = tr_j.sqrt() / (tr_j.sqrt() + tr_p.sqrt());
    *p /= 1.0 - beta;
    for i in coords {
        p[(i, i)] += d[i] / beta;
    }
}
