//! The change test's tests: the plain search (kinds, onsets, drifts, margins).

use super::*;
use crate::sim::rng::Rng;

/// Three actuators on three axes (one of them mixing two), unit weights.
pub(super) fn effects() -> Vec<[f64; 4]> {
    vec![
        [1.0, 0.0, 0.2, 0.0],
        [0.0, 1.0, -0.2, 0.0],
        [0.6, 0.6, 0.3, 0.0],
    ]
}

/// Residuals of a change of actuator `j` from step `onset` on, with white noise and
/// commands varying about 0.5; returns the test after `steps`.
pub(super) fn run(
    j: usize,
    kind: ChangeKind,
    theta: f64,
    onset: usize,
    steps: usize,
) -> ChangeTest {
    let b = effects();
    let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 400, 10, 1);
    let mut rng = Rng::new(7);
    for k in 0..steps {
        let t = k as f64 * 0.02;
        let u: Vec<f64> = (0..3)
            .map(|i| 0.5 + 0.1 * (t * (1.3 + i as f64)).sin())
            .collect();
        let s = if k >= onset {
            match kind {
                ChangeKind::Gain => (theta - 1.0) * u[j],
                ChangeKind::Offset => theta,
                ChangeKind::Stuck => theta - u[j],
            }
        } else {
            0.0
        };
        let mut r = [0.0; 4];
        for i in 0..3 {
            r[i] = b[j][i] * s + 0.05 * rng.normal();
        }
        test.push(t, &r, &u, false);
    }
    test
}

#[test]
fn each_kind_of_change_is_read_with_its_actuator_size_and_onset() {
    for (j, kind, theta) in [
        (0, ChangeKind::Gain, 0.6),
        (1, ChangeKind::Offset, -0.1),
        (2, ChangeKind::Stuck, 0.45),
    ] {
        let test = run(j, kind, theta, 200, 350);
        let r = test.evaluate().expect("a reading");
        assert_eq!((r.actuator, r.kind), (j, kind), "{r:?}");
        assert!((r.value - theta).abs() < 0.02, "{r:?}");
        // Onset at step 200 = 4.0 s.
        assert!((r.since - 4.0).abs() <= 0.1, "{r:?}");
        assert!(r.drop > r.next_kind_drop && r.drop > r.next_actuator_drop);
        // The fit leaves the noise: variance 0.05² per row.
        assert!((r.noise_var / 0.0025 - 1.0).abs() < 0.3, "{r:?}");
    }
}

/// The reading after 7 s (350 steps) in which actuator 1's offset is `offset(t)`, with
/// noise 0.02 a row and a store of `capacity` samples.
pub(super) fn offset_change(capacity: usize, seed: u64, offset: impl Fn(f64) -> f64) -> Reading {
    let b = effects();
    let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, capacity, 10, 1);
    let mut rng = Rng::new(seed);
    for k in 0..350 {
        let t = k as f64 * 0.02;
        let u: Vec<f64> = (0..3)
            .map(|i| 0.5 + 0.1 * (t * (1.3 + i as f64)).sin())
            .collect();
        let s = offset(t);
        let mut r = [0.0; 4];
        for i in 0..3 {
            r[i] = b[1][i] * s + 0.02 * rng.normal();
        }
        test.push(t, &r, &u, false);
    }
    test.evaluate().unwrap()
}

#[test]
fn a_drift_fits_a_ramp_clearly_and_a_step_does_not() {
    // Actuator 1's offset grows 0.05 a second from 4 s: at 7 s the ramp fits clearly
    // better than any step, with its rate and start (noise 0.02 a row: the rate's standard
    // error over 3 s is about 0.002). An offset step of the size the ramp reaches (+0.15
    // from 4 s) fits the step best, the ramp clearly worse.
    let r = offset_change(400, 11, |t| if t >= 4.0 { 0.05 * (t - 4.0) } else { 0.0 });
    assert_eq!(r.actuator, 1, "{r:?}");
    assert!(-r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
    assert!((r.ramp_rate - 0.05).abs() < 0.005, "{r:?}");
    assert!((r.ramp_samples as f64 * 0.02 - 3.0).abs() < 0.2, "{r:?}");
    assert!((r.ramp_since - 4.0).abs() < 0.2, "{r:?}");
    assert!(r.ramp_drop >= r.mixed_drop, "{r:?}");
    let r = offset_change(400, 11, |t| if t >= 4.0 { 0.15 } else { 0.0 });
    assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
    assert!(r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
}

#[test]
fn a_drift_older_than_the_store_still_fits_a_ramp_and_an_old_offset_does_not() {
    // Store of 150 samples (3 s). Actuator 1's offset has grown 0.05 a second since 1 s;
    // at 7 s the store holds only the ramp's last 3 s, which start at +0.15: the ramp over
    // the whole store (offset and slope) fits clearly better than any step. An offset of
    // +0.3 since 1 s fits no slope: not a drift.
    let r = offset_change(150, 5, |t| if t >= 1.0 { 0.05 * (t - 1.0) } else { 0.0 });
    assert_eq!(r.actuator, 1, "{r:?}");
    assert_eq!(r.ramp_samples, 150, "{r:?}");
    assert!((r.ramp_rate - 0.05).abs() < 0.01, "{r:?}");
    assert!(-r.margin_over(r.ramp_drop) > 20.0, "{r:?}");
    let r = offset_change(150, 5, |t| if t >= 1.0 { 0.3 } else { 0.0 });
    assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
    assert!(-r.margin_over(r.ramp_drop) < 20.0, "{r:?}");
}

#[test]
fn the_ring_keeps_the_latest_samples_and_a_change_older_than_it_starts_at_its_oldest() {
    // Capacity 400: after 600 steps with the change at 450 the onset is still found; with
    // the change at 100 the whole stored stretch is the changed one.
    let test = run(1, ChangeKind::Gain, 0.7, 450, 600);
    let r = test.evaluate().unwrap();
    assert_eq!((r.actuator, r.kind), (1, ChangeKind::Gain), "{r:?}");
    assert!((r.since - 9.0).abs() <= 0.1 && r.samples <= 160, "{r:?}");
    let test = run(1, ChangeKind::Gain, 0.7, 100, 600);
    let r = test.evaluate().unwrap();
    assert_eq!(test.len(), 400);
    assert_eq!(r.samples, 400, "{r:?}");
    assert!((r.since - 200.0 * 0.02).abs() < 1e-9, "{r:?}");
    assert!((r.value - 0.7).abs() < 0.02, "{r:?}");
}

#[test]
fn white_noise_gives_no_decisive_margin() {
    // What the diagnosis acts on: the best reading's margin over any other actuator and
    // over the other kinds, in independent samples. Under no change both stay far below
    // the 20 the diagnosis asks for.
    for seed in 1..20 {
        let b = effects();
        let mut test = ChangeTest::new(b, [1.0; 4], 3, 300, 10, 1);
        let mut rng = Rng::new(seed);
        for k in 0..300 {
            let t = k as f64 * 0.02;
            let u = [
                0.5 + 0.1 * (t * 1.3).sin(),
                0.5 + 0.1 * (t * 2.3).sin(),
                0.5,
            ];
            let r = [rng.normal(), rng.normal(), rng.normal(), 0.0];
            test.push(t, &r, &u, false);
        }
        let r = test.evaluate().unwrap();
        assert!(
            r.margin_over(r.next_actuator_drop) < 20.0 && r.margin_over(r.next_kind_drop) < 20.0,
            "seed {seed}: {r:?}"
        );
    }
}

#[test]
fn coloured_residuals_count_fewer_independent_samples() {
    let r = Reading {
        actuator: 0,
        kind: ChangeKind::Gain,
        value: 0.5,
        value_std: 0.1,
        since: 0.0,
        samples: 100,
        drop: 120.0,
        noise_var: 1.0,
        autocorrelation: 0.0,
        command_mean: 0.5,
        command_rms: 0.5,
        next_kind_drop: 100.0,
        next_actuator_drop: 0.0,
        mixed_drop: 0.0,
        ramp_drop: 0.0,
        ramp_rate: 0.0,
        ramp_samples: 0,
        ramp_since: 0.0,
    };
    assert!((r.margin_over(r.next_kind_drop) - 20.0).abs() < 1e-9);
    let coloured = Reading {
        autocorrelation: 0.8,
        ..r
    };
    // (1 - 0.8) / (1 + 0.8) of the samples are independent.
    assert!((coloured.margin_over(coloured.next_kind_drop) - 20.0 / 9.0).abs() < 1e-9);
    let anti = Reading {
        autocorrelation: -0.5,
        ..r
    };
    assert!((anti.margin_over(anti.next_kind_drop) - 20.0).abs() < 1e-9);
}

#[test]
fn the_residual_autocorrelation_is_measured_on_the_changed_stretch() {
    // A gain change with AR(1) noise of coefficient φ on every row: the reading's lag-one
    // autocorrelation is φ (0 for white noise), within sampling error.
    for phi in [0.0f64, 0.5, 0.9] {
        let b = effects();
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 2000, 10, 1);
        let mut rng = Rng::new(11);
        let mut w = [0.0; 3];
        for k in 0..2000 {
            let t = k as f64 * 0.02;
            let u = [0.5 + 0.1 * (t * 1.3).sin(), 0.5, 0.5];
            let s = if k >= 200 { -0.4 * u[0] } else { 0.0 };
            let mut r = [0.0; 4];
            for i in 0..3 {
                w[i] = phi * w[i] + (1.0 - phi * phi).sqrt() * 0.05 * rng.normal();
                r[i] = b[0][i] * s + w[i];
            }
            test.push(t, &r, &u, false);
        }
        let r = test.evaluate().unwrap();
        assert_eq!((r.actuator, r.kind), (0, ChangeKind::Gain), "{r:?}");
        assert!((r.autocorrelation - phi).abs() < 0.05, "phi {phi}: {r:?}");
    }
}

#[test]
fn a_gain_and_an_offset_together_fit_as_mixed_and_one_kind_alone_does_not() {
    // A servo whose PWM is scaled about 1000 µs: about its trim, gain 0.75 and offset
    // -0.25 at once. The two-unknown fit leaves only the noise; the best single kind
    // leaves far more. A pure gain change gains nothing from the second unknown.
    let b = effects();
    let fit = |mixed: bool| {
        let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 400, 10, 1);
        let mut rng = Rng::new(4);
        for k in 0..400 {
            let t = k as f64 * 0.02;
            let u = [0.3 * (t * 1.9).sin(), 0.0, 0.0];
            let s = if k >= 100 {
                -0.25 * u[0] - if mixed { 0.25 } else { 0.0 }
            } else {
                0.0
            };
            let mut r = [0.0; 4];
            for i in 0..3 {
                r[i] = b[0][i] * s + 0.05 * rng.normal();
            }
            test.push(t, &r, &u, false);
        }
        test.evaluate().unwrap()
    };
    let both = fit(true);
    assert_eq!(both.actuator, 0);
    assert!(-both.margin_over(both.mixed_drop) > 100.0, "{both:?}");
    let gain = fit(false);
    assert_eq!(
        (gain.actuator, gain.kind),
        (0, ChangeKind::Gain),
        "{gain:?}"
    );
    assert!(-gain.margin_over(gain.mixed_drop) < 20.0, "{gain:?}");
}

#[test]
fn noise_alone_explains_little() {
    let test = run(0, ChangeKind::Offset, 0.0, 0, 400);
    let r = test.evaluate().expect("a reading");
    // Under no change the drop is a maximum of chi-square(1) variables in noise units.
    assert!(r.drop / r.noise_var < 30.0, "{r:?}");
}

#[test]
fn a_non_finite_residual_drops_the_record_and_too_few_samples_read_nothing() {
    let mut test = run(0, ChangeKind::Gain, 0.5, 100, 300);
    assert!(test.evaluate().is_some());
    test.push(9.0, &[f64::NAN, 0.0, 0.0, 0.0], &[0.5; 3], false);
    assert!(test.is_empty());
    assert_eq!(test.evaluate(), None);
    for k in 0..5 {
        test.push(
            10.0 + k as f64 * 0.02,
            &[0.1, 0.0, 0.0, 0.0],
            &[0.5; 3],
            false,
        );
    }
    assert_eq!(test.evaluate(), None);
}
