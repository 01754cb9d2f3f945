//! The vehicle filters' tests: identification and its release, the steering's entries, the
//! healthy residual.

use super::*;
use crate::model::Model;

/// Identification (see `IdentifyParams`) on a quad whose motor 2 loses half its effect at
/// 10 s and recovers at 40 s. The fault is "decided" at 10.5 s and again at 20 s, is out of
/// force from 23.5 s to 24 s, and is decided once more at 24 s: the MIT rule raises the AHC
/// noise after the onset; 3 s after each decision every AHC entry is capped at q0 and the
/// rate entries are left as they were; the cap ends at once when no fault is in force; the
/// recovery releases it within a second (and it returns 3 s later, the fault still in
/// force). The diagnosis' fit is awaited on each identification after a decision and
/// followed while it stays of one kind (`hold_class`); after the release, once its fit is
/// back where the last one was.
#[test]
fn identification_holds_the_ahc_noise_until_a_further_change() {
    use crate::sim::fault::Fault;
    use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};
    let dt = 0.02;
    let profile = Profile::resolve("quad-x").unwrap();
    let mut cfg = VehicleSimConfig::calm(profile.clone(), dt, 7);
    cfg.faults
        .push(toml::from_str::<Fault>("actuator='motor2'\nt=10.0\nuntil=40.0\ngamma=0.5").unwrap());
    let mut sim = VehicleSim::new(cfg).unwrap();
    let mut pair = FilterPair::<11, 4, 23>::new(FilterSetup::from_profile(&profile, dt).unwrap());
    let q0 = pair.ukf.q0;
    let ahc = 3..11;
    let at = |t: f64, when: f64| (t - when).abs() < dt / 2.0;
    let (mut raised, mut transitions) = (false, 0);
    let (mut released_at, mut released_before_recovery) = (None, 0);
    let mut awaited = Vec::new();
    let loss = |gamma| Identified {
        kind: IdentifiedKind::Gain,
        gamma,
        gamma_std: 0.01,
        delta: 0.0,
        delta_std: 0.02,
        tolerance: 0.15,
    };
    for _ in 0..(45.0 / dt) as usize {
        let s = sim.step();
        let y = SVector::<f64, 4>::from_column_slice(&s.y);
        pair.ukf.try_step(&s.u[..4], &y).unwrap();
        if at(s.t, 10.5) || at(s.t, 20.0) || at(s.t, 24.0) {
            pair.forget(1);
        }
        if (10.0..10.5).contains(&s.t) {
            raised |= ahc
                .clone()
                .any(|i| pair.ukf.ukf.process_noise[i] > 2.0 * q0[i]);
        }
        let in_force = (10.5..23.5).contains(&s.t) || s.t >= 24.0;
        let (before, was) = (pair.ukf.ukf.process_noise, pair.ukf.identifying());
        pair.set_fault_in_force(in_force);
        if pair.ukf.identifying() && !was {
            transitions += 1;
            let rates_kept = (0..3).all(|i| pair.ukf.ukf.process_noise[i] == before[i]);
            assert!(rates_kept, "t = {}: the cap touched the rate entries", s.t);
            awaited.push(pair.awaits_identification(1));
            let x_before = pair.ukf.ukf.x;
            match transitions {
                // No fit (yet): nothing reseated, asked again. On the third, a fit comes next
                // and is followed (until the release, which the fourth checks).
                1 | 3 => {
                    pair.hold_class(1, None);
                    assert_eq!(pair.ukf.ukf.x, x_before);
                    assert!(pair.awaits_identification(1));
                    if transitions == 3 {
                        pair.hold_class(1, Some(loss(0.5)));
                        assert_eq!(pair.ukf.ukf.x[4], 0.5);
                    }
                }
                2 => {
                    pair.hold_class(1, Some(loss(0.55)));
                    let (x, p) = (&pair.ukf.ukf.x, &pair.ukf.ukf.p);
                    assert_eq!((x[4], x[8]), (0.55, 0.0));
                    assert_eq!((p[(4, 4)], p[(4, 8)], p[(0, 4)]), (1e-4, 0.0, 0.0));
                    assert!(!pair.awaits_identification(0), "motor 1 was not decided");
                    // Followed while it stays clear and of the same kind.
                    assert!(pair.awaits_identification(1), "no longer followed");
                    pair.hold_class(1, Some(loss(0.57)));
                    assert_eq!(pair.ukf.ukf.x[4], 0.57);
                    // Another kind is the diagnosis' to decide: not followed, and the
                    // loss still is.
                    let offset = Identified {
                        kind: IdentifiedKind::Offset,
                        gamma: 1.0,
                        gamma_std: 0.03,
                        delta: -0.2,
                        delta_std: 0.01,
                        tolerance: 0.0,
                    };
                    pair.hold_class(1, Some(offset));
                    assert_eq!((pair.ukf.ukf.x[4], pair.ukf.ukf.x[8]), (0.57, 0.0));
                    pair.hold_class(1, Some(loss(0.56)));
                    assert_eq!(pair.ukf.ukf.x[4], 0.56);
                }
                // After the release: the fault is still in force, and the data's fit is
                // followed again once its gain is where the last fit had it (0.5 ± 0.01:
                // within the class tolerance, 0.15, or 3σ of the two if wider), not
                // before (as after the fault's end).
                4 => {
                    pair.hold_class(1, Some(loss(0.95)));
                    assert_eq!(pair.ukf.ukf.x, x_before);
                    pair.hold_class(1, Some(loss(0.66)));
                    assert_eq!(pair.ukf.ukf.x, x_before);
                    let offset = Identified {
                        kind: IdentifiedKind::Offset,
                        ..loss(0.5)
                    };
                    pair.hold_class(1, Some(offset));
                    assert_eq!(pair.ukf.ukf.x, x_before, "another kind");
                    pair.hold_class(1, Some(loss(0.62)));
                    assert_eq!(pair.ukf.ukf.x[4], 0.62);
                    // Followed again: any fit of the kind, as before the release.
                    pair.hold_class(1, Some(loss(0.51)));
                    assert_eq!(pair.ukf.ukf.x[4], 0.51);
                }
                _ => {}
            }
        }
        let held = ahc.clone().all(|i| pair.ukf.ukf.process_noise[i] <= q0[i]);
        let holding = [13.6..19.9, 23.1..23.5, 27.1..40.0];
        if holding.iter().any(|r| r.contains(&s.t)) {
            assert!(pair.ukf.identifying() && held, "t = {}", s.t);
        }
        let free = [0.0..13.4, 20.0..22.9, 23.5..24.0];
        if free.iter().any(|r| r.contains(&s.t)) {
            assert!(!pair.ukf.identifying(), "t = {}", s.t);
        }
        if s.t < 40.0 {
            released_before_recovery = pair.ukf.releases;
        }
        if s.t >= 40.0 && released_at.is_none() && pair.ukf.releases > 0 {
            released_at = Some(s.t);
        }
    }
    assert!(
        raised,
        "the MIT rule did not raise any AHC noise after the onset"
    );
    // One hold after each decision, and one 3 s after the release (the fault still in force).
    assert_eq!(transitions, 4);
    // A fit is awaited during the identification after each decision, and after a release
    // by the actuator whose fit was followed.
    assert_eq!(awaited, [true, true, true, true]);
    let at = released_at.expect("the recovery did not release the hold");
    assert!(at < 41.0, "released at {at} s");
    // (Fed a fit of the fault after its end, the fourth hold is released again.)
    assert_eq!(released_before_recovery, 0, "released before the recovery");
}

/// A quad-X filter pair (n = 11, with a_z) at 50 Hz.
fn quad_pair() -> FilterPair<11, 4, 23> {
    let profile = Profile::resolve("quad-x").unwrap();
    FilterPair::new(FilterSetup::from_profile(&profile, 0.02).unwrap())
}

/// A fault in force until the MIT-UKF identifies (`IDENTIFY_AFTER_S` at 50 Hz).
fn identify(pair: &mut FilterPair<11, 4, 23>) {
    for _ in 0..=IDENTIFY_AFTER_S as usize * 50 + 1 {
        pair.set_fault_in_force(true);
    }
    assert!(pair.ukf.identifying());
}

/// A loss identified at `gamma` (spread 0.01, delta 0 ± 0.013) with this class tolerance.
fn loss_at(gamma: f64, tolerance: f64) -> Identified {
    Identified {
        kind: IdentifiedKind::Gain,
        gamma,
        gamma_std: 0.01,
        delta: 0.0,
        delta_std: 0.013,
        tolerance,
    }
}

/// Which actuators wait for the diagnosis' fit or follow it: those decided in the step that
/// started the identification, all of them, and none decided before a further decision,
/// cleared, or before the MIT-UKF was reset.
#[test]
fn a_further_decision_ends_the_wait_of_the_earlier_ones() {
    let mut pair = quad_pair();
    let waiting = |pair: &FilterPair<11, 4, 23>| -> Vec<usize> {
        (0..4).filter(|&j| pair.awaits_identification(j)).collect()
    };
    pair.forget(0);
    pair.set_fault_in_force(true);
    identify(&mut pair);
    assert_eq!(waiting(&pair), [0]);
    let offset = Identified {
        kind: IdentifiedKind::Offset,
        gamma: 1.0,
        gamma_std: 0.05,
        delta: -0.15,
        delta_std: 0.01,
        tolerance: 0.0,
    };
    pair.hold_class(0, Some(offset));
    assert_eq!(pair.ukf.ukf.x[7], -0.15);
    assert_eq!(waiting(&pair), [0], "no longer followed");
    // Two decided in one step both wait; motor 1's identification, followed, ends.
    pair.forget(2);
    pair.forget(3);
    pair.set_fault_in_force(true);
    assert!(
        waiting(&pair).is_empty(),
        "waiting before the identification"
    );
    identify(&mut pair);
    assert_eq!(waiting(&pair), [2, 3]);
    // A clearing ends one's, and a fresh MIT-UKF (after numerical failure) all of them.
    pair.recovered(2);
    assert_eq!(waiting(&pair), [3]);
    pair.reset(0);
    assert!(waiting(&pair).is_empty());
}

/// A calm quad-X sim whose motor 2 loses half its effect at 5 s, and a filter pair fed it
/// for 6 s with that loss then decided; the step function feeds the MIT-UKF one sample
/// and returns how far its state moved.
fn motor2_loss_decided() -> (
    FilterPair<11, 4, 23>,
    impl FnMut(&mut FilterPair<11, 4, 23>) -> SVector<f64, 11>,
) {
    use crate::sim::fault::Fault;
    use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};
    let dt = 0.02;
    let profile = Profile::resolve("quad-x").unwrap();
    let mut cfg = VehicleSimConfig::calm(profile.clone(), dt, 7);
    cfg.faults
        .push(toml::from_str::<Fault>("actuator='motor2'\nt=5.0\ngamma=0.5").unwrap());
    let mut sim = VehicleSim::new(cfg).unwrap();
    let mut pair = FilterPair::<11, 4, 23>::new(FilterSetup::from_profile(&profile, dt).unwrap());
    let mut step = move |pair: &mut FilterPair<11, 4, 23>| {
        let s = sim.step();
        let y = SVector::<f64, 4>::from_column_slice(&s.y);
        let before = pair.ukf.ukf.x;
        pair.ukf.try_step(&s.u[..4], &y).unwrap();
        pair.ukf.ukf.x - before
    };
    for _ in 0..(6.0 / dt) as usize {
        step(&mut pair);
    }
    pair.forget(1);
    (pair, step)
}

#[test]
fn the_updates_leave_the_identification_while_followed() {
    let (mut pair, mut step) = motor2_loss_decided();
    for _ in 0..=IDENTIFY_AFTER_S as usize * 50 + 1 {
        step(&mut pair);
        pair.set_fault_in_force(true);
    }
    let loss = Identified {
        kind: IdentifiedKind::Gain,
        gamma: 0.4,
        gamma_std: 0.01,
        delta: 0.02,
        delta_std: 0.02,
        tolerance: 0.0,
    };
    pair.hold_class(1, Some(loss));
    let (held, q) = (pair.ukf.ukf.p, pair.ukf.ukf.process_noise);
    let moved = step(&mut pair);
    assert_eq!((pair.ukf.ukf.x[4], pair.ukf.ukf.x[8]), (0.4, 0.02));
    // The variance as predicted (the gain is constant in the model), not updated.
    assert!((pair.ukf.ukf.p[(4, 4)] - (held[(4, 4)] + q[4])).abs() < 1e-15);
    assert!(moved.iter().any(|d| *d != 0.0), "the other states update");
    // Held while followed, also on steps without a clear fit; after a release the data
    // move them again.
    pair.set_fault_in_force(true);
    let moved = step(&mut pair);
    assert!(moved[4] == 0.0 && moved[8] == 0.0, "{moved}");
    pair.ukf.restart_identification();
    pair.set_fault_in_force(true);
    let moved = step(&mut pair);
    assert!(moved[4] != 0.0 && moved[8] != 0.0, "{moved}");
}

/// After a release, while the class in force stands, the coefficient that class leaves
/// unchanged (a loss's bias, an offset's gain) stays at the last fit and the other moves;
/// a class of another kind, or none, frees it, and when the class comes back it is at the
/// fit again (not where the updates took it meanwhile).
#[test]
fn after_a_release_the_class_keeps_its_unchanged_coefficient() {
    let offset = Identified {
        kind: IdentifiedKind::Offset,
        gamma: 1.0,
        gamma_std: 0.05,
        delta: -0.1,
        delta_std: 0.01,
        tolerance: 0.04,
    };
    // (kind, fit, the held entry and its value at the fit, the free entry)
    for (kind, fit, (held, at), free) in [
        (IdentifiedKind::Gain, loss_at(0.4, 0.15), (8, 0.0), 4),
        (IdentifiedKind::Offset, offset, (4, 1.0), 8),
    ] {
        let (mut pair, mut step) = motor2_loss_decided();
        let class = |pair: &mut FilterPair<11, 4, 23>, kind| {
            pair.class_in_force(1, kind);
            pair.set_fault_in_force(true);
        };
        for _ in 0..=IDENTIFY_AFTER_S as usize * 50 + 1 {
            step(&mut pair);
            class(&mut pair, Some(kind));
        }
        pair.hold_class(1, Some(fit));
        step(&mut pair);
        // Released: the held entry stays at the fit, the other moves with the data.
        pair.ukf.restart_identification();
        class(&mut pair, Some(kind));
        for _ in 0..25 {
            let moved = step(&mut pair);
            assert!(
                moved[held] == 0.0 && moved[free] != 0.0,
                "{kind:?}: {moved}"
            );
            class(&mut pair, Some(kind));
        }
        assert_eq!(pair.ukf.ukf.x[held], at, "{kind:?}");
        // Another class, or none: both move.
        let other = match kind {
            IdentifiedKind::Gain => IdentifiedKind::Offset,
            _ => IdentifiedKind::Gain,
        };
        for k in [Some(other), None] {
            class(&mut pair, k);
            let moved = step(&mut pair);
            assert!(moved[held] != 0.0 && moved[free] != 0.0, "{k:?}: {moved}");
        }
        assert_ne!(pair.ukf.ukf.x[held], at);
        // The class back: at the fit again, with the fit's spread.
        class(&mut pair, Some(kind));
        assert_eq!(pair.ukf.ukf.x[held], at, "{kind:?}");
        let sd = if held == 4 {
            fit.gamma_std
        } else {
            fit.delta_std
        };
        assert!((pair.ukf.ukf.p[(held, held)] - sd * sd).abs() < 1e-15);
    }
}

#[test]
fn a_decision_on_another_actuator_keeps_an_earlier_identification() {
    let mut pair = quad_pair();
    pair.forget(0);
    identify(&mut pair);
    let loss = loss_at(0.6, 0.0);
    pair.hold_class(0, Some(loss));
    // The gusts move it, then the innovations release the identification (motor 2's
    // change, not yet decided).
    (pair.ukf.ukf.x[3], pair.ukf.ukf.x[7]) = (0.5, 0.04);
    pair.ukf.restart_identification();
    pair.set_fault_in_force(true);
    assert!(!pair.awaits_identification(0));
    assert!(
        !pair.ukf.keep_capped.iter().any(|c| *c),
        "nothing decided yet"
    );
    // Motor 2's decision: motor 0's identification stands, its noise capped.
    pair.forget(2);
    pair.set_fault_in_force(true);
    assert_eq!((pair.ukf.ukf.x[3], pair.ukf.ukf.x[7]), (0.6, 0.0));
    assert!((pair.ukf.ukf.p[(3, 3)] - 1e-4).abs() < 1e-12);
    let capped: Vec<usize> = (0..11).filter(|&i| pair.ukf.keep_capped[i]).collect();
    assert_eq!(capped, [3, 7]);
    // A decision on motor 0 itself, its clearing, or no fault in force ends that.
    pair.forget(0);
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c));
    identify(&mut pair);
    pair.hold_class(0, Some(loss));
    pair.ukf.restart_identification();
    pair.set_fault_in_force(true);
    pair.forget(1);
    assert!(pair.ukf.keep_capped[3]);
    pair.recovered(0);
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c));
    // No fault in force: the caps go, and the following ends.
    identify(&mut pair);
    pair.hold_class(1, Some(loss));
    pair.forget(3);
    assert!(pair.ukf.keep_capped[4]);
    identify(&mut pair);
    pair.hold_class(3, Some(loss));
    pair.set_fault_in_force(false);
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c));
    pair.forget(2);
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c), "motor 4 not kept");
    // A release long before the decision may have been the followed fault's end: not kept.
    pair.forget(1);
    identify(&mut pair);
    pair.hold_class(1, Some(loss));
    pair.ukf.restart_identification();
    pair.set_fault_in_force(true);
    for _ in 0..=(RELEASE_TO_DECISION_S / 0.02) as usize {
        pair.set_fault_in_force(true);
    }
    pair.forget(2);
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c));
}

/// A release while an actuator is already released (its fit not followed since the first)
/// does not renew it: the last fit is the one the data stopped agreeing with at the first
/// release, more than `IDENTIFY_AFTER_S` before the second. A decision on another actuator
/// just after the second leaves it to the filter (just after the first it is kept: see
/// `a_decision_on_another_actuator_keeps_an_earlier_identification`).
#[test]
fn a_second_release_does_not_renew_an_earlier_one() {
    let loss = loss_at(0.6, 0.15);
    let release = |pair: &mut FilterPair<11, 4, 23>| {
        pair.ukf.restart_identification();
        pair.set_fault_in_force(true);
        assert!(!pair.ukf.identifying());
    };
    let mut pair = quad_pair();
    pair.forget(0);
    identify(&mut pair);
    pair.hold_class(0, Some(loss));
    release(&mut pair);
    // Identifying again, 3 s later: a fit far from the last is not resumed; released again.
    identify(&mut pair);
    pair.hold_class(0, Some(loss_at(0.95, 0.15)));
    assert_ne!(pair.ukf.ukf.x[3], 0.95, "resumed");
    assert!(pair.awaits_identification(0));
    release(&mut pair);
    (pair.ukf.ukf.x[3], pair.ukf.ukf.x[7]) = (0.8, 0.05);
    pair.forget(2);
    assert_eq!((pair.ukf.ukf.x[3], pair.ukf.ukf.x[7]), (0.8, 0.05));
    assert!(!pair.ukf.keep_capped.iter().any(|c| *c));
}

#[test]
#[allow(clippy::needless_range_loop)] // actuator j indexes the effects and the state
fn the_healthy_residual_of_an_offset_is_its_weighted_effect_unweighted() {
    // What the change test relies on: the healthy model's residual of a vehicle whose
    // actuator j gives `s` more than commanded is `s` times `weighted_effects[j]` divided
    // by `residual_weights`, row by row (rates and a_z), and zero without a change.
    let dt = 0.02;
    for name in ["quad-x", "hexa-x", "plane", "heli-h3-120"] {
        let profile = Profile::resolve(name).unwrap();
        let filters = build(&profile, dt).unwrap();
        let (l, m) = (filters.actuators(), filters.measurements());
        let effects = weighted_effects(&profile, dt);
        let weights = residual_weights(&profile, dt);
        let u: Vec<f64> = (0..l).map(|j| 0.3 + 0.05 * j as f64).collect();
        let prev = [0.1, -0.05, 0.02];
        for j in 0..l {
            let s = 0.1;
            let y = match (l, m) {
                (4, 4) => truth::<11, 4>(&profile, dt, &prev, &u, j, s),
                (6, 4) => truth::<15, 4>(&profile, dt, &prev, &u, j, s),
                (3, 3) => truth::<9, 3>(&profile, dt, &prev, &u, j, s),
                (4, 3) => truth::<11, 3>(&profile, dt, &prev, &u, j, s),
                other => panic!("{other:?}"),
            };
            let healthy = match (l, m) {
                (4, 4) => truth::<11, 4>(&profile, dt, &prev, &u, j, 0.0),
                (6, 4) => truth::<15, 4>(&profile, dt, &prev, &u, j, 0.0),
                (3, 3) => truth::<9, 3>(&profile, dt, &prev, &u, j, 0.0),
                (4, 3) => truth::<11, 3>(&profile, dt, &prev, &u, j, 0.0),
                other => panic!("{other:?}"),
            };
            let zero = filters.healthy_residual(&prev, &u, &healthy[..m]);
            assert!(
                zero[..m].iter().all(|r| r.abs() < 1e-12),
                "{name}: {zero:?}"
            );
            let r = filters.healthy_residual(&prev, &u, &y[..m]);
            for i in 0..m {
                let expected = s * effects[j][i] / weights[i];
                assert!(
                    (r[i] - expected).abs() < 1e-9 * (1.0 + expected.abs()),
                    "{name} actuator {j} row {i}: {} vs {expected}",
                    r[i]
                );
            }
        }
    }
}

/// `[p, q, r(, a_z)]` one step after `prev` with actuator j's offset at `s`.
fn truth<const N: usize, const M: usize>(
    profile: &Profile,
    dt: f64,
    prev: &[f64; 3],
    u: &[f64],
    j: usize,
    s: f64,
) -> [f64; 4] {
    let model = RateModel::<N, M>::new(&profile.rate_params(), dt).unwrap();
    let l = model.actuators();
    let mut x = model.healthy_state(*prev);
    x[3 + l + j] = s;
    let next = model.f(&x, u);
    let mut y = [0.0; 4];
    y[..3].copy_from_slice(&[next[0], next[1], next[2]]);
    if M == 4 {
        let h = model.h_matrix(u) * next + model.h_offset(u);
        y[3] = h[3];
    }
    y
}

/// A vertical row on the set filter of a rates-only model (`set_vertical`): the detectors are
/// the same whether `step` gets a_z or not, the healthy residual gains the row's
/// (`a_z - c_z - Σ g_z,j u_j`), and the set, which cannot separate four motors on three rows,
/// bounds each motor's output with it; taken away, the set has three rows again.
#[test]
fn a_vertical_row_reaches_the_set_filter_alone() {
    use crate::sim::vehicle::{VehicleSim, VehicleSimConfig};
    let dt = 0.02;
    let with_az = Profile::resolve("quad-x").unwrap();
    let mut rates_only = with_az.clone();
    rates_only.model.measure_az = false;
    let p = with_az.rate_params();
    let mut plain = build(&rates_only, dt).unwrap();
    let mut row = build(&rates_only, dt).unwrap();
    row.set_vertical(Some((&p.vertical, p.vertical_offset)));
    assert_eq!(
        (plain.set_rows(), row.set_rows(), row.measurements()),
        (3, 4, 3)
    );
    // Generous stated bounds (the calm flight's residuals are far inside them).
    let mut bounds = [[0.05, 0.05, 0.05, 1.0]; LAGS.len()];
    for b in bounds.iter_mut().skip(1) {
        *b = b.map(|v| 2.0 * v);
    }
    let command_ref = [0.5; MAX_ACTUATORS];
    plain.set_residual_bounds(bounds, command_ref);
    row.set_residual_bounds(bounds, command_ref);
    let mut sim = VehicleSim::new(VehicleSimConfig::calm(with_az, dt, 11)).unwrap();
    let mut previous = None;
    for _ in 0..(10.0 / dt) as usize {
        let s = sim.step();
        let u = &s.u[..4];
        for r in plain
            .step(u, &s.y[..3])
            .into_iter()
            .chain(row.step(u, &s.y[..4]))
        {
            r.unwrap();
        }
        for f in 0..2 {
            for j in 0..4 {
                let (a, b) = (plain.ahc(f, j), row.ahc(f, j));
                assert_eq!(
                    (a.gamma, a.delta, a.gamma_lo),
                    (b.gamma, b.delta, b.gamma_lo)
                );
            }
        }
        if let Some(prev) = previous {
            let (a, b) = (
                plain.healthy_residual(&prev, u, &s.y[..3]),
                row.healthy_residual(&prev, u, &s.y[..4]),
            );
            assert_eq!(a[..3], b[..3]);
            let want =
                s.y[3] - p.vertical_offset - (0..4).map(|j| p.vertical[j] * u[j]).sum::<f64>();
            assert!((b[3] - want).abs() < 1e-12, "{} against {want}", b[3]);
        }
        previous = Some([s.y[0], s.y[1], s.y[2]]);
    }
    for j in 0..4 {
        assert!(plain.guaranteed(j).output_bounds.is_none());
        let [lo, hi] = row
            .guaranteed(j)
            .output_bounds
            .expect("bounded through a_z");
        assert!(
            lo <= 0.0 && 0.0 <= hi && hi - lo < 1.0,
            "motor {}: [{lo}, {hi}]",
            j + 1
        );
    }
    row.set_vertical(None);
    assert_eq!(row.set_rows(), 3);
}
