//! Properties of the estimators on arbitrary finite input (proptest): simulated flights with
//! random seeds, and measurements hit by random outliers. After every step that succeeds the
//! state is finite, the covariance (UKF) or shape (ESMF) finite, symmetric and positive
//! semidefinite, and every state's bounds contain its estimate; a step may fail (an error the
//! pipeline answers with a reset), never panic. The vehicle filters' guaranteed (set) bounds
//! contain their centre.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use ahcmon::estimate::{
    AdaptationParams, Esmf, EsmfParams, Estimator, KfUkf, MitEsmf, MitUkf, SlaveKfParams, Ukf,
    UkfParams,
};
use ahcmon::eval::bank::{BankNoise, kalman_p0, set_p0, x0};
use ahcmon::model::PaperHeli;
use ahcmon::sim::noise::{NoiseKind, NoiseSchedule};
use ahcmon::sim::paper::{PaperSim, PaperSimConfig, paper_params};
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;

const STEPS: usize = 300;

/// One filter's step and check: `Err("")` when the step failed (allowed: the filter is out).
type Check<'a> = Box<dyn FnMut() -> Result<(), String> + 'a>;

/// Symmetric within rounding and positive semidefinite within rounding of its largest entry
/// (a Cholesky factor exists once that rounding is added to the diagonal).
fn check_matrix<const N: usize>(p: &SMatrix<f64, N, N>, what: &str) -> Result<(), String> {
    if !p.iter().all(|v| v.is_finite()) {
        return Err(format!("{what}: not finite"));
    }
    let scale = p.amax().max(1e-300);
    let asym = (p - p.transpose()).amax();
    if asym > 1e-9 * scale {
        return Err(format!("{what}: asymmetric by {asym:e} of {scale:e}"));
    }
    let sym = (p + p.transpose()) * 0.5 + SMatrix::<f64, N, N>::identity() * (1e-9 * scale);
    if sym.cholesky().is_none() {
        return Err(format!("{what}: not positive semidefinite: {p}"));
    }
    Ok(())
}

fn check_estimate<const N: usize, const M: usize, E: Estimator<N, M>>(
    f: &E,
    p: &SMatrix<f64, N, N>,
) -> Result<(), String> {
    let name = f.name();
    let x = f.state();
    if !x.iter().all(|v| v.is_finite()) {
        return Err(format!("{name}: state not finite"));
    }
    check_matrix(p, name)?;
    for i in 0..N {
        let (lo, hi) = f.bounds(i);
        let tol = 1e-9 * (1.0 + x[i].abs());
        if !(lo - tol <= x[i] && x[i] <= hi + tol) {
            return Err(format!("{name}: state {i} = {} outside [{lo}, {hi}]", x[i]));
        }
    }
    Ok(())
}

/// Outliers: (step, measurement row, added value).
fn outliers() -> impl Strategy<Value = Vec<(usize, usize, f64)>> {
    prop::collection::vec((0..STEPS, 0..3usize, -5.0..5.0f64), 0..20)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    /// The paper's five filters on a helicopter flight of a random seed with random outliers.
    #[test]
    fn paper_filters_keep_their_invariants(seed in 1u64..1_000_000, hits in outliers()) {
        let process = NoiseSchedule::constant(NoiseKind::Gaussian, 1e-4);
        let measurement = NoiseSchedule::constant(NoiseKind::Gaussian, 2.89e-6);
        let mut sim = PaperSim::new(PaperSimConfig {
            dt: 0.02,
            forward_speed: 10.0,
            process_noise: process.clone(),
            measurement_noise: measurement.clone(),
            faults: vec![],
            dither: None,
            seed,
        })
        .unwrap();
        let n = BankNoise::nominal(&process, &measurement);
        let m = PaperHeli::new(paper_params(10.0), 0.02);
        let (u, a) = (UkfParams::default(), AdaptationParams::default());
        let mut ukf =
            Ukf::<_, 5, 3, 11>::new(m.clone(), u, x0(), kalman_p0(), n.kalman_q(), n.kalman_r());
        let mut kf_ukf = KfUkf::<_, 5, 3, 11>::new(
            m.clone(), u, a, SlaveKfParams::default(), x0(), kalman_p0(), n.kalman_q(), n.kalman_r(),
        );
        let mut mit_ukf =
            MitUkf::<_, 5, 3, 11>::new(m.clone(), u, a, x0(), kalman_p0(), n.kalman_q(), n.kalman_r());
        let mut esmf =
            Esmf::new(m.clone(), EsmfParams::default(), x0(), set_p0(), n.set_q(), n.set_r());
        let mut mit_esmf =
            MitEsmf::new(m, EsmfParams::default(), a, x0(), set_p0(), n.set_q(), n.set_r());
        // A filter whose step failed is out (the pipeline would reset it).
        let mut alive = [true; 5];
        for k in 0..STEPS {
            let s = sim.step();
            let mut y: SVector<f64, 3> = s.y;
            for &(at, row, v) in &hits {
                if at == k {
                    y[row] += v;
                }
            }
            let [a0, a1, a2, a3, a4] = &mut alive;
            let checks: [(&mut bool, Check); 5] = [
                (a0, Box::new(|| match ukf.try_step(&s.u, &y) {
                    Ok(()) => check_estimate(&ukf, &ukf.p),
                    Err(_) => Err(String::new()),
                })),
                (a1, Box::new(|| match kf_ukf.try_step(&s.u, &y) {
                    Ok(()) => check_estimate(&kf_ukf, &kf_ukf.ukf.p),
                    Err(_) => Err(String::new()),
                })),
                (a2, Box::new(|| match mit_ukf.try_step(&s.u, &y) {
                    Ok(()) => check_estimate(&mit_ukf, &mit_ukf.ukf.p),
                    Err(_) => Err(String::new()),
                })),
                (a3, Box::new(|| match esmf.try_step(&s.u, &y) {
                    Ok(_) => check_estimate(&esmf, &esmf.p),
                    Err(_) => Err(String::new()),
                })),
                (a4, Box::new(|| match mit_esmf.try_step(&s.u, &y) {
                    Ok(_) => check_estimate(&mit_esmf, &mit_esmf.esmf.p),
                    Err(_) => Err(String::new()),
                })),
            ];
            for (alive, mut step) in checks {
                if !*alive {
                    continue;
                }
                match step() {
                    Ok(()) => {}
                    // A failed step: allowed, the filter is out.
                    Err(e) if e.is_empty() => *alive = false,
                    Err(e) => prop_assert!(false, "step {k}: {e}"),
                }
            }
        }
    }

    /// The vehicle filters of a quad (MIT-UKF, MIT-ESMF, set filter) on a flight of a random
    /// seed with random outliers on the rates and a_z: the same invariants through the
    /// estimates they report, and the guaranteed bounds contain their centre.
    #[test]
    fn vehicle_filters_keep_their_invariants(seed in 1u64..1_000_000, hits in outliers()) {
        use ahcmon::estimate::vehicle::{FilterPair, FilterSetup, VehicleFilters};
        use ahcmon::sim::vehicle::{VehicleSim, VehicleSimConfig};
        use ahcmon::telemetry::Profile;
        let profile = Profile::resolve("quad-x").unwrap();
        let mut sim = VehicleSim::new(VehicleSimConfig::calm(profile.clone(), 0.02, seed)).unwrap();
        let mut pair =
            FilterPair::<11, 4, 23>::new(FilterSetup::from_profile(&profile, 0.02).unwrap());
        for k in 0..STEPS {
            let s = sim.step();
            let mut y = [s.y[0], s.y[1], s.y[2], s.y[3]];
            for &(at, row, v) in &hits {
                if at == k {
                    y[if row == 2 { 3 } else { row }] += v;
                }
            }
            let results = pair.step(&s.u[..4], &y);
            // The pipeline resets a filter after a failed step; so do we.
            let ok: Vec<usize> = (0..2).filter(|&f| results[f].is_ok()).collect();
            for f in (0..2).filter(|f| !ok.contains(f)) {
                pair.reset(f);
            }
            for j in 0..4 {
                for &f in &ok {
                    let e = pair.ahc(f, j);
                    let all = [e.gamma, e.gamma_lo, e.gamma_hi, e.delta, e.delta_lo, e.delta_hi];
                    prop_assert!(all.iter().all(|v| v.is_finite()), "step {k} filter {f}: {e:?}");
                    prop_assert!(e.gamma_lo <= e.gamma && e.gamma <= e.gamma_hi, "step {k} filter {f}: {e:?}");
                    prop_assert!(e.delta_lo <= e.delta && e.delta <= e.delta_hi, "step {k} filter {f}: {e:?}");
                    let [gg, gd, dd] = e.block;
                    prop_assert!(gg >= 0.0 && dd >= 0.0 && gd * gd <= gg * dd * (1.0 + 1e-9) + 1e-300,
                        "step {k} filter {f}: block {:?}", e.block);
                }
                let g = pair.guaranteed(j);
                let tol = 1e-9;
                prop_assert!(g.gamma_lo - tol <= g.gamma && g.gamma <= g.gamma_hi + tol, "step {k}: {g:?}");
                prop_assert!(g.delta_lo - tol <= g.delta && g.delta <= g.delta_hi + tol, "step {k}: {g:?}");
            }
        }
    }
}
