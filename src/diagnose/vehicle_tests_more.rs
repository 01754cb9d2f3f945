//! Tests of rules X1, D2, R1, C1, C2, F1 and the identification, beside `vehicle_tests.rs`, whose
//! flight and estimate helpers they use.

use super::*;

/// Quad X, motor 2 read at gamma 0.6 from `onset`, rolled past 70° while `rolled(t)`: the
/// first fault decision of `steps` steps.
fn rolled_first_fault(steps: usize, onset: f64, rolled: impl Fn(f64) -> bool) -> Decision {
    let p = Profile::resolve("quad-x").unwrap();
    let mut d = Diagnoser::new(DiagnosisParams::default(), 1, &p, DT);
    let est = faulted(4, onset, &[(1, estimate(0.6, 0.05, 0.0, 0.02))]);
    let mut out = vec![];
    let mut all = vec![];
    for k in 0..steps {
        let t = k as f64 * DT;
        let e = est(t);
        let roll = if rolled(t) { 70f64.to_radians() } else { 0.0 };
        d.envelope(t, [roll, 0.0, 0.0], Some(-9.8));
        d.update(t, &dithered(4, 0.5, 0.04)(t), &[&e, &e], &mut out);
        all.append(&mut out);
    }
    all.into_iter().find(|x| x.event == Event::Fault).unwrap()
}

#[test]
fn x1_a_decision_out_of_the_flight_envelope_is_marked_as_a_crash() {
    // Quad X, motor 2 at gamma 0.6 from 8 s; from 7.7 s the vehicle rolls past 70°.
    let run = |crash: bool| rolled_first_fault(700, 8.0, |t| crash && t >= 7.7);
    let crashed = run(true);
    assert!(crashed.in_crash, "{crashed:?}");
    assert!(crashed.detail.unwrap().contains("(X1)"));
    let flying = run(false);
    assert!(!flying.in_crash && !flying.detail.unwrap().contains("X1"));
}

/// Plane, aileron commanded about 0.1 ± 0.08, its gain `gain` from 16 s, which the filters do
/// not show at all (their estimates stay healthy, so no CUSUM rises and nothing is under way).
fn plane_aileron_gain(gain: f64, to: f64) -> Flight {
    plane_aileron_gain_read(gain, 0.0, to, |_| vec![healthy(0.02); 3])
}

/// As [`plane_aileron_gain`], with an offset `offset` too from 16 s, the filters' estimates
/// given by `est`.
fn plane_aileron_gain_read(
    gain: f64,
    offset: f64,
    to: f64,
    est: impl Fn(f64) -> Vec<AhcEstimate>,
) -> Flight {
    let mut f = Flight::new("plane");
    let u = |t: f64| {
        vec![
            0.1 + 0.08 * (t * 3.1).sin(),
            0.05 * (t * 2.0).sin(),
            0.02 * (t * 1.7).sin(),
        ]
    };
    let change = move |t: f64, u: &[f64]| {
        let deviation = if t >= 16.0 {
            (gain - 1.0) * u[0] + offset
        } else {
            0.0
        };
        (0usize, deviation)
    };
    f.fly(0.0, to, u, est, Some(&change as Change));
    f
}

#[test]
fn d2_the_data_read_while_nothing_is_under_way_and_a_fault_is_what_the_classes_define() {
    // A loss to 0.75: the data, read every `SCAN_S` though no filter statistic moves, name it
    // clearly, and a gain under 1 - loe_tau is a fault (the gain statistic's threshold would
    // need a loss to 0.62).
    let f = plane_aileron_gain(0.75, 22.0);
    let faults = f.events(Event::Fault);
    assert_eq!(faults.len(), 1, "{:?}", f.decisions);
    assert_eq!(faults[0].rule, Some(Rule::F3));
    assert_eq!(faults[0].actuator.as_deref(), Some("aileron"));
    assert!(faults[0].t < 19.0, "{}", faults[0].t);
    // A gain above one is no class: read as clearly, it decides nothing.
    let f = plane_aileron_gain(1.3, 22.0);
    assert!(f.events(Event::Fault).is_empty(), "{:?}", f.decisions);
    // A gain of 0.3 is a fault by D2; with an offset of +0.06 changing with it, a gain and an
    // offset together explain the change clearly better than either: D2 leaves it to the
    // filters (which here do not see it).
    let f = plane_aileron_gain(0.3, 22.0);
    assert_eq!(f.events(Event::Fault).len(), 1, "{:?}", f.decisions);
    let est = |_: f64| vec![healthy(0.02); 3];
    let f = plane_aileron_gain_read(0.3, 0.06, 22.0, est);
    assert!(f.events(Event::Fault).is_empty(), "{:?}", f.decisions);
}

#[test]
fn f1_a_gain_above_one_is_no_evidence_of_a_fault() {
    // The aileron's gain changes from 16 s and the filters read it at `read` (their deviation
    // alarms): a loss to 0.6 is decided at once by F1 (or F3). A gain of 1.3, which the data
    // fit as such, is no fault's kind, and read as an offset (0.3 of the command's mean,
    // 0.02-0.18) it is under the threshold: no F1, the data's reading holds F2 back, and the
    // actuator is suspect by its alarm (S2).
    let run = |gain: f64, read: f64| {
        let est = faulted(3, 16.0, &[(0, estimate(read, 0.05, 0.0, 0.01))]);
        plane_aileron_gain_read(gain, 0.0, 26.0, est)
    };
    let loss = run(0.6, 0.6);
    let faults = loss.events(Event::Fault);
    assert_eq!(faults.len(), 1, "{:?}", loss.decisions);
    assert!(faults[0].t < 17.5, "{:?}", faults[0]);
    let above = run(1.3, 1.8);
    assert!(
        above.events(Event::Fault).is_empty(),
        "{:?}",
        above.decisions
    );
    let suspect = above.events(Event::Suspect);
    assert!(
        suspect.iter().any(|d| d.rule == Some(Rule::S2)),
        "{:?}",
        above.decisions
    );
}

#[test]
fn r1_a_fault_the_data_decided_stands_until_they_have_not_named_it_for_clear_s() {
    let mut f = plane_aileron_gain(0.75, 20.0);
    assert_eq!(f.events(Event::Fault).len(), 1, "{:?}", f.decisions);
    // The store is lost (a long telemetry hole): the data name nothing from 20 s on.
    f.d.residual_gap();
    let n = f.n();
    f.fly(
        20.0,
        25.0,
        dithered(n, 0.1, 0.08),
        |_| vec![healthy(0.02); 3],
        None,
    );
    let cleared = f.events(Event::Cleared);
    assert_eq!(cleared.len(), 1, "{:?}", f.decisions);
    let t = cleared[0].t;
    assert!((21.9..22.2).contains(&t), "cleared at {t}");
}

#[test]
fn c2_a_motors_output_overstated_below_zero_is_a_loss() {
    // Quad X, motor 2 read from 8 s at gamma -0.6 and delta +0.1 (both beyond their
    // tolerances: the mixed fallback) at a command about 0.5: the output read is -0.2, a
    // motor's cannot be; the filters overstate a loss, which is what it is. A surface's
    // output may cross zero: the plane's elevator at 0.1 read at gamma -0.6, delta -0.05 has
    // moved by twice its command through zero, a bias.
    let run = |profile: &str, mean: f64, delta: f64| {
        let mut f = Flight::new(profile);
        let n = f.n();
        let est = move |t: f64| {
            let mut e = vec![healthy(0.02); n];
            if t >= 8.0 {
                e[1] = estimate(-0.6, 0.1, delta, 0.01);
            }
            e
        };
        f.fly(0.0, 14.0, dithered(n, mean, 0.04), est, None);
        let fault = f.events(Event::Fault);
        assert_eq!(fault.len(), 1, "{:?}", f.decisions);
        fault[0].class
    };
    assert_eq!(
        run("quad-x", 0.5, 0.1),
        Some(FaultClass::LossOfEffectiveness)
    );
    assert_eq!(run("plane", 0.1, -0.05), Some(FaultClass::Bias));
}

#[test]
fn c2_a_gain_bounded_near_zero_with_an_offset_is_stuck() {
    // Actuator 2 read from 8 s at gamma 0.02 ± 0.1 with an offset while its command swings:
    // the output no longer follows it. The plane's elevator (command about 0.1) with delta
    // +0.12: stuck. A quad's motor (about 0.5) with delta +0.3 is stuck too; with delta -0.1
    // its output would be below zero, a total loss. The same gain with bounds reaching 0.3
    // (a gain passing through zero) is not told stuck.
    let run = |profile: &str, mean: f64, g_half: f64, delta: f64| {
        let mut f = Flight::new(profile);
        let n = f.n();
        let est = move |t: f64| {
            let mut e = vec![healthy(0.02); n];
            if t >= 8.0 {
                e[1] = estimate(0.02, g_half, delta, 0.01);
            }
            e
        };
        f.fly(0.0, 14.0, dithered(n, mean, 0.04), est, None);
        let fault = f.events(Event::Fault);
        assert_eq!(fault.len(), 1, "{:?}", f.decisions);
        fault[0].class
    };
    assert_eq!(run("plane", 0.1, 0.1, 0.12), Some(FaultClass::Stuck));
    assert_eq!(run("quad-x", 0.5, 0.1, 0.3), Some(FaultClass::Stuck));
    assert_eq!(
        run("quad-x", 0.5, 0.1, -0.1),
        Some(FaultClass::LossOfEffectiveness)
    );
    assert_ne!(run("plane", 0.1, 0.3, 0.12), Some(FaultClass::Stuck));
}

#[test]
fn x1_a_tumble_through_level_is_still_a_crash_until_it_has_been_level_for_clear_s() {
    // Quad X, rolled past 70° from 7.0 s to 7.4 s, level again from 7.4 s (a tumble passes
    // through level): motor 2 at gamma 0.6 from `onset`, decided by F2 3 s later, is decided
    // in the crash when the vehicle has been level for less than clear_s, not afterwards.
    let run = |onset: f64| rolled_first_fault(800, onset, |t| (7.0..7.4).contains(&t));
    let tumbling = run(5.5);
    assert!(
        (7.4..9.4).contains(&tumbling.t) && tumbling.in_crash,
        "{tumbling:?}"
    );
    let recovered = run(10.0);
    assert!(!recovered.in_crash, "{recovered:?}");
}

#[test]
fn identification_a_motors_bias_the_filters_read_as_a_gain_above_one_is_the_offset() {
    // Actuator 2 read from 8 s at gamma 1.3 (bounds ±0.05), offset 0, command about 0.5, and
    // nothing in the data: decided on the filters' mixed fallback, a bias. On a quad's motor no
    // class has a gain above one, so the fault is identified as the offset its output shows
    // at the operating point (0.3 × 0.5), gain one. A plane's surface is not (an angle output
    // has no such elimination: its offset and gain are the data's to tell).
    let run = |profile: &str| {
        let mut f = Flight::new(profile);
        let n = f.n();
        let est = faulted(n, 8.0, &[(1, estimate(1.3, 0.05, 0.0, 0.01))]);
        f.fly(0.0, 14.0, dithered(n, 0.5, 0.03), est, None);
        let fault = f.events(Event::Fault);
        assert_eq!(fault.len(), 1, "{:?}", f.decisions);
        assert_eq!(fault[0].class, Some(FaultClass::Bias), "{:?}", fault[0]);
        f.d.identified(1)
    };
    let id = run("quad-x").expect("the motor's offset is identified");
    assert_eq!(id.kind, IdentifiedKind::Offset);
    assert_eq!(id.gamma, 1.0);
    assert!((id.delta - 0.15).abs() < 0.01, "{id:?}");
    assert_eq!(run("plane"), None);
}

#[test]
fn r1_a_surfaces_fault_stands_while_the_bounds_show_it() {
    // Plane aileron read at gamma 0.75 (bounds ±0.08) from 8 s to 20 s. Its command is about
    // 0.3 until 12 s (a deviation of -0.075: an alarm), then about 0 (the output at trim
    // whatever the gain, and the gain statistic under half its threshold: the alarm ends).
    // The fault stands while the bounds keep the gain below 0.85,
    // and clears once the estimate is back; a quad's motor read the same way clears when its
    // alarm ends.
    let run = |profile: &str| {
        let mut f = Flight::new(profile);
        let n = f.n();
        let est = move |t: f64| {
            let mut e = vec![healthy(0.02); n];
            if (8.0..20.0).contains(&t) {
                e[0] = estimate(0.75, 0.08, 0.0, 0.02);
            }
            e
        };
        let u = move |t: f64| dithered(n, if t < 12.0 { 0.3 } else { 0.0 }, 0.03)(t);
        f.fly(0.0, 26.0, u, est, None);
        assert_eq!(f.events(Event::Fault).len(), 1, "{:?}", f.decisions);
        let cleared = f.events(Event::Cleared);
        assert_eq!(cleared.len(), 1, "{:?}", f.decisions);
        cleared[0].t
    };
    let surface = run("plane");
    assert!((20.0..22.5).contains(&surface), "{surface}");
    let motor = run("quad-x");
    assert!(motor < 20.0, "{motor}");
}

#[test]
fn c1_the_whitened_comparison_tells_a_motors_kind_before_it_is_clear_enough_to_name() {
    // Quad X motor 1, an offset of -0.15 from 16 s while hovering with a small dither; the
    // MIT-UKF reads it as a gain of 0.7 (its narrow prior on a motor's offset), which C2 calls
    // a loss. The whitened comparison favours the offset from the start; at `KIND_MARGIN`,
    // short of the `DATA_MARGIN` that names an actuator, it is the data's class, and the
    // fault's class is a bias from then on.
    let mut f = Flight::new("quad-x");
    let est = faulted(4, 16.0, &[(0, estimate(0.7, 0.05, 0.0, 0.02))]);
    let change = |t: f64, _: &[f64]| (0usize, if t >= 16.0 { -0.15 } else { 0.0 });
    let mut first_read = None;
    let mut t = 0.0;
    while t < 22.0 - 1e-9 {
        f.fly(t, t + DT, dithered(4, 0.5, 0.03), &est, Some(&change));
        t += DT;
        let margin = f.d.whitened_kind(0).map_or(0.0, |k| k.margin);
        if first_read.is_none() && f.d.data_class(0) == Some(FaultClass::Bias) {
            first_read = Some((t, margin));
        }
    }
    let (at, margin) = first_read.expect("the data read a bias");
    assert!(
        margin < DATA_MARGIN,
        "read at {at} with a margin of {margin}"
    );
    assert_eq!(f.last_class(), Some(FaultClass::Bias), "{:?}", f.decisions);
}

#[test]
fn f1_a_second_alarm_at_a_faults_onset_needs_the_data_to_name_it_clearly() {
    // Quad X: from 8 s the data show a change that motors 1 and 4 explain equally well (half
    // of it each), so the change test's best fit flickers between them, and both filters read
    // a loss. The first decided is a fault; the other's alarm, while that fault is younger than
    // `DATA_WAIT_S`, is its evidence: the data never name it clearly.
    let mut f = Flight::new("quad-x");
    let loss = estimate(0.6, 0.05, 0.0, 0.02);
    let est = faulted(4, 8.0, &[(0, loss), (3, loss)]);
    let u = dithered(4, 0.5, 0.04);
    let mut out = vec![];
    for k in 0..((8.0 + DATA_WAIT_S) / DT) as usize {
        let t = k as f64 * DT;
        let u = u(t);
        let s = if t >= 8.0 { -0.2 } else { 0.0 };
        let mut residual = [0.0; 4];
        for (i, r) in residual.iter_mut().enumerate() {
            if f.weights[i] > 0.0 {
                let effect = (f.effects[0][i] + f.effects[3][i]) * s;
                *r = (effect + 0.3 * f.rng.normal()) / f.weights[i];
            }
        }
        f.d.observe(t, &residual, &u);
        let e = est(t);
        f.d.update(t, &u, &[&e, &e], &mut out);
        f.decisions.append(&mut out);
    }
    let faults = f.events(Event::Fault);
    assert_eq!(faults.len(), 1, "{:?}", f.decisions);
}

#[test]
fn c1_a_pair_within_the_stuck_tolerance_keeps_a_stuck_class() {
    // Quad X motor 1 from 8 s: its output stays near 0.5, following a tenth of its command's
    // swings (the calibrated model's own error on them, or a nearly stuck output). A gain and an
    // offset together fit better than the output stuck, but with a gain within `stuck_gamma` of
    // zero, which the class definitions read as stuck too; the MIT-UKF reads a loss.
    let mut f = Flight::new("quad-x");
    let est = faulted(4, 8.0, &[(0, estimate(0.5, 0.05, 0.0, 0.02))]);
    let change = |t: f64, u: &[f64]| {
        let s = if t >= 8.0 {
            0.5 + 0.1 * (u[0] - 0.5) - u[0]
        } else {
            0.0
        };
        (0usize, s)
    };
    f.fly(0.0, 14.0, dithered(4, 0.5, 0.1), est, Some(&change));
    assert_eq!(f.last_class(), Some(FaultClass::Stuck), "{:?}", f.decisions);
}

#[test]
fn f1_f2_a_change_the_data_measure_as_no_fault_is_no_evidence() {
    // Plane, from 8 s the MIT-UKF reads the elevator's offset at 0.10 ± 0.01, past the
    // threshold (0.065). The data change by `offset` on `actuator`. Under the threshold (what
    // stronger gusts than the thresholds' make the MIT-UKF follow) they measure no fault, on
    // the elevator or elsewhere: nothing is decided, and F2's wait restarts while they fit so.
    // On the elevator at a fault's size F1 decides at once.
    let run = |actuator: usize, offset: f64| {
        let mut f = Flight::new("plane");
        let est = faulted(3, 8.0, &[(1, estimate(1.0, 0.05, 0.1, 0.01))]);
        let change = move |t: f64, _: &[f64]| (actuator, if t >= 8.0 { offset } else { 0.0 });
        f.fly(0.0, 16.0, dithered(3, 0.05, 0.05), est, Some(&change));
        let readings = f.d.reading().map(|r| (r.actuator, r.kind, r.value));
        let faults: Vec<_> = (f.events(Event::Fault).iter())
            .map(|d| (d.t, d.rule))
            .collect();
        (faults, readings)
    };
    let (faults, reading) = run(1, 0.03);
    assert_eq!(faults, vec![], "{reading:?}");
    // The rudder's 0.01 the data soon fit best, not clearly: F2's wait restarts while they do
    // (without the rule F2 decides at 13.4 s).
    let (faults, reading) = run(2, 0.01);
    assert!(
        faults.iter().all(|d| d.1 != Some(Rule::F2)),
        "{faults:?} {reading:?}"
    );
    let (faults, reading) = run(1, 0.12);
    let (t, rule) = *faults
        .first()
        .unwrap_or_else(|| panic!("not decided: {reading:?}"));
    assert_eq!(rule, Some(Rule::F1));
    assert!(t < 9.0, "{t}");
}
