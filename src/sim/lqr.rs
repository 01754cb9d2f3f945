//! Discrete LQR: the DARE solved once at start-up by fixed-point iteration (off the hot path).

use nalgebra::SMatrix;

/// Gain `K` with `u = -K x` minimising Σ xᵀQx + uᵀRu for `x+ = A x + B u`.
/// Returns None when the iteration does not converge (an uncontrollable design).
pub fn dlqr<const NX: usize, const NU: usize>(
    a: &SMatrix<f64, NX, NX>,
    b: &SMatrix<f64, NX, NU>,
    q: &SMatrix<f64, NX, NX>,
    r: &SMatrix<f64, NU, NU>,
) -> Option<SMatrix<f64, NU, NX>> {
    let mut p = *q;
    for _ in 0..200_000 {
        let btp = b.transpose() * p;
        let gain = (r + btp * b).cholesky()?.solve(&(btp * a));
        let mut next = a.transpose() * p * a - a.transpose() * p * b * gain + q;
        next = (next + next.transpose()) * 0.5;
        let diff = (next - p).norm();
        p = next;
        if diff <= 1e-10 * p.norm().max(1.0) {
            let btp = b.transpose() * p;
            return Some((r + btp * b).cholesky()?.solve(&(btp * a)));
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalar_dare_matches_closed_form() {
        // x+ = a x + b u: P = a²P - a²b²P²/(r + b²P) + q; solve the quadratic directly.
        let (a, b, q, r) = (1.1, 0.5, 2.0, 1.0);
        let k = dlqr(
            &SMatrix::<f64, 1, 1>::new(a),
            &SMatrix::<f64, 1, 1>::new(b),
            &SMatrix::<f64, 1, 1>::new(q),
            &SMatrix::<f64, 1, 1>::new(r),
        )
        .unwrap()[(0, 0)];
        // b²P² + (r - a²r - q b²)P - q r = 0
        let (qa, qb, qc) = (b * b, r - a * a * r - q * b * b, -q * r);
        let p = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
        let k_ref = a * b * p / (r + b * b * p);
        assert!((k - k_ref).abs() < 1e-8, "{k} vs {k_ref}");
        assert!((a - b * k).abs() < 1.0, "closed loop is stable");
    }
}
