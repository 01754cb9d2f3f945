//! The change test's tests: the residual's colour and the whitened search.

use super::tests::{effects, offset_change, run};
use super::*;
use crate::sim::rng::Rng;

/// A residual of `steps` samples: an AR(1) part (coefficient `phi`, stationary std
/// `ar_std`) plus white noise (`white_std`) on each of three rows.
fn coloured(rng: &mut Rng, steps: usize, phi: f64, ar_std: f64, white_std: f64) -> Vec<[f64; 4]> {
    let fresh = ar_std * (1.0 - phi * phi).sqrt();
    let mut g = [0.0f64; 3];
    (0..steps)
        .map(|_| {
            let mut r = [0.0; 4];
            for i in 0..3 {
                g[i] = phi * g[i] + fresh * rng.normal();
                r[i] = g[i] + white_std * rng.normal();
            }
            r
        })
        .collect()
}

/// During an identified change the colour learns from the residual with the change taken
/// out: with the right identification (a loss and an offset, or a stuck output), exactly
/// what it would have learned from the noise alone, in the weighted residual's units; with
/// a wrong one, something else; with none, nothing (the lags restart).
#[test]
fn the_colour_learns_on_through_an_identified_change() {
    let mut rng = Rng::new(11);
    let (healthy, steps) = (300, 1500);
    let weights = [2.0, 0.5, 4.0, 1.0];
    // The noise in weighted units; the residual pushed is unweighted.
    let noise = coloured(&mut rng, steps, 0.98, 0.1, 0.03);
    let unweighted = |r: &[f64; 4]| -> [f64; 4] { std::array::from_fn(|i| r[i] / weights[i]) };
    let u: Vec<[f64; 3]> = (0..steps)
        .map(|k| [0.5, 0.5 + 0.3 * (0.05 * k as f64).sin(), 0.5])
        .collect();
    // Actuator 1's output from `healthy` on: gamma u + delta.
    let fed = |(gamma, delta): (f64, f64), identified: Option<(f64, f64)>| {
        let mut test = ChangeTest::new(effects(), weights, 3, 300, 10, 3000);
        for (k, (n, u)) in noise.iter().zip(&u).enumerate() {
            let t = k as f64 * 0.02;
            if k < healthy {
                test.push(t, &unweighted(n), u, true);
                continue;
            }
            let s = (gamma - 1.0) * u[1] + delta;
            let b = effects()[1];
            let r = unweighted(&std::array::from_fn(|i| n[i] + b[i] * s));
            match identified {
                Some((g, d)) => test.push_identified(t, &r, u, 1, g, d),
                None => test.push(t, &r, u, false),
            }
        }
        test.colour
    };
    let mut reference = ChangeTest::new(effects(), weights, 3, 300, 10, 3000);
    for (k, (n, u)) in noise.iter().zip(&u).enumerate() {
        reference.push(k as f64 * 0.02, &unweighted(n), u, true);
    }
    let reference = reference.colour;
    // A loss with an offset, and an output stuck at 0.4 (gain 0, offset its value).
    for fault in [(0.6, 0.03), (0.0, 0.4)] {
        let right = fed(fault, Some(fault));
        assert_eq!(right.learned, reference.learned);
        for (a, b) in right
            .cov
            .iter()
            .flatten()
            .zip(reference.cov.iter().flatten())
        {
            assert!(
                (a - b).abs() <= 1e-9 * b.abs().max(1e-6),
                "{fault:?}: {a} vs {b}"
            );
        }
    }
    let wrong = fed((0.6, 0.03), Some((0.8, 0.03)));
    assert!((wrong.cov[1][3] - reference.cov[1][3]).abs() > 0.1 * reference.cov[1][3].abs());
    let none = fed((0.6, 0.03), None);
    assert_eq!(none.learned, healthy - 3);
}

#[test]
fn the_learned_colour_whitens_a_coloured_residual() {
    let mut rng = Rng::new(3);
    let mut test = ChangeTest::new(effects(), [1.0; 4], 3, 300, 10, 3000);
    // Wind-like: most of the variance in a slow AR(1) part.
    let (phi, ar, white) = (0.97, 1.0, 0.5);
    for (k, r) in coloured(&mut rng, 6000, phi, ar, white).iter().enumerate() {
        test.push(k as f64 * 0.02, r, &[0.5; 3], true);
    }
    assert!(test.colour_learned());
    let w = test.colour.whitening(3);
    // The filter applied to a fresh stretch of the same process: unit variance, no
    // lag-one correlation left (before: about phi·ar²/(ar² + white²) = 0.78).
    let fresh = coloured(&mut rng, 20000, phi, ar, white);
    for (i, wi) in w.iter().enumerate().take(3) {
        let (mut h, mut pv) = (0.0, wi.start());
        let out: Vec<f64> = fresh
            .iter()
            .map(|r| {
                let (gain, scale, next) = wi.advance(pv);
                pv = next;
                wi.apply(&mut h, r[i], gain, scale)
            })
            .collect();
        let n = out.len() as f64;
        let var = out.iter().map(|e| e * e).sum::<f64>() / n;
        let lag1 = out.windows(2).map(|x| x[0] * x[1]).sum::<f64>() / n / var;
        assert!((var - 1.0).abs() < 0.1, "row {i}: variance {var}");
        assert!(lag1.abs() < 0.1, "row {i}: lag-one correlation {lag1}");
    }
}

/// A gain or an offset change of actuator 0, or its output stuck at `theta`, from step 1400
/// of 1800 (the store keeps 100 samples from before it), under a wind-like residual (its
/// slow part 10 times the sensor noise), with the command moving a few per cent about 0.5
/// (a hovering motor's).
fn hover_change(kind: ChangeKind, theta: f64, seed: u64) -> ChangeTest {
    let b = effects();
    let mut rng = Rng::new(seed);
    let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 500, 10, 3000);
    let residual = coloured(&mut rng, 1800, 0.97, 0.1, 0.01);
    for (k, r) in residual.iter().enumerate() {
        let t = k as f64 * 0.02;
        let u: Vec<f64> = (0..3)
            .map(|i| 0.5 + 0.04 * ((t * (7.0 + i as f64)).sin() + rng.normal()))
            .collect();
        let s = match (k >= 1400, kind) {
            (false, _) => 0.0,
            (true, ChangeKind::Gain) => (theta - 1.0) * u[0],
            (true, ChangeKind::Stuck) => theta - u[0],
            (true, _) => theta,
        };
        let mut r = *r;
        for i in 0..3 {
            r[i] += b[0][i] * s;
        }
        test.push(t, &r, &u, k < 1400);
    }
    test
}

#[test]
fn a_hovering_motors_gain_and_offset_are_told_apart_on_the_whitened_residual() {
    // An offset of -0.15 at a command of 0.5 moves the output as a gain of 0.7 does.
    for (kind, theta) in [(ChangeKind::Offset, -0.15), (ChangeKind::Gain, 0.7)] {
        let mut clear = 0;
        for seed in 1..=10 {
            let test = hover_change(kind, theta, seed);
            let fit = test
                .whitened_gain_or_offset(0, 400)
                .expect("colour learned");
            assert_eq!(fit.kind, kind, "seed {seed}: {fit:?}");
            // (The offset's level is what the slow wind hides most: 0.043 at worst here.)
            assert!((fit.value - theta).abs() < 0.06, "seed {seed}: {fit:?}");
            assert!(fit.margin >= 10.0, "seed {seed}: {fit:?}");
            assert!(fit.mixed_margin < 20.0, "seed {seed}: {fit:?}");
            clear += usize::from(fit.margin >= 20.0);
            // The plain fit cannot tell them apart here (it picks either).
            let plain = test.evaluate().expect("a reading");
            assert!(
                plain.margin_over(plain.next_kind_drop) < 5.0,
                "seed {seed}: {plain:?}"
            );
        }
        assert!(clear >= 9, "{kind:?}: clear on {clear} of 10");
    }
}

/// Root mean square of `(value - truth) / std` over readings.
fn rms_z(z: &[f64]) -> f64 {
    (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt()
}

#[test]
fn the_whitened_fits_spread_is_what_it_says() {
    // 30 seeds of each: with the spread right, the RMS of the standardised errors is 1
    // (0.75-1.25 holds 95 % of 30-sample draws); the colour is learned, not given, so a
    // little more is allowed, and well below or above is wrong.
    // A motor stuck a little above its hovering command too: its value from the same
    // whitened residual (the reading tells the kind).
    let cases = [
        (ChangeKind::Offset, -0.15),
        (ChangeKind::Gain, 0.7),
        (ChangeKind::Stuck, 0.545),
    ];
    // The gain fitted with the offset free too: the offset's gain is 1, a stuck one's 0.
    for (kind, theta) in cases {
        let gamma = match kind {
            ChangeKind::Offset => 1.0,
            ChangeKind::Gain => theta,
            _ => 0.0,
        };
        let (z, z_pair): (Vec<f64>, Vec<f64>) = (1..=30)
            .map(|seed| {
                let fit = hover_change(kind, theta, seed)
                    .whitened_gain_or_offset(0, 400)
                    .expect("colour learned");
                let z_pair = (fit.pair_gamma - gamma) / fit.pair_gamma_std;
                match kind {
                    ChangeKind::Stuck => ((fit.stuck_value - theta) / fit.stuck_std, z_pair),
                    _ => ((fit.value - theta) / fit.value_std, z_pair),
                }
            })
            .unzip();
        let (rms, rms_pair) = (rms_z(&z), rms_z(&z_pair));
        println!("{kind:?}: RMS z {rms:.2}, of the pair's gain {rms_pair:.2}");
        assert!((0.7..=1.5).contains(&rms), "{kind:?}: RMS z {rms:.2}");
        assert!(
            (0.7..=1.5).contains(&rms_pair),
            "{kind:?}: pair RMS z {rms_pair:.2}"
        );
    }
}

#[test]
fn the_plain_fits_spread_is_what_it_says_on_white_noise() {
    // Offset +0.1 on actuator 1 from 4 s, white noise (see `offset_change`): the change
    // time is fitted too, so a little more than 1 is allowed.
    let z: Vec<f64> = (1..=30)
        .map(|seed| {
            let r = offset_change(400, seed, |t| if t >= 4.0 { 0.1 } else { 0.0 });
            assert_eq!((r.actuator, r.kind), (1, ChangeKind::Offset), "{r:?}");
            (r.value - 0.1) / r.value_std
        })
        .collect();
    let rms = rms_z(&z);
    println!("RMS z {rms:.2}");
    assert!((0.7..=1.5).contains(&rms), "RMS z {rms:.2}");
}

/// A motor stuck a little above its hovering command (0.545 against 0.5) from step 1400 of
/// 1800, actuator `stuck` of four where actuators 2 and 3 push the rates alike but for a
/// weak third row (as a hexa's motor 5 pushing more and motor 6 giving less do, but for
/// yaw), under a wind-like residual.
fn small_stuck(stuck: usize, seed: u64, steps: usize) -> ChangeTest {
    let b = vec![
        [1.0, 0.0, 0.2, 0.0],
        [0.0, 1.0, -0.2, 0.0],
        [0.6, 0.6, 0.1, 0.0],
        [-0.6, -0.6, 0.1, 0.0],
    ];
    let mut rng = Rng::new(seed);
    let mut test = ChangeTest::new(b.clone(), [1.0; 4], 3, 600, 10, 3000);
    let residual = coloured(&mut rng, steps, 0.97, 0.03, 0.01);
    for (k, r) in residual.iter().enumerate() {
        let t = k as f64 * 0.02;
        let u: Vec<f64> = (0..4)
            .map(|i| 0.5 + 0.02 * ((t * (3.0 + i as f64)).sin() + rng.normal()))
            .collect();
        let mut r = *r;
        if k >= 1400 {
            for i in 0..3 {
                r[i] += b[stuck][i] * (0.545 - u[stuck]);
            }
        }
        test.push(t, &r, &u, k < 1400);
    }
    test
}

/// [`ChangeTest::whitened_search`] by brute force: every change time's regressors run
/// through the steady-state filter from that time on (quadratic in the store).
fn brute_force_search(test: &ChangeTest) -> (usize, ChangeKind, usize, f64, f64) {
    // (actuator, kind, samples, value, margin over any other actuator)
    let (rows, n, cap) = (test.rows, test.len, test.buf.len());
    let w = test.colour.whitening(rows);
    let filt: Vec<_> = w.iter().take(rows).map(|wi| wi.steady()).collect();
    let entries: Vec<Entry> = (0..n)
        .map(|k| test.buf[(test.head + cap - n + k) % cap])
        .collect();
    // Apply the steady filter to x (zero before its first sample).
    let whiten = |f: (f64, f64, f64, f64), x: &[f64]| -> Vec<f64> {
        let (_, theta, c, alpha) = f;
        let mut h = 0.0;
        x.iter()
            .map(|&v| {
                let out = c * v + alpha * h;
                h = theta * h + v;
                out
            })
            .collect()
    };
    // The residual through the time-varying filter from the stationary spread.
    let y: Vec<Vec<f64>> = (0..rows)
        .map(|i| {
            let (mut h, mut p) = (0.0, w[i].start());
            entries
                .iter()
                .map(|e| {
                    let (gain, scale, next) = w[i].advance(p);
                    p = next;
                    w[i].apply(&mut h, e.r[i], gain, scale)
                })
                .collect()
        })
        .collect();
    let mut best = vec![[(0.0f64, 0usize, 0.0f64, 0.0f64); 3]; test.effects.len()];
    for tau in 0..=n - test.min_samples {
        let m = n - tau;
        for (j, b) in test.effects.iter().enumerate() {
            let (mut gy, mut gx, mut oy, mut ox, mut go, mut base) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
            for i in 0..rows {
                let g = whiten(
                    filt[i],
                    &entries[tau..]
                        .iter()
                        .map(|e| b[i] * e.u[j])
                        .collect::<Vec<_>>(),
                );
                let o = whiten(filt[i], &vec![b[i]; m]);
                for (k, yk) in y[i][tau..].iter().enumerate() {
                    gy += g[k] * yk;
                    gx += g[k] * g[k];
                    oy += o[k] * yk;
                    ox += o[k] * o[k];
                    go += g[k] * o[k];
                    base += yk * yk;
                }
            }
            let sy = oy + go;
            let drops = [
                (gy * gy / gx, 1.0 + gy / gx),
                (oy * oy / ox, oy / ox),
                (sy * sy / ox - 2.0 * gy - gx, sy / ox),
            ];
            for (k, (drop, value)) in drops.into_iter().enumerate() {
                if drop > best[j][k].0 {
                    best[j][k] = (drop, m, value, base);
                }
            }
        }
    }
    let (mut tj, mut tk) = (0, 0);
    for j in 0..best.len() {
        for k in 0..3 {
            if best[j][k].0 > best[tj][tk].0 {
                (tj, tk) = (j, k);
            }
        }
    }
    let h = best[tj][tk];
    let other = (0..best.len())
        .filter(|&j| j != tj)
        .flat_map(|j| best[j].iter().map(|x| x.0))
        .fold(0.0, f64::max);
    let noise_var = (h.3 - h.0) / (h.1 * rows) as f64;
    let kinds = [ChangeKind::Gain, ChangeKind::Offset, ChangeKind::Stuck];
    (tj, kinds[tk], h.1, h.2, (h.0 - other) / noise_var)
}

#[test]
fn the_whitened_search_equals_its_brute_force() {
    for seed in [1, 2] {
        let mut test = small_stuck(2, seed, 1600);
        let (j, kind, samples, value, margin) = brute_force_search(&test);
        let r = test.whitened_search().expect("colour learned");
        assert_eq!((r.actuator, r.kind, r.samples), (j, kind, samples), "{r:?}");
        assert!((r.value - value).abs() < 1e-9, "{r:?} against {value}");
        let m = r.margin_over(r.next_actuator_drop);
        assert!(
            (m - margin).abs() < 1e-6 * margin.abs().max(1.0),
            "{m} against {margin}"
        );
    }
}

#[test]
fn the_whitened_search_names_a_small_stuck_output_and_its_onset() {
    // 1.5 s after the onset: the right actuator, stuck where it is, since the onset, clearly
    // against the actuator that moves the rates alike (whose loss the plain fit, weighing
    // the wind's slow part like independent samples, can take it for).
    // (The plain fit named it clearly on none of these seeds, and another actuator on 8.)
    for seed in 1..=10 {
        let mut test = small_stuck(2, seed, 1475);
        let r = test.whitened_search().expect("colour learned");
        assert_eq!(
            (r.actuator, r.kind),
            (2, ChangeKind::Stuck),
            "seed {seed}: {r:?}"
        );
        assert!((r.since - 28.0).abs() <= 0.2, "seed {seed}: {r:?}");
        assert!(
            r.margin_over(r.next_actuator_drop) >= 20.0,
            "seed {seed}: {r:?}"
        );
        // Its level is what the wind's slow part hides most over 1.5 s (0.49-0.58 here).
        assert!((r.value - 0.545).abs() < 0.06, "seed {seed}: {r:?}");
        let plain = test.evaluate().expect("a reading");
        assert!(
            plain.actuator != 2 || plain.margin_over(plain.next_actuator_drop) < 20.0,
            "seed {seed}: {plain:?}"
        );
    }
    // And with no change, no clear reading (nor one over the whole store, which the
    // residual's filter started cold at the store's first sample used to give).
    for seed in 1..=10 {
        let mut rng = Rng::new(100 + seed);
        let mut test = ChangeTest::new(effects(), [1.0; 4], 3, 600, 10, 3000);
        for (k, r) in coloured(&mut rng, 1800, 0.97, 0.1, 0.01).iter().enumerate() {
            let t = k as f64 * 0.02;
            let u = [0.5 + 0.02 * (t * 3.0).sin(), 0.5, 0.5];
            test.push(t, r, &u, k < 1400);
        }
        let r = test.whitened_search().expect("colour learned");
        assert!(
            r.margin_over(r.next_actuator_drop) < 20.0,
            "seed {seed}: {r:?}"
        );
        assert!(r.samples < test.len(), "seed {seed}: {r:?}");
    }
}

#[test]
fn without_a_learned_colour_there_is_no_whitened_reading() {
    // Everything pushed while under way: nothing learned.
    let test = run(0, ChangeKind::Gain, 0.6, 200, 350);
    assert!(!test.colour_learned());
    assert_eq!(test.whitened_gain_or_offset(0, 150), None);
}
