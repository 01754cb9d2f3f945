//! ESMF containment: every point consistent with the prior set, the process-noise set and the
//! measurement set lies inside the updated set (Monte Carlo, ≥ 10 000 accepted points), and
//! the linearisation-error box of the bilinear terms is exact.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::estimate::{Esmf, EsmfParams, remainder_box};
use ahcmon::eval::bank::{BankNoise, set_p0, x0};
use ahcmon::model::{Model, PaperHeli};
use ahcmon::sim::noise::{NoiseKind, NoiseSchedule};
use ahcmon::sim::paper::paper_params;
use ahcmon::sim::rng::Rng;
use nalgebra::{SMatrix, SVector};

/// Uniform sample in E(c, P).
fn in_ellipsoid<const N: usize>(
    rng: &mut Rng,
    c: &SVector<f64, N>,
    l: &SMatrix<f64, N, N>,
) -> SVector<f64, N> {
    let mut d = SVector::<f64, N>::from_fn(|_, _| rng.normal());
    d /= d.norm();
    let radius = rng.uniform01().powf(1.0 / N as f64);
    c + l * (d * radius)
}

/// The paper helicopter's ESMF (uniform noise) with a prior of sizeable rates, so the
/// gyroscopic linearisation error matters, correlated in roll and pitch and in gain and bias.
fn prior_set() -> (PaperHeli, BankNoise, Esmf<PaperHeli, 5, 3>) {
    let n = BankNoise::nominal(
        &NoiseSchedule::constant(NoiseKind::Uniform, 0.03),
        &NoiseSchedule::constant(NoiseKind::Uniform, 0.025),
    );
    let m = PaperHeli::new(paper_params(10.0), 0.02);
    let mut f = Esmf::new(
        m.clone(),
        EsmfParams::default(),
        x0(),
        set_p0(),
        n.set_q(),
        n.set_r(),
    );
    f.x = SVector::from([0.4, -0.3, 0.5, 0.9, 0.01]);
    f.p = SMatrix::from_diagonal(&SVector::from([0.04, 0.03, 0.05, 0.05, 1e-4]));
    for (i, j, v) in [(0, 1, 0.01), (3, 4, 0.001)] {
        f.p[(i, j)] = v;
        f.p[(j, i)] = v;
    }
    (m, n, f)
}

#[test]
fn updated_set_contains_every_consistent_point() {
    let (m, n, mut f) = prior_set();
    let (x_prev, p_prev) = (f.x, f.p);
    let u = [0.1, 0.01, -0.06, 0.05];
    let mut rng = Rng::new(11);
    let l_prev = p_prev.cholesky().unwrap().l();
    let l_q = SMatrix::from_diagonal(&n.set_q()).cholesky().unwrap().l();
    // The measurement: from a point of the prior through the model, plus noise in its set.
    let truth = m.f(&in_ellipsoid(&mut rng, &x_prev, &l_prev), &u)
        + in_ellipsoid(&mut rng, &SVector::zeros(), &l_q);
    let r_inv = f.r.try_inverse().unwrap();
    let y = m.h(&truth, &[]) + SVector::<f64, 3>::from([0.005, -0.004, 0.003]);
    let out = f.try_step(&u, &y).unwrap();
    assert!(
        out.consistent && out.inflations == 0 && !out.jumped,
        "the plain update is what this test checks: {out:?}"
    );
    let p_inv = f.p.try_inverse().unwrap();
    let (mut accepted, mut worst) = (0usize, 0.0f64);
    for _ in 0..4_000_000 {
        let z = m.f(&in_ellipsoid(&mut rng, &x_prev, &l_prev), &u)
            + in_ellipsoid(&mut rng, &SVector::zeros(), &l_q);
        let v = y - m.h(&z, &[]);
        if v.dot(&(r_inv * v)) > 1.0 {
            continue;
        }
        accepted += 1;
        let d = z - f.x;
        worst = worst.max(d.dot(&(p_inv * d)));
        if accepted >= 20_000 {
            break;
        }
    }
    println!("accepted {accepted} points; largest (z-x)ᵀP⁻¹(z-x) = {worst:.4}");
    assert!(
        accepted >= 10_000,
        "only {accepted} consistent points sampled"
    );
    assert!(
        worst <= 1.0 + 1e-9,
        "a consistent point lies outside the updated set: {worst}"
    );
}

#[test]
fn remainder_box_is_the_exact_range_of_the_bilinear_terms() {
    let m = PaperHeli::new(paper_params(10.0), 0.02);
    let p = SMatrix::<f64, 5, 5>::from_row_slice(&[
        0.04, 0.01, -0.005, 0.0, 0.0, //
        0.01, 0.03, 0.004, 0.0, 0.0, //
        -0.005, 0.004, 0.05, 0.0, 0.0, //
        0.0, 0.0, 0.0, 0.1, 0.0, //
        0.0, 0.0, 0.0, 0.0, 1e-4,
    ]);
    let (center, half) = remainder_box(m.bilinear_terms(), &p);
    // Sample the boundary densely; the range of each row's remainder must touch both box ends.
    let l = p.cholesky().unwrap().l();
    let mut rng = Rng::new(2);
    let (mut lo, mut hi) = (
        SVector::<f64, 5>::repeat(f64::INFINITY),
        SVector::<f64, 5>::repeat(f64::NEG_INFINITY),
    );
    for _ in 0..400_000 {
        let mut d = SVector::<f64, 5>::from_fn(|_, _| rng.normal());
        d /= d.norm();
        let dz = l * d;
        let mut r = SVector::<f64, 5>::zeros();
        for t in m.bilinear_terms() {
            r[t.row] += t.coeff * dz[t.j] * dz[t.k];
        }
        lo = lo.inf(&r);
        hi = hi.sup(&r);
    }
    for i in 0..3 {
        let (blo, bhi) = (center[i] - half[i], center[i] + half[i]);
        assert!(
            lo[i] >= blo - 1e-12 && hi[i] <= bhi + 1e-12,
            "row {i}: sampled range outside the box"
        );
        // Tight: the sampled extremes reach the box ends (to 1 % of the width).
        assert!(
            (lo[i] - blo).abs() < 0.01 * (bhi - blo) && (hi[i] - bhi).abs() < 0.01 * (bhi - blo),
            "row {i}: box not tight"
        );
    }
}

#[test]
fn bounds_are_clipped_to_the_a_priori_box() {
    let n = BankNoise::nominal(
        &NoiseSchedule::constant(NoiseKind::Uniform, 0.03),
        &NoiseSchedule::constant(NoiseKind::Uniform, 0.025),
    );
    let m = PaperHeli::new(paper_params(10.0), 0.02);
    let mut f = Esmf::new(
        m,
        EsmfParams::default(),
        x0(),
        set_p0(),
        n.set_q(),
        n.set_r(),
    );
    f.p[(3, 3)] = 25.0; // gamma ± 5
    assert_eq!(f.projection(3), (-4.0, 6.0));
    f.box_centre[3] = 1.0;
    f.box_half[3] = 2.0;
    assert_eq!(f.projection(3), (-1.0, 3.0));
    // A set that has left the box (inconsistent prior): its own projection is kept.
    f.x[3] = 9.0;
    f.p[(3, 3)] = 1.0;
    assert_eq!(f.projection(3), (8.0, 10.0));
}

/// A coast over a lost sample (prediction only) keeps every point the dynamics can reach: for
/// points of the prior set through the model (gyroscopic terms included, so the
/// linearisation-error set matters) plus process noise in its set, all lie inside the
/// predicted set.
#[test]
fn coasted_set_contains_every_reachable_point() {
    let (m, n, mut f) = prior_set();
    let (x_prev, p_prev) = (f.x, f.p);
    let u = [0.1, 0.01, -0.06, 0.05];
    f.coast(&u).unwrap();
    assert!(
        f.last.q_bar.sum() > 0.0,
        "the linearisation-error set is exercised"
    );
    let mut rng = Rng::new(12);
    let l_prev = p_prev.cholesky().unwrap().l();
    let l_q = SMatrix::from_diagonal(&n.set_q()).cholesky().unwrap().l();
    let p_inv = f.p.try_inverse().unwrap();
    let mut worst = 0.0f64;
    for _ in 0..20_000 {
        let z = m.f(&in_ellipsoid(&mut rng, &x_prev, &l_prev), &u)
            + in_ellipsoid(&mut rng, &SVector::zeros(), &l_q);
        let d = z - f.x;
        worst = worst.max(d.dot(&(p_inv * d)));
    }
    println!("20000 reachable points; largest (z-x)ᵀP⁻¹(z-x) = {worst:.4}");
    assert!(
        worst <= 1.0 + 1e-9,
        "a reachable point lies outside the coasted set: {worst}"
    );
    // Not vacuous: the set is not much larger than what it must hold.
    assert!(worst > 0.5, "{worst}");
}

/// A random direction on the unit sphere.
fn on_sphere<const N: usize>(rng: &mut Rng) -> SVector<f64, N> {
    let d = SVector::<f64, N>::from_fn(|_, _| rng.normal());
    d / d.norm()
}

/// After an outage the ESMF re-measures the rates (`reseat`): every point whose rates lie in
/// the measurement set about the new rates, and whose gain and bias lie in the old set's
/// projection plus `periods` steps of process noise, is inside the new set. The points are the
/// extreme ones: on the boundary of each part, the process steps all in one direction (the
/// Minkowski sum of `periods` copies of E(0, Q) is E(0, periods² Q)), half of them along the
/// projection's own direction.
#[test]
fn reseated_set_contains_every_consistent_point() {
    let (_, n, mut f) = prior_set();
    let (x_prev, p_prev) = (f.x, f.p);
    let rates = [0.1, 0.2, -0.1];
    let r = n.set_r();
    let half_sq = [r[(0, 0)], r[(1, 1)], r[(2, 2)]];
    let periods = 10.0;
    f.reseat(&rates, &half_sq, periods);
    let mut rng = Rng::new(13);
    let l_ahc = p_prev
        .fixed_view::<2, 2>(3, 3)
        .into_owned()
        .cholesky()
        .unwrap()
        .l();
    let q = n.set_q();
    let l_q = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from([q[3], q[4]]))
        .cholesky()
        .unwrap()
        .l();
    let l_r = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from(half_sq))
        .cholesky()
        .unwrap()
        .l();
    let p_inv = f.p.try_inverse().unwrap();
    let centre = x_prev.fixed_rows::<2>(3).into_owned();
    let mut worst = 0.0f64;
    for k in 0..20_000 {
        let d1 = on_sphere::<2>(&mut rng);
        let d2 = if k % 2 == 0 {
            d1
        } else {
            on_sphere::<2>(&mut rng)
        };
        let ahc = centre + l_ahc * d1 + l_q * d2 * periods;
        let rt = SVector::from(rates) + l_r * on_sphere::<3>(&mut rng);
        let z = SVector::<f64, 5>::from([rt[0], rt[1], rt[2], ahc[0], ahc[1]]);
        let d = z - f.x;
        worst = worst.max(d.dot(&(p_inv * d)));
    }
    println!("20000 extreme points; largest (z-x)ᵀP⁻¹(z-x) = {worst:.4}");
    assert!(
        worst <= 1.0 + 1e-9,
        "a consistent point lies outside: {worst}"
    );
    assert!(worst > 0.7, "{worst}");
    assert_eq!(&f.x.as_slice()[..3], &rates);
}
