//! The calibration's tests: known models recovered, the a_z scale taken only when determined.

// Index loops mirror the model's equations (rows i, actuators j).
#![allow(clippy::needless_range_loop)]

use super::*;
use crate::sim::rng::Rng;

/// A known discrete model with cross-coupling, a previous-increment term, an offset and a
/// two-sample command delay, driven by smooth random commands and measured with gyro noise:
/// the identification finds the delay and recovers B and Phi.
#[test]
fn calibrate_arx_recovers_a_known_model() {
    let phi = [[0.90, 0.05, 0.0], [-0.03, 0.85, 0.0], [0.0, 0.02, 0.95]];
    let e = [[0.30, 0.10, 0.0], [0.0, 0.20, 0.0], [0.0, 0.0, -0.10]];
    let b = [
        [0.8, 0.1, -0.1],
        [-0.8, 0.2, -0.1],
        [0.0, -0.3, -0.1],
        [0.0, 0.0, 0.6],
    ];
    let c = [0.001, -0.002, 0.003];
    let delay = 2;
    let mut rng = Rng::new(11);
    let n = 3000;
    let mut u = vec![[0.0; 4]; n];
    let mut v = [0.0; 4];
    for uk in u.iter_mut() {
        for j in 0..4 {
            v[j] = 0.9 * v[j] + 0.1 * rng.normal();
        }
        *uk = v;
    }
    let mut w = vec![[0.0; 3]; n];
    for k in 2..n {
        for i in 0..3 {
            let mut acc = c[i];
            for m in 0..3 {
                acc += phi[i][m] * w[k - 1][m] + e[i][m] * (w[k - 1][m] - w[k - 2][m]);
            }
            let ud = u[k.saturating_sub(delay)];
            for j in 0..4 {
                acc += b[j][i] * ud[j];
            }
            w[k][i] = acc;
        }
    }
    let measured: Vec<[f64; 3]> = w
        .iter()
        .map(|r| r.map(|x| x + 0.001 * rng.normal()))
        .collect();
    let samples: Vec<CalibrationSample> = (0..n)
        .map(|k| CalibrationSample {
            rates: measured[k],
            u: &u[k],
            az: None,
            follows_previous: true,
            measured: true,
            step: k as u64,
        })
        .collect();
    let base = RateParams {
        damping: [1.0; 3],
        effectiveness: vec![[0.0; 3]; 4],
        vertical: vec![],
        offset: [0.0; 3],
        vertical_offset: 0.0,
    };
    let fit = calibrate_arx(&samples, 0.02, 5, &base).unwrap();
    assert_eq!(fit.params.delay, delay);
    for j in 0..4 {
        for i in 0..3 {
            let got = fit.params.input[j][i];
            assert!(
                (got - b[j][i]).abs() <= 0.02,
                "B[{i}][{j}] {got:.4} vs {}",
                b[j][i]
            );
        }
    }
    for i in 0..3 {
        for m in 0..3 {
            let got = fit.params.phi[i][m];
            assert!(
                (got - phi[i][m]).abs() <= 0.02,
                "Phi[{i}][{m}] {got:.4} vs {}",
                phi[i][m]
            );
        }
    }
    assert!(
        fit.quality.r_squared.iter().all(|r2| *r2 > 0.9),
        "{:?}",
        fit.quality
    );
}

/// The a_z scale replaces the geometry's only when the data determine it: thrust that
/// moves against white noise gives the true scale; thrust that barely moves against a
/// slow (gust-like) disturbance fits noise, and the geometry is kept.
#[test]
fn the_a_z_scale_is_taken_only_when_the_data_determine_it() {
    let base = [-2.0, -2.0];
    let fit = |moving: f64, tau_steps: f64| {
        let mut rng = Rng::new(7);
        let us: Vec<[f64; 2]> = (0..1000)
            .map(|k| {
                let s = moving * (k as f64 * 0.05).sin();
                [0.5 + s, 0.5 - 0.5 * s]
            })
            .collect();
        // First-order disturbance with the given correlation time (steps), std 0.3.
        let a = (-1.0 / tau_steps).exp();
        let mut d = 0.0;
        let with_az: Vec<(f64, &[f64])> = us
            .iter()
            .map(|u| {
                d = a * d + 0.3 * (1.0 - a * a).sqrt() * rng.normal();
                (1.5 * (base[0] * u[0] + base[1] * u[1]) - 9.8 + d, &u[..])
            })
            .collect();
        fit_vertical(&with_az, &base).unwrap()
    };
    let excited = fit(0.4, 1.0);
    assert!(
        excited.scaled && (excited.scale - 1.5).abs() < 0.1,
        "{:?}",
        excited.scale
    );
    // Least squares alone takes x3.05 here (measured; the truth is x1.5).
    let still = fit(0.05, 50.0);
    assert!(!still.scaled && still.scale == 1.0, "{:?}", still.scale);
    assert_eq!(still.vertical, base.to_vec());
}

/// A filled sample is history only: no row's target or instrument comes from it, the runs go
/// on through it.
#[test]
fn a_filled_sample_is_no_rows_target() {
    let u = [0.5; 2];
    let samples: Vec<CalibrationSample> = (0..8)
        .map(|k| CalibrationSample {
            rates: [0.0; 3],
            u: &u,
            az: None,
            follows_previous: k > 0,
            measured: k != 4,
            step: k as u64,
        })
        .collect();
    assert_eq!(unbroken_rows(&samples, 2, 0), [2, 3, 6, 7]);
    assert_eq!(unbroken_rows(&samples, 1, 1), [1, 2, 6]);
}

/// A fit with a non-finite number is no fit (nalgebra's SVD would panic on the NaN and never
/// return on the infinity).
#[test]
fn least_squares_of_non_finite_numbers_is_none() {
    let x = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
    let y = DVector::from_vec(vec![1.0, 2.0, 3.0]);
    assert!(least_squares(&x, &y).is_some());
    for bad in [f64::NAN, f64::INFINITY] {
        let mut xb = x.clone();
        xb[(1, 1)] = bad;
        assert!(least_squares(&xb, &y).is_none());
        assert!(instrumental(&xb, &x, &y).is_none());
        let mut yb = y.clone();
        yb[2] = bad;
        assert!(least_squares(&x, &yb).is_none());
        assert!(instrumental(&x, &x, &yb).is_none());
    }
}
